"""The one answer's model-form rules (issue 17): an unexplained gap that lies in the band of a
mode the calibrated rig still misses, on gages where that mode's shape differs beyond chance, is
that form error ("none": no effect; model form), not a cause."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from ramdaq.analysis.gap.layers import answer, in_form_mode, model_answer
from ramdaq.analysis.gap.rigfit import FormError, ModelLevel

# the clean modal-family trial of issue 17 (check seed 150000): its first rudder mode, 23.44 Hz,
# 1-MAC 0.88 after calibration, differs beyond chance at all 16 gages; the form error's line
# names the worst four (2, 1, 3, 7); the gap lies in the 22.8 Hz band on gages 12, 3, 10
WHERE = {"gages": [12, 3, 10], "band": "22.8 Hz", "band_hz": 22.832, "band_edges_hz": [15.85, 45.49],
         "window": "early", "excess": 1.4e8, "z": 37.0}
ALL16 = list(range(1, 17))


def test_an_unexplained_gap_at_a_mode_the_rig_misses_is_model_form():
    modes = [(23.44, ALL16), (90.57, [6, 12, 7, 2])]
    assert in_form_mode(WHERE, modes)
    a = model_answer("unexplained", [], WHERE, {1, 2, 3, 6, 7, 12}, modes)
    assert a.named == "none" and a.location is None
    # the gages the worst-four line names alone do not hold gage 10: the old rule kept the alarm
    assert model_answer("unexplained", [], WHERE, {1, 2, 3, 6, 7, 12}).named == "unexplained"


def test_a_gap_off_the_misfit_modes_band_or_gages_stays_unexplained():
    # the mode the rig misses is in another band
    assert not in_form_mode(WHERE, [(90.57, ALL16)])
    # in the band, but the gap is on a gage where its shape matches
    assert not in_form_mode(WHERE, [(23.44, [1, 2, 3, 12])])
    # a gap stored without its band's edges is not placed
    assert not in_form_mode({k: v for k, v in WHERE.items() if k != "band_edges_hz"}, [(23.44, ALL16)])
    a = answer("unexplained", [], WHERE, set(), [], [(90.57, ALL16)])
    assert a.named == "unexplained" and a.location["gages"] == [12, 3, 10]


def test_a_named_effect_is_not_set_aside_by_a_form_mode():
    # the band rule reads unexplained gaps only: a library effect the model names stands
    cand = {"name": "hull_coupling", "dbic": -100.0, "closed_held": 0.8, "closed_fit": 0.8,
            "location": {"gages": [12, 3], "window": "early"}}
    a = model_answer("hull_coupling", [cand], None, set(), [(23.44, ALL16)])
    assert a.named == "hull_coupling"


def test_form_modes_list_every_gage_beyond_chance():
    e = FormError(f_id_hz=23.44, df_rel=-0.05, z_f=-52.0, one_minus_mac=0.88, one_minus_mac_rudder=0.78,
                  one_minus_mac_hull=0.02, gages=(2, 1, 3, 7), beyond=(2, 1, 3, 7, 11, 12, 10))
    gone = FormError(f_id_hz=10.8, df_rel=float("nan"), z_f=float("nan"), one_minus_mac=float("nan"),
                     one_minus_mac_rudder=float("nan"), one_minus_mac_hull=float("nan"),
                     gages=(5, 9, 14), missing=True)

    class Fit:          # the fields ModelLevel reads of a ModeFit
        form = (gone, e)

    lvl = ModelLevel(modes=None, fit=Fit())
    assert lvl.form_modes() == [(23.44, [2, 1, 3, 7, 11, 12, 10])]
    assert lvl.form_gages() == {1, 2, 3, 7}       # the line's worst four, as before


def _law(kind: str, stat: float) -> dict:
    from ramdaq.analysis.gap.datamodel import Finding, Layer

    more = (("coulomb_law_z", stat, "1"),) if kind == "coulomb" else (
        (("stiffness_law_z", stat, "1"),) if kind == "stiffness" else (("amplitude_per_doubling", 0.8, "1"),))
    return Finding(check="homogeneity", layer=Layer.NONLINEARITY, gages=(1, 4, 8), statistic=stat,
                   chance_level=4.134, size=0.157, unit="m/s^2 per cycle", text=kind, window="decay",
                   mode_hz=(23.88,), more=more).to_json()


def test_a_told_law_well_above_chance_outranks_a_named_linear_effect():
    # issue 17, modal check seed 157001: Coulomb's law at 84.9 (20.5x its chance level 4.13)
    # while the model named hull_coupling
    cand = {"name": "hull_coupling", "dbic": -100.0, "closed_held": 0.8, "closed_fit": 0.8,
            "location": {"gages": [14, 15], "window": "late"}}
    a = answer("hull_coupling", [cand], None, set(), [_law("coulomb", 84.9)])
    assert a.named == "friction" and a.by == "data" and a.location["gages"] == [1, 4, 8]
    # an amplitude-dependent stiffness is no library effect: unexplained, by the data
    assert answer("hull_coupling", [cand], None, set(), [_law("stiffness", 84.9)]).named == "unexplained"
    # a slope across the blows whose law the decays did not tell, or a law barely past its
    # chance level (1.5x, under PRECEDENCE_STRENGTH), leaves the model's effect standing
    assert answer("hull_coupling", [cand], None, set(), [_law("slope", 84.9)]).named == "hull_coupling"
    assert answer("hull_coupling", [cand], None, set(), [_law("coulomb", 6.2)]).named == "hull_coupling"


def _skew_of_gage_12() -> dict:
    """Modal check seed 157000's phase finding: a 2.8-sample skew of gage 12 at 11.8x chance."""
    from ramdaq.analysis.gap.datamodel import Finding, Layer

    return Finding(check="time_skew", layer=Layer.SENSOR, gages=(12,), statistic=205.1,
                   chance_level=17.34, size=0.00136, unit="s", text="skew", window="decay").to_json()


