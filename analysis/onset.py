"""Impact onset maths: streaming STA/LTA, AIC and hinge-fit onset pickers, AR whitening.

Pure functions over arrays in samples (the caller turns seconds into samples), after ObsPy's
``obspy.signal.trigger`` but with the streaming state explicit, as ``scipy.signal.lfilter``'s
``zi``: a function that runs block by block returns ``(output, state)`` and, fed its own state,
gives the same numbers as one call on the whole record.

* :func:`recursive_sta_lta` -- the recursive short-term / long-term average ratio of
  Withers et al. (1998), as ObsPy's ``recursive_sta_lta``, on every row of ``x`` at once through
  ``lfilter`` (C speed). :func:`recursive_sta_lta_ref` is its plain-loop reference twin.
  Unlike ObsPy, sample 0 is used (ObsPy's loop starts at 1); like ObsPy the ratio is 0 until
  ``nlta`` samples have been seen.
* :func:`exp_average` -- the recursion itself, ``y[i] = y[i-1] + (x[i] - y[i-1]) / n``;
  :func:`exp_average_last` its last value alone (a matrix-vector product, no recursion).
* :func:`aic` / :func:`aic_pick` -- Maeda's (1985) Akaike information criterion picker, summed
  over channels (independent Gaussian channels add their log-likelihoods).
* :func:`hinge_onset` -- a sub-sample onset: every channel is fitted, in one least-squares
  problem per trial onset ``h``, by a straight baseline (pre-event level and slow drift, such as a
  steady hull tone) plus, from ``h`` on, a rising edge ``a (t-h) + b (t-h)**2`` (a half-sine blow
  starts as a ramp, and the modes it drives as ``(t-h)**2``); ``h`` minimises the noise-weighted
  residual. Through a low-pass front end the fitted edge lies one group delay late:
  :func:`butterworth_delay_s` gives it for the rig's anti-alias filter.
* :func:`ar_prediction_filter` -- one autoregressive prediction-error filter shared by all
  channels (they ring with the same modes, so the same poles). Applied to a ringing record it
  leaves white noise plus the *innovations*: a new blow stands out sharply from the ringing of
  the previous one, which is how a double hit is found.
* :func:`next_trigger` (on/off hysteresis, ObsPy's ``trigger_onset`` one onset at a time) and
  :func:`first_hold` (a condition held for n samples) carry their state across blocks too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from . import filters

__all__ = [
    "CONTACT_FRACTION", "StaLtaState", "aic", "aic_pick", "ar_prediction_filter",
    "BLOW_WINDOW_S", "NO_BLOW_RATIO", "band_energy_ratio", "butterworth_delay_s",
    "contact_duration_s",
    "exp_average", "exp_average_last", "first_hold", "hinge_onset", "next_trigger", "prediction_error",
    "recursive_sta_lta", "recursive_sta_lta_ref",
]


def _check_n(name: str, n: int) -> int:
    if isinstance(n, bool) or int(n) != n or n < 1:
        raise ValueError(f"{name} ({n}) must be a whole number of samples >= 1")
    return int(n)


def exp_average(x: np.ndarray, n: int, last: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """Recursive (exponential) average along the last axis: ``y[i] = y[i-1] + (x[i]-y[i-1])/n``.

    Parameters
    ----------
    x : numpy.ndarray, shape (..., n_samples)
        Input, float64 (typically squared samples, so units^2).
    n : int
        Averaging length in samples (time constant ~ ``n`` samples), >= 1.
    last : numpy.ndarray, shape (...), optional
        ``y`` of the sample before ``x[..., 0]`` (the state); zeros if omitted.

    Returns
    -------
    y : numpy.ndarray, shape like ``x``
    last : numpy.ndarray, shape (...)
        ``y[..., -1]``, to pass to the next call (unchanged for an empty ``x``).
    """
    c = 1.0 / _check_n("n", n)
    x = np.asarray(x, dtype=np.float64)
    prev = np.zeros(x.shape[:-1]) if last is None else np.asarray(last, dtype=np.float64)
    if x.shape[-1] == 0:
        return x.copy(), prev.copy()
    y = filters.exp_filter(x, c, prev)
    return y, y[..., -1].copy()


def exp_average_last(x: np.ndarray, n: int, last: np.ndarray | None = None) -> np.ndarray:
    """The last value of :func:`exp_average` ``(x, n, last)`` without its trace, for a caller
    that needs only the state: ``(1-c)**m last + c sum_i (1-c)**(m-1-i) x[..., i]`` with ``c =
    1/n`` over the ``m`` samples, one matrix-vector product (a fifth of the recursion's CPU at
    2048 samples; the same number to rounding, ~1e-15 relative).

    Parameters
    ----------
    x : numpy.ndarray, shape (..., m)
        Input, float64 (units^2 for squared samples).
    n : int
        Averaging length in samples, >= 1.
    last : numpy.ndarray, shape (...), optional
        The average before ``x[..., 0]``; zeros if omitted.

    Returns
    -------
    numpy.ndarray, shape (...)
        The average at ``x[..., -1]`` (``last`` for an empty ``x``).
    """
    c = 1.0 / _check_n("n", n)
    x = np.asarray(x, dtype=np.float64)
    m = x.shape[-1]
    prev = np.zeros(x.shape[:-1]) if last is None else np.asarray(last, dtype=np.float64)
    if m == 0:
        return prev.copy()
    if c == 1.0:  # n == 1: the average is the last sample
        return x[..., -1].copy()
    log_keep = math.log1p(-c)
    w = c * np.exp(np.arange(m - 1, -1, -1) * log_keep)
    return x @ w + math.exp(m * log_keep) * prev


@dataclass(frozen=True)
class StaLtaState:
    """Streaming state of :func:`recursive_sta_lta`.

    Attributes
    ----------
    sta, lta : numpy.ndarray, shape (n_channels,) or ()
        Short- and long-term averages of ``x**2`` at the last sample seen (units^2).
    n_seen : int
        Samples seen since the state was created (the ratio is 0 while ``n_seen < nlta``).
    """

    sta: np.ndarray
    lta: np.ndarray
    n_seen: int


def recursive_sta_lta(x: ArrayLike, nsta: int, nlta: int, state: StaLtaState | None = None
                      ) -> tuple[np.ndarray, StaLtaState]:
    """Recursive STA/LTA of every row of ``x``, carrying state across blocks.

    ``sta[i] = sta[i-1] + (x[i]**2 - sta[i-1]) / nsta`` and likewise ``lta`` with ``nlta``; the
    ratio ``sta / lta`` is 0 for the first ``nlta`` samples of the stream (the LTA is still
    filling) and wherever ``lta`` is 0.

    Parameters
    ----------
    x : array_like, shape (..., n_samples)
        Signal (any unit), e.g. accelerations in m/s^2, one row per channel.
    nsta, nlta : int
        Short- and long-term averaging lengths in samples, ``1 <= nsta < nlta``.
    state : StaLtaState, optional
        State returned by the previous call; ``None`` starts a new stream.

    Returns
    -------
    ratio : numpy.ndarray, shape like ``x``
        Characteristic function STA/LTA (dimensionless).
    state : StaLtaState
        State after the last sample, for the next block.

    Raises
    ------
    ValueError
        ``nsta`` or ``nlta`` is not a positive whole number, or ``nsta >= nlta``.
    """
    nsta, nlta = _check_n("nsta", nsta), _check_n("nlta", nlta)
    if nsta >= nlta:
        raise ValueError(f"nsta ({nsta}) must be shorter than nlta ({nlta})")
    x = np.asarray(x, dtype=np.float64)
    x2 = x * x
    sta, sta_last = exp_average(x2, nsta, None if state is None else state.sta)
    lta, lta_last = exp_average(x2, nlta, None if state is None else state.lta)
    n_seen = 0 if state is None else state.n_seen
    ratio = np.divide(sta, lta, out=np.zeros_like(sta), where=lta > 0)
    warm = nlta - n_seen
    if warm > 0:
        ratio[..., :warm] = 0.0
    return ratio, StaLtaState(sta_last, lta_last, n_seen + x.shape[-1])


def recursive_sta_lta_ref(x: ArrayLike, nsta: int, nlta: int) -> np.ndarray:
    """Plain-loop reference of :func:`recursive_sta_lta` for one channel (slow; for tests).

    Parameters
    ----------
    x : array_like, shape (n_samples,)
    nsta, nlta : int
        Averaging lengths in samples.

    Returns
    -------
    numpy.ndarray, shape (n_samples,)
        STA/LTA, 0 for the first ``nlta`` samples.
    """
    csta, clta = 1.0 / nsta, 1.0 / nlta
    sta = lta = 0.0
    out = np.zeros(len(x))
    for i, v in enumerate(np.asarray(x, dtype=np.float64).tolist()):
        sq = v * v
        sta = csta * sq + (1.0 - csta) * sta
        lta = clta * sq + (1.0 - clta) * lta
        if i >= nlta and lta > 0:
            out[i] = sta / lta
    return out


def next_trigger(on: np.ndarray, off: np.ndarray, is_on: bool) -> tuple[int | None, bool, int]:
    """First new trigger in a block, with hysteresis (the streaming twin of ObsPy's
    ``trigger_onset``, one onset at a time).

    Parameters
    ----------
    on, off : numpy.ndarray of bool, shape (n_samples,)
        Where the characteristic function is above the on level, and below the off level.
    is_on : bool
        Whether the trigger was on at the end of the previous block.

    Returns
    -------
    index : int or None
        First sample where the trigger switches on (after switching off first if ``is_on``).
    is_on : bool
        State after the block (``True`` if ``index`` is not ``None``).
    off_index : int
        Sample where it last switched off within the block, or -1.
    """
    start, off_index = 0, -1
    if is_on:
        offs = np.flatnonzero(off)
        if offs.size == 0:
            return None, True, -1
        start = off_index = int(offs[0])
    ons = np.flatnonzero(on[start:])
    if ons.size == 0:
        return None, False, off_index
    return start + int(ons[0]), True, off_index


def first_hold(ok: np.ndarray, hold_n: int, run: int = 0) -> tuple[int | None, int]:
    """First sample at which ``ok`` has held for ``hold_n`` consecutive samples.

    Parameters
    ----------
    ok : numpy.ndarray of bool, shape (n_samples,)
    hold_n : int
        Samples the condition must hold, >= 1.
    run : int
        Consecutive ``True`` samples carried from the previous block.

    Returns
    -------
    index : int or None
        Index where the run reaches ``hold_n``, or ``None``.
    run : int
        Run length at the end of the block (to carry over).
    """
    if ok.size == 0:
        return None, run
    idx = np.arange(ok.size)
    last_false = np.maximum.accumulate(np.where(ok, -1, idx))
    runs = np.where(last_false >= 0, idx - last_false, idx + 1 + run)
    hit = np.flatnonzero(runs >= hold_n)
    return (int(hit[0]) if hit.size else None), int(runs[-1])


def aic(x: ArrayLike) -> np.ndarray:
    """Maeda's AIC along the last axis: ``aic[k] = k ln var(x[:k]) + (N-k) ln var(x[k:])``.

    Parameters
    ----------
    x : array_like, shape (..., N)

    Returns
    -------
    numpy.ndarray, shape (..., N)
        ``aic[..., k]`` for a change of variance just before sample ``k``; ``+inf`` at ``k = 0``
        (no split). Variances are floored at ``1e-12`` of the whole window's, so a run of
        identical samples does not give ``-inf``.
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[-1]
    out = np.full(x.shape, np.inf)
    if n < 2:
        return out
    x = x - x.mean(axis=-1, keepdims=True)
    floor = 1e-12 * np.maximum(np.mean(x * x, axis=-1, keepdims=True), np.finfo(float).tiny)
    s1, s2 = np.cumsum(x, axis=-1), np.cumsum(x * x, axis=-1)
    k = np.arange(1, n, dtype=np.float64)
    var1 = s2[..., :-1] / k - (s1[..., :-1] / k) ** 2
    r1, r2 = s1[..., -1:] - s1[..., :-1], s2[..., -1:] - s2[..., :-1]
    var2 = r2 / (n - k) - (r1 / (n - k)) ** 2
    out[..., 1:] = k * np.log(np.maximum(var1, floor)) + (n - k) * np.log(np.maximum(var2, floor))
    return out


