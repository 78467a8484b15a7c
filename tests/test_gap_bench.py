"""The gap benchmark's pipeline on a small fixed subset of its development scenarios: the richer
simulator's trial, written to MCAP by the recorder, diagnosed from the file and the nominal rig.
A regression guard for the whole chain (the benchmark's figures come from its own seeds, run by
``ramdaq gap benchmark``): each scenario here is one the development run identified."""

from __future__ import annotations

import numpy as np
import pytest

from ramdaq.daq.commands.gap_bench import _located, scenarios, score

SUBSET = [("none", 1001), ("hull_coupling", 2001), ("tiller", 5001), ("gage_alignment", 9005),
          ("time_skew", 11005)]


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    from ramdaq.daq.commands.gap_bench import run_one

    pick = {(s["effect"], s["seed"]): s for s in scenarios(6, "dev")}
    out = tmp_path_factory.mktemp("gap_bench")
    return [run_one(pick[key], str(out)) for key in SUBSET]


def test_subset_is_diagnosed(results):
    for r in results:
        assert "error" not in r, r.get("error")
        assert r["n_impacts_found"] == r["n_impacts_true"]
        if r["effect"] == "none":
            assert r["verdict"] == "no gap beyond noise"
            continue
        assert r["named"] == r["effect"], (r["effect"], r["named"], r["candidates"][:3])
        loc = _located(r, r["location"])
        assert all(loc.values()), (r["location"], r["truth"])
        assert r["closed_held"] > 0.7


def test_score_counts_the_subset(results):
    thr = {e: 0.0 for e, _ in SUBSET}
    s = score(results, thr, 5.0, 10.0, 0.0)
    assert s["top1"] == 1.0 and s["false_alarms"] == 0.0 and s["n_above"] == 4
    assert s["confusion"]["time_skew"]["time_skew"] == 1


def test_located_judges_a_mode_only_within_the_compared_band():
    edges = [0.0, 5.0, 30.0, 120.0]
    r = {"truth": {"gages": [3], "mode_hz": 25.0, "window": "late"}, "band_edges_hz": edges}
    here = {"gages": [3, 4], "band_hz": 26.0, "effect_mode_hz": None, "window": "late"}
    assert _located(r, here) == {"gages": True, "mode": True, "window": True}
    assert _located(r, here | {"band_hz": 80.0, "gages": [5], "window": "early"}) == {
        "gages": False, "mode": False, "window": False}
    # a stiff steering gear's mode above the band's top edge: its mode is not judged
    r["truth"]["mode_hz"] = 215.5
    assert _located(r, here | {"band_hz": 80.0}) == {"gages": True, "window": True}
    # nor counted in the benchmark's mode localisation
    res = [r | {"effect": "tiller", "size": 1.0, "seconds": 1.0, "signatures": ["tiller"], "zdetect": 20.0,
                "candidates": [{"name": "tiller", "dbic": -50.0, "closed_held": 0.9,
                                "location": here | {"band_hz": 80.0}}]}]
    s = score(res, {"tiller": 0.5}, 5.0, 10.0, 0.0)
    assert s["top1"] == 1.0 and s["localisation"]["gages"] == 1.0 and np.isnan(s["localisation"]["mode"])


def test_pod_threshold_recovers_a_known_pod_curve():
    """The hit/miss a90 of trials drawn from a known logistic POD curve, within four of its
    asymptotic standard errors (from the Fisher information at the true curve; a false failure
    once in ~16 000 seeds)."""
    from ramdaq.daq.commands.gap_bench import pod_threshold

    b0, b1 = 2.0, 3.0
    a = np.geomspace(0.01, 10.0, 2000)
    x = np.log(a)
    p = 1 / (1 + np.exp(-(b0 + b1 * x)))
    hits = np.random.default_rng(7).random(a.size) < p
    logit90 = np.log(0.9 / 0.1)
    true = (logit90 - b0) / b1
    w = p * (1 - p)
    info = np.array([[w.sum(), (w * x).sum()], [(w * x).sum(), (w * x * x).sum()]])
    g = np.array([-1 / b1, -(logit90 - b0) / b1**2])
    se = float(np.sqrt(g @ np.linalg.solve(info, g)))
    assert abs(np.log(pod_threshold(a, hits, 0.9)) - true) < 4 * se


