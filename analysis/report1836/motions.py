"""Rudder, stock and hull motions from gage signals: Report 1836, Table 1 Eq 1-13, Appendixes A-C.

Coordinates (Figure 1): origin at the rudder's centre of mass, x aft along the chord, y
athwartship, z up along the stock. A rigid motion (v, γ, α) of the rudder moves a point (x, z) of
its centre plane athwartship by ``d_y = v + x γ - z α``. The gages sense y, and sit at

* gage 2 at ``z = +z1`` (above the c.m.), gage 6 at ``z = -z2`` (below): Appendix A's
  ``d2 = v - z1 α`` then holds and Eq 2 ``α = (d6 - d2)/(z1 + z2)`` is right. (The spec page's
  gage table words it "z1 below / z2 above"; that contradicts Appendix A's ``d2 = v - z1 α``.)
* gage 4 at ``x = +x1`` (aft), gage 8 at ``x = -x2`` (forward).
* gages 1 and 3 at the rudder top (z′ = 0), x6 forward / x5 aft of the stock; 7/11 and 10/12
  pairwise either side of the stock at two heights (Appendix B).
* hull gages 13 and 14 athwartship on the stock line, 14 above 13 by L_P, the rudder's c.m. L_H
  below 13; hull gages 15 and 16 sense **vertical** motion at ``y = -Y_P/2`` and ``+Y_P/2``, so a
  hull rotation α_b about x moves them by ``u_z = y α_b``.

Displacements and accelerations enter the same linear formulas, so every motion function accepts
either, as floats or arrays of shape ``(..., n_samples)`` (all inputs broadcast). Lengths are in m,
angles in rad. Damping (Eq 14-17) is in :mod:`ramdaq.analysis.report1836.damping`, virtual inertias
(Eq 18-21) in :mod:`ramdaq.analysis.report1836.virtual_mass`, the effective stock lengths of Appendix B
(Figures 8, 9) in :mod:`ramdaq.analysis.report1836.stock_length`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import ArrayLike

from .arrays import Number, as_number, finite, positive

__all__ = [
    "GageGeometry",
    "geometry_constants",
    "gamma",
    "alpha",
    "v_from_2_6",
    "v_from_4_8",
    "alpha_b_from_13_14",
    "alpha_b_from_15_16",
    "d_rudder_hull",
    "d_rudder_hull_from_15_16",
    "rudder_relative_motions",
    "gage_relative_to_hull",
    "gamma_7_11",
    "gamma_10_12",
    "gamma_1_3",
    "d_v_alpha_7_11",
    "d_v_alpha_10_12",
    "d_v_alpha_1_3",
    "log_decrement_ratio",
    "percent_deviation_from_average",
]


@dataclass(frozen=True)
class GageGeometry:
    """Gage distances of Figures 1, 2 and 7, all in metres and all positive (NaN where a gage
    that gives it is left out of the layout).

    Attributes
    ----------
    x1, x2 : float
        Gage 4 aft / gage 8 forward of the c.m., on the x axis.
    z1, z2 : float
        Gage 2 above / gage 6 below the c.m., on the z axis.
    x5, x6 : float
        Gage 3 aft / gage 1 forward of the stock line, at the rudder top.
    x7, x10 : float
        Half-spacing of the stock pairs 7/11 (x7 = x11) and 10/12 (x10 = x12).
    L_H : float
        Vertical distance from hull gage 13 down to the rudder's c.m.
    L_P : float
        Vertical distance between hull gages 13 and 14.
    Y_P : float
        Horizontal distance between hull gages 15 and 16.
    h : float
        x coordinate of the rudder-stock attachment (the stock line) from the c.m.
    b : float
        z coordinate of the rudder-stock attachment (rudder top, z′ = 0) from the c.m.
    """

    x1: float
    x2: float
    z1: float
    z2: float
    x5: float
    x6: float
    x7: float
    x10: float
    L_H: float
    L_P: float
    Y_P: float
    h: float
    b: float

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in ("h", "b"):
                finite(f.name, value)
            elif not math.isnan(value):  # NaN: a gage that gives it is not in the layout
                positive(f.name, value)


def geometry_constants(geom: GageGeometry) -> dict[str, float]:
    """The geometry constants K1 ... K14 of Table 1 and Appendix B.

    Parameters
    ----------
    geom : GageGeometry
        Gage distances, m.

    Returns
    -------
    dict of str to float
        ``"K1"`` ... ``"K14"``. K1, K2, K7, K8, K14 are in 1/m; the others dimensionless except
        K11 = L_H/Y_P (dimensionless, a length ratio).
    """
    g = geom
    return {
        "K1": 1 / (g.x1 + g.x2),
        "K2": 1 / (g.z1 + g.z2),
        "K3": g.z2 / (g.z1 + g.z2),
        "K4": g.z1 / g.z2,
        "K5": g.x2 / (g.x1 + g.x2),
        "K6": g.x1 / g.x2,
        "K7": 1 / (2 * g.x7),
        "K8": 1 / (2 * g.x10),
        "K9": 1 + g.L_H / g.L_P,
        "K10": g.L_H / g.L_P,
        "K11": g.L_H / g.Y_P,
        "K12": g.x6 / (g.x5 + g.x6),
        "K13": g.x5 / g.x6,
        "K14": 1 / (g.x5 + g.x6),
    }


def _a(x: ArrayLike) -> np.ndarray:
    return np.asarray(x, dtype=float)


# --------------------------------------------------------------------------- rudder, Eq 1-3b


def gamma(d4: ArrayLike, d8: ArrayLike, K1: float) -> Number:
    """Eq 1 (A-1): rotation about z, ``γ = K1 (d4 - d8)``.

    Parameters
    ----------
    d4, d8 : float or array_like, shape (..., n)
        Gage 4 (aft) and gage 8 (forward) displacement, m (or acceleration, m/s²).
    K1 : float
        ``1/(x1 + x2)``, 1/m.

    Returns
    -------
    float or numpy.ndarray, shape (..., n)
        γ, rad (or rad/s²).
    """
    return as_number(K1 * (_a(d4) - _a(d8)))


def alpha(d6: ArrayLike, d2: ArrayLike, K2: float) -> Number:
    """Eq 2 (A-2): rotation about x, ``α = K2 (d6 - d2)``; d6 below, d2 above the c.m.

    Parameters
    ----------
    d6, d2 : float or array_like, shape (..., n)
        Gage 6 and gage 2 displacement, m (or acceleration).
    K2 : float
        ``1/(z1 + z2)``, 1/m.
    """
    return as_number(K2 * (_a(d6) - _a(d2)))


def v_from_2_6(d2: ArrayLike, d6: ArrayLike, K3: float, K4: float) -> Number:
    """Eq 3a (A-3a): translation along y, ``v = K3 (d2 + K4 d6)``, m (or m/s²).

    ``K3 = z2/(z1 + z2)``, ``K4 = z1/z2``.
    """
    return as_number(K3 * (_a(d2) + K4 * _a(d6)))


def v_from_4_8(d4: ArrayLike, d8: ArrayLike, K5: float, K6: float) -> Number:
    """Eq 3b (A-3b): translation along y, ``v = K5 (d4 + K6 d8)``, m (or m/s²).

    ``K5 = x2/(x1 + x2)``, ``K6 = x1/x2``.
    """
    return as_number(K5 * (_a(d4) + K6 * _a(d8)))


# --------------------------------------------------------------------------- hull, Eq 8-13


def alpha_b_from_13_14(d13: ArrayLike, d14: ArrayLike, L_P: float) -> Number:
    """Eq 8 (B-13): hull rotation about x from athwartship hull gages, ``(d13 - d14)/L_P``.

    Gage 14 is L_P above gage 13; with ``d_y = v_b - (z - z13) α_b`` this recovers α_b (rad).
    """
    return as_number((_a(d13) - _a(d14)) / float(positive("L_P", L_P)))


def alpha_b_from_15_16(d15: ArrayLike, d16: ArrayLike, Y_P: float) -> Number:
    """Eq 8 (B-14): hull rotation about x from vertical hull gages, ``(d16 - d15)/Y_P``.

    Gages 15 and 16 sense vertical motion at ``y = -Y_P/2`` and ``+Y_P/2``: ``u_z = y α_b``.
    """
    return as_number((_a(d16) - _a(d15)) / float(positive("Y_P", Y_P)))


def d_rudder_hull(
    d13: ArrayLike,
    d14: ArrayLike,
    L_H: float,
    L_P: float,
    h: float = 0.0,
    gamma_b: ArrayLike = 0.0,
) -> Number:
    """Eq 9 / B-16: hull-borne displacement of the rudder's c.m., ``K9 d13 - K10 d14 - h γ_b``.

    Equal to ``d13 + L_H α_b - h γ_b`` with α_b from B-13; the report neglects ``h γ_b``
    (pass ``gamma_b=0``, the default).

    Parameters
    ----------
    d13, d14 : float or array_like, shape (..., n)
        Athwartship hull gages 13 and 14 (14 is L_P above 13), m.
    L_H, L_P : float
        Vertical distances gage 13 -> rudder c.m. (downwards) and 13 -> 14, m.
    h : float, optional
        x coordinate of the stock line from the c.m., m.
    gamma_b : float or array_like, optional
        Hull rotation about z at the stock (Appendix B, Figure 9), rad.
    """
    K10 = float(positive("L_H", L_H)) / float(positive("L_P", L_P))
    return as_number((1 + K10) * _a(d13) - K10 * _a(d14) - h * _a(gamma_b))


def d_rudder_hull_from_15_16(
    d13: ArrayLike,
    d15: ArrayLike,
    d16: ArrayLike,
    L_H: float,
    Y_P: float,
    h: float = 0.0,
    gamma_b: ArrayLike = 0.0,
) -> Number:
    """B-17: ``d_R-H = d13 + K11 (d16 - d15) - h γ_b`` with ``K11 = L_H/Y_P``, m."""
    K11 = float(positive("L_H", L_H)) / float(positive("Y_P", Y_P))
    return as_number(_a(d13) + K11 * (_a(d16) - _a(d15)) - h * _a(gamma_b))


def rudder_relative_motions(
    gamma_: ArrayLike,
    alpha_: ArrayLike,
    v: ArrayLike,
    gamma_b: ArrayLike,
    alpha_b: ArrayLike,
    d_RH: ArrayLike,
) -> tuple[Number, Number, Number]:
    """Motions of the rudder relative to the hull, the signals of Eq 10, 11, 12a/b (C-2...C-4).

    Returns ``(γ - γ_b, α - α_b, v - d_R-H)``; each is then reduced to a decrement with
    :func:`log_decrement_ratio` (rad, rad, m; shapes broadcast).
    """
    return (
        as_number(_a(gamma_) - _a(gamma_b)),
        as_number(_a(alpha_) - _a(alpha_b)),
        as_number(_a(v) - _a(d_RH)),
    )


def gage_relative_to_hull(
    d_M: ArrayLike,
    d13: ArrayLike,
    L_M: float,
    alpha_b: ArrayLike,
    x_M: float = 0.0,
    gamma_b: ArrayLike = 0.0,
) -> Number:
    """B-18 / B-19, the signal of Eq 13: ``d_M - (d13 + L_M α_b - x_M γ_b)``, m.

    Parameters
    ----------
    d_M : float or array_like, shape (..., n)
        Displacement of gage M, m.
    d13 : float or array_like
        Hull gage 13, m.
    L_M : float
        Vertical distance from gage 13 down to gage M, m.
    alpha_b, gamma_b : float or array_like
        Hull rotations about x and z, rad; ``gamma_b=0`` gives B-19.
    x_M : float, optional
        Horizontal distance of gage M from the stock, m, **measured like h**: the x coordinate of
        the stock line seen from gage M (positive when the gage is forward of the stock). With this
        sign B-18 reduces to B-15 at the c.m. (``x_M = h``), as the report's footnote says; the
        report's text calls x_M "positive aft", which contradicts B-15 for x aft.
    """
    return as_number(_a(d_M) - (_a(d13) + L_M * _a(alpha_b) - x_M * _a(gamma_b)))


# --------------------------------------------------------------------------- stock, B-1...B-12


def gamma_7_11(d7: ArrayLike, d11: ArrayLike, K7: float) -> Number:
    """B-3: stock rotation at the 7/11 height, ``K7 (d7 - d11)``; gage 7 at +x7 (aft), rad."""
    return as_number(K7 * (_a(d7) - _a(d11)))


def gamma_10_12(d10: ArrayLike, d12: ArrayLike, K8: float) -> Number:
    """B-6: stock rotation at the 10/12 height, ``K8 (d10 - d12)``, rad.

    Gage 10 is taken aft (+x10) of the stock axis, gage 12 forward, as B-6 requires. The OCR of
    B-4/B-5 (``d12 = (d_v,α) + x12 γ``, ``d10 = (d_v,α) - x10 γ``) places them the other way
    round; if a rig does so, pass ``(d12, d10)``.
    """
    return as_number(K8 * (_a(d10) - _a(d12)))


def gamma_1_3(d1: ArrayLike, d3: ArrayLike, K14: float) -> Number:
    """B-11: rotation at the rudder top (z′ = 0), ``K14 (d3 - d1)``; gage 3 aft by x5, rad."""
    return as_number(K14 * (_a(d3) - _a(d1)))


def d_v_alpha_7_11(d7: ArrayLike, d11: ArrayLike) -> Number:
    """B-7: coupled (v, α) displacement of the stock axis at the 7/11 height, ``(d7 + d11)/2``."""
    return as_number((_a(d7) + _a(d11)) / 2)


def d_v_alpha_10_12(d10: ArrayLike, d12: ArrayLike) -> Number:
    """B-8: coupled (v, α) displacement of the stock axis at the 10/12 height, ``(d10+d12)/2``."""
    return as_number((_a(d10) + _a(d12)) / 2)


def d_v_alpha_1_3(d1: ArrayLike, d3: ArrayLike, K12: float, K13: float) -> Number:
    """B-12: (v, α) displacement of the stock line at the rudder top, ``K12 (d3 + K13 d1)``.

    ``K12 = x6/(x5 + x6)``, ``K13 = x5/x6``; gage 3 aft by x5, gage 1 forward by x6, m.
    """
    return as_number(K12 * (_a(d3) + K13 * _a(d1)))


# --------------------------------------------------------------------------- decrements, averages


def log_decrement_ratio(a0: ArrayLike, aq: ArrayLike, q: int | ArrayLike = 1) -> Number:
    """C-1: logarithmic decrement from two peaks q periods apart, ``(1/q) ln(a0/aq)``.

    Parameters
    ----------
    a0 : float or array_like
        Amplitude of the motion at ``t0`` (any unit; a peak, or a value at a fixed phase).
    aq : float or array_like
        Amplitude at ``t0 + q τ``, same unit and same sign as ``a0``.
    q : int or array_like of int, optional
        Whole number of periods between the two (≥ 1).

    Returns
    -------
    float or numpy.ndarray
        δ per period (dimensionless), broadcast shape of the inputs.
    """
    a0a, aqa = finite("a0", a0), finite("aq", aq)
    qa = np.asarray(q)
    if qa.dtype.kind not in "iu" and not np.all(np.mod(qa, 1) == 0):
        raise ValueError(f"q ({q!r}) must be a whole number of periods")
    if np.any(qa < 1):
        raise ValueError(f"q ({q!r}) must be at least 1")
    if np.any(a0a == 0) or np.any(aqa == 0):
        raise ValueError(f"a0 ({a0!r}) and aq ({aq!r}) must not be zero")
    if np.any(np.sign(a0a) != np.sign(aqa)):
        raise ValueError(f"a0 ({a0!r}) and aq ({aq!r}) must have the same sign (same phase)")
    return as_number(np.log(a0a / aqa) / qa.astype(float))


def percent_deviation_from_average(values: ArrayLike) -> tuple[float, np.ndarray, float]:
    """Average, percent deviations and mean absolute deviation, as in Table 2b, 2f, 2h.

    Parameters
    ----------
    values : array_like, shape (n,)
        The values averaged (e.g. δ_γ, δ_α, δ_v, δ_modal), n ≥ 1, average non-zero.

    Returns
    -------
    mean : float
        Arithmetic average.
    deviations_pct : numpy.ndarray, shape (n,)
        ``100 (value - mean)/mean``.
    mean_abs_deviation_pct : float
        Average of ``|deviations_pct|``, the table's "± x %" entry.
    """
    x = finite("values", values).ravel()
    if x.size == 0:
        raise ValueError("values (empty) must hold at least one value")
    mean = float(np.mean(x))
    if mean == 0:
        raise ValueError(f"values ({values!r}) average to zero; no percent deviation")
    dev = 100 * (x - mean) / mean
    return mean, dev, float(np.mean(np.abs(dev)))