def _flat_top(gage: int, statistic: float, chance: float, size: float) -> dict:
    """A clipping finding on one gage (flat tops at the peaks)."""
    from ramdaq.analysis.gap.datamodel import Finding, Layer

    return Finding(check="clipping", layer=Layer.SENSOR, gages=(gage,), statistic=statistic,
                   chance_level=chance, size=size, unit="m/s^2", text="flat", window="peaks").to_json()


def test_a_trial_not_homogeneous_sets_the_linear_shape_checks_aside():
    # modal check seed 157000: friction on a 12.7 Hz mode; the phases read a 2.8-sample skew of
    # gage 12 at 11.8x its chance level, the homogeneity check a slope at 11.3x

    skew = _skew_of_gage_12()
    clip = _flat_top(3, 40.0, 3.0, 1.0)
    slope = _law("slope", 46.07)
    a = answer(None, [], None, set(), [skew, slope])
    assert a.named == "unexplained" and a.finding["check"] == "homogeneity"
    # without the nonlinearity the skew answers; a flat top reads the raw values and stays (the
    # stronger against its chance level: 13x against the slope's 11x)
    assert answer(None, [], None, set(), [skew]).named == "time_skew"
    assert answer(None, [], None, set(), [clip, slope]).named == "clipping"


def test_an_unexplained_answer_of_the_data_layer_is_placed_in_words():
    # the data layer's "unexplained" (a homogeneity slope whose law the decays did not tell)
    # carries a finding's place, not a map's: the headline's line must not need the map's keys
    from ramdaq.analysis.gap.verdict import where_text

    a = answer(None, [], None, set(), [_law("slope", 46.07)])
    assert a.named == "unexplained" and a.by == "data"
    assert where_text(a.location) == "gages 1, 4, 8, band 23.9 Hz, late window"
    assert where_text(WHERE).endswith("excess 1.4e+08 noise variances (cell z up to 37.0)")


