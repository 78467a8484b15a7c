"""Subspace pole estimators for multi-channel free decays: Matrix Pencil, ESPRIT, ERA.

All three use the shift invariance of a Hankel matrix built from the record: every channel's
samples yₖ = Σᵢ cᵢ zᵢᵏ share the discrete poles zᵢ = exp(sᵢ / fs). They differ in how the
shift is solved:

- Matrix Pencil (Hua & Sarkar 1990), multi-channel form: the channels' Hankel matrices are stacked
  vertically (rows: channel × lag k, columns: lag i = 0 … L); the dominant right singular
  vectors V span the Vandermonde row space, and the poles are eig(V₁⁺ V₂) with V₁, V₂ = V without
  its last / first row (least-squares shift). Computed from the Gram matrix, (L+1)², so cost
  grows with L, not with the number of channels.
- ESPRIT (Roy & Kailath 1989), total-least-squares shift on the same subspace.
- ERA (Juang & Pappa 1985): block Hankel H₀ of the (n_channels × 1) "Markov parameters",
  H₀ = U Σ Vᵀ, A = Σ^(−½) Uᵀ H₁ V Σ^(−½) with H₁ shifted by one sample; poles = eig(A).

All take y of shape (n_channels, n_samples) and a model order (number of complex poles; a real
damped sinusoid needs two) and return discrete poles of shape (order,).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg
from scipy.linalg import lapack

__all__ = [
    "default_pencil_length",
    "era_poles",
    "esprit_poles",
    "hankel_row_space",
    "matrix_pencil_poles",
    "poles_to_modes",
]


def default_pencil_length(n_samples: int, max_length: int = 400) -> int:
    """Pencil parameter L: N/3 (statistically best for one channel), capped for cost."""
    return int(max(4, min(n_samples // 3, max_length)))


def _check(y: ArrayLike, order: int, L: int | None) -> tuple[np.ndarray, int]:
    a = np.atleast_2d(np.asarray(y))
    n = a.shape[-1]
    L = default_pencil_length(n) if L is None else int(L)
    if not 1 <= order < L < n - 1:
        raise ValueError(f"need 1 <= order ({order}) < L ({L}) < n_samples - 1 ({n - 1})")
    return a, L


def _hankel_gram(a: np.ndarray, L: int) -> np.ndarray:
    """Σ_c H_cᴴ H_c, H_c[k, i] = y_c[k + i] (k < n − L, i ≤ L), in O(C L²) (a new array).

    Along each diagonal G[i + 1, j + 1] = G[i, j] + Σ_c ȳ_c[m + i] y_c[m + j] − ȳ_c[i] y_c[j]
    (m = n − L): the first row is a correlation, the rest cumulative sums of those corrections.
    The upper triangle comes from that recursion, the strict lower one is its Hermitian mirror:
    every entry is written (the recursion's strided buffer leaves one slot per row untouched,
    which must never reach the caller uninitialised: ``eigh`` checks the whole matrix).
    """
    n_ch, n = a.shape
    m = n - L
    win = np.lib.stride_tricks.sliding_window_view
    dtype = a.dtype
    first = np.zeros(L + 1, dtype=dtype)  # G[0, d], d = 0 … L
    corr = np.empty((L, L + 1), dtype=dtype)  # Σ_c ȳ[m + p] y[m + p + d] − ȳ[p] y[p + d]
    tmp = np.empty((L, L + 1), dtype=dtype)
    pad = np.zeros(n + L, dtype=dtype)  # beyond the record: zeros (those entries are unused)
    for c, row in enumerate(a):
        first += np.correlate(row, row[:m], "valid")  # Σ_k y[k + d] ȳ[k]
        pad[:n] = row
        np.multiply(row[m:, None].conj(), win(pad[m:], L + 1)[:L], out=corr if c == 0 else tmp)
        if c:
            corr += tmp
        np.multiply(row[:L, None].conj(), win(pad[: 2 * L], L + 1)[:L], out=tmp)
        corr -= tmp
    # Diagonal d of G through a strided view: element (i, i + d) at flat i (L + 2) + d, so
    # view[i, d] = G[i, i + d] = first[d] + Σ_{p<i} corr[p, d]; the rows of the view do not
    # overlap; its entries with i + d > L land in the strict lower triangle, which, with the
    # one slot per row that no view row covers (the subdiagonal), is overwritten below.
    buf = np.empty((L + 1) * (L + 2) + L + 1, dtype=dtype)
    view = np.lib.stride_tricks.as_strided(buf, shape=(L + 1, L + 1),
                                           strides=((L + 2) * buf.itemsize, buf.itemsize))
    view[0] = first
    np.cumsum(corr, axis=0, out=view[1:])
    view[1:] += first
    G = buf[: (L + 1) ** 2].reshape(L + 1, L + 1)
    for i in range(1, L + 1):  # strict lower triangle: overwritten entirely by the mirror
        G[i, :i] = G[:i, i].conj()
    if np.iscomplexobj(G):  # exactly Hermitian: a real diagonal (eigh ignores its imaginary part)
        G.flat[:: L + 2] = G.diagonal().real
    return G


def hankel_row_space(
    y: ArrayLike, L: int | None = None, n_vectors: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Singular values and right singular vectors of the vertically stacked Hankel matrix.

    Parameters
    ----------
    y : array_like, shape (n_channels, n_samples)
        Free decay (noise preferably whitened per channel).
    L : int, optional
        Pencil parameter (columns − 1); default :func:`default_pencil_length`.
    n_vectors : int, optional
        Return only the leading ``n_vectors`` (a partial eigensolver: ~3× faster for the
        pencils' model orders at L = 400); default all L + 1.

    Returns
    -------
    s : numpy.ndarray, shape (L+1,) or (n_vectors,)
        Singular values, descending.
    V : numpy.ndarray, shape (L+1, L+1) or (L+1, n_vectors)
        Right singular vectors as columns, same order.
    """
    a, L = _check(y, 1, L)
    # Stacked Hankel: rows (channel, k = 0 … n−L−1), columns i = 0 … L; its Gram is the sum of
    # the channels' Grams, built in O(L²) per channel from its diagonal recursion.
    a = a if np.iscomplexobj(a) else np.asarray(a, dtype=float)
    G = _hankel_gram(a, L)
    if n_vectors is None or n_vectors >= L + 1:
        w, V = linalg.eigh(G, lower=False)
    elif 8 * n_vectors > L + 1 and not np.iscomplexobj(G) and hasattr(lapack, "dstevd"):
        # Many of them: divide and conquer on the tridiagonal form (all L + 1, a fixed cost),
        # only the vectors asked transformed back, is cheaper than the subset driver's bisection
        # and inverse iteration (a cost per vector): one channel's Gram, 28 vectors of 201 (the
        # order search's first pencil) 2.2 ms against 3.0 ms, of 101 (its residual round) 0.56
        # against 1.25 ms; 12 of 201 (a fit of 4 modes given) stays on the subset, 1.7 ms. The
        # same subspace to rounding (the poles depend on the span alone: ~1e-11 apart). SciPy
        # 1.14, the floor, does not wrap dstevd: there the subset driver below.
        w, V = _leading_eigh(G, n_vectors)
    else:
        w, V = linalg.eigh(G, lower=False, subset_by_index=[L + 1 - n_vectors, L], driver="evr")
    w, V = w[::-1], V[:, ::-1]
    return np.sqrt(np.clip(w, 0.0, None)), V


