"""One report from two layers: the data-only findings (:mod:`ramdaq.analysis.gap.sensors`, no
stiffness or mass model) and the model layer's named effect (:mod:`ramdaq.analysis.gap.diagnose`).

Where both speak of the same gages, a sensor finding of the data layer takes precedence: it
rests on the recorded values and the gages' positions and axes alone, while the model layer's
attribution leans on a rig model that is never exact (issue 17: an approximate rig's own errors
were named as one gage's sensitivity). :func:`precedence` says which of the model's attributions
is set aside, and for which gages.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import scipy.stats

from .datamodel import P_CHANCE, PRECEDENCE_STRENGTH, Finding, Layer
from .evidence import GAP_CELL_Z
from .modal_level import MAX_SPLIT_REL
from .verdict import CLOSURE_TIE, UNEXPLAINED_CLOSURE, closed_share

SENSOR_EFFECTS = frozenset({"gage_sensitivity", "gage_alignment", "clipping", "time_skew", "highpass"})
"""The model layer's effects that blame a sensor."""


@dataclass(frozen=True)
class Precedence:
    """The data layer's ``finding`` (its check) on ``gages`` takes precedence over the model
    layer's ``model_effect``, which it placed on ``model_gages``."""

    gages: tuple[int, ...]
    finding: str
    model_effect: str
    model_gages: tuple[int, ...] = ()

    def to_json(self) -> dict:
        return {"gages": list(self.gages), "data_only": self.finding, "model": self.model_effect,
                "model_gages": list(self.model_gages), "kept": "data_only"}

    def text(self) -> str:
        g = ", ".join(map(str, self.gages))
        on = f" on gage(s) {', '.join(map(str, self.model_gages))}" if self.model_gages else ""
        return (f"the data-only {self.finding} on gage(s) {g} takes precedence over the model's "
                f"{self.model_effect}{on}")


def model_gages(effect_gages: list[int], located: list[int], effect: str) -> set[int]:
    """The gages a model attribution names: its terms' own placements (a sensor effect's gage),
    else, for a sensor effect without one, the gages where it closed the gap."""
    if effect_gages:
        return set(effect_gages)
    return set(located) if set(effect.split("+")) & SENSOR_EFFECTS else set()


def precedence(findings: list[Finding], effect: str | None, gages: set[int]) -> list[Precedence]:
    """The model's attributions set aside: for each sensor finding of the data layer on gages the
    model's named ``effect`` also names (``gages``, from :func:`model_gages`), and for each that
    is the data-only counterpart of a sensor effect the model placed on other gages (the model
    blames one gage's sensitivity, the rigid-body check finds another's gain: the data's gage
    stands). Empty when the model named nothing, or neither."""
    if not effect:
        return []
    counterparts = {COUNTERPART[e] for e in effect.split("+") if e in COUNTERPART and e in SENSOR_EFFECTS}
    return [Precedence(f.gages, f.check, effect, tuple(sorted(gages))) for f in findings
            if f.layer is Layer.SENSOR and (set(f.gages) & gages or f.check in counterparts)]


COUNTERPART = {"gage_sensitivity": "gain", "time_skew": "time_skew", "highpass": "highpass",
               "clipping": "clipping", "ambient_tone": "ambient_tone", "double_hit": "double_hit",
               "friction": "homogeneity"}
"""The data-only check that looks for what each model effect would leave in the data."""


def unconfirmed(findings: list[Finding], looked: tuple[str, ...], effect: str | None) -> list[str]:
    """The data-only checks that looked for the model's named ``effect`` (each of its terms)
    and found nothing beyond chance: the model's attribution then rests on the model alone."""
    if not effect:
        return []
    found = {f.check for f in findings}
    checks = {COUNTERPART[e] for e in effect.split("+") if e in COUNTERPART}
    return sorted(c for c in checks if c in looked and c not in found)


DATA_EFFECT = {"gain": "gage_sensitivity", "dead": "gage_sensitivity", "rigid_body": "gage_alignment",
               "time_skew": "time_skew", "highpass": "highpass", "clipping": "clipping",
               "ambient_tone": "ambient_tone", "double_hit": "double_hit",
               "gain_invariance": "unexplained", "line_persistence": "unexplained",
               "one_gage_line": "unexplained", "chain_misfit": "unexplained",
               "early_nonlinear": "unexplained"}
"""The library effect each data-only check's finding names (a homogeneity finding: friction when
its decays follow Coulomb's law, "unexplained" otherwise -- an amplitude-dependent stiffness the
library does not hold, or a law the decays did not tell: :func:`data_effect`)."""
DATA_WINDOW = {"pre": "pre", "early": "early", "peaks": "early", "decay": "late"}
"""The report's window of a data-only finding's window."""
OVERRIDING_EXCITATION = frozenset({"double_hit", "line_persistence"})
"""Data-only excitation checks whose finding, well above chance, answers before the model's
"unexplained" (issue 17: the modal family's double hits were "unexplained"). Not the ambient
tone: a line before the blows is also what an effect outside the library (mains pickup) leaves."""


NOT_LTI = frozenset({"gain_invariance", "line_persistence", "one_gage_line", "chain_misfit"})
"""Data-only checks of a linear, time-invariant, spatially coherent measurement
(:mod:`ramdaq.analysis.gap.invariance`): a gage's gain changing between impacts, a line switched
on by the blows, an early line on one gage alone. No library effect and no linear model
update explains any of them (nor a gage's phase off the others' that no one time skew fits,
:func:`~ramdaq.analysis.gap.sensors.chain_phase`); well above chance (:data:`PRECEDENCE_STRENGTH`)
they answer "unexplained" at their gages, below it they answer nothing."""


def data_effect(f: dict) -> str | None:
    """The library effect (or "unexplained") a data-only finding as JSON names; None for a
    finding that names none (a flexible body, a noisy gage: model form and context)."""
    if f["check"] == "homogeneity":
        return "friction" if is_friction(f) else "unexplained"
    return DATA_EFFECT.get(f["check"])


def is_friction(f: dict) -> bool:
    """Whether a data-only finding (as JSON) is the homogeneity check's Coulomb friction: a mode's
    decrement per cycle growing as 1/amplitude within the decays, its frequency unchanged
    (:func:`~ramdaq.analysis.gap.homogeneity.decay_laws`)."""
    more = f.get("more", {})
    return f["check"] == "homogeneity" and "coulomb_law_z" in more and "stiffness_law_z" not in more


def told_law(f: dict) -> bool:
    """Whether a data-only finding (as JSON) is the homogeneity check's with the law its decays
    follow told: Coulomb friction (:func:`is_friction`) or an amplitude-dependent stiffness
    (``stiffness_law_z``), not a slope across the blows alone."""
    more = f.get("more", {})
    return f["check"] == "homogeneity" and ("coulomb_law_z" in more or "stiffness_law_z" in more)


def strength(f: dict) -> float:
    """A finding's (as JSON) statistic over its chance level; JSON stores an infinite statistic
    as null (a dead gage), a statistic that could not be measured is no finding at all."""
    stat = math.inf if f["statistic"] is None else float(f["statistic"])
    return stat / max(float(f["chance_level"] or 0.0), 1e-12)


def not_homogeneous(findings: list[dict]) -> bool:
    """Whether the data-only layer found the trial not homogeneous across blows (a finding of
    the nonlinearity layer, as JSON, at least :data:`PRECEDENCE_STRENGTH` times its chance
    level): its other checks read linear models the trial bends. A slope barely past its chance
    level does not set the other checks aside (a modal development double hit at 600x chance
    came with an amplitude slope at 1.07x), nor does a slope a second blow explains
    (:func:`second_blow_slope`)."""
    return any(f.get("layer") == Layer.NONLINEARITY and strength(f) >= PRECEDENCE_STRENGTH
               and not second_blow_slope(f, findings) for f in findings)


