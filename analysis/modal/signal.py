"""Signal helpers shared by the decrement and modal estimators.

- :func:`damped_sinusoids` — synthetic free decays (tests, benchmarks, simulators);
- :func:`estimate_noise_std` — per-channel white-noise level from the median of a Kaiser-windowed
  periodogram (robust to a few strong spectral peaks);
- :func:`significant_band_hz` — highest frequency whose spectrum rises significantly above noise;
- :func:`decimate_valid` — linear-phase FIR decimation that keeps only fully-covered outputs, so
  no filter edge transient is mixed into a free decay (the model is exact on what is returned:
  a pole z maps to the same pole, its amplitude scaled by :func:`fir_gain`).

Nothing here (nor in the estimators that use it) changes process-wide state such as the BLAS
thread count, and nothing is cached between calls except read-only arrays, so results depend
only on the inputs, whichever thread calls and in whatever order (see ``analysis/modal/identify.py``,
"Threads").
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import gammainccinv, gammaincinv  # gamma isf / ppf (scipy.stats: ~1.5 s import)

from .. import filters

__all__ = [
    "damped_sinusoids",
    "decimate_valid",
    "estimate_noise_std",
    "fir_gain",
    "fir_noise_variance_factor",
    "band_lengths",
    "significant_band_hz",
]


def damped_sinusoids(
    fs_hz: float,
    n_samples: int,
    f_hz: ArrayLike,
    delta: ArrayLike,
    amplitude: ArrayLike,
    phase_rad: ArrayLike = 0.0,
) -> np.ndarray:
    """Sum of exponentially damped sinusoids A·exp(−δ f t)·cos(2π f t + φ), t = n / fs_hz.

    Parameters
    ----------
    fs_hz : float
        Sample rate (Hz).
    n_samples : int
        Number of samples.
    f_hz, delta : array_like, shape (n_modes,)
        Damped frequency (Hz) and logarithmic decrement of each mode.
    amplitude : array_like, shape (n_modes,) or (n_channels, n_modes)
        Initial amplitude of each mode (per channel for 2-D input).
    phase_rad : array_like
        Phase at t = 0 (rad), broadcast like `amplitude`.

    Returns
    -------
    numpy.ndarray
        Shape (n_samples,) for 1-D `amplitude`, else (n_channels, n_samples).
    """
    f = np.atleast_1d(np.asarray(f_hz, dtype=float))
    d = np.broadcast_to(np.asarray(delta, dtype=float), f.shape)
    amp = np.asarray(amplitude, dtype=float)
    one_d = amp.ndim <= 1
    amp2 = np.atleast_2d(np.broadcast_to(amp, f.shape) if one_d else amp)
    ph = np.broadcast_to(np.asarray(phase_rad, dtype=float), amp2.shape)
    t = np.arange(n_samples) / fs_hz
    env = np.exp(-(d * f)[:, None] * t)  # (n_modes, n_samples)
    arg = 2.0 * np.pi * f[:, None] * t
    # sum_k A_ck cos(arg_k + phi_ck) = sum_k A cos phi cos arg - A sin phi sin arg
    cos_part = (amp2 * np.cos(ph)) @ (env * np.cos(arg))
    sin_part = (amp2 * np.sin(ph)) @ (env * np.sin(arg))
    y = cos_part - sin_part
    return y[0] if one_d else y


@functools.lru_cache(maxsize=32)
def _kaiser14(n: int) -> tuple[np.ndarray, float]:
    """Periodic Kaiser window (β = 14) of length n and Σw² (cached: ~20 lengths per record).

    The cached window is shared by every caller (and thread): it is read-only, so an in-place
    write raises instead of changing later results.
    """
    w = filters.kaiser(n, 14.0, sym=False)
    w.setflags(write=False)
    return w, float(np.sum(w * w))


def kaiser_periodogram(x: np.ndarray) -> np.ndarray:
    """Kaiser (β = 14, sidelobes ≈ −110 dB) periodogram; white noise of variance σ² has mean σ²."""
    w, w2 = _kaiser14(x.shape[-1])
    X = rfft_rows((x - x.mean(axis=-1, keepdims=True)) * w)
    return np.abs(X) ** 2 / w2


_FAST_PRIMES = 7
"""Largest prime factor of a length that pocketfft transforms by its own radices (2 to 7):
beyond, it runs Bluestein's algorithm, whose real transform costs as much as a complex one (a
decay's record length is arbitrary: 16 rows of 29 138 = 2 x 17 x 857 samples took 30 ms, of
28 672 = 2^12 x 7 samples 2.5 ms)."""


_PACK_FROM = 2048
"""Shortest length :func:`rfft_rows` packs (below, the unpacking costs what it saves)."""


@functools.lru_cache(maxsize=64)
def _largest_prime_factor(n: int) -> int:
    p, k = 1, 2
    while k * k <= n:
        while n % k == 0:
            p, n = k, n // k
        k += 1
    return max(p, n)


def fast_length_below(n: int) -> int:
    """The longest length <= ``n`` whose prime factors are all <= :data:`_FAST_PRIMES` (7-smooth:
    pocketfft's own radices, no Bluestein), e.g. 29 578 -> 29 400; ``n`` itself when it is one.
    The downward counterpart of ``scipy.fft.next_fast_len`` (which pads): for cropping a record
    whose end is arbitrary. ValueError for ``n`` < 1."""
    if n < 1:
        raise ValueError(f"fast_length_below: length {n} < 1")
    best = 1
    p7 = 1
    while p7 <= n:
        p5 = p7
        while p5 <= n:
            p3 = p5
            while p3 <= n:
                best = max(best, p3 << ((n // p3).bit_length() - 1))  # times the largest 2^k fitting
                p3 *= 3
            p5 *= 5
        p7 *= 7
    return best


def rfft_rows(a: np.ndarray) -> np.ndarray:
    """``np.fft.rfft(a, axis=-1)`` of a real (n_rows, n) ``a``. Where n has a prime factor over
    :data:`_FAST_PRIMES`, two rows go through one complex transform (z = a_i + j a_(i+1),
    Z = FFT(z): A_k = (Z_k + conj Z_(n-k)) / 2, B_k = (Z_k - conj Z_(n-k)) / 2j), 1.5-2x
    faster at such lengths and equal to the rfft to rounding (~3e-15 of the larger row's norm:
    a row's last digits then depend on the row it is paired with); otherwise, or for one row,
    ``np.fft.rfft`` itself, equal to the bit (also under :data:`_PACK_FROM` samples)."""
    n = a.shape[-1]
    pairs = a.shape[0] // 2 if a.ndim == 2 else 0
    if pairs == 0 or n < _PACK_FROM or _largest_prime_factor(n) <= _FAST_PRIMES:
        return np.fft.rfft(a, axis=-1)
    m = n // 2 + 1
    z = np.empty((pairs, n), dtype=complex)
    z.real, z.imag = a[0:2 * pairs:2], a[1:2 * pairs:2]
    Z = np.fft.fft(z, axis=-1)
    mirror = np.empty((pairs, m), dtype=complex)  # conj Z_(n-k), k = 0 .. n // 2
    mirror[:, 0] = Z[:, 0]
    mirror[:, 1:] = Z[:, n - 1:n - m:-1]
    np.conjugate(mirror, out=mirror)
    out = np.empty((a.shape[0], m), dtype=complex)
    np.add(Z[:, :m], mirror, out=out[0:2 * pairs:2])
    out[0:2 * pairs:2] *= 0.5
    np.subtract(Z[:, :m], mirror, out=out[1:2 * pairs:2])
    out[1:2 * pairs:2] *= -0.5j
    if a.shape[0] % 2:
        out[-1] = np.fft.rfft(a[-1])
    return out


def estimate_noise_std(x: ArrayLike) -> np.ndarray:
    """White-noise standard deviation of each channel from the median periodogram bin.

    Parameters
    ----------
    x : array_like, shape (n_channels, n_samples) or (n_samples,)
        Signal (any unit).

    Returns
    -------
    numpy.ndarray, shape (n_channels,) or ()
        Noise std (signal unit). Biased high when modes cover most of the band.
    """
    a = np.asarray(x, dtype=float)
    if a.shape[-1] < 16:
        raise ValueError(f"n_samples ({a.shape[-1]}) must be at least 16")
    return noise_std_from_periodogram(kaiser_periodogram(a))


def noise_colour(P: np.ndarray, fs_hz: float, band_hz: tuple[float, float]) -> float:
    """How much denser the noise is inside the band than on average over the whole record's
    band (0 to fs/2): the factor by which a likelihood ratio measured in units of the
    whole-band residual variance overstates the in-band noise's (1 for white noise).

    ``P`` (n_channels, n_bins): the channels' Kaiser periodograms (:func:`kaiser_periodogram`,
    mean = variance for white noise) of records at ``fs_hz`` (Hz); ``band_hz``: (lo, hi), Hz,
    where the modes are searched, above which nothing is significant. A converter's
    anti-alias roll-off leaves the noise ~1.3 times denser in the band than on average (the
    stern plane's simulated record, band to 710 Hz at 2048 Hz: 1.28), so an order search
    dividing by the whole-band variance meets its threshold in far more than its
    ``false_alarm`` of noise records.

    Per channel, the in-band density is the median bin of the band over ln 2 (robust to the
    modes, while they cover under half of its bins: as :func:`estimate_noise_std`, it is biased
    high where they cover more), the mean density that and the bins above the band (no modes)
    averaged over all bins; pooled as the median over channels. It is 1 unless it exceeds 1 by
    4 of its own standard errors (measured on white noise, 400 records each of 400 to 12 288
    samples: at most 2.05 / sqrt(in-band bins) a channel, taken as 2.1; the median over C
    channels 1.25 / sqrt(C) of that): white noise does not move the order search, and the
    factor is never below 1 (no test more sensitive than the white one).
    """
    P = np.atleast_2d(P)
    n_bins = P.shape[-1]
    f = np.arange(n_bins) * (0.5 * fs_hz / (n_bins - 1))
    inside = (f >= band_hz[0]) & (f <= band_hz[1])
    inside[0] = False
    above = f > band_hz[1]
    n_in = int(np.count_nonzero(inside))
    if n_in < 16 or not above.any():
        return 1.0
    s_in = np.median(P[:, inside], axis=1) / np.log(2.0)
    s_mean = (s_in * (n_bins - np.count_nonzero(above)) + P[:, above].sum(axis=1)) / n_bins
    kappa = float(np.median(s_in / np.maximum(s_mean, 1e-300)))
    se = 2.1 / np.sqrt(n_in) * 1.25 / np.sqrt(P.shape[0])
    return kappa if kappa > 1.0 + 4.0 * se else 1.0


def noise_std_from_periodogram(P: np.ndarray) -> np.ndarray:
    """:func:`estimate_noise_std` from the record's periodogram (DC and Nyquist bins included)."""
    return np.sqrt(np.median(P[..., 1:-1], axis=-1) / np.log(2.0))


def significant_band_hz(
    x: ArrayLike, fs_hz: float, noise_std: ArrayLike, *, false_alarm: float = 1e-3
) -> float | None:
    """Highest frequency whose channel-summed, whitened spectrum is significantly above noise.

    Kaiser-windowed periodograms of the whole record and of its first quarter, sixteenth and 1/64 are
    tested, so that lightly and heavily damped modes are both seen. Where the noise is coloured,
    each bin is judged against the noise's level around it (block medians of the whole record's
    spectrum, never below the white level; :func:`_noise_floor`).

    Parameters
    ----------
    x : array_like, shape (n_channels, n_samples)
        Signal.
    fs_hz : float
        Sample rate (Hz).
    noise_std : array_like, shape (n_channels,)
        Noise std of each channel (signal unit).
    false_alarm : float
        Probability that pure noise shows any significant bin (Bonferroni over bins).

    Returns
    -------
    float or None
        Frequency (Hz) of the highest significant spectral peak (its largest bin), or None when
        no bin is significant.
    """
    a = np.atleast_2d(np.asarray(x, dtype=float))
    return significant_band(a, fs_hz, noise_std, false_alarm, None)


def band_lengths(n: int) -> list[int]:
    """The record lengths whose periodograms :func:`significant_band_hz` tests, for a record of
    ``n`` samples: the whole record and its first 1/4, 1/16, 1/64 (those of 64 samples or more):
    a heavily damped mode lives in the first few per cent of a long record, where a
    full-length window is ~0."""
    return [m for m in (n, n // 4, n // 16, n // 64) if m >= 64] or [n]


def significant_band(
    a: np.ndarray, fs_hz: float, noise_std: ArrayLike, false_alarm: float,
    P_full: np.ndarray | None, parts: dict[int, np.ndarray] | None = None,
) -> float | None:
    """:func:`significant_band_hz` on 2-D ``a``; ``P_full``: its whole-record periodogram if
    known; ``parts``: periodograms of its first m samples already computed, by m."""
    sig = np.maximum(np.asarray(noise_std, dtype=float), 1e-300)
    n_ch, n = a.shape
    spectra = []
    floor = None
    for m in band_lengths(n):
        if m == n and P_full is not None:
            P = P_full
        else:
            P = parts[m] if parts is not None and m in parts else kaiser_periodogram(a[:, :m])
        S = np.sum(P / (sig[:, None] ** 2), axis=0)[1:-1]
        f = np.arange(1, S.size + 1) * fs_hz / m
        if floor is None:  # from the whole record's spectrum (the finest: modes cover least)
            floor = _noise_floor(S, f, n_ch)
        spectra.append((S / floor(f), f))
    n_tests = sum(S.size for S, _ in spectra)
    threshold = gammainccinv(n_ch, false_alarm / max(n_tests, 1))
    # A peak spreads over the window's main lobe (±4.6 bins): report the centre (largest bin)
    # of the highest run of significant bins, in whichever record length shows it.
    tops = []
    for S, f in spectra:
        hit = np.flatnonzero(S > threshold)
        if hit.size:
            run_start = hit[np.flatnonzero(np.diff(hit) > 1)[-1] + 1] if np.any(np.diff(hit) > 1) \
                else hit[0]
            run = np.arange(run_start, hit[-1] + 1)
            tops.append(f[run[np.argmax(S[run])]])
    top = max(tops, default=None)
    return None if top is None else float(top)


def significant_bands_alone(fs_hz: float, noise_std: np.ndarray, false_alarm: float,
                            parts: dict[int, np.ndarray], n: int) -> np.ndarray:
    """:func:`significant_band` of each channel on its own, all at once (the same operations
    row by row: equal to the bit; one call instead of one a channel, whose Python overhead cost
    more than the arithmetic: 16 gages x 14 s, ~7 -> ~2 ms). ``parts``: the channels' Kaiser
    periodograms (n_channels, bins) of their first m samples by m, for every m of
    :func:`band_lengths` (``n``: the record's length); ``noise_std`` (n_channels,). Returns the
    highest significant peak (Hz) of each channel, NaN where none."""
    sig = np.maximum(np.asarray(noise_std, dtype=float), 1e-300)
    spectra = []
    level = edges = None
    for m in band_lengths(n):
        S = (parts[m] / (sig[:, None] ** 2))[:, 1:-1]  # one channel's channel sum: itself
        f = np.arange(1, S.shape[1] + 1) * fs_hz / m
        if level is None:  # _noise_floor's blocks (of one channel), every channel at once
            blocks = np.array_split(np.arange(S.shape[1]), max(1, S.shape[1] // 2048))
            level = _block_medians(S, blocks)
            level = level / gammaincinv(1, 0.5)
            level = np.where(level > 1.0 + 1e-9, level, 1.0)
            edges = np.array([f[i[-1]] for i in blocks[:-1]])
        spectra.append((S / level[:, np.searchsorted(edges, f, side="left")], f))
    threshold = gammainccinv(1, false_alarm / max(sum(S.shape[1] for S, _ in spectra), 1))
    tops = np.full(sig.size, np.nan)
    for c in range(sig.size):
        for S, f in spectra:
            hit = np.flatnonzero(S[c] > threshold)
            if hit.size:
                gaps = np.flatnonzero(np.diff(hit) > 1)
                run = np.arange(hit[gaps[-1] + 1] if gaps.size else hit[0], hit[-1] + 1)
                top = f[run[np.argmax(S[c, run])]]
                tops[c] = top if np.isnan(tops[c]) else max(tops[c], top)
    return tops


def _block_medians(S: np.ndarray, blocks: list[np.ndarray]) -> np.ndarray:
    """The median of each row of ``S`` (rows, n) over each of ``blocks`` (consecutive index
    ranges covering 0 .. n - 1 in order, as ``np.array_split`` gives them: at most two sizes,
    the longer first), shape (rows, len(blocks)): equal to the bit to one ``np.median`` a block
    (a median is the middle order statistic, or the mean of the two middle ones: the same
    values whatever the batching), in one call for each block size instead of one a block."""
    sizes = np.array([i.size for i in blocks])
    out = np.empty((S.shape[0], sizes.size))
    start = 0
    for size in np.unique(sizes)[::-1]:  # the longer blocks come first
        nb = int(np.count_nonzero(sizes == size))
        if not (sizes[start:start + nb] == size).all():  # not array_split's layout
            return np.stack([np.median(S[:, i[0] : i[-1] + 1], axis=1) for i in blocks], axis=1)
        lo = int(blocks[start][0])
        part = S[:, lo : lo + nb * size].reshape(S.shape[0], nb, size)
        out[:, start:start + nb] = np.median(part, axis=2)
        start += nb
    return out


def _noise_floor(S: np.ndarray, f: np.ndarray, n_ch: int):
    """Coloured noise: the level of the channel-summed whitened spectrum ``S`` (bins at ``f``
    Hz) relative to white noise of the median-based σ, as a step function of frequency
    (returned: f → factor ≥ 1 dividing S before the test).

    σ from one median over the whole band is white noise's level; a noise whose density varies
    across the band (a converter's anti-alias roll-off: the simulated ALBACORE record's noise
    is ~1.5 times that level below ~700 Hz and ~0.5 times above) then crosses a threshold set
    for white noise in most records, not in ``false_alarm`` of them, and the band (which sets
    the order search's decimation and candidates) reaches up to a noise bin. The level is the
    median of S over blocks of at least 64 bins and 2048 / n_channels bins (the median of
    ≥ 2048 exponential variates: ~2 % standard error; a mode's main lobe, ±5 bins, barely moves
    it), over the median of white noise's S, Gamma(n_channels); floored at 1, so the test is
    never more sensitive than the white-noise test, which it equals wherever the noise is white
    (one block: exactly, σ being that median)."""
    b = max(64, -(-2048 // n_ch))
    blocks = np.array_split(np.arange(S.size), max(1, S.size // b))
    med = gammaincinv(n_ch, 0.5)
    level = _block_medians(S[None, :], blocks)[0] / med
    level = np.where(level > 1.0 + 1e-9, level, 1.0)  # white (one block: 1 to rounding): none
    edges = np.array([f[i[-1]] for i in blocks[:-1]])  # upper edge of each block but the last

    def floor(fq: np.ndarray) -> np.ndarray:
        return level[np.searchsorted(edges, fq, side="left")]

    return floor


def _fir_taps(factor: int, band_hz: float, fs_hz: float) -> np.ndarray:
    fs_d = fs_hz / factor
    width = max(fs_d - 2.0 * band_hz, 0.1 * fs_d)  # passband to band_hz, alias-free band
    numtaps, beta = filters.kaiserord(80.0, width / (0.5 * fs_hz))
    numtaps |= 1  # odd: integer centre delay
    h = filters.firwin_kaiser(numtaps, 0.5 * fs_d, beta, fs_hz)
    return h / h.sum()


def _first_sample_taps(factor: int, band_hz: float, fs_hz: float) -> np.ndarray:
    """The minimum-phase FIR of :func:`_fir_taps`' magnitude (homomorphic, same length; |H|
    equal within 1e-6), unit DC gain: its largest taps come first, so run backwards in time it
    weighs an output's first samples most."""
    g = filters.minimum_phase(_fir_taps(factor, band_hz, fs_hz))
    return g / g.sum()


def decimate_valid(
    x: ArrayLike, fs_hz: float, factor: int, band_hz: float, max_outputs: int | None = None,
    *, from_first: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Low-pass and decimate, returning only outputs whose filter window lies inside the record.

    With ``from_first`` the filter is the minimum-phase one of the same magnitude run backwards
    in time (output n = Σ_k g_k x[n + k]) and the outputs are those at samples 0, factor, …:
    a free decay's first samples, its strongest, weigh in fully (the linear-phase outputs start
    centred on the FIR's half length, 11 samples at a factor of 2 and a 270 Hz band, and weigh
    the first samples by its smallest taps: ~1 % of a 14 s 16-gage decay's decrement variance
    lost). Every output is still exactly Σ gain(z) zⁿ on a sum of damped exponentials zⁿ
    (:func:`fir_gain` of the returned taps), with the same noise spectrum.

    Parameters
    ----------
    x : array_like, shape (n_channels, n_samples)
        Signal.
    fs_hz : float
        Sample rate of `x` (Hz).
    factor : int
        Decimation factor (≥ 1; 1 returns `x` unchanged).
    band_hz : float
        Highest frequency to keep undistorted (Hz); must be below fs_hz / (2 factor).
    max_outputs : int, optional
        Only the first ``max_outputs`` of those outputs, the record read only as far as they
        need (each output equal to the bit to the same output of the whole record's).

    Returns
    -------
    y : numpy.ndarray, shape (n_channels, n_out)
        Filtered, decimated signal.
    n_index : numpy.ndarray, shape (n_out,)
        Index into the original samples that each output is centred on (time = n_index / fs_hz).
    taps : numpy.ndarray
        The zero-phase FIR taps (centre at len // 2), for :func:`fir_gain`; with
        ``from_first``, the reversed minimum-phase taps followed by as many zeros less one (so
        that the centre convention of :func:`fir_gain` gives Σ_k g_k z^k).
    """
    a = np.atleast_2d(np.asarray(x, dtype=float))
    factor = int(factor)
    if factor < 1:
        raise ValueError(f"factor ({factor}) must be >= 1")
    if factor == 1:
        return a, np.arange(a.shape[-1]), np.ones(1)
    if not 0 < band_hz < 0.5 * fs_hz / factor:
        raise ValueError(f"band_hz ({band_hz}) must lie in (0, {0.5 * fs_hz / factor})")
    if from_first:
        return _decimate_from_first(a, fs_hz, factor, band_hz, max_outputs)
    h = _fir_taps(factor, band_hz, fs_hz)
    c = (h.size - 1) // 2
    if max_outputs is not None:  # output j reads samples j - (taps - 1) ... j
        last = -(-(h.size - 1) // factor) * factor + (max(int(max_outputs), 1) - 1) * factor
        a = a[:, : last + 1]
    full = filters.downsample_fir(h, a, factor)  # full[k] = conv[k * factor]
    j = np.arange(full.shape[-1]) * factor
    keep = (j >= h.size - 1) & (j <= a.shape[-1] - 1)
    if not np.any(keep):
        raise ValueError(f"record ({a.shape[-1]} samples) is shorter than the FIR ({h.size})")
    return full[:, keep], j[keep] - c, h


def _decimate_from_first(a: np.ndarray, fs_hz: float, factor: int, band_hz: float,
                         max_outputs: int | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`decimate_valid` with ``from_first``: outputs n = 0, factor, … ≤ n_samples − L
    (L taps), output n = Σ_k g_k a[n + k] (the convolution with g reversed, at n + L − 1)."""
    hc = _first_sample_taps(factor, band_hz, fs_hz)[::-1]
    L = hc.size
    if max_outputs is not None:
        a = a[:, : (L - 1) + (max(int(max_outputs), 1) - 1) * factor + 1]
    n_out = (a.shape[-1] - L) // factor + 1
    if n_out < 1:
        raise ValueError(f"record ({a.shape[-1]} samples) is shorter than the FIR ({L})")
    # upfirdn keeps convolution indices 0, factor, …: zeros put before the record (they reach
    # no output kept) bring index L − 1, output 0, among them.
    pad = (-(L - 1)) % factor
    b = np.concatenate([np.zeros((a.shape[0], pad)), a], axis=1) if pad else a
    full = filters.downsample_fir(hc, b, factor)
    first = (L - 1 + pad) // factor
    return full[:, first : first + n_out], np.arange(n_out) * factor, np.concatenate(
        [hc, np.zeros(L - 1)])


def decimated_index(n_samples: int, fs_hz: float, factor: int, band_hz: float) -> np.ndarray:
    """The ``n_index`` that :func:`decimate_valid` returns for a record of ``n_samples``
    (which outputs it keeps), without filtering anything."""
    if factor == 1:
        return np.arange(n_samples)
    h = _fir_taps(int(factor), band_hz, fs_hz)
    j = np.arange(-(-(h.size - 1) // factor) * factor, n_samples, factor)
    return j - (h.size - 1) // 2


def fir_gain(taps: np.ndarray, z: ArrayLike) -> np.ndarray:
    """Complex gain of a centred FIR on the sequence zⁿ (z a pole at the original rate).

    Parameters
    ----------
    taps : numpy.ndarray
        Taps from :func:`decimate_valid`.
    z : array_like
        Discrete-time poles exp(s / fs_hz).

    Returns
    -------
    numpy.ndarray
        Σ_m h[m] z^(c − m), same shape as `z`; the output of the filter on zⁿ is gain · zⁿ.
    """
    zz = np.asarray(z, dtype=complex)
    c = (taps.size - 1) // 2
    powers = c - np.arange(taps.size)
    return np.sum(taps[:, None] * zz.reshape(1, -1) ** powers[:, None], axis=0).reshape(zz.shape)


def fir_noise_variance_factor(
    taps: np.ndarray, factor: int, f_hz: ArrayLike, fs_hz: float
) -> np.ndarray:
    """Ratio of the decimated noise density at f to that of white noise of the same variance.

    Standard errors computed on decimated data as if its noise were white are multiplied by the
    square root of this factor (≈ 1.05–1.15 for the filters of :func:`decimate_valid`).

    Parameters
    ----------
    taps : numpy.ndarray
        Taps from :func:`decimate_valid`.
    factor : int
        Decimation factor used with them.
    f_hz : array_like
        Frequencies (Hz) at which the ratio is wanted.
    fs_hz : float
        Sample rate before decimation (Hz).

    Returns
    -------
    numpy.ndarray
        |H(f)|² / (factor · Σh²), same shape as `f_hz` (1 for ``factor == 1``).
    """
    if factor == 1:
        return np.ones_like(np.asarray(f_hz, dtype=float))
    z = np.exp(2j * np.pi * np.asarray(f_hz, dtype=float) / fs_hz)
    return np.abs(fir_gain(taps, z)) ** 2 / (factor * np.sum(taps * taps))
