"""Argument checks and return shapes shared by the report's equations: every function takes floats
or numpy arrays (broadcast) and returns a float for scalar input, an array otherwise."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

Number = float | np.ndarray


def as_number(x: np.ndarray) -> Number:
    return float(x) if np.ndim(x) == 0 else x


_RULES = {
    "finite": (lambda a: np.ones_like(a, dtype=bool), "must be finite"),
    "positive": (lambda a: a > 0, "must be positive"),
    "nonnegative": (lambda a: a >= 0, "must not be negative"),
    "nonzero": (lambda a: a != 0, "must not be zero"),
}


_SCALAR_RULES = {  # the same tests on one Python float (no ufunc and reduction per check)
    "finite": lambda v: True,
    "positive": lambda v: v > 0,
    "nonnegative": lambda v: v >= 0,
    "nonzero": lambda v: v != 0,
}


def checked(name: str, value: ArrayLike, rule: str = "finite") -> np.ndarray:
    """``value`` as a float array; ValueError naming ``name`` if not finite or breaking ``rule``.
    A scalar is tested as a Python float (the same tests: a standard error's finite differences
    check ~400 scalars a hit, where numpy's per-call overhead was most of their cost)."""
    arr = np.asarray(value, dtype=float)
    test, why = _RULES[rule]
    if arr.ndim == 0:
        v = float(arr)
        if not math.isfinite(v):
            raise ValueError(f"{name} ({value!r}) must be finite")
        if not _SCALAR_RULES[rule](v):
            raise ValueError(f"{name} ({value!r}) {why}")
        return arr
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} ({value!r}) must be finite")
    if not np.all(test(arr)):
        raise ValueError(f"{name} ({value!r}) {why}")
    return arr


def finite(name: str, value: ArrayLike) -> np.ndarray:
    return checked(name, value, "finite")


def positive(name: str, value: ArrayLike) -> np.ndarray:
    return checked(name, value, "positive")
