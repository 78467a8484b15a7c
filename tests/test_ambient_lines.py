"""A line that rang before the blow is not the blow's predominant mode.

The decay is built here in plain numpy (two damped sines and a steady tone, shapes and noise
chosen by hand, nothing from the simulator): the tone's displacement is the largest on the
rudder gages, as a hull tone's is, and before this check it was taken as the predominant mode
with its near-zero decrement. Then the shipped SAMPSON sample, whose 2.18 Hz hull line rings
before and after each blow (recordings/README.md)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ramdaq.analysis.impact import analyze_decay
from ramdaq.analysis.modal.before_blow import AMBIENT_RATIO, ratio_before_blow
from ramdaq.daq.commands.cli import main

FS = 1024.0
SAMPLES = Path(__file__).resolve().parents[1] / "recordings"


def _decay_with_tone(n_gages: int, seconds: float, pre_s: float, seed: int = 7):
    """(pre, x): ``pre_s`` of the tone and noise before the blow, then ``seconds`` of two
    free decays (9 Hz, delta 0.08; 31 Hz, delta 0.04) plus the same tone (2.5 Hz, 0.06 m/s^2:
    0.24 mm of displacement against the 9 Hz mode's 0.16 mm) and white noise, m/s^2."""
    rng = np.random.default_rng(seed)
    t_all = np.arange(int((pre_s + seconds) * FS)) / FS
    shape9 = np.linspace(1.0, 0.4, n_gages)
    shape31 = np.cos(np.linspace(0, np.pi, n_gages))
    tone = 0.06 * np.cos(2 * np.pi * 2.5 * t_all + 0.3)[None, :] * np.linspace(0.8, 1.2, n_gages)[:, None]
    t = t_all - pre_s
    on = t >= 0
    free = np.zeros((n_gages, t.size))
    for f, d, a, shape in ((9.0, 0.08, 0.5, shape9), (31.0, 0.04, 0.3, shape31)):
        free[:, on] += a * shape[:, None] * np.exp(-d * f * t[on]) * np.sin(2 * np.pi * f * t[on])
    y = tone + free + 0.002 * rng.standard_normal(tone.shape)
    k = int(pre_s * FS)
    return y[:, :k], y[:, k:]


def test_a_steady_tone_is_ambient_and_the_blows_mode_predominant(albacore):
    gages = (1, 2, 3, 4, 6, 7, 8)  # rudder gages of the ALBACORE-like rig (only bodies are read)
    pre, x = _decay_with_tone(len(gages), 6.0, 0.5)
    without = analyze_decay(x, FS, albacore, gages)
    with_pre = analyze_decay(x, FS, albacore, gages, pre=pre)
    f_without = without.modes.frequency_hz[without.predominant]
    f_with = with_pre.modes.frequency_hz[with_pre.predominant]
    assert abs(f_without - 2.5) < 0.05  # the failure this guards against
    assert abs(f_with - 9.0) < 0.05
    # the 9 Hz decay's own decrement, within 5 % (noise 0.002 against 0.5: far below it)
    assert with_pre.modes.delta[with_pre.predominant] == pytest.approx(0.08, rel=0.05)
    assert any(n.startswith("2.50 Hz rang before the blow") for n in with_pre.notes)


def test_the_ratio_reads_a_tone_as_one_and_a_free_decay_as_noise():
    pre, x = _decay_with_tone(4, 6.0, 0.5)
    amp = np.array([[0.06 * g, 0.5 * s] for g, s in zip(np.linspace(0.8, 1.2, 4), np.linspace(1, 0.4, 4),
                                                       strict=True)])
    r = ratio_before_blow(pre, FS, np.array([2.5, 9.0]), amp)
    # the tone: its own amplitude before and after (1 within the 0.5 s window's noise: the
    # noise's 0.002 spread over 512 samples is ~1e-4, 0.2 % of the tone); the decay: only noise
    assert r[0] == pytest.approx(1.0, abs=0.02) and r[0] >= AMBIENT_RATIO
    assert r[1] < 0.01


def test_the_sampson_sample_is_analysed_on_its_rudder_mode(tmp_path, capsys):
    """docs/model.md: the SAMPSON-like rig in water has its predominant mode at 7.598 Hz; the
    2.18 Hz hull line rings before and after each blow."""
    assert main(["analyze", str(SAMPLES / "sampson-water.mcap"), "--no-plots", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "note: 2.18 Hz rang before the blow" in out
    doc = json.loads((tmp_path / "report.json").read_text())
    for imp in doc["impacts"]:
        a = imp["analysis"]
        assert abs(a["f_hz"] - 7.598) < 0.01
        assert a["damping"]["delta_modal"] > 0


def test_a_live_first_look_is_on_the_rudder_mode_too(sampson):
    """The live session's first looks carry the blow's pre-trigger window: on the SAMPSON-like
    rig in water (its hull tone at 2.18 Hz rings before the blow) each look computed reads the
    7.598 Hz mode, as the final does (looks run at once here, in the main thread)."""
    from ramdaq.daq.analyzer import run_job
    from ramdaq.daq.session import Session
    from ramdaq.drivers.sim import SimDevice

    dev = SimDevice(sampson.with_medium("water"), duration_s=5.0, impacts=[3.0], seed=3)
    session = Session(dev, readout=False)
    looks = []

    def look_now(job):
        assert job.pre is not None and job.pre.shape[1] == round(0.5 * dev.info.fs_hz)
        done = run_job(job, session.info, session.rig, session._gages)
        looks.append(done.look)
        return True

    session._jobs.put_look = look_now
    for block in dev:
        session._take(block, None)
    seen = [lk.f_hz for lk in looks if lk is not None]
    assert seen and all(abs(f - 7.598) < 0.1 for f in seen), seen
