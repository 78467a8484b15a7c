"""A whole ramdaq recording in memory, in SI units: what a notebook or a script reads.

::

    rec = ramdaq.read_recording("recordings/albacore-water.mcap")
    rec.values            # (n_channels, n_samples) float64, SI (m/s^2, N); NaN where samples are missing
    rec.time_s            # (n_samples,) s since the stream's first sample
    rec.impacts           # the trigger's detections, as ``ramdaq analyze`` finds them
    rec.to_dataframe()    # pandas, one column per channel (``pip install 'ramdaq[notebook]'``)

This is the one place where the blocks of a recording are joined: ``ramdaq analyze``,
``ramdaq gap`` and the API all read through :func:`read_recording`. The blocks pass through the
same :class:`~ramdaq.daq.trigger.Trigger` as a live trial while they are read, so
``impacts`` are the events ``ramdaq analyze`` judges.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from ..analysis.model.rig import Rig, RigError, load_rig, parse_rig
from ..drivers.block import Block, StreamInfo
from ..drivers.mcap_replay import McapReplayDevice
from .trigger import ImpactEvent, Trigger

__all__ = ["RecordedEvent", "Recording", "optional_import", "read_recording", "rig_of", "rig_or_fail"]


@dataclass(frozen=True)
class RecordedEvent:
    """A message of ``/ramdaq/events``: ``kind`` (``gap``, ``overflow``, ``device_error``,
    ``note``), ``t_s`` its device time in s, ``detail`` the facts the recorder wrote."""

    kind: str
    t_s: float
    detail: dict[str, Any]


@dataclass(frozen=True, eq=False)
class Recording:
    """A recording's samples and what describes them.

    Attributes
    ----------
    path : str
        The file read.
    info : StreamInfo
        The stream as recorded (device, rate, channel names, units, gage numbers, rig text).
    values : numpy.ndarray
        Samples in SI units (``info.units``: m/s^2, N), float64, shape ``(n_channels,
        n_samples)``; column ``j`` is stream sample ``first_sample + j``. Samples the device never
        delivered (a gap) are NaN.
    first_sample : int
        Stream index of column 0.
    scale : numpy.ndarray
        SI units per ADC count of each channel, shape ``(n_channels,)``.
    created_utc : str
        When the recording was made (ISO 8601, UTC; ``""`` if the file does not say).
    rig : Rig or None
        The rig recorded with the stream (in the recorded medium), or the one passed in.
    events : tuple of RecordedEvent
        The recorder's events (gaps, overflows, notes).
    impacts : tuple of ImpactEvent
        The trigger's detections over the whole recording, in time order.
    """

    path: str
    info: StreamInfo
    values: np.ndarray
    first_sample: int
    scale: np.ndarray
    created_utc: str
    rig: Rig | None
    events: tuple[RecordedEvent, ...] = ()
    impacts: tuple[ImpactEvent, ...] = field(default=(), repr=False)

    @property
    def fs_hz(self) -> float:
        """Sample rate, Hz."""
        return self.info.fs_hz

    @property
    def channels(self) -> tuple[str, ...]:
        return self.info.channels

    @property
    def units(self) -> tuple[str, ...]:
        """SI unit of each channel (``"m/s^2"``, ``"N"``)."""
        return self.info.units

    @property
    def gages(self) -> tuple[int, ...]:
        """Report gage number of each channel, 0 for a channel that is not a gage."""
        return self.info.gages

    @property
    def n_samples(self) -> int:
        return int(self.values.shape[1])

    @property
    def duration_s(self) -> float:
        return self.n_samples / self.fs_hz

    @property
    def time_s(self) -> np.ndarray:
        """Time of each column, s since the stream's first sample, shape ``(n_samples,)``."""
        return (self.first_sample + np.arange(self.n_samples)) / self.fs_hz

    def gage_values(self, numbers: tuple[int, ...] | list[int]) -> np.ndarray:
        """The rows of gages ``numbers`` (report numbering), in that order, shape
        ``(len(numbers), n_samples)``; a gage the recording lacks is a ``KeyError``."""
        row = {g: i for i, g in enumerate(self.gages) if g}
        missing = [n for n in numbers if n not in row]
        if missing:
            raise KeyError(f"{self.path}: gage(s) {missing} are not in the recording "
                           f"(it has {sorted(row)})")
        return self.values[[row[n] for n in numbers]]

    def to_dataframe(self) -> Any:
        """A ``pandas.DataFrame``: index ``time_s`` (s), one float64 column per channel in SI
        units (``info.units``). Needs pandas (``pip install 'ramdaq[notebook]'``)."""
        pd = optional_import("pandas")
        df = pd.DataFrame(self.values.T, columns=list(self.channels),
                          index=pd.Index(self.time_s, name="time_s"))
        df.attrs |= {"units": dict(zip(self.channels, self.units, strict=True)),
                     "fs_hz": self.fs_hz, "source": self.path}
        return df

    def to_xarray(self) -> Any:
        """An ``xarray.DataArray`` of dims ``(channel, time_s)`` with coordinates ``gage`` and
        ``unit`` on ``channel``; values SI. Needs xarray (``pip install 'ramdaq[notebook]'``)."""
        xr = optional_import("xarray")
        return xr.DataArray(
            self.values, dims=("channel", "time_s"), name="acceleration",
            coords={"channel": list(self.channels), "time_s": self.time_s,
                    "gage": ("channel", list(self.gages)), "unit": ("channel", list(self.units))},
            attrs={"fs_hz": self.fs_hz, "source": self.path, "created_utc": self.created_utc})


