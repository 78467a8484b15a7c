"""Registry of candidate unmodelled effects, by name (as python-can's interfaces).

Every module of this package that defines a subclass of :class:`~ramdaq.analysis.gap.effects.base.Effect`
with a ``name`` registers it: adding an effect is writing one module, nothing else changes.
"""

from __future__ import annotations

import importlib
import pkgutil

from .base import Effect, Placement, Term

__all__ = ["Effect", "Placement", "Term", "EFFECTS", "get_effect"]


def _discover() -> dict[str, Effect]:
    found: dict[str, Effect] = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name):
        if info.name == "base":
            continue
        mod = importlib.import_module(f"{__name__}.{info.name}")
        for obj in vars(mod).values():
            own = isinstance(obj, type) and obj.__module__ == mod.__name__
            if own and issubclass(obj, Effect) and obj.name:
                if obj.name in found:
                    raise ValueError(f"gap effect name {obj.name!r} defined twice ({mod.__name__})")
                found[obj.name] = obj()
    return found


EFFECTS: dict[str, Effect] = _discover()


def get_effect(name: str) -> Effect:
    """The registered effect called ``name``; a one-line error lists the known ones."""
    try:
        return EFFECTS[name]
    except KeyError:
        raise KeyError(f"unknown gap effect {name!r}; known: {', '.join(sorted(EFFECTS))}") from None
