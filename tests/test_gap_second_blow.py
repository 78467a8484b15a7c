"""A second blow of the ram against the rules that read an amplitude-dependent structure
(issue 17): the data layer's double-hit check and the effect search fit one second blow two
ways; either one explaining the held-out blows makes it a second blow, not a crack. A slope of
the ringing against the blow's size whose law the decays did not tell is what a second pulse
makes of each blow's size; a law told within the decays stands."""

from __future__ import annotations

from ramdaq.analysis.gap.layers import answer, not_homogeneous

ALL16 = list(range(1, 17))


def _double_hit(stat: float, closed_held: float) -> dict:
    return {"check": "double_hit", "layer": "excitation", "gages": ALL16, "window": "early",
            "mode_hz": [7.9], "statistic": stat, "chance_level": 27.8, "closed_held": closed_held,
            "more": {"delay_s": 0.03, "blows": 4, "contact_s": 0.005}}


def _candidate(name: str, closed_held: float) -> dict:
    return {"name": name, "dbic": -1e6, "dbic_marginal": None, "closed_held": closed_held,
            "closed_fit": closed_held, "location": {"gages": [1, 2], "band": "7.9 Hz", "band_hz": 7.9,
                                                      "window": "early", "effect_gages": [],
                                                      "effect_mode_hz": None}}


def _slope(stat: float, told: str | None = None) -> dict:
    more = {"slope_z": 3.0} | ({told: 9.0} if told else {})
    return {"check": "homogeneity", "layer": "nonlinearity", "gages": ALL16[:14], "window": "decay",
            "mode_hz": [7.93], "statistic": stat, "chance_level": 4.0, "closed_held": None, "more": more}


def test_a_second_blow_the_effect_search_explains_held_out_is_a_double_hit():
    # truth development seed 1003: the data fit closed -0.43 held out, the search's 0.92
    f = _double_hit(14306.0, -0.43)
    cands = [_candidate("double_hit+gage_alignment", 1.0), _candidate("double_hit", 0.92)]
    a = answer(None, cands, None, set(), [f])
    assert a.named == "double_hit" and a.by == "data" and a.closed_held == 1.0
    # neither fit explains the held-out blows (a crack's early response): not a second blow
    a = answer(None, [_candidate("double_hit", -0.1), _candidate("tiller", 0.6)], None, set(), [f])
    assert a.named == "unexplained"


def test_a_slope_beside_a_held_out_second_blow_does_not_make_the_trial_nonlinear():
    # benchmark truth 512000's pattern: a second blow at 438x its chance level closing 0.95 held
    # out, an amplitude slope at 3.8x with no law told
    dh, slope = _double_hit(12182.0, 0.95), _slope(15.4)
    assert not not_homogeneous([dh, slope])
    a = answer("unexplained", [_candidate("double_hit", 0.95)], {"gages": [1], "window": "late"},
               set(), [dh, slope])
    assert a.named == "double_hit"
    # without a second blow that closes, the slope makes the trial nonlinear, as before
    assert not_homogeneous([_double_hit(12182.0, 0.2), slope])
    # a law told within the decays (Coulomb's) stands beside any second blow
    assert not_homogeneous([dh, _slope(15.4, "coulomb_law_z")])


def test_a_held_out_second_blow_outranks_a_structural_update_on_a_rig_without_form_error():
    """The model names hull_coupling on a rig left with no form error, and never weighed a
    second blow; the data layer reads one at 921x its chance level whose own correction closes
    81 % held out: a second blow (no linear update of the structure puts a second rise of every
    gage 32 ms after the blow). One closing 30 % does not outrank the update."""
    cands = [_candidate("hull_coupling+gage_alignment", 0.8), _candidate("hull_coupling", 0.62)]
    a = answer("hull_coupling+gage_alignment", cands, None, set(), [_double_hit(25600.0, 0.81)])
    assert a.named == "double_hit" and a.by == "data"
    a = answer("hull_coupling+gage_alignment", cands, None, set(), [_double_hit(25600.0, 0.3)])
    assert a.named == "hull_coupling+gage_alignment"
