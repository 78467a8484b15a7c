"""Nonlinear least squares for damped modes shared by all channels (variable projection).

Model, per channel c (weights w_c = 1/σ_c whiten the channels):

    y_c(t) = o_c + Σ_k e^(−δ_k f_k t) [b_ck cos(2π f_k t) + b'_ck sin(2π f_k t)]

The nonlinear parameters θ = [f₁, δ₁, f₂, δ₂, …] are shared by all channels; the linear ones
(offsets o_c, amplitudes b, b') are solved for every θ by least squares (Golub & Pereyra's
variable projection), so the optimiser sees 2·n_modes unknowns whatever the number of channels.
A Levenberg–Marquardt iteration (box bounds by projection) uses Kaufman's
Jacobian, −P⊥ (∂Φ/∂θᵢ) B, through its small normal equations; at the optimum JᵀJ equals the
Schur complement of the full (linear + nonlinear) Fisher matrix, so s²(JᵀJ)⁻¹ is the covariance
of θ with the linear parameters profiled out, s² the weighted residual variance. Parametrising
directly in f (Hz) and δ gives their standard errors without a delta method.

The complex amplitude a_ck = b_ck − j b'_ck makes y_c(t) = o_c + Σ_k Re(a_ck e^{(−δ_k f_k + j2πf_k) t}),
with t (s) measured from the first sample of the free decay. Data arrays are
(n_channels, n_samples), samples last.

How one evaluation is kept cheap (same results to rounding; see the functions for each)
----------------------------------------------------------------------------------------
- Basis on a uniform grid: exp(s t) as a product of two √N-long tables (:func:`damped_basis`), one
  complex multiply per sample instead of an exp, a cos and a sin (≤ 3 ulp apart).
- Arrays are laid out samples-last (Φ is the transpose of a C-ordered array), so every product
  with Φ runs along contiguous memory; Φᵀ buffers are reused within a fit.
- Normal equations from the 2K × 2K Schur complement Tᵀ P⊥ T, T = t·Φ, instead of the
  n_samples × 4K derivative matrix projected explicitly (:class:`_Problem`).
- Small factorisations call LAPACK/BLAS directly (potrf/potrs/posv/trsm, as scipy's wrappers).
- Modes whose poles are held (the order search's trial fits) are projected out once
  (:class:`HeldPoleFitter`); those trial fits take Σr² and Tᵀr from Grams, never forming a
  residual as large as the data, where that keeps the digits they need (:class:`_GramResidual`).
- Residuals are written into reused buffers (a fresh one per evaluation cost more in page
  faults than the product itself); channels fitted one by one from the same start share the
  first evaluation (:func:`fit_channels_varpro`).
Their measured effect is in ``docs/estimators.md`` ("Speed").
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg
from scipy.linalg import blas, get_lapack_funcs, lapack
from scipy.linalg.lapack import _compute_lwork

__all__ = ["VarProFit", "fit_channels_varpro", "fit_modes_varpro", "kaufman_weights", "linear_amplitudes"]

_TWO_PI = 2.0 * np.pi


class LMStop(StrEnum):
    """How the Levenberg–Marquardt of a fit ended. Only ``CONVERGED`` is convergence."""

    CONVERGED = "converged"
    GAVE_UP = "gave up"
    """The damping grew past 1e10 and no step lowered Σr² (or left a bound it was stuck on)."""
    ITERATION_LIMIT = "iteration limit"


@dataclass(frozen=True)
class VarProFit:
    """Result of :func:`fit_modes_varpro`.

    Attributes
    ----------
    f_hz, delta : numpy.ndarray, shape (n_modes,)
        Frequencies (Hz) and logarithmic decrements.
    covariance : numpy.ndarray, shape (2 n_modes, 2 n_modes)
        Covariance of [f₁, δ₁, f₂, δ₂, …] (white-noise assumption).
    amplitude : numpy.ndarray, shape (n_channels, n_modes), complex
        Complex amplitudes at t = 0.
    offset : numpy.ndarray, shape (n_channels,)
        Constant offsets, the trend's P₀ coefficient (0 when not fitted).
    rss : numpy.ndarray, shape (n_channels,)
        Unweighted residual sum of squares per channel.
    noise_std : numpy.ndarray, shape (n_channels,)
        Residual std per channel, corrected for the parameters used.
    n_eval : int
        Function evaluations.
    success : bool
        The optimiser converged (``stop`` is ``LMStop.CONVERGED``).
    stop : LMStop
        How the optimiser ended: converged, gave up or at the iteration limit.
    """

    f_hz: np.ndarray
    delta: np.ndarray
    covariance: np.ndarray
    amplitude: np.ndarray
    offset: np.ndarray
    rss: np.ndarray
    noise_std: np.ndarray
    n_eval: int
    success: bool
    stop: LMStop


def uniform_grid(t: np.ndarray) -> tuple[float, float] | None:
    """(t₀, Δt) when t is a uniform grid to rounding (t = t₀ + n Δt), else None."""
    if t.size < 64:
        return None
    t0, dt = float(t[0]), float(t[-1] - t[0]) / (t.size - 1)
    if not dt > 0:
        return None
    tol = 1e-12 * (abs(t0) + abs(float(t[-1])) + dt)
    g = np.arange(t.size, dtype=float)  # |t - (t0 + dt n)| in one buffer: the same operations
    g *= dt
    g += t0
    np.subtract(t, g, out=g)
    if np.max(np.abs(g, out=g)) > tol:
        return None
    return t0, dt


def damped_basis(
    t: np.ndarray, f: np.ndarray, d: np.ndarray, offset: bool | int,
    grid: tuple[float, float] | None = None, scratch: dict | None = None,
    out: np.ndarray | None = None, by_matmul: bool = False,
) -> np.ndarray:
    """Φ, shape (n_samples, 2K [+p]): columns e·cos, e·sin per mode (+ a trend), e = exp(−δ f t).

    The trend: ``offset`` (True = 1, or an int p) columns, the Legendre polynomials P₀ … P₍p₋₁₎ of
    the time mapped onto [−1, 1] over the record: a constant, then a slow drift of degree p − 1
    (:func:`trend_basis`).

    Returned as the transpose of a C-ordered (2K [+1], n_samples) array, so that every product
    with Φ runs along contiguous samples. On a uniform grid (``grid`` from
    :func:`uniform_grid`) the complex exponentials exp(s (t₀ + n Δt)) are products of two short
    tables, exp(s (t₀ + j Δt)) · exp(s i m Δt) with n = i m + j and m ≈ √N: one complex multiply
    per sample instead of an exp, a cos and a sin, equal to within a few ulp. ``scratch``: a dict
    in which the complex work array is kept between calls (fewer large allocations); ``out``:
    a (2K [+1], n_samples) array to fill with Φᵀ. ``by_matmul``: that product as a real matrix
    product by BLAS instead (:func:`_blocked_basis`: ~2x faster, the same to rounding but not to
    the bit; a hit's finals use it, the default keeps the bits other callers were tuned on).
    """
    K, n = f.size, t.size
    n_trend = int(offset)
    PhiT = np.empty((2 * K + n_trend, n)) if out is None else out
    s = -(d * f) + 1j * (_TWO_PI * f)
    blocked = False
    if grid is not None and K:
        t0, dt = grid
        ends = np.maximum(s.real * t0, s.real * (t0 + dt * (n - 1)))
        blocked = bool((ends < 300.0).all())  # else the envelope clamp below is active
    if blocked and by_matmul:
        _blocked_basis(PhiT, s, t0, dt, n, scratch)
    elif blocked and scratch is None and K > 1:
        # No work array kept between calls: one mode at a time through a small complex buffer
        # (the same products, to the bit). A fresh (K, rows, m) complex array next to a fresh Φᵀ
        # cost more in page faults than the products: 12 candidates on 4071 samples (the order
        # search's ranking) 0.84 ms -> ~0.15 ms.
        lo, hi = _grid_tables(s, t0, dt, n, scratch)
        rows, m = hi.shape[1], lo.shape[1]
        work = np.empty((rows, m), dtype=complex)
        z = work.reshape(rows * m)[:n]
        for k in range(K):
            np.multiply(hi[k, :, None], lo[k, None, :], out=work)
            PhiT[2 * k] = z.real
            PhiT[2 * k + 1] = z.imag
    elif blocked:
        lo, hi = _grid_tables(s, t0, dt, n, scratch)
        rows, m = hi.shape[1], lo.shape[1]
        work = None if scratch is None else scratch.get("z")
        if work is None or work.shape != (K, rows, m):
            work = np.empty((K, rows, m), dtype=complex)
            if scratch is not None:
                scratch["z"] = work
        np.multiply(hi[:, :, None], lo[:, None, :], out=work)
        Z = work.reshape(K, rows * m)[:, :n]
        PhiT[0 : 2 * K : 2] = Z.real
        PhiT[1 : 2 * K : 2] = Z.imag
    elif K:
        env = np.exp(np.minimum(-(d * f)[:, None] * t[None, :], 300.0))
        arg = _TWO_PI * f[:, None] * t[None, :]
        PhiT[0 : 2 * K : 2] = env * np.cos(arg)
        PhiT[1 : 2 * K : 2] = env * np.sin(arg)
    if n_trend == 1:
        PhiT[-1] = 1.0
    elif n_trend > 1:
        PhiT[2 * K :] = trend_basis(t, n_trend)
    return PhiT.T


def _grid_tables(s: np.ndarray, t0: float, dt: float, n: int,
                 scratch: dict | None) -> tuple[np.ndarray, np.ndarray]:
    """The short tables whose products give exp(s_k (t0 + i dt)), i < n, for the poles ``s``
    (K,): with i = r m + j (m = ceil(sqrt n)), ``lo`` = exp(s (t0 + j dt)) (K, m) and ``hi`` =
    exp(s r m dt) (K, rows); the two time grids kept in ``scratch["grids"]``."""
    grids = None if scratch is None else scratch.get("grids")
    if grids is None:
        m = int(np.ceil(np.sqrt(n)))
        grids = (t0 + dt * np.arange(m), dt * m * np.arange(-(-n // m)))
        if scratch is not None:
            scratch["grids"] = grids
    return np.exp(s[:, None] * grids[0][None, :]), np.exp(s[:, None] * grids[1][None, :])


def _blocked_basis(PhiT: np.ndarray, s: np.ndarray, t0: float, dt: float, n: int,
                   scratch: dict | None) -> None:
    """Rows 2k, 2k+1 of ``PhiT`` (2K [+p], n), C-ordered rows) = Re, Im exp(s_k (t₀ + i Δt)),
    i < n, for the poles ``s`` (K,) (1/s): with i = r m + j (m ≈ √n), the product of the short
    tables h = exp(s r m Δt) and l = exp(s (t₀ + j Δt)) written as a real matrix product per
    mode, [Re; Im](r, j) = [[Re h, −Im h], [Im h, Re h]](r) · [Re l; Im l](j), by BLAS straight
    into Φᵀ's rows seen as (rows, m) blocks (no complex work array, no strided copies out of
    one: ~2x faster than the complex product of the default path, the same to rounding, ≲ 1 ulp of the
    larger term)."""
    K = s.size
    lo, hi = _grid_tables(s, t0, dt, n, scratch)
    rows, m = hi.shape[1], lo.shape[1]
    A = np.empty((K, 2, rows, 2))  # per mode and part (Re, Im): the row's 2 weights of (Re l, Im l)
    A[:, 0, :, 0] = A[:, 1, :, 1] = hi.real
    np.negative(hi.imag, out=A[:, 0, :, 1])
    A[:, 1, :, 0] = hi.imag
    L = np.empty((K, 1, 2, m))
    L[:, 0, 0], L[:, 0, 1] = lo.real, lo.imag
    full = n // m  # whole rows of m samples; the last, partial one apart
    dest = PhiT if PhiT.strides[1] == PhiT.itemsize else np.empty((2 * K, n))
    s0, item = dest.strides
    view = np.lib.stride_tricks.as_strided(dest, shape=(K, 2, full, m),
                                           strides=(2 * s0, s0, m * item, item))
    np.matmul(A[:, :, :full], L, out=view)
    if full * m < n:
        dest[: 2 * K, full * m :] = (A[:, :, full] @ L[:, 0]).reshape(2 * K, m)[:, : n - full * m]
    if dest is not PhiT:  # (rows not contiguous: written through a C-ordered copy)
        PhiT[: 2 * K] = dest


def trend_basis(t: np.ndarray, n_trend: int) -> np.ndarray:
    """The trend columns of :func:`damped_basis` as rows, shape (n_trend, n_samples): Legendre
    P₀ … P₍n₋₁₎ of τ = 2 (t − t₀)/(t_last − t₀) − 1 (well conditioned on a uniform grid)."""
    span = float(t[-1] - t[0]) if t.size > 1 else 1.0
    tau = 2.0 * (t - t[0]) / (span if span > 0 else 1.0) - 1.0
    return np.polynomial.legendre.legvander(tau, n_trend - 1).T


def linear_amplitudes(
    t_s: np.ndarray, y: np.ndarray, f_hz: ArrayLike, delta: ArrayLike, *, fit_offset: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares complex amplitudes for fixed poles.

    Parameters
    ----------
    t_s : numpy.ndarray, shape (n_samples,)
        Sample times (s) from the start of the decay.
    y : numpy.ndarray, shape (n_channels, n_samples)
        Data.
    f_hz, delta : array_like, shape (n_modes,)
        Fixed poles.
    fit_offset : bool or int
        Include a constant per channel (True), or p trend columns (:func:`damped_basis`).

    Returns
    -------
    amplitude : numpy.ndarray, shape (n_channels, n_modes), complex
    offset : numpy.ndarray, shape (n_channels,)
    rss : numpy.ndarray, shape (n_channels,)
    """
    f = np.atleast_1d(np.asarray(f_hz, dtype=float))
    d = np.atleast_1d(np.asarray(delta, dtype=float))
    proj = Projector(damped_basis(t_s, f, d, fit_offset, uniform_grid(t_s)))
    B = proj.coef(y.T)
    rss = np.sum((y.T - proj.Phi @ B) ** 2, axis=0)
    K = f.size
    amp = (B[0 : 2 * K : 2] - 1j * B[1 : 2 * K : 2]).T
    off = B[2 * K] if fit_offset else np.zeros(y.shape[0])  # P₀'s coefficient: the constant
    return amp, off, rss


