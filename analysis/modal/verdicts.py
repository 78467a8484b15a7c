"""Verdicts on whether each channel's free decay can give a decrement at all.

:func:`assess_decay` answers per channel with a :class:`Verdict` and a one-line reason instead of
a number when the record cannot support one. Checks, in order:

1. ``dead`` — non-finite samples, or a flat (constant) channel;
2. ``clipped`` — samples at the rail: with ``adc_full_scale`` given, samples within 0.1 % of ±full
   scale in runs of ≥ 2 or ≥ ``clip_run`` in all; and in any case (an amplifier may saturate below
   the converter's rail) a run of ≥ ``clip_run`` samples exactly at the channel's maximum or
   minimum that either recurs on two or more peaks or lasts ≥ 3 % of the dominant period (an
   unclipped peak repeats its extreme only by quantisation: a coarsely quantised, noise-free
   steady tone can trip this);
3. ``no_decay`` — no mode significantly above noise (order selection of
   :func:`ramdaq.analysis.modal.identify.identify_modes`, run on the channel alone, finds none);
4. ``too_few_cycles`` — the dominant mode spans fewer than ``min_cycles`` periods above noise
   (record length × f, or ln(A/σ)/δ cycles before it sinks into noise, whichever is less);
5. ``negative_damping`` — dominant mode's δ below zero by more than 3 standard errors (growing);
6. ``no_decay`` — δ within 3 standard errors of zero (or below ``min_delta``): a steady tone;
7. ``ok``.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from numpy.typing import ArrayLike

from .identify import identify_modes

__all__ = ["DecayAssessment", "Verdict", "assess_decay"]


class Verdict(StrEnum):
    """Outcome of :func:`assess_decay` for one channel."""

    OK = "ok"
    DEAD = "dead"
    CLIPPED = "clipped"
    NO_DECAY = "no_decay"
    TOO_FEW_CYCLES = "too_few_cycles"
    NEGATIVE_DAMPING = "negative_damping"


@dataclass(frozen=True)
class DecayAssessment:
    """Verdict on one channel.

    Attributes
    ----------
    channel : int
        Row index in the input.
    verdict : Verdict
        What was found.
    reason : str
        One line saying why, with the numbers behind it.
    f_hz, delta : float
        Dominant mode's frequency (Hz) and decrement where they were estimated, else NaN.
    """

    channel: int
    verdict: Verdict
    reason: str
    f_hz: float = float("nan")
    delta: float = float("nan")


def _runs(mask: np.ndarray) -> np.ndarray:
    """Lengths of the runs of True in a boolean vector."""
    edges = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)


def _dominant_period_samples(x: np.ndarray) -> float:
    X = np.abs(np.fft.rfft(x - x.mean()))
    k = int(np.argmax(X[1:]) + 1)
    return x.size / k


def _clipping(x: np.ndarray, adc_full_scale: float | None, clip_run: int) -> str | None:
    if adc_full_scale is not None:
        at_rail = np.abs(x) >= (1.0 - 1e-3) * adc_full_scale
        runs = _runs(at_rail)
        if runs.size and (runs.max() >= 2 or runs.sum() >= clip_run):
            return (f"{int(runs.sum())} samples at the ±{adc_full_scale:g} rail "
                    f"(longest run {int(runs.max())})")
    period = None  # dominant period: an FFT, needed only when a flat run is found
    for name, ext in (("maximum", x.max()), ("minimum", x.min())):
        runs = _runs(x == ext)
        runs = runs[runs >= 2]
        if runs.size == 0 or runs.max() < clip_run:
            continue
        if period is None and runs.size < 2:
            period = _dominant_period_samples(x)
        if runs.size >= 2 or runs.max() >= 0.03 * period:
            return (f"{int(runs.sum())} samples flat at the {name} {ext:.6g} on {runs.size} "
                    f"peak(s) (longest run {int(runs.max())})")
    return None


def assess_decay(
    x: ArrayLike,
    fs_hz: float,
    *,
    adc_full_scale: float | None = None,
    min_cycles: float = 3.0,
    min_delta: float = 1e-3,
    clip_run: int = 3,
    false_alarm: float = 1e-4,
    max_samples: int = 8000,
) -> list[DecayAssessment]:
    """Judge whether each channel holds a usable free decay.

    Parameters
    ----------
    x : array_like, shape (n_channels, n_samples) or (n_samples,)
        Free decay starting at the start of the decay.
    fs_hz : float
        Sample rate (Hz).
    adc_full_scale : float, optional
        Converter full scale in the unit of `x`; without it clipping is detected as flat extremes.
    min_cycles : float
        Fewest periods of the dominant mode above noise for a decrement.
    min_delta : float
        Decrements below this count as no decay.
    clip_run : int
        Consecutive samples at an extreme that make a flat top.
    false_alarm : float
        Passed to :func:`~ramdaq.analysis.modal.identify.identify_modes` (spurious-mode probability).
    max_samples : int
        Longer channels are decimated to about this many samples before the verdict's fit (a
        verdict needs the dominant mode roughly, not to the Cramér-Rao bound; this keeps 16
        channels of a long decay to a fraction of a second each).

    Returns
    -------
    list of DecayAssessment
        One per channel, in input order.
    """
    X = np.atleast_2d(np.asarray(x, dtype=float))
    if X.ndim != 2:
        raise ValueError(f"x must have shape (n_channels, n_samples), got {X.shape}")
    if fs_hz <= 0:
        raise ValueError(f"fs_hz ({fs_hz}) must be positive")
    if adc_full_scale is not None and adc_full_scale <= 0:
        raise ValueError(f"adc_full_scale ({adc_full_scale}) must be positive")
    n_ch, n = X.shape
    out: dict[int, DecayAssessment] = {}
    for c in range(n_ch):
        xc = X[c]
        if not np.all(np.isfinite(xc)):
            out[c] = DecayAssessment(c, Verdict.DEAD, "non-finite samples")
        elif np.ptp(xc) == 0:
            out[c] = DecayAssessment(c, Verdict.DEAD, f"flat at {xc[0]:.6g} for {n} samples")
        elif (why := _clipping(xc, adc_full_scale, clip_run)) is not None:
            out[c] = DecayAssessment(c, Verdict.CLIPPED, why)
    for c in range(n_ch):
        if c in out:
            continue
        if n < 32:
            out[c] = DecayAssessment(c, Verdict.TOO_FEW_CYCLES, f"only {n} samples")
            continue
        # Each channel on its own: a verdict must not borrow modes from other gages.
        tab = identify_modes(X[c], fs_hz, false_alarm=false_alarm, per_channel=False,
                             max_samples=max_samples)
        out[c] = _judge(c, tab, n / fs_hz, min_cycles, min_delta)
    return [out[c] for c in range(n_ch)]


def _judge(c, tab, duration_s, min_cycles, min_delta) -> DecayAssessment:
    if len(tab) == 0:
        return DecayAssessment(c, Verdict.NO_DECAY, "no mode significantly above noise")
    k = int(np.argmax(tab.amplitude[0]))
    f, d, se = tab.frequency_hz[k], tab.delta[k], tab.delta_se[k]
    cycles = duration_s * f
    snr = tab.amplitude[0, k] / max(tab.noise_std[0], 1e-300)
    if d > 0 and snr > 1:
        cycles = min(cycles, np.log(snr) / d)
    if cycles < min_cycles:
        return DecayAssessment(c, Verdict.TOO_FEW_CYCLES,
                               f"{cycles:.1f} cycles of {f:.4g} Hz above noise (< {min_cycles:g})",
                               f, d)
    if d < -3.0 * se:
        return DecayAssessment(c, Verdict.NEGATIVE_DAMPING,
                               f"growing oscillation at {f:.4g} Hz: delta {d:.4g} ± {se:.2g}", f, d)
    if d < max(3.0 * se, min_delta):
        return DecayAssessment(c, Verdict.NO_DECAY,
                               f"steady oscillation at {f:.4g} Hz: delta {d:.3g} ± {se:.2g}", f, d)
    return DecayAssessment(c, Verdict.OK, f"{f:.4g} Hz, delta {d:.4g} ± {se:.2g}", f, d)