def test_a_data_layer_answer_closes_its_own_gap_not_the_models():
    # issue 17, modal check seed 151001: a 1.4x gain on gage 2 of a flexible rudder on a rig off
    # by up to 25 %; the model's gage_sensitivity closed 1 % of the model-level gap (the rig's
    # form error), the data check's gain 100 % of the rigid-body misfit on the held-out impact
    from ramdaq.analysis.gap.datamodel import Finding, Layer

    cand = {"name": "gage_sensitivity", "dbic": -30.0, "closed_held": 0.01, "closed_fit": 0.02,
            "location": {"gages": [2], "window": "late"}}
    gain = Finding(check="gain", layer=Layer.SENSOR, gages=(2,), statistic=194.0, chance_level=3.76,
                   size=1.397, unit="ratio", text="gain", closed_held=0.998, closed_held_ci=(0.99, 1.0))
    a = answer("unexplained", [cand], None, set(), [gain.to_json()])
    assert a.named == "gage_sensitivity" and a.by == "data" and a.closed_held == pytest.approx(0.998)
    assert gain.to_json()["closed_held_ci"] == [0.99, 1.0]
    # a finding whose check measures no closure of its own falls back on the model's
    unmeasured = replace(gain, closed_held=float("nan")).to_json()
    assert unmeasured["closed_held"] is None
    assert answer("unexplained", [cand], None, set(), [unmeasured]).closed_held == pytest.approx(0.01)


def test_a_closure_is_the_share_of_the_gap_beyond_the_noise():
    from ramdaq.analysis.gap.datamodel import closure_of, held_out

    one = np.ones(8)
    # a gap of 9 noise variances per unit, all closed but the noise: 1; none closed: 0
    assert closure_of(10 * one, one, one)[0] == pytest.approx(1.0)
    assert closure_of(10 * one, 10 * one, one)[0] == pytest.approx(0.0)
    frac, (lo, hi) = closure_of(10 * one, 5.5 * one, one)
    assert frac == pytest.approx(0.5) and lo == pytest.approx(0.5) and hi == pytest.approx(0.5)
    # nothing beyond the noise: no gap to close
    assert math.isnan(closure_of(one, one, one)[0])
    # the model layer's split: every third impact held out, the last when none is
    assert held_out(6).tolist() == [False, False, True, False, False, True]
    assert held_out(2).tolist() == [False, True] and not held_out(1).any()


def test_a_flat_top_answers_an_unexplained_trial_beside_a_nonlinearity():
    # modal check seed 153001: clipping on gages 4 and 6 (8 against 3.04), the homogeneity
    # check's slope on the hull's gages 9, 13, 14 (25.5 against 4.06), the model unexplained

    clip = _flat_top(6, 8.0, 3.04, 1.7)
    skew = _skew_of_gage_12()
    slope = _law("slope", 25.5)
    a = answer("unexplained", [], None, set(), [clip, slope])
    assert a.named == "clipping" and a.by == "data" and a.location["gages"] == [6]
    # the same when the model's gap is its form ("none"): the slope names no cause, the flat
    # top does; a told law (Coulomb's: friction) still outranks it, the stronger answering
    assert answer(None, [], None, set(), [clip, slope]).named == "clipping"
    assert answer(None, [], None, set(), [clip, _law("coulomb", 25.5)]).named == "friction"
    # a shape check the nonlinearity bends stays set aside: the model's unexplained stands
    assert answer("unexplained", [], None, set(), [skew, slope]).named == "unexplained"


def _finding(check: str, layer: str, gages: tuple[int, ...], stat: float, chance: float,
             mode_hz: tuple[float, ...] = (), closed_held: float = float("nan"),
             window: str = "decay") -> dict:
    """A data-only finding as JSON, the figures of the issue-17 trial it is taken from."""
    from ramdaq.analysis.gap.datamodel import Finding, Layer

    return Finding(check=check, layer=Layer(layer), gages=gages, statistic=stat, chance_level=chance,
                   size=1.0, unit="", text=check, window=window, mode_hz=mode_hz,
                   closed_held=closed_held).to_json()


