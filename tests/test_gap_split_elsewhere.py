"""A split mode against a slope across the blows at another mode (issue 17, modal dev seed 60004):
the answer's layers on the data-only findings and the model level's split, as ``ramdaq gap``
combines them (:func:`ramdaq.analysis.gap.layers.answer`)."""

from __future__ import annotations

from ramdaq.analysis.gap.datamodel import Finding, Layer
from ramdaq.analysis.gap.layers import PRECEDENCE_STRENGTH, answer
from ramdaq.analysis.gap.modal_level import MAX_SPLIT_REL

WHERE = {"gages": [5, 9], "band": "57.9 Hz", "band_hz": 57.9, "band_edges_hz": [46.0, 104.0],
         "window": "late", "excess": 3.1e5, "z": 37.05}
SPLIT = {"f_lo_hz": 56.6, "f_hi_hz": 59.2, "mac": 0.99999, "gages": [4, 1, 10], "zeta": [0.01, 0.01]}


def _slope(mode_hz: float, ratio: float, law: bool = False) -> dict:
    """The homogeneity check's finding: a frequency moving with the blow's size at ``mode_hz``,
    ``ratio`` times its chance level; with ``law`` the decays told an amplitude-dependent
    stiffness."""
    more = (("stiffness_law_z", -6.6, "1"),) if law else (("frequency_per_doubling", -0.0044, "1"),)
    return Finding(check="homogeneity", layer=Layer.NONLINEARITY, gages=(5, 9, 13, 14),
                   statistic=ratio * 4.0, chance_level=4.0, size=-0.0044, unit="1", text="slope",
                   mode_hz=(mode_hz,), more=more).to_json()


def test_a_slope_at_another_mode_leaves_the_split():
    # the 12.5 Hz hull mode's slope (well above chance, no law told) is that mode's: the pair
    # at 56.6/59.2 Hz, far beyond the widest split read, answers
    elsewhere = _slope(12.46, 2.5)
    assert 12.46 * (1 + MAX_SPLIT_REL) < SPLIT["f_lo_hz"] / (1 + MAX_SPLIT_REL)
    a = answer("unexplained", [], WHERE, {5, 9, 13, 14}, [elsewhere], splits=[SPLIT])
    assert a.named == "split_mode" and a.by == "model"
    assert a.location["gages"] == [4, 1, 10] and a.location["window"] == "late"


def test_a_slope_at_the_split_sets_it_aside():
    # the same slope at the pair's own mode: two linear poles of one shape are what a frequency
    # that moves with the blow is fitted -- unexplained, read by the data layer
    at = _slope(58.0, 2.5)
    a = answer("unexplained", [], WHERE, {5, 9, 13, 14}, [at], splits=[SPLIT])
    assert a.named == "unexplained" and a.by == "data"
    # a slope barely past chance sets nothing aside, there or elsewhere
    weak = _slope(58.0, 0.5 * (1 + PRECEDENCE_STRENGTH))
    assert answer("unexplained", [], WHERE, {5, 9, 13, 14}, [weak], splits=[SPLIT]).named == "split_mode"


def test_a_told_stiffness_law_at_another_mode_still_sets_the_split_aside():
    # a crack's moving mode was fitted a pair beside it (modal dev seed 61000): a told law
    # anywhere keeps the answer "unexplained"
    law = _slope(62.6, 1.7 * PRECEDENCE_STRENGTH, law=True)
    split = {"f_lo_hz": 11.47, "f_hi_hz": 13.61, "mac": 0.96, "gages": [4, 7, 2], "zeta": [0.006, 0.0075]}
    a = answer("unexplained", [], WHERE, {5, 9, 13, 14}, [law], splits=[split])
    assert a.named == "unexplained"
