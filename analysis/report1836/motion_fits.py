"""Each motion signal's own modes, refined from the gages' joint poles (the motion fits).

The report's motions (Eq 1-3b), the motions relative to the hull (Eq 10-13) and the hull's own
(Eq 8) are linear combinations of gage signals, so they hold the gages' modes: the poles the
multi-channel fit found are where each motion's own least-squares fit starts, and where it ends
but for the noise. Each signal's own estimate -- the report compares the decrements of gamma,
alpha and v (Table 2b), so each needs its own -- is the variable-projection fit of the signal
alone (Kaufman's Jacobian, as :mod:`ramdaq.analysis.modal.varpro`), reached by Gauss-Newton
from the joint poles instead of a fresh search:

1. One step for all signals together: the basis Phi at the joint poles, its projector and the
   Schur complement ``T^T P_perp T`` (T = t Phi) are shared; each signal adds only its linear
   amplitudes B (its combination of the gages') and ``T^T r`` (all from the Grams of Phi, T and
   the signals where they keep the digits: :func:`_shared_terms`).
2. A second step for each signal from where its first landed: the step it asks for is its
   remaining distance to the optimum, so a first step that was already converged shows here.
3. Accepted when the second evaluation lowered the residual and its step is within one standard
   error (Gauss-Newton converges quadratically: what remains is a small fraction of that);
   otherwise, or outside the bounds, the signal is fitted by Levenberg-Marquardt
   (:func:`~ramdaq.analysis.modal.varpro.fit_modes_varpro`) from the joint poles, as the
   per-gage fits are.

Only the modes significant in a signal are freed (the per-gage fits' test: whitened energy
above the chi-squared(2) quantile at 1e-3); the others keep the joint poles, their amplitudes
still fitted. The complex amplitudes are the signal's linear fit at the joint poles -- the same
combination of the gages' amplitudes as the signal is of the gages' decays.

Times in s, frequencies in Hz, decrements per period; signals in any one unit (m/s^2 in ramdaq).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg
from scipy.linalg import LinAlgError, lapack
from scipy.special import chdtri

from ..modal.varpro import (
    Projector,
    damped_basis,
    fit_modes_varpro,
    kaufman_weights,
    projected_gram,
    uniform_grid,
)

__all__ = ["SignalModes", "fit_signals_at_poles"]

_SIGNIFICANT = float(chdtri(2, 1e-3))  # the per-gage fits' test of a mode in one channel
_DELTA_BOUNDS = (-3.0, 3.0)  # as the per-gage fits'


@dataclass(frozen=True)
class SignalModes:
    """One signal's own estimate of the joint modes: ``f_hz``, ``delta`` and their standard
    errors ``f_se_hz``, ``delta_se``, shape (n_modes,), NaN for a mode not significant in the
    signal; ``method``: ``"gauss-newton"`` (two steps from the joint poles),
    ``"levenberg-marquardt"`` (the fallback; ``"levenberg-marquardt failed"``: NaN), or
    ``"none"`` (no mode significant); ``amplitude`` (n_modes,) complex, the signal's amplitudes
    at the joint poles (its unit)."""

    f_hz: np.ndarray
    delta: np.ndarray
    f_se_hz: np.ndarray
    delta_se: np.ndarray
    method: str
    amplitude: np.ndarray


@dataclass(frozen=True)
class _Linear:
    """The linear half at poles (f, d): basis Phi (n, m), its projector, coefficients B (m, S),
    residuals R (n, S) and their sums of squares (S,)."""

    Phi: np.ndarray
    proj: Projector
    B: np.ndarray
    R: np.ndarray
    rss: np.ndarray


def _linear(t: np.ndarray, Y: np.ndarray, f: np.ndarray, d: np.ndarray, trend: int) -> _Linear:
    """Least squares of the signals ``Y`` (S, n) on the damped basis at poles (f, d)."""
    Phi = damped_basis(t, f, d, trend, uniform_grid(t), by_matmul=True)
    proj = Projector(Phi)
    B = proj.coef(Y.T)
    R = Y.T - Phi @ B
    return _Linear(Phi, proj, B, R, np.sum(R * R, axis=0))


def _gauss_newton_terms(t: np.ndarray, lin: _Linear, f: np.ndarray, d: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M, Tr, H): the Schur complement ``T^T P_perp T`` (2K, 2K), ``T^T r`` (2K, S) and the
    Jacobian weights (:func:`~ramdaq.analysis.modal.varpro.kaufman_weights`) at the poles of
    ``lin``, T = t Phi's mode columns."""
    K = f.size
    T = lin.Phi[:, : 2 * K] * t[:, None]
    Tp = T - lin.Phi @ lin.proj.coef(T)
    return Tp.T @ Tp, T.T @ lin.R, kaufman_weights(lin.B, f, d)


