"""The report's gage distances (Figures 1, 2, 7) read off a rig's gage positions.

The report's equations name distances (x1, z1, L_H, ...); a rig names positions. This module is
the one place that turns one into the other (:func:`gage_geometry`, all in m), and checks that
the gages sit where the equations assume, refusing a rig that does not with a
:class:`~ramdaq.analysis.model.rig.RigError`: 2 and 6 on the vertical through the centre of mass
(x = 0), 4 and 8 on the horizontal (z = 0), 13 and 14 on one vertical, each stock pair (7/11,
10/12) at one height, all to ``ALIGN_TOL_M``. Gages 15 and 16 give ``Y_P`` as the difference of
their y; their heights are not checked. Which gage of a stock pair is aft is read from the
positions, not assumed (the report's B-4/B-5 and B-6 disagree on it). For a stern plane the
rig's positions are in its surface frame (``analysis/model/surface.py``): "vertical" is along the
stock; the errors name the positions as its file writes them, in ship axes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..report1836.motions import GageGeometry
from .rig import ALIGN_TOL_M, Rig, RigError


@dataclass(frozen=True)
class StockPair:
    """A pair of stock gages at one height: ``aft`` and ``forward`` gage numbers, their height
    ``z_m`` above the centre of mass and half-spacing ``half_spacing_m`` about the stock axis."""

    aft: int
    forward: int
    z_m: float
    half_spacing_m: float


_NOWHERE = (math.nan, math.nan, math.nan)


def _pos(rig: Rig, n: int) -> tuple[float, float, float]:
    """Gage ``n``'s position, m; NaN for a gage the rig leaves out (the distances it gives are
    NaN, and the report's steps that need it are skipped: ``impact.skipped_steps``)."""
    return next((g.position_m for g in rig.gages if g.number == n), _NOWHERE)


def _ship(rig: Rig, p: tuple[float, float, float]) -> tuple[float, ...]:
    """A position as the rig file writes it (ship axes), rounded to the micrometre."""
    return tuple(round(c, 6) + 0.0 for c in rig.surface.to_ship(p))


def _height(rig: Rig) -> str:
    return "height" if rig.surface.is_rudder else "distance along the stock"


def stock_pair(rig: Rig, a: int, b: int) -> StockPair:
    """Order a stock (or rudder-top) gage pair by which is aft of the stock axis."""
    pa, pb = _pos(rig, a), _pos(rig, b)
    if math.isnan(pa[0] + pb[0]):  # one is left out
        return StockPair(a, b, math.nan, math.nan)
    if abs(pa[2] - pb[2]) > ALIGN_TOL_M:
        raise RigError(f"{rig.source}: gages {a} and {b} must be at one {_height(rig)} "
                       f"({_ship(rig, pa)} vs {_ship(rig, pb)} m)")
    aft, fwd = (a, b) if pa[0] > pb[0] else (b, a)
    half = abs(pa[0] - pb[0]) / 2
    return StockPair(aft, fwd, pa[2], half)


def gage_geometry(rig: Rig) -> GageGeometry:
    """The report's distances for ``rig`` (metres), checked against its assumptions; NaN those
    of gages the rig leaves out."""
    p = {n: _pos(rig, n) for n in range(1, 17)}
    h, b = rig.rudder.stock_x_m, rig.rudder.attach_z_m
    along = "vertical" if rig.surface.is_rudder else "line along the stock"
    for n, axis in ((2, 0), (6, 0), (4, 2), (8, 2)):
        if abs(p[n][axis]) > ALIGN_TOL_M:
            line = along if axis == 0 else "chord line" if not rig.surface.is_rudder \
                else "horizontal"
            raise RigError(f"{rig.source}: gage {n} is off the {line} through the centre of mass "
                           f"({_ship(rig, p[n])}); Eq 1-3 assume it on it")
    if abs(p[13][0] - p[14][0]) > ALIGN_TOL_M:
        raise RigError(f"{rig.source}: gages 13 and 14 are not on one {along} "
                       f"({_ship(rig, p[13])}, {_ship(rig, p[14])})")
    return GageGeometry(
        x1=p[4][0], x2=-p[8][0], z1=p[2][2], z2=-p[6][2],
        x5=p[3][0] - h, x6=h - p[1][0],
        x7=stock_pair(rig, 7, 11).half_spacing_m, x10=stock_pair(rig, 10, 12).half_spacing_m,
        L_H=p[13][2], L_P=p[14][2] - p[13][2], Y_P=abs(p[16][1] - p[15][1]), h=h, b=b,
    )