def test_pod_threshold_edge_cases():
    from ramdaq.daq.commands.gap_bench import pod_threshold

    a = np.array([0.1, 0.2, 0.5, 1.0, 2.0])
    # complete separation: the step lies between the largest miss and the smallest hit
    assert pod_threshold(a, np.array([0, 0, 1, 1, 1], bool)) == 0.5
    # every trial a hit: not resolved below the smallest size tried
    assert pod_threshold(a, np.ones(5, bool)) == 0.1
    assert pod_threshold(a, np.zeros(5, bool)) == np.inf
    # detection falling with size, or never reaching 90 % within the sizes tried
    assert pod_threshold(a, np.array([1, 1, 0, 1, 0], bool)) == np.inf
    # hits at the smallest and the largest size only (highpass on the 4-blow development seeds
    # at z 3): the fitted slope is near zero and the 90 % point far past every size (it
    # overflowed math.exp)
    six = 0.05 * 40 ** (np.arange(6) / 5)
    assert pod_threshold(six, np.array([1, 0, 0, 0, 0, 1], bool)) == np.inf


def test_false_alarm_bound_is_clopper_pearson():
    from ramdaq.daq.commands.gap_bench import N_NONE_DEV, false_alarm_bound

    # with no alarms the one-sided bound has the closed form 1 - (1 - c)^(1/n) ("rule of three")
    for n in (20, 40, 59, 60):
        assert false_alarm_bound(0, n) == pytest.approx(1 - 0.05 ** (1 / n), rel=1e-9)
    assert false_alarm_bound(0, N_NONE_DEV) <= 0.05 < false_alarm_bound(0, 58)
    assert false_alarm_bound(2, 40) > 0.05 and false_alarm_bound(3, 3) == 1.0


def test_seed_sets_never_share_a_trial():
    """Every named seed set at the largest size allowed: no seed twice, so thresholds tuned on
    ``dev`` never see a trial of ``benchmark`` or ``holdout``."""
    from ramdaq.daq.commands.gap_bench import SEED_SETS

    seeds = [sc["seed"] for name in SEED_SETS for sc in scenarios(100, name)]
    assert len(seeds) == len(set(seeds))
    with pytest.raises(ValueError, match="seed set 'bench'"):
        scenarios(6, "bench")
    with pytest.raises(ValueError, match="--per-class 101"):
        scenarios(101, "holdout")


def test_benchmark_command_takes_one_seed_set(tmp_path, capsys):
    from ramdaq.daq.commands.cli import main

    with pytest.raises(SystemExit, match="one of --dev, --check, --seeds"):
        main(["gap", "benchmark", "--dev", "--seeds", "holdout", "--out", str(tmp_path)])
    # a re-score of results that were never stored names the file it looked for
    assert main(["gap", "benchmark", "--seeds", "holdout", "--rescore", "--out", str(tmp_path)]) == 1
    # (the default run: both families, rigs perturbed by 25 %)
    assert "holdout_perturb0.25_all_results.json: no stored results" in capsys.readouterr().err


def test_perturbed_rig_is_seeded_and_within_its_fraction():
    from ramdaq.analysis.gap.rigfit import get_value
    from ramdaq.analysis.model.rig import load_rig
    from ramdaq.daq.commands.gap_bench import PERTURBED, perturbed_rig

    rig = load_rig("albacore")
    a, b = perturbed_rig(rig, 0.25, 7), perturbed_rig(rig, 0.25, 7)
    names = list(PERTURBED) + ["hull.modes[0].frequency_hz", "hull.modes[0].modal_mass_kg"]
    f = np.array([get_value(a, n) / get_value(rig, n) for n in names])
    assert np.all(np.abs(f - 1) <= 0.25) and np.any(np.abs(f - 1) > 0.1)
    assert [get_value(b, n) for n in names] == [get_value(a, n) for n in names]
    assert get_value(perturbed_rig(rig, 0.25, 8), "stock.I_m4") != get_value(a, "stock.I_m4")
    with pytest.raises(ValueError, match="--perturb 1.5"):
        scenarios(1, "check", perturb=1.5)


