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
with t measured from the first sample of the free decay.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg

__all__ = ["VarProFit", "fit_modes_varpro", "linear_amplitudes"]

_TWO_PI = 2.0 * np.pi


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
        Constant offsets (0 when not fitted).
    rss : numpy.ndarray, shape (n_channels,)
        Unweighted residual sum of squares per channel.
    noise_std : numpy.ndarray, shape (n_channels,)
        Residual std per channel, corrected for the parameters used.
    n_eval : int
        Function evaluations.
    success : bool
        Optimiser's convergence flag.
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


def _basis(t: np.ndarray, f: np.ndarray, d: np.ndarray, offset: bool) -> np.ndarray:
    env = np.exp(np.minimum(-(d * f)[None, :] * t[:, None], 300.0))
    arg = _TWO_PI * f[None, :] * t[:, None]
    cols = np.empty((t.size, 2 * f.size + int(offset)))
    cols[:, 0 : 2 * f.size : 2] = env * np.cos(arg)
    cols[:, 1 : 2 * f.size : 2] = env * np.sin(arg)
    if offset:
        cols[:, -1] = 1.0
    return cols


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
    fit_offset : bool
        Include a constant per channel.

    Returns
    -------
    amplitude : numpy.ndarray, shape (n_channels, n_modes), complex
    offset : numpy.ndarray, shape (n_channels,)
    rss : numpy.ndarray, shape (n_channels,)
    """
    f = np.atleast_1d(np.asarray(f_hz, dtype=float))
    d = np.atleast_1d(np.asarray(delta, dtype=float))
    proj = _Projector(_basis(t_s, f, d, fit_offset))
    B = proj.coef(y.T)
    rss = np.sum((y.T - proj.Phi @ B) ** 2, axis=0)
    K = f.size
    amp = (B[0 : 2 * K : 2] - 1j * B[1 : 2 * K : 2]).T
    off = B[-1] if fit_offset else np.zeros(y.shape[0])
    return amp, off, rss


class _Projector:
    """Least squares on the basis Φ: Cholesky of the column-scaled Gram, QR if ill-conditioned."""

    def __init__(self, Phi: np.ndarray) -> None:
        self.Phi = Phi
        norm = np.sqrt(np.sum(Phi * Phi, axis=0))
        self.inv_norm = 1.0 / np.where(norm > 0, norm, 1.0)
        G = (Phi.T @ Phi) * self.inv_norm[:, None] * self.inv_norm[None, :]
        self.cho = None
        try:
            cho = linalg.cho_factor(G, check_finite=False)
            if np.min(np.abs(np.diag(cho[0]))) ** 2 > 1e-10:  # cond(Φ) below ~1e5
                self.cho = cho
        except linalg.LinAlgError:
            pass
        if self.cho is None:
            self.Q, self.R = linalg.qr(Phi, mode="economic", check_finite=False)

    def coef(self, M: np.ndarray) -> np.ndarray:
        """Coefficients C minimising ‖M − Φ C‖ (columns of M independently)."""
        if self.cho is not None:
            rhs = (self.Phi.T @ M) * self.inv_norm[:, None]
            return linalg.cho_solve(self.cho, rhs, check_finite=False) * self.inv_norm[:, None]
        return linalg.lstsq(self.R, self.Q.T @ M, check_finite=False)[0]


class _Problem:
    """Residual, gradient and Gauss–Newton matrix of the weighted variable-projection functional.

    Kaufman's Jacobian column for θᵢ is −P⊥ (∂Φ/∂θᵢ) B = −P⊥ D Sᵢ, with D the (n_samples, 4K)
    derivative columns and Sᵢ a selector carrying two rows of B. So JᵀJ and Jᵀr need only
    D⊥ᵀD⊥ (4K × 4K) and Dᵀr (4K × n_channels): no (n_samples·n_channels, 2K) Jacobian is formed.
    """

    def __init__(self, t: np.ndarray, Yw: np.ndarray, offset: bool) -> None:
        self.t, self.Yw, self.offset = t, Yw, offset  # Yw: (n_samples, n_channels)

    def residual(self, theta: np.ndarray) -> tuple[np.ndarray, _Projector, np.ndarray]:
        proj = _Projector(_basis(self.t, theta[0::2], theta[1::2], self.offset))
        B = proj.coef(self.Yw)
        return self.Yw - proj.Phi @ B, proj, B

    def normal_equations(
        self, theta: np.ndarray, resid: np.ndarray, proj: _Projector, B: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(JᵀJ, Jᵀr) at θ for the residual computed there."""
        t = self.t
        f, d = theta[0::2], theta[1::2]
        K = f.size
        n_osc = 2 * K
        c, s = proj.Phi[:, 0:n_osc:2], proj.Phi[:, 1:n_osc:2]  # e·cos, e·sin at θ
        tc, ts = t[:, None] * c, t[:, None] * s
        D = np.empty((t.size, 4 * K))  # per mode: dc/df, ds/df, dc/dδ, ds/dδ
        D[:, 0::4] = -d * tc - _TWO_PI * ts
        D[:, 1::4] = -d * ts + _TWO_PI * tc
        D[:, 2::4] = -f * tc
        D[:, 3::4] = -f * ts
        Dp = D - proj.Phi @ proj.coef(D)
        M = Dp.T @ Dp
        Dr = D.T @ resid  # (4K, n_channels); P⊥ r = r
        S = np.zeros((2 * K, 4 * K, B.shape[1]))  # selectors Sᵢ
        for k in range(K):
            S[2 * k, 4 * k], S[2 * k, 4 * k + 1] = B[2 * k], B[2 * k + 1]
            S[2 * k + 1, 4 * k + 2], S[2 * k + 1, 4 * k + 3] = B[2 * k], B[2 * k + 1]
        JtJ = np.einsum("iac,ab,jbc->ij", S, M, S)
        Jtr = -np.einsum("iac,ac->i", S, Dr)
        return JtJ, Jtr


