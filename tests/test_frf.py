"""Driving-point FRFs (analysis/modal/frf.py): H1 and coherence against an exact single-degree-
of-freedom system; the report's section and plot on a simulated trial with a ram load cell."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal

from ramdaq.analysis.modal.frf import force_window, h1_estimate

FS, N = 1024.0, 16384          # 16 s: the ringing (tau = 1 / (zeta omega) = 0.53 s) dies in it
M, FN, ZETA = 10.0, 30.0, 0.01  # kg, Hz, 1


def accelerance(f_hz: np.ndarray) -> np.ndarray:
    """(m/s^2)/N of the mass-spring-damper: -w^2 / (k - m w^2 + i c w)."""
    w, wn = 2 * np.pi * f_hz, 2 * np.pi * FN
    return -w**2 / (M * wn**2 - M * w**2 + 2j * ZETA * M * wn * w)


def blow(t0_s: float, peak_N: float, offset_N: float = 3.0, noise: float = 0.0, seed: int = 0):
    """(force N, acceleration m/s^2) of a 4 ms half-sine at ``t0_s`` on the SDOF system, exact
    for the sampled force read as piecewise linear (scipy's lsim), with a load-cell offset and
    white noise of rms ``noise`` m/s^2 on the response."""
    t = np.arange(N) / FS
    f = np.where((t >= t0_s) & (t < t0_s + 0.004), peak_N * np.sin(np.pi * (t - t0_s) / 0.004), 0)
    wn = 2 * np.pi * FN
    sys_ = signal.lti([1 / M, 0, 0], [1, 2 * ZETA * wn, wn**2])  # a = s^2 / (m s^2 + c s + k) F
    # the feedthrough: a state-space form of the proper transfer function
    _, y, _ = signal.lsim(sys_, f, t)
    rng = np.random.default_rng(seed)
    return f + offset_N, y + noise * rng.standard_normal(N)


def test_force_window_keeps_the_contact_less_the_offset():
    f, _ = blow(0.01, 100.0)
    w = force_window(f)
    assert w[:10].max() == 0 and w.max() == pytest.approx((f - 3.0).max())  # offset taken off
    assert np.count_nonzero(w) <= round(0.004 * FS) + 1 and w[round(0.02 * FS):].max() == 0


def test_h1_of_one_blow_is_the_exact_accelerance():
    """|H1| within 1 % of the exact accelerance from 5 to 200 Hz (the sampled half-sine's
    spectrum, read as piecewise linear by lsim, differs from the samples' by < 1 % below FS / 5),
    the phase within 0.02 rad, the peak in the bin of the damped frequency; one blow's coherence
    is 1 and the estimate says so."""
    f, a = blow(0.01, 100.0)
    est = h1_estimate(f[None], a[None, None], FS)
    band = (est.f_hz >= 5) & (est.f_hz <= 200)
    exact = accelerance(est.f_hz[band])
    ratio = est.h1[0, band] / exact
    assert np.max(np.abs(np.abs(ratio) - 1)) < 0.01
    assert np.max(np.abs(np.angle(ratio) - np.median(np.angle(ratio)))) < 0.02
    fd = FN * np.sqrt(1 - ZETA**2)
    assert abs(est.peak_hz(1.0)[0] - fd) <= FS / N
    assert est.n_blows == 1 and est.notes and np.allclose(est.coherence[0, band], 1)


def test_h1_over_blows_with_noise_and_its_coherence():
    """Five blows of different force, noise on the response: H1 stays within 5 % of the exact
    accelerance near the resonance (where the response stands far above the noise) and the
    coherence is ~1 there; where the force has no energy, the coherence drops."""
    pairs = [blow(0.01 + 0.001 * k, 50.0 + 20 * k, noise=2e-3, seed=k) for k in range(5)]
    f = np.stack([p[0] for p in pairs])
    a = np.stack([p[1] for p in pairs])[:, None, :]
    est = h1_estimate(f, a, FS)
    near = np.abs(est.f_hz - FN) < 2
    assert np.max(np.abs(np.abs(est.h1[0, near] / accelerance(est.f_hz[near])) - 1)) < 0.05
    assert est.coherence[0, near].min() > 0.99
    # at the 4 ms half-sine's first spectral zero (375 Hz) the response is the noise alone,
    # whose coherence over 5 blows is ~1/5 (chi-square): H1 there is noise over noise, so it
    # and the coherence are not given, and the note says where that starts: where the blows'
    # summed force power (the sampled half-sines' own DFT, offset off) falls 20 dB below its
    # largest (the continuous half-sine's at 326 Hz; ~4 samples of it fall faster)
    zero = np.abs(est.f_hz - 375.0) < 5
    assert np.isnan(est.h1[0, zero]).all() and np.isnan(est.coherence[0, zero]).all()
    power = np.sum(np.abs(np.fft.rfft(f - 3.0, axis=1)) ** 2, axis=0)
    expected = est.f_hz[np.argmax(power < 0.01 * power.max())]
    assert 300 < expected < 326
    assert np.isfinite(est.h1[0, est.f_hz < expected]).all()
    assert est.n_blows == 5 and len(est.notes) == 1 and "dB below its largest" in est.notes[0]
    first = float(est.notes[0].split("the first at ")[1].split(" Hz")[0])
    assert abs(first - expected) < 0.05, est.notes  # printed to 0.1 Hz


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match=r"not \(n_blows, n\)"):
        h1_estimate(np.zeros((2, 10)), np.zeros((3, 1, 10)), FS)
    with pytest.raises(ValueError, match="force is zero in every blow"):
        h1_estimate(np.zeros((1, 10)), np.ones((1, 1, 10)), FS)


def test_report_section_and_plot_from_a_trial_with_a_load_cell(tmp_path):
    """The simulator's ALBACORE-like rig with the ram's load cell, two blows, through the
    trigger: report.json's ``frf`` holds each gage's H1 in (m/s^2)/N over the accepted
    hits and frf.png is written; between 20 and 30 Hz the driving point's |H1| peaks at the
    rig's predominant mode in air (Table 2a's 24.5 Hz, within 2 %, as its decay analysis)."""
    from ramdaq.analysis.model.rig import parse_rig
    from ramdaq.daq.analyzer import HitResult
    from ramdaq.daq.reports.frf_report import frf_section, plot_frf
    from ramdaq.daq.trigger import Trigger
    from ramdaq.drivers.sim import SimDevice
    from tests.conftest import RIGS

    rig = parse_rig((RIGS / "albacore.toml").read_text() + '\n[[forces]]\nname = "ram"\n'
                    'channel = 16\n', "force.toml")
    with SimDevice(rig, duration_s=9.0, impacts=[2.0, 5.5], seed=2) as dev:
        info, blocks = dev.info, list(dev)
    trig = Trigger(info)
    events = [e for b in blocks for e in trig.process(b)] + trig.flush()
    # the hits as the analyzer accepts them (its decay analysis is not what this test is about)
    hits = [HitResult(k, e, True, "", None) for k, e in enumerate(events)]
    assert len(hits) == 2 and not any(e.double_hit or e.clipped for e in events)
    frf = json.loads(json.dumps(frf_section(rig, hits)))
    assert frf["hits"] == [0, 1] and frf["n_blows"] == 2
    assert frf["force_channel"] == "ram" and frf["units"]["h1"] == "(m/s^2)/N"
    assert len(frf["gages"]) == 16 and frf["bins_total"] == frf["samples"] // 2 + 1
    f = np.array(frf["f_hz"])
    # every bin up to the last where H1 is given, on the window's grid
    assert np.allclose(f, np.arange(f.size) / frf["window_s"]) and f.size <= frf["bins_total"]
    assert all(len(d["magnitude"]) == f.size for d in frf["gages"].values())
    band = (f >= 20) & (f <= 30)
    peaks = [f[band][np.argmax(np.array(d["magnitude"])[band])] for d in frf["gages"].values()]
    assert np.median(np.abs(np.array(peaks) / 24.5 - 1)) < 0.02, peaks
    assert plot_frf(frf, tmp_path) == [tmp_path / "frf.png"] and (tmp_path / "frf.png").exists()
    assert frf_section(parse_rig((RIGS / "albacore.toml").read_text(), "r.toml"), hits) is None


def test_window_spans_the_record_between_blows_not_8192_samples():
    """At 5000 Hz MAX_SAMPLES = 8192 cut each blow to 1.64 s (0.61 Hz bins) though 8 s
    separated them: the 12.50 Hz mode peaked at 12.21 Hz and |H1| came out 7 % high. The window
    now spans each blow's record. Checked against the exact FRF of a known two-mode system: the
    response is the force convolved with each mode's sampled kernel
    ``h_m[n] = r_m exp(-sigma_m n T) sin(wd_m n T) T``, whose transfer function is exactly
    ``r_m T e^{-sigma T} sin(wd T) z^-1 / (1 - 2 e^{-sigma T} cos(wd T) z^-1 + e^{-2 sigma T} z^-2)``."""
    from types import SimpleNamespace

    from ramdaq.analysis.model.rig import parse_rig
    from ramdaq.daq.reports.frf_report import frf_section
    from ramdaq.drivers.files.minimal_rig import minimal_rig

    fs, T = 5000.0, 1 / 5000.0
    modes = [(12.5, 0.02, 1.0), (31.0, 0.015, 0.6)]  # f (Hz), zeta, residue (m/s^2 per N s)
    n_rec, pre = round(7.9 * fs), round(0.1 * fs)
    pulse = 1000.0 * np.sin(np.pi * (np.arange(8) + 0.5) / 8)  # 1.6 ms half-sine, N
    force = np.zeros(n_rec)
    force[pre:pre + 8] = pulse
    k = np.arange(n_rec)
    kernel = np.zeros(n_rec)
    for f, z, r in modes:
        w = 2 * np.pi * f
        kernel += r * np.exp(-z * w * k * T) * np.sin(w * np.sqrt(1 - z * z) * k * T) * T
    accel = np.convolve(force, kernel)[:n_rec]
    rig = parse_rig(minimal_rig(["a", "F"], name="two-mode", fs_hz=fs, units="m/s^2",
                                force_channel="F").text, "two-mode.toml")
    hits = []
    for i in range(2):  # two blows 8 s apart, each record from 0.1 s before its onset
        first = i * round(8.0 * fs)
        rec = SimpleNamespace(fs_hz=fs, first_sample=first, counts=np.vstack([accel, force]),
                              scale=np.ones(2))
        hits.append(SimpleNamespace(index=i, accepted=True,
                                    event=SimpleNamespace(record=rec, onset_sample=first + pre)))
    frf = frf_section(rig, hits)
    assert frf["window_s"] > 7.8  # the record, not 8192 samples (1.64 s)
    f = np.array(frf["f_hz"])
    zi = np.exp(-2j * np.pi * f * T)
    exact = 0.0
    for fm, z, r in modes:
        decay, wd = np.exp(-z * 2 * np.pi * fm * T), 2 * np.pi * fm * np.sqrt(1 - z * z) * T
        exact = exact + r * T * decay * np.sin(wd) * zi / (1 - 2 * decay * np.cos(wd) * zi
                                                           + decay ** 2 * zi ** 2)
    h = np.array(frf["gages"]["g01"]["magnitude"], dtype=float)
    band = (f >= 5) & (f <= 60)
    # noise-free and linear: what is left is the ringing past the window's end, e^(-sigma 7.8 s)
    # = 5e-6 of the response for the lighter-decaying mode, and rounding; 1e-3 keeps a wide
    # margin over that and lies far below the 7 % the 1.64 s window gave
    assert np.max(np.abs(h[band] / np.abs(exact[band]) - 1)) < 1e-3
    assert abs(frf["gages"]["g01"]["peak_hz"] - 12.5) <= f[1]  # within a bin (0.127 Hz)


def test_an_import_of_fewer_channels_than_the_rig_analyses(tmp_path, capsys):
    """A new user's CSV had 12 of the rig's 16 gages (or no load-cell column): ``import`` took
    it, as it takes any subset of the rig's channels, and ``analyze`` then failed inside the FRF
    (the rig's DAQ channel numbers used as the recording's rows). The FRF now reads the rows by
    the recorded channels: the 12 recorded gages' H1, and no FRF, with the reason, when the
    force was not recorded. ``import`` says which of the rig's channels it did not fill. The
    CSV comes from ``ramdaq export-csv`` of a simulated trial with the load cell, its columns
    dropped with the csv module."""
    import csv

    from ramdaq.analysis.model.rig import parse_rig
    from ramdaq.daq.commands.cli import main
    from ramdaq.daq.record import record
    from ramdaq.drivers.sim import SimDevice
    from tests.conftest import RIGS

    text = (RIGS / "albacore.toml").read_text() + '\n[[forces]]\nname = "ram"\nchannel = 16\n'
    rig_path = tmp_path / "force.toml"
    rig_path.write_text(text)
    trial = tmp_path / "t.mcap"
    record(SimDevice(parse_rig(text, str(rig_path)), duration_s=9.0, impacts=[2.0, 5.5], seed=2),
           trial, readout=False)
    assert main(["export-csv", str(trial)]) == 0
    rows = list(csv.reader(line for line in trial.with_suffix(".csv").read_text().splitlines()
                           if not line.startswith("#")))
    cases = {"twelve": list(range(13)) + [17], "noforce": list(range(17))}  # columns kept
    assert rows[0][17] == "ram [N]" and rows[0][12] == "g12 [m/s^2]"
    for name, keep in cases.items():
        path = tmp_path / f"{name}.csv"
        path.write_text("\n".join(",".join(r[i] for i in keep) for r in rows) + "\n")
        out = tmp_path / f"{name}.mcap"
        assert main(["import", str(path), "--rig", str(rig_path), "--out", str(out)]) == 0
        said = {"twelve": "gage(s) 13, 14, 15, 16", "noforce": "force channel 'ram'"}[name]
        assert (f"warning: rig 'albacore-like' declares {said}, which no column of {name}.csv "
                "fills: not recorded") in capsys.readouterr().err
        assert main(["analyze", str(out), "--out", str(tmp_path / name), "--no-plots"]) == 0
        frf = json.loads((tmp_path / name / "report.json").read_text())["frf"]
        if name == "twelve":
            assert sorted(frf["gages"]) == [f"g{g:02d}" for g in range(1, 13)]
            f = np.array(frf["f_hz"])
            band = (f >= 20) & (f <= 30)  # the predominant mode in air, as the test above
            peaks = [f[band][np.argmax(np.array(d["magnitude"])[band])] for d in frf["gages"].values()]
            assert np.median(np.abs(np.array(peaks) / 24.5 - 1)) < 0.02, peaks
        else:
            assert frf == {"not_computed": "the rig's force channel 'ram' is not in the recording "
                           "(its channels: " + ", ".join(f"g{g:02d}" for g in range(1, 17)) + ")"}
