"""The rig file: a trial's hardware and structure, described in TOML, in SI units.

A rig names the 16 gages of Report 1836 (number, body, position, sensing axis, sensitivity, DAQ
channel), the rudder, its stock and the hull's modes, the medium (air or water), the acquisition
settings and a default ram impact. Every recording carries its rig's text, so a recording is
self-describing. The file format is documented in ``recordings/rigs/README.md``.

Coordinates (Report 1836, Figure 1): origin at the rudder's centre of mass, x aft along the chord,
y athwartship, z up along the stock. A rigid body with motions (v, gamma, alpha) about a reference
point moves a point r = (x, y, z) by ``u = (-gamma*y, v + gamma*x - alpha*z, alpha*y)``; with this
sign of alpha, Appendix A's ``d2 = v - z1*alpha`` holds for gage 2 *above* the centre of mass, and
Eq 2 ``alpha = (d6 - d2)/(z1 + z2)`` for gage 6 *below* it.

A wrong rig is refused with :class:`RigError`, a one-line message naming the file and the field.
"""

from __future__ import annotations

import difflib
import math
import re
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from .surface import Surface, SurfaceError, to_surface_frame

AXES: dict[str, tuple[float, float, float]] = {
    "x": (1.0, 0.0, 0.0),
    "y": (0.0, 1.0, 0.0),
    "z": (0.0, 0.0, 1.0),
    "-x": (-1.0, 0.0, 0.0),
    "-y": (0.0, -1.0, 0.0),
    "-z": (0.0, 0.0, -1.0),
}
BODIES = ("rudder", "stock", "hull")
MEDIA = ("air", "water")
N_GAGES = 16
"""Gages of the report's layout (numbers 1-16); a rig may leave some out (a field system of 8
channels): the report's steps that need them are then not computed, and say so."""
MIN_GAGES = 3
"""Fewest gages a structural rig may have: three positions and axes pin a body's motion in its
plane of bending and twist, the least the modal comparison and the gap diagnosis work with."""
MAX_CHANNELS = 64
"""Most channels (gages and force channels) a rig may have."""
FORCE_UNITS: dict[str, float] = {"N": 1.0, "kN": 1000.0, "lbf": 4.4482216152605}
"""Units a force channel may be given in, with newtons per unit (lbf: the avoirdupois pound-force)."""
GAGE_UNITS = ("m/s^2", "g")
"""Units a gage may be given in by an imported file that states none."""
STRUCTURE_TABLES = ("rudder", "stock", "damping", "hull", "impact")
"""The tables that describe the structure; a rig with none of them is a channels-only rig."""
ALIGN_TOL_M = 1e-3
"""Gages that the report's equations pair (2 and 6 on a vertical, 4 and 8 on a horizontal) must
line up to this tolerance: 1 mm is well inside how precisely a gage is placed on a rudder."""

MAX_COORDINATE_M = 100.0
"""Largest coordinate of a gage or of the ram's blow from the centre of mass, m: a ship's rudder
or stern plane with its hull gages fits in a 200 m box; more is a typo or a unit in mm."""


@dataclass(frozen=True)
class Span:
    """The plausible values of one rig number: ``lo`` to ``hi`` in ``unit``, and why."""

    lo: float
    hi: float
    unit: str
    why: str