def _levenberg_marquardt(prob, theta, lo, hi, max_iter):
    resid, proj, B = prob.residual(theta)
    cost = float(np.sum(resid**2))
    JtJ, Jtr = prob.normal_equations(theta, resid, proj, B)
    lam, n_eval, converged = 1e-4, 1, False
    for _ in range(max_iter):
        sc = 1.0 / np.sqrt(np.maximum(np.diag(JtJ), 1e-300))
        A = JtJ * sc[:, None] * sc[None, :]
        g = Jtr * sc
        try:
            u = linalg.solve(A + lam * np.eye(A.shape[0]), -g, assume_a="pos")
        except linalg.LinAlgError:
            lam *= 10.0
            continue
        new = np.clip(theta + u * sc, lo, hi)
        r_new, p_new, B_new = prob.residual(new)
        n_eval += 1
        cost_new = float(np.sum(r_new**2))
        if cost_new <= cost:
            small = np.all(np.abs(new - theta) <= 1e-10 * (np.abs(theta) + sc))
            rel = (cost - cost_new) / max(cost, 1e-300)
            theta, cost, resid, proj, B = new, cost_new, r_new, p_new, B_new
            JtJ, Jtr = prob.normal_equations(theta, resid, proj, B)
            lam = max(lam / 5.0, 1e-12)
            if small or rel < 1e-11:
                converged = True
                break
        else:
            if cost_new - cost <= 1e-11 * cost:  # equal to rounding: at the minimum
                converged = True
                break
            lam *= 8.0
            if lam > 1e10:
                converged = True  # no descent direction left: at a minimum to precision
                break
    return theta, resid, B, JtJ, n_eval, converged


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
    fit_offset : bool
        Fit a constant offset per channel.
    f_bounds_hz, delta_bounds : tuple of float
        Box bounds on every f (Hz) and δ.
    max_iter : int
        Levenberg–Marquardt iteration limit.

    Returns
    -------
    VarProFit
    """
    t = np.asarray(t_s, dtype=float)
    Y = np.atleast_2d(np.asarray(y, dtype=float))
    f0 = np.atleast_1d(np.asarray(f0_hz, dtype=float))
    d0 = np.broadcast_to(np.asarray(delta0, dtype=float), f0.shape)
    w = np.ones(Y.shape[0]) if weights is None else np.asarray(weights, dtype=float)
    K, (C, N) = f0.size, Y.shape
    P = 2 * K + int(fit_offset)
    if N <= P + 2 * K:
        raise ValueError(f"n_samples ({N}) too small for {K} modes")
    prob = _Problem(t, (Y * w[:, None]).T, fit_offset)
    lo = np.tile([f_bounds_hz[0], delta_bounds[0]], K)
    hi = np.tile([f_bounds_hz[1], delta_bounds[1]], K)
    theta0 = np.empty(2 * K)
    theta0[0::2], theta0[1::2] = f0, d0
    theta0 = np.clip(theta0, lo, hi)
    theta, resid_w, B, JtJ, n_eval, ok = _levenberg_marquardt(prob, theta0, lo, hi, max_iter)
    B = B / w[None, :]
    rss = np.sum((resid_w / w[None, :]) ** 2, axis=0)
    dof = C * N - C * P - 2 * K
    s2 = float(np.sum(resid_w**2) / max(dof, 1))
    scale = 1.0 / np.sqrt(np.maximum(np.diag(JtJ), 1e-300))
    cov = s2 * scale[:, None] * linalg.pinv(scale[:, None] * JtJ * scale[None, :]) * scale[None, :]
    amp = (B[0 : 2 * K : 2] - 1j * B[1 : 2 * K : 2]).T
    return VarProFit(
        f_hz=theta[0::2].copy(),
        delta=theta[1::2].copy(),
        covariance=cov,
        amplitude=amp,
        offset=B[-1] if fit_offset else np.zeros(C),
        rss=rss,
        noise_std=np.sqrt(rss / max(N - P - 2 * K / C, 1)),
        n_eval=int(n_eval),
        success=bool(ok),
    )