def _leading_eigh(G: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` largest eigenvalues (ascending) and their eigenvectors of the real symmetric
    ``G`` (its lower triangle read): Householder tridiagonalisation (dsytrd), all eigenpairs of
    the tridiagonal by divide and conquer (dstevd), the ``k`` wanted transformed back by the
    reflectors (dormqr on them, as dormtr does)."""
    n = G.shape[0]
    c, d, e, tau, info = lapack.dsytrd(G, lower=1, lwork=int(lapack.dsytrd_lwork(n, lower=1)[0]))
    if info != 0:
        raise linalg.LinAlgError(f"dsytrd failed ({info})")
    w, Z, info = lapack.dstevd(d, e, compute_v=1)
    if info != 0:
        raise linalg.LinAlgError(f"dstevd did not converge ({info})")
    Z = Z[:, n - k :]
    V = np.empty((n, k))
    V[0] = Z[0]  # Q = diag(1, Q'), Q' the reflectors stored below the subdiagonal
    refl = c[1:, : n - 1]
    lwork = int(lapack.dormqr("L", "N", refl, tau, Z[1:], -1)[1][0].real)
    V[1:], _, info = lapack.dormqr("L", "N", refl, tau, Z[1:], lwork)
    if info != 0:
        raise linalg.LinAlgError(f"dormqr failed ({info})")
    return w[n - k :], V


def matrix_pencil_poles(y: ArrayLike, order: int, L: int | None = None) -> np.ndarray:
    """Discrete poles by the multi-channel Matrix Pencil (least-squares shift).

    Parameters
    ----------
    y : array_like, shape (n_channels, n_samples)
        Free decay.
    order : int
        Number of complex poles (2 per real damped sinusoid).
    L : int, optional
        Pencil parameter.

    Returns
    -------
    numpy.ndarray, shape (order,)
        Discrete poles z = exp(s / fs).
    """
    _, L = _check(y, order, L)
    _, V = hankel_row_space(y, L, n_vectors=order)
    Vs = V[:, :order]
    V1, V2 = Vs[:-1], Vs[1:]
    return linalg.eigvals(linalg.lstsq(V1, V2)[0])


def esprit_poles(y: ArrayLike, order: int, L: int | None = None) -> np.ndarray:
    """Discrete poles by multi-channel TLS-ESPRIT on the stacked-Hankel row space.

    Parameters and returns as :func:`matrix_pencil_poles`.
    """
    _, L = _check(y, order, L)
    _, V = hankel_row_space(y, L, n_vectors=order)
    Vs = V[:, :order]
    C = np.hstack([Vs[:-1], Vs[1:]])
    _, _, Wh = linalg.svd(C, full_matrices=False)
    W = Wh.conj().T
    W12, W22 = W[:order, order:], W[order:, order:]
    return linalg.eigvals(-W12 @ linalg.inv(W22))


def era_poles(y: ArrayLike, order: int, n_block_rows: int | None = None) -> np.ndarray:
    """Discrete poles by the Eigensystem Realization Algorithm on a free decay.

    Parameters
    ----------
    y : array_like, shape (n_channels, n_samples)
        Free decay, read as the impulse response of a single-input system.
    order : int
        State dimension (2 per real damped sinusoid).
    n_block_rows : int, optional
        Block rows p of H₀ (lags); columns q = n_samples − p − 1. Default keeps p·n_channels near
        :func:`default_pencil_length`.

    Returns
    -------
    numpy.ndarray, shape (order,)
        Eigenvalues of the identified state matrix (discrete poles).
    """
    a = np.atleast_2d(np.asarray(y))
    n_ch, n = a.shape
    if n_block_rows is None:
        n_block_rows = max(-(-(order + 2) // n_ch) + 1, default_pencil_length(n) // n_ch)
    a, p = _check(a, order, n_block_rows)
    q = n - p - 1
    # H0[(i, c), j] = y_c[i + j]; i < p, j < q. Realised through its Gram on the column side.
    win = np.lib.stride_tricks.sliding_window_view(a, q, axis=-1)  # (n_ch, n − q + 1, q)
    H0 = win[:, :p, :].transpose(1, 0, 2).reshape(p * n_ch, q)
    H1 = win[:, 1 : p + 1, :].transpose(1, 0, 2).reshape(p * n_ch, q)
    G = H0 @ H0.conj().T
    w, U = linalg.eigh(G)
    idx = np.argsort(w)[::-1][:order]
    s = np.sqrt(np.clip(w[idx], 1e-300, None))
    U = U[:, idx]
    V = (H0.conj().T @ U) / s  # right singular vectors
    isq = 1.0 / np.sqrt(s)
    A = (isq[:, None] * (U.conj().T @ H1 @ V)) * isq[None, :]
    return linalg.eigvals(A)


def poles_to_modes(z: ArrayLike, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Frequency (Hz) and logarithmic decrement of discrete poles (upper half plane kept).

    Parameters
    ----------
    z : array_like
        Discrete poles exp(s / fs_hz).
    fs_hz : float
        Sample rate the poles belong to (Hz).

    Returns
    -------
    f_hz, delta : numpy.ndarray
        For poles with positive frequency only: f = Im s / 2π, δ = −Re s / f.
    """
    zz = np.asarray(z, dtype=complex)
    zz = zz[np.abs(zz) > 0]
    s = np.log(zz) * fs_hz
    f = s.imag / (2 * np.pi)
    keep = f > 0
    f, s = f[keep], s[keep]
    return f, -s.real / f