def test_no_effect_with_a_perturbed_rig_scores_as_no_effect(tmp_path):
    """A no-effect trial handed a rig 25 % off: calibrated to the modes first, it must come out
    "no effect; model form: ...", which the score counts as correct, not as a false alarm."""
    from ramdaq.daq.commands.gap_bench import run_one

    sc = next(s for s in scenarios(1, "check", ("none",), perturb=0.25))
    r = run_one(sc, str(tmp_path))
    assert "error" not in r, r.get("error")
    assert r["headline"].startswith("no effect; model form: "), r["headline"]
    s = score([r], {}, 8.0, 10.0, 0.0)
    assert s["false_alarms"] == 0.0
    assert s["perturbed_none"]["no_effect"] == 1 and s["perturbed_none"]["n"] == 1


def test_an_effect_only_where_the_model_form_misses_is_not_named():
    """Scoring follows ramdaq gap: with a perturbed rig whose calibration to the modes still
    misses gage 6, an effect acting at gage 6 alone is not told from that form error."""
    from ramdaq.daq.commands.gap_bench import _decide

    cand = {"name": "gage_alignment", "dbic": -100.0, "dbic_marginal": None, "closed_held": 0.9,
            "closed_fit": 0.9, "location": {"gages": [6]}}
    r = {"candidates": [cand], "zdetect": 20.0, "perturb": 0.25, "min_closure": 0.5}
    assert _decide(r | {"form_gages": []}, 8.0, 10.0, 0.0) == "gage_alignment"
    assert _decide(r | {"form_gages": [6, 13]}, 8.0, 10.0, 0.0) == "none"
    assert _decide(r | {"form_gages": [13]}, 8.0, 10.0, 0.0) == "gage_alignment"
    # and an effect closing less than the raised floor is not named either
    low = r | {"candidates": [cand | {"closed_held": 0.3}], "form_gages": [13]}
    assert _decide(low, 8.0, 10.0, 0.0) == "none"


def test_a_gap_the_best_library_effect_barely_closes_is_unexplained():
    """Issue 17: a significant gap whose best library effect closes less than half of it on the
    held-out impacts is "unexplained" -- never the nearest library effect."""
    from ramdaq.analysis.gap.verdict import UNEXPLAINED_CLOSURE, choose

    cand = {"name": "gage_sensitivity", "dbic": -500.0, "dbic_marginal": None, "closed_fit": 0.6}
    assert choose([cand | {"closed_held": 0.9}], True, 10.0, 0.0) == "gage_sensitivity"
    assert choose([cand | {"closed_held": UNEXPLAINED_CLOSURE - 0.1}], True, 10.0, 0.0) == "unexplained"
    assert choose([cand | {"closed_held": 0.2}], False, 10.0, 0.0) is None


def test_gap_where_names_the_gages_band_window_and_size():
    from ramdaq.analysis.gap.evidence import GapMap, bands_for
    from ramdaq.analysis.gap.verdict import gap_where, where_text

    bands = bands_for(np.array([13.0, 45.0]), 100.0)
    shape = (4, 3, 3)
    exp = np.ones(shape)
    obs = exp.copy()
    obs[2, 1, 1] = 50.0        # gage 7, the 13 Hz band, early window
    obs[3, 1, 1] = 30.0        # gage 9 the same, 0.6 of it
    obs[0, 2, 2] = 5.0         # gage 1, a little elsewhere
    z = (obs - exp) / 0.5
    m = GapMap(z, obs, exp, np.full(shape, 0.5), bands, (1, 3, 7, 9))
    w = gap_where(m, m)
    assert w["gages"] == [7, 9] and w["band"] == "13.0 Hz" and w["window"] == "early"
    assert w["excess"] == pytest.approx(49 + 29 + 4) and w["z"] == pytest.approx(98.0)
    assert "gages 7, 9" in where_text(w)


def _rec(**kw) -> dict:
    base = {"family": "modal", "effect": "crack", "expect": "unexplained", "size": 1.0, "seconds": 1.0,
            "zdetect": 30.0, "perturb": 0.25, "min_closure": 0.0, "signatures": ["friction"],
            "candidates": [{"name": "friction", "dbic": -200.0, "dbic_marginal": None, "closed_held": 0.3,
                            "closed_fit": 0.4, "location": {"gages": [1], "window": "late"}}],
            "truth": {"gages": [1, 3], "mode_hz": 13.0, "window": "early"},
            "band_edges_hz": [0.0, 8.0, 30.0, 100.0], "form_gages": [12],
            "unexplained_where": {"gages": [3], "band": "13.0 Hz", "band_hz": 13.0, "window": "early",
                                  "excess": 1e4, "z": 30.0}, "data_findings": []}
    return base | kw


