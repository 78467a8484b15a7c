"""Six blows of 0.5-2x the unit blow (a 4 ms half sine) ringing one mode through the modal
family's own integrator (:mod:`ramdaq.analysis.truth.modal_family`): the homogeneity tests' trial,
shared by ``test_modal_family`` and ``test_gap_early_shift``."""

from __future__ import annotations

import math

import numpy as np
import scipy.signal

from ramdaq.analysis.truth import modal_family as mf

FS_HZ = 1024.0
"""Sample rate of the blows' records, Hz."""
ONSETS_S = 1.0 + 3.0 * np.arange(6)
"""Blow times, s: 3 s apart in a 19 s record."""
PEAKS = np.array([1.0, 0.5, 2.0, 0.7, 1.4, 1.0])
"""Each blow's force over the unit blow's."""
CONTACT_S = 0.004
"""The half sine's contact time, s."""


def unit_amplitude(f_hz: float) -> float:
    """The unit blow's displacement amplitude on a mode of ``f_hz`` (impulse / w)."""
    return 2 * CONTACT_S / math.pi / (2 * math.pi * f_hz)


def rung_mode(f_hz: float, zeta: float, law: dict | None = None) -> np.ndarray:
    """One mode's displacement (n,) at :data:`FS_HZ` over 19 s, rung by the six blows, with
    ``law`` (:func:`~ramdaq.analysis.truth.modal_family.nonlinear_mode`'s keywords; linear when
    empty or None)."""
    dt = 1 / FS_HZ
    t = np.arange(int(19.0 * FS_HZ)) * dt
    force = mf.half_sine(ONSETS_S, PEAKS, CONTACT_S, t)
    if law:
        return mf.nonlinear_mode(f_hz, zeta, force, dt, **law)[0]
    return scipy.signal.lfilter(*mf.mode_filter(f_hz, zeta, dt), force)


def struck(delay_s: float, rho: float, seed: int = 0) -> np.ndarray:
    """Two linear modes (60 Hz at 1 %, 25 Hz at 0.5 %) at three gages, the six blows each
    followed (``rho`` > 0) by the same half sine ``rho`` times as large ``delay_s`` later
    (a double hit), through the modal family's own mode filter; white noise at 1e-4 of the
    largest peak. (3, n) at :data:`FS_HZ`."""
    dt = 1 / FS_HZ
    t = np.arange(int(19.0 * FS_HZ)) * dt
    force = mf.half_sine(ONSETS_S, PEAKS, CONTACT_S, t)
    if rho > 0:
        force = force + mf.half_sine(ONSETS_S + delay_s, rho * PEAKS, CONTACT_S, t)
    q = scipy.signal.lfilter(*mf.mode_filter(60.0, 0.01, dt), force)
    q2 = scipy.signal.lfilter(*mf.mode_filter(25.0, 0.005, dt), force)
    q2 *= 0.5 * np.abs(q).max() / np.abs(q2).max()
    x = np.outer([1.0, 0.6, -0.4], q) + np.outer([0.3, 1.0, 0.8], q2)
    return x + 1e-4 * np.abs(x).max() * np.random.default_rng(seed).standard_normal(x.shape)