HULL = {"name": "hull_coupling", "dbic": -3.8e6, "closed_held": 0.65, "closed_fit": 0.65,
        "location": {"gages": [10, 12, 11, 7], "window": "pre"}}


def test_a_line_before_the_blows_is_an_ambient_tone_whatever_the_model_names():
    # modal check seed 155000: an 11.7 Hz line in every pre window, the first
    # included, at 4087 against its chance level 31.2 (131x); the model level named hull_coupling
    tone = _finding("ambient_tone", "excitation", (5, 9, 13, 14), 4087.5, 31.16, (11.733,), window="pre")
    a = answer("hull_coupling", [HULL], None, {1, 2}, [tone])
    assert a.named == "ambient_tone" and a.by == "data" and a.location["gages"] == [5, 9, 13, 14]
    assert a.location["window"] == "pre"
    # check seed 155001: a 5.0 Hz tone at 29x beside a slope across the blows at its frequency (the
    # tone's share does not grow with the blow) and the model "unexplained": the tone answers
    slope = _law("slope", 39.3)
    assert answer("unexplained", [], None, set(), [tone, slope]).named == "ambient_tone"
    # a line the blows switch on (down before the next blow, within the pre window's 1 Hz
    # resolution) is not an ambient one: what the library does not hold; a line barely past its
    # chance level (1.5x, under PRECEDENCE_STRENGTH) does not set the model's answer aside
    switched = _finding("line_persistence", "excitation", (9,), 8.0, 3.5, (12.2,))
    a = answer("hull_coupling", [HULL], None, set(), [tone, switched])
    assert a.named == "unexplained" and a.finding["check"] == "line_persistence"
    weak = _finding("ambient_tone", "excitation", (5,), 46.7, 31.16, (11.733,), window="pre")
    assert answer("hull_coupling", [HULL], None, set(), [weak]).named == "hull_coupling"


def test_a_data_finding_that_closes_held_out_outranks_a_structural_update_on_a_wrong_rig():
    # modal check seed 154001: a 3 Hz high-pass on five gages, each at 93-153x its
    # chance level and closing 94-99.6 % of its residual on the held-out impact; the model level,
    # its rig calibrated with form error left on gages 6, 2, 12, 3, named tiller (79 % closed)
    tiller = {"name": "tiller", "dbic": -7.7e8, "closed_held": 0.79, "closed_fit": 0.79,
              "location": {"gages": [8], "window": "late"}}
    hp = [_finding("highpass", "sensor", (g,), s, 17.34, (7.1,), c)
          for g, s, c in ((5, 1606.0, 0.941), (10, 2650.1, 0.996), (14, 2075.2, 0.982))]
    form = {2, 3, 6, 12}
    a = answer("tiller", [tiller], None, form, hp)
    # at every gage the high-pass was found on, the strongest first
    assert a.named == "highpass" and a.by == "data" and a.location["gages"] == [10, 14, 5]
    # without a form error (the rig reproduces the trial's modes) the model's update stands; so
    # it does when the sensor correction explains under half its residual held out
    assert answer("tiller", [tiller], None, set(), hp).named == "tiller"
    poor = [_finding("highpass", "sensor", (5,), 1606.0, 17.34, (7.1,), 0.3)]
    assert answer("tiller", [tiller], None, form, poor).named == "tiller"
    # a second blow likewise (modal development seed 57001: 18 ms after the first, 916x its
    # chance level, closing 74 % held out, named hull_coupling, 54 % closed, by the model)
    hull = {"name": "hull_coupling", "dbic": -2.1e5, "closed_held": 0.54, "closed_fit": 0.54,
            "location": {"gages": [6, 8], "window": "early"}}
    dh = _finding("double_hit", "excitation", tuple(range(1, 17)), 25473.0, 27.81, (4.35,), 0.736,
                  window="early")
    assert answer("hull_coupling", [hull], None, {4, 6, 9, 10}, [dh]).named == "double_hit"
    # unlike a sensor's, on a rig without form error too: no linear update of the structure
    # puts a second rise of every gage 18 ms after the blow (layers.held_out_data)
    assert answer("hull_coupling", [hull], None, set(), [dh]).named == "double_hit"