def test_an_outside_effect_scores_as_unexplained_in_its_own_class():
    from ramdaq.daq.commands.gap_bench import decision

    # the model's map alone, on a rig that still misses modes (gage 12), is the rig's form;
    # with no form error left it stands, where the gap is
    assert decision(_rec(), 8.0, 10.0, 0.0)["named"] == "none"
    d = decision(_rec(form_gages=[]), 8.0, 10.0, 0.0)
    assert d["named"] == "unexplained" and d["location"]["gages"] == [3]
    # a data-only failure of time invariance well above chance answers, at its own gages
    drift = {"check": "gain_invariance", "layer": "sensor", "gages": [3], "window": "decay",
             "mode_hz": [13.0], "statistic": 80.0, "chance_level": 20.0, "more": {}, "text": "drift"}
    r = _rec(data_findings=[drift])
    d = decision(r, 8.0, 10.0, 0.0)
    assert d["named"] == "unexplained" and d["by"] == "data" and d["location"]["gages"] == [3]
    # unexplained only where the calibrated rig still misses its modes is the model's form
    assert decision(_rec(form_gages=[3, 12]), 8.0, 10.0, 0.0)["named"] == "none"
    s = score([r, _rec(effect="none", expect="none", size=0.0, zdetect=2.0)], {}, 8.0, 10.0, 0.0)
    lay = s["by_family"]["modal"]["layers"]
    assert lay["unexplained"]["n"] == 1 and lay["unexplained"]["top1"] == 1.0
    assert lay["unexplained"]["gages"] == 1.0
    assert lay["model form"]["top1"] == 1.0 and s["by_family"]["modal"]["false_alarms"] == 0.0


def test_a_data_only_finding_answers_when_the_model_names_nothing():
    """Both layers in one report: the model sees no gap beyond noise, the data-only layer finds
    a high-pass on gages 2 and 5 (issue 17: missed as "no gap"); a homogeneity finding in the
    frequency is an amplitude-dependent stiffness the library does not hold."""
    from ramdaq.daq.commands.gap_bench import decision

    hp = {"check": "highpass", "gages": [2, 5], "window": "decay", "mode_hz": [13.0], "statistic": 40.0,
          "chance_level": 5.0, "more": {}}
    r = _rec(effect="highpass", expect="highpass", zdetect=2.0, data_findings=[hp])
    d = decision(r, 8.0, 10.0, 0.0)
    assert d["named"] == "highpass" and d["by"] == "data" and d["location"]["gages"] == [2, 5]
    hom = hp | {"check": "homogeneity", "gages": [1], "more": {"frequency_per_doubling": {"value": -0.02}}}
    assert decision(_rec(zdetect=2.0, data_findings=[hom]), 8.0, 10.0, 0.0)["named"] == "unexplained"
    # a decrement moving with the blow whose law the decays did not tell: not named friction
    dec = hom | {"more": {"decrement_per_doubling": {"value": -0.3}}}
    assert decision(_rec(zdetect=2.0, data_findings=[dec]), 8.0, 10.0, 0.0)["named"] == "unexplained"
    fr = hom | {"more": {"coulomb_law_z": {"value": 60.0}, "frequency_change": {"value": 0.001}}}
    assert decision(_rec(zdetect=2.0, data_findings=[fr]), 8.0, 10.0, 0.0)["named"] == "friction"


def test_a_strong_data_sensor_finding_outranks_the_models_unexplained():
    """Issue 17: on the modal family's high-pass trial the data-only layer found the high-pass
    on gages 2, 8, 10, 14 (statistics 5-14x chance) and the model layer's "unexplained" was
    kept. A sensor finding at >= 2x its chance level now answers; one barely past chance, or one
    on a trial the data layer finds not homogeneous across blows, does not."""
    from ramdaq.daq.commands.gap_bench import decision

    hp = {"check": "highpass", "layer": "sensor", "gages": [14], "window": "decay", "mode_hz": [13.0],
          "statistic": 239.0, "chance_level": 17.3, "more": {}}
    r = _rec(effect="highpass", expect="highpass", candidates=[], data_findings=[hp])
    d = decision(r, 8.0, 10.0, 0.0)
    assert d["named"] == "highpass" and d["by"] == "data" and d["location"]["gages"] == [14]
    weak = hp | {"statistic": 20.0}
    # (the model's map kept: no form error left; with one, the rig's form -- either way not the sensor)
    kept = _rec(candidates=[], data_findings=[weak], form_gages=[])
    assert decision(kept, 8.0, 10.0, 0.0)["named"] == "unexplained"
    assert decision(_rec(candidates=[], data_findings=[weak]), 8.0, 10.0, 0.0)["named"] == "none"
    hom = {"check": "homogeneity", "layer": "nonlinearity", "gages": [1], "window": "decay",
           "mode_hz": [13.0], "statistic": 46.0, "chance_level": 4.0,
           "more": {"decrement_per_doubling": {"value": -0.3}}}
    assert decision(_rec(candidates=[], data_findings=[hp, hom]), 8.0, 10.0, 0.0)["named"] == "unexplained"


