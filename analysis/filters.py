"""The few ``scipy.signal`` filters a replay runs, without importing ``scipy.signal``.

``import scipy.signal`` costs ~0.5 s CPU a process (it imports scipy.stats, interpolate,
optimize, spatial and ndimage), a quarter of a 10-minute replay's non-analysis CPU, for a
handful of functions. These are those functions for the arguments ramdaq passes, built from
numpy, ``scipy.special.i0`` and LAPACK's banded triangular solve (``scipy.linalg.lapack.dtbtrs``,
which runs an IIR recursion in Fortran for every channel at once); every design follows
scipy.signal's own steps (the same poles, the same pairing into sections, the same padding and
initial state), so the numbers agree with scipy.signal's to rounding (~1e-15 relative; the
tests compare them). Arrays are float64; time is the last axis.

* :func:`butter` -- digital Butterworth low-pass or band-pass, ``(b, a)`` or second-order
  sections ``(n_sections, 6)``.
* :func:`sosfilt`, :func:`sosfiltfilt` -- a cascade of sections, forward, and forward-backward
  with scipy's odd padding and steady-state initial conditions.
* :func:`exp_filter` -- the first-order recursion ``y[i] = c x[i] + (1 - c) y[i-1]``.
* :func:`fir_filter` -- ``lfilter(b, [1], x)``'s outputs from sample ``len(b) - 1`` on.
* :func:`sosfreqz`, :func:`group_delay` -- frequency response and group delay.
* :func:`kaiserord`, :func:`firwin_kaiser`, :func:`minimum_phase` -- FIR design.
* :func:`downsample_fir` -- ``upfirdn(h, x, up=1, down=q)``: the full convolution at every
  ``q``-th sample.
* :func:`find_peaks` -- ``scipy.signal.find_peaks(x, distance=d)``'s peak indices.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lapack
from scipy.special import i0

__all__ = ["butter", "downsample_fir", "exp_filter", "find_peaks", "fir_filter", "firwin_kaiser",
           "group_delay", "kaiser", "kaiserord", "minimum_phase", "sosfilt", "sosfilt_zi", "sosfiltfilt",
           "sosfreqz"]


# -- IIR design ---------------------------------------------------------------------------------
def butter(order: int, corner_hz: float | tuple[float, float] | list[float], fs_hz: float,
           *, output: str = "ba") -> tuple[np.ndarray, np.ndarray] | np.ndarray:
    """Digital Butterworth filter of ``order`` (bilinear, pre-warped), as
    ``scipy.signal.butter(order, corner_hz, btype, fs=fs_hz, output=output)``: a low-pass for
    one corner (Hz), a band-pass for two (the band-pass has ``2 order`` poles).

    Returns ``(b, a)`` (``output="ba"``, each shape (n + 1,)) or second-order sections
    (``output="sos"``, shape (n_sections, 6), scipy's ``nearest`` pairing, the gain in the first).
    ValueError for an order < 1 or a corner not inside (0, fs_hz / 2).
    """
    if isinstance(order, bool) or int(order) != order or order < 1:
        raise ValueError(f"order ({order}) must be a whole number >= 1")
    wn = np.atleast_1d(np.asarray(corner_hz, dtype=np.float64)) / (fs_hz / 2)
    if wn.size not in (1, 2) or np.any(wn <= 0) or np.any(wn >= 1) or (wn.size == 2 and not wn[0] < wn[1]):
        raise ValueError(f"corner(s) {corner_hz} Hz must be increasing inside (0, {fs_hz / 2}) Hz")
    n = int(order)
    p = -np.exp(1j * np.pi * np.arange(-n + 1, n, 2, dtype=np.float64) / (2 * n))
    z, k = np.array([], dtype=np.float64), 1.0
    warped = 2 * 2.0 * np.tan(np.pi * wn / 2.0)
    if wn.size == 1:
        wo = float(warped[0])
        z, p, k = wo * z, wo * p, k * wo ** n
    else:
        bw, wo = float(warped[1] - warped[0]), float(np.sqrt(warped[0] * warped[1]))
        p_lp = (p * bw / 2).astype(np.complex128)
        z = np.zeros(n)
        p = np.concatenate((p_lp + np.sqrt(p_lp ** 2 - wo ** 2), p_lp - np.sqrt(p_lp ** 2 - wo ** 2)))
        k = k * bw ** n
    z, p, k = _bilinear(z, p, k)
    if output == "ba":
        return k * np.poly(z), np.poly(p).real
    if output == "sos":
        return _zpk2sos(z, p, k)
    raise ValueError(f"output ({output!r}) must be 'ba' or 'sos'")


def _bilinear(z: np.ndarray, p: np.ndarray, k: float) -> tuple[np.ndarray, np.ndarray, float]:
    """scipy.signal.bilinear_zpk at fs = 2 (the pre-warped design's)."""
    fs2 = 4.0
    z_z = np.concatenate(((fs2 + z) / (fs2 - z), -np.ones(p.size - z.size)))
    return z_z, (fs2 + p) / (fs2 - p), k * np.real(np.prod(fs2 - z) / np.prod(fs2 - p))


def _cplxreal(z: np.ndarray) -> np.ndarray:
    """scipy.signal's _cplxreal of a conjugate-paired set: the complex ones (upper half, sorted
    by real part) followed by the real ones, as one array."""
    tol = 100 * np.finfo(np.float64).eps
    z = z[np.lexsort((abs(z.imag), z.real))]
    real = abs(z.imag) <= tol * abs(z)
    zr = z[real].real
    if real.all():
        return zr
    zc = z[~real]
    zp, zn = zc[zc.imag > 0], zc[zc.imag < 0]
    if len(zp) != len(zn) or np.any(abs(zp - zn.conj()) > tol * abs(zn)):
        raise ValueError("roots with no matching conjugate")
    return np.concatenate(((zp + zn.conj()) / 2, zr))


def _nearest(fro: np.ndarray, to: complex, which: str) -> int:
    order = np.argsort(np.abs(fro - to))
    if which == "any":
        return int(order[0])
    return int(order[np.nonzero(np.isreal(fro[order]))[0][0]])


def _section(z: list, p: list) -> np.ndarray:
    sos = np.zeros(6)
    b, a = np.poly(z), np.poly(p)
    sos[3 - len(b):3] = b.real
    sos[6 - len(a):6] = a.real
    return sos


def _zpk2sos(z: np.ndarray, p: np.ndarray, k: float) -> np.ndarray:
    """scipy.signal.zpk2sos with its ``nearest`` pairing, for a digital filter with as many
    zeros as poles (a Butterworth low-pass or band-pass after the bilinear transform)."""
    if len(p) % 2 == 1:
        p, z = np.concatenate((p, [0.0])), np.concatenate((z, [0.0]))
    n_sections = len(p) // 2
    z, p = _cplxreal(z), _cplxreal(p)
    sos = np.zeros((n_sections, 6))
    for si in range(n_sections - 1, -1, -1):
        i = int(np.argmin(np.abs(1 - np.abs(p))))
        p1, p = p[i], np.delete(p, i)
        if np.isreal(p1) and np.isreal(p).sum() == 0:
            j = _nearest(z, p1, "real")
            sos[si], z = _section([z[j], 0], [p1, 0]), np.delete(z, j)
            continue
        if np.isreal(p1):
            real = np.flatnonzero(np.isreal(p))
            j = real[int(np.argmin(np.abs(1 - np.abs(p[real]))))]
            p2, p = p[j], np.delete(p, j)
        else:
            p2 = p1.conj()
        j = _nearest(z, p1, "any")
        z1, z = z[j], np.delete(z, j)
        if not np.isreal(z1):
            sos[si] = _section([z1, z1.conj()], [p1, p2])
        else:
            j = _nearest(z, p1, "real")
            sos[si], z = _section([z1, z[j]], [p1, p2]), np.delete(z, j)
    sos[0][:3] *= k
    return sos


# -- IIR filtering ------------------------------------------------------------------------------
def _all_pole(w: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Solve ``y[i] + a[1] y[i-1] + ... = w[i]`` (``a[0] == 1``) along the last axis of ``w``
    (n_rows, n), in place where it can: a unit lower-banded triangular system, every row a
    right-hand side of one LAPACK ``dtbtrs`` call."""
    n = w.shape[-1]
    ab = np.empty((a.size, n))
    ab[:] = a[:, None]
    y, info = lapack.dtbtrs(ab, w.T, uplo="L", diag="U", overwrite_b=1)
    if info != 0:
        raise ValueError(f"dtbtrs failed (info {info})")
    return y.T


def exp_filter(x: np.ndarray, c: float, y_prev: np.ndarray) -> np.ndarray:
    """``y[..., i] = c x[..., i] + (1 - c) y[..., i-1]`` along the last axis of ``x`` (n_rows, n),
    ``y[..., -1]`` before the first sample ``y_prev`` (n_rows,): ``scipy.signal.lfilter([c, 0],
    [1, c - 1], x, zi=(1 - c) y_prev)`` to rounding. A new array.

    ``y_prev`` enters the solve as one more sample before ``x`` (one that the recursion passes
    through unchanged), so the first sample is computed by the same operations as every other:
    a record filtered block by block, each block given the last value of the one before, gives
    the same bits as the whole record filtered at once."""
    x = np.asarray(x, dtype=np.float64)
    shape = x.shape
    rows = x.reshape(-1, shape[-1])
    w = np.empty((rows.shape[0], rows.shape[1] + 1))
    w[:, 0] = np.asarray(y_prev, dtype=np.float64).reshape(-1)
    np.multiply(rows, c, out=w[:, 1:])
    return _all_pole(w, np.array([1.0, c - 1.0]))[:, 1:].reshape(shape)


def sosfilt(sos: np.ndarray, x: np.ndarray, zi: np.ndarray | None = None) -> np.ndarray:
    """The sections ``sos`` (n_sections, 6; ``a0 == 1``) over the last axis of ``x`` (n_rows, n),
    with direct-form-II-transposed initial states ``zi`` (n_sections, n_rows, 2) or zeros:
    ``scipy.signal.sosfilt(sos, x, axis=-1, zi=zi)[0]`` to rounding."""
    y = np.asarray(x, dtype=np.float64)
    y = y.reshape(-1, y.shape[-1])
    return _sosfilt_into(sos, y, zi, (np.empty(y.shape), np.empty(y.shape), np.empty(y.shape)))


def _sosfilt_into(sos: np.ndarray, y: np.ndarray, zi: np.ndarray | None,
                  bufs: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """:func:`sosfilt` of ``y`` (n_rows, n) with its work arrays given: three C-ordered
    (n_rows, n) float64 arrays (the result is one of the first two; the third is scratch); the
    first and third must not share memory with ``y``, the second may (section 0 reads ``y``
    before section 1 writes there). Reusing warm arrays spares the page faults of fresh ones,
    which cost more than the arithmetic."""
    scratch = bufs[2]
    for s in range(sos.shape[0]):
        b0, b1, b2 = sos[s, :3]
        w = bufs[s % 2]
        np.multiply(y, b0, out=w)
        if b1 != 0:  # (0 for a band-pass's sections: adding 0 * y changes no bit)
            w[:, 1:] += np.multiply(y[:, :-1], b1, out=scratch[:, 1:])
        if b2 != 0:
            w[:, 2:] += np.multiply(y[:, :-2], b2, out=scratch[:, 2:])
        if zi is not None:
            w[:, :2] += zi[s]
        y = _all_pole(w, sos[s, 3:])
    return y


def _lfilter_zi(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """scipy.signal.lfilter_zi of a second-order section (``a[0] == 1``)."""
    companion = np.zeros((2, 2))
    companion[0] = -a[1:]
    companion[1, 0] = 1.0
    return np.linalg.solve(np.eye(2) - companion.T, b[1:] - a[1:] * b[0])


def sosfilt_zi(sos: np.ndarray) -> np.ndarray:
    """scipy.signal.sosfilt_zi: the step response's steady state (n_sections, 2)."""
    zi, scale = np.empty((sos.shape[0], 2)), 1.0
    for s in range(sos.shape[0]):
        b, a = sos[s, :3], sos[s, 3:]
        zi[s] = scale * _lfilter_zi(b, a)
        scale *= b.sum() / a.sum()
    return zi


def sosfiltfilt(sos: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Forward-backward ``sos`` over the last axis of ``x`` (n_rows, n) or (n,), with scipy's odd
    extension of ``3 (2 n_sections + 1)`` samples at each end and its initial states:
    ``scipy.signal.sosfiltfilt(sos, x, axis=-1)`` to rounding. ValueError for a record not
    longer than the extension."""
    x = np.asarray(x, dtype=np.float64)
    a = np.atleast_2d(x)
    n_sec = sos.shape[0]
    edge = 3 * (2 * n_sec + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum())))
    if a.shape[-1] <= edge:
        raise ValueError(f"the record ({a.shape[-1]} samples) must be longer than the filter's "
                         f"padding ({edge})")
    ext = np.concatenate((2 * a[:, :1] - a[:, edge:0:-1], a,
                          2 * a[:, -1:] - a[:, -2:-(edge + 2):-1]), axis=-1)
    zi = sosfilt_zi(sos)[:, None, :]
    out = np.empty((a.shape[0], a.shape[1]))
    step = max(1, _BLOCK_VALUES // ext.shape[1])
    for r in range(0, a.shape[0], step):
        out[r:r + step] = _filtfilt_rows(sos, ext[r:r + step], zi)[:, edge:-edge]
    return out.reshape(x.shape)


_BLOCK_VALUES = 131072
""":func:`sosfiltfilt` filters this many samples' worth of rows at a time (its work arrays, 1 MB
each, stay nearer the core than a whole 16-gage record's; each row's arithmetic, and so every
bit of its result, is the same in any block)."""


def _filtfilt_rows(sos: np.ndarray, ext: np.ndarray, zi: np.ndarray) -> np.ndarray:
    """Forward-backward ``sos`` over the rows of ``ext`` (n_rows, n, odd-extended; overwritten),
    from the step-response states ``zi`` (n_sections, 1, 2)."""
    ext = np.ascontiguousarray(ext)
    bufs = (np.empty(ext.shape), ext, np.empty(ext.shape))  # (ext is free once section 0 read it)
    y = _sosfilt_into(sos, ext, zi * ext[None, :, :1], bufs)
    if sos.shape[0] % 2:  # (the forward result lives in bufs[0], which the backward pass writes first)
        y = y.copy()
    return _sosfilt_into(sos, y[:, ::-1], zi * y[None, :, -1:], bufs)[:, ::-1]


def sosfreqz(sos: np.ndarray, f_hz: np.ndarray | int, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Frequency response of ``sos`` at ``f_hz`` (Hz), or at ``f_hz`` points evenly over
    ``[0, fs_hz / 2)`` for an integer: ``(f, H)`` as ``scipy.signal.sosfreqz(sos, worN=f_hz,
    fs=fs_hz)``."""
    if isinstance(f_hz, (int, np.integer)):
        w = np.linspace(0, np.pi, int(f_hz), endpoint=False)
    else:
        w = 2 * np.pi * np.atleast_1d(np.asarray(f_hz, dtype=np.float64)) / fs_hz
    zm1 = np.exp(-1j * w)
    h = 1.0
    for row in sos:
        h = h * (_polyval(zm1, row[:3]) / _polyval(zm1, row[3:]))
    return w * (fs_hz / (2 * np.pi)), h


def _polyval(x: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``c[0] + c[1] x + ...`` by Horner's rule (numpy.polynomial's order of operations)."""
    out = c[-1] + 0 * x
    for ci in c[-2::-1]:
        out = ci + out * x
    return out


def group_delay(b: np.ndarray, a: np.ndarray, f_hz: np.ndarray, fs_hz: float) -> np.ndarray:
    """Group delay (samples) of ``b / a`` at ``f_hz`` (Hz): ``scipy.signal.group_delay((b, a),
    w=f_hz, fs=fs_hz)[1]``."""
    w = 2 * np.pi * np.atleast_1d(np.asarray(f_hz, dtype=np.float64)) / fs_hz
    c = np.convolve(b, np.conjugate(a[::-1]))
    z = np.exp(-1j * w)
    gd = np.real(np.polyval((c * np.arange(c.size))[::-1], z) / np.polyval(c[::-1], z)) - a.size + 1
    if not np.all(np.isfinite(gd)):
        raise ValueError(f"the group delay is singular at {f_hz} Hz")
    return gd


# -- FIR ----------------------------------------------------------------------------------------
def fir_filter(b: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``scipy.signal.lfilter(b, [1], x, axis=-1)[..., len(b) - 1:]`` (the outputs that need no
    sample before the record) of every row of ``x`` (..., n), to rounding."""
    x = np.asarray(x, dtype=np.float64)
    rows = x.reshape(-1, x.shape[-1])
    out = np.empty((rows.shape[0], max(rows.shape[-1] - len(b) + 1, 0)))
    for i, r in enumerate(rows):
        out[i] = np.convolve(r, b, mode="valid") if out.shape[1] else out[i]
    return out.reshape(*x.shape[:-1], out.shape[1])


def kaiserord(ripple_db: float, width: float) -> tuple[int, float]:
    """Taps and Kaiser ``beta`` for ``ripple_db`` dB of ripple and a transition ``width`` (a
    fraction of Nyquist): ``scipy.signal.kaiserord``."""
    a = abs(ripple_db)
    if a < 8:
        raise ValueError(f"ripple ({a} dB) is too small for the Kaiser formula (>= 8)")
    beta = 0.1102 * (a - 8.7) if a > 50 else (
        0.5842 * (a - 21) ** 0.4 + 0.07886 * (a - 21) if a > 21 else 0.0)
    return int(math.ceil((a - 7.95) / 2.285 / (np.pi * width) + 1)), beta


def firwin_kaiser(numtaps: int, cutoff_hz: float, beta: float, fs_hz: float) -> np.ndarray:
    """Linear-phase low-pass FIR by the window method, unit DC gain: ``scipy.signal.firwin(
    numtaps, cutoff_hz, window=("kaiser", beta), fs=fs_hz)``."""
    c = float(np.asarray(cutoff_hz, dtype=np.float64) / float(0.5 * fs_hz))
    if not 0 < c < 1:
        raise ValueError(f"cutoff ({cutoff_hz} Hz) must lie inside (0, {fs_hz / 2}) Hz")
    m = np.arange(0, numtaps, dtype=np.float64) - 0.5 * (numtaps - 1)
    # scipy's steps for the one band [0, c], its zero terms kept: the taps are then bit-equal
    h = 0
    h += c * np.sinc(c * m)
    h -= 0.0 * np.sinc(0.0 * m)
    h *= _kaiser(numtaps, beta)
    h /= np.sum(h * np.cos(np.pi * m * 0.0))
    return h


def kaiser(n: int, beta: float, *, sym: bool = True) -> np.ndarray:
    """Kaiser window of ``n`` samples: ``scipy.signal.windows.kaiser(n, beta, sym=sym)`` (the
    periodic one, ``sym=False``, is the symmetric one of ``n + 1`` without its last sample)."""
    if n <= 1:
        return np.ones(n)
    if not sym:
        return _kaiser(n + 1, beta)[:-1]
    return _kaiser(n, beta)


def _kaiser(n: int, beta: float) -> np.ndarray:
    """The symmetric Kaiser window, n >= 2."""
    k = np.arange(0, n, dtype=np.float64)
    alpha = (n - 1) / 2.0
    return i0(beta * np.sqrt(1 - ((k - alpha) / alpha) ** 2.0)) / i0(np.asarray(beta, dtype=np.float64))


def minimum_phase(h: np.ndarray) -> np.ndarray:
    """The minimum-phase FIR of the same length and magnitude as the linear-phase ``h``
    (homomorphic): ``scipy.signal.minimum_phase(h, method="homomorphic", half=False)``."""
    h = np.asarray(h, dtype=np.float64)
    if h.ndim != 1 or h.shape[0] <= 2:
        raise ValueError("h must be 1-D and at least 3 taps long")
    n_fft = 2 ** int(math.ceil(math.log2(2 * (h.shape[0] - 1) / 0.01)))
    t = np.abs(np.fft.fft(h, n_fft))
    t += 1e-07 * np.min(t[t > 0])
    t = np.real(np.fft.ifft(np.log(t)))
    win = np.zeros(n_fft)
    win[0] = 1
    win[1:n_fft // 2] = 2
    if n_fft % 2:
        win[n_fft // 2] = 1
    t *= win
    return np.fft.ifft(np.exp(np.fft.fft(t))).real[:h.shape[0]]


_FIR_BLOCK = 32
"""Outputs a row of :func:`downsample_fir` computes from one segment of its samples."""


def downsample_fir(h: np.ndarray, x: np.ndarray, q: int) -> np.ndarray:
    """``scipy.signal.upfirdn(h, x, up=1, down=q, axis=-1)`` of ``x`` (n_rows, n): the full
    convolution of each row with ``h`` at samples 0, q, 2q, ... (``(n + len(h) - 2) // q + 1``
    of them), to rounding, as one matrix product: each run of :data:`_FIR_BLOCK` outputs is its
    segment of the zero-padded row, ``(_FIR_BLOCK - 1) q + len(h)`` samples, times a matrix
    whose column k holds the reversed taps from row k q (zeros elsewhere, which add exact
    zeros). Overlapping windows of the row times the taps, which NumPy cannot hand to BLAS, were
    3-5x dearer (a 14 s hit's NLS data, 14 gages x 28 812 samples by 3, 75 taps). Each output is
    the same sum whatever follows its segment in the row (a record read only as far as its first
    outputs need gives them to the bit)."""
    x = np.asarray(x, dtype=np.float64)
    g = np.asarray(h, dtype=np.float64)[::-1]
    rows, n = x.shape
    L, B = g.size, _FIR_BLOCK
    n_out = (n + L - 2) // q + 1
    n_blocks = -(-n_out // B)
    width = (B - 1) * q + L
    padded = np.zeros((rows, (n_blocks * B - 1) * q + L))
    padded[:, L - 1:L - 1 + n] = x
    segments = np.lib.stride_tricks.as_strided(
        padded, shape=(rows, n_blocks, width),
        strides=(padded.strides[0], B * q * padded.itemsize, padded.itemsize), writeable=False)
    taps = np.zeros((width, B))
    for k in range(B):
        taps[k * q:k * q + L, k] = g
    out = np.ascontiguousarray(segments).reshape(rows * n_blocks, width) @ taps
    return out.reshape(rows, n_blocks * B)[:, :n_out]


# -- peaks --------------------------------------------------------------------------------------
def log_parabola_peak(f_hz: np.ndarray, power: np.ndarray, k: int) -> float:
    """The frequency (Hz) of the line whose power spectrum ``power`` (n_bins,) peaks at bin
    ``k``: the vertex of the parabola through the log power of bins ``k - 1 .. k + 1``
    (Gaussian interpolation: a Hann window's main lobe is near Gaussian, so the line's
    frequency comes to a few per cent of a bin, where the bin's centre is off by up to half
    of one); the bin's centre at the spectrum's ends, where a neighbour holds no power, or where
    the three are level (no vertex)."""
    if not 0 < k < len(power) - 1 or min(power[k - 1:k + 2]) <= 0:
        return float(f_hz[k])
    a, b, c = np.log(power[k - 1:k + 2])
    den = a - 2 * b + c
    shift = 0.5 * (a - c) / den if den < 0 else 0.0
    return float(f_hz[k] + np.clip(shift, -0.5, 0.5) * (f_hz[1] - f_hz[0]))


def find_peaks(x: np.ndarray, distance: float) -> np.ndarray:
    """Indices of the local maxima of ``x`` (n,) (a flat top's middle sample), the lower ones
    within ``distance`` samples of a higher one dropped: ``scipy.signal.find_peaks(x,
    distance=distance)[0]``."""
    x = np.asarray(x, dtype=np.float64)
    if distance < 1:
        raise ValueError(f"distance ({distance}) must be >= 1")
    peaks = _local_maxima(x)
    d = math.ceil(distance)
    if peaks.size < 2 or np.all(np.diff(peaks) >= d):
        return peaks
    keep = np.ones(peaks.size, dtype=bool)
    pos = peaks.tolist()
    for j in np.argsort(x[peaks])[::-1].tolist():
        if not keep[j]:
            continue
        k = j - 1
        while k >= 0 and pos[j] - pos[k] < d:
            keep[k] = False
            k -= 1
        k = j + 1
        while k < len(pos) and pos[k] - pos[j] < d:
            keep[k] = False
            k += 1
    return peaks[keep]


def _local_maxima(x: np.ndarray) -> np.ndarray:
    """scipy.signal's _local_maxima_1d: samples above their left neighbour and above the first
    different sample to their right (a plateau's middle, rounded down)."""
    if x.size < 3:
        return np.zeros(0, dtype=np.intp)
    d = np.diff(x)
    if np.all(d != 0):
        return np.flatnonzero((d[:-1] > 0) & (d[1:] < 0)) + 1
    out, i, n = [], 1, x.size
    xs = x.tolist()
    while i < n - 1:
        if xs[i - 1] < xs[i]:
            ahead = i + 1
            while ahead < n - 1 and xs[ahead] == xs[i]:
                ahead += 1
            if xs[ahead] < xs[i]:
                out.append((i + ahead - 1) // 2)
                i = ahead
        i += 1
    return np.asarray(out, dtype=np.intp)
