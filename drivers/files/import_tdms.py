"""Import an NI TDMS file (LabVIEW, DAQmx, FlexLogger) as a device, with nptdms.

::

    with open_device("trial.tdms", rig=rig) as dev:    # or TdmsImportDevice(...)
        for block in dev:
            ...

Channels are the numeric channels of every group (``group=`` picks one), named by their
channel name (``"group/channel"`` where two groups share a name), mapped to gages like CSV
columns. The time axis comes from the waveform properties ``wf_increment`` (s per sample) and
``wf_start_offset`` (s), which all channels must share, with equal lengths; a file without them
needs a channel named ``time`` (s), placed on a sample grid as a CSV time column is. The unit is
the channel's ``unit_string`` (m/s^2 or g; none is taken as m/s^2). NaN samples are gaps. A
``medium`` property (any case) of the file, a group or an imported channel states the medium
(air or water; :func:`~ramdaq.drivers.files.import_common.stated_medium`).

The file is opened for streaming (``TdmsFile.open``): only the mapped channels are read. Before
nptdms sees it, the chain of segment lead-ins is walked, so a file cut short (a segment that
declares more bytes than are left, or one its writer never finished) is refused as truncated
rather than imported in part; nptdms's own warnings become notes in ``StreamInfo.extra``.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable, Mapping
from os import PathLike
from pathlib import Path

import numpy as np

from ...analysis.model.rig import Rig
from .import_common import FileImportDevice, ImportFormatError, SourceTable, option, snap_rate, stated_medium
from .import_csv import sample_grid

__all__ = ["TdmsImportDevice", "check_tdms_segments"]

_LEAD_IN = 28
_TOC_BIG_ENDIAN = 1 << 6
_UNFINISHED = 0xFFFF_FFFF_FFFF_FFFF
_TIME_NAMES = {"time", "t", "time_s", "zeit", "timestamp"}


class TdmsImportDevice(FileImportDevice):
    """A TDMS file streamed as blocks (back-end name ``"tdms"``).

    Parameters
    ----------
    path : str or PathLike
        The TDMS file.
    rig : Rig or path
        The rig of the trial.
    channels : mapping of str to int, optional
        Channel name (or ``"group/channel"``) -> gage number; only these are imported.
    medium : str, optional
        Override the rig's medium.
    block_s : float
        Longest block, s.
    group : str, optional
        Import only this group's channels.
    fs_hz, force_channel, allow_gaps, sensitivity
        As :class:`~ramdaq.drivers.files.import_common.FileImportDevice`.
    """

    kind = "tdms"

    def __init__(self, path: str | PathLike, *, rig: Rig | str | PathLike,
                 channels: Mapping[str, int] | None = None, medium: str | None = None,
                 block_s: float = 0.1, group: str | None = None, fs_hz: float | None = None,
                 force_channel: str | None = None, allow_gaps: bool = False,
                 sensitivity: float | Mapping[str, float] | None = None) -> None:
        super().__init__(path, rig=rig, channels=channels, medium=medium, block_s=block_s,
                         fs_hz=fs_hz, force_channel=force_channel, allow_gaps=allow_gaps,
                         sensitivity=sensitivity)
        self.group = group

    def _load(self) -> SourceTable:
        return read_tdms_table(self.path, group=self.group)


def check_tdms_segments(path: Path) -> int:
    """Walk the segment lead-ins of a TDMS file; return how many segments it has.

    Raises
    ------
    ImportFormatError
        Not a TDMS file, or truncated: a segment declares more bytes than the file holds, or was
        never finished by its writer.
    """
    size = path.stat().st_size
    pos, n = 0, 0
    with open(path, "rb") as f:
        while pos < size:
            f.seek(pos)
            lead = f.read(_LEAD_IN)
            if lead[:4] != b"TDSm":
                what = "not a TDMS file" if pos == 0 else f"no segment tag at byte {pos}"
                raise ImportFormatError(f"{path}: {what} (expected 'TDSm')")
            if len(lead) < _LEAD_IN:
                raise ImportFormatError(f"{path}: truncated: the file ends inside the lead-in of "
                                        f"the segment at byte {pos}")
            toc = struct.unpack("<l", lead[4:8])[0]
            endian = ">" if toc & _TOC_BIG_ENDIAN else "<"
            _, next_offset, raw_offset = struct.unpack(endian + "lQQ", lead[8:28])
            if next_offset == _UNFINISHED:
                raise ImportFormatError(f"{path}: truncated: the segment at byte {pos} was never "
                                        f"finished by its writer")
            end = pos + _LEAD_IN + next_offset
            if raw_offset > next_offset or end > size:
                raise ImportFormatError(f"{path}: truncated: the segment at byte {pos} declares "
                                        f"{next_offset} bytes but only {size - pos - _LEAD_IN} "
                                        f"follow")
            pos, n = end, n + 1
    if n == 0:
        raise ImportFormatError(f"{path}: empty file")
    return n


class _Collect(logging.Filter):
    """Keeps nptdms's log records (as notes) instead of printing them."""

    def __init__(self) -> None:
        super().__init__()
        self.messages: list[str] = []

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno >= logging.WARNING:
            self.messages.append(record.getMessage())
        return False


