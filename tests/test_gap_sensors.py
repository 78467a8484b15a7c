"""The data-only layer of the gap diagnosis (issue 17 item 1, and its second "Done when"):
sensor effects injected outside the library in plain numpy on a simulated ALBACORE-in-water
trial's recorded values (six blows), exported as CSV, re-imported with ``ramdaq import``, and
found by :func:`ramdaq.analysis.gap.sensors.check_trial` with the right gages and layer; the
clean trial raises nothing.

False-alarm level: every check's chance level is its null distribution's upper
``P_CHANCE`` = 1e-3 quantile after Bonferroni over what it searched, so a clean trial raises a
finding from one of the six checks with probability at most 0.6 %."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from ramdaq.analysis.gap.datamodel import P_CHANCE, Finding, FreeModal, Layer, free_modal_model
from ramdaq.analysis.gap.layers import answer, model_gages, overriding_unexplained, precedence, unconfirmed
from ramdaq.analysis.gap.sensors import chain_phase, check_trial, rigid_gain
from ramdaq.analysis.model.rig import load_rig
from ramdaq.daq.commands.cli import main
from ramdaq.daq.gap_trial import load_trial
from tests.sensor_injection import HULL, injected_recording


@pytest.fixture(scope="module")
def trials(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("injected")
    cache: dict = {}

    def get(effect: str):
        if effect not in cache:
            mcap, what = injected_recording(tmp, effect)
            lt = load_trial(mcap)
            lt.source = str(mcap)
            cache[effect] = (check_trial(lt.x, lt.fs_hz, lt.onsets_s, lt.rig.gages_by_channel()), what, lt)
        return cache[effect]
    return get


def _only(dc, check: str) -> list:
    assert dc.findings, "nothing found"
    assert {f.check for f in dc.findings} == {check}, [f.text for f in dc.findings]
    for f in dc.findings:
        assert f.statistic > f.chance_level and f.p_chance == P_CHANCE
    return dc.findings


def _closes_its_gap(f: Finding) -> None:
    """The injected fault is the same at every blow: its correction read on the blows not held
    out (1, 2, 4, 5) leaves the held-out blows (3 and 6) their noise alone -- all of the check's
    residual beyond it closed (measured 0.9997-1.0), and the interval with it. A bound of 0.95
    still fails a correction read wrong by a fifth of the fault or more."""
    assert f.closed_held > 0.95 and f.closed_held_ci[0] > 0.9, (f.check, f.closed_held, f.closed_held_ci)


def test_clean_trial_raises_nothing(trials):
    dc, _, _ = trials("none")
    assert dc.findings == [], [f.text for f in dc.findings]
    # the free model: ALBACORE in water's four compared modes, none steady
    assert dc.modal.n_modes == 4 and not dc.modal.steady.any()


def test_gain_on_one_gage(trials):
    dc, what, _ = trials("gain")
    (f,) = _only(dc, "gain")
    assert f.gages == what.gages and f.layer is Layer.SENSOR
    # its standard error on this trial is 0.001 and the rigid-body reconstruction carries a
    # 0.5 % form floor: within 1 % of the injected 1.15
    assert f.size == pytest.approx(1.15, abs=0.01)
    _closes_its_gap(f)


def test_three_sample_skew_on_one_gage(trials):
    dc, what, lt = trials("skew")
    (f,) = _only(dc, "time_skew")
    assert f.gages == what.gages and f.layer is Layer.SENSOR
    # phases at four modes up to 215 Hz, each known to ~1e-3 rad: the delay to a tenth of a
    # sample (the scan's step is 0.02 sample)
    assert f.size * lt.fs_hz == pytest.approx(3.0, abs=0.1)
    _closes_its_gap(f)


def test_clipping_at_half_the_peak(trials):
    dc, what, lt = trials("clipping")
    (f,) = _only(dc, "clipping")
    assert f.gages == what.gages and f.layer is Layer.SENSOR
    (row,) = [i for i, g in enumerate(lt.rig.gages_by_channel()) if g.number == 1]
    # the flat top is the clip level itself, to the converter's step
    assert f.size == pytest.approx(np.max(np.abs(lt.x[row])), rel=1e-6)
    _closes_its_gap(f)


def test_hull_tone_before_the_blows(trials):
    dc, what, _ = trials("tone")
    (f,) = _only(dc, "ambient_tone")
    assert set(f.gages) == set(HULL) and f.layer is Layer.EXCITATION and f.window == "pre"
    # six 0.99 s windows on six gages, the line ~20 dB over the noise in each: its frequency
    # to ~0.01 Hz; the refining grid's step is 0.0125 Hz
    assert f.mode_hz[0] == pytest.approx(2.3, abs=0.03)
    assert dc.modal.steady.sum() == 1          # the tone is a steady line, not a mode


def test_highpass_on_four_gages(trials):
    dc, what, _ = trials("highpass")
    fs = _only(dc, "highpass")
    assert {f.gages[0] for f in fs} == set(what.gages)
    # the lead atan(fc/f) at 6.8 and 13 Hz is 0.2 and 0.1 rad, known to ~0.01 rad: fc to 10 %
    for f in fs:
        assert f.size == pytest.approx(1.5, rel=0.1) and f.layer is Layer.SENSOR
        _closes_its_gap(f)
    # the answer names every gage the check found, not the strongest alone
    a = answer(None, [], None, set(), [f.to_json() for f in fs])
    assert a.named == "highpass" and set(a.location["gages"]) == set(what.gages)
    assert a.location["gages"][0] == max(fs, key=lambda f: f.statistic / f.chance_level).gages[0]


def test_double_hit_30_ms_after_the_blow(trials):
    dc, _, _ = trials("double_hit")
    (f,) = _only(dc, "double_hit")
    assert f.layer is Layer.EXCITATION and f.window == "early"
    more = {n: v for n, v, _ in f.more}
    # the delay on the sample grid (0.49 ms) to two samples; the size from a residual whose
    # signal-to-noise is ~10^3 per blow, to 5 % (the early window's unmodelled modes above the
    # free model's band and the anti-alias filter's transient are what is left)
    assert more["delay_s"] == pytest.approx(0.030, abs=1e-3)
    assert f.size == pytest.approx(0.3, rel=0.05)
    assert more["blows"] == 6


def test_noisy_gage(trials):
    dc, what, _ = trials("noisy")
    (f,) = _only(dc, "noisy")
    assert f.gages == what.gages and f.layer is Layer.SENSOR
    # white noise of 0.015 m/s^2 rms added, which first differences read without bias; the
    # simulated floor (anti-alias filtered, 0.004 in first differences) adds under 4 % in
    # quadrature, and ~2000 differences know the rms to ~2 %
    assert 0.015 * 0.96 < f.size < 0.015 * 1.08


def test_dead_gage(trials):
    dc, what, _ = trials("dead")
    (f,) = _only(dc, "dead")
    assert f.gages == what.gages and f.layer is Layer.SENSOR
    assert dc.modal.n_modes == 4                  # the other gages still give the four modes


def test_free_modal_model_shares_poles_across_impacts():
    """Three impacts of different force on four gages, two modes: the poles come back to their
    standard errors, and each impact's shapes scale with its force."""
    fs, rng = 1024.0, np.random.default_rng(5)
    f0, d0 = np.array([11.0, 47.0]), np.array([0.05, 0.02])
    shape = np.array([[1.0, 0.5], [-0.7, 1.0], [0.3, -0.8], [0.9, 0.2]])
    onsets, force = [2.0, 7.0, 12.0], [1.0, 0.5, 2.0]
    t = np.arange(int(17 * fs)) / fs
    x = rng.normal(0, 1e-3, (4, t.size))
    for on, a in zip(onsets, force, strict=True):
        tau = t - on
        e = np.where(tau[None] >= 0, np.exp(-d0[:, None] * f0[:, None] * tau) *
                     np.sin(2 * math.pi * f0[:, None] * tau), 0.0)
        x += a * shape @ e
    fm = free_modal_model(x, fs, np.array(onsets))
    assert fm.n_modes == 2
    assert np.all(np.abs(fm.f_hz - f0) < 5 * fm.f_se_hz)
    assert np.all(np.abs(fm.delta - d0) < 5 * fm.delta_se)
    # amplitudes at each window's start: the ratio between impacts is the force ratio, up to
    # the previous blow's ringing still there (the 11 Hz mode keeps exp(-0.05 * 11 * 5) = 6 %
    # of the half-force blow 5 s earlier: 1.6 % of the third blow's amplitude, in any phase)
    r = np.abs(fm.amp[2]) / np.abs(fm.amp[0])
    ok = fm.snr()[0] > 100
    assert np.allclose(r[ok], 2.0, rtol=0.02)


