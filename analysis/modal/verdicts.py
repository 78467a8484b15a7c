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

Checks 3-7 are read off one joint fit of the channels that pass 1-2 (and show a spectral peak):
each channel's modes significant in it alone, its own fit of them started at the shared poles;
only a channel the joint fit cannot call ``ok`` is searched on its own, as every channel was
before (:func:`assess_decay_jointly`: the same verdicts, one order search instead of one per
channel, and the fit ``analyze_decay`` goes on with);
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

from .identify import channel_periodograms, identify_modes, peak_above_noise
from .signal import noise_std_from_periodogram
from .table import ModeTable

__all__ = ["DecayAssessment", "JointAssessment", "Verdict", "assess_decay", "assess_decay_jointly"]


class Verdict(StrEnum):
    """Outcome of :func:`assess_decay` for one channel."""

    OK = "ok"
    DEAD = "dead"
    CLIPPED = "clipped"
    NO_DECAY = "no_decay"
    TOO_FEW_CYCLES = "too_few_cycles"
    NEGATIVE_DAMPING = "negative_damping"

    @property
    def text(self) -> str:
        """The verdict in a few words, for a plot's title or a table's cell."""
        return _VERDICT_TEXT[self]


_VERDICT_TEXT = {Verdict.OK: "usable", Verdict.DEAD: "dead channel", Verdict.CLIPPED: "clipped",
                 Verdict.NO_DECAY: "no free decay seen", Verdict.TOO_FEW_CYCLES: "too few cycles",
                 Verdict.NEGATIVE_DAMPING: "grows instead of decaying"}


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
        Longer channels are decimated to about this many samples before a channel's own order
        search (a verdict needs the dominant mode roughly, not to the Cramér-Rao bound).

    Returns
    -------
    list of DecayAssessment
        One per channel, in input order (:func:`assess_decay_jointly` says how they are reached).
    """
    return assess_decay_jointly(x, fs_hz, adc_full_scale=adc_full_scale, min_cycles=min_cycles,
                                min_delta=min_delta, clip_run=clip_run, false_alarm=false_alarm,
                                max_samples=max_samples).verdicts


@dataclass(frozen=True)
class JointAssessment:
    """What :func:`assess_decay_jointly` found.

    Attributes
    ----------
    verdicts : list of DecayAssessment
        One per input channel, in input order.
    table : ModeTable or None
        The joint fit (``identify_modes(x[rows], fs_hz, per_channel=True, false_alarm=...)``)
        the verdicts read; None when no channel passed the cheap checks.
    rows : tuple of int
        The input rows ``table`` was fitted on (its channel order).
    own_searches : int
        Channels whose verdict needed their own order search (any verdict but ``ok``, or an
        ``ok`` the joint fit could not vouch for).
    quiet_rows : tuple of int
        Channels among ``rows`` with no mode significant in them, in the joint fit or in their
        own search: noise only, which shaped the joint fit's modes by no more than noise.
    noise_std : numpy.ndarray, shape (n_channels,) or None
        Each input channel's white-noise std from its whole-record periodogram (in its unit;
        :func:`~ramdaq.analysis.modal.signal.estimate_noise_std`, equal to the bit or, at the
        lengths :func:`~ramdaq.analysis.modal.signal.rfft_rows` packs, to rounding), NaN for a
        channel the cheap checks (dead, clipped, too short) set aside: for the hit's peak
        decrements, which need it too.
    """

    verdicts: list[DecayAssessment]
    table: ModeTable | None
    rows: tuple[int, ...]
    own_searches: int
    quiet_rows: tuple[int, ...] = ()
    noise_std: np.ndarray | None = None


def _screen(X: np.ndarray, adc_full_scale: float | None, clip_run: int) -> dict[int, DecayAssessment]:
    """The cheap verdicts: dead, clipped, too short for any fit (by channel)."""
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
        elif n < 32:
            out[c] = DecayAssessment(c, Verdict.TOO_FEW_CYCLES, f"only {n} samples")
    return out


def assess_decay_jointly(
    x: ArrayLike,
    fs_hz: float,
    *,
    adc_full_scale: float | None = None,
    min_cycles: float = 3.0,
    min_delta: float = 1e-3,
    clip_run: int = 3,
    false_alarm: float = 1e-4,
    max_samples: int = 8000,
    band_decimation: bool = False,
) -> JointAssessment:
    """:func:`assess_decay` (same parameters and verdicts), with the joint fit it read.

    The channels that pass the cheap checks (dead, clipped, too short, no spectral peak above
    their noise: where a channel's own order search stops at its first test) are fitted together once
    (:func:`~ramdaq.analysis.modal.identify.identify_modes`, automatic order, ``per_channel``).
    A channel's verdict is then read from that fit: its modes significant in it alone (the
    energy of its linear amplitude on the shared poles against its noise, above the one-channel
    order search's threshold, χ²₂ at ``false_alarm`` / (2 n_samples)); the strongest of them is
    its dominant mode, whose f, δ and standard error are the channel's own fit started at the
    shared poles; the checks 4–7 of the module docstring run on those. Only an ``ok`` is taken
    from the joint fit: a channel with no significant mode there, a failed own fit, or any
    other verdict is judged again on its own (the channel's own order search, as each verdict
    was reached before), so that no channel's fault is borrowed from, or hidden by, the others.
    ``band_decimation``: the joint fit's (:func:`~ramdaq.analysis.modal.identify.identify_modes`).
    """
    X = np.atleast_2d(np.asarray(x, dtype=float))
    if X.ndim != 2:
        raise ValueError(f"x must have shape (n_channels, n_samples), got {X.shape}")
    if fs_hz <= 0:
        raise ValueError(f"fs_hz ({fs_hz}) must be positive")
    if adc_full_scale is not None and adc_full_scale <= 0:
        raise ValueError(f"adc_full_scale ({adc_full_scale}) must be positive")
    n_ch, n = X.shape
    out = _screen(X, adc_full_scale, clip_run)
    rest = [c for c in range(n_ch) if c not in out]
    Xr = _rows(X, rest)
    pg = channel_periodograms(Xr) if rest else {}  # read by both tests, computed once
    sigma = np.full(n_ch, np.nan)
    if rest:  # the channel's own order search would stop at its first test: no peak at all
        sigma[rest] = noise_std_from_periodogram(pg[n])
        for c, peak in zip(rest, peak_above_noise(Xr, fs_hz, false_alarm=false_alarm,
                                                  periodograms=pg, noise_std=sigma[rest]),
                           strict=True):
            if not peak:
                out[c] = DecayAssessment(c, Verdict.NO_DECAY, "no mode significantly above noise")
    rows = tuple(c for c in range(n_ch) if c not in out)
    table = None
    if rows:
        sel = [rest.index(c) for c in rows]
        table = identify_modes(_rows(X, list(rows)), fs_hz, false_alarm=false_alarm,
                               per_channel=True, periodograms={m: _rows(P, sel) for m, P in pg.items()},
                               noise_std=sigma[list(rows)], band_decimation=band_decimation)
        for j, c in enumerate(rows):
            got = _judge_from_joint(c, j, table, min_cycles, min_delta, false_alarm)
            if got is not None:
                out[c] = got
    own = [c for c in rows if c not in out]
    quiet = []
    for c in own:
        # The channel on its own: a verdict must not borrow modes from other gages.
        tab = identify_modes(X[c], fs_hz, false_alarm=false_alarm, per_channel=False,
                             max_samples=max_samples)
        out[c] = _judge(c, tab, n / fs_hz, min_cycles, min_delta)
        if len(tab) == 0 and not _significant_in(table, rows.index(c), false_alarm).size:
            quiet.append(c)
    return JointAssessment([out[c] for c in range(n_ch)], table, rows, len(own), tuple(quiet),
                           sigma)


def _rows(a: np.ndarray, idx: list[int]) -> np.ndarray:
    """``a[idx]``, or ``a`` itself where ``idx`` takes every row in order (a hit's 16 gages
    when all pass the screen: no copy of the record; nothing downstream writes to it)."""
    return a if idx == list(range(a.shape[0])) else a[idx]


def _significant_in(table: ModeTable, j: int, false_alarm: float) -> np.ndarray:
    """Indices of the joint ``table``'s modes significant in its row ``j`` alone: Λ (≈ the mode's
    energy in that channel over its noise variance, from its amplitude on the shared poles)
    above the one-channel order search's threshold, χ²₂.isf(p) = −2 ln p, p = false_alarm /
    (2 n_samples)."""
    if len(table) == 0:
        return np.empty(0, dtype=int)
    n, fs = table.n_samples, table.fs_hz
    amp = np.abs(table.complex_amplitude[j])
    sig = max(float(table.noise_std[j]), 1e-300)
    rate = table.delta * table.frequency_hz / fs  # envelope decay per sample
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        env2 = np.where(rate != 0, -np.expm1(-2.0 * rate * n) / -np.expm1(-2.0 * rate), float(n))
    energy = amp**2 * env2 / (2.0 * sig**2)
    return np.flatnonzero(energy > -2.0 * np.log(false_alarm / (2.0 * n)))


def _judge_from_joint(c: int, j: int, table: ModeTable, min_cycles: float, min_delta: float,
                      false_alarm: float) -> DecayAssessment | None:
    """Channel ``c``'s verdict from row ``j`` of the joint ``table`` when it is ``ok``; else None
    (the channel is then judged on its own)."""
    significant = _significant_in(table, j, false_alarm)
    if significant.size == 0:
        return None
    n, fs = table.n_samples, table.fs_hz
    amp = np.abs(table.complex_amplitude[j])
    sig = max(float(table.noise_std[j]), 1e-300)
    k = int(significant[np.argmax(amp[significant])])
    f, d = table.channel_frequency_hz[j, k], table.channel_delta[j, k]
    se = table.channel_delta_se[j, k]
    if not np.all(np.isfinite([f, d, se])):
        return None
    got = _judge_numbers(c, float(f), float(d), float(se), float(amp[k]) / sig, n / fs,
                         min_cycles, min_delta)
    return got if got.verdict is Verdict.OK else None


def _judge(c, tab, duration_s, min_cycles, min_delta) -> DecayAssessment:
    """Channel ``c``'s verdict from its own one-channel table ``tab``."""
    if len(tab) == 0:
        return DecayAssessment(c, Verdict.NO_DECAY, "no mode significantly above noise")
    k = int(np.argmax(tab.amplitude[0]))
    snr = tab.amplitude[0, k] / max(tab.noise_std[0], 1e-300)
    return _judge_numbers(c, tab.frequency_hz[k], tab.delta[k], tab.delta_se[k], snr, duration_s,
                          min_cycles, min_delta)


def _judge_numbers(c: int, f: float, d: float, se: float, snr: float, duration_s: float,
                   min_cycles: float, min_delta: float) -> DecayAssessment:
    """Checks 4-7 on the dominant mode: f (Hz), δ, its standard error, amplitude / noise std."""
    cycles = duration_s * f
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