def second_blow_slope(f: dict, findings: list[dict]) -> bool:
    """Whether nonlinearity finding ``f`` (as JSON) is a slope across the blows whose law the
    decays did not tell (not :func:`told_law`) beside a second blow that explains the held-out
    impacts: a ``double_hit`` finding standing further above its chance level whose own
    correction, fitted on the other impacts, closes at least
    :data:`~ramdaq.analysis.gap.verdict.UNEXPLAINED_CLOSURE` of its residual held out. A second
    pulse adds ``r e^(-i w tau)`` to each blow's force at a mode, so what a blow delivers at a
    mode is not the blow's size read at its first pulse, and the ringing's amplitude against it
    bends; a decay law told within the decays (Coulomb's, a moving frequency) is no such reading
    and stands. An amplitude-dependent structure's early response reads as a second blow that
    closes nothing held out (-0.4 to -19, :func:`fails_held_out`), so it is not taken for one
    (issue 17: truth double hit 512000 at 438x its chance level, its correction closing 95 % held
    out, was answered "unexplained" from a 7.9 Hz amplitude slope at 3.8x)."""
    if f.get("layer") != Layer.NONLINEARITY or told_law(f):
        return False
    return any(g["check"] == "double_hit" and strength(g) > strength(f)
               and closes_held_out(g) for g in findings)


def at_splits(findings: list[dict], splits: Sequence[dict]) -> list[dict]:
    """The data-only findings (as JSON) that read a mode of one of the model level's ``splits``
    (as JSON): one of their modes (``mode_hz``, Hz) within
    :data:`~ramdaq.analysis.gap.modal_level.MAX_SPLIT_REL` of the pair, the widest split the
    model level reads; a finding that names no mode reads them all. A change across the blows
    of another mode's frequency or damping (a slope on the blow, no law told) says that mode
    is not homogeneous; it does not bend the pair, whose two poles the free model and the
    calibration fit in their own band (issue 17: modal dev seed 60004, a 56.6/59.2 Hz pair of
    MAC 0.99999 set aside by a -0.4 % per doubling slope of the 12.5 Hz hull mode at 2.5x its
    chance level). A law told anywhere (:func:`stiffness_laws`) still sets a split aside: a
    crack's moving mode was fitted a pair beside it (dev seed 61000)."""
    spans = [(s["f_lo_hz"] / (1 + MAX_SPLIT_REL), s["f_hi_hz"] * (1 + MAX_SPLIT_REL)) for s in splits]
    return [f for f in findings
            if not f.get("mode_hz") or any(lo <= m <= hi for m in f["mode_hz"] for lo, hi in spans)]


LINEAR_SHAPE_CHECKS = frozenset({"gain", "rigid_body", "time_skew", "highpass", "double_hit",
                                 "gain_invariance", "chain_misfit"})
"""Data-only checks that read the free *linear* modal model's shapes and phases (the rigid-body
gain and alignment, the phases' timing and high-pass) or a linear one-blow response (the double
hit): an amplitude-dependent structure bends what they read."""


def reads_recorded_values(f: dict) -> bool:
    """Whether finding ``f`` (as JSON) is a sensor finding read on the recorded values
    themselves (a flat top, a dead gage), not on the linear model's shapes
    (:data:`LINEAR_SHAPE_CHECKS`): a nonlinearity elsewhere does not bend it. A finding without
    a layer (stored before layers) is none."""
    return f.get("layer") == Layer.SENSOR and f.get("check") not in LINEAR_SHAPE_CHECKS


def credible(findings: list[dict]) -> list[dict]:
    """The data-only findings (as JSON) that may answer for the trial: none of
    :data:`LINEAR_SHAPE_CHECKS` when the same trial is found not homogeneous across blows
    (:func:`not_homogeneous`) -- the double-hit check fits a *linear* one-blow response, and an
    amplitude-dependent decay (friction stopping a mode's ringing half a period after the blow)
    is what a second blow in anti-phase fits best; the shape checks read the linear model's
    shapes, which the nonlinearity bends (modal check seed 157000: friction on a 12.7 Hz mode
    read as a 2.8-sample skew of gage 12 at 11.8x its chance level, beside the homogeneity
    finding at 11.3x). As :func:`overriding_unexplained` sets them aside."""
    nonlinear = not_homogeneous(findings)
    return [f for f in findings if not (nonlinear and f["check"] in LINEAR_SHAPE_CHECKS)
            and not ((f.get("layer") == Layer.EXCITATION or f["check"] in CHAIN_CHECKS)
                     and fails_held_out(f)) and not channel_not_fixed(f, findings)]


FIXED_CHANNEL = frozenset({"gain", "rigid_body", "time_skew", "highpass"})
"""Data-only sensor checks that read one fixed law of a gage's channel on the free linear
model's shapes and phases: a constant gain or axis, a constant delay, a constant first-order
corner (:func:`channel_not_fixed`)."""
NOT_FIXED = frozenset({"gain_invariance", "one_gage_line"})
"""Data-only findings that a gage's channel is not one fixed law: its gain changes between
impacts (:func:`~ramdaq.analysis.gap.invariance.gain_invariance`), or it rings with a line of its
own that no other gage shows (:func:`~ramdaq.analysis.gap.invariance.one_gage_lines`)."""


def channel_not_fixed(f: dict, findings: list[dict]) -> bool:
    """Whether finding ``f`` (as JSON) reads a fixed channel law (:data:`FIXED_CHANNEL`) on a gage
    where the same data show the channel is not fixed (:data:`NOT_FIXED`, at least
    :data:`PRECEDENCE_STRENGTH` times its chance level). Then the fixed law is the projection
    of another one, not the cause: a gain drifting through the trial reads, averaged over the
    impacts, as a constant gain (its mean); a resonance of the gage's mount or chain at ``fr``
    rings as a line on that gage alone and multiplies its response at the modes by
    ``1 / (1 - (f / fr)^2)`` in gain with a phase lag growing with ``f`` -- a gain, a delay or a
    corner fitted over the modes. Neither a fixed gain, nor a delay, nor a corner changes
    between impacts or rings by itself, so the finding that they cannot make answers, at its
    own statistic and chance level (issue 17: modal development seed 64000, a 126 Hz resonance
    on gage 3 read as a 0.33 ms skew of gage 3 at 100x its chance level beside its own early
    line at 101x -- answered by the larger of the two, a near tie; an earlier run of the same
    seed read the line at 32x; stored development and check trials of every library effect
    show no such pair on one gage but one ambient tone, answered before by its pre-window
    line; no stored answer of 1100 changes)."""
    if f["check"] not in FIXED_CHANNEL:
        return False
    return any(g["check"] in NOT_FIXED and strength(g) >= PRECEDENCE_STRENGTH
               and set(g["gages"]) & set(f["gages"]) for g in findings)


CHAIN_CHECKS = frozenset({"time_skew", "highpass"})
"""Data-only signal-chain findings that must close half their own residual held out to be
credible (:func:`fails_held_out`): a skew or a corner fitted on the other impacts that does not
explain the held-out impact's phases is no fixed law of the channel (issue 17, modal development
seed 51001, a clean trial: gage 15 read as a 0.93 Hz high-pass at 4x its chance level, closing
34 % held out; the right gages of modal high-passes, dev and check seeds, close 59-100 %, skews of
both families 98-100 %; the same a-priori half the model layer asks of an effect)."""


def overriding_unexplained(findings: list[dict]) -> list[dict]:
    """Of data-only findings as JSON (:meth:`Finding.to_json`), those that take precedence over
    the model layer's "unexplained" (:func:`strength` at least :data:`PRECEDENCE_STRENGTH`): a sensor finding
    or a double hit (:data:`OVERRIDING_EXCITATION`); none when the data layer also found the
    trial not homogeneous across blows (a nonlinearity: the sensor checks read the free *linear*
    modal model's shapes, which an amplitude-dependent structure bends, and the double-hit check
    a linear one-blow response) -- then only the homogeneity finding itself, when its decays
    follow Coulomb's law (:func:`is_friction`): friction is in the library, while a crack's or a
    rattle's amplitude-dependent stiffness (or a law the decays did not tell) is not, and a trial
    the model leaves unexplained then stays so -- and a sensor finding that reads the recorded
    values themselves (a flat top, a dead gage: not :data:`LINEAR_SHAPE_CHECKS`)."""
    strong = [f for f in findings if f.get("layer") in set(Layer) and strength(f) >= PRECEDENCE_STRENGTH]
    if not_homogeneous(findings):
        # a flat top (or a dead gage) reads the recorded values, not the linear model's shapes:
        # a nonlinearity elsewhere does not bend it, as :func:`credible` keeps it (modal check
        # seed 153001: clipping on gages 4 and 6 at 2-2.6x chance, a slope on the hull's
        # gages beside it, was left "unexplained")
        return [f for f in strong if is_friction(f) or reads_recorded_values(f)]
    return [f for f in credible(strong) if f["layer"] == Layer.SENSOR or f["check"] in OVERRIDING_EXCITATION]