def projected_gram(W: np.ndarray, QT: np.ndarray | None) -> np.ndarray | None:
    """The Gram of ``W``'s rows (k, n) with their part in the span of ``QT``'s orthonormal rows
    removed, ``W W^T - (W Q)(W Q)^T`` (k, k); None where a diagonal entry lost more than all but
    1e-6 of ``W W^T``'s to the subtraction (a row nearly in Q's span: its digits are gone)."""
    G0 = W @ W.T
    G = G0
    if QT is not None:
        WQ = W @ QT.T
        G = G0 - WQ @ WQ.T
    return G if (G.diagonal() >= 1e-6 * G0.diagonal()).all() else None


class Projector:
    """Least squares on the basis Φ: Cholesky of the column-scaled Gram, QR if ill-conditioned.

    The small factorisations call LAPACK directly (potrf / potrs: the routines
    ``scipy.linalg.cho_factor`` and ``cho_solve`` wrap, with identical results) — their argument
    checking cost more than the 2 × 2 to 25 × 25 solves themselves. The triangular solve is
    BLAS trsm, not LAPACK trtrs (``solve_triangular``): the same bits, but with OpenBLAS's
    default two threads on a loaded 2-core machine trtrs took up to 8 ms for these 2 × 2 to
    11 × 11 solves (its thread pool is woken whatever the size), trsm at most 0.2 ms.
    """

    def __init__(self, Phi: np.ndarray | None, gram: np.ndarray | None = None) -> None:
        self.Phi = self.raw = Phi  # raw: Φ before any projection (see _Problem)
        G = Phi.T @ Phi if gram is None else gram  # Phi None: from the Gram alone (no QR path)
        norm = np.sqrt(G.diagonal())
        self.inv_norm = 1.0 / np.where(norm > 0, norm, 1.0)
        G = G * self.inv_norm[:, None] * self.inv_norm[None, :]
        self.cho = None
        c, info = lapack.dpotrf(G, lower=1)
        if info == 0 and np.abs(c.diagonal()).min() ** 2 > 1e-10:  # cond(Φ) below ~1e5
            self.cho = (c, True)
        if self.cho is None and Phi is not None:
            self.Q, self.R = linalg.qr(Phi, mode="economic", check_finite=False)

    def coef(self, M: np.ndarray) -> np.ndarray:
        """Coefficients C minimising ‖M − Φ C‖ (columns of M independently)."""
        if self.cho is not None:
            return self.coef_from(self.Phi.T @ M)
        return linalg.lstsq(self.R, self.Q.T @ M, check_finite=False)[0]

    def coef_from(self, PhiT_M: np.ndarray) -> np.ndarray:
        """As :meth:`coef` given Φᵀ M (Cholesky path only)."""
        rhs = PhiT_M * self.inv_norm[:, None]
        return lapack.dpotrs(self.cho[0], rhs, lower=1)[0] * self.inv_norm[:, None]

    def whitened(self, PhiT_M: np.ndarray) -> np.ndarray:
        """L⁻¹ (scaled Φᵀ M): (Φᵀ M)ᵀ (ΦᵀΦ)⁻¹ (Φᵀ M) = Vᵀ V for the returned V (Cholesky path)."""
        return blas.dtrsm(1.0, self.cho[0], PhiT_M * self.inv_norm[:, None], lower=1)


