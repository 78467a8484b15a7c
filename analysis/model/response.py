"""Exact time response of a :class:`~ramdaq.analysis.model.structure.StructuralModel`: eigen-analysis,
closed-form modal superposition, and a block-by-block simulator of ram impacts.

The state ``x = [q, q']`` obeys ``x' = A x + B f(t)`` with
``A = [[0, I], [-M^-1 K, -M^-1 C]]``. With ``A = V diag(lambda) V^-1`` the modal states
``z = V^-1 x`` decouple: ``z_i' = lambda_i z_i + beta_i f(t)``. Between impacts ``z_i`` decays
as ``exp(lambda_i t)`` exactly (this *is* the matrix exponential, diagonalised), and a half-sine
ram force ``F0 sin(pi t / T)`` on ``0 <= t <= T`` has the exact modal response
``beta_i F0 J_i(t)`` with::

    J(s) = (W e^{lambda s} - lambda sin(W s) - W cos(W s)) / (lambda^2 + W^2),   0 <= s <= T
    J(s) = e^{lambda (s - T)} J(T),                                           s > T

(``W = pi / T``). Nothing is integrated numerically, so the simulator's only error is floating
point. Conjugate pairs are kept once, with weight 2 on the real part.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from .structure import StructuralModel


@dataclass(frozen=True)
class ModalForm:
    """Diagonalised state space of a model.

    Attributes
    ----------
    eigenvalues : complex ndarray, (n_modes,)
        ``lambda = mu + j omega`` (1/s), one per conjugate pair (omega > 0), sorted by frequency.
    weights : ndarray, (n_modes,)
        2 for a conjugate pair, 1 for a real (overdamped) eigenvalue.
    right : complex ndarray, (2 n_dof, n_modes)
        Right eigenvectors (state shapes).
    left : complex ndarray, (n_modes, 2 n_dof)
        Matching rows of ``V^-1``.
    gage_disp, gage_acc : complex ndarray, (n_gages, n_modes)
        Gage displacement (m) and acceleration (m/s^2) per unit modal state.
    """

    model: StructuralModel
    eigenvalues: np.ndarray
    weights: np.ndarray
    right: np.ndarray
    left: np.ndarray
    gage_disp: np.ndarray
    gage_acc: np.ndarray

    @property
    def n_modes(self) -> int:
        return len(self.eigenvalues)

    def input_vector(self, force: np.ndarray) -> np.ndarray:
        """Modal input ``beta`` (per newton) of a generalised force vector, (n_modes,)."""
        n = self.model.n_dof
        b = np.concatenate([np.zeros(n), np.linalg.solve(self.model.M, force)])
        return self.left @ b

    def feedthrough(self, force: np.ndarray) -> np.ndarray:
        """Gage acceleration per newton of applied force (m/s^2/N), (n_gages,)."""
        return self.model.gage_dofs @ np.linalg.solve(self.model.M, force)

    def state_to_modal(self, x: np.ndarray) -> np.ndarray:
        """Modal states of a real state vector ``[q, q']``."""
        return self.left @ x

    def modal_to_state(self, z: np.ndarray) -> np.ndarray:
        """Real state ``[q, q']`` of modal states ``z`` (one per pair), shape (2 n_dof, ...)."""
        return np.real(self.right @ (self.weights[:, None] * z.reshape(self.n_modes, -1))).reshape(
            (self.right.shape[0],) + z.shape[1:])


def state_matrix(model: StructuralModel) -> np.ndarray:
    """``A = [[0, I], [-M^-1 K, -M^-1 C]]``, shape (2 n_dof, 2 n_dof)."""
    n = model.n_dof
    Minv = np.linalg.inv(model.M)
    return np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ model.K, -Minv @ model.C]])


def modal_form(model: StructuralModel) -> ModalForm:
    """Eigen-analysis of the state matrix, keeping one eigenvalue per conjugate pair."""
    A = state_matrix(model)
    lam, V = scipy.linalg.eig(A)
    W = np.linalg.inv(V)
    keep = np.flatnonzero(lam.imag >= 0)
    order = keep[np.argsort(np.abs(lam[keep]))]
    lam, V, W = lam[order], V[:, order], W[order]
    if np.any(np.abs(lam.imag) < 1e-9 * np.abs(lam)):
        raise ValueError("model has an overdamped (real) mode; ram-impact trials expect "
                         "underdamped modes: check the rig's damping")
    n = model.n_dof
    weights = np.where(lam.imag > 0, 2.0, 1.0)
    gage_disp = model.gage_dofs @ V[:n]
    gage_acc = model.gage_dofs @ (V[n:] * lam)
    return ModalForm(model, lam, weights, V, W, gage_disp, gage_acc)