def aic_pick(x: ArrayLike, margin: int = 4) -> int:
    """Sample where the variance changes, by the AIC summed over rows (channels).

    Parameters
    ----------
    x : array_like, shape (n_samples,) or (n_channels, n_samples)
        Window containing the onset, with noise before it.
    margin : int
        Splits leaving fewer than ``margin`` samples on either side are not considered.

    Returns
    -------
    int
        Index (into the window) of the first sample after the change.
    """
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    n = x.shape[-1]
    if n < 2 * margin + 1:
        raise ValueError(f"window of {n} samples is too short for margin {margin}")
    total = aic(x).sum(axis=0)
    return margin + int(np.argmin(total[margin:n - margin + 1]))


def hinge_onset(x: ArrayLike, guess: int, *, pre_n: int, post_n: int,
                search_n: tuple[int, int], step: float = 0.05,
                noise_var: ArrayLike | None = None) -> float:
    """Sub-sample onset by a joint hinge fit of the rising edge on every channel.

    For a trial onset ``h`` (samples), each channel of the window ``x[:, guess-pre_n :
    guess+post_n+1]`` is fitted by ``c0 + c1 t + [t >= h] (a (t-h) + b (t-h)**2)``; the onset is
    the ``h`` with the smallest residual summed over channels, each weighted by ``1/noise_var``.
    ``h`` is searched on whole samples over ``guess - search_n[0] .. guess + search_n[1]``, then
    in steps of ``step`` samples within one sample of the best.

    Parameters
    ----------
    x : array_like, shape (n_channels, n_samples) or (n_samples,)
        Signal around the onset (any unit).
    guess : int
        First guess of the onset, an index into ``x`` (e.g. :func:`aic_pick`).
    pre_n, post_n : int
        Samples of the window before and after ``guess``; ``post_n`` should span the start of the
        blow's rise only (a fraction of its duration).
    search_n : (int, int)
        How far before and after ``guess`` the onset may lie, samples.
    step : float
        Final resolution, samples.
    noise_var : array_like, shape (n_channels,), optional
        Noise variance of each channel (units^2); equal weights if omitted.

    Returns
    -------
    float
        Onset as a fractional index into ``x``.

    Raises
    ------
    ValueError
        The window does not fit inside ``x`` or leaves fewer than 3 samples after the latest
        trial onset.
    """
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    lo, hi = guess - pre_n, guess + post_n + 1
    if lo < 0 or hi > x.shape[-1]:
        raise ValueError(f"hinge window {lo}..{hi} is outside the {x.shape[-1]} samples given")
    if search_n[1] > post_n - 3 or search_n[0] > pre_n - 3:
        raise ValueError(f"search_n {search_n} leaves under 3 samples on a side of the window "
                         f"(pre_n {pre_n}, post_n {post_n})")
    y = x[:, lo:hi]
    y = y - y[:, :pre_n].mean(axis=1, keepdims=True)
    w = np.ones(len(y)) if noise_var is None else 1.0 / np.maximum(np.asarray(noise_var), 1e-300)
    t = np.arange(-pre_n, post_n + 1, dtype=np.float64)

    def cost(h: np.ndarray) -> np.ndarray:
        s = np.maximum(t[None, :] - h[:, None], 0.0)
        X = np.stack([np.ones_like(s), np.broadcast_to(t / pre_n, s.shape), s, s * s], axis=-1)
        coef = np.linalg.pinv(X) @ y.T[None, :, :]           # (n_h, 4, n_ch)
        r = y[None, :, :] - np.swapaxes(X @ coef, 1, 2)        # (n_h, n_ch, n_pts)
        return np.einsum("hcp,c->h", r * r, w)

    coarse = np.arange(-search_n[0], search_n[1] + 1, dtype=np.float64)
    best = coarse[int(np.argmin(cost(coarse)))]
    fine = best + np.arange(-1.0, 1.0 + step / 2, step)
    fine = fine[(fine >= -search_n[0]) & (fine <= search_n[1])]
    return float(guess + fine[int(np.argmin(cost(fine)))])


