"""What the CSV, UFF 58 and TDMS importers share: channel mapping, units, lossless counts, blocks.

An importer reads another system's recording into a :class:`SourceTable` (channel names, units,
the sample index of each row, a reader of each channel's floats); :class:`FileImportDevice` maps
channels to the rig's gages, converts g to m/s^2, turns each channel into int32 counts with a
per-channel scale and streams blocks like any device: ``ramdaq import`` is ``open_device(FILE,
rig=...)`` into a recorder.

Counts and scale, per channel, in the file's own unit:

* **quantised** -- the values are integer multiples of a common step (an ADC's counts written as
  ``counts * scale``). The step is the smallest gap between distinct values (or 1/2, 1/3, 1/4 of
  it), refined by least squares, or set to the float that reproduces every value bit for bit
  when one lies within an ulp of ``value / count`` at the largest counts. Accepted when every
  value lies within ``STEP_TOLERANCE`` (1 %) of the grid and the counts fit int32: the counts are
  then the source's own, bit-exact from full-precision files (float64, ``%.17g`` text), exact to
  the count from UFF's 13-digit E20.12 (and from float32 up to about 160 000 counts).
* **requantised** -- otherwise (filtered, resampled or computed data), 24 bits:
  ``scale = max|x| / (2**23 - 1)``, ``counts = rint(x / scale)``, so ``|counts| <= 2**23 - 1``
  and ``|x - counts*scale| <= scale/2 = max|x| / (2**24 - 2)``: 6.0e-8 of the channel's peak,
  far below any accelerometer's noise.

``StreamInfo.extra["import"]["channels"]["g01"]`` says which, with the step, the scale, the
measured largest error and the guaranteed bound (in the channel's SI unit, ``si_unit``). A missing
value (NaN, empty) is an error naming where it is, unless ``allow_gaps``: then its row is not
streamed, the blocks split there, a gap the recording keeps, never interpolated. A recording's
gap is on every channel (a block has no per-channel hole, and a sentinel count would be an
invented sample), so the other channels' good values on that row go too:
``extra["import"]["dropped_with_gaps"]`` counts them per channel, and ``ramdaq import`` says so.
Units: m/s^2 and
g (9.80665 m/s^2) for a gage (the file's stated unit wins over the rig's; where the rig states a
different one ``"rig_unit_not_applied"`` says so; a rig that states none assumes m/s^2); N, kN,
lbf for a force channel (the rig's ``[[forces]]``, named in
the stream by its rig name, unit ``"N"``, gage 0); anything else is refused naming the channel.
The file's sample rate must be the rig's unless ``fs_hz`` states it. Every problem with a file is
an :class:`ImportFormatError`: one line naming the file and what."""

from __future__ import annotations

import contextlib
import json
import math
import re
from collections.abc import Callable, Iterator, Mapping
from contextvars import ContextVar
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path

import numpy as np

from ...analysis.model.rig import FORCE_UNITS, PLAUSIBLE, Rig, load_rig
from ..base import Device
from ..block import Block, StreamInfo, sample_time_ns
from ..errors import DeviceError, DeviceNotFound

__all__ = ["G0", "FULL_SCALE_COUNTS", "STEP_TOLERANCE", "ImportFormatError", "SourceTable",
           "Quantisation", "FileImportDevice", "gage_of_name", "parse_channel_map",
           "map_channels", "unit_factor", "force_unit_factor", "quantise", "detect_step",
           "snap_rate", "Pick", "RATE_TOLERANCE", "option", "cli_option_names", "find_channel",
           "rig_source_map"]

G0 = 9.80665
"""Standard gravity, m/s^2 per g."""
FULL_SCALE_COUNTS = 2**23 - 1
"""Largest count of a requantised channel (24-bit)."""
STEP_TOLERANCE = 0.01
"""Largest distance of a value from its step grid, in steps, for the channel to count as
quantised."""
RATE_TOLERANCE = 1e-4
"""Largest relative difference between a file's sample rate and its rig's that is the same rate:
100 ppm, twice a crystal clock's tolerance and far below any rate set in a different number."""
_RATES = PLAUSIBLE["daq.sample_rate_hz"]   # the rates a trial is sampled at (the trigger's), Hz
_UNIT_SLIPS = ((1e3, "1000 times it: are the times in s, read as ms?"),
               (1e6, "1e6 times it: are the times in s, read as us?"),
               (1e-3, "1/1000 of it: are the times in ms, read as s?"),
               (1e-6, "1/1e6 of it: are the times in us, read as s?"))


def _unit_slip(ratio: float) -> str | None:
    """What a file's rate ``ratio`` times the rig's says when it is a power of 1000 (within
    1 %): the time column read in the wrong unit; else None."""
    return next((what for k, what in _UNIT_SLIPS if abs(ratio / k - 1) <= 0.01), None)


_INT32_MAX = 2**31 - 1
_STEP_SAMPLE = 200_000  # values searched for the step (all values are checked against it)
_TINY, _HUGE = 1e-290, 1e290  # m/s^2: a channel's peak beyond these is refused, not scaled
_MAX_TIME_S = 4e9  # |start| and length, s: device time in int64 ns stays far from overflow


class ImportFormatError(DeviceError, ValueError):
    """A file that cannot be imported; the message is one line naming the file and what."""

    def __init__(self, message: str) -> None:
        super().__init__(" ".join(str(message).split()))