def _step(M: np.ndarray, Tr: np.ndarray, H: np.ndarray, free: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, float] | None:
    """One signal's Gauss-Newton step on the modes ``free`` (indices): (step [f, delta per free
    mode], (J^T J)^-1, the decrease of the residual sum of squares it promises); None when J^T J
    is singular. ``Tr`` (2K,), ``H`` (K, 2, 2) are that signal's."""
    K = H.shape[0]
    Hf = H[free]
    Mf = M.reshape(K, 2, K, 2)[free][:, :, free]
    JtJ = np.einsum("kpa,kalb,lqb->kplq", Hf, Mf, Hf).reshape(2 * free.size, 2 * free.size)
    Jtr = -np.einsum("kpa,ka->kp", Hf, Tr.reshape(K, 2)[free]).reshape(-1)
    sc = 1.0 / np.sqrt(np.maximum(JtJ.diagonal(), 1e-300))
    c, info = lapack.dpotrf(JtJ * sc[:, None] * sc[None, :], lower=1)
    if info != 0 or np.min(np.abs(c.diagonal())) ** 2 < 1e-12:
        return None
    inv, info = lapack.dpotri(c, lower=1)
    if info != 0:
        return None
    inv = np.tril(inv) + np.tril(inv, -1).T
    inv = inv * sc[:, None] * sc[None, :]
    step = -inv @ Jtr
    return step, inv, float(-Jtr @ step)


def _significant(t: np.ndarray, B: np.ndarray, rss: np.ndarray, f: np.ndarray,
                 d: np.ndarray) -> np.ndarray:
    """(S, K) bool: mode k stands out of signal s's noise (whitened energy of its fit at the
    joint poles, coefficients ``B`` (m, S) and residual sums of squares ``rss`` (S,), above the
    chi-squared(2) quantile at 1e-3, as the per-gage fits test)."""
    K = f.size
    n, m = t.size, B.shape[0]
    noise2 = np.maximum(rss / max(n - m, 1), 1e-300)
    env2 = np.sum(np.exp(-2.0 * (d * f)[:, None] * t[None, :]), axis=1) / 2.0
    amp2 = B[0 : 2 * K : 2] ** 2 + B[1 : 2 * K : 2] ** 2  # (K, S)
    return (amp2 * env2[:, None] / noise2[None, :]).T > _SIGNIFICANT


_GRAM_MIN_FRACTION = 1e-4  # Grams only while rss >= 1e-4 y^T y (<~ 4 of 16 digits lost), as varpro