def read_tdms_table(path: Path, *, group: str | None = None) -> SourceTable:
    """Open a TDMS file for streaming and describe its channels as a :class:`SourceTable`."""
    from nptdms import TdmsFile
    from nptdms.log import log_manager

    n_segments = check_tdms_segments(path)
    collect = _Collect()
    loggers = list(log_manager.loggers.values())
    for lg in loggers:
        lg.addFilter(collect)
    tdms, f = None, open(path, "rb")  # noqa: SIM115 - closed by close(), also when nptdms fails

    def close() -> None:
        if tdms is not None:
            tdms.close()
        f.close()
        for lg in loggers:
            lg.removeFilter(collect)

    try:
        tdms = TdmsFile.open(f)
        return _describe(tdms, path, group, collect, n_segments, close)
    except ImportFormatError:
        close()
        raise
    except Exception as err:  # nptdms on a damaged file: any exception, reported in one line
        close()
        raise ImportFormatError(f"{path}: not a readable TDMS file ({type(err).__name__}: "
                                f"{err})") from err


def _one_rate(data: list, path: Path) -> None:
    """Refuse channels at different waveform rates (``wf_increment``) with a line that names
    each group's rate: LabVIEW writes decimated copies of a recording as groups of their own
    ("Decimated Data_Level1"), which are not the trial's channels at a lower rate."""
    rates: dict[str, set[float]] = {}
    for g, c in data:
        inc = c.properties.get("wf_increment")
        if isinstance(inc, (int, float, np.number)) and inc > 0:
            rates.setdefault(g, set()).add(round(1.0 / float(inc), 9))
    if len({r for rs in rates.values() for r in rs}) < 2:
        return
    said = "; ".join(f"group {g!r} at {', '.join(f'{r:g}' for r in sorted(rs))} Hz"
                     for g, rs in rates.items())
    raise ImportFormatError(f"{path}: its channels are at different rates ({said}); a recording "
                            f"is one rate: import one group ({option('group=', '--group NAME')})")


