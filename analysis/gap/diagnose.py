"""The sim-to-real gap diagnosis of one trial: where the calibrated model misses, which
unmodelled effect causes it, and how far adding that effect closes the gap on held-out impacts.

Steps (:func:`diagnose`):

1. **Calibrate** the nominal model's constants on the fitted impacts (every third impact is
   held out) -- :mod:`ramdaq.analysis.gap.calibrate`; when the rig was first calibrated to the
   trial's identified modes (``Settings.reference_modes``), a time-history calibration that
   moves the model's modes away from them is not kept (:func:`_kept`).
2. **Where**: the gap map (gage x band x window) of the calibrated model, standardised by
   repeated simulations of that model with the trial's own noise and a model-form tolerance --
   :mod:`ramdaq.analysis.gap.evidence`. From then on every fit weighs each gage x window by what it
   tells beyond that tolerance (a rudder gage's small mode-shape error is thousands of noise
   variances and would otherwise steer every refit); the constants are refitted so weighed.
   The same replicates standardise the gap read in physical terms -- frequency, decrement,
   amplitude, envelope, mode shape, rigid-body consistency per gage x mode x window, and the
   lines before the blows (:mod:`ramdaq.analysis.gap.features`), for the model before and after the
   named effect: the report's reading, not the verdict's.
3. **Which**: every registered effect's signature score (score test, best placement, charged
   for the placements tried); the ``top_k`` strongest are refitted with the base constants free,
   and the two strongest together; each is charged for its extra parameters by the Bayesian
   information criterion, its chi-square gain deflated map cell by map cell by the replicates'
   own excess there (``dBIC = -sum_cells dE / kappa_cell + k ln N + 2 ln n_placements``).
   The candidate to be named is credited only beyond what re-calibration earns by itself
   (:func:`_credited`): not named when its size sits at its null, nor when the base refitted
   without any effect from its constants closes as much (the calibration was not at its
   optimum: a better base is adopted when it keeps the identified modes).
4. **How far**: the gap (energy beyond the noise expectation, summed over the map cells that
   both the fitted and the held-out impacts show) before and after, on the fitted and on the
   held-out impacts, with a bootstrap interval over gages.

The verdict is "no gap beyond noise" unless a map cell of the fitted impacts reaches ``z_gap``
where the held-out impacts' map also stands out (:func:`detection_score`); "explained" when a
candidate beats the calibrated model by ``bic_min`` (:func:`choose`); otherwise "unexplained".
Localisation comes from the data: the gages, band and window whose map cells shrink most when
the effect is added.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace

import numpy as np

from .calibrate import Calibration, ModeRef, Stop, calibrate, departs_from_modes, prefit_frequencies
from .datamodel import CERTAIN
from .effects import EFFECTS
from .evidence import (
    Bands,
    GapMap,
    NoiseModel,
    ScoreBasis,
    Signature,
    bands_for,
    cell_chi2,
    cell_energies,
    cell_inflation,
    form_weights,
    gap_map,
    noise_model,
    replicate_residuals,
    signature_scores,
    window_inflation,
)
from .features import FeatureMap, feature_map
from .forward import Forward
from .layers import Answer, Precedence, blows_tail, model_gages, precedence, strength, unconfirmed
from .rigfit import ModelLevel
from .sensors import DataChecks
from .terms import Placement, Term
from .trialdata import TrialData
from .verdict import (
    CLOSURE_TIE,
    choose,
    closed_share,
    closure,
    detection_score,
    gap_where,
    location,
    where_text,
)


@dataclass(frozen=True)
class Settings:
    """Thresholds of the verdict, tuned on the development seeds of the benchmark (never on
    its own seeds): ``form_tol`` the relative error of the model's mode amplitudes at the gages
    accepted as its form -- a model is never exact, and at a ram blow's signal-to-noise of
    10^4-10^5 a 0.1 % error in a mode shape is hundreds of noise rms; the replicate simulations
    carry it, so the map and every score are judged against it (the fit itself weights by the
    noise alone); ``z_gap`` the map cell score beyond which a gap is called real; ``bic_min``
    how much better (in BIC) a candidate must be; ``top_k`` candidates refitted, and up to
    ``top_k_more`` more (in signature order) while no single one closes ``close_enough`` of the
    gap -- a score test ranks effects by how strongly the residual carries their template, not
    by whether their refit explains it, and a flexible term's template (a split's) picks up part
    of any residual; ``z_pair`` the
    score a second effect needs on what the best single one leaves; ``n_rep`` replicate
    simulations for the noise floor; ``min_closure`` the least fraction of the gap an effect must
    close to be named (see :func:`choose`)."""

    z_gap: float = 8.0
    form_tol: float = 0.02
    bic_min: float = 10.0
    top_k: int = 3
    top_k_more: int = 2
    close_enough: float = 0.8
    z_pair: float = 5.0
    min_closure: float = 0.0
    n_rep: int = 24
    refit_iter: int = 40
    effects: tuple[str, ...] | None = None
    seed: int = 0
    reference_modes: tuple[ModeRef, ...] = ()
    """The trial's identified modes when the rig was calibrated to them first (the model level):
    a time-history calibration that moves the model's modes away from them is not kept
    (:func:`~ramdaq.analysis.gap.calibrate.departs_from_modes`). Empty: no such check."""


@dataclass(frozen=True)
class Candidate:
    """An explanation: one effect or two, refitted, with what it does to the gap: its evidence
    ``dbic`` against the calibrated model, the gap (energy beyond the noise expectation, in
    noise variances) left on the fitted and held-out impacts, the share of the calibrated
    model's gap it closes there (with a 95 % bootstrap interval on the held-out share), where it
    acts (:func:`~ramdaq.analysis.gap.verdict.location`), its maps and modes. The named one is
    measured against the noise floor of its own residual (:func:`_against_its_own_noise`)."""

    terms: list[Term]
    cal: Calibration
    dbic: float
    gap_fit: float
    gap_held: float
    closed_fit: float
    closed_held: float
    closed_held_ci: tuple[float, float]
    location: dict
    map_fit: GapMap | None = None
    map_held: GapMap | None = None
    modes_after: list[dict] = field(default_factory=list)
    dbic_marginal: float | None = None
    """For a pair: what the second term adds to the first alone, in BIC."""
    null: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """What re-calibration alone earns, which this candidate is credited only beyond: the dBIC,
    held-out and fitted closure of the best base refitted without any effect from a candidate's
    constants (:func:`_credited`); zeros until measured."""
    no_credit: str | None = None
    """Why this candidate is not credited (its size at its null, or the same refit without it
    closes as much), or None."""
    cal_forward: Forward | None = field(default=None, repr=False)
    reps: np.ndarray | None = field(default=None, repr=False)
    """The replicates of this candidate's model (set for the named one only): what its
    :attr:`features` are read against."""

    @functools.cached_property
    def features(self) -> FeatureMap | None:
        """The named explanation's discrepancies in physical terms, read when first asked for
        (the report asks; the benchmark, which scores none of it, does not)."""
        if self.reps is None or self.map_fit is None:
            return None
        return feature_map(self.cal_forward, self.cal, self.reps, self.map_fit.bands)

    @property
    def name(self) -> str:
        return "+".join(t.effect.name for t in self.terms)

    def record(self) -> dict:
        """What :func:`choose` decides on: the evidence and closures beyond what re-calibration
        alone earns (:attr:`null`), and no evidence at all when not credited (:attr:`no_credit`)."""
        d0, h0, f0 = self.null
        dbic = 0.0 if self.no_credit else self.dbic - d0
        return {"name": self.name, "dbic": dbic, "dbic_marginal": self.dbic_marginal,
                "closed_held": _beyond(self.closed_held, h0), "closed_fit": _beyond(self.closed_fit, f0)}

    def to_json(self) -> dict:
        return {"effect": self.name, "terms": [t.to_json() for t in self.terms],
                "dbic": round(self.dbic, 2),
                "dbic_marginal": None if self.dbic_marginal is None else round(self.dbic_marginal, 2),
                "gap_fitted": round(self.gap_fit, 2),
                "gap_held_out": round(self.gap_held, 2),
                "closed_fitted": round(self.closed_fit, 3), "closed_held_out": round(self.closed_held, 3),
                "closed_held_out_ci95": [round(v, 3) for v in self.closed_held_ci],
                "location": self.location, "modes": self.modes_after,
                "features": self.features.to_json() if self.features else None}


@dataclass
class Diagnosis:
    """Everything the report shows. ``verdict`` one of "no gap beyond noise", "explained",
    "unexplained"; ``best`` the named candidate (None unless explained)."""

    verdict: str
    best: Candidate | None
    candidates: list[Candidate]
    signatures: list[Signature]
    base: Calibration
    map_fit: GapMap
    map_held: GapMap | None
    gap_fit: float
    gap_held: float
    modes_before: list[dict]
    forward: Forward
    seconds: float
    notes: list[str] = field(default_factory=list)
    z_detect: float = float("nan")
    """:func:`detection_score` of the calibrated model's maps, compared with ``z_gap``."""
    reps: np.ndarray | None = field(default=None, repr=False)
    """The calibrated model's replicate residuals (n_rep, n_seg, n_g, n_s), m/s^2."""
    features_seconds: float = 0.0
    """What reading :attr:`features` cost, s (0 until it is read)."""
    data: DataChecks | None = None
    """The data-only layer's checks of the same trial (:mod:`ramdaq.analysis.gap.sensors`), when
    they were run: reported before the model's ranking, and a sensor finding there takes
    precedence over the model's attribution of the same gages (:attr:`precedence`)."""

    @property
    def precedence(self) -> list[Precedence]:
        """The model's attributions set aside for a data-only sensor finding on the same gages."""
        if self.data is None or self.best is None:
            return []
        loc = self.best.location
        gages = model_gages(loc.get("effect_gages", []), loc.get("gages", []), self.best.name)
        return precedence(self.data.findings, self.best.name, gages)

    @property
    def unconfirmed(self) -> list[str]:
        """The data-only checks that looked for the named effect and found nothing."""
        if self.data is None or self.best is None:
            return []
        return unconfirmed(self.data.findings, self.data.looked, self.best.name)

    model_level: ModelLevel | None = None
    """The rig calibrated to the trial's identified modes before this diagnosis, and the
    model's form error it left (:func:`~ramdaq.analysis.gap.rigfit.model_level`); None when
    the diagnosis started from the rig as given."""

    map_first: GapMap | None = None
    """The calibrated model's map of the trial's first segment alone: its pre window is before
    any blow (:func:`~ramdaq.analysis.gap.verdict.before_blows`)."""

    answer: Answer | None = None
    """The one report's answer of both layers (:func:`~ramdaq.analysis.gap.layers.answer`), the
    same the benchmark scores: set by ``ramdaq gap`` once the model level and the data-only
    checks have run; None for the effect search alone."""

    def model_choice(self) -> str | None:
        """The model layer's own choice: the named effect, "unexplained", or None (no gap)."""
        return self.best.name if self.best else ("unexplained" if self.verdict == "unexplained" else None)

    @property
    def headline(self) -> str:
        """The verdict in one line, from :attr:`answer` when set: "no effect" (the model's form
        when it leaves a gap), "unexplained: where ...", "explained" (the model's named effect)
        or the data-only layer's finding that answered; with a model level, the model's form
        error beside it ("no effect; model form: ...")."""
        a = self.answer
        form = f"; {self.model_level.statement(a and a.named)}" if self.model_level is not None else ""
        if a is None:
            w = self.unexplained_where
            return (self.verdict if w is None else f"unexplained: {where_text(w)}") + form
        if a.named == "none":
            head = ("no effect" if self.verdict == "no gap beyond noise"
                    else "no effect named, the gap is the rig model's form")
            if blows_tail(w := self.unexplained_where):
                head += (f" (the blows' ringing in the next pre window, band {w['band']}, gages "
                         f"{', '.join(map(str, w['gages']))}, none before the first blow: the rig's decay)")
        elif a.named == "unexplained":
            head = f"unexplained: {where_text(a.location)}" if a.location else "unexplained"
            if a.by == "data" and a.finding:     # what the data-only check found, how big
                head += f" -- {a.finding.get('text', '')} ({_beyond_chance(a.finding)})"
        elif a.by == "data":
            f = a.finding or {}
            also = [g for g in (a.location or {}).get("gages", []) if g not in f.get("gages", [])]
            head = (f"explained by the data-only layer: {a.named} ({f.get('text', '')}; "
                    f"{_beyond_chance(f)}"
                    + (f"; found on gage{'s' if len(also) > 1 else ''} {', '.join(map(str, also))} "
                       "too" if also else "") + ")")
        elif self.best is None or a.named != self.best.name:
            head = f"explained by the model level: {a.named} ({where_text(a.location)})"
        else:
            head = self.verdict
        return head + form

    @property
    def unexplained_where(self) -> dict | None:
        """Where the gap no library effect closes lies and how big (:func:`gap_where`); None
        unless the verdict is "unexplained"."""
        if self.verdict != "unexplained":
            return None
        n_fit = int(np.sum(self.forward.td.fitted))
        return gap_where(self.map_fit, self.map_held, self.map_first, n_fit)

    @functools.cached_property
    def features(self) -> FeatureMap | None:
        """Where the calibrated model misses, in physical terms (:mod:`ramdaq.analysis.gap.features`),
        and with the named effect (``best.features``): the report's reading, computed when
        first asked for; the verdict rests on the energy maps and does not use it."""
        if self.reps is None:
            return None
        t0 = time.perf_counter()
        fm = feature_map(self.forward, self.base, self.reps, self.map_fit.bands)
        if self.best is not None:
            _ = self.best.features
        self.features_seconds = time.perf_counter() - t0
        return fm

    def to_json(self) -> dict:
        fw = self.forward
        return {
            "verdict": self.verdict,
            "headline": self.headline,
            "answer": self.answer.to_json() if self.answer else None,
            "model_level": self.model_level.to_json() if self.model_level else None,
            "detection_z": round(self.z_detect, 2) if np.isfinite(self.z_detect) else None,
            "effect": self.best.name if self.best else None,
            "unexplained": self.unexplained_where,
            "best": self.best.to_json() if self.best else None,
            "gap": {"fitted": round(self.gap_fit, 2), "held_out": round(self.gap_held, 2),
                    "unit": "residual energy beyond the noise expectation, in noise variances"},
            "impacts": {"onsets_s": np.round(fw.td.onsets_s, 4).tolist(),
                        "fitted": fw.td.fitted.tolist()},
            "calibration": {p.name: {"multiplier": round(math.exp(t), 4), "unit": p.unit}
                            for p, t in zip(fw.params, self.base.theta, strict=True)},
            "modes": self.modes_before,
            "map_fitted": self.map_fit.to_json(),
            "map_held_out": self.map_held.to_json() if self.map_held else None,
            "features": self.features.to_json() if self.features else None,
            "data_only": self.data.to_json() if self.data else None,
            "precedence": [p.to_json() for p in self.precedence],
            "unconfirmed_by_data_only": self.unconfirmed,
            "ranking": [c.to_json() for c in self.candidates],
            "signatures": [{"effect": s.effect.name, "z": round(s.z, 2) if np.isfinite(s.z) else None,
                            "where": s.placement.key if s.placement else None,
                            "placements": s.n_placements} for s in self.signatures],
            "noise_sigma_m_s2": np.round(fw.sigma, 6).tolist(),
            "decimated_rate_hz": fw.td.fs_hz,
            "band": {"lowpass_hz": round(fw.td.lowpass_hz, 2), "unit": "Hz",
                     "rig_lowpass_hz": round(fw.td.rig_lowpass_hz, 2),
                     "ringing_above": [r.to_json() for r in fw.td.ringing_above]},
            "seconds": round(self.seconds, 2),
            "notes": self.notes,
        }


