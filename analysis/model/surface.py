"""What the control surface is -- a rudder or a stern plane -- and the axes that make one the other.

Report 1836 writes its equations for a rudder and says they "apply equally well to stern planes"
(Appendix B). Here that is a rotation of axes, not a second chain. Everything downstream of the
rig file (the model, the simulator, the report's chain, the gap diagnosis) works in the
*surface frame* of the report's Figure 1: x aft along the chord, y normal to the surface, z along
the stock from the surface towards the hull, origin at the surface's centre of mass. Its motions
are v (along y), gamma (about z, the stock) and alpha (about x).

A rudder's surface frame is the ship's (x aft, y athwartship to starboard, z up). A stern plane's
stock is horizontal, athwartship; its rig file is written in ship axes and read into the surface
frame by a proper rotation (x stays x):

=============  =======================  =======================
stern plane    surface axis in ship     motion in ship axes
=============  =======================  =======================
starboard      x = x, y = z, z = -y     w = v,  beta = -gamma
port           x = x, y = -z, z = y     w = -v, beta = gamma
=============  =======================  =======================

so w (along ship z), beta (about ship y, the stock) and alpha (about x) are the report's stern-
plane motions (Table 2f). The surface's rigid body is the *movable* portion, the rigid section
that the hull modes move is the *fixed* portion (the fixed plane, attached to the hull).

:func:`to_surface_frame` rewrites a stern-plane rig document into the rudder-form document the
parser reads; :class:`Surface` carries the names a report uses for each motion and body.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np

KINDS = ("rudder", "stern_plane")
SIDES = ("starboard", "port")

_SHIP_FROM_SURFACE = {
    # columns: the surface frame's x, y, z axes written in ship axes
    "starboard": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
    "port": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
}

_STERN_BODIES = {"movable": "rudder", "stock": "stock", "fixed": "hull"}
"""A stern-plane rig's gage bodies and the model body each one is."""

_PLANE_KEYS = {"mass_kg": "mass_kg", "Iy_kg_m2": "Iz_kg_m2", "Ix_kg_m2": "Ix_kg_m2",
               "Ixy_kg_m2": "Ixz_kg_m2", "chord_m": "chord_m", "span_m": "span_m",
               "thickness_m": "thickness_m", "stock_x_m": "stock_x_m", "attach_m": "attach_z_m",
               "added_mass_factor": "added_mass_factor"}
"""``[plane]`` key -> the model's ``[rudder]`` key (Iy about the stock is the rudder's Iz)."""

_RUDDER_ONLY = {"Iz_kg_m2": "Iy_kg_m2 (about the stock)", "Ixz_kg_m2": "Ixy_kg_m2",
                "attach_z_m": "attach_m (along the stock)"}
"""A rudder's ``[rudder]`` keys that a ``[plane]`` names otherwise (read, they would collide)."""


class SurfaceError(ValueError):
    """A ``[surface]`` table or stern-plane key that cannot be read: ``field`` and ``why``."""

    def __init__(self, field: str, why: str) -> None:
        super().__init__(f"{field}: {why}")
        self.field = field
        self.why = why


