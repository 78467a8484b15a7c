"""A double hit whose second contact is still under way when the data layer's early window opens
(issue 17, modal benchmark seed 556003: a second blow 17.5 ms after the first at 34 %, the window
from 16 ms) is held out as the contact it was measured to be, not as an impulse: the impulse's
correction closed 37 % of the held-out blow's misfit and the double hit was answered
"unexplained"."""

from __future__ import annotations

import math

import numpy as np
import scipy.signal

from ramdaq.analysis.gap.datamodel import free_modal_model
from ramdaq.analysis.gap.signal_checks import EARLY_FROM_S, double_hits

FS = 2048.0
ONSETS = 2.0 + 4.0 * np.arange(6)
LEVELS = np.array([1.0, 0.5, 2.0, 0.7, 1.4, 1.0])
CONTACT_S = 0.0048
DELAY_S = 0.0175
RHO = 0.34
MODES = ((13.1, 0.02), (58.4, 0.01), (215.0, 0.003))
"""Frequency (Hz) and damping ratio of three modes."""
SHAPES = np.array([[1.0, 0.6, 0.3], [0.7, -0.5, 0.8], [0.4, 1.0, -0.6], [-0.3, 0.8, 1.0]])


def _half_sines(t: np.ndarray, starts: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    f = np.zeros_like(t)
    for a, b in zip(starts, sizes, strict=True):
        on = (t >= a) & (t < a + CONTACT_S)
        f[on] += b * np.sin(math.pi * (t[on] - a) / CONTACT_S)
    return f


def _record(seed: int) -> np.ndarray:
    """Plain numpy and scipy.signal: each blow a 4.8 ms half sine and a second one 17.5 ms later at
    34 %, through three second-order modes (acceleration of a unit modal mass, discretised by the
    bilinear transform at 16x the rate, then decimated), white noise at 1e-4 of the peak. (4, n)."""
    up = 16
    t = np.arange(int(26.0 * FS * up)) / (FS * up)
    force = _half_sines(t, ONSETS, LEVELS) + _half_sines(t, ONSETS + DELAY_S, RHO * LEVELS)
    x = np.zeros((SHAPES.shape[0], t.size // up))
    for (f, z), col in zip(MODES, SHAPES.T, strict=True):
        w = 2 * math.pi * f
        b, a = scipy.signal.bilinear([1.0, 0.0, 0.0], [1.0, 2 * z * w, w * w], fs=FS * up)
        x += np.outer(col, scipy.signal.lfilter(b, a, force)[::up] / (w * CONTACT_S))
    rng = np.random.default_rng(seed)
    return x + 1e-4 * np.abs(x).max() * rng.standard_normal(x.shape)


def test_a_second_contact_under_way_in_the_early_window_closes_held_out():
    assert DELAY_S - EARLY_FROM_S < CONTACT_S        # the case: the second contact spans the start
    x = _record(seed=0)
    fm = free_modal_model(x, FS, ONSETS)
    (f,) = double_hits(x, FS, ONSETS, [1, 2, 3, 4], fm)
    delay = dict((k, v) for k, v, _ in f.more)["delay_s"]
    # the measurement itself: the delay within a sample, the size within 10 %
    assert abs(delay - DELAY_S) < 1 / FS and abs(f.size / RHO - 1) < 0.1, f.text
    # the correction, read on the other blows, is the law itself: what it leaves held out is
    # noise and the contact's discretisation (measured 0.97 on the benchmark's trial); an
    # impulse left over half of the misfit
    assert f.closed_held > 0.9, (f.closed_held, f.text)
