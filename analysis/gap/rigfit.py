"""A rig's uncertain constants calibrated to a trial's identified modes (frequencies, damping
ratios and mode shapes at the gages), and what no calibration explains: the model's form error.

The constants are fitted as log multipliers of the start rig's values, each within bounds
(:func:`fit_params`: defaults by kind, an optional ``[uncertainty]`` table in the rig file,
the user's own), by ``scipy.optimize.least_squares`` on the whitened differences of paired
modes (:func:`calibrate_to_modes`). The rudder's mass is not fitted: modes and shapes fix
masses and stiffnesses only up to one common factor (the ram's force, solved per impact,
absorbs it), so the mass is the scale the others are measured in.

Each difference is divided by the identification's standard error combined with a floor that
says how closely a model is expected to match at all (:data:`FORM_F`, :data:`FORM_ZETA`,
:data:`FORM_SHAPE`): at a ram blow's signal-to-noise the identification's errors are 1e-6 of a
frequency, and without the floors the fit would trade every shape for the last digit of one
frequency.

A few modes fix fewer numbers than there are constants: each constant is pulled towards its
start by a prior (:func:`prior_sd`, from its bounds), its posterior sd comes from the whitened
Jacobian (widened by the misfit left), and the constants the modes do not pin (:data:`PINNED`)
are held at their start, so a fit started from the right rig stays there.

When the fit leaves nothing beyond the floors it is polished with the identification's errors
alone as weights, so that a rig of the right form ends within the identification's uncertainty;
the polish is kept only within :data:`POLISH_SD` posterior sds (further, it fits biases).

Whatever the fit leaves beyond both is the model's form error (:class:`FormError`, judged by
:func:`significant`): per paired mode the frequency difference and 1 - MAC with the gages that
carry it, and identified modes the model has no mode for. :func:`model_level` is the gap
diagnosis's first step (``ramdaq gap``): the effect search then runs against the calibrated rig.
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.optimize
import scipy.stats

from ..model.response import ModalForm, modal_form
from ..model.rig import Rig, RigError
from ..model.structure import build_model
from ..model.surface import plane_field
from .calibrate import Stop
from .modal_level import (
    Coupled,
    ModalComparison,
    ModelModesAtGages,
    Split,
    TrialModes,
    compare,
    coupled_modes,
    model_modes_at_gages,
    modes_at_gages,
    splits,
    trial_modes,
)
from .model_sensitivity import matrix_derivatives, mode_derivatives
from .trialdata import TrialData

FORM_F = 1e-3
"""Relative frequency difference a model is held to at best (0.1 %: the report quotes its
frequencies to three or four figures, and a rig's form error -- a stock of one element, a
rigid rudder -- shows first at that level)."""
FORM_ZETA = 0.05
"""Relative damping-ratio difference held to at best (5 %: a free decay's decrement is read
to a few per cent across gages, Report 1836 Table 4)."""
FORM_SHAPE = 0.01
"""Difference held to at best per gage entry of a mode shape, relative to that entry (1 %: a
gage's sensitivity is calibrated to about 1 %). Relative, not of the shape's norm: a hull gage
that sees a rudder mode at a thousandth of the rudder's gages still sees it hundreds of times
above its noise, and the time-domain comparison holds every gage to its noise."""
PINNED = 0.5
"""A constant is pinned by the trial's modes when they take away at least this share of its
prior variance (posterior variance <= half the prior's: the data say more about it than the
bounds did). Constants the modes do not pin are held at their start value (a combination of
them the modes cannot see would otherwise wander within its bounds on the identification's
noise and biases)."""

PINNED_SD = 0.5
"""The largest posterior sd (of the log multiplier: 0.5 is +-50 %, a factor 1.65 at 1 sd) a
fitted constant may have and still be called *pinned* in the printed table. :data:`PINNED` alone
says the modes told more than the bounds did, which is why such a constant is fitted and not
held; with the default factor-2 bounds of masses, inertias and stiffnesses (prior sd ln 2 =
0.69) it already leaves at most 0.49, but with the factor-5 bounds of the damping constants
(prior sd 1.61) halving the variance still leaves sd 1.14, a factor 3 either way at 1 sd (the
SAMPSON water trial: c at +-108 % read "pinned"). Such a constant is fitted, as before, and
printed *loose* (:attr:`FittedParam.loose`): the word says how far its value can be trusted,
the rule of what is fitted is unchanged."""


POLISH_SD = 3.0
"""How far (posterior sds of the fit with the floors) the polish on the identification's own
standard errors may move a constant: further, it is fitting what the floors say a model is not
expected to match (3 impacts' spread understates a shape's error, and an identified shape's
phase leans on the damping constants); 3 sd is a 1-in-370 chance for a Gaussian."""


def prior_sd(p: FitParam) -> float:
    """The prior standard deviation of a constant's log multiplier: half the log width of its
    bounds (a +-25 % bound, [0.8, 1.25], is a 1-sigma prior of 0.22; the default factor 2 is
    0.69). Every constant is pulled towards its start by ``theta / prior_sd`` (Tikhonov: the
    fit moves a constant only as far as the modes ask, and not at all where they are silent)."""
    return max(0.5 * math.log(p.hi / p.lo), 1e-6)


FORM_FALSE_ALARM = 0.01
"""The chance that a model of the right form is reported with a form error: each difference
is judged against Student's t (the standard errors come from a few impacts' spread: n - 1
degrees of freedom) at this level shared over every frequency and gage entry compared."""


def significant(n_seen: int, n_tests: int) -> float:
    """The score beyond which one of ``n_tests`` differences, each with a standard error from
    ``n_seen`` impacts, is a form error (:data:`FORM_FALSE_ALARM`, two-sided, Bonferroni)."""
    return float(scipy.stats.t.isf(FORM_FALSE_ALARM / (2 * max(n_tests, 1)), max(n_seen - 1, 1)))


@dataclass(frozen=True)
class FitParam:
    """A fitted constant: ``name`` is its key in the rig file (``stock.I_m4``,
    ``hull.modes[0].frequency_hz``); ``start`` its start value (SI, the key's unit); ``lo``,
    ``hi`` the bounds as multipliers of ``start``."""

    name: str
    start: float
    lo: float
    hi: float


@dataclass(frozen=True)
class FittedParam:
    """A constant after the fit: its start and fitted value, its bounds (multipliers) and
    whether it ended at one of them (within 0.1 %); ``sd`` the posterior standard deviation of
    its log multiplier (the relative uncertainty of the fitted value, from the weighted
    Jacobian, the prior and the misfit left); ``pinned`` whether the trial's modes pin it
    (:data:`PINNED`): a constant they do not pin is held at its start value."""

    name: str
    start: float
    value: float
    lo: float
    hi: float
    sd: float = float("nan")
    pinned: bool = True

    @property
    def factor(self) -> float:
        return self.value / self.start

    @property
    def loose(self) -> bool:
        """Fitted (the modes take away at least :data:`PINNED` of its prior variance) but its
        posterior sd still beyond :data:`PINNED_SD`: moved by the modes, not pinned by them."""
        return self.pinned and math.isfinite(self.sd) and self.sd > PINNED_SD

    def pin_text(self) -> str:
        """The table's word for it: ``pinned``, ``loose`` (fitted, sd beyond :data:`PINNED_SD`)
        or ``NOT PINNED, held`` (at its start)."""
        return "NOT PINNED, held" if not self.pinned else "loose" if self.loose else "pinned"

    @property
    def at_bound(self) -> bool:
        return (abs(math.log(self.factor / self.lo)) < 1e-3
                or abs(math.log(self.factor / self.hi)) < 1e-3)


@dataclass(frozen=True)
class FormError:
    """What the fitted model still misses in one identified mode (``f_id_hz``): the frequency
    difference ``df_rel`` (model/identified - 1) and its score ``z_f`` against the combined
    standard error; ``one_minus_mac`` over all gages and per body (NaN where not defined);
    ``gages`` the gages carrying most of the shape difference, worst first (at most four, for
    the report's line); ``beyond`` every gage whose shape entry differs beyond chance, worst
    first (a shape the model gets wrong as a whole differs at every gage the mode moves);
    ``missing`` when the model has no mode for it at all."""

    f_id_hz: float
    df_rel: float
    z_f: float
    one_minus_mac: float
    one_minus_mac_rudder: float
    one_minus_mac_hull: float
    gages: tuple[int, ...]
    missing: bool = False
    beyond: tuple[int, ...] = ()

    def text(self) -> str:
        if self.missing:
            return (f"a mode at {self.f_id_hz:.2f} Hz the model lacks "
                    f"(gages {', '.join(map(str, self.gages))})")
        bodies = ", ".join(f"{b} {v:.3f}" for b, v in (("rudder", self.one_minus_mac_rudder),
                                                        ("hull", self.one_minus_mac_hull))
                           if np.isfinite(v))
        return (f"{self.f_id_hz:.2f} Hz: df {100 * self.df_rel:+.2f} %, 1-MAC {self.one_minus_mac:.3f}"
                + (f" ({bodies})" if bodies else "")
                + (f", gages {', '.join(map(str, self.gages))}" if self.gages else ""))


DAMPING_SE = 3.0
"""A damping ratio the fitted rig misses by more than this many combined standard errors (the
identification's, from the impacts' spread, and :data:`FORM_ZETA` of the ratio) is a damping
misfit: ~1 chance in 370 for a Gaussian error."""

DAMPING_MIN_MAC = 0.5
"""A pair whose shapes share less than this (MAC) is not used to fit or judge damping: the
damping ratio of a model mode that is not the identified one says nothing of the damping law
(a rig 100x too heavy paired a 43 Hz mode with one of MAC 0.01, and fitting its ratio pushed
the hull's damping to its bound at the cost of the one mode both had)."""

MASS_SCALE_LIMIT = 3.0
"""A rudder mass more than this factor from what the modes imply (either way) is named as a
likely unit or value error of the rig: the default bounds reach a factor 2 on the inertias and
2 on the stiffnesses, and a crude rig from drawings is seldom off by more than 2 in mass."""


@dataclass(frozen=True)
class DampingMisfit:
    """A paired mode whose damping ratio the fitted rig does not reach: ``zeta_id`` +-
    ``zeta_id_se`` identified, ``zeta_model`` the fitted rig's (the closest the rig's damping
    law gets within its bounds); ``at_bounds`` the damping constants that ended at a bound,
    ``held`` those held at their start (the ratios do not pin them within their bounds)."""

    f_id_hz: float
    zeta_id: float
    zeta_id_se: float
    zeta_model: float
    at_bounds: tuple[str, ...] = ()
    held: tuple[str, ...] = ()

    def text(self) -> str:
        why = "; ".join(([f"damping constants at their bounds: {', '.join(self.at_bounds)}"]
                         if self.at_bounds else [])
                        + ([f"held at their start: {', '.join(self.held)}"] if self.held else [])
                        ) or "beyond what the rig's damping law reaches"
        return (f"{self.f_id_hz:.2f} Hz: damping {100 * self.zeta_id:.2f} +- {100 * self.zeta_id_se:.2f} % "
                f"measured, {100 * self.zeta_model:.2f} % in the fitted rig ({why})")


@dataclass(frozen=True)
class MassScale:
    """The rudder's mass and inertias against what the identified rudder modes imply for the
    rig's stiffnesses: ``ratio`` = rig / implied (10: the rig's rudder is ten times heavier than
    its modes say, or its stock ten times too soft), from the modes ``modes_hz`` paired by
    shape alone (:func:`mass_scale`)."""

    ratio: float
    modes_hz: tuple[float, ...]
    rig_mass_kg: float = float("nan")
    """The rig file's rudder mass, kg (the implied one is ``rig_mass_kg / ratio``)."""

    @property
    def absurd(self) -> bool:
        """Beyond :data:`MASS_SCALE_LIMIT` either way."""
        return not 1 / MASS_SCALE_LIMIT <= self.ratio <= MASS_SCALE_LIMIT

    def check_lines(self) -> list[str]:
        """The one "CHECK THE RIG" line ``rig fit`` and ``gap`` print when :attr:`absurd`, else
        none."""
        return [f"CHECK THE RIG: {self.text()}"] if self.absurd else []

    def text(self) -> str:
        """The line's text (:meth:`check_lines`)."""
        r = f"{self.ratio:.0f}" if self.ratio >= 10 else f"{self.ratio:.2g}"
        kg = (f" ({self.rig_mass_kg:.0f} kg in the rig against ~{self.rig_mass_kg / self.ratio:.0f} kg)"
              if math.isfinite(self.rig_mass_kg) else "")
        return (f"rudder mass {r}x what the modes imply{kg}: check the rig's units/values "
                f"(rudder modes {', '.join(f'{f:.2f}' for f in self.modes_hz)} Hz against the rig's, paired "
                "by shape, the rudder's mass and inertias scaled together; modes weigh mass against "
                f"stiffness only, so it may be the stock's stiffnesses {1 / self.ratio:.2g}x)")


@dataclass(frozen=True)
class ModeFit:
    """The result of :func:`calibrate_to_modes`: the start and fitted rigs, the constants, how
    the solver ended (``stop``, with ``message`` and ``nfev``), the comparison before and after,
    the form errors left (empty: the fitted model matches every identified mode within the
    identification's uncertainty and the floors) and ``cost_before``/``cost_after`` (sum of
    squared whitened differences, priors excluded)."""

    start: Rig
    rig: Rig
    params: tuple[FittedParam, ...]
    stop: Stop
    message: str
    nfev: int
    before: ModalComparison
    after: ModalComparison
    form: tuple[FormError, ...]
    cost_before: float
    cost_after: float
    misfit_scale: float = 1.0
    """sqrt(chi2 / degrees of freedom) of the data left by the fit, when above 1: how much
    larger than the identification's standard errors the model-vs-data differences are (the
    posterior sds are widened by it; 3 impacts' spread understates a shape's error)."""
    damping: tuple[DampingMisfit, ...] = ()
    """The paired modes whose damping ratio the fitted rig still misses (:func:`damping_misfits`)."""
    scale: MassScale | None = None
    """The rudder's mass against what the modes imply for the rig's stiffnesses
    (:func:`mass_scale`; None when no rudder mode could be paired by shape)."""
    kept_start: bool = False
    """The fit lowered the misfit by less than chance, so the start rig was kept
    (:func:`_start_kept`; ``message`` says by how much)."""

    def held(self) -> list[FittedParam]:
        """The constants the trial's modes do not pin, held at their start value."""
        return [p for p in self.params if not p.pinned]

    def at_bounds(self) -> list[FittedParam]:
        return [p for p in self.params if p.at_bound]

    def form_text(self) -> str:
        """One line: the model's form error, or that none is left."""
        if not self.form and not self.damping:
            return "none beyond the identification's uncertainty"
        return "; ".join([f.text() for f in self.form] + [d.text() for d in self.damping])

    def outcome(self) -> str:
        """How the fit ended, in a word: ``bound-limited`` when it left constants at their
        bounds (the bounds set the result, not the modes), else the solver's stop
        (``converged``, ...)."""
        return "bound-limited" if self.at_bounds() else self.stop.value

    def solver_text(self) -> str:
        """How the solver ended, and the constants it left at their bounds: a fit that ends
        with any there is "bound-limited" and names them, never "converged"."""
        s = (self.message if self.kept_start else "converged" if self.stop is Stop.CONVERGED else
             f"{self.stop.value} after {self.nfev} evaluations ({self.message}): the constants are "
             "where it stopped, not a minimum shown to be one")
        b = self.at_bounds()
        if b:
            s = ("bound-limited: " + ", ".join(f"{p.name} x{p.factor:.3g}" for p in b)
                 + f" ended at {'its bound' if len(b) == 1 else 'their bounds'}, so the result is "
                 "where the bounds stopped it, not a fit of the modes (check the rig's values, or "
                 "widen the bounds with --bound)"
                 + ("" if self.stop is Stop.CONVERGED else f"; the solver: {s}"))
        h = self.held()
        if h:
            s += ("; held at their start, not pinned by these modes: "
                  + ", ".join(p.name for p in h))
        return s


# -- the constants and their bounds -------------------------------------------------------------
_HULL = re.compile(r"^hull\.modes\[(\d+)\]\.(\w+)$")


def _kinds(rig: Rig) -> list[tuple[str, tuple[float, float]]]:
    """Every constant the fit may move, with its default bounds (multipliers): masses,
    inertias and stiffnesses a factor 2 either way (a crude rig); damping a factor 5 (the least
    known); a hull mode's frequency a factor 1.5 (further, it would become another mode)."""
    wide, damp, hull_f = (0.5, 2.0), (0.2, 5.0), (1 / 1.5, 1.5)
    names = [("rudder.Iz_kg_m2", wide), ("rudder.Ix_kg_m2", wide), ("rudder.Ixz_kg_m2", wide),
             ("stock.I_m4", wide), ("stock.J_m4", wide)]
    if rig.medium == "water":
        names.append(("rudder.added_mass_factor", wide))
    m = rig.medium
    names += [(f"damping.{m}.C_N_s_per_m", damp), (f"damping.{m}.c_N_m_s_per_rad", damp),
              (f"damping.{m}.c_alpha_N_m_s_per_rad", damp)]
    for k in range(len(rig.hull_modes)):
        names += [(f"hull.modes[{k}].frequency_hz", hull_f), (f"hull.modes[{k}].modal_mass_kg", wide),
                  (f"hull.modes[{k}].damping_ratio", damp)]
    return names


def get_value(rig: Rig, name: str) -> float:
    """The value of the rig-file key ``name`` in ``rig``."""
    if (m := _HULL.match(name)) is not None:
        return float(getattr(rig.hull_modes[int(m[1])], m[2]))
    part = name.split(".")
    if part[0] == "damping":
        return float(getattr(rig.damping[part[1]], part[2]))
    return float(getattr(getattr(rig, part[0]), part[1]))


def set_value(rig: Rig, name: str, value: float) -> Rig:
    """``rig`` with the rig-file key ``name`` set to ``value``."""
    if (m := _HULL.match(name)) is not None:
        k = int(m[1])
        modes = list(rig.hull_modes)
        modes[k] = replace(modes[k], **{m[2]: value})
        return replace(rig, hull_modes=tuple(modes))
    part = name.split(".")
    if part[0] == "damping":
        d = replace(rig.damping[part[1]], **{part[2]: value})
        return replace(rig, damping={**rig.damping, part[1]: d})
    return replace(rig, **{part[0]: replace(getattr(rig, part[0]), **{part[1]: value})})


def fit_params(rig: Rig, bounds: dict[str, tuple[float, float]] | None = None) -> list[FitParam]:
    """The constants to fit and their bounds (multipliers of the start value): the defaults of
    each kind, then the rig file's optional ``[uncertainty]`` table (``"stock.I_m4" = [0.8,
    1.25]``), then ``bounds``. A constant bounded ``[1, 1]`` is held. Raises RigError naming a
    key that is not a fitted constant or bounds that do not hold the start value."""
    kinds = dict(_kinds(rig))
    given = {}
    doc = tomllib.loads(rig.text) if rig.text else {}
    for name, b in doc.get("uncertainty", {}).items():
        given[name] = (b, f"{rig.source}: uncertainty.{name}")
    for name, b in (bounds or {}).items():
        given[name] = (b, f"--bound {name}")
    for name, (b, where) in given.items():
        if name not in kinds:
            raise RigError(f"{where}: not a constant the fit can move (those are: "
                           f"{', '.join(kinds)})")
        ok = (isinstance(b, list | tuple) and len(b) == 2
              and all(isinstance(v, int | float) and math.isfinite(v) for v in b))
        if not ok or not 0 < b[0] <= 1 <= b[1]:
            raise RigError(f"{where}: bounds must be [lo, hi] multipliers with 0 < lo <= 1 <= hi, "
                           f"got {b!r}")
        kinds[name] = (float(b[0]), float(b[1]))
    out = []
    for name, (lo, hi) in kinds.items():
        v = get_value(rig, name)
        if hi > lo and v != 0:
            out.append(FitParam(name, v, lo, hi))
    return out


def apply(rig: Rig, params: list[FitParam], theta: np.ndarray) -> Rig:
    """``rig`` with each constant at ``start * exp(theta)``: what :func:`set_value` of each in
    turn gives, with one copy of each part changed and of the rig (the fit asks thousands of
    times, and a rig copied once per constant was a quarter of the model level's time)."""
    parts: dict[str, dict[str, float]] = {}
    hull: dict[int, dict[str, float]] = {}
    damping: dict[str, dict[str, float]] = {}
    for p, t in zip(params, theta, strict=True):
        v = p.start * math.exp(t)
        if (m := _HULL.match(p.name)) is not None:
            hull.setdefault(int(m[1]), {})[m[2]] = v
            continue
        part = p.name.split(".")
        if part[0] == "damping":
            damping.setdefault(part[1], {})[part[2]] = v
        else:
            parts.setdefault(part[0], {})[part[1]] = v
    new = {k: replace(getattr(rig, k), **kv) for k, kv in parts.items()}
    if hull:
        new["hull_modes"] = tuple(replace(h, **hull[k]) if k in hull else h
                                  for k, h in enumerate(rig.hull_modes))
    if damping:
        new["damping"] = {**rig.damping, **{k: replace(rig.damping[k], **kv) for k, kv in damping.items()}}
    return replace(rig, **new) if new else rig


# -- the fit -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Pairs:
    """The paired modes a fit compares: identified ``i_id`` with model ``i_model``, and each
    difference's combined standard error (relative for f and zeta; per gage for the shape;
    ``s_zeta`` NaN where the identified damping is too uncertain to fit)."""

    i_id: np.ndarray
    i_model: np.ndarray
    s_f: np.ndarray
    s_zeta: np.ndarray
    s_shape: np.ndarray


FLOORS = (FORM_F, FORM_ZETA, FORM_SHAPE)
NO_FLOORS = (1e-12, 1e-12, 1e-12)
"""The identification's own standard errors alone (a floor only against a zero)."""


def _pairs(tm: TrialModes, cmp: ModalComparison, floors: tuple[float, float, float] = FLOORS) -> _Pairs:
    i = np.array([p.i_id for p in cmp.pairs], int)
    m = np.array([p.i_model for p in cmp.pairs], int)
    s_f = np.hypot(tm.f_se_hz[i] / tm.f_hz[i], floors[0])
    z, z_se = tm.zeta[i], tm.zeta_se[i]
    s_z = np.where(z > 3 * z_se, np.hypot(z_se / np.where(z > 0, z, 1.0), floors[1]), np.nan)
    return _Pairs(i, m, s_f, s_z, np.maximum(np.hypot(tm.shape_se[:, i], floors[2] * np.abs(tm.shapes[:, i])),
                                             1e-12))


def _model_at(start: Rig, params: list[FitParam], theta: np.ndarray,
              memo: dict | None = None) -> tuple[Rig, ModalForm]:
    """The rig at ``theta`` and its model's modal form; ``memo`` keeps the last one made (the
    solver asks for the Jacobian where it has just asked for the residual)."""
    key = theta.tobytes()
    if memo is not None and memo.get("key") == key:
        return memo["rig"], memo["form"]
    rig = apply(start, params, theta)
    form = modal_form(build_model(rig))
    if memo is not None:
        memo.update(key=key, rig=rig, form=form)
    return rig, form


def _differences(tm: TrialModes, rig: Rig, pr: _Pairs, form: ModalForm | None = None,
                 model: ModelModesAtGages | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Whitened differences of the paired modes: frequency (n_pairs,), damping ratio
    (n_pairs,; 0 where not fitted) and shape (n_gages, n_pairs) complex, the model's shape
    scaled by the complex factor that matches it best to the identified one. ``form``:
    ``rig``'s modal form, when already made; ``model``: the modes themselves, when they are
    not ``rig``'s model's (an effect's update on it)."""
    mm = model if model is not None else model_modes_at_gages(rig) if form is None else modes_at_gages(form)
    if len(mm.f_hz) <= pr.i_model.max(initial=-1) or np.any(mm.f_hz[pr.i_model] <= 0):
        raise ValueError("the model lost a paired mode")
    f = np.log(mm.f_hz[pr.i_model] / tm.f_hz[pr.i_id]) / pr.s_f
    z = np.nan_to_num(np.log(mm.zeta[pr.i_model] / np.abs(tm.zeta[pr.i_id])) / pr.s_zeta)
    phi_m, phi = mm.shapes[:, pr.i_model], tm.shapes[:, pr.i_id]
    a = np.sum(np.conj(phi_m) * phi, axis=0) / np.sum(np.abs(phi_m) ** 2, axis=0)
    return f, z, (a * phi_m - phi) / pr.s_shape


def _data_residual(tm: TrialModes, start: Rig, params: list[FitParam], pr: _Pairs,
                   theta: np.ndarray, memo: dict | None = None) -> np.ndarray:
    rig, form = _model_at(start, params, theta, memo)
    f, z, d = _differences(tm, rig, pr, form)
    return np.concatenate([f, z, d.real.ravel(), d.imag.ravel()])


def _residual(tm: TrialModes, start: Rig, params: list[FitParam], pr: _Pairs,
              theta: np.ndarray, memo: dict | None = None) -> np.ndarray:
    return np.concatenate([_data_residual(tm, start, params, pr, theta, memo), theta * _pull(params)])


def _data_jacobian(tm: TrialModes, start: Rig, params: list[FitParam], pr: _Pairs,
                   theta: np.ndarray, memo: dict | None = None) -> np.ndarray:
    """The Jacobian of :func:`_data_residual` at ``theta`` (rows as the residual's, one column
    per constant), from the model's modal sensitivities (:mod:`.model_sensitivity`): one
    eigen-analysis instead of two per constant. The shape rows differentiate the best complex
    scale ``a`` too; a change of a model shape's scale moves nothing."""
    rig, form = _model_at(start, params, theta, memo)
    lam = form.eigenvalues[pr.i_model]
    dlam, dacc = mode_derivatives(form, *matrix_derivatives(rig, [p.name for p in params]))
    dlam = dlam[:, pr.i_model]                                      # (p, k)
    df = dlam.imag / lam.imag / pr.s_f
    dz = dlam.real / lam.real - (lam.conj() * dlam).real / np.abs(lam) ** 2
    dz = np.where(np.isfinite(pr.s_zeta), dz / np.where(np.isfinite(pr.s_zeta), pr.s_zeta, 1.0), 0.0)
    phi_m, phi = form.gage_acc[:, pr.i_model], tm.shapes[:, pr.i_id]
    dphi = dacc[:, :, pr.i_model]                                   # (p, n_g, k)
    norm = np.sum(np.abs(phi_m) ** 2, axis=0)
    c = np.sum(np.conj(phi_m) * phi, axis=0)
    da = (np.sum(np.conj(dphi) * phi, axis=1) / norm
          - c * 2 * np.sum(np.conj(phi_m) * dphi, axis=1).real / norm ** 2)
    dd = (da[:, None, :] * phi_m + (c / norm) * dphi) / pr.s_shape
    p = len(params)
    return np.concatenate([df, dz, dd.real.reshape(p, -1), dd.imag.reshape(p, -1)], axis=1).T


def _jacobian(tm: TrialModes, start: Rig, params: list[FitParam], pr: _Pairs,
              theta: np.ndarray, memo: dict | None = None) -> np.ndarray:
    """The Jacobian of :func:`_residual` (data rows, then the prior's diagonal). Where the
    model cannot be built or differentiated (the residual is :func:`_safe`'s constant there)
    its data rows are zero: no information, as differences of that constant gave."""
    try:
        jd = _data_jacobian(tm, start, params, pr, theta, memo)
    except (ValueError, np.linalg.LinAlgError):
        jd = np.zeros((2 * len(pr.i_id) + 2 * pr.s_shape.size, len(params)))
    return np.vstack([np.nan_to_num(jd), np.diag(_pull(params))])


def _pull(params: list[FitParam]) -> np.ndarray:
    """1 / :func:`prior_sd` of each constant."""
    return np.array([1 / prior_sd(p) for p in params])


def _posterior(tm: TrialModes, start: Rig, params: list[FitParam], pr: _Pairs,
               theta: np.ndarray) -> tuple[np.ndarray, float]:
    """The posterior sd of each constant's log multiplier at ``theta`` (linearised: the data
    Jacobian from the modal sensitivities (:func:`_data_jacobian`), each residual whitened by its
    standard error, the Gauss-Newton precision J'J / s2 plus the prior's), and s = sqrt(s2), the
    misfit scale: chi2 per degree of freedom of the data left, when above 1 (the standard errors
    were too small for what the data and model differ by; their covariance is widened by it)."""
    n = len(params)
    r0 = _data_residual(tm, start, params, pr, theta)
    try:
        jac = np.nan_to_num(_data_jacobian(tm, start, params, pr, theta))
    except (ValueError, np.linalg.LinAlgError):
        jac = np.zeros((len(r0), n))    # the model cannot be differentiated there: no information
    s2 = max(1.0, float(r0 @ r0) / max(len(r0) - n, 1))
    cov = np.linalg.pinv(jac.T @ jac / s2 + np.diag(_pull(params) ** 2))
    return np.sqrt(np.clip(np.diag(cov), 0.0, None)), math.sqrt(s2)


def _pinned(params: list[FitParam], sd: np.ndarray) -> np.ndarray:
    """Which constants the modes pin: posterior variance <= (1 - :data:`PINNED`) x prior's."""
    return sd ** 2 <= (1 - PINNED) * (1 / _pull(params)) ** 2


def calibrate_to_modes(tm: TrialModes, start: Rig, bounds: dict[str, tuple[float, float]] | None = None,
                       *, max_nfev: int = 400, passes: int = 3) -> ModeFit:
    """Fit ``start``'s constants to the identified modes ``tm`` (:func:`_calibrate`), then its
    damping constants to the identified damping ratios alone (:func:`_fit_damping`), and say
    how heavy its rudder is against what the modes imply (:func:`mass_scale`, on the start
    rig: the fit's bounds cannot reach a unit error). Raises ValueError when no identified
    mode pairs with a model mode (nothing to fit)."""
    mf = _calibrate(tm, start, bounds, max_nfev=max_nfev, passes=passes)
    params = fit_params(start, bounds)
    if params:
        mf = _fit_damping(tm, mf, params, 2 * float(np.max(tm.f_hz, initial=0.0)), max_nfev)
    return replace(mf, scale=mass_scale(tm, start))


def _calibrate(tm: TrialModes, start: Rig, bounds: dict[str, tuple[float, float]] | None = None,
               *, max_nfev: int = 400, passes: int = 3) -> ModeFit:
    """Fit ``start``'s constants (:func:`fit_params`, within their bounds, each pulled towards
    its start by :func:`prior_sd`) to the identified modes ``tm``. The modes are paired once
    (:func:`~ramdaq.analysis.gap.modal_level.compare`), fitted, and paired again with the fitted
    model; while the pairing changes the fit is repeated (at most ``passes`` times). The
    constants the modes do not pin (:data:`PINNED`, from the posterior at that fit) are then
    held at their start and the others fitted again. When no form error is left, the fit is
    polished with the identification's own standard errors as the only weights (the floors let
    it stop a hundred standard errors short), and the polish is kept if it leaves no form error
    either and moves no constant more than :data:`POLISH_SD` of its posterior sd. The posterior
    sds and which constants are pinned are those with the floors' weights.
    Raises ValueError when no identified mode pairs with a model mode (nothing to fit)."""
    params = fit_params(start, bounds)
    top = 2 * float(np.max(tm.f_hz, initial=0.0))
    before = compare(tm, start, top_hz=top)
    if not before.pairs:
        raise ValueError("no identified mode pairs with a mode of the rig's model: nothing to fit")
    if not params:
        return _result(tm, start, params, np.zeros(0), top, before, (Stop.NOTHING_TO_FIT,
                                                                      "no constant to fit", 0))
    theta, cmp, nfev = np.zeros(len(params)), before, 0
    for _ in range(passes):
        theta, how = _solve(tm, start, params, _pairs(tm, cmp), theta, max_nfev)
        nfev += how[2]
        new = compare(tm, apply(start, params, theta), top_hz=top)
        same = _same_pairs(new, cmp)
        cmp = new
        if same:
            break
    post = _posterior(tm, start, params, _pairs(tm, cmp), theta)
    keep = _pinned(params, post[0])
    if not keep.all():
        post = None                 # the others refitted: the posterior is the new fit's
        sub = [p for p, k in zip(params, keep, strict=True) if k]
        theta = np.zeros(len(params))
        if sub:
            theta[keep], how = _solve(tm, start, sub, _pairs(tm, cmp), np.zeros(len(sub)), max_nfev)
            nfev += how[2]
    out = _result(tm, start, params, theta, top, before, (how[0], how[1], nfev), keep, posterior=post)
    kept = _start_kept(tm, out, params, keep, top, nfev)
    if kept is not None:
        return kept
    if out.form or out.stop is not Stop.CONVERGED or not keep.any():
        return out
    fine = _pairs(tm, cmp, NO_FLOORS)
    sub = [p for p, k in zip(params, keep, strict=True) if k]
    theta2 = np.zeros(len(params))
    theta2[keep], how2 = _solve(tm, start, sub, fine, theta[keep], 3 * max_nfev)
    note = "" if how2[0] is Stop.CONVERGED else f" ({how2[0].value}, {how2[2]} evaluations, but lower)"
    polished = _result(tm, start, params, theta2, top, before,
                       (Stop.CONVERGED, f"{how[1]}; polished on the identification's errors{note}",
                        nfev + how2[2]), keep)
    better = _cost(tm, polished.rig, cmp, fine) < _cost(tm, out.rig, cmp, fine)
    sd = np.array([p.sd for p in out.params])
    within = bool(np.all(np.abs(theta2 - theta) <= POLISH_SD * np.nan_to_num(sd, nan=np.inf)))
    return polished if not polished.form and better and within else out


def _same_pairs(a: ModalComparison, b: ModalComparison) -> bool:
    """Whether two comparisons pair the same identified modes with the same model modes."""
    return [(p.i_id, p.i_model) for p in a.pairs] == [(p.i_id, p.i_model) for p in b.pairs]


FIT_GAIN_LEVEL = 0.05
"""The chance that a fit's gain over its start rig is noise (:func:`_start_kept`): the rig is
moved only where the modes ask for it beyond that chance."""


def _start_kept(tm: TrialModes, fit: ModeFit, params: list[FitParam], keep: np.ndarray,
                top: float, nfev: int) -> ModeFit | None:
    """The start rig, unmoved, when the fit ``fit`` (its constants ``keep`` fitted) pairs the
    same modes and lowers the misfit (``cost_before - cost_after``) by less than chance: the
    drop of a least-squares misfit when ``k`` constants that the data do not need are fitted
    is ``s^2 chi2(k)`` (``s^2``: the misfit per degree of freedom left, when above 1); at
    :data:`FIT_GAIN_LEVEL`. Else None. A rig that already describes the trial then stays as it
    is, instead of drifting along a direction the modes hardly see (the shipped ALBACORE
    trial fitted to its own generating rig moved masses and stiffnesses 10-16 % together and
    the 13 Hz mode's damping ratio 100 standard errors off, for a 3 % lower misfit)."""
    k = int(keep.sum())
    if k == 0 or not _same_pairs(fit.before, fit.after) or not np.isfinite(fit.cost_before):
        return None
    gain = fit.cost_before - fit.cost_after
    chance = fit.misfit_scale ** 2 * float(scipy.stats.chi2.isf(FIT_GAIN_LEVEL, k))
    if gain >= chance:
        return None
    msg = (f"kept the start rig: fitting {k} constants lowered the misfit by {max(gain, 0.0):.3g}, "
           f"less than chance ({chance:.3g}: chi-square, {k} constants, "
           f"{FIT_GAIN_LEVEL:.0%}, times the misfit scale squared)")
    return replace(_result(tm, fit.start, params, np.zeros(len(params)), top, fit.before,
                           (Stop.CONVERGED, msg, nfev), keep), kept_start=True)


def _solve(tm: TrialModes, start: Rig, params: list[FitParam], pr: _Pairs, theta: np.ndarray,
           max_nfev: int) -> tuple[np.ndarray, tuple[Stop, str, int]]:
    """One bounded least-squares run from ``theta``: the end point and (stop, message, nfev)."""
    lo = np.log([p.lo for p in params])
    hi = np.log([p.hi for p in params])
    memo: dict = {}         # the model at the last point: its Jacobian is asked for there next
    res = scipy.optimize.least_squares(lambda th: _safe(tm, start, params, pr, th, memo),
                                       np.clip(theta, lo, hi), bounds=(lo, hi), method="trf",
                                       jac=lambda th: _jacobian(tm, start, params, pr, th, memo),
                                       x_scale=0.1, max_nfev=max_nfev)
    stop = Stop.CONVERGED if res.status > 0 else Stop.ITERATION_LIMIT
    return res.x, (stop, str(res.message), int(res.nfev))


def _result(tm: TrialModes, start: Rig, params: list[FitParam], theta: np.ndarray, top: float,
            before: ModalComparison, how: tuple[Stop, str, int], pinned: np.ndarray | None = None,
            weights: _Pairs | None = None,
            posterior: tuple[np.ndarray, float] | None = None) -> ModeFit:
    """The fit at ``theta`` (held constants at 0), each constant's posterior sd with the
    ``weights`` it was fitted with (default: the floors) and whether it was ``pinned``.
    ``posterior``: :func:`_posterior` at this ``theta`` with the floors and this fit's pairs,
    when already computed (the pinning test's, when nothing was held)."""
    rig = apply(start, params, theta)
    after = compare(tm, rig, top_hz=top)
    pinned = np.ones(len(params), bool) if pinned is None else pinned
    sd, scale = np.full(len(params), np.nan), 1.0
    if params and after.pairs:
        sd, scale = (posterior if posterior is not None and weights is None
                     else _posterior(tm, start, params, weights or _pairs(tm, after), theta))
    fitted = tuple(FittedParam(p.name, p.start, get_value(rig, p.name), p.lo, p.hi, float(d), bool(k))
                   for p, d, k in zip(params, sd, pinned, strict=True))
    return ModeFit(start=start, rig=rig, params=fitted, stop=how[0], message=how[1], nfev=how[2],
                   before=before, after=after, form=form_errors(tm, rig, after),
                   cost_before=_cost(tm, start, before), cost_after=_cost(tm, rig, after),
                   misfit_scale=scale)


def _safe(tm: TrialModes, start: Rig, params: list[FitParam], pr: _Pairs, theta: np.ndarray,
          memo: dict | None = None) -> np.ndarray:
    """:func:`_residual`, or a large constant where the model cannot be built (an inertia
    matrix no longer positive definite, an overdamped mode): the solver backs off."""
    n = 2 * len(pr.i_id) + 2 * pr.s_shape.size + len(theta)
    try:
        r = _residual(tm, start, params, pr, theta, memo)
    except (ValueError, np.linalg.LinAlgError):
        return np.full(n, 1e4)
    return np.where(np.isfinite(r), r, 1e4)


def _cost(tm: TrialModes, rig: Rig, cmp: ModalComparison, pr: _Pairs | None = None) -> float:
    """Sum of squared whitened differences of ``cmp``'s pairs (by default with the floors)."""
    if not cmp.pairs:
        return float("nan")
    f, z, d = _differences(tm, rig, pr or _pairs(tm, cmp))
    return float(f @ f + z @ z + np.sum(np.abs(d) ** 2))


def form_errors(tm: TrialModes, rig: Rig, cmp: ModalComparison) -> tuple[FormError, ...]:
    """The differences of ``cmp``'s pairs beyond :func:`significant` combined standard errors
    (frequency, or a gage's shape entry), and the identified modes left unpaired."""
    out = []
    if cmp.pairs:
        pr = _pairs(tm, cmp)
        f, _, d = _differences(tm, rig, pr, model=cmp.model)
        n_tests = d.size + len(f)
        for k, p in enumerate(cmp.pairs):
            limit = significant(int(tm.n_seen[p.i_id]), n_tests)
            zg = np.abs(d[:, k])
            beyond = [i for i in np.argsort(-zg) if zg[i] > limit]
            if abs(f[k]) <= limit and not beyond:
                continue
            out.append(FormError(f_id_hz=p.f_id_hz, df_rel=p.df_rel, z_f=float(f[k]),
                                 one_minus_mac=1 - p.mac, one_minus_mac_rudder=1 - p.mac_rudder,
                                 one_minus_mac_hull=1 - p.mac_hull,
                                 gages=tuple(tm.gage_numbers[i] for i in beyond[:4]),
                                 beyond=tuple(tm.gage_numbers[i] for i in beyond)))
    for i in cmp.unpaired_id:
        big = np.argsort(-np.abs(tm.shapes[:, i]))[:3]
        out.append(FormError(f_id_hz=float(tm.f_hz[i]), df_rel=float("nan"), z_f=float("nan"),
                             one_minus_mac=float("nan"), one_minus_mac_rudder=float("nan"),
                             one_minus_mac_hull=float("nan"),
                             gages=tuple(tm.gage_numbers[g] for g in big), missing=True))
    return tuple(sorted(out, key=lambda e: e.f_id_hz))


# -- a rig's mass scale, and the damping left ------------------------------------------------------
def mass_scale(tm: TrialModes, rig: Rig, *, min_mac: float = 0.8, min_share: float = 0.5) -> MassScale | None:
    """How heavy ``rig``'s rudder is against what ``tm``'s rudder modes imply for its
    stiffnesses. The rig's model without its hull modes (a hull mode has its own frequency,
    which no rudder mass moves) is paired with the identified modes that carry at least
    ``min_share`` of their shape on the rudder's gages, by the MAC over the rudder's gages
    alone (at least ``min_mac``; a mass scale moves frequencies far more than shapes). Then the
    factor ``s`` on the rudder's own mass and inertias (not the water's added mass, which a
    wrong unit in the rig file does not touch) that brings each paired model mode to its
    identified frequency is found; ``ratio`` is ``1 / s`` of their median (one mode the rig
    models badly -- a crude rig's torsion -- does not decide it). None when the rig has no
    structure or no mode pairs, and when the paired modes say no one scale: a mode no factor
    within 1e-4..1e4 brings to its frequency (in water the rudder's own mass is a small part of
    what moves, so a mode the added mass holds needs no rudder mass at all), or factors that
    differ by more than :data:`MASS_SCALE_LIMIT` between modes -- a wrong mass or unit moves every
    mode by one factor, a wrong stiffness moves them by different ones (new user: a stock 24 %
    too soft in water read "rudder mass 43x what the modes imply", the 13 Hz mode's factor at
    the search's bound, the 59.8 Hz mode's 0.55)."""
    if rig.rudder is None or rig.stock is None:
        return None
    rows = np.array([g.body == "rudder" for g in rig.gages_by_channel()])
    if rows.sum() < 2:
        return None
    bare = replace(rig, hull_modes=())
    try:
        mm = model_modes_at_gages(bare)
    except (ValueError, np.linalg.LinAlgError):
        return None
    a, b = tm.shapes[rows], mm.shapes[rows]
    share = np.sum(np.abs(a) ** 2, axis=0) / np.maximum(np.sum(np.abs(tm.shapes) ** 2, axis=0), 1e-300)
    na, nb = np.sum(np.abs(a) ** 2, axis=0), np.sum(np.abs(b) ** 2, axis=0)
    m = np.abs(a.conj().T @ b) ** 2 / np.maximum(np.outer(na, nb), 1e-300)
    m[share < min_share] = 0.0
    m[:, ~(mm.f_hz > 0)] = 0.0
    rows_i, cols = scipy.optimize.linear_sum_assignment(-m)
    use = [(i, c) for i, c in zip(rows_i, cols, strict=True) if m[i, c] >= min_mac]
    if not use:
        return None
    i_id, i_m = np.array([u[0] for u in use]), np.array([u[1] for u in use])
    r = rig.rudder

    def miss(log_s: float, i: int, c: int) -> float:
        k = math.exp(log_s)
        scaled = replace(bare, rudder=replace(r, mass_kg=r.mass_kg * k, Iz_kg_m2=r.Iz_kg_m2 * k,
                                              Ix_kg_m2=r.Ix_kg_m2 * k, Ixz_kg_m2=r.Ixz_kg_m2 * k))
        try:
            f = model_modes_at_gages(scaled).f_hz
        except (ValueError, np.linalg.LinAlgError):
            return 1e6
        if len(f) <= c or f[c] <= 0:
            return 1e6
        return float(np.log(f[c] / tm.f_hz[i]) ** 2)

    edge = math.log(1e4)
    each = np.array([scipy.optimize.minimize_scalar(miss, bounds=(-edge, edge), args=(i, c),
                                                    method="bounded", options={"xatol": 1e-3}).x
                     for i, c in zip(i_id, i_m, strict=True)])
    reached = np.abs(each) < edge - 0.01  # a factor at the search's edge reaches no frequency
    if not reached.any() or np.ptp(each[reached]) > math.log(MASS_SCALE_LIMIT):
        return None
    return MassScale(ratio=float(math.exp(-np.median(each[reached]))),
                     modes_hz=tuple(sorted(float(tm.f_hz[i]) for i in i_id[reached])),
                     rig_mass_kg=r.mass_kg)


def _is_damping(name: str) -> bool:
    """A constant of the rig's damping law: the rudder's viscous dampers or a hull mode's ratio."""
    return name.startswith("damping.") or name.endswith(".damping_ratio")


def damping_misfits(mf: ModeFit) -> tuple[DampingMisfit, ...]:
    """The paired modes of ``mf.after`` (shapes alike, :data:`DAMPING_MIN_MAC`) whose fitted
    damping ratio differs from the identified one by more than :data:`DAMPING_SE` combined
    standard errors (the identification's and
    :data:`FORM_ZETA` of the ratio). The fit has already taken the damping constants as close
    as their bounds let it (:func:`_fit_damping`): what is left, the law cannot reach."""
    bound = tuple(p.name for p in mf.params if _is_damping(p.name) and p.at_bound)
    held = tuple(p.name for p in mf.params if _is_damping(p.name) and not p.pinned)
    out = []
    for p in mf.after.pairs:
        if not (math.isfinite(p.zeta_id) and math.isfinite(p.zeta_model)) or not p.mac >= DAMPING_MIN_MAC:
            continue
        se = math.hypot(p.zeta_id_se if math.isfinite(p.zeta_id_se) else 0.0, FORM_ZETA * abs(p.zeta_id))
        if abs(p.zeta_model - p.zeta_id) > DAMPING_SE * se:
            out.append(DampingMisfit(p.f_id_hz, p.zeta_id, p.zeta_id_se, p.zeta_model, bound, held))
    return tuple(out)


def _fit_damping(tm: TrialModes, mf: ModeFit, params: list[FitParam], top: float,
                 max_nfev: int) -> ModeFit:
    """``mf`` with its damping constants (:func:`_is_damping`) fitted again to the identified
    damping ratios alone (of the pairs whose shapes are alike, :data:`DAMPING_MIN_MAC`), every
    other constant at its fitted value. Fitted with the frequencies
    and shapes, they are judged against the shapes' misfit too (widened by it, issue 17: a crude
    rig left every damping constant "not pinned" and its modes at 0.27-2.13 % against 1.0-3.0 %
    measured); the ratios pin them by themselves. Pinned as :data:`PINNED`, on this fit's own
    posterior; the others are held at their start. Then :func:`damping_misfits`. Only when the
    first fit misses some ratio (:func:`damping_misfits`): a fit that meets them all, polished
    on the identification's own errors, is not moved by this one's coarser weights."""
    idx = [k for k, p in enumerate(params) if _is_damping(p.name)]
    if not idx or not mf.after.pairs or not damping_misfits(mf):
        return replace(mf, damping=damping_misfits(mf))
    pr = _pairs(tm, mf.after)
    alike = np.array([p.mac >= DAMPING_MIN_MAC for p in mf.after.pairs])
    pz = replace(pr, s_f=np.full_like(pr.s_f, np.inf), s_shape=np.full_like(pr.s_shape, np.inf),
                 s_zeta=np.where(alike, pr.s_zeta, np.nan))
    if not np.isfinite(pz.s_zeta).any():
        return replace(mf, damping=damping_misfits(mf))
    sub = [params[k] for k in idx]
    theta = np.array([math.log(p.factor) for p in mf.params])
    th, how = _solve(tm, mf.rig, sub, pz, theta[idx], max_nfev)
    sd = _damping_sd(tm, mf.rig, sub, pz, th)
    keep = _pinned(sub, sd)
    th = np.where(keep, th, 0.0)
    if keep.any() and not keep.all():
        th[keep], how = _solve(tm, mf.rig, [p for p, k in zip(sub, keep, strict=True) if k], pz,
                               th[keep], max_nfev)
    theta[idx] = th
    pinned = np.array([p.pinned for p in mf.params])
    pinned[idx] = keep
    stop, msg = (mf.stop, mf.message) if how[0] is Stop.CONVERGED else (
        how[0], f"damping constants: {how[1]}")
    out = _result(tm, mf.start, params, theta, top, mf.before, (stop, msg, mf.nfev + how[2]), pinned)
    fitted = list(out.params)
    for j, k in enumerate(idx):
        fitted[k] = replace(fitted[k], sd=float(sd[j]))
    out = replace(out, params=tuple(fitted))
    return replace(out, damping=damping_misfits(out))


def _damping_sd(tm: TrialModes, rig: Rig, sub: list[FitParam], pz: _Pairs, theta: np.ndarray) -> np.ndarray:
    """The posterior sd of the damping constants' log multipliers from the damping ratios
    alone (as :func:`_posterior`, but not widened by the misfit left: each ratio's standard
    error already holds :data:`FORM_ZETA`, and a law held short of the ratios by its bounds
    would otherwise read as not informed by them, and be held at its start instead of at
    the bound the ratios push it to)."""
    k = len(pz.i_id)
    use = np.isfinite(pz.s_zeta)
    try:
        jac = np.nan_to_num(_data_jacobian(tm, rig, sub, pz, theta))[k:2 * k][use]
    except (ValueError, np.linalg.LinAlgError):
        jac = np.zeros((int(use.sum()), len(sub)))
    cov = np.linalg.pinv(jac.T @ jac + np.diag(_pull(sub) ** 2))
    return np.sqrt(np.clip(np.diag(cov), 0.0, None))


# -- the fitted rig file ---------------------------------------------------------------------------
_TABLE = re.compile(r"^\s*(\[\[?)\s*([\w.]+)\s*\]\]?")


def fitted_rig_text(mf: ModeFit, trial: str, date: str) -> str:
    """The start rig's text with each fitted constant's value replaced (its line keeps its
    place, the old value in a comment), and a header saying what was fitted, from which trial
    ``trial`` and when (``date``). The result parses to the fitted values. Raises RigError
    when a constant's table is not in the text as a ``[table]`` header (an inline table)."""
    lines = mf.start.text.splitlines()
    plane = not mf.start.surface.is_rudder  # a stern plane's file names [rudder] [plane]
    for p in mf.params:
        lines = _set_line(lines, p, mf.start.source, plane_field(p.name) if plane else p.name)
    ids = ", ".join(f"{q.f_id_hz:.3f}" for q in mf.after.pairs)
    head = [f"# Fitted by `ramdaq rig fit` on {date} from {trial} ({mf.after.trial.n_impacts} impacts; "
            f"modes {ids} Hz), starting from {mf.start.source} (medium {mf.start.medium}).",
            "# Fitted constants (x start value): " + ", ".join(
                f"{p.name} x{p.factor:.4g}" for p in mf.params) + ".",
            f"# Solver: {mf.solver_text()}.",
            f"# Model form left: {mf.form_text()}.",
            "# The rudder's mass is the scale of the others (modes fix masses and stiffnesses only "
            "up to a common factor).", ""]
    text = "\n".join(head + lines) + "\n"
    _check_written(text, mf)
    return text


def _set_line(lines: list[str], p: FittedParam, source: str, field: str) -> list[str]:
    """``lines`` with ``p``'s key, named ``field`` in the file, set to its fitted value in its
    table (added after the table's header when the key was left at its default)."""
    if (m := _HULL.match(field)) is not None:
        table, index, key = "hull.modes", int(m[1]), m[2]
    else:
        table, _, key = field.rpartition(".")
        index = 0
    seen, inside, header = -1, False, None
    for n, line in enumerate(lines):
        t = _TABLE.match(line)
        if t:
            if inside:
                break
            if t[2] == table:
                seen += 1
                inside = seen == index
                header = n if inside else header
            continue
        if inside and re.match(rf"^\s*{re.escape(key)}\s*=", line):
            out = list(lines)
            out[n] = _value_line(line[: line.index("=")].rstrip(), p)
            return out
    if header is None:
        raise RigError(f"{source}: {field}: no [{table}] table header for it in the text "
                       "(an inline table?); the fitted rig cannot be written in its place")
    out = list(lines)
    out.insert(header + 1, _value_line(key, p))
    return out


def _value_line(key: str, p: FittedParam) -> str:
    return (f"{key} = {p.value:.9g}    # fitted: x{p.factor:.4g} of {p.start:.6g}"
            + (" (at its bound)" if p.at_bound else ""))


def _check_written(text: str, mf: ModeFit) -> None:
    from ..model.rig import parse_rig
    back = parse_rig(text, source=mf.start.source)
    for p in mf.params:
        v = get_value(back, p.name)
        if not math.isclose(v, p.value, rel_tol=1e-8):
            raise RigError(f"{mf.start.source}: {p.name}: written as {v}, fitted {p.value}")


# -- the gap diagnosis's first step --------------------------------------------------------------
@dataclass(frozen=True)
class ModelLevel:
    """The model level of a diagnosis: the trial's modes (None when they could not be
    identified), the rig calibrated to them (None when nothing could be fitted) and ``note``,
    why not, when either is missing."""

    modes: TrialModes | None
    fit: ModeFit | None
    note: str = ""
    updates: Mapping[str, tuple[FormError, ...]] = field(default_factory=dict)
    """The form errors left with each structural candidate's update on the model, by the
    candidate's name (:func:`with_updates`): what that effect leaves unexplained."""

    def statement(self, named: str | None = None) -> str:
        """``model form: ...`` -- what the fitted rig still misses, or why it was not fitted;
        with the ``named`` effect's update on it when one was made (:attr:`updates`): what
        that effect leaves of the form error."""
        if self.fit is None:
            return f"model form: not assessed ({self.note})"
        if named in self.updates:
            left = ("; ".join(e.text() for e in self.updates[named])
                    or "none beyond the identification's uncertainty")
            return f"model form with {named}'s update on the rig: {left}"
        s = f"model form: {self.fit.form_text()}"
        if self.fit.stop is not Stop.CONVERGED or self.fit.at_bounds():
            s += f" (calibration to the modes {self.fit.solver_text()})"
        return s

    def form_gages(self) -> set[int]:
        """The gages where the fitted rig still misses the shape or frequency of a mode it has
        (empty: none). A mode the model lacks altogether is not counted: an extra mode or a
        steady tone is what the effect search's structural and excitation effects add."""
        return set() if self.fit is None else gages_of(self.fit.form)

    def form_modes(self) -> list[tuple[float, list[int]]]:
        """Each identified mode the fitted rig has but still misses (its shape or frequency): its
        frequency (Hz) and every gage where its shape differs beyond chance (all of them, not
        only the worst four :meth:`form_gages` reads; none when only its frequency misses).
        Empty when nothing was fitted or no form error is left."""
        return [] if self.fit is None else modes_of(self.fit.form)

    def form_left(self, model: ModelModesAtGages) -> tuple[FormError, ...] | None:
        """The form errors left when the trial's identified modes are held against ``model``
        instead of the calibrated rig's own modes: the calibrated rig with a structural
        effect's update on it (the effect search's refitted modes, as the gages see them,
        :func:`~ramdaq.analysis.gap.modal_level.modes_of_set`). Issue 17: a structural effect is
        a model update that must explain the modal differences calibration left; what it
        explains is no longer the rig's form. None when nothing was fitted."""
        if self.fit is None or self.modes is None:
            return None
        top = 2 * float(np.max(self.modes.f_hz, initial=0.0))
        cmp = compare(self.modes, self.fit.rig, top_hz=top, model=model)
        return form_errors(self.modes, self.fit.rig, cmp)

    def form_with_update(self, update: Callable[[Rig], Rig]) -> tuple[FormError, ...] | None:
        """The form errors left when a structural effect's update is carried into the model
        and its constants are calibrated to the trial's modes again, from the rig given (the
        perturbed start), within the same bounds: issue 17's "structural effects are model
        updates that must explain the modal differences that remain". ``update`` maps the
        calibrated rig to the rig with the effect (an effect's ``rig`` hook with its fitted
        term); the modes it adds (a tiller, a hull structure's own mode) join the start rig with
        their own frequency, modal mass and damping free, each within its kind's bounds. None
        when nothing was fitted, the update adds no mode (it changes no constant the start rig
        can carry), or the calibration with it fails."""
        if self.fit is None or self.modes is None:
            return None
        rig = self.fit.rig
        new = update(rig)
        n0 = len(rig.hull_modes)
        if len(new.hull_modes) <= n0 or new.hull_modes[:n0] != rig.hull_modes:
            return None
        start = replace(self.fit.start, hull_modes=self.fit.start.hull_modes + new.hull_modes[n0:])
        bounds = {p.name: (p.lo, p.hi) for p in self.fit.params}
        try:
            return calibrate_to_modes(self.modes, start, bounds).form
        except (ValueError, np.linalg.LinAlgError, RigError):
            return None

    def splits(self) -> list[Split]:
        """Identified modes of one shape where the calibrated rig has one mode
        (:func:`~ramdaq.analysis.gap.modal_level.splits`): a split no constant makes."""
        if self.fit is None or self.modes is None:
            return []
        return splits(self.modes, self.fit.after, self.fit.rig)

    def coupled(self) -> list[Coupled]:
        """Identified hull modes the rudder does not ride rigidly, which the calibrated rig lacks
        (:func:`~ramdaq.analysis.gap.modal_level.coupled_modes`): hull coupling."""
        if self.fit is None or self.modes is None:
            return []
        return coupled_modes(self.modes, self.fit.rig, self.fit.after)

    def candidate_form(self, name: str) -> dict:
        """What the answer reads of a candidate: ``{"form_gages": [...], "form_modes": [...]}``,
        the form left with its update (:attr:`updates`), or {} when none was made for it."""
        if name not in self.updates:
            return {}
        form = self.updates[name]
        return {"form_gages": sorted(gages_of(form)), "form_modes": modes_of(form)}

    def to_json(self) -> dict:
        skipped = [] if self.modes is None else list(self.modes.skipped)
        if self.fit is None:
            return {"fitted": False, "note": self.note, "identification_failed": skipped,
                    "modes_hz": [] if self.modes is None else np.round(self.modes.f_hz, 4).tolist()}
        f = self.fit
        return {
            "fitted": True, "identification_failed": skipped, "statement": self.statement(),
            "stop": f.stop.value, "message": f.message, "outcome": f.outcome(),
            "constants": {p.name: {"start": p.start, "value": p.value, "factor": round(p.factor, 5),
                                   "bounds": [p.lo, p.hi], "at_bound": p.at_bound,
                                   "sd_rel": p.sd if math.isfinite(p.sd) else None,
                                   "pinned": p.pinned, "loose": p.loose} for p in f.params},
            "modes": [{"f_id_hz": p.f_id_hz, "f_id_se_hz": p.f_id_se_hz, "f_start_hz": b.f_model_hz,
                       "f_fitted_hz": p.f_model_hz, "zeta_id": p.zeta_id, "zeta_fitted": p.zeta_model,
                       "mac_start": b.mac, "mac_fitted": p.mac}
                      for p, b in _matched(f.after, f.before)],
            "form_errors": [_form_json(e) for e in f.form],
            "damping_misfits": [{"f_id_hz": m.f_id_hz, "zeta_id": m.zeta_id, "zeta_id_se": m.zeta_id_se,
                                 "zeta_fitted": m.zeta_model, "at_bounds": list(m.at_bounds),
                                 "held": list(m.held)} for m in f.damping],
            "mass_scale": None if f.scale is None else {
                "ratio": f.scale.ratio, "modes_hz": list(f.scale.modes_hz), "absurd": f.scale.absurd},
            "form_left_with": {name: [_form_json(e) for e in form] for name, form in self.updates.items()},
            "splits": [s.to_json() for s in self.splits()],
            "coupled": [c.to_json() for c in self.coupled()],
        }


def _form_json(e: FormError) -> dict:
    return {"f_id_hz": e.f_id_hz, "df_rel": e.df_rel, "one_minus_mac": e.one_minus_mac,
            "gages": list(e.gages), "beyond_gages": list(e.beyond), "missing_in_model": e.missing}


def gages_of(form: tuple[FormError, ...]) -> set[int]:
    """The gages carrying the shape differences of the modes a model has but misses
    (:meth:`ModelLevel.form_gages` of any form errors)."""
    return {g for e in form if not e.missing for g in e.gages}


def modes_of(form: tuple[FormError, ...]) -> list[tuple[float, list[int]]]:
    """Each mode a model has but misses: its frequency (Hz) and every gage beyond chance
    (:meth:`ModelLevel.form_modes` of any form errors)."""
    return [(e.f_id_hz, list(e.beyond)) for e in form if not e.missing]


def _matched(after: ModalComparison, before: ModalComparison) -> list:
    b = {p.i_id: p for p in before.pairs}
    return [(p, b[p.i_id]) for p in after.pairs if p.i_id in b]


def with_updates(level: ModelLevel, updates: Mapping[str, Callable[[Rig], Rig]]) -> ModelLevel:
    """``level`` with the form left by each named update (:meth:`ModelLevel.form_with_update`;
    those it cannot make are left out)."""
    done = {name: form for name, up in updates.items()
            if (form := level.form_with_update(up)) is not None}
    return replace(level, updates={**level.updates, **done})


def model_level(td: TrialData, bounds: dict[str, tuple[float, float]] | None = None) -> ModelLevel:
    """Identify ``td``'s modes and calibrate its rig to them. Never raises on what the data or
    the rig may be (no decay, no mode recurring, no mode pairing, a model that cannot be
    built): says why instead."""
    try:
        tm = trial_modes(td)
    except (ValueError, np.linalg.LinAlgError) as err:
        return ModelLevel(None, None, f"modes not identified: {err}")
    if tm.n_modes == 0:
        return ModelLevel(tm, None, "no mode recurs across the impacts")
    try:
        return ModelLevel(tm, calibrate_to_modes(tm, td.rig, bounds))
    except (ValueError, np.linalg.LinAlgError) as err:
        return ModelLevel(tm, None, str(err))