# -- how messages name options -------------------------------------------------------------------
_CLI_NAMES: ContextVar[bool] = ContextVar("ramdaq_import_cli_names", default=False)


@contextlib.contextmanager
def cli_option_names() -> Iterator[None]:
    """Within it, import messages name the command line's options only (``--fs``), not the
    Python arguments (``fs_hz=``): ``ramdaq import`` reads files inside it."""
    token = _CLI_NAMES.set(True)
    try:
        yield
    finally:
        _CLI_NAMES.reset(token)


def option(python: str, cli: str) -> str:
    """An option as a message names it: ``"--fs"`` on the command line (see
    :func:`cli_option_names`), ``"fs_hz= (--fs)"`` from Python."""
    return cli if _CLI_NAMES.get() else f"{python} ({cli})"


# -- channels and units --------------------------------------------------------------------------
_UNIT_SUFFIX = re.compile(r"^(.*?)\s*[\[(]\s*[^\])]*?\s*[\])]$")
_SOURCE_LINE = re.compile(r'^\[\[gages\]\]\s*#\s*source channel ("(?:[^"\\]|\\.)*")\s*\n'
                          r"\s*number\s*=\s*(\d+)", re.MULTILINE)


def find_channel(name: str, names: list[str], aliases: Mapping[str, str] | None = None
                 ) -> str | None:
    """The one of ``names`` that ``name`` means: itself, another name of it (``aliases``: a UFF
    record's ID line 1 for its node number), or either without a unit suffix (``"Load cell
    [N]"``, ``"Load cell (N)"`` mean ``"Load cell"``); None if none is there."""
    aliases = aliases or {}
    m = _UNIT_SUFFIX.match(name.strip())
    for n in (name, m.group(1) if m else None):
        if n in names:
            return n
        if n in aliases:
            return aliases[n]
    return None


def rig_source_map(rig_text: str) -> dict[str, int]:
    """Source channel -> gage number as a channels-only rig written by ``ramdaq import``
    records it (``[[gages]]  # source channel "AI0 acc"`` then ``number = 1``); empty for a rig
    that records none."""

    return {json.loads(m.group(1)): int(m.group(2)) for m in _SOURCE_LINE.finditer(rig_text)}


_GAGE_NAME = re.compile(r"^(?:g|gage|gauge)?[\s_\-#]*0*(\d{1,4})$", re.IGNORECASE)


def gage_of_name(name: str) -> int | None:
    """Gage number named by ``"g01"``, ``"G1"``, ``"gage 1"``, ``"gauge_01"`` or ``"1"``."""
    m = _GAGE_NAME.match(str(name).strip())
    return int(m.group(1)) if m else None


def parse_channel_map(text: str | None) -> dict[str, int] | None:
    """``"colA=1,colB=g02"`` -> ``{"colA": 1, "colB": 2}`` (source name -> gage number).

    Raises
    ------
    ValueError
        An item without ``=`` or whose right side names no gage.
    """
    if not text:
        return None
    out: dict[str, int] = {}
    for item in text.split(","):
        if not item.strip():
            continue
        name, sep, gage = item.rpartition("=")
        n = gage_of_name(gage)
        if not sep or not name.strip() or n is None:
            raise ValueError(f"--channels item {item.strip()!r}: expected SOURCE=GAGE, e.g. "
                             f"'Accel 3=g03'")
        out[name.strip()] = n
    return out


_SENSITIVITY = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(m?V)\s*/\s*(.+?)\s*$")
_PER_MS2 = {"(m/s^2)", "m/s^2", "(m/s2)", "m/s2", "ms^-2", "(m/s/s)", "m/s/s"}


def parse_sensitivity(text: str) -> float:
    """An accelerometer's sensitivity, ``"100mV/g"``, ``"0.1 V/g"`` or ``"10.2 mV/(m/s^2)"``,
    in V per m/s^2.

    Raises
    ------
    ValueError
        Not a positive number with V or mV per g or per m/s^2.
    """
    m = _SENSITIVITY.match(text)
    per = m.group(3).lower().replace(" ", "").replace("**", "^") if m else ""
    if m is None or not (per in _GEE or per in _PER_MS2) or not float(m.group(1)) > 0:
        raise ValueError(f"sensitivity {text.strip()!r}: expected e.g. 100mV/g, 0.1V/g or "
                         f"10.2mV/(m/s^2)")
    volts = float(m.group(1)) * (1e-3 if m.group(2) == "mV" else 1.0)
    return volts / (G0 if per in _GEE else 1.0)


def parse_sensitivities(text: str | None) -> float | dict[str, float] | None:
    """``"100mV/g"`` (every channel in volts) or ``"Accel 1=100mV/g,Accel 2=98.5mV/g"`` (source
    name -> sensitivity), in V per m/s^2 (:func:`parse_sensitivity`)."""
    if not text or not text.strip():
        return None
    if "=" not in text:
        return parse_sensitivity(text)
    out: dict[str, float] = {}
    for item in text.split(","):
        if not item.strip():
            continue
        name, sep, value = item.rpartition("=")
        if not sep or not name.strip():
            raise ValueError(f"--sensitivity item {item.strip()!r}: expected SOURCE=VALUE, e.g. "
                             f"'Accel 1=100mV/g'")
        out[name.strip()] = parse_sensitivity(value)
    return out