def test_a_double_hit_answers_unexplained_unless_the_trial_is_not_homogeneous():
    """Issue 17: the modal family's double hits came out "unexplained" while the data-only check
    found them at 10-600x chance. A double hit well above chance answers now; on a trial the
    data layer finds not homogeneous across blows it does not (friction, a crack or a rattle
    bend the one-blow decay the check fits: the modal family's development trials read them as
    second blows at 50-140 % of the first), and the homogeneity finding does not answer either
    (friction, a crack and a rattle all move the decrement with the blow)."""
    from ramdaq.daq.commands.gap_bench import decision

    dh = {"check": "double_hit", "layer": "excitation", "gages": list(range(1, 17)), "window": "early",
          "mode_hz": [13.0], "statistic": 1.8e4, "chance_level": 29.1, "more": {}}
    d = decision(_rec(effect="double_hit", expect="double_hit", data_findings=[dh]), 8.0, 10.0, 0.0)
    assert d["named"] == "double_hit" and d["by"] == "data" and d["location"]["window"] == "early"
    hom = {"check": "homogeneity", "layer": "nonlinearity", "gages": [2, 3], "window": "decay",
           "mode_hz": [13.0], "statistic": 46.0, "chance_level": 4.0,
           "more": {"decrement_per_doubling": {"value": -0.5}}}
    assert decision(_rec(data_findings=[dh, hom]), 8.0, 10.0, 0.0)["named"] == "unexplained"
    # a homogeneity slope barely past its chance level does not set a strong double hit aside
    marginal = hom | {"statistic": 4.3}
    assert decision(_rec(data_findings=[dh, marginal]), 8.0, 10.0, 0.0)["named"] == "double_hit"
    # with no gap the model names, the homogeneity finding answers, not the double hit
    assert decision(_rec(zdetect=2.0, data_findings=[dh, hom]), 8.0, 10.0, 0.0)["named"] == "unexplained"
    fr = hom | {"more": {"coulomb_law_z": {"value": 60.0}}}
    assert decision(_rec(zdetect=2.0, data_findings=[dh, fr]), 8.0, 10.0, 0.0)["named"] == "friction"


def test_friction_told_from_a_crack_or_rattle_answers_the_models_unexplained():
    """Issue 17: the modal family's friction trial came out "unexplained": the homogeneity check
    saw it (46x chance) but could not tell it from a crack or a rattle, effects outside the
    library. Now the decays' laws tell them: a decrement per cycle growing as 1/amplitude with
    the frequency unchanged (Coulomb) answers "friction" over the model's "unexplained", with its
    gages; a frequency moving with the amplitude (a crack, a stop) stays "unexplained", where the
    model placed it; a Coulomb finding barely past chance does not override."""
    from ramdaq.daq.commands.gap_bench import decision

    fr = {"check": "homogeneity", "layer": "nonlinearity", "gages": [4, 6], "window": "decay",
          "mode_hz": [22.1], "statistic": 188.0, "chance_level": 4.1,
          "more": {"coulomb_law_z": {"value": 188.0}, "frequency_change": {"value": -0.0004}}}
    d = decision(_rec(effect="friction", expect="friction", data_findings=[fr]), 8.0, 10.0, 0.0)
    assert d["named"] == "friction" and d["by"] == "data" and d["location"]["gages"] == [4, 6]
    stiff = fr | {"more": {"stiffness_law_z": {"value": -22.0}, "frequency_change": {"value": -0.05}}}
    # the crack's stiffness law answers "unexplained" itself, at the gages it was read on (the
    # model's map cell on a rig with form error left is not the place: unexpl8)
    d = decision(_rec(data_findings=[stiff]), 8.0, 10.0, 0.0)
    assert d["named"] == "unexplained" and d["by"] == "data" and d["location"]["gages"] == [4, 6]
    weak = fr | {"statistic": 6.0}
    assert decision(_rec(data_findings=[weak], form_gages=[]), 8.0, 10.0, 0.0)["named"] == "unexplained"
    assert decision(_rec(data_findings=[weak]), 8.0, 10.0, 0.0)["named"] == "none"