@dataclass(frozen=True)
class ModelModes:
    """The model's true modes: what every estimator is held against.

    ``frequency_hz`` is the damped frequency ``omega/2pi``; ``decrement`` the logarithmic
    decrement ``-2 pi mu / omega`` of a free decay; ``damping_ratio`` ``-mu/|lambda|``;
    ``gage_shapes`` complex displacement shapes at the gages, (n_gages, n_modes), each
    normalised to unit largest magnitude with that entry real and positive.
    """

    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    decrement: np.ndarray
    eigenvalues: np.ndarray
    gage_shapes: np.ndarray
    gage_numbers: tuple[int, ...]


def model_modes(form: ModalForm) -> ModelModes:
    lam = form.eigenvalues
    shapes = form.gage_disp.copy()
    for i in range(shapes.shape[1]):
        j = np.argmax(np.abs(shapes[:, i]))
        shapes[:, i] *= np.conj(shapes[j, i]) / np.abs(shapes[j, i]) ** 2
    return ModelModes(
        frequency_hz=lam.imag / (2 * math.pi),
        damping_ratio=-lam.real / np.abs(lam),
        decrement=-2 * math.pi * lam.real / lam.imag,
        eigenvalues=lam,
        gage_shapes=shapes,
        gage_numbers=form.model.gage_numbers,
    )


def half_sine_response(lam: np.ndarray, duration_s: float, s: np.ndarray) -> np.ndarray:
    """``J(s)`` of the module docstring: modal state per unit ``beta F0``.

    Parameters
    ----------
    lam : complex ndarray, (n_modes,)
    duration_s : float
        Half-sine duration T, s.
    s : ndarray, (n,)
        Time since the start of the impact, s; ``J = 0`` for ``s <= 0``.

    Returns
    -------
    complex ndarray, (n_modes, n)
    """
    w = math.pi / duration_s
    lam = np.asarray(lam)[:, None]
    s = np.asarray(s, dtype=float)[None, :]
    sc = np.clip(s, 0.0, duration_s)
    den = lam**2 + w**2
    during = (w * np.exp(lam * sc) - lam * np.sin(w * sc) - w * np.cos(w * sc)) / den
    after = np.exp(lam * np.maximum(s - duration_s, 0.0))
    return np.where(s <= 0, 0.0, during * after)


def half_sine_force(peak_N: float, duration_s: float, s: np.ndarray) -> np.ndarray:
    """Ram force (N) at times ``s`` (s) since the impact's start, zero outside ``[0, T]``."""
    s = np.asarray(s, dtype=float)
    inside = (s >= 0) & (s <= duration_s)
    return np.where(inside, peak_N * np.sin(math.pi * np.clip(s, 0, duration_s) / duration_s), 0.0)


@dataclass
class _Active:
    t_s: float
    peak_N: float
    duration_s: float
    beta: np.ndarray
    feed: np.ndarray