_GRAM_MIN_FRACTION = 1e-4  # Grams only while Σr² ≥ 10⁻⁴ Σy² (≲ 4 of 16 digits lost)


class _GramResidual:
    """A residual known by its Σr² per channel (``ss``, (n_channels,); None where only Tᵀr is
    wanted, :class:`GaussNewtonGain`) alone.

    Σr²_c = Σy²_c − yᵀΦ(ΦᵀΦ)⁻¹Φᵀy (from ΦᵀY and the coefficients B) and Tᵀr = TᵀY − (ΦᵀT)ᵀB
    need no (n_samples × n_channels) residual: an evaluation touches the data once, in one
    product, instead of forming, squaring and summing a residual as large as the data (twice
    as dear for the order search's trial fits). The subtraction loses the digits of Σy²/Σr²:
    used only while Σr² ≥ ``_GRAM_MIN_FRACTION`` Σy² per channel (relative error ≲ 10⁻¹¹ with
    the products' own rounding, against the trial fits' 10⁻³ of the residual variance per
    degree of freedom, ≥ 10⁻⁹ of Σr² on 16 channels × 12k samples), otherwise the residual is
    formed as before.
    """

    __slots__ = ("ss",)

    def __init__(self, ss: np.ndarray) -> None:
        self.ss = ss