def second_blow_held(f: dict, candidates: list[dict]) -> dict:
    """A double-hit finding (as JSON) that fails its own held-out test (:func:`fails_held_out`)
    with the held-out closure of the effect search's second blow instead, when that closes at
    least :data:`~ramdaq.analysis.gap.verdict.UNEXPLAINED_CLOSURE` (the best candidate naming
    ``double_hit``, alone or with another effect); any other finding unchanged. The two fit one
    second blow two ways: the data layer's on the free linear model's early response (which
    lacks the modes above the compared band that a short pulse rings), the effect search's
    through the calibrated rig's forward model; a second blow is what either explains on the
    impacts it was not fitted to -- an amplitude-dependent stiffness is explained by neither
    (issue 17: truth development seed 1003, a second blow at 515x its chance level whose data
    fit closed -0.43 held out while the effect search's double_hit closed 0.92, was answered
    "unexplained" by :func:`early_nonlinear`)."""
    if f["check"] != "double_hit" or not fails_held_out(f):
        return f
    held = [v for c in candidates if "double_hit" in c["name"].split("+")
            and (v := held_closure(c)) is not None]
    if not held or max(held) < UNEXPLAINED_CLOSURE:
        return f
    return f | {"closed_held": max(held), "closed_held_by": "effect search"}


def fails_held_out(f: dict) -> bool:
    """Whether a data-only finding (as JSON) measured its own held-out closure and it is below
    :data:`~ramdaq.analysis.gap.verdict.UNEXPLAINED_CLOSURE`: its correction, read on the other
    impacts, does not explain the held-out ones -- the half the model layer asks of an effect
    before it names one. A double hit read at 300-700x chance on a modal crack or rattle trial
    (a bilinear stiffness's or an impact's response, not a second blow) closed -0.4 to -19 of its
    residual held out, the modal double hits 0.71-0.84 (issue 17: modal check seed 160000 and
    the earlier sessions' stored dev and check trials)."""
    v = held_closure(f)
    return v is not None and v < UNEXPLAINED_CLOSURE


def held_closure(d: dict) -> float | None:
    """The share of its residual a finding's (or a candidate's, as JSON) correction, fitted on
    the other impacts, closes on the held-out ones; None where it was not measured (absent,
    null or not finite)."""
    v = d.get("closed_held")
    return float(v) if v is not None and math.isfinite(float(v)) else None


def closes_held_out(d: dict) -> bool:
    """Whether a finding's (or a candidate's, as JSON) measured held-out closure
    (:func:`held_closure`) is at least :data:`~ramdaq.analysis.gap.verdict.UNEXPLAINED_CLOSURE`:
    the half the model layer asks of an effect before it names one."""
    v = held_closure(d)
    return v is not None and v >= UNEXPLAINED_CLOSURE


@dataclass(frozen=True)
class Answer:
    """The one report's answer, both layers: ``named`` a library effect, ``"none"`` (no effect;
    what the model misses is its form) or ``"unexplained"``; ``by`` "model" or "data" (the
    layer that answered); ``location`` as a candidate's (``gages``, ``window``, ...) or the
    unexplained gap's, None when there is nothing to place; ``closed_held`` the share of the
    held-out impacts' gap the named effect closes -- the model's gap for the model's answer, the
    data check's own residual for the data layer's (:func:`data_closure`; None when not
    measured); ``finding`` the
    data-only finding (JSON) that answered, when the data layer did."""

    named: str
    by: str
    location: dict | None
    closed_held: float | None
    finding: dict | None = None

    def to_json(self) -> dict:
        return {"named": self.named, "by": self.by, "location": self.location,
                "closed_held": self.closed_held, "finding": self.finding}


def model_answer(model: str | None, candidates: list[dict], where: dict | None,
                 form_gages: set[int], form_modes: Sequence[tuple[float, Sequence[int]]] = ()) -> Answer:
    """The model layer's answer from its choice ``model`` (:func:`~ramdaq.analysis.gap.verdict.choose`:
    None for no gap, "unexplained", or a candidate's name), the candidates' records (with their
    ``location``), the unexplained gap's place ``where`` and the gages where the rig calibrated to
    the trial's modes still misses them (``form_gages``): an effect acting only there, or an
    unexplained gap only there, is not told from that form error -- "none" (no effect; model
    form). So is an unexplained gap in the band of a mode the calibrated rig misses
    (``form_modes``: each such mode's frequency, Hz, and every gage where its shape differs
    beyond chance) on gages among that mode's (:func:`in_form_mode`). A structural candidate is
    held against the form its own update leaves (its ``form_gages``, when given: the rig
    calibrated again with the effect on, :meth:`~ramdaq.analysis.gap.rigfit.ModelLevel.form_with_update`):
    a form error the effect explains is the effect, not the rig's form."""
    named = model or "none"
    c = next((c for c in candidates if c["name"] == named), None)
    if named == "unexplained" and in_form_mode(where, form_modes):
        named = "none"
    elif form_gages:
        within = where is None or not where["gages"] or set(where["gages"]) <= form_gages
        if named == "unexplained" and within:
            named = "none"
        elif c is not None and c["location"]["gages"] and set(c["location"]["gages"]) <= set(
                c.get("form_gages", form_gages)):
            named, c = "none", None
        elif c is not None and unspecific(c, candidates):
            named, c = "none", None
    loc = c["location"] if c else (where if named == "unexplained" else None)
    return Answer(named, "model", loc, c["closed_held"] if c else None)


def unspecific(c: dict, candidates: list[dict]) -> bool:
    """Whether a structural or excitation candidate ``c`` (a record, as :func:`model_answer`
    reads it) closes no more of the held-out gap than a sensor effect does (within
    :data:`~ramdaq.analysis.gap.verdict.CLOSURE_TIE`): a gage's gain or timing adds no mode and
    moves no frequency, so when it closes as much as a structural update on a rig that carries
    form error, what closes is the freedom any term adds to fit that form error, not the
    update's physics -- no evidence for it (issue 17: a clean modal trial, check seed 150006,
    the rig's 23.67 Hz mode 1-MAC 0.998 after calibration, named tiller at 26.0 Hz closing
    70.9 %, with time_skew 70.0 % and gage_sensitivity 69.3 % beside it). A sensor effect
    named is judged by the data layer's checks instead (:func:`form_not_sensor`)."""
    if c["name"].split("+")[0] in SENSOR_EFFECTS:
        return False
    own = closed_share(c)
    return any(r["name"] in SENSOR_EFFECTS and closed_share(r) >= own - CLOSURE_TIE for r in candidates)


def split_answer(split: dict, candidates: list[dict]) -> Answer:
    """The answer "split_mode" from the model level's split (as JSON), placed at its gages and
    mode, late window (where the halves beat); its closure the effect search's split_mode's."""
    f = 0.5 * (split["f_lo_hz"] + split["f_hi_hz"])
    c = next((c for c in candidates if c["name"] == "split_mode"), None)
    loc = {"gages": list(split["gages"]), "window": "late", "band_hz": f, "effect_mode_hz": f,
           "band": f"{f:.1f} Hz"}
    return Answer("split_mode", "model", loc, c["closed_held"] if c else None)