def test_a_second_blow_that_explains_no_held_out_blow_is_not_named():
    # modal check seed 160000: a double hit read at 572x chance on a crack trial closed
    # -19 of its own residual on the held-out blow (a bilinear stiffness is no second blow); the
    # double-hit trials' closed 71-84 %
    crack = _finding("double_hit", "excitation", tuple(range(1, 17)), 15893.3, 27.81, (4.04,), -19.4,
                     window="early")
    real = _finding("double_hit", "excitation", tuple(range(1, 17)), 14866.7, 27.81, (6.7,), 0.708,
                    window="early")
    assert answer("unexplained", [], None, set(), [real]).named == "double_hit"
    assert answer("unexplained", [], None, set(), [crack]).named == "unexplained"
    # not named double_hit where the model found no gap either: read as what it measures, an
    # early response that is not one linear response scaled by the blow (layers.early_nonlinear)
    a = answer(None, [], None, set(), [crack])
    assert a.named == "unexplained" and a.finding["check"] == "early_nonlinear"


def test_a_models_gage_fault_on_a_body_the_data_find_flexible_and_sound_is_model_form():
    # modal check seed 150005, a clean trial on a rig off by up to 25 %: the model level named
    # gage_sensitivity on gages 6, 3 (57 % closed); the data layer's rigid-body check found both
    # bodies' gages flexible and no gage at fault
    cand = {"name": "gage_sensitivity", "dbic": -2.6e6, "closed_held": 0.57, "closed_fit": 0.57,
            "location": {"gages": [6, 3, 1], "window": "early", "effect_gages": [6, 3]}}
    rudder = _finding("flex", "model form", (1, 2, 3, 4, 6, 8), 56.9, 3.77)
    hull = _finding("flex", "model form", (5, 9, 13, 14, 15, 16), 13.0, 3.77)
    form = {2, 3, 5, 6, 7, 9, 13, 14}
    a = answer("gage_sensitivity", [cand], None, form, [rudder, hull])
    assert a.named == "none" and a.by == "model"
    # the data's own gain on a blamed gage confirms the model; a rig reproducing the trial's
    # modes (no form error), or a body the check did not find flexible, leaves the model's answer
    gain = _finding("gain", "sensor", (6,), 40.0, 3.77, (), 0.99)
    assert answer("gage_sensitivity", [cand], None, form, [rudder, gain]).named == "gage_sensitivity"
    assert answer("gage_sensitivity", [cand], None, set(), [rudder, hull]).named == "gage_sensitivity"
    assert answer("gage_sensitivity", [cand], None, form, [hull]).named == "gage_sensitivity"


def test_a_frequency_moving_with_the_amplitude_answers_before_a_split_mode():
    # issue 17, modal dev seed 61000: a crack on a 62.6 Hz mode (its frequency 2.6 % lower early
    # in the bigger blows, 10x chance) beside a pair of 13.6 Hz poles of one shape
    split = {"f_lo_hz": 13.56, "f_hi_hz": 13.61, "mac": 0.99, "gages": [6, 8, 12]}
    stiff = _law("stiffness", 43.0)
    a = answer("unexplained", [], None, set(), [stiff], (), [split])
    assert a.named == "unexplained" and a.by == "data" and a.location["gages"] == [1, 4, 8]
    # Coulomb's law keeps the frequency: it says nothing against two linear poles; nor does a
    # stiffness law under PRECEDENCE_STRENGTH (1.5x its chance level)
    assert answer("unexplained", [], None, set(), [_law("stiffness", 6.2)], (), [split]).named == "split_mode"
    # on the model's high-pass with a stiffness law beside it, the law answers (the high-pass
    # reads the linear model's phases, which the nonlinearity bends)
    hp = {"name": "highpass", "dbic": -40.0, "closed_held": 0.08, "closed_fit": 0.1,
          "location": {"gages": [13], "window": "late"}}
    assert answer("highpass", [hp], None, set(), [stiff]).named == "unexplained"


