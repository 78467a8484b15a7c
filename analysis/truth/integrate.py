"""Time integration of the truth structure: an exactly discretised state-space recursion with a
piecewise-linear (Legendre-projected) input hold, run at an oversampled rate.

This is deliberately *not* the diagnosis' closed-form modal superposition
(:mod:`ramdaq.analysis.model.response`): forces are never integrated analytically against the modes. Over each
step ``[t_k, t_k + dt]`` a force ``u(t)`` is replaced by its L2 projection on ``{1, 2 tau/dt - 1}``
(moments ``m0_k``, ``m1_k``, taken by Gauss-Legendre quadrature over the part of the step where
``u`` is smooth), and the state ``x = [q, q']`` advances exactly for that input::

    x_{k+1} = Phi x_k + G0 (m0_k - m1_k) + G1 2 m1_k,
    Phi = e^{A dt},  G0 = int_0^dt e^{A s} ds B,  G1 = int_0^dt e^{A (dt - s)} (s/dt) ds B

(the first-order-hold discretisation; ``Phi, G0, G1`` from one matrix exponential of the augmented
system, :func:`discretise`). Its error is the part of ``u`` that is neither constant nor linear
within a step: for a 5 ms half-sine at dt = 1/8192 s, ~1e-5 of the response. The recursion is
linear, so it is evaluated in the eigenbasis of ``Phi`` (``Phi = V diag(e^{lambda dt}) V^-1``)
with one first-order IIR filter per mode (``scipy.signal.lfilter``); :func:`run_physical` is the
same recursion as a plain loop over physical coordinates, kept as the reference it is tested
against. Nonlinear terms (Coulomb friction) go through :func:`friction_input`: an explicit
recursion at a coarser step that returns the friction force as one more input series.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.signal

from ..model.response import half_sine_response
from .structure import TruthModel

_GL_X, _GL_W = np.polynomial.legendre.leggauss(6)
FAST_DECAY = 40.0
"""A fast mode's state is computed until it has decayed by e^-40 after its drive stops."""


@dataclass(frozen=True)
class ModalRecursion:
    """The truth model's discrete recursion in the eigenbasis of ``Phi``.

    ``lam`` (m,) continuous eigenvalues kept once per conjugate pair, ``weights`` 2 for a pair and
    1 for a real one; ``V`` (2n, m) right and ``W`` (m, 2n) left eigenvectors; ``mu = e^{lam dt}``;
    ``g0``, ``g1`` (m,) the scalar hold integrals of each mode; ``dt`` s.
    """

    model: TruthModel
    dt: float
    lam: np.ndarray
    weights: np.ndarray
    V: np.ndarray
    W: np.ndarray
    mu: np.ndarray
    g0: np.ndarray
    g1: np.ndarray
    Minv: np.ndarray

    def beta(self, force: np.ndarray) -> np.ndarray:
        """Modal input (m,) of a generalised force vector (n,)."""
        n = self.model.n_dof
        return self.W[:, n:] @ (self.Minv @ force)

    def run(self, force: np.ndarray, m0: np.ndarray, m1: np.ndarray,
            z0: np.ndarray | None = None) -> np.ndarray:
        """Modal states (m, N) at steps ``0..N-1`` driven by ``force * u(t)`` with step moments
        ``m0, m1`` (N,) of ``u``, starting from modal state ``z0`` (m,) (default rest).

        A mode that decays by ``e^-FAST_DECAY`` within a fraction of the record (the stock's own
        modes) is run only over windows that start where the drive does and end that long after
        it stops; elsewhere its state is below ``e^-FAST_DECAY`` of its peak and is kept as 0.
        """
        N = len(m0)
        b = self.beta(force)
        Z = np.zeros((len(self.lam), N), dtype=complex)
        active = np.flatnonzero((m0 != 0) | (m1 != 0))
        if z0 is not None:
            active = np.union1d(active, [0])
        for i in range(len(self.lam)):
            L = math.ceil(FAST_DECAY / (abs(self.lam[i].real) * self.dt))
            if 4 * L >= N or 4 * len(active) >= N:
                windows = [(0, N)]
            else:
                cut = np.flatnonzero(np.diff(active) > L)
                starts = np.concatenate([active[:1], active[cut + 1]])
                ends = np.minimum(np.concatenate([active[cut], active[-1:]]) + L, N)
                windows = list(zip(starts, ends, strict=True))
            c0, c1 = b[i] * self.g0[i], b[i] * (2 * self.g1[i] - self.g0[i])
            for a, e in windows:
                zi = np.array([z0[i] if (z0 is not None and a == 0) else 0.0], dtype=complex)
                Z[i, a:e], _ = scipy.signal.lfilter([0.0, 1.0], [1.0, -self.mu[i]],
                                                    c0 * m0[a:e] + c1 * m1[a:e], zi=zi)
        return Z

    def output_matrix(self, rows: np.ndarray, kind: str = "acc") -> np.ndarray:
        """Real matrix (k, 2m) mapping ``[Re Z; Im Z]`` to ``rows @ q`` (disp), ``q'`` (vel) or
        ``q''`` (acc, without the direct force term), for ``rows`` (k, n)."""
        n = self.model.n_dof
        part = {"disp": self.V[:n], "vel": self.V[n:], "acc": self.V[n:] * self.lam}[kind]
        c = self.weights * (np.atleast_2d(rows) @ part)
        return np.hstack([c.real, -c.imag])

    def feedthrough(self, rows: np.ndarray, force: np.ndarray) -> np.ndarray:
        """Acceleration of ``rows`` (k, n) per unit of the force's amplitude ``u(t)``, (k,)."""
        return np.atleast_2d(rows) @ (self.Minv @ force)


