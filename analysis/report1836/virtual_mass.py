"""Virtual mass and virtual moments of inertia of a control surface: Report 1836, Eq 18-21.

Appendix E. Eq 18 (E-6) and E-7/E-9 take the virtual inertia from the drop of a mode's frequency
between air and water; Eq 19-21 (Reference 15) from strip theory on an elliptic-section plate.
All SI: ρ is a *mass* density in kg/m³ (the report's ρ/g,
:data:`ramdaq.analysis.model.units.RHO_REPORT_KG_M3`),
lengths in m, masses in kg, inertias in kg·m²; floats or numpy arrays (broadcast).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .arrays import Number, as_number, checked, positive

__all__ = [
    "m_vir_from_frequencies",
    "inertia_vir_from_frequencies",
    "m_vir_flat_plate",
    "Iz_vir_elliptic",
    "Ix_vir",
]


def m_vir_from_frequencies(m_a: ArrayLike, f_air_hz: ArrayLike, f_water_hz: ArrayLike) -> Number:
    """Eq 18 (E-6): virtual mass from in-air and in-water frequencies (kg).

    ``m_vir = m_a [(f_air/f_water)² - 1]``.

    Parameters
    ----------
    m_a : float or array_like
        Mass of the rudder in air, kg.
    f_air_hz, f_water_hz : float or array_like
        Frequency of the same (translational) mode in air and in water, Hz.
    """
    m = positive("m_a", m_a)
    fa = positive("f_air_hz", f_air_hz)
    fw = positive("f_water_hz", f_water_hz)
    return as_number(m * ((fa / fw) ** 2 - 1))


def inertia_vir_from_frequencies(
    I_a: ArrayLike, f_air_hz: ArrayLike, f_water_hz: ArrayLike
) -> Number:
    """E-7 / E-9: virtual moment of inertia from frequencies, ``I_vir = I_a [(f_a/f_w)² - 1]``.

    Parameters
    ----------
    I_a : float or array_like
        Moment of inertia in air, kg·m² ((I_z)_a with γ frequencies, E-7, or (I_x)_a with α
        frequencies, E-9).
    f_air_hz, f_water_hz : float or array_like
        Frequencies of the rotational mode in air and in water, Hz.

    Notes
    -----
    The report found E-7 and E-9 unreliable with the measured (coupled) frequencies and used
    Eq 20 and 21 instead.
    """
    ia = positive("I_a", I_a)
    fa = positive("f_air_hz", f_air_hz)
    fw = positive("f_water_hz", f_water_hz)
    return as_number(ia * ((fa / fw) ** 2 - 1))


def m_vir_flat_plate(rho: ArrayLike, chord: ArrayLike, span: ArrayLike) -> Number:
    """Eq 19: strip-theory added mass of a flat plate, ``m_vir = (π/4) ρ x̄² z̄`` (kg).

    Parameters
    ----------
    rho : float or array_like
        Mass density of the water, kg/m³ (the report's ρ/g).
    chord : float or array_like
        Mean chord x̄, m.
    span : float or array_like
        Span z̄, m.
    """
    r = positive("rho", rho)
    c = positive("chord", chord)
    s = positive("span", span)
    return as_number(np.pi / 4 * r * c**2 * s)


def Iz_vir_elliptic(
    rho: ArrayLike,
    chord: ArrayLike,
    thickness: ArrayLike,
    span: ArrayLike,
    r2_mvir: ArrayLike = 0.0,
) -> Number:
    """Eq 20: virtual moment of inertia about z of an elliptic section (kg·m²).

    ``(I_z)_vir = (π/8) ρ [(x̄/2)² - (ȳ/2)²]² z̄ + r² m_vir``.

    Parameters
    ----------
    rho : float or array_like
        Mass density of the water, kg/m³.
    chord, thickness, span : float or array_like
        Mean chord x̄, thickness ȳ and span z̄, m.
    r2_mvir : float or array_like, optional
        Parallel-axis transfer r²·m_vir to the centre of mass of the rudder-fluid system, kg·m²
        (≈ 0 in the report).
    """
    r = positive("rho", rho)
    c = positive("chord", chord)
    t = checked("thickness", thickness, "nonnegative")
    s = positive("span", span)
    transfer = checked("r2_mvir", r2_mvir, "nonnegative")
    return as_number(np.pi / 8 * r * ((c / 2) ** 2 - (t / 2) ** 2) ** 2 * s + transfer)


def Ix_vir(m_vir: ArrayLike, span: ArrayLike, s2_mvir: ArrayLike = 0.0) -> Number:
    """Eq 21 (reconstructed): virtual moment of inertia about x, ``m_vir z̄²/16 + s² m_vir``.

    The printed formula is lost in the report. ``z̄²/16`` is the squared radius of gyration
    (z̄/4)² of an added mass spread along the span as a semi-ellipse, ``∝ √(1 - (2z/z̄)²)``,
    about mid-span. With Eq 19's m_vir it gives 1.770 ft·ton·s² for ALBACORE against the printed
    1.75 (1.1 % apart); the difference is reported, not hidden (:mod:`ramdaq.analysis.report1836.table2`).

    Parameters
    ----------
    m_vir : float or array_like
        Virtual mass, kg (Eq 19).
    span : float or array_like
        Span z̄, m.
    s2_mvir : float or array_like, optional
        Parallel-axis transfer s²·m_vir, kg·m² (≈ 0 in the report).

    Returns
    -------
    float or numpy.ndarray
        (I_x)_vir, kg·m².
    """
    m = positive("m_vir", m_vir)
    s = positive("span", span)
    transfer = checked("s2_mvir", s2_mvir, "nonnegative")
    return as_number(m * s**2 / 16 + transfer)