def _shared_terms(t: np.ndarray, Y: np.ndarray, f: np.ndarray, d: np.ndarray, trend: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(B, rss, M, T^T r, H) of the signals ``Y`` (S, n) at the joint poles (f, d): the linear
    fit (:func:`_linear`) and its Gauss-Newton terms (:func:`_gauss_newton_terms`), from Grams
    where they keep the digits: W = [Phi^T; (t Phi_modes)^T] meets the samples in two products
    (W W^T, W Y^T), the residual and P_perp T are never formed (rss = y^T y - (Phi^T y)^T B,
    T^T r = T^T y - (Phi^T T)^T B, M = T^T T - (Phi^T T)^T (Phi^T Phi)^-1 Phi^T T). A signal
    whose rss is below 1e-4 of its y^T y (its digits lost to the subtraction) gets its rss and
    T^T r from its residual itself; all get the explicit path where the Gram needs the QR path
    or the Schur complement M lost over half its digits (as varpro's)."""
    K, n = f.size, t.size
    P = 2 * K + trend
    W = np.empty((P + 2 * K, n))
    damped_basis(t, f, d, trend, uniform_grid(t), out=W[:P], by_matmul=True)
    np.multiply(W[: 2 * K], t[None, :], out=W[P:])
    G = W @ W.T
    proj = Projector(None, gram=G[:P, :P])
    if proj.cho is not None:
        WY = W @ Y.T  # (P + 2K, S)
        B = proj.coef_from(WY[:P])
        yy = np.einsum("ij,ij->i", Y, Y)
        rss = yy - np.sum(WY[:P] * B, axis=0)
        PtT, TT = G[:P, P:], G[P:, P:]
        V = proj.whitened(PtT)
        M = TT - V.T @ V
        if (M.diagonal() > 1e-8 * TT.diagonal()).all():
            Tr = WY[P:] - PtT.T @ B
            for j in np.flatnonzero(~(rss >= _GRAM_MIN_FRACTION * yy)):  # explicit residual
                r = Y[j] - B[:, j] @ W[:P]
                rss[j], Tr[:, j] = r @ r, W[P:] @ r
            return B, rss, M, Tr, kaufman_weights(B, f, d)
    lin = _linear(t, Y, f, d, trend)
    return (lin.B, lin.rss, *_gauss_newton_terms(t, lin, f, d))


class _Held:
    """The signals' least squares with the modes ``free`` moving and the others (and the trend)
    held at their joint poles: the held columns are projected out of the signals once (one QR
    shared by every signal and step), so that a step touches only the free modes' columns.

    A step's terms come from Grams (:meth:`_gram_terms`): the free modes' columns and their time
    derivative columns W meet the samples in three products (W W^T, W Q, W y), the projected
    columns, residual and P_perp T are never formed; where the Grams would lose digits (a
    residual below 1e-4 of the signal's sum of squares, a projected column or Schur complement
    nearly cancelled), the explicit path (:meth:`_explicit_terms`) as before."""

    def __init__(self, t: np.ndarray, Y: np.ndarray, f: np.ndarray, d: np.ndarray,
                 free: np.ndarray, trend: int) -> None:
        held = np.setdiff1d(np.arange(f.size), free)
        self.t, self.grid = t, uniform_grid(t)
        F = damped_basis(t, f[held], d[held], trend, self.grid, by_matmul=True)
        Q, R = linalg.qr(F, mode="economic", check_finite=False)
        rd = np.abs(np.diag(R))
        self.QT = np.ascontiguousarray(Q[:, rd > 1e-10 * rd.max()].T) if rd.size else None
        self.Yp = Y if self.QT is None else Y - (Y @ self.QT.T) @ self.QT
        self.yy = np.einsum("ij,ij->i", self.Yp, self.Yp)

    def _perp(self, A: np.ndarray) -> np.ndarray:
        """A (n, c) with the held columns projected out."""
        return A if self.QT is None else A - self.QT.T @ (self.QT @ A)

    def terms(self, s: int, f: np.ndarray, d: np.ndarray
              ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """Signal ``s``'s (rss, M, T^T r, H) with the free modes at poles (f, d) (as
        :func:`_gauss_newton_terms` on all columns: the held ones profiled out)."""
        got = self._gram_terms(s, f, d)
        return got if got is not None else self._explicit_terms(s, f, d)

    def _gram_terms(self, s: int, f: np.ndarray, d: np.ndarray
                    ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray] | None:
        """:meth:`terms` from Grams, or None where they would lose digits. With W = [Phi^T;
        (t Phi)^T] (2c, n), Yp and the projected columns orthogonal to the held ones Q: the
        projected Gram is G = W W^T - (W Q)(W Q)^T; b = G_pp^-1 (W y)_p, rss = y^T y - (W y)_p^T b,
        T^T r = (W y)_T - G_Tp b and M = G_TT - G_Tp G_pp^-1 G_pT."""
        c = 2 * f.size
        W = np.empty((2 * c, self.t.size))
        damped_basis(self.t, f, d, 0, self.grid, out=W[:c], by_matmul=True)
        np.multiply(W[:c], self.t[None, :], out=W[c:])
        G = projected_gram(W, self.QT)
        if G is None:
            return None
        proj = Projector(None, gram=G[:c, :c])
        if proj.cho is None:
            return None
        wy = W @ self.Yp[s]
        b = proj.coef_from(wy[:c, None])
        rss = float(self.yy[s] - wy[:c] @ b[:, 0])
        if not rss >= _GRAM_MIN_FRACTION * self.yy[s]:
            return None
        PtT, TT = G[:c, c:], G[c:, c:]
        V = proj.whitened(PtT)
        M = TT - V.T @ V
        if not (M.diagonal() > 1e-8 * TT.diagonal()).all():
            return None
        return rss, M, wy[c:] - PtT.T @ b[:, 0], kaufman_weights(b, f, d)[..., 0]

    def _explicit_terms(self, s: int, f: np.ndarray, d: np.ndarray
                        ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`terms` on the projected columns and residual themselves."""
        phi = damped_basis(self.t, f, d, 0, self.grid, by_matmul=True)
        c = phi.shape[1]
        T = phi * self.t[:, None]
        both = self._perp(np.hstack([phi, T]))  # one pass over the held columns for both
        phi_p, T1 = both[:, :c], both[:, c:]
        proj = Projector(phi_p)
        b = proj.coef(self.Yp[s][:, None])
        r = self.Yp[s] - phi_p @ b[:, 0]
        Tp = T1 - phi_p @ proj.coef(T1)
        return float(r @ r), Tp.T @ Tp, T.T @ r, kaufman_weights(b, f, d)[..., 0]


def fit_signals_at_poles(signals: np.ndarray, fs_hz: float, f_hz: np.ndarray,
                         delta: np.ndarray, *, modes: tuple[int, ...] | None = None,
                         trend_terms: int = 1) -> list[SignalModes]:
    """Each signal's own estimate of the modes ``modes`` (indices; None: all) among the joint
    modes (``f_hz``, ``delta``), where significant in it; the other modes held at their joint
    poles, their amplitudes fitted.

    Parameters
    ----------
    signals : numpy.ndarray, shape (n_signals, n_samples)
        Free decays combined from the gages that gave the poles, t = 0 at the first sample.
    fs_hz : float
        Sample rate, Hz.
    f_hz, delta : numpy.ndarray, shape (n_modes,)
        The joint fit's poles (frequency Hz, logarithmic decrement), where each fit starts.
    modes : tuple of int, optional
        The modes each signal estimates on its own (e.g. the predominant one); None: all.
    trend_terms : int
        Trend columns (Legendre P0 ...) of the joint fit, fitted with each signal's modes.

    Returns
    -------
    list of SignalModes
        One per signal, in order (see the module docstring for how each was reached); NaN for
        the modes not estimated.
    """
    Y = np.atleast_2d(np.asarray(signals, dtype=float))
    f, d = np.asarray(f_hz, dtype=float), np.asarray(delta, dtype=float)
    if Y.ndim != 2 or not np.all(np.isfinite(Y)):
        raise ValueError(f"signals (shape {Y.shape}) must be finite, (n_signals, n_samples)")
    if f.size == 0 or f.shape != d.shape:
        raise ValueError(f"f_hz ({f.size}) and delta ({d.size}) must hold the same modes, >= 1")
    n = Y.shape[1]
    if n <= 4 * f.size + trend_terms + 2:
        raise ValueError(f"n_samples ({n}) too small for {f.size} modes")
    wanted = np.zeros(f.size, dtype=bool)
    wanted[list(range(f.size)) if modes is None else list(modes)] = True
    t = np.arange(n) / fs_hz
    B, rss, M, Tr, H = _shared_terms(t, Y, f, d, trend_terms)
    sig = _significant(t, B, rss, f, d) & wanted[None, :]
    helds: dict[tuple[int, ...], _Held] = {}
    out = []
    for s in range(Y.shape[0]):
        amp = B[0 : 2 * f.size : 2, s] - 1j * B[1 : 2 * f.size : 2, s]
        free = np.flatnonzero(sig[s])
        if free.size == 0:
            nan = np.full(f.size, np.nan)
            out.append(SignalModes(nan, nan, nan, nan, "none", amp))
            continue
        key = tuple(free)
        if key not in helds:
            helds[key] = _Held(t, Y, f, d, free, trend_terms)
        est = _gauss_newton(helds[key], s, f, d, free, trend_terms,
                            (M, Tr[:, s], H[..., s], float(rss[s])))
        if est is None:
            est = _levenberg_marquardt(t, Y[s], f, d, free, trend_terms)
        out.append(SignalModes(*est, amplitude=amp))
    return out


def _placed(K: int, free: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(f, delta) of all K modes from ``values`` [f, delta per free mode]; NaN elsewhere."""
    f, d = np.full(K, np.nan), np.full(K, np.nan)
    f[free], d[free] = values[0::2], values[1::2]
    return f, d


_MAX_STEPS = 8
_CONVERGED = 1e-2  # a step below this many standard errors is the last (what remains is ~its square)


def _gauss_newton(held: _Held, s: int, f: np.ndarray, d: np.ndarray, free: np.ndarray,
                  trend: int, first: tuple[np.ndarray, np.ndarray, np.ndarray, float]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, str] | None:
    """Signal ``s``'s Gauss-Newton iteration on the modes ``free`` from the joint poles, the
    others held (``held``); ``first``: its terms there (M, T^T r, H, rss) from the shared
    evaluation of all modes. A step that raises the residual is halved (up to 4 times).
    (f, delta, f_se, delta_se, method) once a step is below 1e-2 standard errors; None when it
    is not within 8 steps, J^T J is singular or a pole leaves the bounds."""
    K, n = f.size, held.t.size
    fk, dk = f[free], d[free]
    M, Tr, H, rss = first
    H, Mf, Tf = H[free], M.reshape(K, 2, K, 2)[free][:, :, free], Tr.reshape(K, 2)[free]
    M, Tr, H = Mf.reshape(2 * free.size, 2 * free.size), Tf.reshape(-1), H
    every = np.arange(free.size)
    dof = max(n - 2 * K - trend - 2 * free.size, 1)
    for _ in range(_MAX_STEPS):
        st = _step(M, Tr, H, every)
        if st is None:
            return None
        step, inv, gain = st
        se = np.sqrt(np.abs(np.diag(inv)) * max(rss - gain, 0.0) / dof)
        if np.all(np.abs(step) <= _CONVERGED * se):
            theta = np.column_stack([fk, dk]).ravel() + step
            return (*_placed(K, free, theta), *_placed(K, free, se), "gauss-newton")
        for _ in range(5):
            fn, dn = fk + step[0::2], dk + step[1::2]
            if np.any(fn <= 0) or np.any(np.abs(dn) >= _DELTA_BOUNDS[1]):
                return None
            terms = held.terms(s, fn, dn)
            if terms[0] <= rss:
                break
            step = step / 2
        else:
            return None
        fk, dk = fn, dn
        rss, M, Tr, H = terms
    return None


def _levenberg_marquardt(t: np.ndarray, y: np.ndarray, f: np.ndarray, d: np.ndarray,
                         free: np.ndarray, trend: int
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]:
    """Signal ``y``'s fit of the modes ``free`` by Levenberg-Marquardt from the joint poles
    (the per-gage fits' bounds: f within (0.5, 0.49 fs) of 1/record, |delta| < 3); NaN where it
    fails."""
    K = f.size
    duration = t[-1] + t[1]
    nan = np.full(K, np.nan)
    try:
        fit = fit_modes_varpro(t, y[None, :], f[free], d[free], fit_offset=trend,
                               f_bounds_hz=(0.5 / duration, 0.49 / t[1]), delta_bounds=_DELTA_BOUNDS)
    except (ValueError, LinAlgError):
        return nan, nan, nan, nan.copy(), "levenberg-marquardt failed"
    se = np.sqrt(np.abs(np.diag(fit.covariance)))
    values = np.column_stack([fit.f_hz, fit.delta]).ravel()
    return (*_placed(K, free, values), *_placed(K, free, se), "levenberg-marquardt")