def ar_prediction_filter(x: ArrayLike, order: int, noise_var: ArrayLike | None = None
                         ) -> np.ndarray:
    """Least-squares AR prediction-error filter shared by all channels.

    Each row is divided by its noise rms (or, without ``noise_var``, by its own rms), then
    ``x[t] ~ sum_k c_k x[t-k]`` and ``x[t] ~ sum_k c_k x[t+k]`` are fitted over every row and
    sample at once (forward and backward prediction, the modified covariance method, Marple
    1987 ch. 8). Scaling by the noise lets the rows that ring well above it set the poles;
    scaling every row to unit rms would let noise-only rows drag the fit towards whitening noise.
    The backward equations matter on a window shorter than a period of the slowest mode: the
    forward equations alone then leave that mode's poles loose (a quarter period of 8 Hz at
    70 dB: the innovation after the window 10-40x its variance in it; with both, 1x).

    Parameters
    ----------
    x : array_like, shape (n_channels, n_samples) or (n_samples,)
        Ringing to model; needs ``n_channels * (n_samples - order) > order``.
    order : int
        Number of predictor taps (four times the number of modes is exact for noise-free
        damped ringing: each mode's pair of poles and their reflections, which the backward
        equations bring; twice for undamped).
    noise_var : array_like, shape (n_channels,), optional
        Noise variance of each row (units^2).

    Returns
    -------
    numpy.ndarray, shape (order + 1,)
        ``a = [1, -c_1, ..., -c_order]``: ``scipy.signal.lfilter(a, 1, x)`` is the prediction
        error (the innovation).
    """
    order = _check_n("order", order)
    x = np.atleast_2d(np.asarray(x, dtype=np.float64))
    n = x.shape[-1]
    if x.shape[0] * (n - order) <= order:
        raise ValueError(f"{x.shape[0]} x {n} samples are too few for an AR({order}) fit")
    var = np.mean(x * x, axis=-1) if noise_var is None else np.asarray(noise_var, dtype=float)
    x = x / np.maximum(np.sqrt(var), 1e-300).reshape(-1, 1)
    fb = np.concatenate([x, x[:, ::-1]])  # the backward equations: the forward ones, reversed
    lags = np.stack([fb[:, order - k: n - k] for k in range(1, order + 1)], axis=-1)
    coef, *_ = np.linalg.lstsq(lags.reshape(-1, order), fb[:, order:].ravel(), rcond=None)
    return np.concatenate([[1.0], -coef])