def test_ramdaq_gap_prints_the_answer_the_benchmark_scores():
    """One decision (issue 17): ``ramdaq gap``'s report and the benchmark's scoring read the same
    function. The model layer alone finds the gap "unexplained"; a high-pass the data-only layer
    finds at 14x chance takes precedence in both, and the printed verdict says so."""
    from types import SimpleNamespace

    from ramdaq.analysis.gap.diagnose import Diagnosis
    from ramdaq.daq.commands.gap import answer_lines
    from ramdaq.daq.commands.gap_bench import decision
    from ramdaq.daq.gap_layers import one_answer

    hp = {"check": "highpass", "layer": "sensor", "gages": [14], "window": "decay", "mode_hz": [13.0],
          "statistic": 239.0, "chance_level": 17.3, "more": {}, "text": "a 1.5 Hz high-pass on gage 14"}
    r = _rec(effect="highpass", expect="highpass", candidates=[], data_findings=[hp])
    where = r["unexplained_where"]
    level = SimpleNamespace(form_gages=lambda: {12}, form_modes=lambda: [],
                            statement=lambda named=None: "model form: x",
                            splits=lambda: [], coupled=lambda: [], candidate_form=lambda name: {})
    d = SimpleNamespace(verdict="unexplained", best=None, candidates=[], unexplained_where=where,
                        model_level=level,
                        data=SimpleNamespace(findings=[SimpleNamespace(to_json=lambda: hp)]))
    d.model_choice = lambda: Diagnosis.model_choice(d)
    d.answer = one_answer(d)
    assert d.answer.to_json() == decision(r, 8.0, 10.0, 0.0)
    assert d.answer.named == "highpass" and d.answer.by == "data"
    head = Diagnosis.headline.fget(d)
    assert head.startswith("explained by the data-only layer: highpass") and head.endswith("; model form: x")
    assert "takes precedence" in answer_lines(d)[0]
    # without the data-only finding both say what the model's map says: with the rig's form
    # error left (gage 12) and nothing in the data, model form (issue 17, unexpl8); with no form
    # error left, unexplained, where the gap is
    d.data = SimpleNamespace(findings=[])
    d.answer = one_answer(d)
    assert d.answer.to_json() == decision(r | {"data_findings": []}, 8.0, 10.0, 0.0)
    assert Diagnosis.headline.fget(d).startswith("no effect named, the gap is the rig model's form")
    level.form_gages = lambda: set()
    d.answer = one_answer(d)
    assert d.answer.to_json() == decision(r | {"data_findings": [], "form_gages": []}, 8.0, 10.0, 0.0)
    assert Diagnosis.headline.fget(d).startswith("unexplained: gages 3") and answer_lines(d) == []
    # a coupled hull mode the identified modes show answers where the map alone is unexplained:
    # the report says why, not that the gap lies in the form error
    c = {"f_hz": 6.2, "zeta": 0.02, "hull_share": 0.2, "nonrigid": 0.001, "statistic": 13.0,
         "chance_level": 1.0, "gages": [13, 14, 9, 5], "kind": "driven"}
    level.coupled = lambda: [SimpleNamespace(to_json=lambda: c)]
    d.answer = one_answer(d)
    assert d.answer.named == "hull_coupling" and d.answer.by == "model"
    (why,) = answer_lines(d)
    assert "identified modes show hull_coupling" in why and "form error" not in why


_MISSED = ("measured on this check seed (2026-11-27, branch gen): the unexplained gap is placed "
           "on other gages, or a library effect is named")


@pytest.mark.slow
@pytest.mark.parametrize("effect", [
    "crack", "rattle",
    pytest.param("mains_pickup", marks=pytest.mark.xfail(reason=_MISSED + " (gage 1, not 7-9)")),
    pytest.param("sensor_resonance", marks=pytest.mark.xfail(reason=_MISSED + " (tiller named)")),
    pytest.param("gain_drift", marks=pytest.mark.xfail(reason=_MISSED + " (gages 10, 16, 12, not 4)"))])