_LENGTH = Span(1e-3, 100.0, "m", "a model's millimetres to a large ship's control surface")
_INERTIA = Span(1e-6, 1e8, "kg m^2", "a model's surface to a large ship's")
_MODULUS = Span(1e8, 1e12, "Pa", "structural plastics to the stiffest steels")
_DAMPER = Span(0.0, 1e9, "N s/m or N m s/rad", "the report's constants are 1e2 to 1e5")
PLAUSIBLE: dict[str, Span] = {
    "daq.sample_rate_hz": Span(50.0, 51_200.0, "Hz", "the rates the trigger supports"),
    "daq.adc_full_scale_V": Span(1e-3, 1e3, "V", "converter input ranges"),
    "daq.anti_alias_hz": Span(1.0, 25_600.0, "Hz", "below the highest Nyquist frequency"),
    "daq.noise_m_s2_rms": Span(0.0, 100.0, "m/s^2", "an accelerometer's noise, not its signal"),
    "water.density_kg_m3": Span(900.0, 1100.0, "kg/m^3", "fresh water 998, sea water 1025"),
    "rudder.mass_kg": Span(1e-2, 1e6, "kg", "a model's grams to a large ship's control surface"),
    "rudder.Iz_kg_m2": _INERTIA, "rudder.Ix_kg_m2": _INERTIA,
    "rudder.Ixz_kg_m2": Span(-1e8, 1e8, "kg m^2", "a model's surface to a large ship's"),
    "rudder.chord_m": _LENGTH, "rudder.span_m": _LENGTH, "rudder.thickness_m": _LENGTH,
    "rudder.stock_x_m": Span(-100.0, 100.0, "m", "within the control surface"),
    "rudder.attach_z_m": _LENGTH,
    "rudder.added_mass_factor": Span(0.0, 10.0, "1", "1 is Eq 19-21 as printed"),
    "stock.E_Pa": _MODULUS, "stock.G_Pa": _MODULUS,
    "stock.I_m4": Span(1e-14, 10.0, "m^4", "a 2 mm rod to a 3 m solid shaft"),
    "stock.J_m4": Span(1e-14, 10.0, "m^4", "a 2 mm rod to a 3 m solid shaft"),
    "stock.shear_area_m2": Span(1e-8, 100.0, "m^2", "a 2 mm rod to a 3 m solid shaft"),
    "stock.bending_length_m": _LENGTH, "stock.torsion_length_m": _LENGTH,
    "damping.air.C_N_s_per_m": _DAMPER, "damping.air.c_N_m_s_per_rad": _DAMPER,
    "damping.air.c_alpha_N_m_s_per_rad": _DAMPER, "damping.water.C_N_s_per_m": _DAMPER,
    "damping.water.c_N_m_s_per_rad": _DAMPER, "damping.water.c_alpha_N_m_s_per_rad": _DAMPER,
    "hull.modes[].frequency_hz": Span(0.1, 1e4, "Hz", "a ship's hull modes"),
    "hull.modes[].modal_mass_kg": Span(1e-3, 1e10, "kg", "a model's to a large ship's hull"),
    "impact.peak_force_N": Span(1e-3, 1e8, "N", "a modal hammer's to a heavy ram's blow"),
    "impact.duration_s": Span(1e-5, 1.0, "s", "a hammer's tap to a slow ram's push"),
    "ambient[].frequency_hz": Span(0.01, 1e4, "Hz", "a ship's machinery and hull"),
    "ambient[].v_b_amplitude_m": Span(0.0, 1.0, "m", "vibration, not motion"),
    "gages[].sensitivity_V_per_m_s2": Span(1e-6, 10.0, "V per m/s^2",
                                           "accelerometers of 0.01 mV/g to 100 V/g"),
}
"""Ranges outside which a rig's number is an error, not a trial (a mass of 2.87e30 kg is a typo),
by generic path (list indices as ``[]``). Each is wide: it catches units and exponents gone
wrong, not unusual structures."""


class RigError(ValueError):
    """A rig file that cannot describe a trial; the message names the file and field."""


@dataclass(frozen=True)
class ForceChannel:
    """A force channel: a load cell in the ram, or an instrumented hammer. ``name`` is its
    channel name in the stream; ``channel`` the DAQ channel index; ``unit`` the unit its source
    gives (``N``, ``kN``, ``lbf``; the stream is always in N); ``location_m`` where the force acts
    (m, None if not known)."""

    name: str
    channel: int
    unit: str = "N"
    location_m: tuple[float, float, float] | None = None

    @property
    def newtons_per_unit(self) -> float:
        return FORCE_UNITS[self.unit]


@dataclass(frozen=True)
class Gage:
    """One accelerometer.

    ``position_m`` is (x, y, z) in metres from the rudder's centre of mass; ``axis`` the sensing
    direction (``"y"`` athwartship, ``"z"`` vertical, signs allowed); ``sensitivity_V_per_m_s2``
    volts per m/s^2; ``channel`` the DAQ channel index (0-based row of every block); ``unit``
    the unit an imported file gives it in when the file says none (``"m/s^2"`` or ``"g"``; the
    stream is always in m/s^2), None where the rig does not say (m/s^2 is then assumed; see
    :attr:`assumed_unit`).
    """

    number: int
    body: str
    position_m: tuple[float, float, float]
    axis: str
    sensitivity_V_per_m_s2: float
    channel: int
    unit: str | None = None

    @property
    def assumed_unit(self) -> str:
        """The unit an imported file's unlabelled column is read in: :attr:`unit`, else m/s^2."""
        return self.unit or "m/s^2"

    @property
    def direction(self) -> np.ndarray:
        """Unit sensing vector, shape (3,)."""
        return np.array(AXES[self.axis])


@dataclass(frozen=True)
class Rudder:
    """Rigid rudder. Masses kg, inertias kg m^2 about the centre of mass, lengths m.

    ``stock_x_m`` (the report's h) is the x of the stock axis; ``attach_z_m`` (the report's b) the
    height of the rudder-stock attachment above the centre of mass. ``chord_m``, ``span_m``,
    ``thickness_m`` are the report's x-bar, z-bar, y-bar used by Eq 19-21 for the added mass in
    water; ``added_mass_factor`` scales that added mass (1 = Eq 19-21 as printed).
    """

    mass_kg: float
    Iz_kg_m2: float
    Ix_kg_m2: float
    Ixz_kg_m2: float
    chord_m: float
    span_m: float
    thickness_m: float
    stock_x_m: float
    attach_z_m: float
    added_mass_factor: float = 1.0