@dataclass(frozen=True)
class Surface:
    """The control surface a rig describes: ``kind`` ("rudder" or "stern_plane") and, for a
    stern plane, the ``side`` of the hull it is on ("starboard" or "port")."""

    kind: str = "rudder"
    side: str = "starboard"

    @property
    def is_rudder(self) -> bool:
        return self.kind == "rudder"

    @property
    def title(self) -> str:
        """What it is, in words: "rudder" or "stern plane"."""
        return self.kind.replace("_", " ")

    @property
    def ship_from_surface(self) -> np.ndarray:
        """Rotation (3, 3): a surface-frame vector times it is the same vector in ship axes."""
        return np.eye(3) if self.is_rudder else _SHIP_FROM_SURFACE[self.side]

    def to_ship(self, vector: tuple[float, float, float]) -> tuple[float, float, float]:
        """A surface-frame position or direction (m or unit) in ship axes."""
        return tuple(float(c) for c in self.ship_from_surface @ np.asarray(vector, float))

    def to_surface(self, vector: tuple[float, float, float]) -> tuple[float, float, float]:
        """A ship-axes position or direction in the surface frame."""
        return tuple(float(c) for c in self.ship_from_surface.T @ np.asarray(vector, float))

    def ship_axis(self, axis: str) -> str:
        """A surface-frame axis name (``"y"``, ``"-z"``, ...) as the ship's axis name."""
        return _axis_name(self.to_ship(_axis_vector(axis)))

    def surface_axis(self, axis: str) -> str:
        """A ship axis name as the surface frame's axis name."""
        return _axis_name(self.to_surface(_axis_vector(axis)))

    @property
    def signs(self) -> dict[str, float]:
        """Sign of each model motion in the surface's own named motion (w = sign * v, ...)."""
        if self.is_rudder:
            return {"v": 1.0, "gamma": 1.0, "alpha": 1.0}
        R = self.ship_from_surface
        return {"v": float(R[2, 1]), "gamma": float(R[1, 2]), "alpha": 1.0}

    def label(self, name: str) -> str:
        """A model quantity's name as this surface calls it: for a stern plane ``v_2_6`` is
        ``w_2_6``, ``gamma_b`` is ``beta_b``, ``alpha1_over_gamma1`` is ``alpha1_over_beta1``,
        ``I_z_kg_m2`` (about the stock) ``I_y_kg_m2``, ``hull_motions`` ``fixed_portion_motions``;
        a rudder's names are the model's."""
        if self.is_rudder:
            return name
        for pattern, new in _STERN_LABELS:
            name = pattern.sub(new, name)
        return name

    def words(self, text: str) -> str:
        """A sentence of the analysis (a note) in this surface's words: for a stern plane the
        motions renamed as :meth:`label` does, "rudder" the movable plane, "hull" the fixed
        portion."""
        if self.is_rudder:
            return text
        for pattern, new in _STERN_LABELS[:-2] + _STERN_WORDS:
            text = pattern.sub(new, text)
        return text

    def relabel(self, obj: Any) -> Any:
        """``obj`` (dicts, lists, values) with every dict key renamed by :meth:`label`; the
        values are untouched but for ``alpha1_over_gamma1``, whose sign follows the renamed
        motion (alpha1/beta1 = sign * alpha1/gamma1)."""
        if self.is_rudder:
            return obj
        if isinstance(obj, dict):
            out = {}
            for k, v in obj.items():
                if k == "alpha1_over_gamma1" and isinstance(v, int | float):
                    v = self.signs["gamma"] * v
                out[self.label(k) if isinstance(k, str) else k] = self.relabel(v)
            return out
        if isinstance(obj, list | tuple):
            return [self.relabel(v) for v in obj]
        return obj

    def body(self, model_body: str) -> str:
        """A model body's name for this surface: a stern plane's rudder body is "movable", its
        hull section "fixed"."""
        if self.is_rudder:
            return model_body
        return {v: k for k, v in _STERN_BODIES.items()}[model_body]


_STERN_LABELS = (
    (re.compile(r"gamma"), "beta"),
    (re.compile(r"(?<![A-Za-z0-9])v(?![A-Za-z0-9])"), "w"),
    (re.compile(r"I(_?)xz"), r"I\1xy"),
    (re.compile(r"(?<![A-Za-z0-9])I(_?)z(?![A-Za-z0-9])"), r"I\1y"),
    (re.compile(r"rudder"), "movable"),
    (re.compile(r"hull"), "fixed_portion"),
)


_STERN_WORDS = (
    (re.compile(r"rudder-top"), "plane-root"),
    (re.compile(r"rudder"), "movable plane"),
    (re.compile(r"hull"), "fixed portion"),
)


def read_surface(doc: dict[str, Any]) -> Surface:
    """The ``[surface]`` table of a rig document (absent: a rudder)."""
    raw = doc.get("surface", {})
    if not isinstance(raw, dict):
        raise SurfaceError("surface", f"expected a table, got {raw!r}")
    for key in raw:
        if key not in ("kind", "side"):
            raise SurfaceError(f"surface.{key}", "unknown key (surface has kind and side)")
    kind = raw.get("kind", "rudder")
    if kind not in KINDS:
        raise SurfaceError("surface.kind", f"{kind!r} is not one of {', '.join(KINDS)}")
    side = raw.get("side", "starboard")
    if kind == "rudder" and "side" in raw:
        raise SurfaceError("surface.side", "only a stern plane has a side")
    if side not in SIDES:
        raise SurfaceError("surface.side", f"{side!r} is not one of {', '.join(SIDES)}")
    return Surface(kind, side)