@dataclass(frozen=True)
class Pick:
    """One source channel to import: its index in the file, the gage it is (0 for a force
    channel), its name in the stream (``g01``, or the rig's force channel name) and its rig
    DAQ channel."""

    index: int
    gage: int
    name: str
    channel: int

    @property
    def is_force(self) -> bool:
        return self.gage == 0


def map_channels(names: list[str], rig: Rig, channels: Mapping[str, int] | None,
                 source: str, force_channel: str | None = None,
                 aliases: Mapping[str, str] | None = None) -> list[Pick]:
    """Pick the source channels to import and their gages, in the rig's channel order.

    Parameters
    ----------
    names : list of str
        Source channel names, in the file's order.
    rig : Rig
        Gage numbers and DAQ channel order.
    channels : mapping of str to int, optional
        Explicit source name -> gage number; only these are imported. Without it every channel
        must be named like a gage (``g01``, ``gage 1``, ``1``).
    source : str
        The file, for messages.
    force_channel : str, optional
        The source channel that is the rig's (first) force channel; by default a source channel
        named like one of the rig's ``[[forces]]`` is that force channel.
    aliases : mapping of str to str, optional
        Other names of source channels (:func:`find_channel`), for ``channels`` and
        ``force_channel``.

    Returns
    -------
    list of Pick
        Sorted by rig channel.
    """
    if aliases and channels is not None:
        channels = {(find_channel(k, names, aliases) or k): g for k, g in channels.items()}
    if aliases and force_channel is not None:
        force_channel = find_channel(force_channel, names, aliases) or force_channel
    forces = _pick_forces(names, rig, force_channel, source)
    taken = {p.index for p in forces}
    names = [n if i not in taken else "" for i, n in enumerate(names)]  # "" is no gage name
    return sorted(forces + [Pick(i, g, f"g{g:02d}", rig.gage(g).channel)
                            for i, g in _pick_gages(names, rig, channels, source, bool(forces))],
                  key=lambda p: p.channel)


def _pick_forces(names: list[str], rig: Rig, force_channel: str | None, source: str) -> list[Pick]:
    """The source channels that are the rig's force channels (see :func:`map_channels`)."""
    if force_channel is not None:
        found = find_channel(force_channel, names)
        if found is None:
            raise ImportFormatError(f"{source}: force channel {force_channel!r} is not in the file "
                                    f"(it has {', '.join(repr(n) for n in names[:20])})")
        force_channel = found
        if not rig.forces:
            raise ImportFormatError(f"{source}: force channel {force_channel!r} given, but rig "
                                    f"{rig.name!r} has no [[forces]] channel")
        f = rig.forces[0]
        return [Pick(names.index(force_channel), 0, f.name, f.channel)]
    return [Pick(names.index(f.name), 0, f.name, f.channel) for f in rig.forces if f.name in names]


def _pick_gages(names: list[str], rig: Rig, channels: Mapping[str, int] | None, source: str,
                have_force: bool) -> list[tuple[int, int]]:
    """``(index into names, gage number)`` of the gage channels; ``""`` names are taken."""
    known = {g.number: g.channel for g in rig.gages}
    if channels is None:
        pairs = [(i, n, gage_of_name(n)) for i, n in enumerate(names) if n]
    else:
        index = {n: i for i, n in enumerate(names)}
        missing = [k for k in channels if k not in index]
        if missing:
            have = ", ".join(repr(n) for n in names[:20])
            raise ImportFormatError(f"{source}: channel map names {missing[0]!r}, which the "
                                    f"file does not have (it has {have})")
        pairs = [(index[k], k, int(g)) for k, g in channels.items()]
    picked: dict[int, tuple[int, str]] = {}
    for i, n, gage in pairs:
        if gage is None:
            raise ImportFormatError(f"{source}: channel {n!r} is not a gage name (g01, gage 1 "
                                    f"or 1); map it with {option('channels=', '--channels')}")
        if gage not in known:
            raise ImportFormatError(f"{source}: channel {n!r} is gage {gage}, which rig "
                                    f"{rig.name!r} does not have")
        if gage in picked:
            raise ImportFormatError(f"{source}: channels {picked[gage][1]!r} and {n!r} are "
                                    f"both gage {gage}")
        picked[gage] = (i, n)
    if not picked and not have_force:
        raise ImportFormatError(f"{source}: no channels to import")
    return [(i, g) for g, (i, _) in picked.items()]


_MS2 = {"m/s^2", "m/s2", "m/s/s", "ms^-2", "m*s^-2", "m.s^-2", "ms-2", "m/sec^2", "m/sec2"}
_GEE = {"g", "gn", "g_n", "g0", "g's"}


_VOLTS = {"v": 1.0, "volt": 1.0, "volts": 1.0, "mv": 1e-3, "millivolt": 1e-3, "millivolts": 1e-3}


def is_volts(unit: str | None) -> bool:
    """Whether a stated unit is a voltage (V, mV, Volts)."""
    return unit is not None and unit.strip().lower() in _VOLTS


def sensitivity_of(given: float | Mapping[str, float] | None, channel: str,
                   unit: str | None) -> float | None:
    """The sensitivity (V per m/s^2) ``given`` (one for all, or per source channel:
    :func:`parse_sensitivities`) that converts a source channel in volts; None for a channel
    not in volts or not named."""
    if not is_volts(unit):
        return None
    return given.get(channel) if isinstance(given, Mapping) else given