def in_form_mode(where: dict | None, form_modes: Sequence[tuple[float, Sequence[int]]]) -> bool:
    """Whether an unexplained gap (``where``, :func:`~ramdaq.analysis.gap.verdict.gap_where`,
    with its band's edges) lies in the band of a mode the calibrated rig still misses, on gages
    where that mode's shape differs beyond chance: it is what the rig's wrong shape of that mode
    leaves in the map (issue 17: a clean modal-family trial's first rudder mode, 1-MAC 0.88
    after calibration and beyond chance at all 16 gages, left a 23 Hz early-window gap on gages
    12, 3, 10, of which the form error's worst four named only 3). A gap without band edges
    (stored before they were) is not placed."""
    if not where or not where.get("gages") or "band_edges_hz" not in where:
        return False
    lo, hi = where["band_edges_hz"]
    return any(lo <= f < hi and set(where["gages"]) <= set(g) for f, g in form_modes)


def declared_tone(findings: list[dict], location: dict | None) -> dict | None:
    """The data layer's ``declared_ambient`` note (a line the rig's ``[[ambient]]`` declares,
    present as declared) at the model's ambient tone (its frequency within 1 Hz, the pre
    window's resolution, when the model placed one): that tone is the user's stated environment,
    not an effect. None when there is none."""
    f = (location or {}).get("effect_mode_hz")
    return next((d for d in findings if d["check"] == "declared_ambient"
                 and (f is None or not d["mode_hz"] or abs(d["mode_hz"][0] - f) <= 1.0)), None)


SAME_LINE_HZ = 1.0
"""Lines closer than this are one line, Hz: the resolution of the 1 s pre window the ambient-tone
check reads (:func:`~ramdaq.analysis.gap.signal_checks.pre_trigger_lines`), as
:func:`declared_tone` reads it."""


def dead_first(findings: list[dict]) -> list[dict]:
    """The data-only findings (as JSON) of a gage the blow did not move: certain (no statistic
    reaches it) and spoiling every other reading of that gage, they answer before anything else,
    as a gain of zero at it (a new user's trial with a dead gage 8 and a faint mains hum answered
    ambient_tone, the dead gage only listed)."""
    return [f for f in findings if f["check"] == "dead"]


def ambient_first(findings: list[dict]) -> list[dict]:
    """The data-only ambient tones (as JSON) that answer before anything else: a line found
    before the blows -- in every pre window with the previous blows' ringing taken out, and in
    the first, before any blow, where nothing rings -- at least :data:`PRECEDENCE_STRENGTH` times
    its chance level. No structure rings before it is struck, so no model update (hull coupling,
    a tiller) and no nonlinearity explains it, whatever its frequency; a line the blows switch on
    (a ``line_persistence`` finding within :data:`SAME_LINE_HZ`: down before the next blow, an
    effect outside the library) is not one. Issue 17, modal check seeds 155000-1: an 11.8 Hz hull
    tone at 131x its chance level was named hull_coupling by the model level; a 5.0 Hz one at 29x
    read as a mode whose amplitude grows as the blow^0.20 -- the tone's share does not grow with
    the blow."""
    return [f for f in findings if f["check"] == "ambient_tone" and strength(f) >= PRECEDENCE_STRENGTH
            and f["mode_hz"] and not on_switched_line(f["mode_hz"][0], findings)]


def on_switched_line(f_hz: float, findings: list[dict]) -> bool:
    """Whether ``f_hz`` (Hz) lies on a line the blows switch on: a ``line_persistence`` finding
    (as JSON) within :data:`SAME_LINE_HZ`, steady through each decay and gone before the next
    blow -- neither an ambient tone (it would be there throughout) nor a mode (it would ring on,
    decaying)."""
    return any(abs(f_hz - h) <= SAME_LINE_HZ
               for f in findings if f["check"] == "line_persistence" for h in f["mode_hz"])


def flat_tops_first(findings: list[dict], named: str) -> list[dict]:
    """The data-only clipping findings (as JSON) that answer before the model layer's effect
    (unless it names clipping itself): flat tops at a gage's peaks at least
    :data:`PRECEDENCE_STRENGTH` times their chance level, whose own correction -- the rails read
    on the other blows -- closes at least :data:`~ramdaq.analysis.gap.verdict.UNEXPLAINED_CLOSURE`
    of the free model's misfit at the held-out blows' peaks. Both are read on the recorded
    values themselves: samples that stay at one value at the extremes of several blows of
    different force (the flat tops' excess over the noise's chance of equal neighbours,
    :func:`~ramdaq.analysis.gap.signal_checks.flat_tops`) are the converter's rail, which no
    structure (a linear update, a coupled hull mode) and no nonlinearity of the structure makes,
    while a model fitted to the clipped peaks takes up their cut amplitude with whatever freedom
    its candidates add (issue 17's benchmark: modal clipping read as
    hull_coupling+gage_alignment). The same a-priori bar and half as :func:`held_out_data`."""
    if "clipping" in named.split("+"):
        return []
    return [f for f in credible(findings) if f["check"] == "clipping" and strength(f) >= PRECEDENCE_STRENGTH
            and closes_held_out(f)]


def held_out_data(findings: list[dict]) -> list[dict]:
    """The credible data-only findings (as JSON, :func:`credible`) of a sensor or a second blow
    (:data:`HELD_OUT_EXCITATION`) that outrank a model layer's structural update on a rig that
    carries form error: at least :data:`PRECEDENCE_STRENGTH` times their chance level, and their
    own correction, fitted on the other impacts, closing at least
    :data:`~ramdaq.analysis.gap.verdict.UNEXPLAINED_CLOSURE` of their check's residual on the
    held-out ones (the same a-priori half the model layer asks of an effect). The data layer
    rests on the recorded values and the gages' positions alone; the model's update is fitted to
    a rig already known wrong (issue 17: modal check seed 154001, a 3 Hz high-pass on five gages
    at 93-153x chance, each closing 94-99.6 % held out, was named tiller; modal development seed
    57001, a second blow 18 ms after the first at 916x chance closing 74 % held out, was named
    hull_coupling). A second blow outranks a structural update on any rig, form error or not
    (the caller's choice): its pulse is read on the early window's recorded values, where no
    linear update of the structure puts a second rise of every gage tens of ms after the blow,
    and its held-out closure says it repeats blow after blow (development seed 13003 of an
    earlier run: a second blow named with a gage's alignment beside it)."""
    return [f for f in credible(findings)
            if (f.get("layer") == Layer.SENSOR or f["check"] in HELD_OUT_EXCITATION)
            and data_effect(f) not in (None, "unexplained") and strength(f) >= PRECEDENCE_STRENGTH
            and closes_held_out(f)]


HELD_OUT_EXCITATION = frozenset({"double_hit"})
"""Data-only excitation checks that measure their own held-out closure and name a library
effect (a second blow): with the sensor checks, what :func:`held_out_data` weighs against a
structural update."""


RIGID_BODY_EFFECTS = frozenset({"gage_sensitivity", "gage_alignment"})
"""The model's sensor effects the data layer's rigid-body redundancy check (its ``gain`` and
``rigid_body`` findings) tests each gage of a body for."""


def form_not_sensor(out: Answer, findings: list[dict], form_gages: set[int]) -> bool:
    """Whether the model layer's sensor attribution ``out`` (a gage's sensitivity or alignment)
    is the rig's form instead: the rig carries form error (``form_gages``), the data layer's
    rigid-body redundancy check ran on the body of every gage the model blames (a ``flex``
    finding holds them: that body deforms in its modes) and found no sensor fault on any of them
    (no credible sensor finding there). The data layer's check rests on the gages' positions and
    axes alone and reads a gain on the modes the body carries rigidly; the model's attribution
    leans on a rig already known wrong (issue 17: "gage 3 sensitivity" named in 16 of 48 trials
    whatever the truth; modal check seed 150005, a clean trial, named gage_sensitivity on gages
    6, 3, 1 where the data found only the rudder's flexible shapes)."""
    if out.by != "model" or out.named.split("+")[0] not in RIGID_BODY_EFFECTS or not form_gages:
        return False
    loc = out.location or {}
    gages = set(loc.get("effect_gages") or loc.get("gages") or [])
    flex = {g for f in findings if f["check"] == "flex" for g in f["gages"]}
    faulty = {g for f in credible(findings) if f.get("layer") == Layer.SENSOR for g in f["gages"]}
    return bool(gages) and gages <= flex and not gages & faulty