def prediction_error(x: ArrayLike, a: np.ndarray) -> np.ndarray:
    """Innovation ``e = lfilter(a, 1, x)`` on every row, valid samples only.

    Parameters
    ----------
    x : array_like, shape (..., n_samples)
    a : numpy.ndarray, shape (order + 1,)
        From :func:`ar_prediction_filter`.

    Returns
    -------
    numpy.ndarray, shape (..., n_samples - order)
        ``e[..., j]`` is the error at sample ``j + order`` of ``x``; it depends on ``x`` only
        (no filter state), so any split of a record gives the same numbers.
    """
    return filters.fir_filter(np.asarray(a, dtype=np.float64), x)


def butterworth_delay_s(order: int, corner_hz: float, fs_hz: float) -> float:
    """Low-frequency group delay of a digital Butterworth low-pass (bilinear, pre-warped), s.

    A rising edge comes out of such a filter late by this delay, so an onset picked on the
    filtered signal minus it is the onset at the filter's input. Computed numerically for the
    filter ``scipy.signal.butter(order, corner_hz, fs=fs_hz)``; for ``corner_hz`` well below
    ``fs_hz / 2`` it tends to the analogue ``1 / (2 pi corner_hz sin(pi / (2 order)))``.

    Raises
    ------
    ValueError
        ``corner_hz`` is not between 0 and ``fs_hz / 2``.
    """
    if not 0 < corner_hz < fs_hz / 2:
        raise ValueError(f"corner_hz ({corner_hz}) must lie between 0 and fs_hz/2 ({fs_hz / 2})")
    b, a = filters.butter(_check_n("order", order), corner_hz, fs_hz)
    gd = filters.group_delay(b, a, [1e-6 * fs_hz], fs_hz)
    return float(gd[0]) / fs_hz


