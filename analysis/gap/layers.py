"""One report from two layers: the data-only findings (:mod:`ramdaq.analysis.gap.sensors`, no
stiffness or mass model) and the model layer's named effect (:mod:`ramdaq.analysis.gap.diagnose`).

Where both speak of the same gages, a sensor finding of the data layer takes precedence: it
rests on the recorded values and the gages' positions and axes alone, while the model layer's
attribution leans on a rig model that is never exact (issue 17: an approximate rig's own errors
were named as one gage's sensitivity). :func:`precedence` says which of the model's attributions
is set aside, and for which gages.
"""

from __future__ import annotations

from dataclasses import dataclass

from .datamodel import Finding, Layer

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


PRECEDENCE_STRENGTH = 2.0
"""A data-only sensor finding overrides the model layer's "unexplained" when its statistic is at
least this many times its chance level (which is already Bonferroni-corrected at ``P_CHANCE``):
well above chance, not a borderline excursion. Stated a priori, not tuned on benchmark seeds."""


def overrides_unexplained(layer: Layer | str, statistic: float | None, chance_level: float | None) -> bool:
    """Whether a data-only finding (its ``layer``, ``statistic`` and ``chance_level``, as a
    :class:`Finding` or its JSON holds them; a JSON ``None`` statistic is infinite) takes
    precedence over the model layer's "unexplained" (issue 17: a high-pass found on four gages
    by their phases was kept "unexplained" because the library effect closed too little of a
    gap the approximate rig also leaves): a sensor finding whose statistic is
    :data:`PRECEDENCE_STRENGTH` times its chance level or more. The model's unexplained
    remainder is then the rig's form, reported beside it."""
    stat = float("inf") if statistic is None else float(statistic)
    level = max(float(chance_level or 0.0), 1e-12)
    return Layer(layer) is Layer.SENSOR and stat >= PRECEDENCE_STRENGTH * level


def overriding_unexplained(findings: list[dict]) -> list[dict]:
    """Of data-only findings as JSON (:meth:`Finding.to_json`), those that take precedence over
    the model layer's "unexplained" (:func:`overrides_unexplained`); none when the data layer
    also found the trial not homogeneous across blows (a nonlinearity): the sensor checks read
    the free *linear* modal model's shapes, which an amplitude-dependent structure bends."""
    if any(f.get("layer") == Layer.NONLINEARITY for f in findings):
        return []
    return [f for f in findings if f.get("layer") in set(Layer)
            and overrides_unexplained(f["layer"], f["statistic"], f["chance_level"])]