def test_an_effect_outside_the_library_comes_out_unexplained(tmp_path, effect):
    """Issue 17: a modal-family trial (perturbed rig, all of ramdaq gap's layers) with an effect
    the library does not hold is answered "unexplained" with at least one of its gages -- never
    the nearest library effect. Slow (a whole diagnosis each, ~1-3 min on a loaded machine)."""
    from ramdaq.daq.commands.gap_bench import decision, run_one

    sc = scenarios(1, "check", (effect,), 0.25, "modal")[0]
    r = run_one(sc, str(tmp_path))
    assert "error" not in r, r["error"]
    d = decision(r, 8.0, 10.0, 0.0)
    assert d["named"] == "unexplained", (d, r.get("headline"))
    assert set(d["location"]["gages"]) & set(r["truth"]["gages"]), (d["location"], r["truth"])


def test_wilson_interval():
    """The Wilson score interval against its closed form at the edges (k = 0: 0 to
    z^2 / (n + z^2)) and a value worked by hand (17 of 20 at 95 %: 0.640-0.948:
    centre 0.794, half-width 0.154)."""
    from ramdaq.daq.commands.gap_bench import wilson

    z = 1.96
    assert wilson(0, 10) == pytest.approx((0.0, z * z / (10 + z * z)), abs=1e-12)
    assert wilson(10, 10) == pytest.approx((1 - z * z / (10 + z * z), 1.0), abs=1e-12)
    assert wilson(17, 20) == pytest.approx((0.640, 0.948), abs=1e-3)
    assert all(np.isnan(wilson(0, 0)))


def test_a_benchmark_trial_has_the_blows_asked_for():
    """``--blows`` reaches both generators (the trigger sees each blow); fewer than four leave
    no impact to hold out after three fitted, and are refused."""
    from ramdaq.daq.commands.gap_bench import _generate_modal, _generate_truth

    for fam, gen in (("truth", _generate_truth), ("modal", _generate_modal)):
        (sc,) = scenarios(1, "check", ("none",), 0.25, fam, blows=4)
        assert sc["blows"] == 4 and gen(sc)["n_impacts"] == 4
    with pytest.raises(ValueError, match="--blows 3"):
        scenarios(1, "check", blows=3)


def test_the_score_prints_its_confidence_intervals():
    """Top-1 per family and layer with its Wilson interval, false alarms with their one-sided
    bound, and what the run's size can show."""
    from ramdaq.daq.commands.gap_bench import format_score

    # form_gages empty: the map's unexplained cell stands (on a rig with form error left it is
    # model form, test_an_outside_effect_scores_as_unexplained_in_its_own_class)
    rs = [_rec(form_gages=[]), _rec(effect="none", expect="none", size=0.0, zdetect=2.0)]
    lines = format_score(score(rs, {}, 8.0, 10.0, 0.0), {})
    text = "\n".join(lines)
    assert "(1 of 1; 95 % interval 21-100 %)" in text          # top-1, Wilson of 1 of 1
    assert "(0 of 1; 95 % upper bound 95 %)" in text            # false alarms, Clopper-Pearson
    assert any(line.startswith("what this size can show") for line in lines)
    assert "modal   unexplained      1   100%" in text and "21-100 %" in text


def _stand_in(sc: dict, workdir: str) -> dict:
    """A scenario's result without running it (module level: the worker unpickles it by name)."""
    return _rec(effect="none", expect="none", size=0.0, zdetect=2.0, cpu_seconds=1.5) | sc