def answer(model: str | None, candidates: list[dict], where: dict | None, form_gages: set[int],
           findings: list[dict], form_modes: Sequence[tuple[float, Sequence[int]]] = (),
           splits: Sequence[dict] = (), coupled: Sequence[dict] = ()) -> Answer:
    """The one report's answer (:class:`Answer`), what ``ramdaq gap`` prints and the benchmark
    scores: the model layer's (:func:`model_answer`), which a credible data-only finding
    (:func:`credible`) replaces when the model names no effect or blames a sensor (the data layer
    rests on the recorded values and the gages' positions alone), and when the model says
    "unexplained" and a finding overrides it (:func:`overriding_unexplained`). A named linear
    effect (structure, excitation) gives way only to a nonlinearity whose law the decays told
    (:func:`told_law`) well above chance: no linear model update makes a decrement grow as
    1/amplitude or a frequency move with it (issue 17: a modal friction trial read Coulomb's law
    at 20.5x its chance level while the model named hull_coupling). Of several, the
    strongest against its chance level answers. Before everything, a dead gage answers, as a gain
    of zero there (:func:`dead_first`); then, before all of these, a line found before the
    blows well above chance answers ambient_tone (:func:`ambient_first`); on a rig left with form
    error (``form_gages``), a sensor finding or a second blow whose own correction closes half its
    residual held out outranks a structural update (:func:`held_out_data`); a second blow that
    does not is not credible (:func:`fails_held_out`). ``form_modes``: the modes the calibrated rig
    still misses, as :func:`model_answer` reads them. ``splits``: the model level's modes split in
    two (:meth:`~ramdaq.analysis.gap.rigfit.ModelLevel.splits` as JSON: two identified modes of one
    shape where the calibrated rig has one), which answer a gap the model leaves unexplained
    (before the form error would make it "none") when no data-only finding overrides it, the
    trial is homogeneous across blows (:func:`not_homogeneous`) and no frequency moves with the
    amplitude (:func:`stiffness_laws`).
    ``coupled``: the model level's hull modes the rudder does not ride rigidly or rides as the
    rig's stock carries it (:meth:`~ramdaq.analysis.gap.rigfit.ModelLevel.coupled` as JSON), which
    answer "hull_coupling" where the layers would otherwise say "none" (no gap, or model form) or
    "unexplained" (also a data-only "unexplained" that stands less far above its chance level,
    :func:`coupled_over_data`), and place the model's own hull_coupling at that mode
    (:func:`coupled_answer`). A gage's phase read at a coupled mode is no timing finding there
    (:func:`phase_at_coupled`). Its records of kind "tiller" (the stock's top turning with the
    rudder, :func:`~ramdaq.analysis.gap.modal_level.stock_turns`) are no hull mode: they answer
    "tiller" where the rest answers "none" or "unexplained" by the model (:func:`turned_stock`)."""
    if dead := dead_first(findings):
        return _data_answer(dead[0], candidates, findings)
    findings = [second_blow_held(f, candidates) for f in findings if not shift_not_grown(f)]
    turns = [c for c in coupled if c.get("kind") == "tiller"]
    # a coupled "hull mode" on a line the blows switch on is that line, which the free model fits
    # with a pole of almost no damping and the rig lacks (issue 17, modal benchmark seed 562002:
    # mains pickup at 60, 180 and 300 Hz read as hull modes coupled at 7000x their chance level,
    # answered "hull_coupling" over the line found at 4.7x)
    coupled = [c for c in coupled if c not in turns and not on_switched_line(c["f_hz"], findings)]
    model, coupled = unrung_hull(model, candidates, coupled, form_gages)
    if coupled:
        findings = [f for f in findings if not phase_at_coupled(f, coupled)]
    out = _answer(model, candidates, where, form_gages, findings, form_modes, splits)
    if coupled and (out.by == "model" and out.named in ("none", "unexplained", "hull_coupling")
                    or coupled_over_data(out, coupled)):
        # the effect search's own hull_coupling may sit at a residual peak the rig's form leaves
        # (modal dev 59000: named at 22.7 Hz on rudder gages, the coupled mode at 6.0 Hz on the
        # hull's): the identified coupled mode says where the coupling is. A coupled mode is its
        # own test against its own chance level, so it answers also where the map's gap stays
        # below z_gap (issue 17: the truth family's hull couplings of size 0.05, benchmark seed
        # 501005 and holdout seed 901005, rang a driven hull mode at 9.1 and 6.2 Hz in every
        # blow, the map's largest z 3.7 and 7.7, and were answered "no effect")
        return coupled_answer(max(coupled, key=lambda c: c["statistic"] / c["chance_level"]), candidates)
    return turned_stock(out, turns, candidates)


GROWTH_Z = float(scipy.stats.norm.isf(P_CHANCE))
"""The z past which an early-less-late frequency shift grows with the blow, in its own sense
(:func:`shift_not_grown`): the one-sided normal ``P_CHANCE`` quantile, 3.09 -- one test, the
mode the shift's own chi-square chose, as
:func:`~ramdaq.analysis.gap.homogeneity.fades_with_blow` reads the opposite sense."""


def shift_not_grown(f: dict) -> bool:
    """Whether data-only finding ``f`` (as JSON) is the homogeneity check's early-less-late
    frequency shift (:func:`~ramdaq.analysis.gap.homogeneity.early_shift`, with
    ``shift_per_doubling_z``) whose shift does not grow with the blow beyond chance: its slope
    per doubling of the blow not of its size's sign at a z past :data:`GROWTH_Z`.

    The finding reads an amplitude-dependent stiffness, and that law predicts its own second
    statistic: the longer a crack stays open or a stop in contact, the more the early window
    moves, so a blow twice the size shifts it more (the stored modal cracks and rattles of both
    seed sets: z 4.4 to 63 in their own sense). A shift the same at every blow size is a
    difference between the windows that a linear structure scales with the blow (a pole or a
    line the free model does not hold, beating with the mode early and not late) -- no
    stiffness law, and no evidence of where an effect acts. Set aside before the layers weigh
    the findings (issue 17: modal check seed 162003, mains pickup at 60 Hz on gages 13, 14, read
    "23.13 Hz 3.0 % lower early" on gages 1, 2, 3, 6 at 3.8x its chance level, its slope
    -0.03 % per doubling at z -0.07, answered over the switched line at 2.4x on gages 13, 14)."""
    more = f.get("more") or {}
    if f.get("check") != "homogeneity" or more.get("shift_per_doubling_z") is None:
        return False
    z, size = _number(more["shift_per_doubling_z"]), _number(more.get("frequency_change"))
    return not (math.isfinite(z) and z * size > 0 and abs(z) > GROWTH_Z)


def _number(v: dict | float | None) -> float:
    """A finding's ``more`` entry as JSON (``{"value": ..., "unit": ...}``) or a plain number, as
    a float; NaN where absent or null (no slope measured)."""
    v = v["value"] if isinstance(v, dict) else v
    return math.nan if v is None else float(v)


def turned_stock(out: Answer, turns: Sequence[dict], candidates: list[dict]) -> Answer:
    """The answer "tiller" from the model level's stock turning with the rudder (``turns``, as
    JSON, :func:`~ramdaq.analysis.gap.modal_level.stock_turns`), where the model layer would
    otherwise say "none" (no gap, or the gap taken for the rig's form) or "unexplained": the
    stock's top turns with the rudder in phase, by a share that grows with frequency, while the
    stock twists linearly between them -- a steering gear of finite stiffness, which every rig
    with a rigid gear leaves at zero whatever its constants (a +-25 % error of masses,
    inertias and stiffnesses moves the modes, not the twist's kinematics), so the calibration
    that absorbs the lowered torsion mode does not absorb it. Placed at its gages and mode,
    all windows; its closure the effect search's tiller's. ``out`` unchanged otherwise (issue 17:
    the truth family's tillers of size 0.1-2 answered "none" with the rig calibrated to their
    modes, the stock's top turning by 0.09-0.78 of the rudder's rotation; development seeds
    1001-1003, 1005 of ``gap-benchmark --effects tiller``)."""
    if not turns or out.by != "model" or out.named not in ("none", "unexplained"):
        return out
    t = max(turns, key=lambda c: c["statistic"] / c["chance_level"])
    cd = next((x for x in candidates if x["name"] == "tiller"), None)
    loc = {"gages": list(t["gages"]), "window": "all", "band_hz": t["f_hz"], "effect_mode_hz": t["f_hz"],
           "band": f"{t['f_hz']:.1f} Hz"}
    return Answer("tiller", "model", loc, cd["closed_held"] if cd else None)


