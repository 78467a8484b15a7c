"""Driving-point frequency response functions from a force channel and the gages' acceleration
over a trial's blows: the H1 estimate and its coherence.

For blows ``k`` with force spectrum ``F_k(f)`` (N s) and acceleration spectra ``A_k(f)``
(m/s^2 s) of each gage, ``H1 = sum_k conj(F_k) A_k / sum_k |F_k|^2`` in (m/s^2)/N (accelerance),
and the ordinary coherence ``|sum_k conj(F_k) A_k|^2 / (sum_k |F_k|^2 sum_k |A_k|^2)`` (0..1;
1 at every frequency for a single blow, which then says nothing). H1 is the estimate that
noise on the response does not bias.

Each blow's force is cut to its contact (a *force window*: the samples from its start to the last
one at or above 5 % of its peak, the rest zero) after its baseline (the median over the blow's
record: a load cell's offset) is taken off, so the noise of the force channel between blows does
not enter ``F``. An exponential window on both signals (time constant ``exp_tau_s``) can force a
ringing that outlasts the record to decay in it; it adds ``1 / (2 pi f tau)`` to every mode's
damping ratio, which :class:`FrfEstimate` records.

Where the blows put almost no force (a half-sine of contact ``T`` has none at ``1.5/T``, ``2.5/T``,
...; a hard hammer tip above its band) ``|F|`` is the force channel's noise and ``A / F`` is noise
over noise: H1 and coherence are NaN at every frequency whose force power is more than
:data:`FORCE_RANGE_DB` below its largest, and a note says from where (the usable band of an impact
test ends where the force spectrum has fallen 10-20 dB: Ewins, *Modal testing*, 2nd ed., 3.9).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CONTACT_FRACTION", "FORCE_RANGE_DB", "FrfEstimate", "force_window", "h1_estimate"]

CONTACT_FRACTION = 0.05
"""A blow's contact: where its force is at least this fraction of its peak (as the analyzer's)."""
FORCE_RANGE_DB = 20.0
"""H1 is given where the blows' force power is within this many dB of its largest (module
docstring); elsewhere NaN."""


@dataclass(frozen=True)
class FrfEstimate:
    """H1 over ``n_blows`` blows: ``f_hz`` (n_f,), Hz; ``h1`` (n_gages, n_f) complex, (m/s^2)/N;
    ``coherence`` (n_gages, n_f), 0..1; ``exp_tau_s`` the exponential window's time constant, s
    (None: none); ``notes`` what the numbers cannot say (a single blow's coherence)."""

    f_hz: np.ndarray
    h1: np.ndarray
    coherence: np.ndarray
    n_blows: int
    exp_tau_s: float | None
    notes: tuple[str, ...] = ()

    def peak_hz(self, f_min_hz: float = 0.0) -> np.ndarray:
        """Frequency of each gage's largest ``|H1|`` at or above ``f_min_hz``, Hz, (n_gages,)."""
        keep = self.f_hz >= f_min_hz
        i = np.argmax(np.nan_to_num(np.abs(self.h1[:, keep]), nan=-1.0), axis=1)
        return self.f_hz[keep][i]


def force_window(force: np.ndarray) -> np.ndarray:
    """``force`` (N, (n,)) less its median, zero outside its contact: from the first sample to
    the last at or above :data:`CONTACT_FRACTION` of the peak. A blow whose record starts at its
    onset; an all-zero force stays zero."""
    f = np.asarray(force, dtype=np.float64)
    f = f - np.median(f)
    peak = np.max(np.abs(f)) if f.size else 0.0
    if not peak > 0:
        return np.zeros_like(f)
    last = int(np.flatnonzero(np.abs(f) >= CONTACT_FRACTION * peak)[-1])
    out = np.zeros_like(f)
    out[:last + 1] = f[:last + 1]
    return out


def h1_estimate(force: np.ndarray, accel: np.ndarray, fs_hz: float, *,
                exp_tau_s: float | None = None) -> FrfEstimate:
    """H1 and coherence of each gage over the blows.

    Parameters
    ----------
    force : numpy.ndarray, shape (n_blows, n)
        Each blow's force from its onset, N.
    accel : numpy.ndarray, shape (n_blows, n_gages, n)
        The gages' acceleration over the same samples, m/s^2.
    fs_hz : float
        Sample rate, Hz.
    exp_tau_s : float, optional
        Time constant of an exponential window on both signals, s.

    Raises
    ------
    ValueError
        Shapes that do not match, fewer than 2 samples, no blow, or a force of zero in every blow.
    """
    force, accel = np.asarray(force, dtype=np.float64), np.asarray(accel, dtype=np.float64)
    if force.ndim != 2 or accel.ndim != 3 or accel.shape[0] != force.shape[0] \
            or accel.shape[2] != force.shape[1]:
        raise ValueError(f"h1_estimate: force {force.shape} and accel {accel.shape} are not "
                         f"(n_blows, n) and (n_blows, n_gages, n)")
    n_blows, n = force.shape
    if n_blows < 1 or n < 2 or not fs_hz > 0:
        raise ValueError(f"h1_estimate: {n_blows} blows of {n} samples at {fs_hz} Hz")
    f = np.stack([force_window(row) for row in force])
    a = accel - accel.mean(axis=2, keepdims=True)
    if exp_tau_s is not None:
        w = np.exp(-np.arange(n) / (exp_tau_s * fs_hz))
        f, a = f * w, a * w
    F = np.fft.rfft(f, axis=1) / fs_hz           # N s
    A = np.fft.rfft(a, axis=2) / fs_hz           # m/s^2 s
    gff = np.sum(np.abs(F) ** 2, axis=0)         # (n_f,)
    if not np.any(gff > 0):
        raise ValueError("h1_estimate: the force is zero in every blow")
    gfa = np.sum(np.conj(F)[:, None, :] * A, axis=0)  # (n_gages, n_f)
    gaa = np.sum(np.abs(A) ** 2, axis=0)
    excited = gff >= gff.max() * 10 ** (-FORCE_RANGE_DB / 10)
    with np.errstate(invalid="ignore", divide="ignore"):
        h1 = np.where(excited, gfa / gff, np.nan)
        coh = np.where(excited & (gaa > 0), np.abs(gfa) ** 2 / (gff * gaa), np.nan)
    f_hz = np.fft.rfftfreq(n, 1 / fs_hz)
    notes = ("one blow: its coherence is 1 at every frequency and says nothing",) \
        if n_blows == 1 else ()
    if not excited.all():
        notes += (f"H1 not given at {int(np.sum(~excited))} of {excited.size} frequencies, the "
                  f"first at {f_hz[np.argmin(excited)]:.1f} Hz: the force there is more than "
                  f"{FORCE_RANGE_DB:g} dB below its largest",)
    return FrfEstimate(f_hz, h1, np.clip(coh, 0.0, 1.0), n_blows, exp_tau_s, notes)
