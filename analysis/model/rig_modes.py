"""What a rig's model predicts, in the terms a trial engineer checks before the first blow:
its modes in air and in water, the predominant one, and Report 1836's Eq 18 applied to them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .response import ModelModes, modal_form, model_modes, predominant_mode
from .rig import Rig
from .structure import build_model


@dataclass(frozen=True)
class MediumModes:
    """The model's modes in one medium and the index of the predominant one."""

    medium: str
    table: ModelModes
    predominant: int
    added: dict[str, float]

    @property
    def predominant_hz(self) -> float:
        return float(self.table.frequency_hz[self.predominant])


def modes_in(rig: Rig, medium: str) -> MediumModes:
    """Modes of ``rig`` in ``medium``, with the predominant mode after the rig's default blow."""
    r = rig.with_medium(medium)
    model = build_model(r)
    form = modal_form(model)
    i = predominant_mode(form, r.impact.peak_force_N, r.impact.duration_s, r.impact.location_m,
                         r.impact.direction)
    return MediumModes(medium, model_modes(form), i, model.added)


@dataclass(frozen=True)
class Eq18Check:
    """Eq 18, ``m_vir = m_a [(f_air / f_water)^2 - 1]``, on the model's predominant frequencies,
    beside the added mass the model itself carries (Eq 19). Masses in kg, frequencies in Hz."""

    f_air_hz: float
    f_water_hz: float
    m_a_kg: float
    m_vir_eq18_kg: float
    m_vir_model_kg: float

    @property
    def difference(self) -> float:
        """(Eq 18 - model) / model."""
        return self.m_vir_eq18_kg / self.m_vir_model_kg - 1


def eq18_check(rig: Rig) -> Eq18Check:
    air, water = modes_in(rig, "air"), modes_in(rig, "water")
    m_a = rig.rudder.mass_kg
    ratio = air.predominant_hz / water.predominant_hz
    return Eq18Check(air.predominant_hz, water.predominant_hz, m_a, m_a * (ratio**2 - 1),
                     water.added["m_vir"])


RIG_SPREAD_RATIO = 1.3
"""Farthest a structure's mode lies from its rig model's nearest mode, as a frequency ratio, when
the rig describes it: masses, inertias and stiffnesses each within +-25 % (the spread the gap
diagnosis calibrates over) move a frequency, sqrt(k / m), by at most sqrt(1.25 / 0.75) = 1.29."""


@dataclass(frozen=True)
class RigAgreement:
    """The record's predominant mode against the rig model's modes in the trial's medium:
    ``nearest_hz`` the model mode nearest ``f_record_hz`` in ratio, ``ratio`` the larger over
    the smaller (>= 1); ``agrees`` when within :data:`RIG_SPREAD_RATIO`."""

    medium: str
    f_record_hz: float
    nearest_hz: float
    predominant_hz: float
    ratio: float

    @property
    def agrees(self) -> bool:
        return self.ratio <= RIG_SPREAD_RATIO

    def warning(self) -> str | None:
        """One line when the rig does not describe the record, else None."""
        if self.agrees:
            return None
        return (f"the rig does not describe this record: its predominant mode, "
                f"{self.f_record_hz:.3g} Hz, is {self.ratio:.2f}x from the rig model's nearest "
                f"mode in {self.medium} ({self.nearest_hz:.3g} Hz; predominant "
                f"{self.predominant_hz:.3g} Hz), beyond the {RIG_SPREAD_RATIO}x a rig within "
                f"+-25 % allows: the masses, damping constants and virtual inertias rest on the "
                f"rig (a wrong rig file? `ramdaq rig fit` tunes one)")


def rig_agreement(rig: Rig, f_record_hz: float) -> RigAgreement:
    """How near the rig model's modes in ``rig.medium`` lie to a record's predominant mode
    ``f_record_hz`` (Hz); the rig must describe a structure (``rig.structural``)."""
    m = modes_in(rig, rig.medium)
    f = m.table.frequency_hz[m.table.frequency_hz > 0]
    ratios = np.maximum(f / f_record_hz, f_record_hz / f)
    k = int(np.argmin(ratios))
    return RigAgreement(rig.medium, float(f_record_hz), float(f[k]), m.predominant_hz,
                        float(ratios[k]))
