"""Effective lengths ℓ (bending) and ℓ_T (torsion) of a rudder stock: Report 1836, Appendix B.

The report plots, against the height z′ above the rudder-stock attachment (z′ = 0 at the rudder
top, z′ = z - b), the stock's (v, α) displacement (Figure 8, from B-7, B-8, B-12) and its rotation
γ (Figure 9, from B-3, B-6, B-11), and reads off by eye where "the curve becomes linear" (bending)
or "vertical" (torsion): that height is the effective attachment of the stock to the hull, and
``ℓ = z′_B + b``, ``ℓ_T = z′_T + b``. This module makes that reading numerical.

Bending (Figure 8)
    Above the attachment the stock moves with the hull, on the straight asymptote
    ``d(z′) = d0 - α_b z′`` (rigid hull rotation α_b about x). The asymptote is fitted to the
    hull-side points (e.g. gages 13 and 14 at their z′), or given its slope by α_b (Eq 8).
    Below it the stock is a cantilever clamped at z′_B and loaded only at the rudder end (its
    own mass neglected, as in the report), so its deflection relative to the asymptote is the
    Euler-Bernoulli end-load shape ``w = s² (a + c s)`` with ``s = z′_B - z′``: zero deflection
    *and zero slope* at the clamp, which is exactly where the curve joins the line tangentially
    ("becomes linear"). z′_B is the height that best fits this shape to the stock points (linear
    least squares in a, c for each trial z′_B, all the search grid's trials at once, minimised
    over z′_B between the highest stock point and the lowest hull-side point). With three stock
    points (gages 1/3, 7/11, 10/12) the fit is exact; with two, only ``w = a s²`` is fitted.
    Shear deformation of a Timoshenko stock adds a term linear in s that this reading ignores.

Torsion (Figure 9)
    A stock under an end torque twists linearly from the rudder up to its torsional attachment;
    above it γ = γ_b (the hull's). z′_T is where the straight line fitted to the stock points
    (γ against z′) reaches γ_b; γ_b is given, or the average of hull-side γ values.

All lengths in m, displacements in m (or any consistent unit: amplitudes of one mode at one
instant), angles in rad.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import minimize_scalar

__all__ = ["EffectiveLength", "effective_length_bending", "effective_length_torsion"]


@dataclass(frozen=True)
class EffectiveLength:
    """Result of an effective-length reading.

    Attributes
    ----------
    z_attach : float
        Height z′ of the effective attachment above the rudder top, m (z′_B or z′_T).
    length : float
        ``z_attach + b``: ℓ or ℓ_T, m.
    value_at_attach : float
        The asymptote's value there: ``(d_v,α)_R-H`` (m) for bending, γ_b (rad) for torsion.
    slope : float
        Slope of the hull-side asymptote against z′ (``-α_b`` for bending, 0 for torsion).
    intercept : float
        Value of the hull-side asymptote at z′ = 0.
    rms_residual : float
        RMS misfit of the stock points to the fitted shape (same unit as the values).
    """

    z_attach: float
    length: float
    value_at_attach: float
    slope: float
    intercept: float
    rms_residual: float


def _vec(name: str, x: ArrayLike) -> np.ndarray:
    a = np.asarray(x, dtype=float).ravel()
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} ({x!r}) must be finite")
    return a


def _paired(zn: str, z: ArrayLike, vn: str, v: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    za, va = _vec(zn, z), _vec(vn, v)
    if za.shape != va.shape:
        raise ValueError(f"{zn} ({za.size} values) and {vn} ({va.size} values) differ in length")
    return za, va


def _end_load_misfit(zb: np.ndarray, zs: np.ndarray, w: np.ndarray, cubic: bool) -> np.ndarray:
    """RMS misfit of the least-squares fit of ``w = s^2 (a + c s)`` (``a s^2`` alone without
    ``cubic``), ``s = zb - zs``, for every trial clamp height in ``zb`` (n_trials,) at once.

    The residual is ``w`` less its projection on the columns s^2 (and s^3), orthonormalised
    row by row by Gram-Schmidt twice over (as accurate as a QR); a column no larger than
    rounding once the earlier ones are taken out adds nothing, as ``lstsq``'s rank cut-off."""
    s = np.asarray(zb, dtype=float)[:, None] - zs[None, :]
    r = np.broadcast_to(w, s.shape).copy()
    basis: list[np.ndarray] = []
    for col in ((s**2, s**3) if cubic else (s**2,)):
        v = col.copy()
        for _ in range(2):
            for q in basis:
                v -= np.sum(q * v, axis=1, keepdims=True) * q
        norm = np.linalg.norm(v, axis=1, keepdims=True)
        big = norm > 4 * np.finfo(float).eps * zs.size * np.linalg.norm(col, axis=1, keepdims=True)
        q = np.divide(v, norm, out=np.zeros_like(v), where=big & (norm > 0))
        basis.append(q)
        r -= np.sum(q * r, axis=1, keepdims=True) * q
    return np.sqrt(np.mean(r**2, axis=1))