def _beyond(closed: float, null: float) -> float:
    """The share of what a null refit leaves (it closed ``null``) that a candidate closing
    ``closed`` of the same gap closes."""
    if not np.isfinite(null) or not np.isfinite(closed) or not 0 < null < 1:
        return closed
    return 1 - (1 - closed) / (1 - null)


def modes_of(cal: Calibration, top_hz: float) -> list[dict]:
    """Frequency and decrement of the compared modes of a calibrated model."""
    lam = cal.fit.modes.lam
    out = []
    for v in lam:
        f = v.imag / (2 * math.pi)
        if 0 < f < top_hz:
            out.append({"f_hz": round(float(f), 4), "delta": round(float(-2 * math.pi * v.real / v.imag), 5)})
    return out


def _start(fw: Forward, base: Calibration, sig: Signature, others: list[Term] = (),
           theta_pre: np.ndarray | None = None, n_short: int = 4) -> tuple[Term, np.ndarray]:
    """The refit's start for one effect, and the base constants to start with: the best of the
    score test's estimate, the probes, the placement's own starts and the effect switched off
    (a linearised estimate can overshoot far into nonsense).

    For a term that changes the structure (``theta_pre`` given), each start is judged with the
    constants re-tuned to the data's spectrum peaks with it on: the nominal tuning with the
    term on rings a fraction of a percent off, which at these signal-to-noise ratios hides what
    the term does. Where the placement has starts of its own (a stiffness spanning decades),
    ``n_short`` starts -- the best half, then the best of each other starting frequency in turn
    (4: with 8 the 12 truth-family tiller and 12 hull-coupling trials of the check and benchmark
    seeds named the same first effect -- one second effect moved, benchmark seed 501001's
    +gage_sensitivity to +gage_alignment -- at 0.12 s a brief refit) --
    are each refitted briefly with every constant free (the calibration may have hidden the
    effect in constants far from where the re-tuning leaves them: a blow's duration, a damping),
    and the best of those is the start. A brief refit takes six steps on the calibration's
    Jacobian with the term's columns differenced, Broyden-updated, never differenced afresh
    (``refresh=False``: a fresh Jacobian of every constant costs more predictions than the six
    steps, and the refit only ranks the starts; the chosen start's refit converges in full)."""
    pl = sig.placement
    retune = theta_pre is not None and sig.effect.retunes()
    tried = _tried_starts(fw, base, sig, others, theta_pre if retune else None)
    if not tried:
        return Term(sig.effect, pl, pl.x0), base.theta
    if not retune or pl.starts is None:
        return tried[0][1], tried[0][2]
    best = None
    for _, t, th in _shortlist(tried, n_short):
        try:
            cal = calibrate(fw, [*others, t], theta0=th, max_iter=6, jac0=base.jacobian(),
                            refresh=False)
        except (ValueError, np.linalg.LinAlgError):
            continue
        if best is None or cal.cost < best.cost:
            best = cal
    if best is None:
        return tried[0][1], tried[0][2]
    return best.terms[-1], best.theta