def unit_factor(unit: str | None, channel: str, source: str,
                sensitivity: float | None = None) -> float:
    """m/s^2 per unit of ``unit``: 1 for m/s^2 (and for no unit), 9.80665 for g; for a voltage
    (V, mV) 1 / the accelerometer's ``sensitivity`` (V per m/s^2), which it then needs.

    Raises
    ------
    ImportFormatError
        Any other unit, or a voltage without a sensitivity, naming the channel.
    """
    if unit is None or not unit.strip() or unit.strip().upper() == "NONE":
        return 1.0
    u = unit.strip().lower().replace(" ", "").replace("**", "^").replace("\u00b2", "^2")
    if u in _MS2:
        return 1.0
    if u in _GEE:
        return G0
    if is_volts(unit):
        if sensitivity is None:
            raise ImportFormatError(
                f"{source}: channel {channel!r} is in {unit.strip()!r}: an accelerometer's "
                f"volts need its sensitivity, {option('sensitivity=', '--sensitivity')} "
                f"'{channel}=100mV/g' (mV/g or V/(m/s^2); one value for every channel in volts)")
        return _VOLTS[unit.strip().lower()] / sensitivity
    raise ImportFormatError(f"{source}: channel {channel!r} is in {unit.strip()!r}; only m/s^2, "
                            f"g, and V or mV with {option('sensitivity=', '--sensitivity')} are "
                            f"accepted for an acceleration (a force channel in N, kN or lbf is "
                            f"named with --force-channel)")


def _stated(unit: str | None) -> bool:
    return unit is not None and bool(unit.strip()) and unit.strip().upper() != "NONE"


def force_unit_factor(unit: str | None, rig_unit: str, channel: str, source: str) -> float:
    """N per unit of a force channel: the file's ``unit`` (N, kN, lbf), or the rig's
    ``rig_unit`` when the file states none.

    Raises
    ------
    ImportFormatError
        Any other unit, naming the channel.
    """
    u = unit.strip() if _stated(unit) else rig_unit
    for name, factor in FORCE_UNITS.items():
        if u.lower() == name.lower():
            return factor
    raise ImportFormatError(f"{source}: force channel {channel!r} is in {u!r}; expected "
                            f"{', '.join(FORCE_UNITS)}")


# -- counts and scale ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Quantisation:
    """How one channel became counts.

    Attributes
    ----------
    method : {"stated", "quantised", "requantised", "zero"}
        The scale the file states (``# scale`` line) fits every value; source step detected;
        24-bit requantisation; or an all-zero channel.
    step : float
        The step in the file's unit (``nan`` when requantised).
    scale : float
        SI units per count (m/s^2 for a gage, N for a force).
    max_error : float
        Largest ``|counts*scale - x|`` over the channel, in the channel's SI unit (measured).
    bound : float
        Guaranteed bound on that error, in the channel's SI unit.
    exact : bool
        Every value was reproduced bit for bit (before the unit factor).
    """

    method: str
    step: float
    scale: float
    max_error: float
    bound: float
    exact: bool

    def to_json(self) -> dict:
        return {"method": self.method, "step": _finite(self.step), "scale": self.scale,
                "max_error_si": self.max_error, "error_bound_si": self.bound,
                "exact": self.exact}