@dataclass(frozen=True)
class Stock:
    """Flexible stock between the rudder (attachment at z = b) and the hull.

    E, G in Pa; ``I_m4`` area moment of the section; ``J_m4`` torsion constant (the report's J_e);
    ``shear_area_m2`` the effective shear area kappa*A (Timoshenko); lengths in m: ``bending_length_m``
    from the rudder attachment up to the hull attachment in bending, ``torsion_length_m`` likewise
    in torsion.
    """

    E_Pa: float
    G_Pa: float
    I_m4: float
    J_m4: float
    shear_area_m2: float
    bending_length_m: float
    torsion_length_m: float


@dataclass(frozen=True)
class Damping:
    """Viscous damping of the rudder on its stock (Eq 62a, b).

    ``C_N_s_per_m`` acts on v (absolute), ``c_N_m_s_per_rad`` on gamma - gamma_b,
    ``c_alpha_N_m_s_per_rad`` on alpha - alpha_b.
    """

    C_N_s_per_m: float
    c_N_m_s_per_rad: float
    c_alpha_N_m_s_per_rad: float


@dataclass(frozen=True)
class HullMode:
    """One hull mode, seen at the stock's hull attachment.

    ``v_b``, ``gamma_b``, ``alpha_b``: m, rad, rad per unit modal coordinate; ``modal_mass_kg`` the
    generalised mass of that normalisation; ``frequency_hz`` and ``damping_ratio`` of the hull
    alone (dry); ``added_mass_ratio_water`` multiplies the modal mass by (1 + ratio) in water.
    """

    name: str
    frequency_hz: float
    damping_ratio: float
    modal_mass_kg: float
    v_b: float
    gamma_b: float
    alpha_b: float
    added_mass_ratio_water: float = 0.0
    moves_hull: bool = True
    """False for a degree of freedom that moves the stock's top but not the hull around it (a
    tiller on its steering gear): the hull gages do not see it."""


@dataclass(frozen=True)
class Daq:
    """Acquisition front-end: rate Hz, ADC bits and +-full scale V, anti-alias corner Hz and
    order, and the channel noise floor in m/s^2 rms (broadband, before the anti-alias filter)."""

    sample_rate_hz: float
    adc_bits: int
    adc_full_scale_V: float
    anti_alias_hz: float
    anti_alias_order: int
    noise_m_s2_rms: float

    def anti_alias_sos(self, fs_hz: float) -> np.ndarray | None:
        """The anti-alias low-pass (Butterworth of ``anti_alias_order`` at ``anti_alias_hz``) as
        second-order sections at ``fs_hz``, shape (n_sections, 6); None when its corner is not
        below half that rate (or not known: NaN), where it leaves the sampled band alone."""
        if not self.anti_alias_hz < fs_hz / 2:
            return None
        from .. import filters  # here: the rig is read where no filter is needed

        return filters.butter(self.anti_alias_order, self.anti_alias_hz, fs_hz, output="sos")


@dataclass(frozen=True)
class ImpactSpec:
    """A ram blow: half-sine of ``peak_force_N`` lasting ``duration_s`` at ``location_m`` on the
    rudder, pushing along ``direction`` (an axis name)."""

    peak_force_N: float
    duration_s: float
    location_m: tuple[float, float, float]
    direction: str = "y"


@dataclass(frozen=True)
class Ambient:
    """Steady vibration of hull mode ``hull_mode`` (1-based) at ``frequency_hz``, sized so the
    hull moves ``v_b_amplitude_m`` at the stock: present before, during and after every hit."""

    hull_mode: int
    frequency_hz: float
    v_b_amplitude_m: float


