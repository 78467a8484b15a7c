"""Where an impact's record ends: its ringing's decay at the noise floor, judged window by window.

The trigger (:mod:`ramdaq.daq.trigger`) follows a blow's ringing; this watch tells it when the
record can close, so that the final analysis starts as soon as the decay has nothing more to
give rather than at the next blow. From ``min_n`` samples after the onset (the trigger's
``post_s``: the shortest record, so a final always has that much decay) the responding gages'
samples are cut into windows of :data:`WINDOW_S`, aligned to the onset. In each window the mean
square of every *predominant* gage (those whose ringing power in the first window judged is
within :data:`PREDOMINANT_DB` of the loudest's: the gages that ring longest, so the weak ones
cannot end the record early) is divided by that gage's pre-event noise power (the trigger's LTA
frozen at the blow, units^2). A window is *at the noise floor* when the mean of those ratios is
at most ``1 + Z_MARGIN * sd``, where ``sd = sqrt(2 / N_eff)`` is the relative standard deviation
of the mean square of ``N_eff`` independent Gaussian noise samples (chi-square), ``N_eff`` the
window's samples times the noise's bandwidth over Nyquist (the rig's anti-alias Butterworth,
:func:`noise_bandwidth_fraction`); the gages are taken as fully correlated (a common-mode noise
is the worst case; independent gages would narrow the margin by sqrt(gages)). So a window of
noise alone passes with probability 0.9987 (one-sided 3 sigma) and a window that fails still
holds ringing the noise cannot explain; at 2048 Hz with the rigs' 800 Hz filter a window
passes while ringing with at most ~0.33 of the noise power (amplitude ~0.8 noise rms). The
decay is at the floor when :data:`HOLD_WINDOWS` windows in a row pass; the record ends at the
last sample of the last of them.

Everything is decided from the samples alone (no wall clock), so a replay through the same
trigger ends every record at the same sample as the live trial did.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

WINDOW_S = 0.1
"""Window of the envelope, s: 1.3 periods of the 13 Hz predominant mode in water, 2.5 in air."""
MIN_WINDOW_N = 16
"""Fewest samples of a window (at low rates): a mean square of fewer is too noisy to judge."""
Z_MARGIN = 3.0
"""Standard deviations of a noise window's mean square allowed above the noise power."""
HOLD_WINDOWS = 2
"""Windows in a row at the floor: one low window between two beating modes does not end it."""
PREDOMINANT_DB = 10.0
"""Gages whose ringing power is within this of the loudest's (dB) are watched."""


def noise_bandwidth_fraction(anti_alias: tuple[int, float] | None, fs_hz: float) -> float:
    """Equivalent noise bandwidth of the anti-alias Butterworth ``(order n, corner f_c Hz)`` over
    Nyquist, in (0, 1]: ``f_c * (pi / 2n) / sin(pi / 2n) / (fs / 2)``; 1 (white noise to Nyquist)
    for ``None``, a stream whose rig names no filter."""
    if anti_alias is None:
        return 1.0
    order, corner = anti_alias
    a = math.pi / (2 * order)
    return float(min(1.0, corner * (a / math.sin(a)) / (fs_hz / 2)))


def floor_threshold(window_n: int, bandwidth: float, z: float = Z_MARGIN) -> float:
    """Largest mean of (window mean square / noise power) still at the noise floor: ``1 + z *
    sqrt(2 / N_eff)`` with ``N_eff = window_n * bandwidth`` independent samples (at least 1)."""
    return 1.0 + z * math.sqrt(2.0 / max(1.0, window_n * bandwidth))


@dataclass
class FloorWatch:
    """One ringing's decay, window by window (see the module docstring).

    ``noise`` the pre-event noise power per watched gage (units^2, shape (n,)); windows of
    ``window`` samples from ``pos`` (the first sample of the next window to judge);
    ``threshold`` from :func:`floor_threshold`; ``rows`` the predominant gages (indices into
    ``noise``, chosen on the first window judged); ``run`` windows in a row at the floor so far;
    ``end`` the record's last sample once the decay is at the floor, else None."""

    noise: np.ndarray
    window: int
    threshold: float
    pos: int
    rows: np.ndarray | None = None
    run: int = 0
    end: int | None = None

    @classmethod
    def begin(cls, noise: np.ndarray, onset: int, min_n: int, fs_hz: float,
              bandwidth: float) -> FloorWatch:
        """The watch of a blow at sample ``onset``: windows from ``onset + min_n`` on."""
        window = max(MIN_WINDOW_N, round(WINDOW_S * fs_hz))
        noise = np.maximum(np.asarray(noise, dtype=float), np.finfo(float).tiny)
        return cls(noise, window, floor_threshold(window, bandwidth), onset + min_n)

    def scan(self, read: Callable[[int, int], np.ndarray], limit: int, *,
             squared: bool = False) -> int | None:
        """Judge every whole window before sample ``limit``; ``read(a, b)`` gives the watched
        gages' samples ``a .. b-1`` (SI units, shape (n, b - a)), or with ``squared`` their
        squares (units^2; a caller that has them spares the square). The record's last sample
        once the decay is at the floor (then and ever after), else None."""
        if self.end is not None:
            return self.end
        m = (limit - self.pos) // self.window
        if m <= 0:
            return None
        x = read(self.pos, self.pos + m * self.window)
        x2 = x if squared else x * x
        ratio = x2.reshape(len(self.noise), m, self.window).mean(axis=2) / self.noise[:, None]
        if self.rows is None:
            ringing = ratio[:, 0] - 1.0
            loud = ringing >= ringing.max() * 10 ** (-PREDOMINANT_DB / 10)
            self.rows = np.flatnonzero(loud) if ringing.max() > 0 else np.arange(len(self.noise))
        at_floor = ratio[self.rows].mean(axis=0) <= self.threshold
        for k, ok in enumerate(at_floor):
            self.run = self.run + 1 if ok else 0
            if self.run >= HOLD_WINDOWS:
                self.end = self.pos + (k + 1) * self.window - 1
                return self.end
        self.pos += m * self.window
        return None
