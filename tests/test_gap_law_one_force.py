"""The homogeneity check's stiffness law (a mode's frequency moving with its amplitude within the
decays) is read across blows of different force at the same time after each blow; with blows of
one force it is not read (issue 17, a new user's finding: ALBACORE in water, five clean blows of
one force, printed "[nonlinearity] mode 6.88 Hz: its frequency falls by 3.3 % as its amplitude
grows", z 4.4 against its chance level 3.84). At one force every decay has the same amplitude at a
given time after its blow: what the slope then regresses is the reading's noise on itself."""

from __future__ import annotations

import math

import numpy as np

from ramdaq.analysis.gap.datamodel import free_modal_model
from ramdaq.analysis.gap.homogeneity import MIN_LEVEL_SPAN, decay_laws
from ramdaq.analysis.gap.sensors import check_trial
from ramdaq.daq.commands.cli import main
from ramdaq.daq.gap_trial import load_trial

FS = 2048.0
MODES = ((6.85, 0.12), (13.0, 0.10), (59.8, 0.0155))
"""Frequency (Hz) and logarithmic decrement of three linear modes, ALBACORE in water's lowest
three as the free model reads them."""
SHAPE = 9 * np.array([[0.015, 0.47, 0.44], [0.010, 0.30, 0.2], [0.008, 0.2, 0.5], [0.012, 0.1, 0.3]])
"""Each gage's (row) amplitude of each mode (column), m/s^2: the lowest mode weak everywhere
beside a strong 13 Hz one, as on ALBACORE's gage 6."""
ONSETS = np.array([5.0, 15.0, 25.0, 35.0, 45.0])


def _linear(levels: np.ndarray, seed: int) -> np.ndarray:
    """Plain numpy: the three modes' free decays after each blow (sine from rest, each blow's
    size ``levels``), white noise of 0.0044 m/s^2 rms (ALBACORE's simulated floor)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(52 * FS)) / FS
    x = 0.0044 * rng.standard_normal((SHAPE.shape[0], t.size))
    for o, b in zip(ONSETS, levels, strict=True):
        on = t >= o
        tt = t[on] - o
        for (f, d), col in zip(MODES, SHAPE.T, strict=True):
            x[:, on] += b * np.outer(col, np.exp(-d * f * tt) * np.sin(2 * math.pi * f * tt))
    return x


def _laws(x: np.ndarray):
    fm = free_modal_model(x, FS, ONSETS)
    snr = np.median(fm.snr(), axis=0)
    ks = np.flatnonzero(snr.max(axis=0) >= 30)
    return decay_laws(x, fm, ks, [int(np.argmax(snr[:, k])) for k in ks], [1, 2, 3, 4])


def test_blows_of_one_force_read_no_stiffness_law():
    laws = _laws(_linear(np.ones(ONSETS.size), seed=1))
    assert len(laws) >= 2
    # not read: no z, no size (the old reading gave |z| up to 2.7 on these records' seeds 0-3)
    assert all(w.z_stiffness == 0.0 and math.isnan(w.df_rel) for w in laws), laws


def test_blows_of_different_force_read_it_and_a_linear_structure_passes():
    levels = np.array([1.0, 0.5, 2.0, 0.7, 1.4])          # the benchmark's 0.5-2x
    assert np.ptp(np.log(levels)) >= MIN_LEVEL_SPAN
    laws = _laws(_linear(levels, seed=1))
    read = [w for w in laws if math.isfinite(w.df_rel)]
    assert len(read) >= 2, laws
    # linear: each slope's z is standard normal; 4.0 is its 1e-3 two-sided level Bonferroni over
    # some ten slopes, as the check's own chance level (3.84 over six)
    assert all(abs(w.z_stiffness) < 4.0 for w in read), read


def test_albacore_five_clean_blows_of_one_force_raise_no_nonlinearity(tmp_path):
    """The new user's trial as they made it (`ramdaq trial ... --duration 50 --impact-every 10`,
    seed 0): before, its homogeneity check named an amplitude-dependent stiffness."""
    out = tmp_path / "trial.mcap"
    main(["trial", "--rig", "albacore", "--medium", "water", "--duration", "50", "--impact-every", "10",
          "--seed", "0", "--fast", "--quiet", "--no-rerun", "--out", str(out)])
    lt = load_trial(out)
    assert len(lt.onsets_s) == 5
    dc = check_trial(lt.x, lt.fs_hz, lt.onsets_s, lt.rig.gages_by_channel())
    assert not [f for f in dc.findings if f.check == "homogeneity"], [f.text for f in dc.findings]