def unrung_hull(model: str | None, candidates: list[dict], coupled: Sequence[dict],
                form_gages: set[int]) -> tuple[str | None, list[dict]]:
    """The model's choice and its coupled hull modes (``coupled``, as JSON) as the answer reads
    them: the hull lines (``kind`` "line", :func:`~ramdaq.analysis.gap.modal_level.extra_lines`)
    set aside -- a hull mode the rig lacks that the rudder rides is no coupling alone (clean
    modal-family trials ring two or three hull modes) -- and the effect search's hull_coupling
    (its first term) set aside for "unexplained" on a rig left with form error (``form_gages``)
    when no flexibly coupled mode backs it and no identified line rings within a factor 1.25 of
    its mode (``effect_mode_hz``): the search places the mode within +-25 % of a residual peak and
    the stock's coupling moves it by up to that. An added hull mode with free frequency,
    stiffness and two tilts is the most flexible update in the library; on a rig with form error
    it closes up to half the held-out gap of a clean trial, so its closure there is no evidence:
    a mode it adds that the trial does not ring is the freedom fitting the form error (issue 17:
    a modal no-effect trial answered hull_coupling; modal development seeds 51000 and 51001, 50
    and 44 % closed at 83.8 and 21.3 Hz, their lines at 10.2 and 7.3 Hz, are set aside; 51005's,
    43 % at 17.1 Hz beside a 14.9 Hz line, is not; the right hull_coupling answers of the truth
    family's development and check seeds 2003, 101001 and 101004 sit 3-7 % from a line)."""
    flexible = [c for c in coupled if c.get("kind", "flexible") != "line"]
    lines = [c["f_hz"] for c in coupled if c.get("kind") == "line"]
    c = next((x for x in candidates if x["name"] == model), None)
    f = (c or {}).get("location", {}).get("effect_mode_hz") if model else None
    if (model and model.split("+")[0] == "hull_coupling" and form_gages and not flexible and f
            and not any(abs(math.log(h / f)) <= math.log(1.25) for h in lines)):
        return "unexplained", flexible
    return model, flexible


def coupled_over_data(out: Answer, coupled: Sequence[dict]) -> bool:
    """Whether the model level's strongest coupled mode (``coupled``, as JSON) answers before a
    data-only finding that answered "unexplained" (``out``): the coupled mode stands further
    above its own chance level (its statistic over its chance level, each a chi-square ratio at
    its Bonferroni-corrected 1e-3) than the finding does above its own. Both are tests against
    their own chance level, and of several findings the strongest against its chance level
    answers, as everywhere in the layers. A coupled mode is a decaying mode that every blow
    rings, the hull's by most of its energy, which the calibrated rig lacks and which the
    rudder's gages do not ride rigidly -- what a hull mode coupled through the stock makes and
    no +-25 % change of the rig's constants (which only moves the modes the rig has) can
    (issue 17: modal development seed 59004,
    a 28.5 Hz coupled mode at 14000x its chance level answered "unexplained" by gage 2's phase
    that no one time skew fits, at 7.1x; check seed 158004, a 95.9 Hz coupled mode at 19600x
    beside the 24.5 Hz mode's frequency read 2.9 % lower early than late at 2.4x, an
    amplitude-dependent stiffness law just past :data:`PRECEDENCE_STRENGTH`). A law the decays
    told is weighed the same way, by its strength: a data-only chance level assumes the free
    linear model is the whole trial, and no stored trial of another class holds a coupled mode
    (the 222 development trials of both families, and the check seeds' hull-coupling and
    no-effect trials: coupled modes in 4 of 6 and 3 of 6 hull-coupling trials, in no other).
    False when the data layer did not answer, or answered a library effect."""
    if out.by != "data" or out.named != "unexplained" or not out.finding or not coupled:
        return False
    return max(c["statistic"] / c["chance_level"] for c in coupled) > strength(out.finding)


def phase_at_coupled(f: dict, coupled: Sequence[dict]) -> bool:
    """Whether data-only finding ``f`` (as JSON) is a phase misfit (``chain_misfit``: a gage's
    phase off the other gages' that no one time skew fits) read at one of the model level's
    coupled hull modes (``coupled``, as JSON: one of the finding's modes within that mode's
    half-power bandwidth ``2 zeta f``, where two reads of one pole agree).

    The misfit's chance level assumes real mode shapes: each gage in or out of phase with the
    others, as a classically damped structure's modes are. A hull mode the rudder does not ride
    rigidly, with the hull's own damping and beside a rudder mode, is damped
    non-proportionally, and such a pair's shapes are complex: each gage's phase departs from
    0 or pi by an amount set by where it sits, which no one delay of its channel fits. The
    coupling makes that departure, so it is not evidence against a fixed channel (issue 17:
    modal development seed 59004, a hull mode at 28.47 Hz coupled at 14000x its chance level,
    read as gage 2's phase misfit at 7.1x on the 24.9 and 28.4 Hz modes and answered
    "unexplained" over the model's hull_coupling)."""
    if f["check"] != "chain_misfit":
        return False
    return any(abs(m - c["f_hz"]) <= 2 * c.get("zeta", 0.0) * c["f_hz"]
               for m in f.get("mode_hz") or [] for c in coupled)


def coupled_answer(c: dict, candidates: list[dict]) -> Answer:
    """The answer "hull_coupling" from the model level's coupled mode (as JSON), placed at its
    gages and mode, all windows (the mode rings through the decay); its closure the effect
    search's hull_coupling's."""
    cd = next((x for x in candidates if x["name"] == "hull_coupling"), None)
    f = c["f_hz"]
    loc = {"gages": list(c["gages"]), "window": "all", "band_hz": f, "effect_mode_hz": f,
           "band": f"{f:.1f} Hz"}
    return Answer("hull_coupling", "model", loc, cd["closed_held"] if cd else None)


