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

import math
import tomllib
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
ALIGN_TOL_M = 1e-3
"""Gages that the report's equations pair (2 and 6 on a vertical, 4 and 8 on a horizontal) must
line up to this tolerance: 1 mm is well inside how precisely a gage is placed on a rudder."""


class RigError(ValueError):
    """A rig file that cannot describe a trial; the message names the file and field."""


@dataclass(frozen=True)
class Gage:
    """One accelerometer.

    ``position_m`` is (x, y, z) in metres from the rudder's centre of mass; ``axis`` the sensing
    direction (``"y"`` athwartship, ``"z"`` vertical, signs allowed); ``sensitivity_V_per_m_s2``
    volts per m/s^2; ``channel`` the DAQ channel index (0-based row of every block).
    """

    number: int
    body: str
    position_m: tuple[float, float, float]
    axis: str
    sensitivity_V_per_m_s2: float
    channel: int

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
    """A whole trial description. See the module docstring for coordinates and units."""

    name: str
    medium: str
    water_density_kg_m3: float
    daq: Daq
    rudder: Rudder
    stock: Stock
    damping: dict[str, Damping]
    hull_modes: tuple[HullMode, ...]
    impact: ImpactSpec
    gages: tuple[Gage, ...]
    ambient: tuple[Ambient, ...] = ()
    source: str = "<string>"
    text: str = ""
    surface: Surface = Surface()
    """What the surface is (rudder or stern plane); every vector above is in its frame."""

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

    def gages_by_channel(self) -> tuple[Gage, ...]:
        """Gages in DAQ channel order (the row order of every block)."""
        return tuple(sorted(self.gages, key=lambda g: g.channel))

    def with_medium(self, medium: str) -> Rig:
        """The same rig in another medium ("air" or "water")."""
        if medium not in MEDIA:
            raise RigError(f"{self.source}: medium: {medium!r} is not one of {', '.join(MEDIA)}")
        if medium not in self.damping:
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
    ambient = _read_ambient(r, len(hull_modes))
    return Rig(
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
    )


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
        number = r.integer(f"{p}.number")
        if not 1 <= number <= N_GAGES:
            r.fail(f"{p}.number", f"{number} is outside 1..{N_GAGES}")
        if number in seen_numbers:
            r.fail(f"{p}.number", f"duplicate gage {number} (also gages[{seen_numbers[number]}])")
        seen_numbers[number] = i
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
                    channel=channel)
        z = gage.position_m[2]
        top, bottom = rudder.attach_z_m + stock.bending_length_m, rudder.attach_z_m
        if body == "stock" and not bottom - ALIGN_TOL_M <= z <= top + ALIGN_TOL_M:
            r.fail(f"{p}.position_m", f"stock gage {number} at z = {z} m is off the stock "
                   f"(z from {bottom} to {top} m)")
        gages.append(gage)
    missing = sorted(set(range(1, N_GAGES + 1)) - set(seen_numbers))
    if missing:
        r.fail("gages", f"missing gage(s) {', '.join(map(str, missing))}; the report's layout "
               f"needs all {N_GAGES}")
    by_number = {g.number: g for g in gages}
    for a, b, coords, what in ((2, 6, (0, 1), "vertical"), (4, 8, (1, 2), "horizontal")):
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

    def fail(self, field: str, why: str) -> None:
        for model, file in self.renames.items():  # a stern plane's file names its own fields
            field = field.replace(model, file)
        raise RigError(f"{self.source}: {field}: {why}")

    def get(self, path: str, default: Any = _MISSING) -> Any:
        node: Any = self.doc
        for part in path.replace("]", "").replace("[", ".").split("."):
            if isinstance(node, list) and part.isdigit() and int(part) < len(node):
                node = node[int(part)]
            elif isinstance(node, dict) and part in node:
                node = node[part]
            else:
                if default is not self._MISSING:
                    return default
                self.fail(path, "missing")
        return node

    def has(self, path: str) -> bool:
        return self.get(path, default=None) is not None

    def text(self, path: str, default: Any = _MISSING) -> str:
        v = self.get(path, default)
        if not isinstance(v, str):
            self.fail(path, f"expected text, got {v!r}")
        return v

    def number(self, path: str, default: Any = _MISSING) -> float:
        v = self.get(path, default)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            self.fail(path, f"expected a finite number, got {v!r}")
        return float(v)

    def integer(self, path: str) -> int:
        v = self.get(path)
        if isinstance(v, bool) or not isinstance(v, int):
            self.fail(path, f"expected a whole number, got {v!r}")
        return v

    def positive(self, path: str, default: Any = _MISSING) -> float:
        v = self.number(path, default)
        if v <= 0:
            self.fail(path, f"must be positive, got {v}")
        return v

    def nonnegative(self, path: str, default: Any = _MISSING) -> float:
        v = self.number(path, default)
        if v < 0:
            self.fail(path, f"must not be negative, got {v}")
        return v

    def vector(self, path: str) -> tuple[float, float, float]:
        v = self.get(path)
        ok = isinstance(v, list) and len(v) == 3 and all(
            isinstance(c, int | float) and not isinstance(c, bool) for c in v)
        if not ok:
            self.fail(path, f"expected [x, y, z] in metres, got {v!r}")
        return (float(v[0]), float(v[1]), float(v[2]))

    def axis(self, path: str, default: Any = _MISSING) -> str:
        v = self.text(path, default)
        if v not in AXES:
            self.fail(path, f"unknown axis {v!r} (expected one of {', '.join(AXES)})")
        return v
