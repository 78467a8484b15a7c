"""A channels-only rig for a record that comes without one (``ramdaq import FILE --fs --units``).

The rig names each source channel's gage (a name like ``g03`` or ``3`` keeps its number, the
others are numbered from 1 in the file's order), the unit the file gives them in when it states
none, the force channel if one is named, and the rate. It describes no structure, so the
analysis gives each gage's frequency, decrement and damping ratio and skips the report's chain;
``recordings/rigs/README.md`` ("A channels-only rig") has the format.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from ...analysis.model.rig import FORCE_UNITS, GAGE_UNITS, MAX_CHANNELS
from .import_common import ImportFormatError, gage_of_name

__all__ = ["MinimalRig", "minimal_rig", "source_channel_names"]


@dataclass(frozen=True)
class MinimalRig:
    """A channels-only rig's TOML ``text`` and the source channel -> gage map it implies."""

    text: str
    channels: dict[str, int]


def source_channel_names(path: Path, fmt: str, *, time_unit: str | None = None) -> list[str]:
    """The channel names a CSV, UFF 58 or TDMS file holds (``fmt``: ``csv``, ``uff``, ``unv``,
    ``tdms``), in the file's order. Raises :class:`ImportFormatError` for an unreadable file."""
    if fmt == "csv":
        from .import_csv import read_csv_table

        return read_csv_table(path.read_bytes(), str(path), time_unit=time_unit,
                              fs_hz=None).names
    if fmt in ("uff", "unv"):
        from .import_uff import read_uff_table

        return read_uff_table(path).names
    if fmt == "tdms":
        from .import_tdms import read_tdms_table

        src = read_tdms_table(path)
        if src.close is not None:
            src.close()
        return src.names
    raise ImportFormatError(f"{path}: format {fmt!r} is not csv, uff or tdms")


def minimal_rig(names: list[str], *, name: str, fs_hz: float, units: str,
                force_channel: str | None = None, force_unit: str = "N",
                medium: str = "air") -> MinimalRig:
    """A channels-only rig for source channels ``names``.

    Parameters
    ----------
    names : list of str
        The source channels to import, in the file's order.
    name : str
        The rig's name (the file's stem).
    fs_hz : float
        Sample rate, Hz.
    units : {"m/s^2", "g"}
        The unit of the gage channels whose file states none.
    force_channel : str, optional
        The source channel that is a force (it keeps its name); the others are gages.
    force_unit : {"N", "kN", "lbf"}
        Its unit when the file states none.
    medium : {"air", "water"}

    Raises
    ------
    ValueError
        A unit that is not one of the above, no gage channel, more than 64 channels, or a
        ``force_channel`` not among ``names``.
    """
    if units not in GAGE_UNITS:
        raise ValueError(f"--units {units!r}: expected {' or '.join(GAGE_UNITS)}")
    if force_unit not in FORCE_UNITS:
        raise ValueError(f"force unit {force_unit!r}: expected {', '.join(FORCE_UNITS)}")
    if force_channel is not None and force_channel not in names:
        raise ValueError(f"--force-channel {force_channel!r} is not a channel of the file (it has "
                         f"{', '.join(repr(n) for n in names[:20])})")
    accel = [n for n in names if n != force_channel]
    if not accel or len(names) > MAX_CHANNELS:
        raise ValueError(f"{len(accel)} acceleration channel(s) of {len(names)}: a rig needs 1 to "
                         f"{MAX_CHANNELS} channels, one at least a gage")
    channels = _number_gages(accel)
    lines = [f"# A channels-only rig, written by ramdaq import (no rig given): {len(channels)} "
             f"gage(s){' and a force channel' if force_channel else ''}.",
             f"name = {json.dumps(name)}", 'units = "SI"', f"medium = {json.dumps(medium)}", "",
             "[daq]", f"sample_rate_hz = {float(fs_hz)!r}"]
    for k, (src, gage) in enumerate(channels.items()):
        lines += ["", f"[[gages]]  # source channel {json.dumps(src)}", f"number = {gage}",
                  f"channel = {k}", f"unit = {json.dumps(units)}"]
    if force_channel is not None:
        lines += ["", "[[forces]]", f"name = {json.dumps(force_channel)}",
                  f"channel = {len(channels)}", f"unit = {json.dumps(force_unit)}"]
    return MinimalRig("\n".join(lines) + "\n", channels)


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
