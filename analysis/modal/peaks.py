"""The report's decrement method: band-pass one mode, read successive peaks, average log ratios.

DTMB Report 1836 (Eq C-1, Eq 7) reads the decrement of a mode from an oscillogram as
δ = (1/q) ln[A(t₀) / A(t₀ + qτ)], after band-pass filtering the mode out, and averages the values
over successive peaks. :func:`decrement_from_peaks` does the same on a sampled record:

1. zero-phase Butterworth band-pass around the mode (:func:`bandpass_mode`);
2. positive peaks, each refined by a parabola through three samples;
3. the filter's start and end transients are skipped: they decay at the filter's slowest pole
   rate σ_filt, so the first ln(10³)/(σ_filt − σ_mode) seconds are dropped (≈ 1 ‰ residual error
   per ratio; flagged ``filter_limited`` when the filter is not clearly faster than the mode or
   the record is too short to wait for it);
4. peaks below ``min_snr`` × the band-passed noise std are dropped (a noisy peak is biased up);
5. δᵢ = (1/q) ln(Aᵢ / Aᵢ₊q) for every peak i; δ = mean δᵢ, as the report did.

The mean telescopes: it depends on the first q and the last q peaks only, so its standard error is
√(2/q)·s/m with m ratios and s the residual std of ln Aᵢ about a straight line in time. The
least-squares slope of ln Aᵢ (``delta_fit``) uses all peaks and is returned beside it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

from .. import filters
from .signal import estimate_noise_std

__all__ = ["PeakDecrement", "bandpass_mode", "bandpass_rows", "decrement_from_peaks",
           "decrements_from_peaks"]


@dataclass(frozen=True)
class PeakDecrement:
    """Result of :func:`decrement_from_peaks`.

    Attributes
    ----------
    delta : float
        Mean of the per-peak decrements (the report's average).
    std_error : float
        Standard error of `delta` (NaN with fewer than 3 peaks).
    n_ratios : int
        Number of peak ratios averaged.
    q : int
        Periods between the two peaks of each ratio.
    delta_fit : float
        Decrement from the least-squares slope of ln(peak) against time.
    f_hz : float
        Frequency from the mean peak spacing (Hz).
    peak_times_s, peak_amplitudes : numpy.ndarray, shape (n_peaks,)
        Interpolated peaks that were used (s, signal units).
    ratios : numpy.ndarray, shape (n_ratios,)
        Per-peak decrements δᵢ.
    skipped_s : float
        Time dropped at the start for the filter transient (s).
    filter_limited : bool
        True when the band-pass's own transient decays at less than 1.5× the mode's rate,
        so that the filter, not the structure, may set the decay.
    """

    delta: float
    std_error: float
    n_ratios: int
    q: int
    delta_fit: float
    f_hz: float
    peak_times_s: np.ndarray
    peak_amplitudes: np.ndarray
    ratios: np.ndarray
    skipped_s: float
    filter_limited: bool


def _bandpass_sos(fs_hz: float, f_hz: float, rel_bandwidth: float, order: int) -> np.ndarray:
    if not 0 < rel_bandwidth < 1.5:
        raise ValueError(f"rel_bandwidth ({rel_bandwidth}) must lie in (0, 1.5)")
    lo, hi = f_hz * (1 - rel_bandwidth / 2), f_hz * (1 + rel_bandwidth / 2)
    if not 0 < f_hz or hi >= fs_hz / 2:
        raise ValueError(f"f_hz ({f_hz}) band edge {hi:.4g} Hz must be below fs_hz/2 ({fs_hz / 2})")
    return filters.butter(order, [lo, hi], fs_hz, output="sos")


def bandpass_mode(
    x: ArrayLike,
    fs_hz: float,
    f_hz: float,
    rel_bandwidth: float = 0.4,
    *,
    order: int = 2,
    axis: int = -1,
) -> np.ndarray:
    """Zero-phase Butterworth band-pass around one mode.

    Parameters
    ----------
    x : array_like, shape (..., n_samples)
        Signal (any unit).
    fs_hz : float
        Sample rate (Hz).
    f_hz : float
        Mode frequency (Hz), the band centre.
    rel_bandwidth : float
        Band width as a fraction of `f_hz`: edges f·(1 ∓ rel_bandwidth/2).
    order : int
        Butterworth order of the low-pass prototype (the band-pass has 2·order poles; the
        forward-backward pass doubles the attenuation).
    axis : int
        Time axis.

    Returns
    -------
    numpy.ndarray
        Filtered signal, same shape as `x`.
    """
    sos = _bandpass_sos(fs_hz, f_hz, rel_bandwidth, order)
    return np.moveaxis(filters.sosfiltfilt(sos, np.moveaxis(np.asarray(x, dtype=float), axis, -1)),
                       -1, axis)


def _parabolic_peaks(y: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    idx = idx[(idx > 0) & (idx < y.size - 1)]
    ym, y0, yp = y[idx - 1], y[idx], y[idx + 1]
    den = ym - 2 * y0 + yp
    p = np.where(den != 0, 0.5 * (ym - yp) / np.where(den != 0, den, 1.0), 0.0)
    return idx + p, y0 - 0.25 * (ym - yp) * p


def decrement_from_peaks(
    x: ArrayLike,
    fs_hz: float,
    f_hz: float,
    q: int = 1,
    *,
    rel_bandwidth: float = 0.4,
    order: int = 2,
    bandpass: bool = True,
    skip_s: float | None = None,
    min_snr: float = 5.0,
    noise_std: float | None = None,
) -> PeakDecrement:
    """Logarithmic decrement of one mode of one gage by the report's peak-ratio method.

    Parameters
    ----------
    x : array_like, shape (n_samples,)
        One gage's free decay, starting at the start of the decay.
    fs_hz : float
        Sample rate (Hz).
    f_hz : float
        Mode frequency (Hz), approximately.
    q : int
        Whole periods between the two peaks of a ratio (Eq C-1).
    rel_bandwidth, order : float, int
        Band-pass, see :func:`bandpass_mode`.
    bandpass : bool
        False to read peaks of `x` as it is (a record that holds one mode only).
    skip_s : float, optional
        Time to drop at the start (s); default from the filter's pole decay rate.
    min_snr : float
        Peaks below ``min_snr`` × the band-passed noise std are not used.
    noise_std : float, optional
        Noise std of `x` (signal unit); default estimated from its spectrum.

    Returns
    -------
    PeakDecrement

    Raises
    ------
    ValueError
        For bad arguments, or when fewer than q + 1 usable peaks remain.
    """
    y = np.asarray(x, dtype=float)
    if y.ndim != 1:
        raise ValueError(f"x must be 1-D (one gage), got shape {y.shape}")
    _check(fs_hz, f_hz, q)
    sigma_noise = float(estimate_noise_std(y)) if noise_std is None else float(noise_std)
    sigma_filt = np.inf
    if bandpass:
        y, sigma_filt, noise_gain = _bandpassed(y, fs_hz, f_hz, rel_bandwidth, order)
        sigma_noise *= noise_gain
    return _decrement(y, fs_hz, f_hz, q, bandpass, skip_s, min_snr, sigma_noise, sigma_filt)


def decrements_from_peaks(
    x: ArrayLike, fs_hz: float, f_hz: float, q: int = 1, *, rel_bandwidth: float = 0.4,
    order: int = 2, bandpass: bool = True, skip_s: float | None = None, min_snr: float = 5.0,
    noise_std: ArrayLike | None = None, bandpassed: ArrayLike | None = None,
) -> list[PeakDecrement | ValueError]:
    """:func:`decrement_from_peaks` of each row of ``x`` (n_signals, n_samples), same
    parameters: the noise estimates and the band-pass run on all rows at once (the same
    operations row by row, so equal to the bit but for the noise estimates' transforms at the
    lengths :func:`~ramdaq.analysis.modal.signal.rfft_rows` packs, equal to rounding: a hit's
    gages and motions, one call instead of one each, whose filter start-up and checks cost more
    than the filtering). A row whose decrement cannot be read gets the ValueError
    :func:`decrement_from_peaks` raises for it.
    ``noise_std`` (n_signals,): each row's noise std where the caller has it already (the
    verdicts' periodograms of a hit's gages: ~7 ms of a 14 s hit's 16 gages), else estimated.
    ``bandpassed`` (n_signals, n_samples): the rows of ``x`` band-passed already
    (:func:`bandpass_rows` with the same ``fs_hz``, ``f_hz``, ``rel_bandwidth``, ``order``), used
    instead of filtering ``x`` again: a hit's motions, linear combinations of its gages, are the
    same combinations of its band-passed gages (the filter is linear; equal to rounding), so
    their filtering (~7 ms for 12 motions x 14 s) is not run again; ``x`` still gives the
    noise estimates where ``noise_std`` is not given."""
    Y = np.asarray(x, dtype=float)
    if Y.ndim != 2:
        raise ValueError(f"x must be 2-D (one signal a row), got shape {Y.shape}")
    _check(fs_hz, f_hz, q)
    if noise_std is not None:
        sigma_noise = np.asarray(noise_std, dtype=float)
        if sigma_noise.shape != Y.shape[:1]:
            raise ValueError(f"noise_std has shape {sigma_noise.shape}, x has {Y.shape[0]} rows")
    else:
        sigma_noise = estimate_noise_std(Y) if Y.shape[0] else np.empty(0)
    sigma_filt = np.inf
    if bandpass and Y.shape[0]:
        _, sigma_filt, noise_gain = _bandpass_design(float(fs_hz), float(f_hz),
                                                     float(rel_bandwidth), int(order))
        if bandpassed is None:
            Y = bandpass_rows(Y, fs_hz, f_hz, rel_bandwidth=rel_bandwidth, order=order)
        else:
            Yb = np.asarray(bandpassed, dtype=float)
            if Yb.shape != Y.shape:
                raise ValueError(f"bandpassed has shape {Yb.shape}, x has {Y.shape}")
            Y = Yb
        sigma_noise = sigma_noise * noise_gain
    out: list[PeakDecrement | ValueError] = []
    for y, sn in zip(Y, sigma_noise, strict=True):
        try:
            out.append(_decrement(y, fs_hz, f_hz, q, bandpass, skip_s, min_snr, float(sn),
                                  sigma_filt))
        except ValueError as e:
            out.append(e)
    return out


def bandpass_rows(x: ArrayLike, fs_hz: float, f_hz: float, *, rel_bandwidth: float = 0.4,
                  order: int = 2) -> np.ndarray:
    """Each row of ``x`` (n_signals, n_samples) band-passed forward and backward around
    ``f_hz`` as :func:`decrements_from_peaks` does (its ``bandpassed=``; the same filter, the
    same bits). The filter is linear: a linear combination of the rows' outputs is the output
    of the combination (to rounding), so signals made of a record's rows (a hit's motions of its
    gages) need not be filtered again. ValueError where the band does not fit below fs/2."""
    Y = np.asarray(x, dtype=float)
    if Y.ndim != 2:
        raise ValueError(f"x must be 2-D (one signal a row), got shape {Y.shape}")
    _check(fs_hz, f_hz, 1)
    sos, _, _ = _bandpass_design(float(fs_hz), float(f_hz), float(rel_bandwidth), int(order))
    return filters.sosfiltfilt(sos, Y)


def _check(fs_hz: float, f_hz: float, q: int) -> None:
    """The arguments :func:`decrement_from_peaks` refuses: q < 1, under 3 samples a period."""
    if q < 1:
        raise ValueError(f"q ({q}) must be a positive whole number of periods")
    if fs_hz / f_hz < 3:
        raise ValueError(f"f_hz ({f_hz}) leaves fewer than 3 samples per period at {fs_hz} Hz")


def _decrement(y: np.ndarray, fs_hz: float, f_hz: float, q: int, bandpass: bool,
               skip_s: float | None, min_snr: float, sigma_noise: float,
               sigma_filt: float) -> PeakDecrement:
    """Steps 2-5 of the module docstring on ``y`` (band-passed when ``bandpass``; its noise
    std ``sigma_noise``, the filter's slowest pole rate ``sigma_filt`` 1/s)."""
    period_n = fs_hz / f_hz
    t_p, a_p = _peaks_above(y, fs_hz, period_n, min_snr * sigma_noise)
    if t_p.size < 3:
        raise ValueError(f"only {t_p.size} peaks above {min_snr} x noise; need at least 3")
    sigma_mode = max(_line(t_p, -np.log(a_p))[0], 0.0)
    filter_limited = bool(sigma_filt < 1.5 * sigma_mode)
    n_min = max(q + 1, 3)
    end_s = float(np.log(1e3) / (sigma_filt + sigma_mode)) if bandpass else 0.0
    if skip_s is None:
        skip_s, cut_short = _transient_skip_s(t_p, y.size / fs_hz - end_s,
                                              sigma_filt - sigma_mode, n_min)
        filter_limited = filter_limited or cut_short
    keep = (t_p >= skip_s) & (t_p <= y.size / fs_hz - end_s)
    if np.count_nonzero(keep) < n_min:
        keep = t_p >= skip_s
    t_p, a_p = t_p[keep], a_p[keep]
    if t_p.size < q + 1:
        raise ValueError(f"only {t_p.size} usable peaks for q = {q}")
    return _from_peaks(t_p, a_p, q, float(skip_s), filter_limited)


def _bandpassed(y: np.ndarray, fs_hz: float, f_hz: float, rel_bandwidth: float,
                order: int) -> tuple[np.ndarray, float, float]:
    """``y`` band-passed forward and backward around ``f_hz``; the slowest decay rate of the
    filter's poles (1/s), which limits the decays it can pass; and the factor by which it scales
    white noise's std (the forward-backward pass applies |H|^2)."""
    sos, sigma_filt, noise_gain = _bandpass_design(float(fs_hz), float(f_hz),
                                                   float(rel_bandwidth), int(order))
    return filters.sosfiltfilt(sos, y), sigma_filt, noise_gain


@lru_cache(maxsize=64)
def _bandpass_design(fs_hz: float, f_hz: float, rel_bandwidth: float,
                     order: int) -> tuple[np.ndarray, float, float]:
    """The band-pass of :func:`_bandpassed` (sos, read-only), its slowest pole's decay rate
    (1/s) and its forward-backward noise gain. Cached: a hit's gages and motions all ask for the
    same mode's filter (its design, roots and response cost more than filtering the record)."""
    sos = _bandpass_sos(fs_hz, f_hz, rel_bandwidth, order)
    sos.setflags(write=False)
    poles = np.concatenate([np.roots(s[3:]) for s in sos])
    sigma_filt = float(np.min(-np.log(np.abs(poles)) * fs_hz))
    _, H = filters.sosfreqz(sos, 4096, fs_hz)
    return sos, sigma_filt, float(np.sqrt(np.mean(np.abs(H) ** 4)))


def _peaks_above(y: np.ndarray, fs_hz: float, period_n: float,
                 floor: float) -> tuple[np.ndarray, np.ndarray]:
    """Peak times (s) and amplitudes of ``y`` (parabola-interpolated maxima at least 0.6 period
    apart) from the first one above ``floor`` up to the first one lost below it after that."""
    idx = filters.find_peaks(y, max(1, int(0.6 * period_n)))
    t_all, a_all = _parabolic_peaks(y, idx)
    t_all = t_all / fs_hz
    usable = a_all > floor
    if usable.any():
        i0 = int(np.argmax(usable))
        lost = np.flatnonzero(~usable[i0:])
        if lost.size:
            usable[i0 + lost[0]:] = False
    return t_all[usable], a_all[usable]


def _transient_skip_s(t_p: np.ndarray, last_s: float, rate: float,
                      n_min: int) -> tuple[float, bool]:
    """Time to skip at the start (s) while the filter's transient (decaying at ``rate`` 1/s
    faster than the mode) is above 1e-3; when that leaves fewer than ``n_min`` of the peaks
    ``t_p`` up to ``last_s``, the start of the last ``n_min`` instead, flagged (True)."""
    skip_s = float(np.log(1e3) / rate) if rate > 0 and np.isfinite(rate) else 0.0
    in_end = t_p <= last_s
    if np.count_nonzero(in_end & (t_p >= skip_s)) >= n_min:
        return skip_s, False
    # Not enough record after the filter transient: keep the last n_min peaks, flagged.
    cand = t_p[in_end] if np.count_nonzero(in_end) >= n_min else t_p
    return (float(cand[-n_min]) if cand.size >= n_min else 0.0), True


def _line(t: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares straight line through (t, y): (slope, intercept), as ``np.polyfit(t, y, 1)``
    (to rounding) from centred sums, without its general machinery (a hit reads ~50 lines)."""
    tm, ym = t.mean(), y.mean()
    dt = t - tm
    slope = float(dt @ (y - ym) / (dt @ dt))
    return slope, float(ym - slope * tm)


def _from_peaks(t_p: np.ndarray, a_p: np.ndarray, q: int, skipped_s: float,
                filter_limited: bool) -> PeakDecrement:
    """The decrement from the peaks kept (times s, amplitudes): the mean of the log ratios of
    peaks ``q`` periods apart, its standard error from the scatter about a straight line in
    log amplitude, and that line's own decrement."""
    ln_a = np.log(a_p)
    ratios = (ln_a[:-q] - ln_a[q:]) / q
    m = ratios.size
    f_meas = float((t_p.size - 1) / (t_p[-1] - t_p[0]))
    if t_p.size >= 3:
        slope, icpt = _line(t_p, ln_a)
        resid = ln_a - (slope * t_p + icpt)
        s = np.sqrt(np.sum(resid**2) / (t_p.size - 2))
        std_error = float(np.sqrt(2.0 / q) * s / m)
        delta_fit = float(-slope / f_meas)
    else:
        std_error, delta_fit = float("nan"), float(ratios.mean())
    return PeakDecrement(
        delta=float(ratios.mean()),
        std_error=std_error,
        n_ratios=m,
        q=q,
        delta_fit=delta_fit,
        f_hz=f_meas,
        peak_times_s=t_p,
        peak_amplitudes=a_p,
        ratios=ratios,
        skipped_s=skipped_s,
        filter_limited=filter_limited,
    )
