"""How much of each identified mode was already there before the blow: a line that rang at
the same amplitude before the ram struck (an ambient tone, a machine on the hull) is not the
blow's free decay, whatever decrement its fit gives, and cannot be the predominant mode."""

from __future__ import annotations

import numpy as np

AMBIENT_RATIO = 0.5
"""A mode whose amplitude before the blow is at least this fraction of its amplitude at the
decay's start is an ambient line: then at least a quarter of its energy in the decay is not
the blow's (a steady part, not a free decay). On the shipped samples the ambient hull tone of
``sampson-water`` reads 0.95; every mode the blow excites reads below 0.2 (the previous blow's
ringing still fading, 0.5 s before the next, included)."""


def ratio_before_blow(pre: np.ndarray, fs_hz: float, f_hz: np.ndarray,
                      amplitude: np.ndarray) -> np.ndarray:
    """Each mode's amplitude in the pre-trigger window over its amplitude at the decay's start.

    ``pre`` (n_channels, n) m/s^2, the samples before the blow; ``f_hz`` (n_modes,) the modes'
    frequencies; ``amplitude`` (n_channels, n_modes) their amplitudes at the decay's start on
    the same channels. Each channel's pre-trigger line at ``f_hz`` is a least-squares sine,
    cosine and offset; the ratio is of root-sum-squares over channels, (n_modes,). NaN where
    the window is shorter than half a period of the mode or holds no sample."""
    n = pre.shape[1]
    t = np.arange(n) / fs_hz
    out = np.full(len(f_hz), np.nan)
    post = np.sqrt(np.sum(np.abs(amplitude) ** 2, axis=0))
    for k, f in enumerate(np.asarray(f_hz, dtype=float)):
        if n == 0 or n / fs_hz < 0.5 / f or not post[k] > 0:
            continue
        basis = np.stack([np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t), np.ones(n)], axis=1)
        coef = np.linalg.lstsq(basis, pre.T, rcond=None)[0]
        out[k] = float(np.sqrt(np.sum(coef[0] ** 2 + coef[1] ** 2)) / post[k])
    return out


def ambient_modes(pre: np.ndarray | None, fs_hz: float, f_hz: np.ndarray,
                  amplitude: np.ndarray) -> list[tuple[int, float]]:
    """``[(mode index, ratio), ...]`` of the modes :func:`ratio_before_blow` finds ambient
    (ratio >= :data:`AMBIENT_RATIO`); none without a pre-trigger window."""
    if pre is None:
        return []
    r = ratio_before_blow(pre, fs_hz, f_hz, amplitude)
    return [(k, float(v)) for k, v in enumerate(r) if v >= AMBIENT_RATIO]