def test_a_data_finding_barely_past_chance_does_not_overturn_the_models_form():
    # modal development seed 64002 (a resonance on gage 6): the model level's gap lay in the
    # rig's form error on gages 1, 2, 3, 6, 7, 10, 11, 12; gage 14's gain read 6.72 against its
    # chance level 3.77 (1.8x) and answered gage_sensitivity. Under PRECEDENCE_STRENGTH (2x) it
    # does not set the model's "none" aside; at 2.7x it does.
    form = {1, 2, 3, 6, 7, 10, 11, 12}
    weak = _finding("gain", "sensor", (14,), 6.723, 3.765, (7.349, 86.338), 1.0)
    strong = _finding("gain", "sensor", (14,), 10.0, 3.765, (7.349, 86.338), 1.0)
    for model in ("unexplained", None):
        assert answer(model, [], None, form, [weak]).named == "none"
        a = answer(model, [], None, form, [strong])
        assert a.named == "gage_sensitivity" and a.by == "data" and a.location["gages"] == [14]
    # a clean development trial (seed 1019): a line before the blows at 1.1x its chance level
    tone = _finding("ambient_tone", "excitation", (7,), 34.3, 31.16, (11.7,), window="pre")
    assert answer(None, [], None, set(), [tone]).named == "none"


def test_a_mode_dependent_gain_the_alignment_does_not_close_held_out_is_the_bodys_form():
    # modal development seed 51003, a clean trial on a rig off by up to 25 %: the model level's
    # gap (24.4 Hz, gage 1) lay in a mode the calibrated rig misses; the data layer found the
    # rudder flexible (85x) and gage 13's gain differing from mode to mode (22.9x, named
    # gage_alignment), while the model's gage_alignment closed 9 % of the held-out gap
    where = {"gages": [1], "band": "24.4 Hz", "band_hz": 24.402, "band_edges_hz": [15.44, 47.06],
             "window": "early", "excess": 1.4e7, "z": 37.05}
    modes = [(24.399, ALL16), (90.709, ALL16)]
    form = {2, 3, 4, 7, 8}
    hz = (6.991, 9.863, 24.399, 90.71)
    flex = _finding("flex", "model form", (1, 2, 3, 4, 6, 8), 318.409, 3.765, hz)
    tilt = _finding("rigid_body", "model form", (13,), 316.157, 13.816, hz)
    align = {"name": "gage_alignment", "dbic": -3.5e5, "closed_held": 0.0903, "closed_fit": 0.0824,
             "location": {"gages": [4], "window": "early", "effect_gages": [1]}}
    a = answer("unexplained", [align], where, form, [flex, tilt], modes)
    assert a.named == "none" and a.by == "model"
    # the same finding where the alignment, fitted on the other blows, explains the held-out one
    # (development seed 9003: gage 6 at 200x, the model's gage_alignment closing 100 %) answers
    held = align | {"closed_held": 0.998, "closed_fit": 0.999}
    a = answer("unexplained", [held], where, form, [flex, tilt], modes)
    assert a.named == "gage_alignment" and a.by == "data" and a.location["gages"] == [13]
    # seed 9003 itself: the model named gage_alignment on gage 6, the rig's only form-error gage
    own = {"name": "gage_alignment", "dbic": -1.1e5, "closed_held": 1.0, "closed_fit": 1.0,
           "location": {"gages": [6], "window": "pre", "effect_gages": [6]}}
    six = _finding("rigid_body", "model form", (6,), 3254.474, 16.266, (7.928, 24.44, 87.333, 265.358))
    a = answer("gage_alignment", [own], None, {6}, [six], [(87.333, [6])])
    assert a.named == "gage_alignment" and a.location["gages"] == [6]
