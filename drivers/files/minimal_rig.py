"""A channels-only rig for a record that comes without one (``ramdaq import FILE [--units]``).

The rig names each source channel's gage (a name like ``g03`` or ``3`` keeps its number, the
others are numbered from 1 in the file's order), the unit each channel's samples are in (the
file's where it states one, else ``--units``), the force channel if one is named, and the rate
(the file's own: a CSV's time column, UFF's abscissa, TDMS's wf_increment). It describes no structure, so the
analysis gives each gage's frequency, decrement and damping ratio and skips the report's chain;
``recordings/rigs/README.md`` ("A channels-only rig") has the format.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from ...analysis.model.rig import FORCE_UNITS, GAGE_UNITS, MAX_CHANNELS
from .import_common import G0, ImportFormatError, find_channel, gage_of_name, unit_factor

__all__ = ["MinimalRig", "SourceChannels", "minimal_rig", "source_channels",
           "source_channel_names"]


@dataclass(frozen=True)
class MinimalRig:
    """A channels-only rig's TOML ``text``, the source channel -> gage map it implies, and the
    gage channels whose file unit differs from the ``units`` asked for (``(channel, file unit)``:
    the file's unit was applied and recorded, see :func:`minimal_rig`)."""

    text: str
    channels: dict[str, int]
    overridden: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class SourceChannels:
    """What a file says of its channels: names, units as stated (None: not stated) and its
    sample rate, Hz (from a CSV's time column, UFF's abscissa or TDMS's wf_increment), and
    the medium it states (``# medium: water`` from ``ramdaq export-csv``; None: not stated)."""

    names: list[str]
    units: list[str | None]
    fs_hz: float
    aliases: dict[str, str] | None = None
    medium: str | None = None
    anti_alias: tuple[int, float] | None = None
    """The anti-alias filter the file states, (order, corner Hz) (``# anti-alias:`` from
    ``ramdaq export-csv``; None: not stated)."""


def source_channels(path: Path, fmt: str, *, time_unit: str | None = None,
                    fs_hz: float | None = None, group: str | None = None) -> SourceChannels:
    """The channels a CSV, UFF 58 or TDMS file holds (``fmt``: ``csv``, ``uff``, ``unv``,
    ``tdms``), in the file's order, with their stated units and the file's rate. ``fs_hz``
    (Hz) is needed only for a CSV of one row; ``group`` picks a TDMS file's group. Raises
    :class:`ImportFormatError` for an unreadable file."""
    if fmt == "csv":
        from .import_csv import read_csv_table

        src = read_csv_table(path.read_bytes(), str(path), time_unit=time_unit, fs_hz=fs_hz)
    elif fmt in ("uff", "unv"):
        from .import_uff import read_uff_table

        src = read_uff_table(path)
    elif fmt == "tdms":
        from .import_tdms import read_tdms_table

        src = read_tdms_table(path, group=group)
        if src.close is not None:
            src.close()
    else:
        raise ImportFormatError(f"{path}: format {fmt!r} is not csv, uff or tdms")
    return SourceChannels(list(src.names), list(src.units), float(src.fs_hz), dict(src.aliases),
                          src.notes.get("medium"), src.notes.get("anti_alias"))


def source_channel_names(path: Path, fmt: str, *, time_unit: str | None = None) -> list[str]:
    """The channel names a file holds (:func:`source_channels`)."""
    return source_channels(path, fmt, time_unit=time_unit).names


def minimal_rig(names: list[str], *, name: str, fs_hz: float, units: str | None,
                force_channel: str | None = None, force_unit: str = "N",
                medium: str = "air", file_units: list[str | None] | None = None,
                anti_alias: tuple[int, float] | None = None,
                sensitivities: Mapping[str, float] | None = None) -> MinimalRig:
    """A channels-only rig for source channels ``names``.

    Each gage records the unit its samples are in: the file's own where ``file_units`` states
    one (m/s^2 or g, any spelling :func:`unit_factor` knows), else ``units``. A file unit that
    differs from ``units`` wins (the header is the file's word for its own samples) and is
    listed in :attr:`MinimalRig.overridden`, for the caller to say so. The rig written thus
    re-imports its own source and a sibling file without unit headers at the same scale.

    Parameters
    ----------
    names : list of str
        The source channels to import, in the file's order.
    name : str
        The rig's name (the file's stem).
    fs_hz : float
        Sample rate, Hz.
    units : {"m/s^2", "g"} or None
        The unit of the gage channels whose file states none; None only when every gage
        channel states its own.
    force_channel : str, optional
        The source channel that is a force (it keeps its name); the others are gages.
    force_unit : {"N", "kN", "lbf"}
        Its unit when the file states none.
    medium : {"air", "water"}
    file_units : list of (str or None), optional
        The unit each of ``names`` states in the file.
    anti_alias : (int, float), optional
        The filter the samples passed, (order, corner Hz), where the file states it: written
        into ``[daq]`` so that the trigger removes its delay from onsets, as for the recording
        the file was exported from (without it the onset is the filtered edge's, ~0.5 sample
        later at 2048 Hz for a 4th-order 800 Hz filter).
    sensitivities : mapping of str to float, optional
        The accelerometer sensitivity (V per m/s^2) of each source channel recorded in volts
        (``--sensitivity``): written into its gage, so that the rig converts the file again.

    Raises
    ------
    ValueError
        A unit that is not one of the above, a gage channel with no unit at all, no gage
        channel, more than 64 channels, or a ``force_channel`` not among ``names``.
    """
    if units is not None and units not in GAGE_UNITS:
        raise ValueError(f"--units {units!r}: expected {' or '.join(GAGE_UNITS)}")
    if force_unit not in FORCE_UNITS:
        raise ValueError(f"force unit {force_unit!r}: expected {', '.join(FORCE_UNITS)}")
    if force_channel is not None:
        force_channel = find_channel(force_channel, names) or force_channel
    if force_channel is not None and force_channel not in names:
        raise ValueError(f"--force-channel {force_channel!r} is not a channel of the file (it has "
                         f"{', '.join(repr(n) for n in names[:20])})")
    stated = dict(zip(names, file_units or [None] * len(names), strict=True))
    accel = [n for n in names if n != force_channel]
    if not accel or len(names) > MAX_CHANNELS:
        raise ValueError(f"{len(accel)} acceleration channel(s) of {len(names)}: a rig needs 1 to "
                         f"{MAX_CHANNELS} channels, one at least a gage")
    applied, overridden = {}, []
    for n in accel:
        applied[n] = _gage_unit(stated[n], units, n, name)
        if _is_stated(stated[n]) and units is not None and applied[n] != units:
            overridden.append((n, applied[n]))
    if force_channel is not None and _is_stated(stated[force_channel]):
        force_unit = _force_unit(stated[force_channel], force_channel, name)
    channels = _number_gages(accel)
    lines = [f"# A channels-only rig, written by ramdaq import (no rig given): {len(channels)} "
             f"gage(s){' and a force channel' if force_channel else ''}; each unit is the one "
             f"its samples are in.",
             f"name = {json.dumps(name)}", 'units = "SI"', f"medium = {json.dumps(medium)}", "",
             "[daq]", f"sample_rate_hz = {float(fs_hz)!r}"]
    if anti_alias is not None:
        lines += [f"anti_alias_hz = {float(anti_alias[1])!r}", f"anti_alias_order = {int(anti_alias[0])}"]
    for k, (src, gage) in enumerate(channels.items()):
        lines += ["", f"[[gages]]  # source channel {json.dumps(src)}", f"number = {gage}",
                  f"channel = {k}", f"unit = {json.dumps(applied[src])}"]
        if sensitivities and src in sensitivities:  # its file is in volts
            lines.append(f"sensitivity_V_per_m_s2 = {float(sensitivities[src])!r}")
    if force_channel is not None:
        lines += ["", "[[forces]]", f"name = {json.dumps(force_channel)}",
                  f"channel = {len(channels)}", f"unit = {json.dumps(force_unit)}"]
    return MinimalRig("\n".join(lines) + "\n", channels, tuple(overridden))


def _is_stated(unit: str | None) -> bool:
    return unit is not None and bool(unit.strip()) and unit.strip().upper() != "NONE"


def _gage_unit(stated: str | None, units: str | None, channel: str, source: str) -> str:
    """The rig unit (``"m/s^2"`` or ``"g"``) of a gage channel: the file's, else ``units``."""
    if not _is_stated(stated):
        if units is None:
            raise ValueError(f"channel {channel!r} states no unit; give --units g|m/s^2")
        return units
    return "g" if unit_factor(stated, channel, source) == G0 else "m/s^2"


def _force_unit(stated: str, channel: str, source: str) -> str:
    """The rig unit (a key of ``FORCE_UNITS``) of a force channel's stated unit."""
    for unit in FORCE_UNITS:
        if stated.strip().lower() == unit.lower():
            return unit
    raise ImportFormatError(f"{source}: force channel {channel!r} is in {stated.strip()!r}; "
                            f"expected {', '.join(FORCE_UNITS)}")


def _number_gages(names: list[str]) -> dict[str, int]:
    """Source name -> gage number: its own (``g03``, ``3``) where that is free and at most 64,
    else the lowest free number, in the file's order."""
    own = {n: gage_of_name(n) for n in names}
    taken: set[int] = set()
    out: dict[str, int] = {}
    for n in names:
        g = own[n]
        if g is not None and 1 <= g <= MAX_CHANNELS and g not in taken:
            out[n] = g
            taken.add(g)
    free = (g for g in range(1, MAX_CHANNELS + 1) if g not in taken and g not in own.values())
    for n in names:
        if n not in out:
            out[n] = next(free)
    return {n: out[n] for n in names}