class _Problem:
    """Residual, gradient and Gauss–Newton matrix of the weighted variable-projection functional.

    Kaufman's Jacobian column for θᵢ is −P⊥ (∂Φ/∂θᵢ) B. Every derivative column of mode k is a
    combination of t·e·cos and t·e·sin of that mode, so with T = t·Φ_osc (n_samples × 2K),
    ∂Φ/∂θᵢ B_c = T gᵢ_c for a vector gᵢ_c with two non-zeros (mode k's entries, from B and θ).
    Then JᵀJ = Σ_c gᵢ_cᵀ (Tᵀ P⊥ T) gⱼ_c and Jᵀr = −Σ_c gᵢ_cᵀ Tᵀ r_c: only the 2K × 2K Schur
    complement Tᵀ P⊥ T (from the Grams ΦᵀΦ, ΦᵀT, TᵀT and the projector's Cholesky) and Tᵀr
    (2K × n_channels) touch the samples. When that complement has lost more than half the
    digits, or Φ needed the QR path, P⊥T is formed explicitly instead.

    ``fixed`` (n_samples × m): further basis columns whose coefficients are fitted but that do
    not depend on θ (the offset and modes whose poles are held). They are projected out once
    (one QR): the data become P⊥_F Y and the basis P⊥_F Φ(θ), whose span with F is the same, so
    residual, B (coefficients of the unprojected Φ) and JᵀJ, Jᵀr (the θ block of the problem
    with all columns) are unchanged while every evaluation touches 2K + m columns, not
    (2K + m)².

    ``grid``: :func:`uniform_grid` of ``t`` where the caller has it (the channels fitted one by
    one on the same times; default False: computed here). ``by_matmul``: :func:`damped_basis`'s.
    """

    def __init__(
        self, t: np.ndarray, Yw: np.ndarray, offset: bool, fixed: np.ndarray | None = None,
        grid: tuple[float, float] | None | bool = False, by_matmul: bool = False,
    ) -> None:
        self.t, self.offset, self.by_matmul = t, offset, by_matmul
        self.Yc = np.ascontiguousarray(np.asarray(Yw).T)  # (n_channels, n_samples)
        self.grid = uniform_grid(t) if grid is False else grid  # (given: uniform_grid(t))
        self.scratch: dict = {}
        self._pool: list[np.ndarray] = []  # Φᵀ buffers of projectors the caller released
        self._rpool: list[np.ndarray] = []  # residual buffers of points the caller released
        self.QfT = None
        if fixed is not None and fixed.shape[1]:
            Q, R = linalg.qr(fixed, mode="economic", check_finite=False)
            rd = np.abs(np.diag(R))
            Q = Q[:, rd > 1e-10 * rd.max()]  # drop dependent fixed columns (same span)
            self.QfT = np.ascontiguousarray(Q.T)  # (m, n_samples)
            # Yc − (Yc Q_F) Q_Fᵀ, the difference written over the product: the same operations,
            # one data-sized array allocated, not two (16 gages x 4071 samples: 0.45 -> 0.07 ms,
            # page faults)
            proj_f = (self.Yc @ self.QfT.T) @ self.QfT
            self.Yc = np.subtract(self.Yc, proj_f, out=proj_f)
            self.offset = False  # a fitted constant, if any, is among the fixed columns
        self.Yw = self.Yc.T  # (n_samples, n_channels)
        self._yy: np.ndarray | None = None  # Σy² per channel once Grams are used (use_grams)

    def use_grams(self) -> None:
        """From now on, Σr² per channel from Grams where they keep enough digits (see
        :class:`_GramResidual`): for trial fits, whose tolerance is far above the digits lost."""
        self._yy = np.einsum("ij,ij->i", self.Yc, self.Yc)

    def _perp(self, A: np.ndarray) -> np.ndarray:
        """P⊥_F A for A of shape (n_samples, k) (A itself without fixed columns)."""
        if self.QfT is None:
            return A
        AT = A.T
        return (AT - (AT @ self.QfT.T) @ self.QfT).T

    def _gram_point(self, theta: np.ndarray, need_ss: bool = True
                    ) -> tuple[_GramResidual, Projector, np.ndarray] | None:
        """:meth:`residual` from Grams alone (after :meth:`use_grams`), or None where they would
        lose digits. The rows W = [Φᵀ; (t·Φ_modes)ᵀ] of the unprojected basis and its time
        derivative columns meet the data once (W Yw: Yw ⊥ F, so (P⊥Φ)ᵀYw = ΦᵀYw), the fixed
        columns once (W Q_F) and themselves once (W Wᵀ): P⊥_F Φ and P⊥_F T are never formed;
        their Grams are W Wᵀ − (W Q_F)(W Q_F)ᵀ, used while no diagonal entry falls below 10⁻⁶ of
        its unprojected value (else None: the explicit path). ``need_ss`` False: for Jᵀr and JᵀJ
        alone (:class:`GaussNewtonGain`), Σr² not computed (``ss`` None), no Σr² test."""
        K, n = theta.size // 2, self.t.size
        P = 2 * K + int(self.offset)
        shape = (P + 2 * K, n)
        W = self._pool.pop() if self._pool and self._pool[-1].shape == shape else np.empty(shape)
        damped_basis(self.t, theta[0::2], theta[1::2], self.offset, self.grid, self.scratch,
                     out=W[:P], by_matmul=self.by_matmul)
        np.multiply(W[: 2 * K], self.t[None, :], out=W[P:])
        G = projected_gram(W, self.QfT)
        if G is None:
            if len(self._pool) < 4:
                self._pool.append(W)
            return None
        proj = Projector(None, gram=G[:P, :P])
        proj.raw = W[:P].T
        if proj.cho is None:
            self.release(proj)
            return None
        WY = W @ self.Yw
        B = proj.coef_from(WY[:P])
        ss = None
        if need_ss:
            ss = self._yy - np.sum(WY[:P] * B, axis=0)
            if not (ss >= _GRAM_MIN_FRACTION * self._yy).all():
                self.release(proj)
                return None
        proj.grams = (G[:P, P:], G[P:, P:], WY[P:], None)  # ΦᵀP⊥T, TᵀP⊥T, TᵀY, (Tᵀr)
        return _GramResidual(ss), proj, B

    def residual(self, theta: np.ndarray) -> tuple[np.ndarray, Projector, np.ndarray]:
        """(r, projector, B): r = Yw − Φ B, shape (n_samples, n_channels) (a transposed view);
        after :meth:`use_grams`, a :class:`_GramResidual` where it keeps the digits."""
        if self._yy is not None and (got := self._gram_point(theta)) is not None:
            return got
        shape = (theta.size + int(self.offset), self.t.size)
        buf = self._pool.pop() if self._pool and self._pool[-1].shape == shape else None
        raw = damped_basis(self.t, theta[0::2], theta[1::2], self.offset, self.grid, self.scratch,
                           out=buf, by_matmul=self.by_matmul)
        proj = Projector(self._perp(raw))
        proj.raw = raw
        B = proj.coef(self.Yw)
        # r = Yc − Bᵀ Φᵀ into a reused (n_channels, n_samples) buffer: a fresh one per call cost
        # more in page faults than the product itself (same operations, same bits).
        rbuf = self._rpool.pop() if self._rpool else np.empty_like(self.Yc)
        np.matmul(B.T, proj.Phi.T, out=rbuf)
        np.subtract(self.Yc, rbuf, out=rbuf)
        proj.resid_buf = rbuf
        return rbuf.T, proj, B

    def sumsq(self, resid: np.ndarray) -> float:
        """Σr² of a residual from :meth:`residual` (as ``np.sum(resid**2)``, without allocating)."""
        if isinstance(resid, _GramResidual):
            return float(np.sum(resid.ss))
        sq = self.scratch.get("sq")
        if sq is None or sq.shape != self.Yc.shape:
            sq = self.scratch["sq"] = np.empty_like(self.Yc)
        np.square(resid, out=sq.T)
        return float(np.sum(sq))

    @staticmethod
    def channel_ss(resid: np.ndarray) -> np.ndarray:
        """Σr² per channel of a residual from :meth:`residual`, shape (n_channels,)."""
        if isinstance(resid, _GramResidual):
            return resid.ss
        return np.sum(resid**2, axis=0)

    def release(self, proj: Projector, keep_residual: bool = False) -> None:
        """Hand back a projector from :meth:`residual` that will not be used again (its Φᵀ
        buffer, and unless ``keep_residual`` the residual computed with it, are reused by a
        later call; without release every call allocates)."""
        rbuf = getattr(proj, "resid_buf", None)
        if rbuf is not None and not keep_residual and len(self._rpool) < 4:
            self._rpool.append(rbuf)
        proj.resid_buf = None
        buf = proj.raw.base  # Φ is the transposed view of the (2K [+1], n_samples) array
        if (buf is not None and buf.flags.owndata and buf.flags.c_contiguous and buf.ndim == 2
                and buf.shape[1] == self.t.size and len(self._pool) < 4):
            self._pool.append(buf)

    def normal_equations(
        self, theta: np.ndarray, resid: np.ndarray, proj: Projector, B: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(JᵀJ, Jᵀr) at θ for the residual computed there."""
        f, d = theta[0::2], theta[1::2]
        K = f.size
        grams = getattr(proj, "grams", None)
        if grams is not None:
            PtT, TT, TtY, Tr = grams  # Tᵀr itself when known, else from TᵀY
            V = proj.whitened(PtT)
            M = TT - V.T @ V
            if (M.diagonal() > 1e-8 * TT.diagonal()).all():
                return self._jtj_jtr(f, d, B, M, TtY - PtT.T @ B if Tr is None else Tr)
            raw = proj.raw  # the Schur complement lost digits: the explicit path
            proj = Projector(self._perp(raw))
            proj.raw = raw
        Phi = proj.Phi
        work = self.scratch.get("T")
        if work is None or work.shape != (2 * K, self.t.size):
            work = self.scratch["T"] = np.empty((2 * K, self.t.size))
        np.multiply(proj.raw[:, : 2 * K].T, self.t[None, :], out=work)
        T = self._perp(work.T)  # t·e·cos, t·e·sin per mode (a scratch array: not kept)
        TT = T.T @ T
        M = None
        PtT = Phi.T @ T if proj.cho is not None or isinstance(resid, _GramResidual) else None
        if proj.cho is not None:
            V = proj.whitened(PtT)
            M = TT - V.T @ V
            if not (M.diagonal() > 1e-8 * TT.diagonal()).all():
                M = None
        if M is None:
            Tp = T - Phi @ proj.coef(T)
            M = Tp.T @ Tp
        if isinstance(resid, _GramResidual):  # Tᵀr = TᵀY − (ΦᵀT)ᵀ B
            Tr = T.T @ self.Yw - PtT.T @ B
        else:
            Tr = T.T @ resid  # (2K, n_channels); P⊥ r = r
        return self._jtj_jtr(f, d, B, M, Tr)

    @staticmethod
    def _jtj_jtr(f: np.ndarray, d: np.ndarray, B: np.ndarray, M: np.ndarray,
                 Tr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(JᵀJ, Jᵀr) from the Schur complement M = Tᵀ P⊥ T (2K × 2K) and Tᵀr (2K × C)."""
        K = f.size
        # JᵀJ = Σ_c Hᵀ M H blockwise and Jᵀr = −Σ_c Hᵀ Tᵀr (H: kaufman_weights)
        H = kaufman_weights(B, f, d)
        HM = np.einsum("kpac,kalb->kplbc", H, M.reshape(K, 2, K, 2))
        JtJ = np.einsum("kplbc,lqbc->kplq", HM, H).reshape(2 * K, 2 * K)
        JtJ = 0.5 * (JtJ + JtJ.T)
        Jtr = -np.einsum("kpac,kac->kp", H, Tr.reshape(K, 2, -1)).reshape(2 * K)
        return JtJ, Jtr


def kaufman_weights(B: np.ndarray, f: np.ndarray, d: np.ndarray) -> np.ndarray:
    """H (K, 2, 2, C): the weight ``H[k, p, a, c]`` of the time-derivative column (k, a) of
    T = t Φ (a: t·e·cos, t·e·sin of mode k) in ∂Φ/∂θ_(k,p) B_c (p: f, δ), so that channel c's
    Kaufman Jacobian column for θ_(k,p) is −P⊥ T H[k, p, :, c]; from the coefficients B
    (2K [+ trend], C) of the modes' columns at poles f (Hz), δ (K,). With (b, b') = B[2k:2k+2]:
    ∂/∂f: t·c (−δ b + 2π b') + t·s (−2π b − δ b'); ∂/∂δ: −f (t·c b + t·s b')."""
    K = f.size
    b, bp = B[0 : 2 * K : 2], B[1 : 2 * K : 2]  # (K, C)
    dd, ff = d[:, None], f[:, None]
    H = np.empty((K, 2, 2, B.shape[1]))
    H[:, 0, 0] = _TWO_PI * bp - dd * b
    H[:, 0, 1] = -_TWO_PI * b - dd * bp
    H[:, 1, 0] = -ff * b
    H[:, 1, 1] = -ff * bp
    return H


_GESDD = get_lapack_funcs(("gesdd", "gesdd_lwork"), (np.eye(2),), ilp64="preferred")


def pinv_small(a: np.ndarray, atol: float = 0.0) -> np.ndarray:
    """``scipy.linalg.pinv(a, atol=atol)`` of a small real (m, n) float64 matrix, equal to the bit:
    the same LAPACK routine (gesdd, scipy's choice of integer width and workspace) and the same
    arithmetic after it, without the wrappers' checks, which cost more than a 2 x 2 to 24 x 24
    decomposition itself (~0.25 ms a call, ~40 calls a hit). Non-finite entries: ValueError."""
    if not np.isfinite(a).all():
        raise ValueError("array must not contain infs or NaNs")
    gesdd, gesdd_lwork = _GESDD
    lwork = _compute_lwork(gesdd_lwork, a.shape[0], a.shape[1], compute_uv=True,
                           full_matrices=False)
    u, s, vh, info = gesdd(a, compute_uv=True, lwork=lwork, full_matrices=False)
    if info > 0:
        raise linalg.LinAlgError("SVD did not converge")
    if info < 0:
        raise ValueError(f"illegal value in {-info}th argument of internal gesdd")
    val = atol + np.max(s, initial=0.0) * (max(a.shape) * np.finfo(np.float64).eps)
    rank = np.sum(s > val)
    u = u[:, :rank]
    u /= s[:rank]
    return (u @ vh[:rank]).conj().T


def _gauss_newton_decrease(JtJ: np.ndarray, Jtr: np.ndarray) -> float:
    """Decrease of Σr² the undamped Gauss–Newton step promises: (Jᵀr)ᵀ (JᵀJ)⁺ (Jᵀr)."""
    sc = 1.0 / np.sqrt(np.maximum(JtJ.diagonal(), 1e-300))
    g = Jtr * sc
    A = JtJ * sc[:, None] * sc[None, :]
    c, x, info = lapack.dposv(A, g, lower=0)
    if info == 0 and np.min(np.abs(c.diagonal())) ** 2 > 1e-12:  # well conditioned: = pinv
        return float(g @ x)
    return float(g @ pinv_small(A, atol=1e-12) @ g)


def _free_descent(
    A: np.ndarray, g: np.ndarray, theta: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> float:
    """Gauss–Newton decrease left on the coordinates that no active bound blocks.

    A coordinate at a bound whose descent direction (−g) points out of the box is held; the
    decrease the (scaled) model promises on the others is gᵀ A⁺ g over them: zero at a
    Karush–Kuhn–Tucker point of the box-constrained problem.
    """
    blocked = ((theta <= lo) & (g > 0)) | ((theta >= hi) & (g < 0))
    free = ~blocked
    if not np.any(free):
        return 0.0
    gf = g[free]
    return float(gf @ pinv_small(A[np.ix_(free, free)], atol=1e-12) @ gf)


_EXTRAPOLATE_RATIO = 1.5  # actual / predicted decrease above which a step is doubled
_MAX_DOUBLINGS = 6


def _levenberg_marquardt(prob, theta, lo, hi, max_iter, chi2_tol=0.0, dof=1, first=None,  # noqa: PLR0913
                         se_tol=0.0):
    """Levenberg–Marquardt with step doubling where the Gauss–Newton model is too pessimistic.

    A fit whose residual is not small next to its signal (a weak mode at the noise level: the
    candidates the order search tries and rejects) sees curvature from the residual that JᵀJ
    does not: there the accepted steps gain about twice the decrease the model predicts, the
    damping falls to its floor and the iteration creeps along a nearly straight valley in
    ~50 equal steps. When an accepted step gains more than 1.5× its prediction the step is
    doubled while the cost keeps falling (one residual per try; every accepted point is still a
    descent step, so the iteration reaches the same kind of minimum). Fits of modes well above
    the noise gain what the model predicts and never double: their path is unchanged.

    Converged: a step changes θ by < 1e-10 relative, or Σr² by < 1e-11 relative, or (with
    ``chi2_tol`` > 0) an accepted step lowered Σr² by less than ``chi2_tol`` · Σr²/dof and the
    undamped Gauss–Newton model promises less than that from the new point as well; or (with
    ``se_tol`` > 0) the undamped Gauss–Newton step from the current point (the start, or an
    accepted one) promises less than ``se_tol`` · Σr²/dof: θ then lies within about √se_tol
    standard errors of the minimum (Δθᵀ Cov⁻¹ Δθ = ΔΣr² / s²).
    ``first``: ``prob.residual(theta)`` when the caller has it already.

    Gave up (not converged): the damping grew past 1e10 without a step that lowers Σr² (or,
    stuck on a bound away from a Karush–Kuhn–Tucker point, without one that leaves it).
    Returns (θ, residual, B, JᵀJ, evaluations, how it stopped: :class:`LMStop`).

    Box bounds: coordinates on a bound whose descent direction leaves the box are held and the
    step solved for the others; a step the bounds still cut to (almost) nothing is not
    convergence unless the point is a Karush–Kuhn–Tucker point (:func:`_free_descent`), it
    counts as a rejected step (the larger damping turns the next one towards the gradient).
    (A noise candidate that slides to f = f_min, δ = δ_max to take up a drift must come back
    down in δ along f = f_min; the plain clipped step kept pointing out of the corner.)
    """
    run = LMRun(prob, theta, lo, hi, chi2_tol, dof, first, se_tol)
    run.advance(max_iter)
    return run.result()


class LMRun:
    """One :func:`_levenberg_marquardt` fit that can be advanced a few iterations at a time:
    :meth:`advance` by a, then by b, takes the path of one call with ``max_iter`` = a + b, to
    the bit (the whole iteration state is kept between calls). For a look at a fit part-way (the
    order search's early look at a candidate) that continues where it looked instead of
    starting again. :meth:`result` ends it; nothing may be advanced after."""

    def __init__(self, prob, theta, lo, hi, chi2_tol=0.0, dof=1, first=None,  # noqa: PLR0913
                 se_tol=0.0) -> None:
        self.prob, self.lo, self.hi = prob, lo, hi
        self.chi2_tol, self.dof, self.se_tol = chi2_tol, dof, se_tol
        self.theta = theta
        self.resid, self.proj, self.B = prob.residual(theta) if first is None else first
        self.cost = prob.sumsq(self.resid)
        self.JtJ, self.Jtr = prob.normal_equations(theta, self.resid, self.proj, self.B)
        self.lam, self.n_eval, self.stop = 1e-4, 1, LMStop.ITERATION_LIMIT
        self.finished = bool(se_tol > 0 and _gauss_newton_decrease(self.JtJ, self.Jtr)
                             < se_tol * self.cost / max(dof, 1))
        if self.finished:  # the start is within √se_tol standard errors
            self.stop = LMStop.CONVERGED

    def advance(self, max_iter: int) -> None:
        """Up to ``max_iter`` more iterations (none once converged or given up)."""
        for _ in range(max_iter):
            if self.finished:
                return
            self._iterate()

    def result(self) -> tuple:
        """(θ, residual, B, JᵀJ, evaluations, how it stopped) at the point reached."""
        self.prob.release(self.proj, keep_residual=True)
        return self.theta, self.resid, self.B, self.JtJ, self.n_eval, self.stop

    def _iterate(self) -> None:
        """One iteration: a damped step tried, taken if it lowers Σr² (:func:`_levenberg_marquardt`)."""
        prob, lo, hi, theta, cost = self.prob, self.lo, self.hi, self.theta, self.cost
        sc = 1.0 / np.sqrt(np.maximum(self.JtJ.diagonal(), 1e-300))
        A = self.JtJ * sc[:, None] * sc[None, :]
        g = self.Jtr * sc
        u, info = _damped_step(A, g, self.lam, theta, lo, hi)
        if info != 0:  # not positive definite (scipy: LinAlgError)
            self.lam *= 10.0
            return
        new = np.clip(theta + u * sc, lo, hi)
        r_new, p_new, B_new = prob.residual(new)
        self.n_eval += 1
        cost_new = prob.sumsq(r_new)
        if cost_new > cost:
            prob.release(p_new)
            if cost_new - cost <= 1e-11 * cost:  # equal to rounding: at the minimum
                self._end(LMStop.CONVERGED)
                return
            self.lam *= 8.0
            if self.lam > 1e10:  # damped to nothing and still no descent
                self._end(LMStop.GAVE_UP)
            return
        small = bool((np.abs(new - theta) <= 1e-10 * (np.abs(theta) + sc)).all())
        rel = (cost - cost_new) / max(cost, 1e-300)
        if (small or rel < 1e-11) and ((new <= lo) | (new >= hi)).any():
            tol = max(1e-11 * cost, self.chi2_tol * cost / max(self.dof, 1))
            if _free_descent(A, g, theta, lo, hi) > tol:  # stuck on a bound, not at a minimum
                prob.release(p_new)
                self.lam *= 8.0
                if self.lam > 1e10:
                    self._end(LMStop.GAVE_UP)
                return
        predicted = -(2.0 * (g @ u) + u @ A @ u)  # Gauss–Newton decrease of Σr² (≥ 0)
        if not (small or rel < 1e-11) and cost - cost_new > _EXTRAPOLATE_RATIO * predicted:
            (new, cost_new, r_new, p_new, B_new), n = _extrapolate(
                prob, theta, (new, cost_new, r_new, p_new, B_new), lo, hi)
            self.n_eval += n
            rel = (cost - cost_new) / max(cost, 1e-300)
        drop = cost - cost_new
        prob.release(self.proj)
        self.theta, self.cost, self.resid, self.proj, self.B = new, cost_new, r_new, p_new, B_new
        self.JtJ, self.Jtr = prob.normal_equations(new, r_new, p_new, B_new)
        self.lam = max(self.lam / 5.0, 1e-12)
        if not (small or rel < 1e-11) and (self.chi2_tol > 0 or self.se_tol > 0):
            dof = max(self.dof, 1)
            ftol = self.chi2_tol * cost_new / dof
            gn = _gauss_newton_decrease(self.JtJ, self.Jtr)
            small = (drop < ftol and gn < ftol) or gn < self.se_tol * cost_new / dof
        if small or rel < 1e-11:
            self._end(LMStop.CONVERGED)

    def _end(self, stop: LMStop) -> None:
        self.stop, self.finished = stop, True


def _damped_step(A: np.ndarray, g: np.ndarray, lam: float, theta: np.ndarray, lo: np.ndarray,
                 hi: np.ndarray) -> tuple[np.ndarray, int]:
    """The scaled damped Gauss–Newton step u of (A + λI) u = −g, and LAPACK's ``info`` (non-zero:
    not positive definite). Coordinates on a bound whose descent direction (−g) leaves the box
    are held (u = 0 there) and the step is solved for the others (projected, active-set LM; all
    free inside the box); with every coordinate held the step is zero (no 0 x 0 system reaches
    LAPACK)."""
    # = linalg.solve(..., assume_a="pos") (same LAPACK call and triangle, less overhead)
    if not (np.isfinite(A).all() and np.isfinite(g).all()):
        raise ValueError("array must not contain infs or NaNs")
    held = ((theta <= lo) & (g > 0)) | ((theta >= hi) & (g < 0))
    if held.all():  # every coordinate pinned: no step (a KKT point, which the caller judges)
        return np.zeros_like(g), 0
    if held.any():
        u, free = np.zeros_like(g), ~held
        _, u_free, info = lapack.dposv(A[np.ix_(free, free)] + lam * np.eye(np.sum(free)),
                                       -g[free], lower=0)
        u[free] = u_free
    else:
        _, u, info = lapack.dposv(A + lam * np.eye(A.shape[0]), -g, lower=0)
    return u, info


def _extrapolate(prob, theta: np.ndarray, trial: tuple, lo: np.ndarray,
                 hi: np.ndarray) -> tuple[tuple, int]:
    """An accepted step from ``theta`` doubled (up to ``_MAX_DOUBLINGS`` times) while the cost
    keeps falling. ``trial`` and the result: (θ, Σr², residual, projector, B) of the point
    reached; and the residuals evaluated. A point given up is released."""
    new, cost_new, r_new, p_new, B_new = trial
    step = new - theta
    n = 0
    for _ in range(_MAX_DOUBLINGS):
        step = 2.0 * step
        far = np.clip(theta + step, lo, hi)
        r_far, p_far, B_far = prob.residual(far)
        n += 1
        cost_far = prob.sumsq(r_far)
        if not cost_far < cost_new:
            prob.release(p_far)
            break
        prob.release(p_new)
        new, cost_new, r_new, p_new, B_new = far, cost_far, r_far, p_far, B_far
    return (new, cost_new, r_new, p_new, B_new), n


def fit_modes_varpro(
    t_s: ArrayLike,
    y: ArrayLike,
    f0_hz: ArrayLike,
    delta0: ArrayLike,
    *,
    weights: ArrayLike | None = None,
    fit_offset: bool = True,
    f_bounds_hz: tuple[float, float] = (0.0, np.inf),
    delta_bounds: tuple[float, float] = (-2.0, 20.0),
    max_iter: int = 100,
    chi2_tol: float = 0.0,
    se_tol: float = 0.0,
    by_matmul: bool = False,
    keep: dict | None = None,
) -> VarProFit:
    """Fit damped modes with poles shared by all channels by variable projection.

    Parameters
    ----------
    t_s : array_like, shape (n_samples,)
        Sample times (s) from the start of the free decay (need not be uniform).
    y : array_like, shape (n_channels, n_samples)
        Data.
    f0_hz, delta0 : array_like, shape (n_modes,)
        Starting frequencies (Hz) and decrements.
    weights : array_like, shape (n_channels,), optional
        1/σ_c per channel (default 1): the fit is weighted least squares.
    fit_offset : bool or int
        Fit a constant offset per channel (True), or p trend columns (:func:`damped_basis`).
    f_bounds_hz, delta_bounds : tuple of float
        Box bounds on every f (Hz) and δ.
    max_iter : int
        Levenberg–Marquardt iteration limit.
    chi2_tol : float
        Also stop when an accepted step lowers the weighted residual sum of squares by less than
        ``chi2_tol`` times its variance per degree of freedom (0: to rounding). The order search
        uses 1e-3 for its trial fits, which only decide a likelihood-ratio test (Λ then within
        ~1e-3 of its converged value, against thresholds of tens); final fits use 0.
    se_tol : float
        Also stop at a point (the start or an accepted step) from which the undamped
        Gauss–Newton step promises to lower the weighted Σr² by less than ``se_tol`` times its
        variance per degree of freedom: f and δ are then within about √se_tol of their standard
        errors of the converged values (0: off). The per-channel fits of
        :func:`~ramdaq.analysis.modal.identify.identify_modes` use 3e-4.
    by_matmul : bool
        The basis by :func:`damped_basis`'s ``by_matmul`` (a hit's finals).
    keep : dict, optional
        Given, it receives the last evaluation's weighted residual (``"resid_w"``, (n_samples,
        n_channels), the data times ``weights`` minus the model) and its
        :class:`Projector` (``"proj"``, on the basis at the fit's poles): for a caller that
        needs them at the fit's poles (the order search's linear screen), not computed again.

    Returns
    -------
    VarProFit
    """
    t = np.asarray(t_s, dtype=float)
    Y = np.atleast_2d(np.asarray(y, dtype=float))
    f0 = np.atleast_1d(np.asarray(f0_hz, dtype=float))
    d0 = np.broadcast_to(np.asarray(delta0, dtype=float), f0.shape)
    w = np.ones(Y.shape[0]) if weights is None else np.asarray(weights, dtype=float)
    K, N = f0.size, Y.shape[1]
    P = 2 * K + int(fit_offset)
    if N <= P + 2 * K:
        raise ValueError(f"n_samples ({N}) too small for {K} modes")
    prob = _Problem(t, (Y * w[:, None]).T, fit_offset, by_matmul=by_matmul)
    lo, hi, theta0 = _box_start(f0, d0, f_bounds_hz, delta_bounds)
    return _fitted(prob, theta0, lo, hi, w, max_iter, chi2_tol, se_tol=se_tol, keep=keep)


def _box_start(f0: np.ndarray, d0: np.ndarray, f_bounds_hz: tuple[float, float],
               delta_bounds: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bounds (lo, hi) on θ = [f₁, δ₁, …] and the start θ₀ clipped into them."""
    K = f0.size
    lo = np.tile([f_bounds_hz[0], delta_bounds[0]], K)
    hi = np.tile([f_bounds_hz[1], delta_bounds[1]], K)
    theta0 = np.empty(2 * K)
    theta0[0::2], theta0[1::2] = f0, d0
    return lo, hi, np.clip(theta0, lo, hi)


def _fitted(prob: _Problem, theta0: np.ndarray, lo: np.ndarray, hi: np.ndarray, w: np.ndarray,
            max_iter: int, chi2_tol: float, first: tuple | None = None,
            se_tol: float = 0.0, keep: dict | None = None) -> VarProFit:
    """:func:`fit_modes_varpro`'s fit and result on ``prob`` (weights ``w``) from θ₀ (``first``:
    ``prob.residual(theta0)`` when known; ``se_tol``: :func:`_levenberg_marquardt`'s;
    ``keep``: :func:`fit_modes_varpro`'s)."""
    fit_offset = prob.offset
    K, C, N = theta0.size // 2, prob.Yc.shape[0], prob.Yc.shape[1]
    P = 2 * K + int(fit_offset)
    dof = C * N - C * P - 2 * K
    run = LMRun(prob, theta0, lo, hi, chi2_tol, dof, first, se_tol)  # (_levenberg_marquardt)
    run.advance(max_iter)
    theta, resid_w, B, JtJ, n_eval, stop = run.result()
    if keep is not None:
        keep["resid_w"], keep["proj"] = resid_w, run.proj
    B = B / w[None, :]
    rss = np.sum((resid_w / w[None, :]) ** 2, axis=0)
    s2 = float(np.sum(resid_w**2) / max(dof, 1))
    scale = 1.0 / np.sqrt(np.maximum(np.diag(JtJ), 1e-300))
    cov = s2 * scale[:, None] * pinv_small(scale[:, None] * JtJ * scale[None, :]) * scale[None, :]
    amp = (B[0 : 2 * K : 2] - 1j * B[1 : 2 * K : 2]).T
    return VarProFit(
        f_hz=theta[0::2].copy(),
        delta=theta[1::2].copy(),
        covariance=cov,
        amplitude=amp,
        offset=B[2 * K] if fit_offset else np.zeros(C),
        rss=rss,
        noise_std=np.sqrt(rss / max(N - P - 2 * K / C, 1)),
        n_eval=int(n_eval),
        success=stop is LMStop.CONVERGED,
        stop=stop,
    )


def fit_channels_varpro(
    t_s: np.ndarray, y: np.ndarray, f0_hz: np.ndarray, delta0: np.ndarray, *,
    fit_offset: bool | int, f_bounds_hz: tuple[float, float],
    delta_bounds: tuple[float, float], max_iter: int = 100, se_tol: float = 0.0,
    by_matmul: bool = False,
) -> list[VarProFit | None]:
    """Each channel (row of ``y``, (n_channels, n_samples)) fitted on its own from the same
    start: ``fit_modes_varpro(t_s, y[c:c+1], f0_hz, delta0, ..., se_tol=se_tol)`` for every c
    (None where that raises ValueError or LinAlgError), the first evaluation at the common
    start (basis, its factorisation and the Grams of the derivative columns: all but each
    channel's coefficients, residual and Tᵀr) computed once for all channels. ``by_matmul``:
    :func:`damped_basis`'s."""
    t = np.asarray(t_s, dtype=float)
    Y = np.atleast_2d(np.asarray(y, dtype=float))
    f0, d0 = np.asarray(f0_hz, dtype=float), np.asarray(delta0, dtype=float)
    K, (C, N) = f0.size, Y.shape
    if N <= 4 * K + int(fit_offset):
        return [None] * C
    lo, hi, theta0 = _box_start(f0, d0, f_bounds_hz, delta_bounds)
    grid = uniform_grid(t)  # the same grid for every channel's problem
    raw = damped_basis(t, theta0[0::2], theta0[1::2], fit_offset, grid, by_matmul=by_matmul).copy()
    proj = Projector(raw)
    shared = None
    if proj.cho is not None:  # else each channel's own first evaluation (QR path)
        PtY = raw.T @ Y.T
        B = proj.coef_from(PtY)
        R = Y.T - raw @ B  # (n_samples, n_channels)
        T = raw[:, : 2 * K] * t[:, None]
        shared = (raw.T @ T, T.T @ T, T.T @ R)  # ΦᵀT, TᵀT, Tᵀr
    out: list[VarProFit | None] = []
    for c in range(C):
        prob = _Problem(t, Y[c : c + 1].T, fit_offset, grid=grid, by_matmul=by_matmul)
        first = None
        if shared is not None:
            pc = copy.copy(proj)  # its Φ is not a pooled buffer: never handed to a channel's pool
            pc.grams = (shared[0], shared[1], None, shared[2][:, c : c + 1])
            first = (np.ascontiguousarray(R[:, c : c + 1]), pc, B[:, c : c + 1])
        try:
            out.append(_fitted(prob, theta0, lo, hi, np.ones(1), max_iter, 0.0, first, se_tol))
        except (ValueError, linalg.LinAlgError):
            out.append(None)
    return out


HELD_MAX_ITER = 100
"""Levenberg-Marquardt iterations of a :class:`HeldPoleFitter` fit, a look part-way included."""


class HeldPoleFitter:
    """Fits of further modes to weighted data with the poles (f_fixed, d_fixed) held.

    All amplitudes (and the offset) are fitted; the held modes' columns are projected out once
    here (:class:`_Problem` ``fixed``) and reused for every candidate tried against them.
    ``grams``: Σr² from Grams wherever they keep the digits a trial fit needs
    (:class:`_GramResidual`; for fits with ``chi2_tol`` > 0 and screens only). ``by_matmul``:
    :func:`damped_basis`'s.
    """

    def __init__(
        self, t: np.ndarray, y: np.ndarray, f_fixed: np.ndarray, d_fixed: np.ndarray, *,
        weights: np.ndarray, fit_offset: bool, grams: bool = False, by_matmul: bool = False,
    ) -> None:
        Y = np.atleast_2d(y)
        self.C, self.N = Y.shape
        self.K_fixed, self.fit_offset, self.weights = f_fixed.size, fit_offset, weights
        grid = uniform_grid(t)
        fixed = damped_basis(t, f_fixed, d_fixed, fit_offset, grid, by_matmul=by_matmul)
        self.prob = _Problem(t, (Y * weights[:, None]).T, fit_offset, fixed=fixed, grid=grid,
                             by_matmul=by_matmul)
        if grams:  # trial fits and screens only: Σr² from Grams (see _GramResidual)
            self.prob.use_grams()

    def weighted_rss(self, f: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Σ (w r)² per channel of the linear fit with the new poles (f, δ) fixed too."""
        theta = np.empty(2 * f.size)
        theta[0::2], theta[1::2] = f, d
        self._last = (theta, self.prob.residual(theta))  # the first step of a fit from there
        return self.prob.channel_ss(self._last[1][0])

    def fit(
        self, f0: np.ndarray, d0: np.ndarray, *, f_bounds_hz: tuple[float, float],
        delta_bounds: tuple[float, float], chi2_tol: float = 0.0, max_iter: int = HELD_MAX_ITER,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
        """(f, δ, rss, noise_std, n_eval): f and δ of the new modes; unweighted residual sum of
        squares and noise std per channel (degrees of freedom as :func:`fit_modes_varpro`)."""
        run = self.start(f0, d0, f_bounds_hz=f_bounds_hz, delta_bounds=delta_bounds,
                         chi2_tol=chi2_tol)
        got = run.advance(max_iter)
        run.close()
        return got

    def start(
        self, f0: np.ndarray, d0: np.ndarray, *, f_bounds_hz: tuple[float, float],
        delta_bounds: tuple[float, float], chi2_tol: float = 0.0, se_tol: float = 0.0,
    ) -> HeldFit:
        """A fit of the new modes from (f0, δ0), to be advanced a few iterations at a time
        (:class:`HeldFit`); its first evaluation done (:meth:`weighted_rss`'s if at that start).
        ``chi2_tol``, ``se_tol``: :func:`_levenberg_marquardt`'s."""
        C, N = self.C, self.N
        K = f0.size + self.K_fixed
        P = 2 * K + int(self.fit_offset)
        if N <= P + 2 * K:
            raise ValueError(f"n_samples ({N}) too small for {K} modes")
        lo = np.tile([f_bounds_hz[0], delta_bounds[0]], f0.size)
        hi = np.tile([f_bounds_hz[1], delta_bounds[1]], f0.size)
        theta0 = np.empty(2 * f0.size)
        theta0[0::2], theta0[1::2] = f0, d0
        dof = C * N - C * P - 2 * K
        theta0 = np.clip(theta0, lo, hi)
        last, self._last = getattr(self, "_last", None), None
        first = last[1] if last is not None and np.array_equal(last[0], theta0) else None
        run = LMRun(self.prob, theta0, lo, hi, chi2_tol, dof, first, se_tol)
        return HeldFit(run, self.weights, max(N - P - 2 * K / C, 1))


class HeldFit:
    """A :class:`HeldPoleFitter` fit under way: :meth:`advance` by a, then by b iterations
    reaches the point of one fit of ``max_iter`` = a + b, to the bit (:class:`LMRun`)."""

    def __init__(self, run: LMRun, weights: np.ndarray, dof: float) -> None:
        self.run, self.weights, self.dof = run, weights, dof

    def advance(self, max_iter: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
        """Up to ``max_iter`` more iterations; then :meth:`HeldPoleFitter.fit`'s tuple at the
        point reached."""
        run = self.run
        run.advance(max_iter)
        rss = run.prob.channel_ss(run.resid) / self.weights**2
        noise_std = np.sqrt(rss / self.dof)
        return run.theta[0::2].copy(), run.theta[1::2].copy(), rss, noise_std, int(run.n_eval)

    def close(self) -> None:
        """The fit ended: its buffers handed back for reuse."""
        self.run.result()


class GaussNewtonGain:
    """Decrease of the weighted Σr² that one undamped Gauss–Newton step on all poles promises,
    for weighted data (n_channels, n_samples) set up once and poles given per call.

    Only Jᵀr and JᵀJ are needed: from Grams (:meth:`_Problem._gram_point`, Tᵀr = TᵀY − (ΦᵀT)ᵀB),
    no residual as large as the data is formed. Their rounding is relative to ‖Y‖/‖r‖ (the
    square root of the ratio Σr² would lose), ≲ 10⁻¹¹ of the gain, which enters the order
    search's test multiplied by 4 plus 1. Where the Grams lose digits, the residual is formed.
    ``by_matmul``: :func:`damped_basis`'s.
    """

    def __init__(self, t: np.ndarray, y: np.ndarray, *, weights: np.ndarray,
                 fit_offset: bool, by_matmul: bool = False) -> None:
        self.prob = _Problem(t, (np.atleast_2d(y) * weights[:, None]).T, fit_offset,
                             by_matmul=by_matmul)

    def __call__(self, f: np.ndarray, d: np.ndarray) -> float:
        theta = np.empty(2 * f.size)
        theta[0::2], theta[1::2] = f, d
        got = self.prob._gram_point(theta, need_ss=False)
        resid, proj, B = self.prob.residual(theta) if got is None else got
        gain = _gauss_newton_decrease(*self.prob.normal_equations(theta, resid, proj, B))
        self.prob.release(proj)
        return gain


def gauss_newton_gain(
    t: np.ndarray, y: np.ndarray, f: np.ndarray, d: np.ndarray, *, weights: np.ndarray,
    fit_offset: bool,
) -> float:
    """Decrease of the weighted Σr² that one undamped Gauss–Newton step on all poles promises
    (:class:`GaussNewtonGain` for one set of poles)."""
    return GaussNewtonGain(t, y, weights=weights, fit_offset=fit_offset)(f, d)


def drop_one_rss_increase(
    t: np.ndarray, y: np.ndarray, f: np.ndarray, d: np.ndarray, *, fit_offset: bool
) -> np.ndarray | None:
    """Rise of each channel's least-squares RSS when one mode's two columns are dropped.

    Returns shape (n_modes, n_channels): for mode k, β_Sᵀ [(ΦᵀΦ)⁻¹_SS]⁻¹ β_S per channel (S its
    two columns, β the full fit's coefficients) — the drop-one refits of all modes from one
    factorisation. None when Φ needs the QR path (ill-conditioned): refit those directly.
    """
    Y = np.atleast_2d(y)
    proj = Projector(damped_basis(t, f, d, fit_offset, uniform_grid(t)))
    if proj.cho is None:
        return None
    B = proj.coef(Y.T)  # (P, C)
    P = B.shape[0]
    Ginv = proj.coef_from(np.eye(P))  # coef_from(X) = (ΦᵀΦ)⁻¹ X
    out = np.empty((f.size, Y.shape[0]))
    for k in range(f.size):
        S = slice(2 * k, 2 * k + 2)
        b = B[S]  # (2, C)
        out[k] = np.sum(b * np.linalg.solve(Ginv[S, S], b), axis=0)
    return out