@dataclass(frozen=True)
class Rig:
    """A whole trial description. See the module docstring for coordinates and units.

    A *channels-only* rig (no ``[rudder]``, ``[stock]``, ``[damping]``, ``[hull]`` or
    ``[impact]``: what ``ramdaq import`` writes for a record without a rig) has ``rudder``,
    ``stock`` and ``impact`` None, no damping or hull modes, and gages that need only a number
    and a channel; :meth:`require_structure` refuses it where a model is needed."""

    name: str
    medium: str
    water_density_kg_m3: float
    daq: Daq
    rudder: Rudder | None
    stock: Stock | None
    damping: dict[str, Damping]
    hull_modes: tuple[HullMode, ...]
    impact: ImpactSpec | None
    gages: tuple[Gage, ...]
    ambient: tuple[Ambient, ...] = ()
    source: str = "<string>"
    text: str = ""
    surface: Surface = Surface()
    """What the surface is (rudder or stern plane); every vector above is in its frame."""
    forces: tuple[ForceChannel, ...] = ()

    @property
    def structural(self) -> bool:
        """The rig describes the structure (rudder, stock, hull), not only its channels."""
        return self.rudder is not None

    @property
    def described(self) -> str:
        """What the rig describes, in the words every command's rig line uses: the surface
        ("rudder", "stern plane") or "channels only"."""
        return self.surface.title if self.structural else "channels only"

    def require_structure(self, what: str, fix: str = "") -> None:
        """Raise :class:`RigError` if this is a channels-only rig: ``what`` needs the structure;
        ``fix``, if given, says what to do."""
        if not self.structural:
            raise RigError(f"{self.source}: rig {self.name!r} describes only its channels (no "
                           f"[rudder], [stock], [hull]); {what} needs the structure"
                           + (f"; {fix}" if fix else ""))

    def cannot_describe_rate(self, fs_hz: float) -> str | None:
        """Why this rig cannot describe a record sampled at ``fs_hz`` (Hz): its anti-alias corner
        at or above that record's Nyquist frequency; None if it can (a channels-only rig that
        names no filter, corner NaN, can)."""
        corner = self.daq.anti_alias_hz
        if not corner >= fs_hz / 2:
            return None
        return (f"at {fs_hz:g} Hz the anti-alias corner of rig {self.name!r} ({corner:g} Hz, "
                f"daq.anti_alias_hz, a rig for {self.daq.sample_rate_hz:g} Hz) lies above "
                f"Nyquist: the rig cannot describe this record; use a rig of this rate")

    @property
    def n_channels(self) -> int:
        """DAQ channels: gages and force channels."""
        return len(self.gages) + len(self.forces)

    @property
    def hull_attach_z_m(self) -> float:
        """Height of the stock's hull attachment (bending), m."""
        return self.rudder.attach_z_m + self.stock.bending_length_m

    @property
    def active_damping(self) -> Damping:
        return self.damping[self.medium]

    def gage(self, number: int) -> Gage:
        for g in self.gages:
            if g.number == number:
                return g
        raise KeyError(number)

    def force(self, name: str) -> ForceChannel:
        for f in self.forces:
            if f.name == name:
                return f
        raise KeyError(name)

    def gages_by_channel(self) -> tuple[Gage, ...]:
        """Gages in DAQ channel order (the row order of every block)."""
        return tuple(sorted(self.gages, key=lambda g: g.channel))

    def with_medium(self, medium: str) -> Rig:
        """The same rig in another medium ("air" or "water")."""
        if medium not in MEDIA:
            raise RigError(f"{self.source}: medium: {medium!r} is not one of {', '.join(MEDIA)}")
        if self.structural and medium not in self.damping:
            raise RigError(f"{self.source}: damping.{medium}: missing, so medium {medium} is unusable")
        return replace(self, medium=medium)


# ---------------------------------------------------------------------------------------------
def shipped_rigs() -> tuple[str, ...]:
    """Names of the rigs shipped with ramdaq (package data ``ramdaq.rigs``), e.g. ``albacore``."""
    return tuple(sorted(f.name[:-5] for f in resources.files("ramdaq.rigs").iterdir()
                        if f.name.endswith(".toml")))


def rig_path(spec: str | Path) -> Path:
    """The file a ``--rig`` names: a path as given, or a shipped rig by its bare name
    (``albacore`` is ``ramdaq.rigs``' ``albacore.toml``) when no such file exists here."""
    path = Path(spec)
    if path.exists() or path.suffix or len(path.parts) != 1:
        return path
    shipped = resources.files("ramdaq.rigs") / f"{spec}.toml"
    if shipped.is_file():
        return Path(str(shipped))
    raise RigError(f"{spec}: no such rig file, nor a shipped rig (shipped: {', '.join(shipped_rigs())})")


def load_rig(path: str | Path) -> Rig:
    """Read and check a rig file (a path, or a shipped rig's name: :func:`rig_path`). Raises
    :class:`RigError` naming file and field."""
    path = rig_path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise RigError(f"{path}: cannot read rig file ({err.strerror})") from err
    return parse_rig(text, source=str(path))


