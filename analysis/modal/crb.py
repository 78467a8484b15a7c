"""Damping measures and the Cramér–Rao bound for damped-sinusoid estimators.

Report 1836 states damping as the logarithmic decrement δ (Eq C-1), the natural log of the ratio
of two successive peaks one period apart. For a pole λ = −σ + jω (ω = 2πf the damped angular
frequency) the decrement is δ = σ/f = 2πσ/ω, and the damping ratio is

    ζ = δ / √(4π² + δ²),    δ = 2πζ / √(1 − ζ²)

(exact; the report's δ/2π = ζ holds only for light damping).

The Cramér–Rao bound (CRB) is the smallest standard deviation that any unbiased estimator can
reach for a given signal, noise and record; the benchmark and the tests hold the modal estimator
against it.

Parametrisation used by the bound (per mode, θ = [A, φ, f, δ]), with t_n = n / fs_hz,
n = 0 … N−1:

- real signal:    s[n] = A · exp(−δ f t_n) · cos(2π f t_n + φ),  noise real white, variance σ²;
- complex signal: s[n] = A · exp(−δ f t_n) · exp(j(2π f t_n + φ)),  noise circular complex
  white with E|w|² = σ² (σ²/2 in each of the real and imaginary parts).

The Fisher information matrix is F = (1/σ²) Σ ∂s/∂θ ∂s/∂θᵀ (real) or (2/σ²) Re Σ ∂s/∂θᴴ ∂s/∂θ
(complex), summed numerically over the record from the analytic derivatives; the bound on the
covariance is F⁻¹. A signal-to-noise ratio quoted with these bounds is A²/(2σ²) for a real
signal (power of the undamped sinusoid at t = 0 over the noise power) and A²/σ² for a complex one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "CramerRaoBound",
    "crb_damped_sinusoid",
    "crb_damped_sinusoids",
    "damping_ratio_from_decrement",
    "decrement_from_damping_ratio",
    "fisher_information_damped_sinusoids",
]

_TWO_PI = 2.0 * np.pi


def damping_ratio_from_decrement(delta: ArrayLike) -> np.ndarray | float:
    """Damping ratio ζ from logarithmic decrement δ, exactly: ζ = δ / √(4π² + δ²).

    Parameters
    ----------
    delta : float or array_like
        Logarithmic decrement (dimensionless, per period). Negative values (growing
        oscillation) give negative ζ.

    Returns
    -------
    float or numpy.ndarray
        Damping ratio ζ (fraction of critical), same shape as `delta`.
    """
    d = np.asarray(delta, dtype=float)
    z = d / np.sqrt(_TWO_PI**2 + d * d)
    return float(z) if z.ndim == 0 else z


def decrement_from_damping_ratio(zeta: ArrayLike) -> np.ndarray | float:
    """Logarithmic decrement δ from damping ratio ζ, exactly: δ = 2πζ / √(1 − ζ²).

    Parameters
    ----------
    zeta : float or array_like
        Damping ratio, −1 < ζ < 1 (an oscillating mode).

    Returns
    -------
    float or numpy.ndarray
        Logarithmic decrement δ, same shape as `zeta`.

    Raises
    ------
    ValueError
        If any |ζ| ≥ 1 (no oscillation, so no decrement).
    """
    z = np.asarray(zeta, dtype=float)
    if np.any(np.abs(z) >= 1.0) or not np.all(np.isfinite(z)):
        raise ValueError(f"zeta ({zeta}) must satisfy |zeta| < 1 for an oscillating mode")
    d = _TWO_PI * z / np.sqrt(1.0 - z * z)
    return float(d) if d.ndim == 0 else d


@dataclass(frozen=True)
class CramerRaoBound:
    """Cramér–Rao lower bounds on the standard deviations of one mode's parameters.

    Attributes
    ----------
    amplitude_std : float
        Bound on std of the amplitude A (signal units).
    phase_std_rad : float
        Bound on std of the phase φ at t = 0 (rad).
    f_std_hz : float
        Bound on std of the damped frequency f (Hz).
    delta_std : float
        Bound on std of the logarithmic decrement δ.
    covariance : numpy.ndarray
        Full bound F⁻¹ over all modes' [A, φ, f, δ], shape (4 n_modes, 4 n_modes).
    """

    amplitude_std: float
    phase_std_rad: float
    f_std_hz: float
    delta_std: float
    covariance: np.ndarray


def _as_1d(name: str, v: ArrayLike, n: int) -> np.ndarray:
    a = np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} ({v}) must be finite")
    return a


def fisher_information_damped_sinusoids(
    amplitude: ArrayLike,
    delta: ArrayLike,
    f_hz: ArrayLike,
    noise_std: float,
    n_samples: int,
    fs_hz: float,
    *,
    phase_rad: ArrayLike = 0.0,
    complex_signal: bool = False,
) -> np.ndarray:
    """Fisher information matrix for a sum of damped sinusoids in white Gaussian noise.

    Parameters
    ----------
    amplitude, delta, f_hz, phase_rad : float or array_like, shape (n_modes,)
        Per mode: amplitude A (> 0), logarithmic decrement δ, damped frequency f (Hz), phase φ
        (rad) at t = 0. Scalars broadcast.
    noise_std : float
        Noise standard deviation σ (signal units; total for complex noise).
    n_samples : int
        Record length N.
    fs_hz : float
        Sample rate (Hz), known.
    complex_signal : bool
        Complex exponential model instead of real cosine (see module docstring).

    Returns
    -------
    numpy.ndarray, shape (4 n_modes, 4 n_modes)
        Fisher information over [A₁, φ₁, f₁, δ₁, A₂, …].
    """
    if noise_std <= 0 or not np.isfinite(noise_std):
        raise ValueError(f"noise_std ({noise_std}) must be positive")
    if n_samples < 4:
        raise ValueError(f"n_samples ({n_samples}) must be at least 4")
    if fs_hz <= 0:
        raise ValueError(f"fs_hz ({fs_hz}) must be positive")
    n_modes = int(np.broadcast(np.asarray(amplitude), np.asarray(delta), np.asarray(f_hz),
                               np.asarray(phase_rad)).size)
    A = _as_1d("amplitude", amplitude, n_modes)
    d = _as_1d("delta", delta, n_modes)
    f = _as_1d("f_hz", f_hz, n_modes)
    ph = _as_1d("phase_rad", phase_rad, n_modes)
    t = np.arange(n_samples) / fs_hz
    cols = []
    for k in range(n_modes):
        env = np.exp(-d[k] * f[k] * t)
        arg = _TWO_PI * f[k] * t + ph[k]
        if complex_signal:
            u = env * np.exp(1j * arg)  # ∂s/∂A
            du_dphi = 1j * A[k] * u
            du_df = A[k] * u * (-d[k] * t + 1j * _TWO_PI * t)
            du_dd = A[k] * u * (-f[k] * t)
        else:
            c, s = env * np.cos(arg), env * np.sin(arg)
            u = c
            du_dphi = -A[k] * s
            du_df = A[k] * (-d[k] * t * c - _TWO_PI * t * s)
            du_dd = A[k] * (-f[k] * t * c)
        cols += [u, du_dphi, du_df, du_dd]
    D = np.stack(cols, axis=1)
    if complex_signal:
        return 2.0 * np.real(D.conj().T @ D) / noise_std**2
    return (D.T @ D) / noise_std**2


def crb_damped_sinusoids(
    amplitude: ArrayLike,
    delta: ArrayLike,
    f_hz: ArrayLike,
    noise_std: float,
    n_samples: int,
    fs_hz: float,
    *,
    phase_rad: ArrayLike = 0.0,
    complex_signal: bool = False,
) -> list[CramerRaoBound]:
    """Cramér–Rao bounds for each mode of a sum of damped sinusoids (joint estimation).

    Parameters are those of :func:`fisher_information_damped_sinusoids`.

    Returns
    -------
    list of CramerRaoBound
        One per mode, each carrying the full joint covariance bound.
    """
    F = fisher_information_damped_sinusoids(
        amplitude, delta, f_hz, noise_std, n_samples, fs_hz,
        phase_rad=phase_rad, complex_signal=complex_signal,
    )
    # Scale to unit diagonal before inverting: A, φ, f and δ differ by orders of magnitude.
    scale = 1.0 / np.sqrt(np.diag(F))
    cov = scale[:, None] * np.linalg.pinv(scale[:, None] * F * scale[None, :]) * scale[None, :]
    std = np.sqrt(np.abs(np.diag(cov)))
    return [
        CramerRaoBound(
            amplitude_std=float(std[4 * k]),
            phase_std_rad=float(std[4 * k + 1]),
            f_std_hz=float(std[4 * k + 2]),
            delta_std=float(std[4 * k + 3]),
            covariance=cov,
        )
        for k in range(F.shape[0] // 4)
    ]


def crb_damped_sinusoid(
    amplitude: float,
    delta: float,
    f_hz: float,
    noise_std: float,
    n_samples: int,
    fs_hz: float,
    *,
    phase_rad: float = 0.0,
    complex_signal: bool = False,
) -> CramerRaoBound:
    """Cramér–Rao bound for one exponentially damped sinusoid in white Gaussian noise.

    Parameters
    ----------
    amplitude : float
        Initial amplitude A (signal units, > 0).
    delta : float
        Logarithmic decrement δ (decay rate σ = δ f, 1/s).
    f_hz : float
        Damped frequency f (Hz).
    noise_std : float
        Noise standard deviation σ (signal units).
    n_samples : int
        Record length N (samples, starting at the start of the decay).
    fs_hz : float
        Sample rate (Hz), known.
    phase_rad : float
        Phase φ at t = 0 (rad); matters for short real records only.
    complex_signal : bool
        Complex exponential model and circular noise instead of a real cosine.

    Returns
    -------
    CramerRaoBound
        Bounds on the std of A, φ, f (Hz) and δ; parametrisation in the module docstring.

    Examples
    --------
    >>> b = crb_damped_sinusoid(1.0, 0.06, 24.5, 0.01, 2048, 2048.0)
    >>> 0 < b.delta_std < 1e-3
    True
    """
    return crb_damped_sinusoids(
        amplitude, delta, f_hz, noise_std, n_samples, fs_hz,
        phase_rad=phase_rad, complex_signal=complex_signal,
    )[0]
