r"""Damping constants of a control surface: Report 1836, Table 1, Eq 14-17 (Appendix D).

All inputs and outputs are SI (kg, kg·m², m, s, Hz, N·s/m, N·m·s/rad); convert report values with
:mod:`ramdaq.analysis.model.units`. Functions accept floats or numpy arrays (broadcast) and return the same.
The virtual mass and inertias (Eq 18-21) are in :mod:`ramdaq.analysis.report1836.virtual_mass`.

Decrement and damping
---------------------
A motion ``A(t) = A1 e^{μt} sin(ωt + φ)`` has, over ``q`` whole damped periods ``τ = 2π/ω``, the
logarithmic decrement ``δ = -μτ`` exactly, so ``-μ/ω = δ/2π`` and ``-μ = f δ`` with ``f = ω/2π``
the *damped* (measured) frequency. For one degree of freedom ``m ẍ + C ẋ + k x = 0``,
``μ = -C/(2m)`` exactly, hence Eq 16 ``C = 2 m f δ`` is exact when f is the measured frequency.
Only the identification ``δ/2π = C/C_c = ζ`` is a light-damping approximation: exactly
``ζ = δ/√(4π² + δ²)`` and ``δ = 2πζ/√(1 - ζ²)``.

Eq 14 and Eq 15, re-derived (Appendix D)
----------------------------------------
Equations of motion at zero speed (Reference 1, Eq 62a, b)::

    M_y v'' = -12 k_s [v - v_b + h γ - b α - (ℓ/2)(α + α_b)] - C v'                    (62a)
    I_z γ'' - I_xz α'' = -12 k_s h (v - v_b) + 6 k_s h (ℓ + 2b) α - [G J_e/ℓ + 12 k_s h²] γ
                         + 6 k_s h ℓ α_b + (G J_e/ℓ) γ_b - c (γ' - γ_b')                (62b)

Substitute damped sinusoids sharing one λ = μ + jω: ``v = v1 e^{μt} sin ωt`` and, for every other
motion X ∈ {α, γ, v_b, α_b, γ_b}, ``X = e^{μt}(X1 sin ωt + X2 cos ωt)``. Then
``X' = e^{μt}[(μX1 - ωX2) sin ωt + (ωX1 + μX2) cos ωt]`` and
``X'' = e^{μt}[(X1(μ²-ω²) - 2μωX2) sin ωt + (X2(μ²-ω²) + 2μωX1) cos ωt]``. Each equation holds
for all t, so its sin ωt and its cos ωt parts vanish separately; the cos part is what the report
obtains by evaluating at ``t = 2nπ/ω`` (sin = 0, cos = 1), where ``v = 0``, ``v' = v1 ω e^{μt}``,
``v'' = 2 μ ω v1 e^{μt}``, and every other X equals ``X2 e^{μt}``.

(62a), cos part: ``2μω M_y v1 = -12 k_s [-v_b2 + h γ2 - b α2 - (ℓ/2)(α2 + α_b2)] - C ω v1``, so ::

    C = -2 M_y μ + (12 k_s / (v1 ω)) [v_b2 - h γ2 + b α2 + (ℓ/2)(α2 + α_b2)]            (14)

The (ℓ/2)(α2 + α_b2) term enters with a **plus** sign: Appendix D's own result is right and
Table 1's printed minus is a misprint (this sign also follows from the stock as a beam element,
whose end shear is ``12 k_s [Δw - (ℓ/2)(θ1 + θ2)]``).

(62b), cos part, after grouping ``6 k_s h (ℓ + 2b) α2 + 6 k_s h ℓ α_b2 + 12 k_s h (v_b2 - h γ2)
= 12 k_s h [v_b2 - h γ2 + b α2 + (ℓ/2)(α2 + α_b2)]``::

    c = { -I_z [γ2(μ²-ω²) + 2μω γ1] + I_xz [α2(μ²-ω²) + 2μω α1]
          + 12 k_s h [v_b2 - h γ2 + b α2 + (ℓ/2)(α2 + α_b2)] - (G J_e/ℓ)(γ2 - γ_b2) }
        / [(γ1 - γ_b1) ω + (γ2 - γ_b2) μ]                                                 (15)

The OCR prints the torsion term ``(G J_e/ℓ)(γ2 - γ_b2)`` inside the ``12 k_s h [...]`` bracket and
the denominator as ``(γ1 γ_b1)ω``; both are transcription damage. Reductions: with all
2-subscript terms zero, (14) gives ``C = -2 M_y μ = 2 M_y f δ_v`` (Eq 16); with in addition
``γ_b1 = 0``, (15) gives ``c = -2μ (I_z - I_xz α1/γ1) = 2 (I_z - I_xz α1/γ1) f δ_γ`` (Eq 17).
The sin parts of (62a, b) are a second relation each, dominated by the stiffness terms (they fix
ω); the report does not use them, and neither does this module.

Checked against the simulator (tests/test_report1836.py): the model of
:mod:`ramdaq.analysis.model.structure` has exactly (62a)'s and (62b)'s rows -- the stock a beam
element between the hull and the rudder attachment, C on v, c on γ - γ_b; its α row (62c) and
``c_alpha`` on α - α_b enter neither (62a) nor (62b), nor therefore (14) or (15) -- and every
exact damped mode of it (an eigenvector of the state matrix) gives back the rig's C and c
through (14) and (15) to 1e-10, for both rigs, both media and the stern plane. With Table 1's
printed minus on the (ℓ/2) term the ALBACORE-like 13 Hz mode misses C by 40 %. Eq 14/15 on
*measured* amplitudes, their standard errors and why they swing:
:mod:`ramdaq.analysis.report1836.full_damping`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

# The exact delta <-> zeta relations live in ramdaq.analysis.modal.crb; re-exported here for the chain.
from ..modal.crb import damping_ratio_from_decrement, decrement_from_damping_ratio
from .arrays import Number, as_number, checked, finite, positive

__all__ = [
    "damping_ratio_from_decrement",
    "decrement_from_damping_ratio",
    "mu_from_decrement",
    "stock_stiffness_k_s",
    "C_translational",
    "c_rotational",
    "C_translational_full",
    "c_rotational_full",
]

# --------------------------------------------------------------------------- decrement <-> ζ


def mu_from_decrement(f_hz: ArrayLike, delta: ArrayLike) -> Number:
    """Real part μ (1/s) of ``λ = μ + jω`` from the damped frequency and decrement: ``μ = -f δ``.

    Exact for a damped sinusoid (``-μ/ω = δ/2π`` with ω the damped circular frequency).
    """
    f = positive("f_hz", f_hz)
    d = finite("delta", delta)
    return as_number(-f * d)


def stock_stiffness_k_s(EI: ArrayLike, kappa_AG: ArrayLike, ell: ArrayLike) -> Number:
    """The report's stock stiffness ``k_s = (EI/ℓ³) / (1 + 12 EI/(κAG ℓ²))`` (N/m).

    Parameters
    ----------
    EI : float or array_like
        Bending rigidity of the stock, N·m².
    kappa_AG : float or array_like
        Shear rigidity κAG, N; ``numpy.inf`` for an Euler-Bernoulli stock.
    ell : float or array_like
        Effective bending length ℓ, m.
    """
    ei = positive("EI", EI)
    kag = np.asarray(kappa_AG, dtype=float)
    if np.any(np.isnan(kag)) or np.any(kag <= 0):
        raise ValueError(f"kappa_AG ({kappa_AG!r}) must be positive")
    length = positive("ell", ell)
    return as_number(ei / length**3 / (1 + 12 * ei / (kag * length**2)))


# --------------------------------------------------------------------------- Eq 16, 17


def C_translational(m_y: ArrayLike, f_hz: ArrayLike, delta_v: ArrayLike) -> Number:
    """Eq 16: translational damping constant ``C = -2 m_y μ = 2 m_y f δ_v`` (N·s/m).

    Parameters
    ----------
    m_y : float or array_like
        Mass of the rudder in translation, kg (in water including the virtual mass).
    f_hz : float or array_like
        Frequency of the mode, Hz.
    delta_v : float or array_like
        Logarithmic decrement of the v motion (Eq 6a/6b).

    Notes
    -----
    Eq 14 with the 2-subscript (quadrature) terms ``γ2 = α2 = α_b2 = v_b2 = 0``.
    """
    m = positive("m_y", m_y)
    f = positive("f_hz", f_hz)
    d = finite("delta_v", delta_v)
    return as_number(2 * m * f * d)


def c_rotational(
    I_z: ArrayLike,
    I_xz: ArrayLike,
    alpha1_over_gamma1: ArrayLike,
    f_hz: ArrayLike,
    delta_gamma: ArrayLike,
) -> Number:
    """Eq 17: rotational damping constant ``c = 2 (I_z - I_xz α1/γ1) f δ_γ`` (N·m·s/rad).

    Parameters
    ----------
    I_z : float or array_like
        Moment of inertia about the z axis through the centre of mass, kg·m².
    I_xz : float or array_like
        Product of inertia, kg·m² (either sign).
    alpha1_over_gamma1 : float or array_like
        Ratio of the in-phase amplitudes of α and γ in the mode (dimensionless).
    f_hz : float or array_like
        Frequency of the mode, Hz.
    delta_gamma : float or array_like
        Logarithmic decrement of the γ motion (Eq 4).

    Notes
    -----
    Eq 15 with ``γ2 = α2 = γ_b1 = γ_b2 = α_b2 = v_b2 = 0``.
    """
    iz = positive("I_z", I_z)
    ixz = finite("I_xz", I_xz)
    ratio = finite("alpha1_over_gamma1", alpha1_over_gamma1)
    f = positive("f_hz", f_hz)
    d = finite("delta_gamma", delta_gamma)
    return as_number(2 * (iz - ixz * ratio) * f * d)


# --------------------------------------------------------------------------- Eq 14, 15


def C_translational_full(
    m_y: ArrayLike,
    f_hz: ArrayLike,
    delta: ArrayLike,
    v1: ArrayLike,
    k_s: ArrayLike,
    h: ArrayLike,
    b: ArrayLike,
    ell: ArrayLike,
    *,
    v_b2: ArrayLike = 0.0,
    gamma2: ArrayLike = 0.0,
    alpha2: ArrayLike = 0.0,
    alpha_b2: ArrayLike = 0.0,
) -> Number:
    """Eq 14 (re-derived, see module docstring): translational damping constant C (N·s/m).

    ``C = -2 m_y μ + (12 k_s/(v1 ω)) [v_b2 - h γ2 + b α2 + (ℓ/2)(α2 + α_b2)]`` with
    ``μ = -f δ`` and ``ω = 2π f``.

    Parameters
    ----------
    m_y : float or array_like
        Mass in translation, kg.
    f_hz, delta : float or array_like
        Damped frequency (Hz) and logarithmic decrement of the mode.
    v1 : float or array_like
        Amplitude of v, m, with the time origin chosen so that ``v = v1 e^{μt} sin ωt``.
    k_s : float or array_like
        Stock stiffness k_s, N/m (:func:`stock_stiffness_k_s`).
    h, b : float or array_like
        x and z coordinates of the rudder-stock attachment from the centre of mass, m.
    ell : float or array_like
        Effective bending length ℓ of the stock, m.
    v_b2, gamma2, alpha2, alpha_b2 : float or array_like, keyword-only
        Cosine (quadrature) amplitudes of v_b (m), γ, α, α_b (rad); zero when the phases are
        negligible, which turns Eq 14 into Eq 16.
    """
    m = positive("m_y", m_y)
    mu = np.asarray(mu_from_decrement(f_hz, delta))
    omega = 2 * np.pi * np.asarray(f_hz, dtype=float)
    v1a = checked("v1", v1, "nonzero")
    ks = checked("k_s", k_s, "nonnegative")
    a2 = finite("alpha2", alpha2)
    quad = (
        finite("v_b2", v_b2)
        - finite("h", h) * finite("gamma2", gamma2)
        + finite("b", b) * a2
        + positive("ell", ell) / 2 * (a2 + finite("alpha_b2", alpha_b2))
    )
    return as_number(-2 * m * mu + 12 * ks / (v1a * omega) * quad)


def c_rotational_full(
    I_z: ArrayLike,
    I_xz: ArrayLike,
    f_hz: ArrayLike,
    delta: ArrayLike,
    gamma1: ArrayLike,
    alpha1: ArrayLike,
    k_s: ArrayLike,
    h: ArrayLike,
    b: ArrayLike,
    ell: ArrayLike,
    GJ_e: ArrayLike,
    *,
    gamma2: ArrayLike = 0.0,
    alpha2: ArrayLike = 0.0,
    v_b2: ArrayLike = 0.0,
    alpha_b2: ArrayLike = 0.0,
    gamma_b1: ArrayLike = 0.0,
    gamma_b2: ArrayLike = 0.0,
) -> Number:
    """Eq 15 (re-derived, see module docstring): rotational damping constant c (N·m·s/rad).

    ``c = {-I_z [γ2(μ²-ω²) + 2μωγ1] + I_xz [α2(μ²-ω²) + 2μωα1]
    + 12 k_s h [v_b2 - hγ2 + bα2 + (ℓ/2)(α2 + α_b2)] - (GJ_e/ℓ)(γ2 - γ_b2)}
    / [(γ1 - γ_b1)ω + (γ2 - γ_b2)μ]``, ``μ = -f δ``, ``ω = 2π f``.

    Parameters
    ----------
    I_z, I_xz : float or array_like
        Moment and product of inertia about the centre of mass, kg·m².
    f_hz, delta : float or array_like
        Damped frequency (Hz) and logarithmic decrement of the mode.
    gamma1, alpha1 : float or array_like
        Sine (in-phase with v) amplitudes of γ and α, rad.
    k_s : float or array_like
        Stock stiffness, N/m.
    h, b, ell : float or array_like
        Attachment coordinates and effective bending length, m.
    GJ_e : float or array_like
        Torsional rigidity of the stock, N·m² (G J_e/ℓ is the torsional stiffness, the report's
        Eq 62b uses ℓ here).
    gamma2, alpha2, v_b2, alpha_b2, gamma_b1, gamma_b2 : float or array_like, keyword-only
        Remaining amplitudes (rad, or m for v_b2); all zero turns Eq 15 into Eq 17.
    """
    iz = positive("I_z", I_z)
    ixz = finite("I_xz", I_xz)
    mu = np.asarray(mu_from_decrement(f_hz, delta))
    omega = 2 * np.pi * np.asarray(f_hz, dtype=float)
    g1, g2 = finite("gamma1", gamma1), finite("gamma2", gamma2)
    a1, a2 = finite("alpha1", alpha1), finite("alpha2", alpha2)
    gb1, gb2 = finite("gamma_b1", gamma_b1), finite("gamma_b2", gamma_b2)
    ks = checked("k_s", k_s, "nonnegative")
    hh, bb, length = finite("h", h), finite("b", b), positive("ell", ell)
    gj = checked("GJ_e", GJ_e, "nonnegative")
    denominator = (g1 - gb1) * omega + (g2 - gb2) * mu
    if np.any(denominator == 0):
        raise ValueError(
            "gamma1 - gamma_b1 and gamma2 - gamma_b2 give a zero denominator "
            "((gamma1 - gamma_b1) omega + (gamma2 - gamma_b2) mu = 0): no relative gamma motion"
        )
    p = mu**2 - omega**2
    ab2 = finite("alpha_b2", alpha_b2)
    shear = finite("v_b2", v_b2) - hh * g2 + bb * a2 + length / 2 * (a2 + ab2)
    numerator = (
        -iz * (g2 * p + 2 * mu * omega * g1)
        + ixz * (a2 * p + 2 * mu * omega * a1)
        + 12 * ks * hh * shear
        - gj / length * (g2 - gb2)
    )
    return as_number(numerator / denominator)