def _finite(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def detect_step(v: np.ndarray) -> tuple[float, bool] | None:
    """Common step of ``v`` (finite, non-zero values): ``(step, exact)`` or ``None``.

    ``exact`` is True when ``rint(v/step)*step == v`` bit for bit. See the module docstring.
    """
    if v.size == 0:
        return None
    sample = v if v.size <= _STEP_SAMPLE else v[:: -(-v.size // _STEP_SAMPLE)]
    u = np.unique(np.abs(sample))
    gaps = np.diff(u, prepend=0.0)
    gaps = gaps[gaps > 0]
    if gaps.size == 0:
        return None
    g = float(gaps.min())
    mag = np.abs(sample)
    peak = float(np.max(np.abs(v)))
    for m in (1, 2, 3, 4):
        s = g / m
        if not s > 1e-300:  # a step this small is no ADC's
            return None
        for limit in (2.0**4, 2.0**8, 2.0**12, 2.0**16, 2.0**20):  # the gap is not exact:
            near = sample[mag <= limit * s]  # refine on small counts first, then larger
            kn = np.rint(near / s)
            if kn.size and np.any(kn):
                s = float(np.dot(kn, near) / np.dot(kn, kn))
        if not s > 0 or peak / s > _INT32_MAX - 1:
            return None
        k = np.rint(v / s)
        err = float(np.max(np.abs(v - k * s)))
        if err > STEP_TOLERANCE * s:
            continue
        s_ls = float(np.dot(k, v) / np.dot(k, k))
        # the exact float step, if any, is within an ulp of v/k at the largest counts
        top = np.argpartition(np.abs(k), -min(16, k.size))[-16:]
        near = np.unique(v[top] / k[top])
        cands = np.unique(np.concatenate([near, np.nextafter(near, 0), np.nextafter(near, 1),
                                          [s_ls, s]]))
        head_k, head_v = k[:64], v[:64]
        for c in cands[np.argsort(np.abs(cands - s_ls))]:
            if np.array_equal(head_k * c, head_v) and np.array_equal(k * c, v):
                return float(c), True
        err_ls = float(np.max(np.abs(v - k * s_ls)))
        return (s_ls, False) if err_ls <= err else (s, False)
    return None


def quantise(x: np.ndarray, factor: float, scale: float | None = None
             ) -> tuple[np.ndarray, Quantisation]:
    """Counts (int32, 0 where ``x`` is not finite) and how they were made.

    ``scale`` (SI per count), when the file states it (``ramdaq export-csv``'s ``# scale``
    line), is taken as it is, bit for bit, if every value lies within ``STEP_TOLERANCE`` of its
    grid (``x * factor / scale`` near whole counts that fit int32); otherwise the step is found
    as for any file (``method`` says ``"quantised"``, not ``"stated"``).

    Parameters
    ----------
    x : numpy.ndarray
        One channel in the file's unit, float64; NaN for missing samples.
    factor : float
        m/s^2 per file unit.

    Raises
    ------
    ValueError
        The channel's largest value is beyond 1e-290 .. 1e290 m/s^2.
    """
    finite = np.isfinite(x)
    v = x[finite]
    v = v[v != 0]
    if v.size == 0:
        return np.zeros(x.shape, np.int32), Quantisation("zero", math.nan, 1.0, 0.0, 0.0, True)
    peak = float(np.max(np.abs(v))) * factor
    if not _TINY <= peak <= _HUGE:
        raise ValueError(f"its largest value {peak:g} m/s^2 is out of range")
    xf = np.where(finite, x, 0.0)
    if scale is not None and scale > 0 and peak / scale < _INT32_MAX - 1:
        counts = np.rint(xf * factor / scale)
        err = float(np.max(np.abs(counts * scale - xf * factor)))
        if err <= STEP_TOLERANCE * scale:
            exact = bool(np.array_equal(counts * scale, xf * factor))
            return counts.astype(np.int32), Quantisation("stated", scale / factor, scale, err,
                                                          max(err, STEP_TOLERANCE * scale), exact)
    found = detect_step(v)
    if found is not None and found[0] * factor >= _TINY:
        step, exact = found
        scale = step * factor
        counts = np.rint(xf / step)
        err = float(np.max(np.abs(counts * scale - xf * factor)))
        bound = max(err, STEP_TOLERANCE * scale)
        return counts.astype(np.int32), Quantisation("quantised", step, scale, err, bound, exact)
    scale = peak / FULL_SCALE_COUNTS
    xs = xf * factor
    counts = np.rint(xs / scale)
    err = float(np.max(np.abs(counts * scale - xs)))
    return counts.astype(np.int32), Quantisation("requantised", math.nan, scale, err, scale / 2,
                                                  False)


def _dropped_with_gaps(missing: np.ndarray, nan_rows: list[np.ndarray],
                       names: list[str]) -> dict:
    """``{"dropped_with_gaps": {"missing": {channel: n}, "good": {channel: n}}}``: a row
    missing a value on some channels is a gap on every channel (a recording's gaps are
    stream-wide; a block has no per-channel hole), so the other channels' good values on those
    rows go with it; the counts say how many, per source channel. Empty when no row misses a
    value."""
    if not missing.any():
        return {}
    lost = {n: int(np.count_nonzero(nan)) for n, nan in zip(names, nan_rows, strict=True)}
    good = {n: int(np.count_nonzero(missing & ~nan)) for n, nan in zip(names, nan_rows,
                                                                       strict=True)}
    return {"dropped_with_gaps": {"missing": {n: k for n, k in lost.items() if k},
                                  "good": {n: k for n, k in good.items() if k}}}


MEDIA = ("air", "water")


def stated_medium(found: list[tuple[str, object]], source: str) -> dict:
    """The medium a file states, from ``(where, value)`` pairs (a TDMS ``medium`` property, a
    UFF header's ``medium: water``): ``{"medium": "water", "medium_where": where}`` for
    :attr:`SourceTable.notes`, ``{}`` when the file states none. ImportFormatError, naming
    where, when a value is not air or water or two places disagree."""
    media: dict[str, str] = {}
    for where, v in found:
        m = str(v).strip().lower()
        if m not in MEDIA:
            raise ImportFormatError(f"{source}: {where} states medium {v!r}: expected air or water")
        media.setdefault(m, where)
    if len(media) > 1:
        (a, wa), (b, wb) = media.items()
        raise ImportFormatError(f"{source}: {wa} states medium {a} but {wb} states {b}")
    if not media:
        return {}
    ((m, where),) = media.items()
    return {"medium": m, "medium_where": where}


def snap_rate(fs_hz: float, rel_tol: float) -> float:
    """The value with the fewest significant digits within ``rel_tol`` of ``fs_hz``, Hz.

    A rate recovered from printed times or increments (``1/4.88281e-04 = 2048.0016``) comes back
    as the rate the recorder was set to (``2048.0``).
    """
    for digits in range(1, 16):
        c = float(f"{fs_hz:.{digits}g}")
        if c > 0 and abs(c / fs_hz - 1) <= rel_tol:
            return c
    return fs_hz


# -- the source and the device -------------------------------------------------------------------
@dataclass
class SourceTable:
    """A file's samples as its importer found them.

    Attributes
    ----------
    names : list of str
        Source channel names.
    units : list of str or None
        Each channel's unit as the file states it (None: not stated).
    sample_index : numpy.ndarray
        int64 sample index of each row from the first row's sample, strictly increasing.
    fs_hz : float
        Sample rate, Hz.
    t0_s : float
        Time of sample index 0, s (the file's own time origin).
    read : callable
        ``read(i)`` -> float64 values of channel ``i``, one per row, NaN where missing.
    fmt : str
        ``"csv"``, ``"uff58"``, ``"tdms"``.
    notes : dict
        Format-specific facts for ``StreamInfo.extra["import"]`` (JSON-serialisable).
    close : callable, optional
        Releases the file once every channel has been read.
    where : callable, optional
        ``where(row)`` -> where that row is in the file (``"line 12"``), for messages.
    aliases : dict
        Other names of channels -> their name (a UFF record's ID line 1 -> its node).
    """

    names: list[str]
    units: list[str | None]
    sample_index: np.ndarray
    fs_hz: float
    t0_s: float
    read: Callable[[int], np.ndarray]
    fmt: str
    notes: dict = field(default_factory=dict)
    close: Callable[[], None] | None = None
    where: Callable[[int], str] | None = None
    aliases: dict[str, str] = field(default_factory=dict)


class FileImportDevice(Device):
    """Base of the file importers: a finite stream of the file's samples as counts.

    Parameters
    ----------
    path : str or PathLike
        The file.
    rig : Rig or path
        The rig the recording was made on (gage numbers, channel order, medium).
    channels : mapping of str to int, optional
        Source channel name -> gage number; only these are imported.
    medium : str, optional
        Override the rig's medium ("air" or "water").
    block_s : float
        Longest block, s.
    fs_hz : float, optional
        The file's sample rate, Hz, as the user states it. Without it the file's own rate must
        be the rig's ``daq.sample_rate_hz`` (within :data:`RATE_TOLERANCE`); with it, the
        file's rate must be this one (a CSV's rows are placed on its grid).
    force_channel : str, optional
        The source channel that is the rig's force channel (:func:`map_channels`).
    allow_gaps : bool
        A missing value (NaN, an empty cell) drops its row, a gap in the stream that the
        recording keeps. Without it a missing value is an error naming where it is.
    sensitivity : float or mapping of str to float, optional
        V per m/s^2 of the accelerometers whose channels the file holds in volts (V, mV): one
        for all, or per source channel (:func:`parse_sensitivities`). A channel in volts
        without one, or one given for a channel not in volts, is an error.
    """

    kind = "import"
    pace = "fast"  # a file has no clock to keep: the record loop waits for the recorder

    def __init__(self, path: str | PathLike, *, rig: Rig | str | PathLike,
                 channels: Mapping[str, int] | None = None, medium: str | None = None,
                 block_s: float = 0.1, fs_hz: float | None = None,
                 force_channel: str | None = None, allow_gaps: bool = False,
                 sensitivity: float | Mapping[str, float] | None = None) -> None:
        super().__init__()
        if fs_hz is not None and not (isinstance(fs_hz, int | float) and 0 < fs_hz < 1e9):
            raise ValueError(f"{self.kind}: fs_hz ({fs_hz}) must be a positive rate in Hz")
        if not block_s > 0:
            raise ValueError(f"{self.kind}: block_s ({block_s}) must be positive")
        self.path = Path(path)
        rig = rig if isinstance(rig, Rig) else load_rig(rig)
        self.rig = rig.with_medium(medium) if medium else rig
        self.medium_given, self._rig_medium = medium, rig.medium
        self.channels = dict(channels) if channels is not None else None
        self.block_s = float(block_s)
        self.fs_hz = None if fs_hz is None else float(fs_hz)
        self.force_channel = force_channel
        self.allow_gaps = bool(allow_gaps)
        self.sensitivity = dict(sensitivity) if isinstance(sensitivity, Mapping) else sensitivity
        self._blocks: Iterator[Block] | None = None

    def _load(self) -> SourceTable:
        """Read the file (subclasses)."""
        raise NotImplementedError

    def _open(self) -> StreamInfo:
        if not self.path.is_file():
            raise DeviceNotFound(f"{self.kind}: no file at {self.path}")
        src = self._load()
        try:
            return self._convert(src)
        finally:
            if src.close is not None:
                src.close()

    def _convert(self, src: SourceTable) -> StreamInfo:
        name = str(self.path)
        idx = np.asarray(src.sample_index, dtype=np.int64)
        if idx.size == 0 or idx[0] < 0 or np.any(np.diff(idx) <= 0):
            raise ImportFormatError(f"{name}: no samples, or samples overlap or go back in time")
        fs, t0 = float(src.fs_hz), float(src.t0_s)
        if not (1e-3 <= fs <= 1e9 and abs(t0) < _MAX_TIME_S and (idx[-1] + 1) / fs < _MAX_TIME_S):
            raise ImportFormatError(f"{name}: sample rate {fs:g} Hz, start {t0:g} s or length "
                                    f"{int(idx[-1]) + 1} samples is out of range")
        self._check_rate(fs, name)
        medium_note = self._apply_stated_medium(src.notes.get("medium"), name)
        stated_scales = src.notes.get("scales", {})
        picks = map_channels(src.names, self.rig, self._channel_map(src.names, name), name,
                             self.force_channel, src.aliases)
        counts = np.empty((len(picks), idx.size), np.int32)
        missing = np.zeros(idx.size, bool)
        scales, notes, nan_rows = [], {}, []
        for row, pick in enumerate(picks):
            i = pick.index
            x = np.asarray(src.read(i), dtype=np.float64)
            what = f"{name}: channel {src.names[i]!r}"
            if x.shape != idx.shape:
                raise ImportFormatError(f"{what} has {x.size} samples, expected {idx.size}")
            if np.any(np.isinf(x)):
                raise ImportFormatError(f"{what} is infinite at sample {np.argmax(np.isinf(x))}")
            if not self.allow_gaps and np.any(np.isnan(x)):
                r = int(np.argmax(np.isnan(x)))
                raise ImportFormatError(
                    f"{name}: {src.where(r) if src.where else f'row {r}'}, column "
                    f"{src.names[i]!r}: missing value (empty or NaN); "
                    f"{option('allow_gaps=', '--allow-gaps')} "
                    f"imports it as a gap in the recording")
            sens, sens_from = self._sensitivity_of(src.names[i], src.units[i], name,
                                                   None if pick.is_force else pick.gage)
            factor = (force_unit_factor(src.units[i], self.rig.force(pick.name).unit,
                                        src.names[i], name) if pick.is_force
                      else unit_factor(src.units[i] if _stated(src.units[i])
                                       else self.rig.gage(pick.gage).assumed_unit, src.names[i],
                                       name, sens))
            try:
                counts[row], q = quantise(x, factor, stated_scales.get(src.names[i]))
            except ValueError as err:
                raise ImportFormatError(f"{what}: {err}") from None
            nan_rows.append(np.isnan(x))
            missing |= nan_rows[-1]
            scales.append(q.scale)
            rig_unit = None if pick.is_force else self.rig.gage(pick.gage).unit
            assumed = self.rig.force(pick.name).unit if pick.is_force else \
                self.rig.gage(pick.gage).assumed_unit
            notes[pick.name] = {"source": src.names[i], "unit": src.units[i] or f"{assumed} (assumed)",
                                "si_unit": "N" if pick.is_force else "m/s^2", **q.to_json()}
            if sens is not None:
                notes[pick.name]["sensitivity_V_per_m_s2"] = sens
            if sens_from:
                notes[pick.name]["sensitivity_from"] = sens_from
            if rig_unit is not None and _stated(src.units[i]) and sens is None and \
                    factor != unit_factor(rig_unit, src.names[i], name):
                notes[pick.name]["rig_unit_not_applied"] = rig_unit  # the header's unit wins
        self._check_sensitivities_used([src.names[p.index] for p in picks],
                                       [src.units[p.index] for p in picks], name)
        if missing.all():
            raise ImportFormatError(f"{name}: every row misses a value; nothing to import")
        # samples count from the file's time zero, so times in ramdaq are the file's times
        offset = round(t0 * fs) if t0 >= 0 else 0
        self._idx, self._counts = idx[~missing] + offset, counts[:, ~missing]
        self._scale, self._fs = np.asarray(scales, np.float64), fs
        self._t0_ns = round((t0 - offset / fs) * 1e9)  # the sub-sample part of the start
        self._block_n = max(1, round(self.block_s * fs))
        breaks = np.flatnonzero(np.diff(self._idx) != 1) + 1
        self._segments = list(zip(np.r_[0, breaks], np.r_[breaks, self._idx.size], strict=True))
        report = {**src.notes, "format": src.fmt, "file": self.path.name, "bytes": self.path.stat().st_size,
                  "rows": int(idx.size), "fs_hz": src.fs_hz, "t0_s": t0,
                  "first_sample": int(self._idx[0]), "segments": len(self._segments),
                  "missing_samples": int(idx[-1] - idx[0] + 1 - self._idx.size),
                  "channels": notes, **medium_note,
                  **_dropped_with_gaps(missing, nan_rows, [src.names[p.index] for p in picks])}
        self._blocks = self._iter_blocks()
        return StreamInfo(
            device=f"{self.kind}://{self.path}", fs_hz=fs,
            channels=tuple(p.name for p in picks),
            units=tuple("N" if p.is_force else "m/s^2" for p in picks),
            gages=tuple(p.gage for p in picks), rig_toml=self.rig.text,
            extra={"medium": self.rig.medium, "rig_name": self.rig.name,
                   "block_samples": self._block_n, "import": report})

    def _sensitivity_of(self, channel: str, unit: str | None, name: str,
                        gage: int | None) -> tuple[float | None, str]:
        """The sensitivity (V per m/s^2) that converts a source channel the file holds in volts,
        and where it came from ("" where given, else the rig's words): the one given for it,
        else that of its ``gage`` in the rig (a channels-only rig written by an import of a file
        in volts keeps it); None for a channel not in volts (or one in volts with neither). A
        sensitivity named for a channel not in volts is an error (it would otherwise go unused,
        unsaid)."""
        given = self.sensitivity
        if isinstance(given, dict) and channel in given and not is_volts(unit):
            raise ImportFormatError(f"{name}: channel {channel!r} is in {unit or 'no unit'!r}, "
                                    f"not volts: its {option('sensitivity=', '--sensitivity')} "
                                    f"does not apply")
        sens = sensitivity_of(given, channel, unit)
        if sens is None and is_volts(unit) and gage is not None:
            rig_sens = self.rig.gage(gage).sensitivity_V_per_m_s2
            if math.isfinite(rig_sens):
                return rig_sens, f"gage {gage}'s sensitivity in rig {self.rig.name!r}"
        return sens, ""

    def _check_sensitivities_used(self, names: list[str], units: list[str | None], name: str) -> None:
        """A sensitivity given for a channel not imported, or one value with no channel in volts,
        is an error, not a silent no-op."""
        given, opt = self.sensitivity, option("sensitivity=", "--sensitivity")
        if isinstance(given, dict):
            unused = [c for c in given if c not in names]
            if unused:
                raise ImportFormatError(f"{name}: {opt} names {', '.join(map(repr, unused))}, "
                                        f"not among the channels imported ({', '.join(map(repr, names))})")
        elif given is not None and not any(is_volts(u) for u in units):
            raise ImportFormatError(f"{name}: {opt} given, but no channel imported is in volts")

    def _apply_stated_medium(self, stated: str | None, name: str) -> dict:
        """The medium the file states (``# medium: water``, a TDMS ``medium`` property, a UFF
        header's ``medium: water``) applied to the rig unless ``medium`` was given;
        ``{"medium_stated": {...}}`` says what was stated (``file``, None when nothing), the
        rig's, the one applied and why (``given``, ``file`` or ``rig``), for the importer's
        caller to print."""
        if stated is None:
            return {"medium_stated": {"file": None, "rig": self._rig_medium, "applied": self.rig.medium,
                                      "by": "rig" if self.medium_given is None else "given"}}
        if self.medium_given is not None:
            applied, why = self.medium_given, "given"
        else:
            applied, why = stated, "file"
            if stated != self._rig_medium:
                try:
                    self.rig = self.rig.with_medium(stated)
                except ValueError as err:
                    raise ImportFormatError(f"{name}: the file states medium {stated}, which rig "
                                            f"{self.rig.name!r} cannot take ({err})") from None
        return {"medium_stated": {"file": stated, "rig": self._rig_medium, "applied": applied,
                                  "by": why}}

    def _channel_map(self, names: list[str], name: str) -> Mapping[str, int] | None:
        """The map given, else the source channels the rig was written for (a channels-only
        rig from ``ramdaq import``) when the file's channels are among them, else None."""
        known = rig_source_map(self.rig.text)
        if self.channels is not None or not known:
            return self.channels
        force = None if self.force_channel is None else find_channel(self.force_channel, names)
        others = [n for n in names if n != force and n not in {f.name for f in self.rig.forces}]
        if all(n in known for n in others):
            return {n: known[n] for n in others}
        if any(n in known for n in others) or all(gage_of_name(n) is None for n in others):
            odd = next(n for n in others if n not in known)
            have = ", ".join(repr(n) for n in list(known)[:20])
            raise ImportFormatError(f"{name}: channel {odd!r} is not a source channel of rig "
                                    f"{self.rig.name!r} (it was written for {have}); map this "
                                    f"file's channels with {option('channels=', '--channels')}")
        return None

    def _check_rate(self, fs: float, name: str) -> None:
        """The file's rate ``fs`` (Hz) against ``fs_hz`` as stated, else against the rig's."""
        if self.fs_hz is not None:
            if abs(fs / self.fs_hz - 1) > RATE_TOLERANCE:
                raise ImportFormatError(f"{name}: the file's sample rate is {fs:g} Hz, not the "
                                        f"{self.fs_hz:g} Hz stated "
                                        f"({option('fs_hz=', '--fs')})")
            why = self.rig.cannot_describe_rate(fs)
            if why:
                raise ImportFormatError(f"{name}: {why}")
            return
        rig_fs = self.rig.daq.sample_rate_hz
        if abs(fs / rig_fs - 1) > RATE_TOLERANCE:
            said = (f"{name}: the file's sample rate {fs:g} Hz disagrees with rig "
                    f"{self.rig.name!r} (daq.sample_rate_hz = {rig_fs:g} Hz)")
            unit = _unit_slip(fs / rig_fs)
            if unit or not _RATES.lo <= fs <= _RATES.hi:
                # a time column read in the wrong unit, or a rate no trial has: stating it would
                # only make a recording nothing can analyse (a new user's 't [ms]' on seconds,
                # told to give --fs 2.048e+06)
                why = unit or f"outside the {_RATES.lo:g}-{_RATES.hi:g} Hz a trial is sampled at"
                raise ImportFormatError(f"{said}: {why} -- check the time column's unit (its "
                                        f"header, or {option('time_unit=', '--time-unit')})")
            raise ImportFormatError(f"{said}; if the file is right, state it with "
                                    f"{option(f'fs_hz={fs:g}', f'--fs {fs:g}')}")

    def _iter_blocks(self) -> Iterator[Block]:
        seq = 0
        for a, b in self._segments:
            for s in range(a, b, self._block_n):
                first = int(self._idx[s])
                yield Block(seq=seq, first_sample=first,
                            t0_ns=self._t0_ns + sample_time_ns(first, self._fs), fs_hz=self._fs,
                            counts=np.ascontiguousarray(self._counts[:, s:min(b, s + self._block_n)]),
                            scale=self._scale.copy())
                seq += 1

    def _read(self, timeout: float | None) -> Block | None:
        return next(self._blocks, None) if self._blocks is not None else None

    def _close(self) -> None:
        self._blocks = None
        self._counts = np.empty((0, 0), np.int32)
