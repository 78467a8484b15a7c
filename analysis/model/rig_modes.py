"""What a rig's model predicts, in the terms a trial engineer checks before the first blow:
its modes in air and in water, the predominant one, and Report 1836's Eq 18 applied to them.
"""

from __future__ import annotations

from dataclasses import dataclass

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