BLOW_WINDOW_S = 0.2
"""The windows before and after an onset whose spectra :func:`band_energy_ratio` compares, s."""
NO_BLOW_RATIO = 2.0
"""An onset after which no octave band's RMS rises above this factor is no blow: the blows
measured rose 25-12 500x in their strongest band, friction sticking at most 1.04x (the noise's
scatter; :func:`band_energy_ratio`); 2 lies a factor 12 and 2 from them."""


def band_energy_ratio(before: np.ndarray, after: np.ndarray, fs_hz: float) -> float:
    """Whether an onset added energy in any band: the largest over octave bands (from 4 bins,
    4 / window s, to ``fs_hz / 2``) of the median over channels of RMS(``after``) /
    RMS(``before``) in that band (Hann-windowed spectra of the two windows, shape
    (n_channels, n) each, n >= 8); NaN where no band has a channel with both.

    A blow struck into the last one's ringing may leave a mode ringing less (struck against its
    motion, J v + J^2 / 2m < 0: the median RMS ratio over the whole band read 0.85 for an
    ALBACORE blow 3 s after a double hit), but it drives every mode up to 1 / its contact
    time, so some band rings far more after it (that blow: 25x at 20-40 Hz; the blows of four
    modal development trials: 45-12 500x). A mode that stops ringing by friction (Coulomb
    sticking) takes energy out of its band and adds none: at most 1.04x in any band (modal
    development seed 58004's sticks), the noise's own scatter."""
    n = before.shape[-1]
    win = np.hanning(n)
    pb = np.abs(np.fft.rfft(before * win, axis=-1)) ** 2
    pa = np.abs(np.fft.rfft(after * win, axis=-1)) ** 2
    f = np.fft.rfftfreq(n, 1.0 / fs_hz)
    best, lo = math.nan, 4.0 * fs_hz / n
    while lo < fs_hz / 2:
        band = (f >= lo) & (f < 2 * lo)
        with np.errstate(invalid="ignore", divide="ignore"):
            r = np.sqrt(pa[:, band].sum(axis=-1) / pb[:, band].sum(axis=-1))
        r = r[np.isfinite(r)]
        if r.size:
            best = float(np.median(r)) if math.isnan(best) else max(best, float(np.median(r)))
        lo *= 2
    return best


CONTACT_FRACTION = 0.05
"""A blow's contact lasts while its force is above this fraction of its peak: 5 % is well above
a load cell's noise after a blow of any useful size, and cuts a half-sine within 3 % of its
length."""


def contact_duration_s(force: ArrayLike, fs_hz: float, *, window_s: float = 0.5) -> float:
    """How long a blow's force lasts, s, from its onset (sample 0 of ``force``, N, shape (n,)):
    to the last sample within ``window_s`` where ``|F|`` is at least :data:`CONTACT_FRACTION` of
    its peak there. NaN when the window holds no force (all zero or not finite)."""
    f = np.abs(np.asarray(force, dtype=np.float64)[: max(1, round(window_s * fs_hz))])
    if f.size == 0 or not np.all(np.isfinite(f)) or not f.max() > 0:
        return float("nan")
    on = np.flatnonzero(f >= CONTACT_FRACTION * f.max())
    return float(on[-1] + 1) / fs_hz