def parse_rig(text: str, source: str = "<string>") -> Rig:
    """Parse and check rig TOML text. Raises :class:`RigError` naming ``source`` and the field."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise RigError(f"{source}: not valid TOML ({err})") from err
    try:
        doc, surface, renames = to_surface_frame(doc)
    except SurfaceError as err:
        raise RigError(f"{source}: {err}") from err
    r = _Reader(doc, source, renames)
    units = r.text("units", default="SI")
    if units != "SI":
        r.fail("units", f"{units!r} is not supported; rig files are in SI (m, kg, s, N, rad)")
    medium = r.text("medium")
    if medium not in MEDIA:
        r.fail("medium", f"{medium!r} is not one of {', '.join(MEDIA)}")
    if not any(r.has(t) for t in STRUCTURE_TABLES):
        return _parse_channels_only(r, medium, text)
    daq = _read_daq(r)
    rudder = _read_rudder(r)
    stock = Stock(
        E_Pa=r.positive("stock.E_Pa"),
        G_Pa=r.positive("stock.G_Pa"),
        I_m4=r.positive("stock.I_m4"),
        J_m4=r.positive("stock.J_m4"),
        shear_area_m2=r.positive("stock.shear_area_m2"),
        bending_length_m=r.positive("stock.bending_length_m"),
        torsion_length_m=r.positive("stock.torsion_length_m"),
    )
    damping = _read_damping(r, medium)
    hull_modes = _read_hull_modes(r)
    impact = ImpactSpec(
        peak_force_N=r.positive("impact.peak_force_N"),
        duration_s=r.positive("impact.duration_s"),
        location_m=r.vector("impact.location_m"),
        direction=r.axis("impact.direction", default="y"),
    )
    gages = _read_gages(r, rudder, stock)
    forces = _read_forces(r, len(gages))
    r.read_elsewhere("uncertainty")  # bounds for calibrating the rig to a trial's modes
    ambient = _read_ambient(r, len(hull_modes))
    rig = Rig(
        name=r.text("name"),
        medium=medium,
        water_density_kg_m3=r.positive("water.density_kg_m3", default=1025.0),
        daq=daq,
        rudder=rudder,
        stock=stock,
        damping=damping,
        hull_modes=hull_modes,
        impact=impact,
        gages=gages,
        ambient=ambient,
        source=source,
        text=text,
        surface=surface,
        forces=forces,
    )
    r.refuse_unknown_keys()
    return rig


def _parse_channels_only(r: _Reader, medium: str, text: str) -> Rig:
    """A rig of channels only: ``name``, ``medium``, ``[daq] sample_rate_hz`` (the rest of
    ``[daq]`` optional), gages with a number (1..64) and a channel, force channels."""
    daq = Daq(sample_rate_hz=r.positive("daq.sample_rate_hz"),
              adc_bits=int(r.positive("daq.adc_bits", default=24)),
              adc_full_scale_V=r.positive("daq.adc_full_scale_V", default=10.0),
              anti_alias_hz=r.positive("daq.anti_alias_hz") if r.has("daq.anti_alias_hz")
              else math.nan,  # not known: the trigger then removes no filter delay
              anti_alias_order=int(r.positive("daq.anti_alias_order", default=1)),
              noise_m_s2_rms=r.nonnegative("daq.noise_m_s2_rms", default=0.0))
    gages: list[Gage] = []
    seen: dict[int, int] = {}
    for i, _ in enumerate(r.get("gages", default=[])):
        p = f"gages[{i}]"
        number = _gage_number(r, i, MAX_CHANNELS, seen)
        axis = r.get(f"{p}.axis", default=None)
        gages.append(Gage(number=number, body=r.text(f"{p}.body", default=""),
                          position_m=r.vector(f"{p}.position_m") if r.has(f"{p}.position_m")
                          else (math.nan,) * 3,
                          axis=r.axis(f"{p}.axis") if axis is not None else "",
                          sensitivity_V_per_m_s2=r.positive(f"{p}.sensitivity_V_per_m_s2")
                          if r.has(f"{p}.sensitivity_V_per_m_s2") else math.nan,
                          channel=r.integer(f"{p}.channel"), unit=_gage_unit(r, p)))
    forces = _read_forces(r, 0)
    channels = sorted([g.channel for g in gages] + [f.channel for f in forces])
    if not channels:
        r.fail("gages", "a rig needs at least one [[gages]] or [[forces]] channel")
    if channels != list(range(len(channels))) or len(channels) > MAX_CHANNELS:
        r.fail("gages", f"channels {channels} are not 0..{len(channels) - 1} without holes or "
               f"repeats (at most {MAX_CHANNELS})")
    rig = Rig(name=r.text("name"), medium=medium,
              water_density_kg_m3=r.positive("water.density_kg_m3", default=1025.0), daq=daq,
              rudder=None, stock=None, damping={}, hull_modes=(), impact=None,
              gages=tuple(sorted(gages, key=lambda g: g.number)), source=r.source, text=text,
              forces=forces)
    r.refuse_unknown_keys()
    return rig


def _gage_number(r: _Reader, i: int, top: int, seen: dict[int, int]) -> int:
    """``gages[i].number``, refused outside 1..``top`` or when an earlier gage has it; ``seen``
    (number -> index of the gage that has it) gains it."""
    p = f"gages[{i}]"
    number = r.integer(f"{p}.number")
    if not 1 <= number <= top:
        r.fail(f"{p}.number", f"{number} is outside 1..{top}")
    if number in seen:
        r.fail(f"{p}.number", f"duplicate gage {number} (also gages[{seen[number]}])")
    seen[number] = i
    return number


def _gage_unit(r: _Reader, p: str) -> str | None:
    if r.get(f"{p}.unit", None) is None:
        return None
    unit = r.text(f"{p}.unit")
    if unit not in GAGE_UNITS:
        r.fail(f"{p}.unit", f"{unit!r} is not an acceleration unit ({', '.join(GAGE_UNITS)})")
    return unit


def _read_forces(r: _Reader, first_channel: int) -> tuple[ForceChannel, ...]:
    """``[[forces]]``: name, channel (from ``first_channel`` up when the gages come first: a
    structural rig's gages hold 0..15), unit (N, kN, lbf; default N), location_m (optional)."""
    forces: list[ForceChannel] = []
    for i, _ in enumerate(r.get("forces", default=[])):
        p = f"forces[{i}]"
        unit = r.text(f"{p}.unit", default="N")
        if unit not in FORCE_UNITS:
            r.fail(f"{p}.unit", f"{unit!r} is not a force unit ({', '.join(FORCE_UNITS)})")
        f = ForceChannel(name=r.text(f"{p}.name"), channel=r.integer(f"{p}.channel"), unit=unit,
                         location_m=r.vector(f"{p}.location_m") if r.has(f"{p}.location_m")
                         else None)
        if first_channel and f.channel != first_channel + i:
            r.fail(f"{p}.channel", f"{f.channel}: force channels follow the gages "
                   f"({first_channel + i} expected)")
        if not f.name.strip() or any(f.name == o.name for o in forces):
            r.fail(f"{p}.name", f"{f.name!r} is empty or repeated")
        forces.append(f)
    return tuple(forces)


def _read_daq(r: _Reader) -> Daq:
    daq = Daq(
        sample_rate_hz=r.positive("daq.sample_rate_hz"),
        adc_bits=int(r.positive("daq.adc_bits")),
        adc_full_scale_V=r.positive("daq.adc_full_scale_V"),
        anti_alias_hz=r.positive("daq.anti_alias_hz"),
        anti_alias_order=int(r.positive("daq.anti_alias_order")),
        noise_m_s2_rms=r.nonnegative("daq.noise_m_s2_rms"),
    )
    if not 2 <= daq.adc_bits <= 31:
        r.fail("daq.adc_bits", f"{daq.adc_bits} is outside 2..31 (counts are int32)")
    if daq.anti_alias_hz >= daq.sample_rate_hz / 2:
        r.fail("daq.anti_alias_hz", f"{daq.anti_alias_hz} Hz is not below Nyquist "
               f"({daq.sample_rate_hz / 2} Hz)")
    return daq


def _read_rudder(r: _Reader) -> Rudder:
    rudder = Rudder(
        mass_kg=r.positive("rudder.mass_kg"),
        Iz_kg_m2=r.positive("rudder.Iz_kg_m2"),
        Ix_kg_m2=r.positive("rudder.Ix_kg_m2"),
        Ixz_kg_m2=r.number("rudder.Ixz_kg_m2"),
        chord_m=r.positive("rudder.chord_m"),
        span_m=r.positive("rudder.span_m"),
        thickness_m=r.positive("rudder.thickness_m"),
        stock_x_m=r.number("rudder.stock_x_m"),
        attach_z_m=r.positive("rudder.attach_z_m"),
        added_mass_factor=r.nonnegative("rudder.added_mass_factor", default=1.0),
    )
    if rudder.Ixz_kg_m2**2 >= rudder.Ix_kg_m2 * rudder.Iz_kg_m2:
        r.fail("rudder.Ixz_kg_m2", "makes the inertia matrix not positive definite "
               "(need Ixz^2 < Ix*Iz)")
    return rudder


def _read_damping(r: _Reader, medium: str) -> dict[str, Damping]:
    """The damping constants of each medium the file gives; the rig's own medium's are required."""
    damping: dict[str, Damping] = {}
    for med in MEDIA:
        if r.has(f"damping.{med}"):
            damping[med] = Damping(
                C_N_s_per_m=r.nonnegative(f"damping.{med}.C_N_s_per_m"),
                c_N_m_s_per_rad=r.nonnegative(f"damping.{med}.c_N_m_s_per_rad"),
                c_alpha_N_m_s_per_rad=r.nonnegative(f"damping.{med}.c_alpha_N_m_s_per_rad"),
            )
    if medium not in damping:
        r.fail(f"damping.{medium}", "missing for the rig's medium")
    return damping


def _read_hull_modes(r: _Reader) -> tuple[HullMode, ...]:
    modes_raw = r.get("hull.modes")
    if not isinstance(modes_raw, list) or not modes_raw:
        r.fail("hull.modes", "needs at least one [[hull.modes]] table (a hull bending mode)")
    hull_modes = []
    for i, _ in enumerate(modes_raw):
        p = f"hull.modes[{i}]"
        hull_modes.append(HullMode(
            name=r.text(f"{p}.name"),
            frequency_hz=r.positive(f"{p}.frequency_hz"),
            damping_ratio=r.nonnegative(f"{p}.damping_ratio"),
            modal_mass_kg=r.positive(f"{p}.modal_mass_kg"),
            v_b=r.number(f"{p}.v_b"),
            gamma_b=r.number(f"{p}.gamma_b"),
            alpha_b=r.number(f"{p}.alpha_b"),
            added_mass_ratio_water=r.nonnegative(f"{p}.added_mass_ratio_water", default=0.0),
        ))
        if hull_modes[-1].damping_ratio >= 1:
            r.fail(f"{p}.damping_ratio", "must be below 1 (an underdamped mode)")
    return tuple(hull_modes)


def _read_ambient(r: _Reader, n_hull_modes: int) -> tuple[Ambient, ...]:
    ambient = []
    for i, _ in enumerate(r.get("ambient", default=[])):
        p = f"ambient[{i}]"
        amb = Ambient(hull_mode=r.integer(f"{p}.hull_mode"),
                      frequency_hz=r.positive(f"{p}.frequency_hz"),
                      v_b_amplitude_m=r.nonnegative(f"{p}.v_b_amplitude_m"))
        if not 1 <= amb.hull_mode <= n_hull_modes:
            r.fail(f"{p}.hull_mode", f"{amb.hull_mode} is not a hull mode (1..{n_hull_modes})")
        ambient.append(amb)
    return tuple(ambient)


def _read_gages(r: _Reader, rudder: Rudder, stock: Stock) -> tuple[Gage, ...]:
    raw = r.get("gages")
    if not isinstance(raw, list):
        r.fail("gages", "needs [[gages]] tables, one per gage")
    gages: list[Gage] = []
    seen_numbers: dict[int, int] = {}
    seen_channels: dict[int, int] = {}
    for i, _ in enumerate(raw):
        p = f"gages[{i}]"
        number = _gage_number(r, i, N_GAGES, seen_numbers)
        body = r.text(f"{p}.body")
        if body not in BODIES:
            r.fail(f"{p}.body", f"{body!r} is not one of {', '.join(BODIES)}")
        channel = r.integer(f"{p}.channel")
        if channel < 0:
            r.fail(f"{p}.channel", f"{channel} is negative")
        if channel in seen_channels:
            r.fail(f"{p}.channel", f"duplicate channel {channel} "
                   f"(also gages[{seen_channels[channel]}])")
        seen_channels[channel] = i
        gage = Gage(number=number, body=body, position_m=r.vector(f"{p}.position_m"),
                    axis=r.axis(f"{p}.axis"),
                    sensitivity_V_per_m_s2=r.positive(f"{p}.sensitivity_V_per_m_s2"),
                    channel=channel, unit=_gage_unit(r, p))
        z = gage.position_m[2]
        top, bottom = rudder.attach_z_m + stock.bending_length_m, rudder.attach_z_m
        if body == "stock" and not bottom - ALIGN_TOL_M <= z <= top + ALIGN_TOL_M:
            r.fail(f"{p}.position_m", f"stock gage {number} at z = {z} m is off the stock "
                   f"(z from {bottom} to {top} m)")
        gages.append(gage)
    if len(gages) < MIN_GAGES:
        r.fail("gages", f"{len(gages)} gage(s); a structure needs {MIN_GAGES} or more (the report's "
               f"layout has {N_GAGES}: gages 1-{N_GAGES})")
    by_number = {g.number: g for g in gages}
    for a, b, coords, what in ((2, 6, (0, 1), "vertical"), (4, 8, (1, 2), "horizontal")):
        if a not in by_number or b not in by_number:
            continue  # the motion they give is not computed (impact.skipped_steps says so)
        pa, pb = by_number[a].position_m, by_number[b].position_m
        if any(abs(pa[k] - pb[k]) > ALIGN_TOL_M for k in coords):
            r.fail(f"gages[{seen_numbers[b]}].position_m",
                   f"gages {a} and {b} are not on a common {what} "
                   f"({pa} vs {pb}); Eq 2/3a and 1/3b need them aligned")
    channels = sorted(seen_channels)
    if channels != list(range(len(channels))):
        r.fail("gages", f"channels {channels} are not 0..{len(channels) - 1} without holes")
    return tuple(sorted(gages, key=lambda g: g.number))


class _Reader:
    """Typed access to a nested TOML dict by dotted path, failing with one clear line."""

    _MISSING = object()

    def __init__(self, doc: dict[str, Any], source: str,
                 renames: dict[str, str] | None = None) -> None:
        self.doc = doc
        self.source = source
        self.renames = renames or {}
        self.asked: set[str] = set()  # every path read, list indices as [] (the valid keys)

    def fail(self, field: str, why: str) -> None:
        for model, file in self.renames.items():  # a stern plane's file names its own fields
            field = field.replace(model, file)
        raise RigError(f"{self.source}: {field}: {why}")

    def get(self, path: str, default: Any = _MISSING) -> Any:
        self.asked.add(_generic(path))
        node: Any = self.doc
        for part in path.replace("]", "").replace("[", ".").split("."):
            if isinstance(node, list) and part.isdigit() and int(part) < len(node):
                node = node[int(part)]
            elif isinstance(node, dict) and part in node:
                node = node[part]
            else:
                if default is not self._MISSING:
                    return default
                have = list(node) if isinstance(node, dict) else []
                near = difflib.get_close_matches(part, have, n=1, cutoff=0.6)
                self.fail(path, f"missing (the file has {near[0]!r}: misspelt?)" if near else "missing")
        return node

    def has(self, path: str) -> bool:
        return self.get(path, default=None) is not None

    def read_elsewhere(self, table: str) -> None:
        """Take ``table`` and everything in it as read: a table of the rig file that another
        module reads and checks (``[uncertainty]``: :mod:`ramdaq.analysis.gap.rigfit`)."""
        node = self.doc.get(table)
        if node is not None:
            self.asked.add(table)
            self.asked.update(_key_paths(node, table))

    def text(self, path: str, default: Any = _MISSING) -> str:
        v = self.get(path, default)
        if not isinstance(v, str):
            self.fail(path, f"expected text, got {v!r}")
        return v

    def number(self, path: str, default: Any = _MISSING) -> float:
        return self._plausible(path, self._finite(path, default))

    def _finite(self, path: str, default: Any) -> float:
        v = self.get(path, default)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            self.fail(path, f"expected a finite number, got {v!r}")
        return float(v)

    def _plausible(self, path: str, v: float) -> float:
        """``v``, or a failure when it lies outside :data:`PLAUSIBLE`'s span for ``path``."""
        span = PLAUSIBLE.get(_generic(path))
        if span is not None and not span.lo <= v <= span.hi:
            self.fail(path, f"{v:g} {span.unit} is implausible: expected {span.lo:g} to "
                      f"{span.hi:g} {span.unit} ({span.why})")
        return v

    def integer(self, path: str) -> int:
        v = self.get(path)
        if isinstance(v, bool) or not isinstance(v, int):
            self.fail(path, f"expected a whole number, got {v!r}")
        return v

    def positive(self, path: str, default: Any = _MISSING) -> float:
        v = self._finite(path, default)
        if v <= 0:
            self.fail(path, f"must be positive, got {v}")
        return self._plausible(path, v)

    def nonnegative(self, path: str, default: Any = _MISSING) -> float:
        v = self._finite(path, default)
        if v < 0:
            self.fail(path, f"must not be negative, got {v}")
        return self._plausible(path, v)

    def vector(self, path: str) -> tuple[float, float, float]:
        v = self.get(path)
        ok = isinstance(v, list) and len(v) == 3 and all(
            isinstance(c, int | float) and not isinstance(c, bool) for c in v)
        if not ok:
            self.fail(path, f"expected [x, y, z] in metres, got {v!r}")
        if not all(abs(c) <= MAX_COORDINATE_M for c in v):
            self.fail(path, f"{v!r} is implausible: every coordinate must lie within "
                      f"{MAX_COORDINATE_M:g} m of the centre of mass")
        return (float(v[0]), float(v[1]), float(v[2]))

    def axis(self, path: str, default: Any = _MISSING) -> str:
        v = self.text(path, default)
        if v not in AXES:
            self.fail(path, f"unknown axis {v!r} (expected one of {', '.join(AXES)})")
        return v

    def refuse_unknown_keys(self) -> None:
        """Fail on the first key of the file that the parser never read, naming the nearest
        valid key at its level (a misspelt ``added_mass_factr`` is not silently the default)."""
        for path in _key_paths(self.doc, ""):
            if path in self.asked or any(a.startswith((path + ".", path + "[")) for a in self.asked):
                continue
            parent, _, key = path.rpartition(".")
            level = [a[len(parent) + 1:] if parent else a for a in self.asked
                     if not parent or a.startswith(parent + ".")]
            valid = sorted({re.split(r"[.\[]", a)[0] for a in level})
            near = difflib.get_close_matches(key, valid, n=1, cutoff=0.6)
            hint = f"did you mean {near[0]!r}?" if near else f"valid keys here: {', '.join(valid)}"
            self.fail(path.replace("[]", ""), f"unknown key {key!r}; {hint}")


def _generic(path: str) -> str:
    """``"hull.modes[0].name"`` -> ``"hull.modes[].name"``: a path with its list indices dropped."""
    return re.sub(r"\[\d+\]", "[]", path)


def _key_paths(node: Any, prefix: str) -> Iterator[str]:
    """Every key of a parsed TOML document as a generic dotted path, parents before children."""
    if isinstance(node, dict):
        for k, v in node.items():
            path = f"{prefix}.{k}" if prefix else str(k)
            yield path
            yield from _key_paths(v, path)
    elif isinstance(node, list):
        for item in node:
            yield from _key_paths(item, f"{prefix}[]")