def optional_import(name: str) -> Any:
    """Import an optional dependency, or say how to install it."""
    import importlib

    try:
        return importlib.import_module(name)
    except ImportError:
        raise ImportError(f"{name} is not installed: pip install 'ramdaq[notebook]'") from None


READ_JOIN_S = 1.0
""":func:`read_recording` reads the recorded blocks joined into blocks of up to this many
seconds (:class:`~ramdaq.drivers.mcap_replay.McapReplayDevice`'s ``join_s``)."""


def rig_of(path: str | PathLike, info: StreamInfo, rig: Rig | str | Path | None) -> Rig | None:
    """The rig passed in (a :class:`Rig`, a shipped rig's name or a file), else the recorded
    one; put in the recorded medium."""
    if rig is None:
        if not info.rig_toml:
            return None
        rig = parse_rig(info.rig_toml, source=f"{path}:rig.toml")
    elif not isinstance(rig, Rig):
        rig = load_rig(rig)
    medium = info.extra.get("medium")
    if not medium or medium == rig.medium:
        return rig
    try:
        return rig.with_medium(medium)
    except RigError as err:
        raise RigError(f"{err} (the medium comes from the recording: {path} was made in {medium})") from err


def _join(blocks: list[Block], n_channels: int) -> tuple[np.ndarray, int]:
    """The blocks' samples in SI, side by side at their stream index (NaN in gaps), and the
    stream index of column 0."""
    if not blocks:
        return np.empty((n_channels, 0)), 0
    first = blocks[0].first_sample
    x = np.full((n_channels, blocks[-1].next_sample - first), np.nan)
    for b in blocks:
        x[:, b.first_sample - first:b.next_sample - first] = b.values()
    return x, first


def _trigger_offline(trig: Trigger, blocks: list[Block], values: np.ndarray) -> list[ImpactEvent]:
    """The impacts in a whole recording (``values``: its blocks joined, :func:`_join`): the
    trigger armed on all of it (a blow at its first sample is found and analysable,
    :meth:`Trigger.arm_on_record`), then fed its blocks."""
    trig.arm_on_record(values)
    impacts = [e for b in blocks for e in trig.process(b)]
    return impacts + trig.flush()


