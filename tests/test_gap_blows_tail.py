"""A pre-window gap that is the previous blows' ringing (issue 17, clean trials): absent before the
first blow, it is the rig's decay (model form, "none"); a line present before the first blow too
stays "unexplained"."""

from __future__ import annotations

import numpy as np

from ramdaq.analysis.gap.evidence import GapMap, bands_for
from ramdaq.analysis.gap.layers import answer, blows_tail
from ramdaq.analysis.gap.verdict import gap_where

GAGES = (1, 3, 7, 9)
N_FIT = 3           # segments the fitted map sums


def _maps(first_excess: float) -> tuple[GapMap, GapMap]:
    """A fitted map (3 segments) with a large gap on gages 7, 9 in the 87 Hz band, pre window,
    and the first segment's map holding ``first_excess`` of the per-segment excess there."""
    bands = bands_for(np.array([24.5, 87.4]), 200.0)
    shape = (4, 3, 3)
    sd = np.full(shape, 0.5)
    exp = np.full(shape, float(N_FIT))
    obs = exp.copy()
    obs[2, 2, 0] += 9e5             # gage 7, the 87.4 Hz band, pre window: a tail of 9e5 variances
    obs[3, 2, 0] += 6e5
    fit = GapMap((obs - exp) / sd, obs, exp, sd, bands, GAGES)
    e1 = np.ones(shape)
    o1 = e1.copy()
    o1[2, 2, 0] += first_excess * 9e5 / N_FIT
    o1[3, 2, 0] += first_excess * 6e5 / N_FIT
    return fit, GapMap((o1 - e1) / sd, o1, e1, sd, bands, GAGES)


def test_a_pre_window_gap_absent_before_the_first_blow_is_the_rigs_decay():
    fit, first = _maps(0.0)
    w = gap_where(fit, fit, first, N_FIT)
    assert w["window"] == "pre" and w["gages"] == [7, 9]
    assert w["before_blows"]["share"] == 0.0 and w["before_blows"]["z"] <= 3.0
    assert blows_tail(w)
    # no form error left by the model level, no data-only finding: model form, not an alarm
    assert answer("unexplained", [], w, set(), []).named == "none"


def test_a_line_present_before_the_first_blow_stays_unexplained():
    fit, first = _maps(1.0)         # a steady line: the first pre window holds its share too
    w = gap_where(fit, fit, first, N_FIT)
    assert abs(w["before_blows"]["share"] - 1.0) < 1e-9
    assert not blows_tail(w)
    assert answer("unexplained", [], w, set(), []).named == "unexplained"
    # stored without the first segment's map (older results): not read as a tail
    w_old = gap_where(fit, fit)
    assert "before_blows" not in w_old and not blows_tail(w_old)


def test_a_gap_in_the_decay_windows_is_never_a_tail():
    fit, first = _maps(0.0)
    obs = fit.observed.copy()
    obs[2, 1, 1] += 5e6             # a larger gap in the early window
    fit2 = GapMap((obs - fit.expected) / fit.spread, obs, fit.expected, fit.spread, fit.bands, GAGES)
    w = gap_where(fit2, fit2, first, N_FIT)
    assert w["window"] == "early" and "before_blows" not in w and not blows_tail(w)


def test_the_headline_says_the_gap_is_the_blows_ringing():
    from types import SimpleNamespace

    from ramdaq.analysis.gap.diagnose import Diagnosis
    from ramdaq.analysis.gap.layers import Answer

    fit, first = _maps(0.0)
    d = SimpleNamespace(verdict="unexplained", answer=Answer("none", "model", None, None), model_level=None,
                        unexplained_where=gap_where(fit, fit, first, N_FIT))
    head = Diagnosis.headline.fget(d)
    assert head.startswith("no effect named") and "87.4 Hz" in head and "before the first blow" in head


def _cand(name: str, closed: float, gages: list[int]) -> dict:
    return {"name": name, "dbic": -1e6, "dbic_marginal": None, "closed_held": closed, "closed_fit": closed,
            "location": {"gages": gages, "window": "early"}}


# check seed 150006 (clean modal trial): every candidate closed ~70 % of the rig's form error
CANDS_150006 = [_cand("tiller", 0.709, [8, 4, 1, 11, 3, 12]),
                _cand("split_mode", 0.706, [8, 4, 12, 10, 1, 11]),
                _cand("time_skew", 0.700, [8, 12, 11, 1, 10]),
                _cand("gage_sensitivity", 0.693, [8, 11, 12, 1, 10])]
FORM_150006 = {1, 5, 6, 7, 8, 9, 13, 14, 16}


def test_a_structural_effect_a_sensor_effect_closes_as_much_of_is_the_rigs_form():
    from ramdaq.analysis.gap.layers import model_answer, unspecific

    assert unspecific(CANDS_150006[0], CANDS_150006)
    assert model_answer("tiller", CANDS_150006, None, FORM_150006).named == "none"
    # a tiller that closes 20 % more than any sensor effect is specific: it stands
    own = [_cand("tiller", 0.9, [8, 4, 1])] + CANDS_150006[1:]
    assert not unspecific(own[0], own)
    assert model_answer("tiller", own, None, FORM_150006).named == "tiller"
    # without form error left on the rig the rule does not apply
    assert model_answer("tiller", CANDS_150006, None, set()).named == "tiller"


def test_a_data_finding_naming_unexplained_needs_twice_its_chance_level_after_a_model_none():
    homog = {"check": "homogeneity", "layer": "nonlinearity", "gages": [5, 9, 13, 14], "statistic": 1.4,
             "chance_level": 1.0, "window": "decay", "mode_hz": [7.6], "more": {}, "text": "slope"}
    a = answer("tiller", CANDS_150006, None, FORM_150006, [homog])
    assert a.named == "none"            # 1.4x chance: what a clean modal trial shows
    a = answer("tiller", CANDS_150006, None, FORM_150006, [homog | {"statistic": 2.5}])
    assert a.named == "unexplained" and a.by == "data"