def effective_length_bending(
    z_stock: ArrayLike,
    d_stock: ArrayLike,
    z_hull: ArrayLike,
    d_hull: ArrayLike,
    b: float,
    *,
    alpha_b: float | None = None,
    z_search: tuple[float, float] | None = None,
    n_grid: int = 2001,
) -> EffectiveLength:
    """Effective bending length ℓ from (d_v,α) values along the stock (Figure 8).

    Parameters
    ----------
    z_stock, d_stock : array_like, shape (n_s,)
        Heights z′ (m) and (v, α) displacements (m) of the stock axis below the attachment, e.g.
        ``(0, d_v_alpha_1_3)``, ``(z′_7, d_v_alpha_7_11)``, ``(z′_10, d_v_alpha_10_12)``; n_s ≥ 2.
    z_hull, d_hull : array_like, shape (n_h,)
        Heights z′ (m) and athwartship displacements (m) of hull-side points on the stock line
        (e.g. gages 13 and 14); n_h ≥ 2, or ≥ 1 when ``alpha_b`` is given.
    b : float
        Height of the rudder top (z′ = 0) above the rudder's centre of mass, m.
    alpha_b : float, optional
        Hull rotation about x (Eq 8), rad; fixes the asymptote's slope to ``-alpha_b``.
    z_search : (float, float), optional
        Interval searched for z′_B, m. Default: highest stock point to lowest hull-side point.
    n_grid : int, optional
        Grid points of the coarse search before the bounded refinement.

    Returns
    -------
    EffectiveLength
        ``z_attach`` = z′_B, ``length`` = ℓ, ``value_at_attach`` = (d_v,α)_R-H.
    """
    zs, ds = _paired("z_stock", z_stock, "d_stock", d_stock)
    zh, dh = _paired("z_hull", z_hull, "d_hull", d_hull)
    if zs.size < 2:
        raise ValueError(f"z_stock ({zs.size} points) needs at least 2 stock points")
    if alpha_b is None:
        if np.unique(zh).size < 2:
            raise ValueError(f"z_hull ({zh.size} points) needs 2 distinct heights, or give alpha_b")
        slope, intercept = np.polyfit(zh, dh, 1)
    else:
        if zh.size < 1:
            raise ValueError("z_hull (0 points) needs at least 1 hull-side point")
        slope = -float(alpha_b)
        intercept = float(np.mean(dh - slope * zh))
    lo, hi = z_search if z_search is not None else (float(zs.max()), float(zh.min()))
    if not lo < hi:
        raise ValueError(f"z_search ({lo}, {hi}) is empty: stock points must lie below hull points")
    if n_grid < 3:
        raise ValueError(f"n_grid ({n_grid}) must be at least 3")
    w = ds - (intercept + slope * zs)
    cubic = zs.size >= 3

    def misfit(zb: float) -> float:
        return float(_end_load_misfit(np.array([zb]), zs, w, cubic)[0])

    grid = np.linspace(lo, hi, n_grid)
    costs = _end_load_misfit(grid, zs, w, cubic)
    k = int(np.argmin(costs))
    a, c = grid[max(k - 1, 0)], grid[min(k + 1, n_grid - 1)]
    xatol = 1e-12 * (hi - lo)
    res = minimize_scalar(misfit, bounds=(a, c), method="bounded", options={"xatol": xatol})
    zb = float(res.x) if res.fun <= costs[k] else float(grid[k])
    return EffectiveLength(
        z_attach=zb,
        length=zb + float(b),
        value_at_attach=float(intercept + slope * zb),
        slope=float(slope),
        intercept=float(intercept),
        rms_residual=misfit(zb),
    )


def effective_length_torsion(
    z_stock: ArrayLike,
    gamma_stock: ArrayLike,
    b: float,
    *,
    gamma_b: float | None = None,
    z_hull: ArrayLike | None = None,
    gamma_hull: ArrayLike | None = None,
) -> EffectiveLength:
    """Effective torsion length ℓ_T from γ values along the stock (Figure 9).

    Parameters
    ----------
    z_stock, gamma_stock : array_like, shape (n_s,)
        Heights z′ (m) and rotations γ (rad) below the torsional attachment, e.g. from
        :func:`~ramdaq.analysis.report1836.motions.gamma_1_3`, ``gamma_7_11``, ``gamma_10_12``; n_s ≥ 2.
    b : float
        Height of the rudder top above the rudder's centre of mass, m.
    gamma_b : float, optional
        Hull rotation about z, rad. If omitted, the mean of ``gamma_hull``.
    z_hull, gamma_hull : array_like, optional
        Hull-side γ values (their heights are only checked to lie above the stock points).

    Returns
    -------
    EffectiveLength
        ``z_attach`` = z′_T, ``length`` = ℓ_T, ``value_at_attach`` = γ_b.
    """
    zs, gs = _paired("z_stock", z_stock, "gamma_stock", gamma_stock)
    if np.unique(zs).size < 2:
        raise ValueError(f"z_stock ({zs.size} points) needs at least 2 distinct heights")
    if gamma_b is None:
        if gamma_hull is None:
            raise ValueError("gamma_b (None) must be given, or gamma_hull")
        gh = _vec("gamma_hull", gamma_hull)
        if gh.size == 0:
            raise ValueError("gamma_hull (empty) must hold at least one value")
        if z_hull is not None and np.min(_vec("z_hull", z_hull)) <= zs.max():
            raise ValueError("z_hull must lie above every stock point")
        gamma_b = float(np.mean(gh))
    slope, intercept = np.polyfit(zs, gs, 1)
    if slope == 0:
        raise ValueError("gamma_stock does not vary along the stock: no torsional attachment")
    zt = float((gamma_b - intercept) / slope)
    resid = gs - (intercept + slope * zs)
    return EffectiveLength(
        z_attach=zt,
        length=zt + float(b),
        value_at_attach=float(gamma_b),
        slope=0.0,
        intercept=float(gamma_b),
        rms_residual=float(np.sqrt(np.mean(resid**2))),
    )
