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