def test_the_run_prints_its_wall_and_cpu_time(tmp_path, capsys, monkeypatch):
    """The whole run's wall and CPU time (this process and its workers, and the scenarios' own)
    end the figures; a stand-in scenario (the worker is forked, so it runs the stand-in too)
    keeps it quick."""
    from ramdaq.daq.commands import gap_bench

    monkeypatch.setattr(gap_bench, "run_one", _stand_in)
    assert gap_bench.run_benchmark(tmp_path, per_class=1, seeds="check", jobs=1, effects=("none",),
                                   perturb=0.25, family="modal") == 0
    out = capsys.readouterr().out
    assert "no false alarm in 1 no-effect trials bounds the rate by 95 %" in out
    # no effect trial: no top-1 to bound and no class to list, said as such (a new user's smoke
    # run printed "a top-1 of 85 % is known to (Wilson 95 %) " and an empty "per-class top-1:")
    assert "what this size can show: no effect trial above its threshold, no top-1" in out
    assert "per-class top-1: none (no effect trial above its threshold)" in out
    last = out.strip().splitlines()[-1]
    assert last.startswith("whole run: ") and "min CPU of this process and its workers" in last
    assert "the scenarios' own 0.0 min (median 1.5 s a scenario)" in last


def test_the_progress_line_shows_the_answer_that_is_scored():
    """A modal no-effect trial's progress line read "unexplained" (the effect search's verdict)
    while the summary counted it as "no effect; model form" (the one answer of both layers, as
    ``ramdaq gap`` prints it): the line now leads with that answer and says what the search
    alone said where it differs."""
    from ramdaq.daq.commands.gap_bench import _tag

    assert _tag({"verdict": "unexplained", "named": None, "answer": "none"}) == \
        "none (effect search: unexplained)"
    assert _tag({"verdict": "explained", "named": "tiller", "answer": "tiller"}) == "tiller"
    assert _tag({"verdict": "no gap beyond noise", "named": None}) == "no gap beyond noise"
    assert _tag({"error": "ValueError: no impacts"}) == "ValueError: no impacts"


def test_a_dead_gage_leads_the_answer():
    """A new user's trial with gage 8 dead and a faint 50 Hz hum on every gage answered
    ambient_tone (a line before the blows answers first) and only listed the dead gage. A gage
    the blow did not move is certain and spoils every other reading of it: it answers first, as
    a gain of zero (gage_sensitivity) at that gage; without it the hum answers as before."""
    from ramdaq.daq.commands.gap_bench import decision

    dead = {"check": "dead", "layer": "sensor", "gages": [8], "window": "early", "mode_hz": [],
            "statistic": float("inf"), "chance_level": 1.0, "more": {}}
    hum = {"check": "ambient_tone", "layer": "excitation", "gages": [1, 2, 3, 4, 6, 7, 9, 10],
           "window": "pre", "mode_hz": [50.0], "statistic": 4000.0, "chance_level": 10.0, "more": {}}
    d = decision(_rec(data_findings=[hum, dead]), 8.0, 10.0, 0.0)
    assert d["named"] == "gage_sensitivity" and d["by"] == "data" and d["location"]["gages"] == [8]
    d = decision(_rec(data_findings=[hum]), 8.0, 10.0, 0.0)
    assert d["named"] == "ambient_tone" and d["by"] == "data"


def test_a_dead_gage_is_said_certain_not_inf_times_its_chance_level():
    """The new user's dead gage read "statistic infx its chance level" in the verdict and
    "statistic inf > 1" in its finding's line: no statistic measures a gage that did not move,
    and both now say it is certain."""
    import math
    from types import SimpleNamespace

    from ramdaq.analysis.gap.datamodel import Finding, Layer
    from ramdaq.analysis.gap.diagnose import Diagnosis
    from ramdaq.daq.commands.gap import finding_line
    from ramdaq.daq.gap_layers import one_answer

    text = "gage 8 is dead: its first blow moves it by 0 m/s^2 (one converter step or less)"
    dead = Finding(check="dead", layer=Layer.SENSOR, gages=(8,), statistic=math.inf, chance_level=1.0,
                   size=0.0, unit="m/s^2", text=text, window="early")
    assert finding_line(dead).endswith("(early window; certain: no chance level applies)")
    level = SimpleNamespace(form_gages=lambda: set(), form_modes=lambda: [],
                            statement=lambda named=None: "", splits=lambda: [], coupled=lambda: [],
                            candidate_form=lambda name: {})
    d = SimpleNamespace(verdict="unexplained", best=None, candidates=[], model_level=level,
                        unexplained_where=_rec()["unexplained_where"],
                        data=SimpleNamespace(findings=[dead]))
    d.model_choice = lambda: Diagnosis.model_choice(d)
    d.answer = one_answer(d)
    head = Diagnosis.headline.fget(d)
    assert head.startswith(f"explained by the data-only layer: gage_sensitivity ({text}; certain: "
                           "no chance level applies"), head