def _answer(model: str | None, candidates: list[dict], where: dict | None, form_gages: set[int],
            findings: list[dict], form_modes: Sequence[tuple[float, Sequence[int]]],
            splits: Sequence[dict]) -> Answer:
    out = model_answer(model, candidates, where, form_gages, form_modes)
    named = out.named
    if named == "ambient_tone" and (d := declared_tone(findings, out.location)):
        return Answer("none", "data", out.location, None, d)    # the environment the rig declares
    if first := (ambient_first(findings) if named.split("+")[0] != "ambient_tone" else []) or flat_tops_first(
            findings, named):
        return _data_answer(max(first, key=strength), candidates, findings)
    if form_not_sensor(out, findings, form_gages):
        out, named = Answer("none", "model", None, None), "none"
    overriding = [f for f in overriding_unexplained(findings) if data_effect(f)]
    if (model == "unexplained" and splits and not overriding
            and not not_homogeneous(at_splits(findings, splits))
            and not stiffness_laws(findings) and not early_nonlinear(findings)):
        # a split is two modes of a linear structure; where the blows of different force show
        # an amplitude-dependent structure, two poles of one shape are its two stiffnesses (a
        # crack open and closed: modal dev 61000's 11.5 Hz pair 18.7 % apart)
        return split_answer(max(splits, key=lambda s: s["mac"]), candidates)
    if named == "unexplained":
        finds = overriding or data_unexplained(findings)
        if not finds and (form_gages or blows_tail(where)):
            # the model level's gap sits in the rig's form error and nothing in the data says
            # the trial is not linear, time-invariant and coherent: model form, not an effect
            # (issue 17: a clean modal trial's map cell at its 37.05 cap on gages 6, 3)
            out = Answer("none", "model", None, None)
    elif contra := friction_contradicted(named, findings):
        finds = contra
    else:
        finds = [f for f in credible(findings) if data_effect(f)
                 and (f["check"] not in NOT_LTI and data_effect(f) != "unexplained"
                      or strength(f) >= PRECEDENCE_STRENGTH)]
        laws = [f for f in finds
                if (told_law(f) or f["check"] in NOT_LTI) and strength(f) >= PRECEDENCE_STRENGTH]
        same = [strength(f) for f in finds if data_effect(f) == named]
        lti = [f for f in laws if f["check"] in NOT_LTI]
        if same and not (lti and max(map(strength, lti)) > max(same)):
            return out
        if same:
            # the data confirm the model's effect, but a stronger failure of time invariance
            # (no fixed sensor or structure makes one) answers (issue 17: a gain drifting by
            # 60 % over the trial read as a high-pass on its gage at 6x its chance level)
            finds = lti
        elif named != "none" and named.split("+")[0] not in SENSOR_EFFECTS | {"gage_alignment"}:
            # a named effect a data-only check looked for and did not find (its counterpart
            # check ran: the data layer answered) does not beat a strong finding on other gages
            # (issue 17: split_mode+double_hit on gages 12, 10, 15, the double hit not found,
            # over gage 3's gain at 37x its chance level)
            unconf = findings and any(COUNTERPART.get(e) not in {None, *(f["check"] for f in findings)}
                                      for e in named.split("+"))
            on = set((out.location or {}).get("gages") or [])
            strong = [f for f in finds if unconf and strength(f) >= PRECEDENCE_STRENGTH
                      and not set(f["gages"]) & on]
            held = [f for f in held_out_data(findings) if form_gages or f["check"] in HELD_OUT_EXCITATION]
            if not laws and not strong and not held:
                return out
            finds = laws or strong or held
    if out.named == "none":
        finds = beyond_form(finds) or early_nonlinear(findings)
    finds = [f for f in finds if not form_shape_unsupported(f, candidates)]
    if not finds:
        return out
    f = max(finds, key=strength)
    raw = [g for g in finds if reads_recorded_values(g) and strength(g) >= PRECEDENCE_STRENGTH]
    if data_effect(f) == "unexplained" and not told_law(f) and f["check"] not in NOT_LTI and raw:
        # a slope across the blows whose law the decays did not tell names no cause; a flat top
        # well above chance is one, read on the recorded values (modal check seed 153001:
        # clipping on gages 4 and 6 at 2.6x, a slope on the hull's gages at 6.3x, answered
        # "unexplained"; the same check's slope reaches 2.5x on a clean modal trial)
        f = max(raw, key=strength)
    elif law := slope_placed_by_law(f, finds):
        f = law
    return _data_answer(f, candidates, findings)


def slope_placed_by_law(f: dict, finds: list[dict]) -> dict | None:
    """The stiffness law (as JSON, :func:`stiffness_laws`: a frequency the decays themselves show
    moving with the amplitude, at least :data:`PRECEDENCE_STRENGTH` times its chance level) among
    the answering findings ``finds`` that places an "unexplained" answer instead of ``f``, when
    ``f`` is a slope across the blows whose law the decays did not tell (a homogeneity finding,
    not :func:`told_law`); the strongest of them; None otherwise.

    The two are not readings of one kind. A mode's amplitude that does not grow as the blow is
    read against a reference (:func:`~ramdaq.analysis.gap.homogeneity.reference_level`: the
    median of the other modes' levels, the best-measured mode's where fewer than three modes are
    read; stored trials before it, the best-measured mode's): against one mode it says that the
    two modes' ratio changes with the blow, not which of them departs from linearity -- where the
    reference is the mode an amplitude-dependent stiffness acts on, a linear mode reads as growing
    as the blow to a power 1/p, and the finding names the linear mode's gages, which its strength
    against its own chance level does not correct. A law told within each free decay reads one
    mode's own backbone, cycle by cycle, in its own band: the mode it names is the one that
    departs, and its gages are where that mode shows. So where both stand past the bar an
    "unexplained" answer needs, the slope says that the trial is not homogeneous and the law
    says where; the answer is "unexplained" either way. Coulomb's law (friction, a library
    effect) is left to the rules that name it. Issue 17: a modal crack on a 25.1 Hz mode (check
    seed 160002) was answered at the 7.26 Hz mode's gages by its amplitude "as the blow to the
    power 0.38" at 15.8x its chance level, beside the 25.0 Hz mode's frequency falling 10 % as
    its amplitude grows at 2.0x; a modal mains pickup at 60 Hz on gages 8, 9 (check seed
    162004) at the 13.47 Hz mode's gages 1-3 by a power -0.40 at 33.8x, beside the 60 Hz line's
    own law at 10.6x on gages 8, 9. The same seeds drawn without their effect show neither
    slope."""
    if f.get("check") != "homogeneity" or told_law(f):
        return None
    laws = stiffness_laws(finds)
    return max(laws, key=strength) if laws else None


def beyond_form(finds: list[dict]) -> list[dict]:
    """The data-only findings (as JSON) that may answer where the model level found the gap to be
    the rig's form ("none"): those at :data:`PRECEDENCE_STRENGTH` times their chance level or more.
    A data-only statistic's chance level assumes the free linear model is the whole trial (every
    mode in it, white noise); a weak mode it leaves out or coloured noise puts a finding past
    its level more often than stated, and with the model level's gap already in the rig's form
    nothing else speaks for a fault. Stored development/check trials (re-scored): four clean
    ones answered an ambient tone at 1.0-1.35x its chance level (development seeds 1019, 1022,
    1030, 1052), modal development seed 64002 a gain on gage 14 at 1.8x (the truth: a resonance
    on gage 6), a crack (check seed 160000) friction at 1.03x; one gain fault of 0.5 (check
    seed 151000) was named only at 1.83x and is lost. The bar is the one the model level's
    own "unexplained" asks of a data finding; a strong finding answers as before."""
    return [f for f in finds if strength(f) >= PRECEDENCE_STRENGTH]


def form_shape_unsupported(f: dict, candidates: list[dict]) -> bool:
    """Whether a model-form finding of the data layer that names a sensor effect (the rigid-body
    check's ``rigid_body``: one gage's gain differing from mode to mode, named gage_alignment)
    is not told from the structure's own form: the model layer's candidate of that effect,
    fitted on the other impacts, closes less than
    :data:`~ramdaq.analysis.gap.verdict.UNEXPLAINED_CLOSURE` of the held-out gap
    (:func:`~ramdaq.analysis.gap.verdict.closed_share`; measured, else nothing is set aside).

    The check's statistic, the chi-square of the per-mode gains about their mean (K - 1 dof),
    has its chance level on a body that moves rigidly in every mode it reads; a tilted axis
    (cos and sin of the tilt mixed by each mode's motion) and a flexible part at the gage (its
    elastic shape, which the rig's rigid body lacks) both make the gain differ by mode, and the
    finding names both. The held-out closure tells them apart: a tilt is one fixed law of the
    channel, so the alignment fitted on three blows explains the fourth (development trials
    9003, 9004: 100 % held out), while a body's elastic shape, which the rigid-body rig fits as a
    tilt, is not that law and the fit leaves the held-out gap (issue 17, modal development seed
    51003, a clean trial: gage 13 at 22.9x its chance level beside the rudder's flex finding at
    85x, the model's gage_alignment closing 9 %). The same a-priori half the model layer asks of
    an effect before it names one (:func:`fails_held_out` for the checks that measure their own
    closure, which this check does not)."""
    if f.get("layer") != Layer.MODEL_FORM or data_effect(f) not in SENSOR_EFFECTS:
        return False
    cd = next((c for c in candidates if c["name"] == data_effect(f)), None)
    if cd is None:
        return False
    measured = [v for v in (cd.get("closed_held"), cd.get("closed_fit"))
                if v is not None and math.isfinite(float(v))]
    return bool(measured) and closed_share(cd) < UNEXPLAINED_CLOSURE