def _finding(check: str, layer: Layer, gages: tuple[int, ...]) -> Finding:
    return Finding(check=check, layer=layer, gages=gages, statistic=100.0, chance_level=10.0,
                   size=1.2, unit="ratio", text=check)


def test_a_data_sensor_finding_takes_precedence_on_the_same_gages():
    data = [_finding("gain", Layer.SENSOR, (3,)), _finding("double_hit", Layer.EXCITATION, (1, 2, 3))]
    # the model blames gage 3's alignment: set aside for the data layer's gain there
    (p,) = precedence(data, "gage_alignment", model_gages([3], [3, 4], "gage_alignment"))
    assert p.gages == (3,) and p.finding == "gain" and p.model_effect == "gage_alignment"
    assert p.to_json()["kept"] == "data_only"
    # a sensor effect placed without a gage of its own is read where it closed the gap
    assert model_gages([], [4, 3], "highpass") == {3, 4}
    # the model blames gage 5's sensitivity, the rigid-body check finds gage 3's gain: gage 3
    (p,) = precedence(data, "gage_sensitivity", {5})
    assert p.gages == (3,) and p.model_gages == (5,)
    # another gage and another kind, or an effect that names no gage: nothing set aside (an
    # excitation finding of the data layer never overrides)
    assert precedence(data, "time_skew", {5}) == []
    assert precedence(data, "hull_coupling", model_gages([], [3], "hull_coupling")) == []
    assert precedence(data, None, {3}) == []


