"""Conversions between SI and the units of DTMB Report 1836.

The report works in long tons force (1 ton = 2240 lbf), feet and seconds. Its mass is the
gravitational-system unit ton·s²/ft, its moments of inertia ft·ton·s², its translational damping
ton·s/ft and rotational damping ft·ton·s. Sea water is given as a *weight* density
ρ = 64.15 lb/ft³ with g = 32.17 ft/s², so the report's mass density is ρ/g.

ramdaq computes in SI (m, kg, s, N, rad) and converts only at the edges::

    >>> round(to_si(0.0878, "mass"), 2)        # ALBACORE rudder mass in air, kg
    1281.36
    >>> round(from_si(to_si(0.3261, "damping_translational"), "damping_translational"), 12)
    0.3261

The foot and the pound-force are exact by definition (1 ft = 0.3048 m,
1 lbf = 0.45359237 kg × 9.80665 m/s² = 4.4482216152605 N).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "FT_M",
    "LBF_N",
    "LONG_TON_LBF",
    "TONF_N",
    "RHO_WEIGHT_LBF_FT3",
    "G_FT_S2",
    "RHO_REPORT_KG_M3",
    "QUANTITIES",
    "to_si",
    "from_si",
    "report_unit",
    "si_unit",
]

FT_M: float = 0.3048
"""One international foot in metres (exact)."""
LBF_N: float = 4.4482216152605
"""One pound-force in newtons (exact)."""
LONG_TON_LBF: float = 2240.0
"""One long ton-force in pounds-force (the report's "ton")."""
TONF_N: float = LONG_TON_LBF * LBF_N
"""One long ton-force in newtons (≈ 9964.016 N)."""
RHO_WEIGHT_LBF_FT3: float = 64.15
"""The report's weight density of sea water, lbf/ft³ (Table 2d, 2j)."""
G_FT_S2: float = 32.17
"""The report's acceleration of gravity, ft/s² (Table 2d, 2j)."""

# value_in_report_units * factor = value_in_SI
QUANTITIES: dict[str, tuple[float, str, str]] = {
    "length": (FT_M, "ft", "m"),
    "area": (FT_M**2, "ft^2", "m^2"),
    "volume": (FT_M**3, "ft^3", "m^3"),
    "area_moment": (FT_M**4, "ft^4", "m^4"),
    "time": (1.0, "s", "s"),
    "frequency": (1.0, "Hz", "Hz"),
    "angle": (1.0, "rad", "rad"),
    "dimensionless": (1.0, "1", "1"),
    "acceleration": (FT_M, "ft/s^2", "m/s^2"),
    "force": (TONF_N, "ton", "N"),
    "moment": (TONF_N * FT_M, "ft·ton", "N·m"),
    "mass": (TONF_N / FT_M, "ton·s^2/ft", "kg"),
    "inertia": (TONF_N * FT_M, "ft·ton·s^2", "kg·m^2"),
    "damping_translational": (TONF_N / FT_M, "ton·s/ft", "N·s/m"),
    "damping_rotational": (TONF_N * FT_M, "ft·ton·s", "N·m·s/rad"),
    "stiffness_translational": (TONF_N / FT_M, "ton/ft", "N/m"),
    "stiffness_rotational": (TONF_N * FT_M, "ft·ton/rad", "N·m/rad"),
    "weight_density": (LBF_N / FT_M**3, "lbf/ft^3", "N/m^3"),
    "mass_density": (TONF_N / FT_M**4, "ton·s^2/ft^4", "kg/m^3"),
}
"""Quantity name -> (SI value of one report unit, report unit, SI unit)."""

RHO_REPORT_KG_M3: float = (
    RHO_WEIGHT_LBF_FT3 * QUANTITIES["weight_density"][0] / (G_FT_S2 * FT_M)
)
"""The report's sea-water mass density ρ/g = 64.15 lbf/ft³ / 32.17 ft/s², in kg/m³ (≈ 1027.7)."""


def _factor(quantity: str) -> float:
    try:
        return QUANTITIES[quantity][0]
    except KeyError:
        known = ", ".join(sorted(QUANTITIES))
        raise ValueError(f"unknown quantity {quantity!r}; known quantities: {known}") from None


def to_si(value: ArrayLike, quantity: str) -> float | np.ndarray:
    """Convert ``value`` from the report's unit of ``quantity`` to SI.

    Parameters
    ----------
    value : float or array_like, any shape
        Value(s) in the report's unit (see :data:`QUANTITIES`).
    quantity : str
        A key of :data:`QUANTITIES`, e.g. ``"mass"`` (ton·s²/ft -> kg).

    Returns
    -------
    float or numpy.ndarray
        The value(s) in SI, same shape as ``value``.

    Raises
    ------
    ValueError
        If ``quantity`` is not known; the message names it.
    """
    factor = _factor(quantity)
    if np.ndim(value) == 0:
        return float(value) * factor
    return np.asarray(value, dtype=float) * factor


def from_si(value: ArrayLike, quantity: str) -> float | np.ndarray:
    """Convert ``value`` from SI to the report's unit of ``quantity``.

    Parameters
    ----------
    value : float or array_like, any shape
        Value(s) in SI.
    quantity : str
        A key of :data:`QUANTITIES`, e.g. ``"inertia"`` (kg·m² -> ft·ton·s²).

    Returns
    -------
    float or numpy.ndarray
        The value(s) in the report's unit, same shape as ``value``.

    Raises
    ------
    ValueError
        If ``quantity`` is not known; the message names it.
    """
    factor = _factor(quantity)
    if np.ndim(value) == 0:
        return float(value) / factor
    return np.asarray(value, dtype=float) / factor


def report_unit(quantity: str) -> str:
    """The report's unit of ``quantity`` as text, e.g. ``"ton·s/ft"``; ValueError if unknown."""
    _factor(quantity)
    return QUANTITIES[quantity][1]


def si_unit(quantity: str) -> str:
    """The SI unit of ``quantity`` as text, e.g. ``"N·s/m"``; ValueError if unknown."""
    _factor(quantity)
    return QUANTITIES[quantity][2]