class BlockwiseOfflineTrigger:
    """The offline trigger of :func:`read_recording` over a recording read block by block
    (``ramdaq gap`` keeps only counts): the blocks are held until they cover the trigger's
    :attr:`~ramdaq.daq.trigger.Trigger.head_samples`, the trigger is armed on them (and on the
    force channel's every sample, ``force_row``, read by :func:`force_row` beforehand), then
    they and every later block go through it. The impacts are those :func:`read_recording`
    finds."""

    def __init__(self, trig: Trigger, force_row: np.ndarray | None = None):
        self._trig, self._force_row = trig, force_row
        self._held: list[Block] | None = []

    def process(self, block: Block) -> list[ImpactEvent]:
        """Feed the next block; the impacts whose records completed."""
        if self._held is None:
            return self._trig.process(block)
        self._held.append(block)
        if block.next_sample - self._held[0].first_sample < self._trig.head_samples:
            return []
        return self._arm()

    def flush(self) -> list[ImpactEvent]:
        """At the recording's end: the impacts still open."""
        return (self._arm() if self._held is not None else []) + self._trig.flush()

    def _arm(self) -> list[ImpactEvent]:
        held, self._held = self._held or [], None
        head, _ = _join(held, self._trig.info.n_channels)
        self._trig.arm_on_record(head, self._force_row)
        return [e for b in held for e in self._trig.process(b)]


def force_row(path: str | PathLike, row: int | None) -> np.ndarray | None:
    """Every sample of channel ``row`` of a recording, SI, in stream order (a first pass for
    :class:`BlockwiseOfflineTrigger`); None when ``row`` is None."""
    if row is None:
        return None
    with McapReplayDevice(path) as dev:
        parts = [b.counts[row] * b.scale[row] for b in dev]
    return np.concatenate(parts) if parts else np.empty(0)


def read_recording(path: str | PathLike, *, rig: Rig | str | Path | None = None,
                   trigger: bool = True,
                   progress: Callable[[int, int], None] | None = None) -> Recording:
    """Read a ramdaq MCAP recording whole, every check of its integrity made.

    Parameters
    ----------
    path : str or PathLike
        The recording (``ramdaq record``, ``ramdaq trial``, ``ramdaq import``).
    rig : Rig, str or Path, optional
        The rig to describe it with, instead of the one recorded with it.
    trigger : bool
        Find the impacts: the trigger of a live trial, armed on the whole recording (offline:
        a blow at its first sample is found) and run over its blocks.
    progress : callable, optional
        Called as ``progress(bytes_read, total_bytes)`` after each block.

    Raises
    ------
    RecordingError
        The file is missing a footer, damaged, or not a ramdaq recording (one line naming it).
    RigError
        ``rig`` does not load.
    """
    # blocks joined up to READ_JOIN_S: the same samples and impacts, the trigger's per-block
    # CPU a twentieth (every gap and change of scale still starts a block)
    with McapReplayDevice(path, join_s=READ_JOIN_S) as dev:
        info = dev.info
        the_rig = rig_of(path, info, rig)
        trig = Trigger(info) if trigger else None
        blocks: list[Block] = []
        total = Path(path).stat().st_size
        for b in dev:
            blocks.append(b)
            if progress:
                progress(dev.bytes_read, total)
        values, first = _join(blocks, info.n_channels)
        impacts = _trigger_offline(trig, blocks, values) if trig is not None else []
        events = tuple(RecordedEvent(e["kind"], e["t_ns"] / 1e9, e.get("detail", {}))
                       for e in dev.events())
        created = dev.metadata.get("created_utc", "")
    scale = blocks[0].scale.copy() if blocks else np.full(info.n_channels, np.nan)
    return Recording(str(path), info, values, first, scale, created, the_rig, events, tuple(impacts))


def recorded_rig(path: str | PathLike) -> Rig:
    """The rig recording ``path`` carries, in its recorded medium, from its summary alone (no
    samples read); :class:`RigError` naming the file when it carries none."""
    from ..drivers.mcap_replay import McapReplayDevice

    with McapReplayDevice(path) as dev:
        rig = rig_of(path, dev.info, None)
    if rig is None:
        raise no_rig(path)
    return rig


def no_rig(path: str | PathLike) -> RigError:
    """The error for a recording at ``path`` that carries no rig and was given none."""
    return RigError(f"{path}: the recording carries no rig; pass one (--rig, rig=)")


def rig_or_fail(rec: Recording) -> Rig:
    """The recording's rig; a :class:`RigError` naming the file when it has none."""
    if rec.rig is None:
        raise no_rig(rec.path)
    return rec.rig