def _tried_starts(fw: Forward, base: Calibration, sig: Signature, others: list[Term],
                  theta_pre: np.ndarray | None) -> list[tuple[float, Term, np.ndarray]]:
    """Each start of :func:`_start` as (chi-square of the fitted impacts, term, base constants),
    best first; with ``theta_pre`` the constants re-tuned to the spectrum peaks with the term on,
    else the calibrated ones. Starts whose prediction fails are left out."""
    pl = sig.placement
    fitted = np.flatnonzero(fw.td.fitted)
    starts = [sig.x0, *pl.probes, pl.x0, *(pl.starts if pl.starts is not None else [])]
    tried: list[tuple[float, Term, np.ndarray]] = []
    for x in starts:
        t = Term(sig.effect, pl, np.clip(x, pl.lo, pl.hi))
        try:
            th = (prefit_frequencies(fw, theta_pre, [*others, t], max_nfev=24) if theta_pre is not None
                  else base.theta)
            r = fw.whitened(fw.fit(th, list(others) + [t]), fitted)
        except (ValueError, np.linalg.LinAlgError):
            continue
        tried.append((float(r @ r), t, th))
    tried.sort(key=lambda c: c[0])
    return tried


def _shortlist(tried: list[tuple[float, Term, np.ndarray]],
               n_short: int) -> list[tuple[float, Term, np.ndarray]]:
    """The best ``n_short // 2`` starts, then the best of each other starting frequency until
    there are ``n_short``: a re-tuned start's residual says little about the basin it lies in
    (a mode parked below the band re-tunes as well as one at the truth)."""
    short = tried[:n_short // 2]
    freqs = {round(float(c[1].x[0]), 6) for c in short}
    for c in tried:
        f0 = round(float(c[1].x[0]), 6)
        if len(short) < n_short and f0 not in freqs:
            freqs.add(f0)
            short.append(c)
    return short


N_REREAD = 3
"""At most this many times a single effect's placement is read again after its refit (while
each refit improves on the last): see :meth:`~ramdaq.analysis.gap.effects.base.Effect.placement_after`."""


def _carry(t: Term, pl: Placement) -> np.ndarray:
    """Start values on a re-read placement ``pl``: what it read anew (its start differs from the
    old placement's) from it, the rest (the effect's size) as the term was fitted."""
    old = dict(zip(t.placement.names, zip(t.placement.x0, t.x, strict=True), strict=True))
    x = [old[n][1] if n in old and np.isclose(old[n][0], x0) else x0
         for n, x0 in zip(pl.names, pl.x0, strict=True)]
    return np.clip(np.array(x, float), pl.lo, pl.hi)


def _by_z(sigs: Iterable[Signature]) -> list[Signature]:
    """Signatures strongest first (NaN scores last)."""
    return sorted(sigs, key=lambda s: -s.z if not np.isnan(s.z) else np.inf)


@dataclass
class _Replicates:
    """How the calibrated model's replicate residuals were made (86 MB at 20 impacts), to make
    them again, the same to the last bit, when they are next read: the search need not hold
    them while it refits. ``cal`` the calibration they simulate (its Jacobian let go), ``W``
    the forward model's weights they were made under."""

    fw: Forward
    cal: Calibration
    noise: NoiseModel
    W: np.ndarray
    settings: Settings

    def make(self) -> np.ndarray:
        """The replicates, (n_rep, n_seg, n_g, n_s) m/s^2 (one simulation of each)."""
        st, w_now = self.settings, self.fw.W
        self.fw.set_weights(self.W)
        try:
            return replicate_residuals(self.fw, self.cal, self.noise, st.n_rep, seed=st.seed,
                                       form_tol=st.form_tol)
        finally:
            self.fw.set_weights(w_now)


@dataclass
class _Search:
    """What the search for an explanation shares once the model is calibrated: the weighted
    forward model, the settings, the spectrum prefit's constants ``theta_pre``, the calibrated
    ``base``, its replicate residuals (None while let go; ``replicates`` makes them again) and
    their cell energies (``rep_cells``) and inflation
    (``kappa_cells``) on ``bands``, the calibrated model's maps of the fitted and held-out
    impacts, the effective number of data ``n_eff`` (BIC's ln N), the bootstrap's generator, and
    where progress and notes go."""

    fw: Forward
    settings: Settings
    theta_pre: np.ndarray
    base: Calibration
    reps: np.ndarray | None
    replicates: _Replicates
    bands: Bands
    rep_cells: np.ndarray
    kappa_cells: np.ndarray
    m_fit: GapMap
    m_held: GapMap | None
    n_eff: int
    rng: np.random.Generator
    say: Callable[[str], None]
    notes: list[str]

    def held_reps(self) -> np.ndarray:
        """The replicates, made again if they were let go, and held from then on."""
        if self.reps is None:
            self.reps = self.replicates.make()
        return self.reps

    @property
    def td(self) -> TrialData:
        return self.fw.td

    def chi2(self, cal: Calibration, keep: np.ndarray | None = None) -> float:
        """The fitted impacts' chi-square of ``cal``, cell by cell deflated by the replicates'
        own excess there; only the samples ``keep`` where given."""
        resid = cal.fit.resid if keep is None else np.where(keep, cal.fit.resid, np.nan)
        return cell_chi2(self.fw, resid, self.bands, self.td.fitted, self.kappa_cells)

    def maps(self, resid: np.ndarray, rep_cells: np.ndarray) -> tuple[GapMap, GapMap | None]:
        """The gap maps of ``resid`` on the fitted and (None if there are none) held-out impacts,
        against replicates whose cell energies are ``rep_cells``."""
        held = ~self.td.fitted
        return (gap_map(self.fw, resid, rep_cells, self.bands, self.td.fitted),
                gap_map(self.fw, resid, rep_cells, self.bands, held) if held.any() else None)


KEEP_REPLICATES_BYTES = 32 << 20
"""Replicates of the calibrated model this small (27 MB at 6 impacts, 24 replicates) are kept
through the search rather than let go and made again (a second simulation of all of them);
larger ones (86 MB at 20 impacts) are let go while the singles refit, as the memory target
asks."""


def diagnose(td: TrialData, settings: Settings = Settings(),
             progress: Callable[[str], None] | None = None) -> Diagnosis:
    """Diagnose one trial (see the module docstring)."""
    t_start = time.perf_counter()
    say = progress or (lambda s: None)
    fw, theta_pre, base, reps, bands, rep_cells, made = _calibrated(td, settings, say)
    held = ~td.fitted
    m_fit = gap_map(fw, base.fit.resid, rep_cells, bands, td.fitted)
    m_held = gap_map(fw, base.fit.resid, rep_cells, bands, held) if held.any() else None
    z_detect = detection_score(m_fit, m_held)
    significant = z_detect > settings.z_gap
    notes = _trial_notes(td)
    basis = ScoreBasis(fw, base, reps)
    # the replicates are let go during the refits and made again when next read (the search's
    # peak memory), unless they are small: then they are kept (the same numbers, not made twice)
    search = _Search(fw=fw, settings=settings, theta_pre=theta_pre, base=base,
                     reps=reps if reps.nbytes <= KEEP_REPLICATES_BYTES else None,
                     replicates=made, bands=bands, rep_cells=rep_cells,
                     kappa_cells=cell_inflation(fw, rep_cells, bands, td.fitted), m_fit=m_fit,
                     m_held=m_held, n_eff=basis.r.size, rng=np.random.default_rng(settings.seed),
                     say=say, notes=notes)
    names = tuple(EFFECTS) if settings.effects is None else settings.effects  # (): none
    say(f"scoring {len(names)} candidate effects")
    sigs = _by_z(signature_scores(fw, base, basis, EFFECTS[n]) for n in names)
    # (N, k) and the replicates whitened: a second effect's basis is made anew; the replicates
    # themselves are let go during the singles' refits (the search's peak) and made again
    del basis, reps
    # the calibration's Jacobian is read from here on only to start each refit (copied into
    # the solver's): parked while the refits run, which each hold one of their own
    base.park_jacobian()
    cands = sorted(_candidates(search, sigs, significant), key=lambda c: c.dbic)
    if "kept_modal" in base.cache:
        notes.append(base.cache["kept_modal"])
    cands, best, ref = _credited(search, cands, significant)
    if ref is not None and closed_share(ref.record()) > 0 and departs_from_modes(
            fw, ref.cal.theta, np.zeros(len(fw.params)), settings.reference_modes) is None:
        # the base calibration was not at its optimum: the better one is adopted -- when it also
        # closes some of the gap, not only a better fit of the fitted impacts (the SAMPSON
        # sample's one fitted impact: dBIC < 0 but -6 % closed, which read "not at its optimum")
        notes.append(f"the calibration was not at its optimum: refitted without any effect from a "
                     f"candidate's constants it closes {100 * closed_share(ref.record()):.0f} % of the gap "
                     "by itself; the better constants are adopted and effects credited only beyond them")
        base, m_fit, m_held = ref.cal, ref.map_fit, ref.map_held
        search.base, search.m_fit, search.m_held = base, m_fit, m_held
        z_detect = detection_score(m_fit, m_held)
        significant = z_detect > settings.z_gap
        best = best if significant else None
    verdict = "no gap beyond noise" if not significant else ("explained" if best else "unexplained")
    gap_fit, gap_held = m_fit.excess(), m_held.excess() if m_held else 0.0
    if best is not None:
        best.cal.restore_fit(fw)    # let go if it was not the best single (_keep_best_jacobian)
        named, gap_fit, gap_held = _against_its_own_noise(search, best, gap_held)
        cands = [named if c is best else c for c in cands]
        best = named
    notes += _solver_notes(base, best)
    reps = search.held_reps()
    m_first = gap_map(fw, base.fit.resid, rep_cells, bands, np.array([0]))
    return Diagnosis(
        verdict=verdict, best=best, candidates=cands, signatures=sigs, base=base, map_fit=m_fit,
        map_held=m_held, gap_fit=gap_fit, gap_held=gap_held,
        modes_before=modes_of(base, td.lowpass_hz), forward=fw,
        seconds=time.perf_counter() - t_start, notes=notes, z_detect=z_detect, reps=reps,
        map_first=m_first)


def _calibrated(td: TrialData, settings: Settings, say: Callable[[str], None]
                ) -> tuple[Forward, np.ndarray, Calibration, np.ndarray, Bands, np.ndarray, _Replicates]:
    """Step 1: the noise, the calibration and its replicates. Returns the forward model weighted
    by what each gage x window tells beyond the model's form tolerance, the spectrum prefit's
    constants, the calibration refitted under those weights, its replicate residuals
    (n_rep, n_seg, n_g, n_s) m/s^2, the map's bands, the replicates' cell energies and how to
    make the replicates again."""
    # noise first from the nominal model's residual, then everything is weighted by it
    sigma0 = np.full(td.n_gages, td.rig.daq.noise_m_s2_rms * math.sqrt(2 * td.lowpass_hz / td.fs_full_hz))
    fw0 = Forward(td, sigma0)
    fit0 = fw0.fit(np.zeros(len(fw0.params)))
    sigma = noise_model(fw0, fit0.resid).sigma
    fw = Forward(td, np.maximum(sigma, 1e-12))
    say(f"calibrating {len(fw.params)} constants on {int(td.fitted.sum())} of {td.n_seg} impacts")
    theta_pre = prefit_frequencies(fw)
    base = _kept(fw, calibrate(fw, theta0=theta_pre), settings)
    noise = noise_model(fw, base.fit.resid)
    say(f"noise floor from {settings.n_rep} simulations of the calibrated model")
    reps = replicate_residuals(fw, base, noise, settings.n_rep, seed=settings.seed,
                               form_tol=settings.form_tol)
    bands = bands_for(base.fit.modes.f_hz, td.lowpass_hz)
    rep_cells = cell_energies(fw, reps, bands)
    # from here on every fit weighs each gage x window by what it tells beyond the model's form
    # tolerance (a rudder gage's 2 % mode-shape error is thousands of noise variances, and would
    # otherwise steer every refit); the constants are refitted under those weights first, so
    # that no candidate gains merely from the reweighting
    W_old = fw.W
    fw.set_weights(form_weights(fw, window_inflation(fw, rep_cells, td.fitted)))
    # the whitened residual's Jacobian scales with the weights, sample by sample
    ratio = (fw.W / W_old)[td.fitted].ravel()
    first = base
    base = _kept(fw, calibrate(fw, theta0=base.theta, max_iter=settings.refit_iter,
                               jac0=first.jac * ratio[:, None]), settings)
    first.drop_jacobian()
    made = _Replicates(fw, first, noise, W_old, settings)
    return fw, theta_pre, base, reps, bands, cell_energies(fw, reps, bands), made


def _kept(fw: Forward, cal: Calibration, settings: Settings) -> Calibration:
    """``cal``, the time-history calibration, unless it moved the model's modes away from the
    trial's identified ones (``settings.reference_modes``) where the modal-level constants (the
    rig as calibrated to them, ``theta = 0``) stay close: then the model at those constants, its
    Jacobian differenced there (the fit not iterated), with the reason in :attr:`Calibration.cache`
    ``"kept_modal"`` (issue 17: a crude rig's clean trial, calibrated to its time histories,
    ended 8.6 Hz delta 2.7 against the measured 6.30 Hz delta 0.19, damping constants at their
    bounds)."""
    zero = np.zeros(len(fw.params))
    why = departs_from_modes(fw, cal.theta, zero, settings.reference_modes)
    if why is None:
        return cal
    cal.drop_jacobian()
    kept = calibrate(fw, theta0=zero, max_iter=0)
    kept.cache["kept_modal"] = why
    return kept


def _beyond_chance(finding: dict) -> str:
    """A data-only finding's statistic against its chance level, in words: ``statistic 12.3x
    its chance level``, or, where no statistic measures it (a dead gage: certain), that."""
    s = strength(finding)
    return f"statistic {s:.1f}x its chance level" if math.isfinite(s) else CERTAIN


def _trial_notes(td: TrialData) -> list[str]:
    """What limits what the trial can show: nothing held out, events left out, few impacts."""
    notes = []
    if not (~td.fitted).any():
        notes.append("one impact only: nothing held out, closure on held-out impacts not measured")
    if td.decay_cut:
        notes.append(td.decay_cut)
    if td.dropped_onsets_s:
        notes.append("events too soon after the previous impact to compare, left out: "
                     + ", ".join(f"{t:.3f} s" for t in td.dropped_onsets_s))
    if td.lowpass_hz > td.rig_lowpass_hz:
        notes.append(f"compared up to {td.lowpass_hz:.0f} Hz, above the rig's {td.rig_lowpass_hz:.0f} Hz "
                     "band: the trial rings there after every blow on several gages, and its modes there "
                     "show a structural effect (a split or a coupled hull mode)")
    if td.fitted.sum() < 3:
        notes.append(f"only {int(td.fitted.sum())} impact(s) fitted: constants and effects are weakly "
                     "separated (a steady tone and a slow decay at its frequency look alike); six impacts "
                     "or more are advised")
    return notes


def _solver_notes(base: Calibration, best: Candidate | None) -> list[str]:
    """The calibration's or the named explanation's solver gave up (:class:`Stop`): its
    constants are where it stopped, not a minimum shown to be one."""
    fits = [("the calibration", base.stop)]
    if best is not None:
        fits.append((f"the refit with {best.name}", best.cal.stop))
    return [f"{what} gave up before converging (no step lowered the cost): its constants are "
            "where the solver stopped" for what, stop in fits if stop is Stop.GAVE_UP]


def _candidates(search: _Search, sigs: list[Signature], significant: bool) -> list[Candidate]:
    """Step 3: the ``top_k`` strongest signatures refitted, up to ``top_k_more`` more while none
    closes ``close_enough`` of a significant gap, then the best single with the second effect
    that stands out on top of it (:func:`_second_effect`). In the order refitted."""
    st = search.settings
    live = [s for s in sigs if s.placement is not None and s.z > -np.inf]
    cands: list[Candidate] = []
    for k, s in enumerate(live[: st.top_k + st.top_k_more]):
        if k >= st.top_k and (not significant or max(map(closed_share, (c.record() for c in cands)),
                                                     default=0.0) >= st.close_enough):
            break
        cands += _consider(search, cands, [s])
        _keep_best_jacobian(cands)
    pair = _second_effect(search, cands, live)
    if pair is not None:
        cands += _consider(search, cands, pair)
    for c in cands:
        c.cal.drop_jacobian()
    return cands


def _credited(search: _Search, cands: list[Candidate], significant: bool
              ) -> tuple[list[Candidate], Candidate | None, Candidate | None]:
    """An effect credited only with what it earns itself, not with what re-calibration did
    (issue 17: a crude rig's clean trial credited a 8e-5 Hz high-pass with the 69 % of the gap
    its refit's free constants closed). The candidate :func:`choose` would name is tested twice:
    its terms switched off at its fitted constants (:func:`_at_null`: a size at its null, a
    double hit of ratio 0, is not named), and the base refitted without any effect from its
    constants (:func:`_null_refit`): when that closes as much (within ``CLOSURE_TIE``) or the
    effect's evidence beyond it is under ``bic_min``, it is not credited. Every candidate is then
    measured beyond the best such null refit (:attr:`Candidate.null`), and the choice made again.
    Returns the candidates (so marked), the one to name (None: none) and the best null refit
    when it is better than the calibration (None otherwise)."""
    st = search.settings
    ref: Candidate | None = None
    nulls: dict[str, Candidate | None] = {}
    for _ in range(2 * len(cands) + 1):
        pick = choose([c.record() for c in cands], significant, st.bic_min, st.min_closure)
        best = next((c for c in cands if c.name == pick), None)
        if best is None:
            return cands, None, ref
        why = _at_null(search, best)
        if why is None:
            if pick not in nulls:
                nulls[pick] = null = _null_refit(search, best)
                if null is not None and null.dbic < 0 and (ref is None or null.dbic < ref.dbic):
                    ref = null      # every candidate measured beyond it: chosen again
                    cands = [replace(c, null=(ref.dbic, ref.closed_held, ref.closed_fit)) for c in cands]
                    continue
            if nulls[pick] is not None:
                why = _earned_by_null(best, nulls[pick], st.bic_min)
        if why is None:
            return cands, best, ref
        search.notes.append(f"{best.name} not credited: {why}")
        cands = [replace(c, no_credit=why) if c.name == pick else c for c in cands]
    return cands, None, ref


def _earned_by_null(c: Candidate, null: Candidate, bic_min: float) -> str | None:
    """Why candidate ``c`` earns nothing beyond the ``null`` refit (the base refitted without
    any effect from its constants), or None."""
    mine, its = closed_share(c.record() | {"closed_held": c.closed_held, "closed_fit": c.closed_fit}), \
        closed_share(null.record())
    if its >= mine - CLOSURE_TIE:
        return (f"refitted without it from its constants, the calibration closes {100 * its:.0f} % of "
                f"the gap (it closed {100 * mine:.0f} %): re-calibration, not the effect")
    if c.dbic - null.dbic > -bic_min:
        return (f"beyond the calibration refitted without it from its constants its evidence is "
                f"dBIC {c.dbic - null.dbic:.1f}")
    return None


def _at_null(search: _Search, c: Candidate) -> str | None:
    """Why ``c`` is not named for a term whose fitted size sits at its null: switched off (its
    placement's ``x0``) at the same constants the fit is as good within the term's own BIC
    charge plus ``bic_min``; or None."""
    fw, st = search.fw, search.settings
    c.cal.restore_fit(fw)
    keep = np.isfinite(c.cal.fit.resid)
    on = search.chi2(c.cal, keep)
    for i, t in enumerate(c.terms):
        off = [*c.terms[:i], t.with_x(t.placement.x0), *c.terms[i + 1:]]
        try:
            resid = fw.fit(c.cal.theta, off).resid
        except (ValueError, np.linalg.LinAlgError):
            continue
        d = cell_chi2(fw, np.where(keep, resid, np.nan), search.bands, search.td.fitted,
                      search.kappa_cells) - on
        if d < len(t.x) * math.log(search.n_eff) + st.bic_min:
            ps = ", ".join(f"{n} = {v:.4g}" for n, v in zip(t.placement.names, t.x, strict=True))
            return f"its {t.effect.name} sits at its null ({ps}; switched off, chi-square +{d:.1f})"
    return None


def _null_refit(search: _Search, c: Candidate) -> Candidate | None:
    """The base constants refitted without any effect, started from candidate ``c``'s: judged as
    a candidate of no terms (its dBIC against the calibration, its closures). None when the
    refit fails."""
    search.say(f"refitting the calibration from {c.name}'s constants, without it")
    try:
        cal = calibrate(search.fw, [], theta0=c.cal.theta, max_iter=search.settings.refit_iter,
                        jac0=search.base.jacobian())
    except (ValueError, np.linalg.LinAlgError):
        return None
    null = _judged(search, [], cal, 0, None)
    cal.drop_jacobian()
    return null


def _keep_best_jacobian(cands: list[Candidate]) -> None:
    """Let go of every single candidate's Jacobian (N x p, 40 MB at 20 impacts) and prediction
    and residual but the best one's, which :func:`_second_effect` scores on and a pair starts
    from; nothing else reads them once judged (the named one's fit is made again). The best
    one's Jacobian is parked (:meth:`Calibration.park_jacobian`) while the next singles refit."""
    singles = sorted(cands, key=lambda c: c.dbic)
    for c in singles[1:]:
        c.cal.drop_jacobian()
        c.cal.drop_fit_arrays()     # remade for the one named (diagnose)
    if singles:
        singles[0].cal.park_jacobian()


def _second_effect(search: _Search, cands: list[Candidate],
                   live: list[Signature]) -> list[Signature] | None:
    """[the best single's signature, the second's] when a second effect's signature stands out
    (``z_pair``) in what the best single leaves: the score test again, conditional on the first
    effect, over the ``top_k + 2`` strongest; else None."""
    singles = sorted(cands, key=lambda c: c.dbic)
    if not singles or len(live) < 2:
        return None
    c1 = singles[0]
    first = next(s for s in live if s.effect.name == c1.name)
    c1.cal.unpark_jacobian()
    basis1 = ScoreBasis(search.fw, c1.cal, search.held_reps())
    search.say(f"scoring a second effect on top of {c1.name}")
    second = _by_z(signature_scores(search.fw, c1.cal, basis1, s.effect)
                   for s in live[: search.settings.top_k + 2] if s.effect.name != c1.name)
    del basis1
    c1.cal.drop_jacobian()      # scored on: a pair's refit starts from the base's Jacobian
    if second and second[0].placement is not None and second[0].z > search.settings.z_pair:
        return [first, second[0]]
    return None


def _consider(search: _Search, cands: list[Candidate], group: list[Signature]) -> list[Candidate]:
    """The candidate of one signature, or of a pair whose first effect is among ``cands``
    already (it starts where that single ended): started, refitted and judged. Empty, with a
    note, when the refit fails."""
    done = {c.terms[0].effect.name: c for c in cands if len(c.terms) == 1}
    starts = [done[s.effect.name] for s in group if s.effect.name in done]
    terms, theta0 = _group_start(search, group, done, starts)
    search.say("refitting with " + " + ".join(t.effect.name for t in terms))
    new = [t.effect.name not in done for t in terms]
    try:
        cal = _refit(search, terms, theta0, new)
        if not starts:
            cal = _refit_single(search, group[0], cal, (terms[0], theta0))
    except (ValueError, np.linalg.LinAlgError) as exc:
        search.notes.append(f"refit with {'+'.join(t.effect.name for t in terms)} failed: {exc}")
        return []
    first = done.get(cal.terms[0].effect.name) if len(cal.terms) == 2 else None
    # parameters counted on the terms as they started: a placement read again after the refit
    # (a double hit's) may fit another number of delays, which this count does not follow
    return [_judged(search, group, cal, sum(len(t.x) for t in terms), first)]


def _group_start(search: _Search, group: list[Signature], done: dict[str, Candidate],
                 starts: list[Candidate]) -> tuple[list[Term], np.ndarray]:
    """The terms to refit and the base constants to start from. A single starts from the
    constants the data's spectrum gave, before the calibration hid what it cannot model in them
    (a tone becomes an undamped, detuned hull mode), re-tuned with its term on; a pair from its
    refitted single's constants and term."""
    ref = min(starts, key=lambda c: c.dbic).cal if starts else search.base
    known = [c.terms[0] for c in starts]
    theta0 = ref.theta.copy() if starts else search.theta_pre.copy()
    terms = []
    for s in group:
        if s.effect.name in done:
            terms.append(done[s.effect.name].terms[0])
            continue
        t, th = _start(search.fw, ref, s, known, None if starts else search.theta_pre)
        terms.append(t)
        theta0 = theta0 if starts else th
    return terms, theta0


def _refit(search: _Search, terms: list[Term], theta0: np.ndarray, new: list[bool]) -> Calibration:
    """The terms' own parameters first, the constants held (a tone's frequency must be found to
    a fraction of a cycle over the trial before anything else can move), then all. ``new``: per
    term, whether it is not refitted already (only those are fitted alone first)."""
    fit0 = None
    if any(len(t.x) for t, n in zip(terms, new, strict=True) if n):
        alone = calibrate(search.fw, terms, theta0=theta0, free_base=False, max_iter=15)
        terms, fit0 = alone.terms, alone.fit      # where the refit with all free starts
    return calibrate(search.fw, terms, theta0=theta0, max_iter=search.settings.refit_iter,
                     jac0=search.base.jacobian(), fit0=fit0)


def _refit_single(search: _Search, sig: Signature, cal: Calibration,
                  start: tuple[Term, np.ndarray] | None = None) -> Calibration:
    """A single effect's refit made good: again from the calibrated constants (the term where
    its score test put it) when the re-tuned start led somewhere worse than the calibration
    itself -- unless ``cal`` started there already (``start``: its term and constants), when
    that refit would be ``cal`` again; then its placement read again with the refit's constants
    and refitted from there, up to :data:`N_REREAD` times while that improves."""
    pl = sig.placement
    t0 = Term(sig.effect, pl, np.clip(sig.x0, pl.lo, pl.hi))
    same = (start is not None and start[0].effect is t0.effect and start[0].placement is pl
            and np.array_equal(start[0].x, t0.x) and np.array_equal(start[1], search.base.theta))
    if cal.cost > search.base.cost and not same:
        cal.park_jacobian()     # the refit being made holds its own
        alt = _refit(search, [t0], search.base.theta, [True])
        cal = min(cal, alt, key=lambda c: c.cost)
    for _ in range(N_REREAD):
        pl = sig.effect.placement_after(search.fw, cal)
        if pl is None or pl.key == cal.terms[0].placement.key:
            break
        cal.park_jacobian()
        alt = _refit(search, [Term(sig.effect, pl, _carry(cal.terms[0], pl))], cal.theta, [True])
        if alt.cost >= cal.cost:
            break
        cal = alt
    cal.unpark_jacobian()
    return cal


def _judged(search: _Search, group: list[Signature], cal: Calibration, k: int,
            first: Candidate | None) -> Candidate:
    """A refit as a candidate: its evidence (dBIC, charged for ``k`` parameters), the gap maps
    after it, how much of the gap it closes and where. ``first``: for a pair, the single it grew
    from, against which the second term's own evidence (``dbic_marginal``) is measured."""
    base = search.base
    # choosing where an effect sits among n placements costs ln n in evidence (2 ln n in BIC)
    look = sum(2 * math.log(max(1, s.n_placements)) for s in group)
    # the gain in chi-square, cell by cell deflated by the replicates' own excess there (a
    # gain where the model's form tolerance already spreads the replicates counts little),
    # on the samples both fits keep (a clipping term leaves some out)
    gain = (search.chi2(base, np.isfinite(cal.fit.resid)) - search.chi2(cal) + base.prior - cal.prior)
    dbic = -gain + k * math.log(search.n_eff) + look
    # an effect read straight off the data (no template) counts by its detection score
    dbic -= sum(s.z ** 2 for s in group if s.k == 0 and np.isfinite(s.z))
    a_fit, a_held = search.maps(cal.fit.resid, search.rep_cells)
    m_fit, m_held = search.m_fit, search.m_held
    c_fit, _ = closure(m_fit, a_fit, search.rng, m_held)
    c_held, ci = closure(m_held, a_held, search.rng, m_fit) if a_held else (float("nan"), (np.nan, np.nan))
    loc = location([m_fit] + ([m_held] if m_held else []), [a_fit] + ([a_held] if a_held else []),
                   cal.terms)
    marginal = None
    if first is not None:
        # what the second term adds to the single it grew from, deflated along that direction
        gain2 = search.chi2(first.cal) + first.cal.prior - search.chi2(cal) - cal.prior
        marginal = -gain2 + len(cal.terms[1].x) * math.log(search.n_eff)
    return Candidate(
        terms=cal.terms, cal=cal, dbic=dbic, gap_fit=a_fit.excess(m_fit.gap_cells()),
        gap_held=a_held.excess(m_held.gap_cells()) if a_held else 0.0, closed_fit=c_fit,
        closed_held=c_held, closed_held_ci=ci, location=loc, map_fit=a_fit, map_held=a_held,
        modes_after=modes_of(cal, search.td.lowpass_hz), dbic_marginal=marginal)


def _against_its_own_noise(search: _Search, best: Candidate,
                           gap_held: float) -> tuple[Candidate, float, float]:
    """The named explanation judged against the noise floor of its own residual: a tone or a
    drift left in the pre windows would otherwise count as noise and flatter it. Returns the
    candidate with its maps, closures and gaps so measured (its replicates attached, for its
    features), and the calibrated model's gap on the fitted and held-out impacts against the
    same floor (``gap_held`` as given when nothing is held out)."""
    fw, st = search.fw, search.settings
    noise2 = noise_model(fw, best.cal.fit.resid)
    reps2 = replicate_residuals(fw, best.cal, noise2, st.n_rep, seed=st.seed + 1, form_tol=st.form_tol)
    cells2 = cell_energies(fw, reps2, search.bands)
    b_fit, b_held = search.maps(search.base.fit.resid, cells2)
    a_fit, a_held = search.maps(best.cal.fit.resid, cells2)
    closed_fit, _ = closure(b_fit, a_fit, search.rng, b_held)
    named = replace(best, map_fit=a_fit, closed_fit=closed_fit, gap_fit=a_fit.excess(b_fit.gap_cells()),
                    reps=reps2, cal_forward=fw)
    if b_held is None:
        return named, b_fit.excess(), gap_held
    closed_held, ci = closure(b_held, a_held, search.rng, b_fit)
    named = replace(named, map_held=a_held, closed_held=closed_held, closed_held_ci=ci,
                    gap_held=a_held.excess(b_held.gap_cells()))
    return named, b_fit.excess(), b_held.excess()