def friction_contradicted(named: str, findings: list[dict]) -> list[dict]:
    """The homogeneity check's findings (as JSON) beyond their chance level that contradict the
    model's named friction: its decays tell a law that is not Coulomb's (:func:`told_law`, not
    :func:`is_friction`: a frequency moving with the amplitude, which a Coulomb oscillator
    keeps). Friction's own data-only counterpart read the decays and found another law, so the
    model's friction -- a Coulomb law fitted to the rig's model -- is not what the data show
    (issue 17, modal check seed 160000: a crack named friction); empty when the model names
    no friction."""
    if named.split("+")[0] != "friction":
        return []
    return [f for f in findings if told_law(f) and not is_friction(f) and strength(f) > 1]


TAIL_SHARE = 0.5
"""A pre-window gap is the blows' own ringing when the first segment's pre window -- before any
blow -- holds less than half the fitted segments' mean excess per segment at its cells (and
nothing beyond chance, :data:`~ramdaq.analysis.gap.evidence.GAP_CELL_Z`): a line or noise the
blows do not make is in every pre window alike (share ~1, its scatter small for a gap that is
beyond ``z_gap``), a decay carried over from the previous blow is in none before the first
(share ~0). Half is the a-priori midpoint, not tuned."""


def blows_tail(where: dict | None) -> bool:
    """Whether an unexplained gap (:func:`~ramdaq.analysis.gap.verdict.gap_where`) is the
    previous blows' ringing mis-modelled in the next segment's pre window: in the pre window,
    and absent before the first blow (``before_blows``: cell z within chance and under
    :data:`TAIL_SHARE` of the per-segment excess). Seconds after a blow a lightly damped mode
    still rings (the truth family's ALBACORE-in-air 87.3 Hz mode: zeta 0.05 %, 1/e in 3.7 s, a
    blow every 3-6 s), and its tail carries the model's errors grown with time: a frequency off
    by ``df`` is ``2 pi df t`` out of phase (0.04 Hz, 0.05 %, within
    :data:`~ramdaq.analysis.gap.rigfit.FORM_F`'s 0.1 %, is 1 rad at 4 s: a residual the size of
    the tail), a decay rate off by ``d`` is ``d t`` of it. The replicates carry amplitude and
    decay tolerances, not frequency ones, so the map calls it beyond chance; it is the rig's
    form, not an effect (issue 17: a clean truth-family trial "unexplained: band 87.4 Hz, pre
    window, excess 9.4e5 noise variances" while the model level left no form error's gages).
    A gap stored without ``before_blows`` is not one."""
    b = (where or {}).get("before_blows")
    return (bool(b) and where["window"] == "pre" and b["z"] <= GAP_CELL_Z
            and math.isfinite(b["share"]) and b["share"] < TAIL_SHARE)


def stiffness_laws(findings: list[dict]) -> list[dict]:
    """The homogeneity check's findings (as JSON) of a frequency that moves with the amplitude
    (a told law that is not Coulomb's: :func:`told_law`, :func:`is_friction`) at least
    :data:`PRECEDENCE_STRENGTH` times their chance level. They answer "unexplained" before the
    model level's split mode: two linear poles of one shape are what the free model and the
    calibrated rig fit to one mode whose frequency moves within each blow (issue 17: the modal
    family's crack on a 62.6 Hz mode, dev seed 61000, was fitted a 13.56/13.61 Hz pair beside
    it), while no pair of linear poles makes a frequency that changes with the blow's size."""
    return [f for f in findings if told_law(f) and not is_friction(f) and strength(f) >= PRECEDENCE_STRENGTH]


PER_GAGE = frozenset({"gain", "rigid_body", "time_skew", "highpass", "clipping", "noisy", "dead"})
"""Data-only sensor checks that test each gage's channel on its own, one finding a gage."""


def _data_answer(f: dict, candidates: list[dict], findings: Sequence[dict] = ()) -> Answer:
    """The answer a data-only finding ``f`` (as JSON) gives, placed at its gages and window; a
    check of each gage on its own (:data:`PER_GAGE`) that found the same fault on other gages
    (credible ``findings``, :func:`credible`) names them too, the strongest first (a 1.5 Hz
    high-pass on gages 1-4, each found at 1.47-1.51 Hz, was answered at gage 4 alone: new
    user, 2026-11-29)."""
    eff = data_effect(f)
    cd = next((c for c in candidates if c["name"] == eff), None)
    gages = list(f["gages"])
    if f["check"] in PER_GAGE:
        for g in sorted((x for x in credible(list(findings)) if x["check"] == f["check"]),
                        key=strength, reverse=True):
            gages += [n for n in g["gages"] if n not in gages]
    loc = {"gages": gages, "window": DATA_WINDOW.get(f["window"], f["window"]), "band_hz": None,
           "effect_mode_hz": f["mode_hz"][0] if f["mode_hz"] else None}
    return Answer(eff, "data", loc, data_closure(f, cd), f)


def data_unexplained(findings: list[dict]) -> list[dict]:
    """The credible data-only findings (as JSON, :func:`credible`) that name no library effect
    but a failure of the linear, time-invariant measurement (:func:`data_effect` "unexplained":
    an amplitude-dependent structure, a gain changing between impacts, a line switched on by
    the blows), at least :data:`PRECEDENCE_STRENGTH` times their chance level: the data-only
    evidence an "unexplained" answer rests on, at its own gages."""
    return [f for f in credible(findings)
            if data_effect(f) == "unexplained" and strength(f) >= PRECEDENCE_STRENGTH]


def early_nonlinear(findings: list[dict]) -> list[dict]:
    """The double-hit check's findings (as JSON) at least :data:`PRECEDENCE_STRENGTH` times their
    chance level whose second blow explains no held-out blow (:func:`fails_held_out`), read as
    what they measure: the early windows depart, well above chance, from the free *linear*
    model's response to one blow, and not as one fixed second blow would make them -- so the
    blows' early responses are not one linear response scaled by the blow. A linear structure
    with a linear gage set (any rig update: a split or added mode, a coupled hull) responds to
    every blow in proportion (the free model's poles hold its modes, their amplitudes are free
    per blow), and a second blow of the ram repeats blow after blow (it closes its held-out
    residual: the modal double hits 0.71-0.84); an amplitude-dependent stiffness (a breathing
    crack, a stop or rattle) responds to the larger blows differently in the first cycles, where
    its amplitude is largest. Returned as "unexplained" findings (check ``early_nonlinear``,
    layer nonlinearity, early window, at the double hit's statistic and chance level), which
    answer where the layers would otherwise say "none" (the model's gap taken for its form)
    and set the model level's split aside as :func:`stiffness_laws` do (issue 17: the modal
    family's cracks and rattles read 300-700x as double hits closing -0.03 to -19 of their
    held-out residual, dev seeds 61000, 61001, 62001, check seeds 160000, 161000; no clean trial
    of the stored dev and check runs holds a double hit at all)."""
    out = []
    for f in findings:
        if f["check"] == "double_hit" and strength(f) >= PRECEDENCE_STRENGTH and fails_held_out(f):
            text = (f"the early windows depart from one linear response to each blow ({strength(f):.0f}x "
                    "the chance level of the second-blow test, and no second blow explains the held-out "
                    "blows): the structure responds to larger blows differently -- an amplitude-dependent "
                    "stiffness (a crack, a stop); no library effect")
            out.append(f | {"check": "early_nonlinear", "layer": Layer.NONLINEARITY.value, "text": text})
    return out


def data_closure(f: dict, cd: dict | None) -> float | None:
    """The closure a data-only finding (as JSON) answers with: its own -- the share of its
    check's residual (the data layer's gap, not the rig model's) its correction, fitted on the
    other impacts, closes on the held-out ones (:attr:`~ramdaq.analysis.gap.datamodel.Finding.closed_held`)
    -- when measured; else the model candidate's of the same effect (``cd``, a check that
    measures none, as the homogeneity's), else None. On a perturbed rig and a structure that is
    not the simulator the model-level gap is the rig's form error, which a gain or a skew closes
    ~0 % of (issue 17: the modal family's sensor layer read 0.9 % median)."""
    own = held_closure(f)
    if own is not None:
        return own
    return cd["closed_held"] if cd else None