def to_surface_frame(doc: dict[str, Any]) -> tuple[dict[str, Any], Surface, dict[str, str]]:
    """A rig document as the parser reads it: the ``surface`` table taken out and, for a stern
    plane, every ship-axes quantity turned into the surface frame (module docstring) and every
    stern-plane key renamed to the model's. Returns the new document (``doc`` is not changed),
    the surface, and the renames (model field -> file field) for error messages."""
    surface = read_surface(doc)
    out = {k: v for k, v in doc.items() if k != "surface"}
    if surface.is_rudder:
        return out, surface, {}
    if "rudder" in out:
        raise SurfaceError("rudder", "a stern plane's rig describes its plane in [plane], "
                           "not [rudder]")
    plane = out.pop("plane", None)
    if isinstance(plane, dict):
        for rudder_key, plane_key in _RUDDER_ONLY.items():
            if rudder_key in plane:
                raise SurfaceError(f"plane.{rudder_key}", f"a rudder's key; a stern plane's is "
                                   f"{plane_key}")
        out["rudder"] = {_PLANE_KEYS.get(k, k): v for k, v in plane.items()}
    if "impact" in out and isinstance(out["impact"], dict):
        out["impact"] = _turn_impact(out["impact"], surface)
    out["hull"] = _turn_hull(out.get("hull"), surface)
    if isinstance(out.get("gages"), list):
        out["gages"] = [_turn_gage(g, i, surface) for i, g in enumerate(out["gages"])]
    renames = {"rudder." + v: "plane." + k for k, v in _PLANE_KEYS.items()}
    renames |= {"rudder": "plane", ".v_b": ".w_b", ".gamma_b": ".beta_b"}
    return out, surface, renames


def plane_field(model_field: str) -> str:
    """A rig constant's dotted path as a stern plane's file names it (``rudder.Iz_kg_m2`` ->
    ``plane.Iy_kg_m2``); paths outside ``[rudder]`` are named alike in both files."""
    table, _, key = model_field.partition(".")
    if table != "rudder":
        return model_field
    back = {v: k for k, v in _PLANE_KEYS.items()}
    return f"plane.{back.get(key, key)}"


def _turn_vector(v: Any, surface: Surface) -> Any:
    ok = isinstance(v, list) and len(v) == 3 and all(
        isinstance(c, int | float) and not isinstance(c, bool) for c in v)
    return list(surface.to_surface(tuple(v))) if ok else v


_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0),
          "-x": (-1.0, 0.0, 0.0), "-y": (0.0, -1.0, 0.0), "-z": (0.0, 0.0, -1.0)}


def _axis_vector(name: str) -> tuple[float, float, float]:
    return _AXES[name]


def _axis_name(vec: tuple[float, float, float]) -> str:
    return next(k for k, a in _AXES.items() if np.allclose(a, vec))


def _turn_axis(name: Any, surface: Surface) -> Any:
    return surface.surface_axis(name) if isinstance(name, str) and name in _AXES else name


def _turn_impact(impact: dict[str, Any], surface: Surface) -> dict[str, Any]:
    out = dict(impact)
    if "location_m" in out:
        out["location_m"] = _turn_vector(out["location_m"], surface)
    out["direction"] = _turn_axis(out.get("direction", "z"), surface)
    return out


def _turn_hull(hull: Any, surface: Surface) -> Any:
    """Hull (fixed-portion) modes: w_b, beta_b, alpha_b in ship axes -> v_b, gamma_b, alpha_b."""
    if not isinstance(hull, dict) or not isinstance(hull.get("modes"), list):
        return hull
    sign = surface.signs
    modes = []
    for i, mode in enumerate(hull["modes"]):
        if not isinstance(mode, dict):
            modes.append(mode)
            continue
        for old in ("v_b", "gamma_b"):
            if old in mode:
                raise SurfaceError(f"hull.modes[{i}].{old}", "a stern plane's hull modes give "
                                   "w_b, beta_b and alpha_b")
        m = {k: v for k, v in mode.items() if k not in ("w_b", "beta_b")}
        for new, old, s in (("w_b", "v_b", sign["v"]), ("beta_b", "gamma_b", sign["gamma"])):
            if new in mode:
                val = mode[new]
                m[old] = s * val if isinstance(val, int | float) and not isinstance(val, bool) \
                    else val
        modes.append(m)
    return {**hull, "modes": modes}


def _turn_gage(gage: Any, i: int, surface: Surface) -> Any:
    if not isinstance(gage, dict):
        return gage
    g = dict(gage)
    if "body" in g:
        if g["body"] not in _STERN_BODIES:
            raise SurfaceError(f"gages[{i}].body", f"{g['body']!r} is not one of "
                               f"{', '.join(_STERN_BODIES)} (a stern plane's bodies)")
        g["body"] = _STERN_BODIES[g["body"]]
    if "position_m" in g:
        g["position_m"] = _turn_vector(g["position_m"], surface)
    if "axis" in g:
        g["axis"] = _turn_axis(g["axis"], surface)
    return g