@dataclass
class ModalSimulator:
    """Block-by-block exact response to half-sine impacts, noise-free (m/s^2 at the gages).

    A stateful stepper: ``advance(n)`` returns the next ``n`` samples, shape ``(n_gages, n)``,
    and moves the sample clock on. Impacts may start between samples.
    """

    form: ModalForm
    fs_hz: float
    sample: int = 0
    z: np.ndarray = field(default=None)  # type: ignore[assignment]
    _active: list[_Active] = field(default_factory=list)
    _decay_cache: dict[int, np.ndarray] = field(default_factory=dict)
    _ambient: list[tuple[np.ndarray, float]] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.z is None:
            self.z = np.zeros(self.form.n_modes, dtype=complex)
        w = self.form.weights[None, :]
        # real output matrix acting on [Re z; Im z]
        self._out = np.hstack([np.real(w * self.form.gage_acc), -np.imag(w * self.form.gage_acc)])

    def add_impact(self, t_s: float, peak_N: float, duration_s: float,
                   location_m: tuple[float, float, float], direction: str = "y") -> None:
        """Schedule a half-sine ram blow starting at ``t_s`` (s from the stream's start)."""
        if t_s * self.fs_hz < self.sample:
            raise ValueError(f"impact at {t_s} s is in the past (clock at {self.sample / self.fs_hz} s)")
        f = self.form.model.force_vector(location_m, direction)
        self._active.append(_Active(t_s, peak_N, duration_s, self.form.input_vector(f),
                                    self.form.feedthrough(f)))

    def advance(self, n: int) -> np.ndarray:
        lam = self.form.eigenvalues
        k = np.arange(n)
        decay = self._decay_cache.get(n)
        if decay is None:
            decay = np.exp(lam[:, None] * (k + 1)[None, :] / self.fs_hz)  # e^{lam (t_k - t0)}, k>=1
            decay = np.hstack([np.ones((len(lam), 1)), decay])  # columns 0..n
            self._decay_cache[n] = decay
        t0 = self.sample / self.fs_hz
        t = (self.sample + np.arange(n + 1)) / self.fs_hz  # sample times plus the next block start
        Z = self.z[:, None] * decay  # (n_modes, n+1)
        forced = np.zeros((self.form.model.gage_dofs.shape[0], n))
        still = []
        for imp in self._active:
            if imp.t_s >= t[-1]:
                still.append(imp)
                continue
            Jt = half_sine_response(lam, imp.duration_s, t - imp.t_s)
            J0 = half_sine_response(lam, imp.duration_s, np.array([t0 - imp.t_s]))
            Z += imp.peak_N * imp.beta[:, None] * (Jt - J0 * decay)
            forced += imp.feed[:, None] * half_sine_force(imp.peak_N, imp.duration_s, t[:n] - imp.t_s)
            if imp.t_s + imp.duration_s > t[-1]:
                still.append(imp)
        self._active = still
        self.z = Z[:, n]
        self.sample += n
        zs = Z[:, :n]
        out = self._out @ np.vstack([zs.real, zs.imag]) + forced
        for amp, f_hz in self._ambient:
            out += np.real(amp[:, None] * np.exp(2j * math.pi * f_hz * t[None, :n]))
        return out

    def add_ambient(self, hull_mode: int, frequency_hz: float, v_b_amplitude_m: float) -> None:
        """Add a steady sinusoidal drive of hull mode ``hull_mode`` (1-based), sized so the hull
        moves ``v_b_amplitude_m`` at the stock; it is in steady state from the first sample."""
        amp = ambient_gage_amplitudes(self.form.model, hull_mode, frequency_hz, v_b_amplitude_m)
        self._ambient.append((amp, frequency_hz))

    def free_decay(self, t_s: np.ndarray) -> np.ndarray:
        """Closed-form modal superposition of the free decay from the current state,
        gage accelerations (m/s^2) at ``t_s`` seconds after the current sample, (n_gages, n)."""
        lam = self.form.eigenvalues
        Z = self.z[:, None] * np.exp(lam[:, None] * np.asarray(t_s)[None, :])
        return np.real((self.form.gage_acc * self.form.weights) @ Z)


def impact_amplitudes(form: ModalForm, peak_N: float, duration_s: float,
                      location_m: tuple[float, float, float], direction: str = "y") -> np.ndarray:
    """Displacement amplitude (m) of each mode at each gage just after a half-sine blow,
    shape (n_gages, n_modes): ``|w_i * shape_gi * beta_i * F0 * J_i(T)|``."""
    beta = form.input_vector(form.model.force_vector(location_m, direction))
    J = half_sine_response(form.eigenvalues, duration_s, np.array([duration_s]))[:, 0]
    return np.abs(form.weights * form.gage_disp * (beta * peak_N * J))


def predominant_mode(form: ModalForm, peak_N: float, duration_s: float,
                     location_m: tuple[float, float, float], direction: str = "y",
                     bodies: tuple[str, ...] = ("rudder",)) -> int:
    """Index of the mode that dominates the displacement of the gages on ``bodies`` after a
    blow, as it stands out on an oscillogram: large *and* lasting. The measure is each mode's
    share of the time-integrated squared displacement, ``sum_g A_gi^2 / (2 |mu_i|)``."""
    amp = impact_amplitudes(form, peak_N, duration_s, location_m, direction)
    rig = form.model.rig
    rows = [i for i, n in enumerate(form.model.gage_numbers) if rig.gage(n).body in bodies]
    energy = (amp[rows] ** 2).sum(axis=0) / (2 * np.abs(form.eigenvalues.real))
    return int(np.argmax(energy))


def ambient_gage_amplitudes(model: StructuralModel, hull_mode: int, frequency_hz: float,
                            v_b_amplitude_m: float) -> np.ndarray:
    """Complex gage acceleration amplitudes (m/s^2), (n_gages,), of a steady drive of one hull
    mode, from the frequency response ``(K - W^2 M + j W C)^-1``, scaled to the wanted v_b."""
    w = 2 * math.pi * frequency_hz
    k = 2 + hull_mode
    e = np.zeros(model.n_dof)
    e[k] = 1.0
    X = np.linalg.solve(model.K - w**2 * model.M + 1j * w * model.C, e)
    v_b = sum(mode.v_b * X[3 + i] for i, mode in enumerate(model.rig.hull_modes))
    X *= v_b_amplitude_m / abs(v_b)
    return -(w**2) * (model.gage_dofs @ X)
