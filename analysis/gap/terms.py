"""An effect switched on in the gap diagnosis's simulator: where it sits (:class:`Placement`) and
its parameter values (:class:`Term`). The core (:mod:`~ramdaq.analysis.gap.forward`,
:mod:`~ramdaq.analysis.gap.calibrate`) takes terms; the effects (:mod:`ramdaq.analysis.gap.effects`)
sit above it and make them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Placement:
    """One way an effect could sit in a trial.

    ``key`` names the discrete choice (JSON-able, e.g. ``{"gage": 5}``); ``names``/``units`` its
    continuous parameters; ``x0`` the effect switched off (or as good as), ``lo``/``hi`` bounds;
    ``probes`` (k, n_params) parameter values whose predictions span the effect's signature --
    the score test's projection on them gives the refit's start, ``x0 + sum c_k (probe_k - x0)``.
    ``starts`` (k, n_params) further refit starts to try where the effect's size is far from
    linear (an extra mode's stiffness spans decades). ``gages`` (report numbers),
    ``mode_hz`` and ``window`` say where the effect would show.
    """

    key: dict
    names: tuple[str, ...]
    units: tuple[str, ...]
    x0: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    probes: np.ndarray
    gages: tuple[int, ...] = ()
    mode_hz: float | None = None
    window: str = "all"
    starts: np.ndarray | None = None


@dataclass(frozen=True)
class Term:
    """An effect switched on: the effect, where it sits, and its parameter values."""

    effect: Effect  # noqa: F821 -- effects.base.Effect, not imported: the effects sit above the core
    placement: Placement
    x: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def with_x(self, x: np.ndarray) -> Term:
        return Term(self.effect, self.placement, np.asarray(x, dtype=float))

    def value(self, name: str) -> float:
        return float(self.x[self.placement.names.index(name)])

    def to_json(self) -> dict:
        p = self.placement
        return {"effect": self.effect.name, "where": p.key,
                "params": {n: {"value": float(v), "unit": u}
                           for n, v, u in zip(p.names, self.x, p.units, strict=True)}}


def placement(key: dict, names: tuple[str, ...], units: tuple[str, ...], x0, lo, hi, probes,
              **where) -> Placement:
    """A :class:`Placement` from plain lists."""
    a = lambda v: np.atleast_1d(np.asarray(v, dtype=float))  # noqa: E731
    if where.get("starts") is not None:
        where["starts"] = np.atleast_2d(np.asarray(where["starts"], float))
    return Placement(key, names, units, a(x0), a(lo), a(hi), np.atleast_2d(np.asarray(probes, float)),
                     **where)
