"""The homogeneity check tells the law behind an amplitude slope across the blows (issue 17: a
modal friction trial read "amplitude grows as the blow to the power 1.56" and came out
"unexplained"), and does not judge a mode on which a line rings before the blows (an ambient-tone
trial read "decrement changes by +36 % per doubling of the blow" at its line)."""

from __future__ import annotations

import numpy as np
import scipy.stats

from ramdaq.analysis.gap.datamodel import P_CHANCE, FreeModal
from ramdaq.analysis.gap.homogeneity import COULOMB_MIN, DecayLaw, coulomb_behind, off_lines
from ramdaq.analysis.gap.layers import data_effect, is_friction

LEVEL = float(scipy.stats.norm.isf(P_CHANCE))
"""The one-sided chance level the law's z is held to (one test: the slope chose the mode)."""


def _law(f_hz: float, z: float, size: float) -> DecayLaw:
    return DecayLaw(f_hz, 6, 14, -2.3, -0.008, z, 0.0275, size)


def test_an_amplitude_growing_faster_than_the_blow_with_coulombs_decays_is_friction():
    best = (26.3, "amplitude", 13.06, 0.56, 3)              # modal check 157000's slope
    w = coulomb_behind(best, [_law(63.7, 9.0, 2.0), _law(12.72, LEVEL + 1.0, 1.9)])
    assert w is not None and w.mode_hz == 12.72             # the slope's own mode, not another's


def test_the_law_must_fit_on_every_count():
    best = (26.3, "amplitude", 13.06, 0.56, 3)
    assert coulomb_behind(best, [_law(12.72, LEVEL - 0.5, 1.9)]) is None       # z within chance
    assert coulomb_behind(best, [_law(12.72, LEVEL + 1, 0.5 * COULOMB_MIN)]) is None   # too small
    assert coulomb_behind(best, [_law(15.0, LEVEL + 1, 1.9)]) is None          # another mode
    # friction takes a larger share of small blows: an exponent below 1 is not its law
    assert coulomb_behind((26.3, "amplitude", 13.06, -0.3, 3), [_law(12.72, LEVEL + 1, 1.9)]) is None
    assert coulomb_behind((26.3, "decrement", 13.06, 0.56, 3), [_law(12.72, LEVEL + 1, 1.9)]) is None


def test_the_friction_finding_names_friction():
    from ramdaq.analysis.gap.homogeneity import _coulomb_slope_finding

    fm = _fm([12.7, 13.06])
    snr = np.array([[50.0, 60.0], [10.0, 5.0]])
    f = _coulomb_slope_finding(fm, (26.3, "amplitude", 13.06, 0.56, 1), _law(12.72, 4.1, 1.9), snr,
                               (4, 6), 4.1, "null")
    assert is_friction(f.to_json()) and data_effect(f.to_json()) == "friction" and f.gages == (4,)


def _fm(f_hz: list[float]) -> FreeModal:
    k = len(f_hz)
    return FreeModal(f_hz=np.array(f_hz), delta=np.full(k, 0.05), f_se_hz=np.zeros(k), delta_se=np.zeros(k),
                     amp=np.ones((4, 2, k), complex), amp_se=np.full((4, 2, k), 0.01),
                     noise=np.full((4, 2), 1e-3), t0_s=np.array([1.25, 4.25, 7.25, 10.25]), n_s=2048,
                     fs_hz=1024.0, steady=np.zeros(k, bool))


def test_a_mode_on_a_line_before_the_blows_is_not_judged():
    fm = _fm([5.02, 7.2, 6.1])
    kept = off_lines(fm, np.arange(3), [4.99])
    assert kept.tolist() == [1, 2]                           # 6.1 Hz is 1.1 Hz off the line (LINE_HZ 1 Hz)
    assert off_lines(fm, np.arange(3), []).tolist() == [0, 1, 2]


def test_coulombs_slope_with_a_moving_frequency_is_not_friction():
    """Modal check seed 160000: a crack's 112 Hz mode read Coulomb's slope just past chance with
    its frequency +1.3 % over the decays; Coulomb friction keeps the frequency."""
    from ramdaq.analysis.gap.homogeneity import STIFF_MIN, _law_finding

    fm = _fm([112.2, 60.0])
    snr = np.array([[50.0, 60.0], [40.0, 5.0]])
    moving = DecayLaw(112.23, 6, 40, 2.0, 1.3 * STIFF_MIN, 4.2, 0.204, 6.5)
    f = _law_finding(fm, [moving], snr, (6, 8), 4.1, "null").to_json()
    assert not is_friction(f) and data_effect(f) == "unexplained" and set(f["gages"]) == {6, 8}
    kept = DecayLaw(112.23, 6, 40, 2.0, 0.3 * STIFF_MIN, 4.2, 0.204, 6.5)
    assert is_friction(_law_finding(fm, [kept], snr, (6, 8), 4.1, "null").to_json())
    # a slope well above chance (modal check seed 157002: 9.4 against 3.8) is not contradicted by
    # a frequency move within chance, and is by one beyond it
    strong = DecayLaw(112.23, 6, 40, -2.3, -1.6 * STIFF_MIN, 9.4, 0.204, 1.6)
    assert is_friction(_law_finding(fm, [strong], snr, (6, 8), 4.1, "null").to_json())
    beyond = DecayLaw(112.23, 6, 40, -5.0, -1.6 * STIFF_MIN, 9.4, 0.204, 1.6)
    assert not is_friction(_law_finding(fm, [beyond], snr, (6, 8), 4.1, "null").to_json())


def test_a_friction_the_decays_contradict_is_unexplained():
    """The model's friction on a trial whose decays tell a law that is not Coulomb's (the
    frequency moves with the amplitude) answers "unexplained" at the decays' mode and gages."""
    from ramdaq.analysis.gap.layers import answer

    moving = {"check": "homogeneity", "layer": "nonlinearity", "gages": [3, 6], "window": "decay",
              "statistic": 4.2, "chance_level": 4.1, "mode_hz": [112.2], "closed_held": None,
              "more": {"coulomb_law_z": {"value": 4.2}, "stiffness_law_z": {"value": 2.0}}}
    cand = [{"name": "friction", "closed_held": 0.6, "location": {"gages": [3, 6], "window": "late"}}]
    out = answer("friction", cand, None, set(), [moving])
    assert out.named == "unexplained" and out.by == "data" and out.location["gages"] == [3, 6]
    coulomb = moving | {"more": {"coulomb_law_z": {"value": 4.2}}}
    assert answer("friction", cand, None, set(), [coulomb]).named == "friction"