def test_a_model_effect_the_data_checks_looked_for_and_did_not_find_is_unconfirmed():
    looked = ("gain", "time_skew", "highpass", "clipping", "ambient_tone", "double_hit")
    data = [_finding("gain", Layer.SENSOR, (3,))]
    assert unconfirmed(data, looked, "double_hit") == ["double_hit"]
    assert unconfirmed(data, looked, "gage_sensitivity") == []
    assert unconfirmed(data, looked, "double_hit+highpass") == ["double_hit", "highpass"]
    assert unconfirmed(data, looked, "hull_coupling") == []       # no data-only counterpart


def test_gap_reports_the_data_only_layer_first_and_it_takes_precedence(trials, capsys, tmp_path):
    """``ramdaq gap`` prints the data-only section before the model's cause and ranking, writes
    it to gap.json, and when the model blames a gage's sensitivity the data-only gain stands.
    (One candidate effect only, to keep the model layer's run short.)"""
    dc, what, lt = trials("gain")
    capsys.readouterr()
    out = tmp_path / "gap"
    assert main(["gap", lt.source, "--no-plots", "--effects", "gage_sensitivity", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert text.index("data-only (no stiffness or mass model") < text.index("ranking (")
    assert "gage 3: gain x1.1" in text
    doc = json.loads((out / "gap.json").read_text())
    (f,) = doc["data_only"]["findings"]
    assert f["check"] == "gain" and f["gages"] == [3] and f["layer"] == "sensor"
    assert f["statistic"] > f["chance_level"]
    if doc["effect"] == "gage_sensitivity":
        (p,) = doc["precedence"]
        assert p["gages"] == [3] and p["kept"] == "data_only"
        assert "set aside: the data-only gain on gage(s) 3" in text


def _rudder_modal(bend: float, gain: float = 1.0, carried: int = 0) -> tuple[FreeModal, list]:
    """A free modal model of ALBACORE's six rudder gages (all along y): three modes, four
    impacts, each mode's shape a rigid-body motion (y translation, rotations about x and z)
    plus ``bend`` x a quadratic in position that differs from mode to mode (a flexible rudder,
    issue 17's modal family), and ``carried`` lower modes (hull modes) that carry the rudder
    along as one rigid body; gage 3's entries times ``gain``. Standard errors 1e-4 of unit
    shapes (SNR ~10^4: far past the checks' MIN_ENTRY_SNR)."""
    gages = [g for g in load_rig("albacore").gages_by_channel() if g.body == "rudder"]
    x = np.array([g.position_m[0] for g in gages])
    z = np.array([g.position_m[2] for g in gages])
    rng = np.random.default_rng(3)
    shapes = []
    for _ in range(3):
        rigid = rng.normal(size=3) @ np.vstack([np.ones_like(x), z, x])      # y, rot x, rot z
        quad = rng.normal(size=3) @ np.vstack([x**2, z**2, x * z])
        shapes.append(rigid + bend * quad)
    shapes = [rng.normal(size=3) @ np.vstack([np.ones_like(x), z, x]) for _ in range(carried)] + shapes
    amp = np.repeat(np.array(shapes).T[None].astype(complex), 4, axis=0)     # (4, 6, 3)
    amp[:, [g.number for g in gages].index(3), :] *= gain
    n = amp.shape
    k = n[2]
    fm = FreeModal(f_hz=np.array([4.0, 7.0, 10.0][:carried] + [13.0, 45.0, 80.0]), delta=np.full(k, 0.1),
                   f_se_hz=np.zeros(k), delta_se=np.zeros(k), amp=amp, amp_se=np.full(n, 1e-4),
                   noise=np.full(n[:2], 1e-4), t0_s=np.arange(4.0), n_s=1000, fs_hz=2048.0,
                   steady=np.zeros(k, bool))
    return fm, gages


def test_a_flexible_rudder_is_model_form_not_a_gage_fault():
    # issue 17: the modal family's rudder bends (quadratic terms in its shapes); the rigid-body
    # check named gages 1, 2, 6, 15 on every trial. Bent by 0.3 of its rigid motion per m^2
    # (well past the 0.5 % gain floor), no single gage's removal makes the rest rigid: one
    # model-form finding for the body, no gain and no per-gage rigid-body finding
    fm, gages = _rudder_modal(bend=0.3)
    (f,) = rigid_gain(fm, gages)
    assert f.check == "flex" and f.layer is Layer.MODEL_FORM and len(f.gages) >= 5
    assert f.statistic > f.chance_level
    # a rigid rudder with gage 3 reading 20 % high in every mode: that gage's gain, nothing else
    fm, gages = _rudder_modal(bend=0.0, gain=1.2)
    (f,) = rigid_gain(fm, gages)
    assert f.check == "gain" and f.gages == (3,) and f.size == pytest.approx(1.2, rel=1e-3)
    # rigid and healthy: nothing
    assert rigid_gain(*_rudder_modal(bend=0.0)) == []


def test_a_reversed_gage_is_said_to_be_its_wiring_or_the_rig_files_axis():
    """A new user's rig gave gage 4 the axis -y where it reads +y: the data layer read a
    confident 'polarity reversed' sensor fault. The data cannot tell the two apart, so the
    finding names both: the gage wired backwards, or its axis in the rig file of the wrong sign."""
    (f,) = rigid_gain(*_rudder_modal(bend=0.0, gain=-1.0))
    assert f.check == "gain" and f.gages == (3,) and f.size == pytest.approx(-1.0, rel=1e-3)
    assert ("(its polarity reversed: the gage wired backwards, or its axis in the rig file of the "
            "wrong sign)") in f.text


def test_a_gain_on_a_flexible_rudder_is_read_on_the_modes_that_carry_it_rigidly():
    # issue 17, modal check seeds 151000/151001: the modal family's rudder bends in its own
    # modes and rides the hull's as one body; a 1.1-1.4x gain was only ever "flex". Two hull
    # modes carry the bent rudder of the test above: gage 3's 20 % gain is read on them, with
    # the body's form beside it, and its correction fitted on impacts 1, 2, 4 closes the held-out
    # third's rigid-body misfit (exact shapes, SNR 1e4: all of it to the 0.5 % gain floor)
    fm, gages = _rudder_modal(bend=0.3, gain=1.2, carried=2)
    found = {f.check: f for f in rigid_gain(fm, gages)}
    assert set(found) == {"gain", "flex"}
    g = found["gain"]
    assert g.gages == (3,) and g.size == pytest.approx(1.2, rel=1e-3) and g.mode_hz == (4.0, 7.0)
    assert g.closed_held == pytest.approx(1.0, abs=1e-3) and g.closed_held_ci[0] > 0.99
    # the same bent rudder with every gage healthy: its form only, no gain
    assert [f.check for f in rigid_gain(*_rudder_modal(bend=0.3, carried=2))] == ["flex"]


def test_a_sensor_finding_well_above_chance_outranks_unexplained():
    # issue 17: a high-pass the phases found on four gages lost to the model's "unexplained"
    hp = _finding("highpass", Layer.SENSOR, (2,)).to_json()            # statistic 10x chance
    weak = Finding(check="gain", layer=Layer.SENSOR, gages=(4,), statistic=15.0, chance_level=10.0,
                   size=1.1, unit="ratio", text="gain").to_json()     # 1.5x: not well above
    form = _finding("flex", Layer.MODEL_FORM, (1, 2)).to_json()
    assert overriding_unexplained([hp, weak, form]) == [hp]
    # the trial is not homogeneous across blows: the linear shapes the sensor checks read bend
    nonlin = _finding("homogeneity", Layer.NONLINEARITY, (1, 2)).to_json()
    assert overriding_unexplained([hp, nonlin]) == []


def _modal_trial(effect: str, i: int, tmp_path):
    """The modal family's development-seed trial ``i`` of ``effect`` (perturbed-rig scenario
    list; the data-only layer sees no rig constants), recorded and read back as ``ramdaq gap``
    reads it (the trigger's onsets, 0.4-0.9 ms after the generator's): the loaded trial and
    the generator's truth."""
    from ramdaq.daq.commands.gap_bench import _generate_modal, scenarios
    from ramdaq.daq.record import record
    from ramdaq.drivers.array_device import ArrayDevice

    sc = scenarios(i + 1, "dev", (effect,), 0.25, "modal")[i]
    gen = _generate_modal(sc)
    path = tmp_path / f"modal-{effect}-{i}.mcap"
    dev = ArrayDevice(gen["counts"], gen["scale"], gen["fs_hz"], gages=gen["gages"], rig_toml=gen["rig"].text,
                      extra={"medium": sc["medium"], "adc_bits": gen["adc_bits"]})
    record(dev, path, readout=False, overwrite=True)
    return load_trial(path), gen["truth"]


def _double_hits(lt):
    from ramdaq.analysis.gap.signal_checks import double_hits

    nums = [g.number for g in lt.rig.gages_by_channel()]
    fm = free_modal_model(lt.x, lt.fs_hz, lt.onsets_s, pre_s=1.0)
    return double_hits(lt.x, lt.fs_hz, lt.onsets_s, nums, fm)


@pytest.mark.parametrize("i", [2, 3])
def test_a_clean_modal_trials_contact_is_no_double_hit(i, tmp_path):
    """Issue 17: clean modal-family trials (contacts of 3-8 ms, modes above the free model's
    band ringing early) were read as second blows 13-16 ms after the blow; these two
    development trials were (at 25 % and 48 %, on every blow). The early window now starts at
    16 ms and a second blow must show on two blows. Fragile: with the generator's own onsets
    (0.4-0.9 ms earlier) trial 3 still reads a 22 % second blow at 17 ms."""
    lt, _ = _modal_trial("none", i, tmp_path)
    assert _double_hits(lt) == []


def test_a_modal_double_hit_is_found_with_its_delay(tmp_path):
    """The modal family's development double hit at 54 ms, 15 % of the blow, is found on every
    blow: the delay to two samples (the trigger's onsets are within a sample or two) and the
    size to 20 % (the second blow's 3-8 ms contact is not the impulse the scan shifts)."""
    lt, truth = _modal_trial("double_hit", 0, tmp_path)
    (f,) = _double_hits(lt)
    more = {n: v for n, v, _ in f.more}
    assert more["delay_s"] == pytest.approx(truth["params"]["delay_s"], abs=2 / lt.fs_hz)
    assert f.size == pytest.approx(truth["params"]["ratio"], rel=0.2) and more["blows"] == 6


def test_a_second_blow_is_measured_with_the_contact_held():
    """The contact-held measurement (issue 17: read from where the modes' amplitudes step after
    16 ms, a 26 ms, 15 % second blow came out 20.9 ms, 88 %): three modes rung by a 5 ms half-sine
    and the same 30 % as large 18.1 ms later (on the sample grid), at four gages, white noise at
    1e-3 of the peak. The delay to the sample and the size to 5 % (noise alone moves them far
    less). The contact length is a nuisance the fast poles trade with, not asserted."""
    from ramdaq.analysis.gap.contact import contact_response, second_blow

    fs = 2048.0
    poles = np.array([-0.02 * 2 * math.pi * f + 2j * math.pi * f for f in (13.0, 45.0, 80.0)])
    t = np.arange(int(3.0 * fs)) / fs
    d = 37 / fs                        # 18.1 ms, on the sample grid the delays are tried on
    h = contact_response(t - 1.0, poles, 0.005) + 0.3 * contact_response(t - 1.0 - d, poles, 0.005)
    shapes = np.random.default_rng(3).standard_normal((4, 3)) + 0.2j
    x = np.real(shapes @ h.T)
    x += 1e-3 * np.abs(x).max() * np.random.default_rng(4).standard_normal(x.shape)
    sig = np.full(4, 1e-3 * np.abs(x).max())
    m = second_blow(x, fs, 1.0, poles, sig)
    assert m.delay_s == pytest.approx(d, abs=0.5 / fs)
    assert m.rho == pytest.approx(0.3, rel=0.05)


def test_a_modal_friction_trial_reads_coulombs_law(tmp_path):
    """Issue 17: the modal family's friction came out "unexplained" -- the homogeneity check saw
    it but could not tell it from a crack or a rattle. This development trial (Coulomb friction
    on its 12.9 Hz mode, size 0.5), recorded and read back as ``ramdaq gap`` reads it, now reads
    Coulomb's law within its decays (a decrement per cycle growing as 1/amplitude, the frequency
    within STIFF_MIN) beyond its chance level, on the gages where the mode shows, and the finding
    names the library's friction."""
    from ramdaq.analysis.gap.homogeneity import STIFF_MIN, homogeneity
    from ramdaq.analysis.gap.layers import data_effect

    lt, truth = _modal_trial("friction", 0, tmp_path)
    nums = [g.number for g in lt.rig.gages_by_channel()]
    fm = free_modal_model(lt.x, lt.fs_hz, lt.onsets_s, pre_s=1.0)
    (f,) = homogeneity(lt.x, fm, nums)
    more = {n: v for n, v, _ in f.more}
    assert f.statistic > f.chance_level and "coulomb_law_z" in more, f.text
    assert abs(more["frequency_change"]) < STIFF_MIN and abs(f.mode_hz[0] - truth["mode_hz"]) < 0.5
    assert set(truth["gages"]) <= set(f.gages) and data_effect(f.to_json()) == "friction"


def _phases_modal(departure: np.ndarray) -> FreeModal:
    """Six gages, six modes (10-110 Hz), four impacts of real unit shapes (SNR 1000: each phase
    known to 0.001 rad, under the 0.02 rad floor); gage index 2's phase off the others' by
    ``departure`` (rad, per mode, the same at every impact)."""
    f = np.array([10.0, 25.0, 40.0, 60.0, 85.0, 110.0])
    amp = np.ones((4, 6, 6), complex)
    amp[:, 2, :] *= np.exp(1j * departure)[None, :]
    return FreeModal(f_hz=f, delta=np.full(6, 0.1), f_se_hz=np.zeros(6), delta_se=np.zeros(6), amp=amp,
                     amp_se=np.full(amp.shape, 1e-3), noise=np.full((4, 6), 1e-3), t0_s=np.arange(4.0),
                     n_s=1000, fs_hz=2048.0, steady=np.zeros(6, bool))


def test_a_phase_no_one_delay_fits_is_unexplained_at_its_gage_not_a_skew():
    # issue 17: a modal friction trial read as gage 15 "runs -2.50 ms"; dev seed 58000 read
    # skews on gages 9, 13, 14 whose residual was 52-168x its chance level. A half-sample delay
    # is a skew; the same delay with +-0.25 rad from mode to mode (12 floors: no delay and no
    # corner makes it) is "unexplained" at that gage
    f = np.array([10.0, 25.0, 40.0, 60.0, 85.0, 110.0])
    lag = -2 * math.pi * f * 0.5 / 2048.0
    (skew,) = chain_phase(_phases_modal(lag), [1, 2, 3, 4, 5, 6])
    assert skew.check == "time_skew" and skew.gages == (3,)
    assert skew.size == pytest.approx(0.5 / 2048.0, rel=0.05)
    (bad,) = chain_phase(_phases_modal(lag + 0.25 * np.array([1, -1, 1, -1, 1, -1])), [1, 2, 3, 4, 5, 6])
    assert bad.check == "chain_misfit" and bad.gages == (3,) and bad.statistic > bad.chance_level
    more = {name: v for name, v, _ in bad.more}
    assert more["residual_chi2"] > more["residual_level"]
    assert "unexplained at gage 3" in bad.text
    # the layers answer it "unexplained" at its gage when well above chance (10x)
    a = answer(None, [], None, set(), [bad.to_json()])
    assert a.named == "unexplained" and a.location["gages"] == [3]


def test_a_skew_that_does_not_close_its_held_out_impacts_is_not_credible():
    # modal dev seed 51001, a clean trial: gage 15 read as a 0.93 Hz high-pass at 4x its chance
    # level, closing 34 % of its phase residual held out (development skews and high-passes of
    # both families close 93-100 %): not a fixed law of the channel, no answer
    hp = replace(_finding("highpass", Layer.SENSOR, (15,)), closed_held=0.34).to_json()
    assert answer(None, [], None, set(), [hp]).named == "none"
    ok = replace(_finding("highpass", Layer.SENSOR, (15,)), closed_held=0.95).to_json()
    assert answer(None, [], None, set(), [ok]).named == "highpass"


def test_a_gain_is_read_on_weak_modes_the_rudder_rides_rigidly():
    # modal dev seed 52002: the hull modes that carry the bent rudder rigidly reach SNR 14-24 on
    # its gages; at the shape checks' entry SNR of 20 one of them was left and a x1.4 gain on
    # gage 8 was only "flex". At SNR 22 (mean over the gages; the weaker entries under 20) in
    # both carried modes gage
    # 3's 20 % gain is read there (at an entry SNR of 20 only "flex")
    fm, gages = _rudder_modal(bend=0.3, gain=1.2, carried=2)
    se = fm.amp_se.copy()
    se[:, :, :2] = np.abs(fm.amp[:, :, :2]).mean(axis=1, keepdims=True) / 22.0
    found = {f.check: f for f in rigid_gain(replace(fm, amp_se=se), gages)}
    assert set(found) == {"gain", "flex"}
    assert found["gain"].gages == (3,) and found["gain"].size == pytest.approx(1.2, rel=0.02)


def test_a_dead_gage_raises_no_numpy_warning(trials):
    """A new user's dead gage put numpy's RuntimeWarnings (an All-NaN slice in the model level's
    noise, an invalid divide in the line-persistence check) on the terminal, beside the finding
    that says what they mean. The data-only layer and the model level's modes run quietly; the
    dead gage is still found, and its noise is NaN where no impact measured one."""
    import warnings

    from ramdaq.analysis.gap.modal_level import trial_modes
    from ramdaq.daq.gap_trial import trial_data

    _, what, lt = trials("dead")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        dc = check_trial(lt.x, lt.fs_hz, lt.onsets_s, lt.rig.gages_by_channel())
        tm = trial_modes(trial_data(lt))
    assert [f.gages for f in dc.findings if f.check == "dead"] == [what.gages]
    assert tm.n_modes >= 3 and np.isfinite(tm.noise_std).sum() >= tm.noise_std.size - 1