def _describe(tdms, path: Path, group: str | None, collect: _Collect, n_segments: int,
              close: Callable[[], None]) -> SourceTable:
    groups = tdms.groups()
    if group is not None:
        groups = [g for g in groups if g.name == group]
        if not groups:
            have = ", ".join(repr(g.name) for g in tdms.groups())
            raise ImportFormatError(f"{path}: no group {group!r} (it has {have})")
    found = [(g.name, c) for g in groups for c in g.channels()
             if len(c) > 0 and np.issubdtype(c.dtype, np.number)
             and not np.issubdtype(c.dtype, np.complexfloating)]
    time = [c for _, c in found if c.name.strip().lower() in _TIME_NAMES
            and "wf_increment" not in c.properties]
    data = [(g, c) for g, c in found if all(c is not t for t in time)]
    if not data:
        raise ImportFormatError(f"{path}: no numeric channels with samples")
    short = [c.name for _, c in data]
    names = [c.name if short.count(c.name) == 1 else f"{g}/{c.name}" for g, c in data]
    _one_rate(data, path)
    n = len(data[0][1])
    for nm, (_, c) in zip(names, data, strict=True):
        if len(c) != n:
            raise ImportFormatError(f"{path}: channel {nm!r} has {len(c)} samples and "
                                    f"{names[0]!r} {n} (a truncated or partial file?)")
    props = [c.properties for _, c in data]
    if all("wf_increment" in p for p in props):
        inc = [_number(p["wf_increment"], path, nm, "wf_increment") for p, nm in zip(props, names,
                                                                                     strict=True)]
        off = [_number(p.get("wf_start_offset", 0.0), path, nm, "wf_start_offset")
               for p, nm in zip(props, names, strict=True)]
        for k in range(1, len(names)):
            if abs(inc[k] / inc[0] - 1) > 1e-9 or off[k] != off[0]:
                raise ImportFormatError(f"{path}: channel {names[k]!r} has wf_increment {inc[k]} "
                                        f"s and wf_start_offset {off[k]} s, {names[0]!r} "
                                        f"{inc[0]} s and {off[0]} s")
        if not inc[0] > 0:
            raise ImportFormatError(f"{path}: wf_increment {inc[0]} s is not positive")
        fs, t0 = snap_rate(1.0 / inc[0], 1e-12), off[0]
        index = np.arange(n, dtype=np.int64)
        notes: dict = {"time": "wf_increment"}
    elif time:
        t = np.asarray(time[0][:], dtype=np.float64)
        if t.size != n:
            raise ImportFormatError(f"{path}: time channel has {t.size} samples, data {n}")
        index, fs, notes = sample_grid(t, None, lambda r: f"sample {r}", str(path))
        t0 = float(t[0])
        notes["time"] = f"channel {time[0].name!r}"
    else:
        missing = next(nm for p, nm in zip(props, names, strict=True) if "wf_increment" not in p)
        raise ImportFormatError(f"{path}: channel {missing!r} has no wf_increment and the file "
                                f"has no time channel")
    units = [str(p["unit_string"]) if "unit_string" in p else None for p in props]
    notes |= tdms_medium(tdms, groups, data, path)
    start = props[0].get("wf_start_time")
    notes |= {"tdms_segments": n_segments, "groups": sorted({g for g, _ in data}),
              "wf_start_time": None if start is None else str(start),
              "nptdms_warnings": collect.messages}

    def read(i: int) -> np.ndarray:
        try:
            x = np.asarray(data[i][1][:], dtype=np.float64)
        except Exception as err:  # damaged data section
            raise ImportFormatError(f"{path}: channel {names[i]!r}: unreadable data "
                                    f"({type(err).__name__}: {err})") from err
        return x

    return SourceTable(names=names, units=units, sample_index=index, fs_hz=fs, t0_s=t0,
                       read=read, fmt="tdms", notes=notes, close=close)


def tdms_medium(tdms, groups: list, data: list, path: Path) -> dict:
    """The medium the file's, its groups' or the imported channels' ``medium`` property states
    (the name in any case; :func:`~ramdaq.drivers.files.import_common.stated_medium`)."""
    levels = [("the file's", tdms.properties)] + [(f"group {g.name!r}'s", g.properties) for g in groups] \
        + [(f"channel {c.name!r}'s", c.properties) for _, c in data]
    found = [(f"{what} property {k!r}", v) for what, props in levels for k, v in props.items()
             if str(k).strip().lower() == "medium"]
    return stated_medium(found, str(path))


def _number(v: object, path: Path, channel: str, prop: str) -> float:
    try:
        x = float(v)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ImportFormatError(f"{path}: channel {channel!r}: {prop} {v!r} is not a number") \
            from None
    if not np.isfinite(x):
        raise ImportFormatError(f"{path}: channel {channel!r}: {prop} {x} is not finite")
    return x