def state_matrix(model: TruthModel) -> tuple[np.ndarray, np.ndarray]:
    """``A`` (2n, 2n) and ``M^-1`` (n, n)."""
    n = model.n_dof
    Minv = np.linalg.inv(model.M)
    return np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ model.K, -Minv @ model.C]]), Minv


def discretise(model: TruthModel, dt: float, force: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``Phi`` (2n, 2n), ``G0``, ``G1`` (2n,) of the hold recursion for one force vector, from one
    matrix exponential of ``[[A dt, B dt, 0], [0, 0, 1], [0, 0, 0]]``."""
    A, Minv = state_matrix(model)
    n2 = A.shape[0]
    aug = np.zeros((n2 + 2, n2 + 2))
    aug[:n2, :n2] = A * dt
    aug[n2 // 2:n2, n2] = Minv @ force * dt
    aug[n2, n2 + 1] = 1.0
    E = scipy.linalg.expm(aug)
    return E[:n2, :n2], E[:n2, n2], E[:n2, n2 + 1]


def modal_recursion(model: TruthModel, dt: float) -> ModalRecursion:
    """Eigen-decomposition of the recursion of ``model`` at step ``dt`` (s)."""
    A, Minv = state_matrix(model)
    lam, V = scipy.linalg.eig(A)
    W = np.linalg.inv(V)
    tol = 1e-9 * np.abs(lam)
    keep = np.flatnonzero((lam.imag > tol) | (np.abs(lam.imag) <= tol))
    keep = keep[np.argsort(np.abs(lam[keep]))]
    lam, V, W = lam[keep], V[:, keep], W[keep]
    real = np.abs(lam.imag) <= tol[keep]
    lam = np.where(real, lam.real, lam)
    weights = np.where(real, 1.0, 2.0)
    x = lam * dt
    mu = np.exp(x)
    g0 = np.expm1(x) / lam
    g1 = (np.expm1(x) - x) / (lam * x)
    return ModalRecursion(model, dt, lam, weights, V, W, mu, g0, g1, Minv)


def blow_amplitudes(rec: ModalRecursion, F0: float, duration_s: float,
                    location_m: tuple[float, float, float], direction: str) -> np.ndarray:
    """Complex modal states (m,) just after one half-sine blow (for sizing, not for the trial)."""
    b = rec.beta(rec.model.force_vector(location_m, direction))
    return b * F0 * half_sine_response(rec.lam, duration_s, np.array([duration_s]))[:, 0]


def gage_mode_amplitudes(rec: ModalRecursion, z: np.ndarray) -> np.ndarray:
    """Displacement amplitude (m) of each mode at each gage, (n_gages, m), for modal states z."""
    n = rec.model.n_dof
    return np.abs(rec.weights * (rec.model.gage_dofs @ rec.V[:n]) * z)


def decay_weighted(rec: ModalRecursion, amp: np.ndarray) -> np.ndarray:
    """Each mode's visible share: amplitude^2 times the time it lasts, per gage, (n_gages, m)."""
    return amp**2 / (2 * np.abs(rec.lam.real))


def run_physical(model: TruthModel, dt: float, force: np.ndarray, m0: np.ndarray,
                 m1: np.ndarray) -> np.ndarray:
    """Reference: the same recursion as a plain loop over ``x = [q, q']``, states (2n, N)."""
    Phi, G0, G1 = discretise(model, dt, force)
    X = np.zeros((Phi.shape[0], len(m0)))
    for k in range(len(m0) - 1):
        X[:, k + 1] = Phi @ X[:, k] + G0 * (m0[k] - m1[k]) + G1 * 2 * m1[k]
    return X


def half_sine_moments(onsets_s: np.ndarray, peaks_N: np.ndarray, duration_s: float, dt: float,
                      n: int) -> tuple[np.ndarray, np.ndarray]:
    """Step moments ``m0``, ``m1`` (n,) of a train of half-sine blows (N): the force's mean over
    each step and its coefficient on ``2 tau/dt - 1``, by 6-point Gauss-Legendre over the part of
    the step inside each blow (the half-sine is smooth there, so this is exact to ~1e-12)."""
    m0, m1 = np.zeros(n), np.zeros(n)
    w = math.pi / duration_s
    for t0, F in zip(np.atleast_1d(onsets_s), np.atleast_1d(peaks_N), strict=True):
        k = np.arange(int(t0 // dt), min(n, int((t0 + duration_s) // dt) + 1))
        a = np.maximum(k * dt, t0)
        b = np.minimum((k + 1) * dt, t0 + duration_s)
        ok = b > a
        k, a, b = k[ok], a[ok], b[ok]
        tt = 0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * _GL_X[None, :]
        f = F * np.sin(w * (tt - t0))
        wq = 0.5 * (b - a)[:, None] * _GL_W[None, :] / dt
        p1 = 2 * (tt - k[:, None] * dt) / dt - 1
        m0[k] += (wq * f).sum(axis=1)
        m1[k] += 3 * (wq * f * p1).sum(axis=1)
    return m0, m1


def smooth_moments(fun: Callable[[np.ndarray], np.ndarray], dt: float,
                   n: int) -> tuple[np.ndarray, np.ndarray]:
    """Step moments of a smooth force ``fun(t)`` (vectorised), by 2-point Gauss-Legendre."""
    g = 1 / math.sqrt(3)
    k = np.arange(n) * dt
    fa, fb = fun(k + 0.5 * dt * (1 - g)), fun(k + 0.5 * dt * (1 + g))
    return 0.5 * (fa + fb), 1.5 * g * (fb - fa)


def half_sine_samples(onsets_s: np.ndarray, peaks_N: np.ndarray, duration_s: float,
                      t: np.ndarray) -> np.ndarray:
    """The blow train's force (N) at times ``t`` (for the direct term of the accelerations)."""
    out = np.zeros_like(t)
    for t0, F in zip(np.atleast_1d(onsets_s), np.atleast_1d(peaks_N), strict=True):
        i0, i1 = np.searchsorted(t, [t0, t0 + duration_s])
        out[i0:i1] += F * np.sin(math.pi * (t[i0:i1] - t0) / duration_s)
    return out


def friction_input(rec: ModalRecursion, z_lin: np.ndarray, row: np.ndarray, torque_Nm: float,
                   rate_eps: float, stride: int) -> np.ndarray:
    """Coulomb friction ``-T tanh(r q' / eps)`` on the coordinate ``r q`` (``row``, (n,)), as a
    force amplitude per fine step (N,) to feed back through :meth:`ModalRecursion.run` along
    ``row``.

    Integrated at the coarse step ``stride * dt``: the nonlinear part of the state, ``x_nl``,
    advances exactly (``Phi``) under a friction held constant over the step (zero-order hold),
    whose value is implicit -- the friction of the mid-step rate, ``T_k = -T tanh((v_k + v_k+1) /
    (2 eps))``, solved by safeguarded Newton iterations -- so the stiff tanh (equivalent damping
    ``T/eps``) cannot make the scheme unstable. ``v = r q'`` is the linear response's rate, read
    from ``z_lin`` (modal states of the linear run, (m, N)), plus that of ``x_nl``.
    """
    model, N = rec.model, z_lin.shape[1]
    dtc = rec.dt * stride
    Phi, G0, _ = discretise(model, dtc, row)
    n = model.n_dof
    rv = np.concatenate([np.zeros(n), row])
    zc = z_lin[:, ::stride]
    lin = (rec.output_matrix(row, "vel") @ np.vstack([zc.real, zc.imag]))[0]
    lin = np.append(lin, lin[-1])
    s = float(rv @ G0)
    c = 0.5 / rate_eps
    x = np.zeros(2 * n)
    out = np.zeros(len(lin) - 1)
    v, T = lin[0], 0.0
    tanh = math.tanh
    for j in range(len(out)):
        y = Phi @ x
        a = v + float(rv @ y) + lin[j + 1]
        for _ in range(4):  # g(T) = T + torque tanh(c (a + s T)) = 0, g' >= 1
            th = tanh(c * (a + s * T))
            T -= (T + torque_Nm * th) / (1 + torque_Nm * c * s * (1 - th * th))
            T = min(max(T, -torque_Nm), torque_Nm)
        out[j] = T
        x = y + G0 * T
        v = lin[j + 1] + float(rv @ x)
    return np.repeat(out, stride)[:N]
