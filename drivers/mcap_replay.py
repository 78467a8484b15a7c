"""Replay a ramdaq recording as a device: the blocks come back exactly as they were recorded.

::

    with open_device("trial.mcap", pace="realtime") as dev:
        for block in dev:      # same seq, first_sample, t0_ns, counts and scale as recorded
            ...

The stream description is rebuilt from the ``ramdaq.stream`` metadata and the ``rig.toml``
attachment (see :mod:`ramdaq.drivers.mcap_format`). Blocks are read chunk by chunk in file order, never
the whole file at once. ``pace="realtime"`` hands each block over when its last sample would
have been acquired (``speed`` times faster); ``"fast"`` as fast as they decode.

A file without a footer (its recorder was killed) is refused with a hint to run
``ramdaq recover``; an MCAP file that is not a ramdaq recording is refused too.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from os import PathLike
from pathlib import Path
from typing import Any, BinaryIO, NamedTuple

from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, SeekingReader

from ramdaq.drivers import mcap_format as fmt
from ramdaq.drivers.base import TIMED_OUT, Device
from ramdaq.drivers.block import Block, StreamInfo
from ramdaq.drivers.errors import DeviceNotFound

__all__ = ["McapReplayDevice", "JsonMessage"]

_FOOTER_RECORD_BYTES = 1 + 8 + 8 + 8 + 4  # opcode, length, summary_start, summary_offset, crc
_FOOTER_OPCODE = 0x02


class JsonMessage(NamedTuple):
    """A message of a JSON topic: its ``log_time`` (device time, ns) and decoded object."""

    t_ns: int
    obj: Any


class McapReplayDevice(Device):
    """A recorded ramdaq MCAP file, streamed back as blocks.

    Parameters
    ----------
    path : str or PathLike
        The recording.
    pace : {"fast", "realtime"}
        ``"fast"``: blocks as fast as they are read. ``"realtime"``: each block when its last
        sample is due, counted from when the first block was read.
    speed : float
        Multiplier of the real-time pace (2.0 replays twice as fast).
    """

    kind = "mcap"

    def __init__(self, path: str | PathLike, *, pace: str = "fast", speed: float = 1.0) -> None:
        super().__init__()
        if pace not in ("fast", "realtime"):
            raise ValueError(f"mcap: pace {pace!r} must be 'fast' or 'realtime'")
        if not speed > 0:
            raise ValueError(f"mcap: speed ({speed}) must be positive")
        self.path = Path(path)
        self.pace = pace
        self.speed = float(speed)
        self._file: BinaryIO | None = None
        self._blocks: Iterator[Block] | None = None
        self._pending: Block | None = None
        self._start: tuple[float, int] | None = None  # (monotonic time, first sample) of block 0

    # -- Device hooks ------------------------------------------------------------------------
    def _open(self) -> StreamInfo:
        if not self.path.is_file():
            raise DeviceNotFound(f"mcap: no recording at {self.path}")
        with open(self.path, "rb") as f:
            _check_finished(f, self.path)
            reader = SeekingReader(f)
            try:
                summary = reader.get_summary()
                meta = {m.name: m.metadata for m in reader.iter_metadata()}
                rig = next(
                    (a.data for a in reader.iter_attachments() if a.name == fmt.RIG_ATTACHMENT), b""
                )
            except (McapError, ValueError, EOFError) as err:
                raise fmt.NotARamdaqRecording(f"{self.path}: unreadable MCAP summary ({err})") from err
        topics = {ch.topic: ch for ch in summary.channels.values()} if summary else {}
        block_channel = topics.get(fmt.BLOCK_TOPIC)
        if fmt.STREAM_METADATA not in meta or block_channel is None:
            raise fmt.NotARamdaqRecording(
                f"{self.path}: not a ramdaq recording (no {fmt.STREAM_METADATA} metadata "
                f"or no {fmt.BLOCK_TOPIC} topic)"
            )
        try:
            info = fmt.stream_info_from_metadata(meta[fmt.STREAM_METADATA], rig.decode())
        except fmt.NotARamdaqRecording as err:
            raise fmt.NotARamdaqRecording(f"{self.path}: {err}") from err
        self._file = open(self.path, "rb")  # noqa: SIM115 - closed by _close
        messages = NonSeekingReader(self._file).iter_messages(
            topics=[fmt.BLOCK_TOPIC], log_time_order=False
        )
        self._blocks = (fmt.decode_block(m.data) for _, _, m in messages)
        return info

    def _read(self, timeout: float | None) -> Block | None:
        block = self._pending
        if block is None:
            block = next(self._blocks, None)
            if block is None:
                return None
        self._pending = None
        if self.pace == "realtime":
            now = time.monotonic()
            if self._start is None:
                self._start = (now, block.first_sample)
            t_start, s_start = self._start
            due = t_start + (block.next_sample - s_start) / block.fs_hz / self.speed
            wait = due - now
            if timeout is not None and wait > timeout:
                time.sleep(max(timeout, 0.0))
                self._pending = block
                return TIMED_OUT
            if wait > 0:
                time.sleep(wait)
        return block

    def _close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
        self._blocks = None

    # -- other topics ------------------------------------------------------------------------
    @property
    def rig_toml(self) -> str:
        """The rig file recorded with the stream (``""`` if none)."""
        return self.info.rig_toml

    def json_messages(self, topic: str) -> list[JsonMessage]:
        """All messages of a JSON topic, in log-time order (``[]`` if the topic is absent)."""
        self.open()
        with open(self.path, "rb") as f:
            reader = SeekingReader(f)
            return [
                JsonMessage(m.log_time, fmt.decode_json(m.data))
                for _, _, m in reader.iter_messages(topics=[topic])
            ]

    def events(self) -> list[dict]:
        """The ``/ramdaq/events`` messages: ``{"kind", "t_ns", "detail"}`` dicts, in time order."""
        return [m.obj for m in self.json_messages(fmt.EVENTS_TOPIC)]


def _check_finished(f: BinaryIO, path: Path) -> None:
    """Refuse a non-MCAP file, and an MCAP file whose writer never wrote the footer."""
    size = os.fstat(f.fileno()).st_size
    magic = fmt.MCAP_MAGIC
    if f.read(len(magic)) != magic:
        raise fmt.NotARamdaqRecording(f"{path}: not an MCAP file (it does not start with the MCAP magic)")
    tail_len = _FOOTER_RECORD_BYTES + len(magic)
    if size >= len(magic) + tail_len:
        f.seek(size - tail_len)
        tail = f.read(tail_len)
        if tail[0] == _FOOTER_OPCODE and tail.endswith(magic):
            f.seek(0)
            return
    raise fmt.TruncatedRecording(
        f"{path}: recording has no footer (its recorder was killed?); "
        f"run `ramdaq recover {path}` to salvage it"
    )
