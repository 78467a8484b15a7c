"""Write a stream of blocks to an MCAP file, from its own thread, without ever blocking the caller.

::

    with Recorder("trial.mcap", dev.info) as rec:
        for block in dev:
            rec.put(block)            # never blocks; False if the block had to be dropped

The caller's thread only checks continuity, serializes JSON and hands items to a queue; the thread
``ramdaq-recorder`` encodes them (:func:`ramdaq.drivers.mcap_format.encode_block`) and writes them. The
file format is documented in :mod:`ramdaq.drivers.mcap_format`.

Nothing is lost silently:

* a queue full of blocks (the disk or the CPU fell behind) drops the new block, counts it in
  :attr:`Recorder.overflows` and writes an ``overflow`` event naming the blocks and samples lost;
* a block that does not follow the previous one (``seq`` jump or ``first_sample``
  discontinuity) is written as it is, after a ``gap`` event;
* the file is always finished (summary and footer) when the ``with`` block ends, by an exception
  too; and each chunk (at most ``chunk_seconds`` of samples, or one block if longer, or
  ``chunk_seconds`` of wall time) goes straight to the operating system when it is complete, so a
  SIGKILL or a crash of Python loses at most the chunk being filled and the blocks still queued
  (and the derived topics' messages of that chunk's time, which follow it in chunks of their own).
  ``ramdaq recover`` (:func:`ramdaq.daq.recover.recover`) turns such a file into a finished one.

Events and JSON messages share the queue with blocks so the file keeps the order they were given
in, but only blocks count against ``queue_blocks``: events are rare, and are never dropped.
"""

from __future__ import annotations

import math
import queue
import threading
import time
import warnings
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any, NamedTuple

from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

from ..drivers import mcap_format as fmt
from ..drivers.block import Block, StreamInfo
from . import topics
from .errors import RecordingError

__all__ = ["Recorder", "RecorderStats"]

_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
_MAX_VARINT_BYTES = 5  # a sint32 zigzag varint takes at most 5 bytes
_STOP = object()
CLOCK_METADATA = "ramdaq.clock"


@dataclass(frozen=True)
class RecorderStats:
    """What a :class:`Recorder` has done so far.

    Attributes
    ----------
    blocks, samples : int
        Blocks and samples per channel written to the file.
    bytes : int
        Bytes in the file so far (finished chunks only).
    message_bytes : int
        Encoded size of the block messages written, before compression.
    overflows, dropped_samples : int
        Blocks (and their samples per channel) dropped because the queue was full.
    gaps : int
        Discontinuities found in the blocks given to :meth:`Recorder.put`.
    events : int
        Messages written to ``/ramdaq/events``.
    queued : int
        Blocks waiting in the queue.
    """

    blocks: int
    samples: int
    bytes: int
    message_bytes: int
    overflows: int
    dropped_samples: int
    gaps: int
    events: int
    queued: int


class _Dropped(NamedTuple):
    seq: int
    first_sample: int
    n_samples: int
    t0_ns: int


@dataclass(frozen=True)
class _Json:
    topic: str
    data: bytes
    t_ns: int  # device time: the record's publish_time
    log_ns: int  # UTC: the record's log_time


@dataclass(frozen=True)
class _Meta:
    name: str
    data: dict[str, str]


class _OsFile:
    """A write-only file with no user-space buffer: each ``write`` is handed to the OS at once."""

    def __init__(self, path: Path, overwrite: bool) -> None:
        self._raw = open(path, "wb" if overwrite else "xb", buffering=0)
        self._pos = 0

    def write(self, data: bytes) -> int:
        view = memoryview(data).cast("B")
        while view:
            view = view[self._raw.write(view) :]
        self._pos += len(data)
        return len(data)

    def tell(self) -> int:
        return self._pos

    def flush(self) -> None:
        """Nothing to do: every write already reached the OS."""

    def close(self) -> None:
        self._raw.close()


class Recorder:
    """Record blocks, events and JSON messages to an MCAP file from a dedicated thread.

    Parameters
    ----------
    path : str or PathLike
        File to create. An existing file is an error unless ``overwrite``.
    info : StreamInfo
        The stream; stored as ``ramdaq.stream`` metadata plus a ``rig.toml`` attachment.
    queue_blocks : int
        Blocks that may wait for the writer thread before :meth:`put` starts dropping them.
    chunk_seconds : float
        Most samples (in seconds of stream time) and most wall time a chunk stays in memory.
    compression : {"zstd", "lz4", "none"}
        Chunk compression.
    overwrite : bool
        Replace an existing file.
    derived : bool
        Also write ``/ramdaq/gages`` and ``/ramdaq/gages/trace`` (:mod:`ramdaq.daq.topics`):
        each channel in SI per block and decimated, for Foxglove's Plot panel. They are written
        in chunks of their own, each after the chunk of blocks of the same time (see
        :mod:`ramdaq.drivers.mcap_format`, *Chunks*).

    Times: each record's ``publish_time`` is the device time of what it holds (a block's first
    sample, an event's ``t_ns``; clamped at 0); its ``log_time`` is UTC, ns since 1970: the wall
    clock when the first block arrived, less that block's length, is taken as the UTC of its
    first sample, and device time runs on from there. The ``ramdaq.clock`` metadata record
    holds that anchor (``utc_ns``, ``device_ns``). A JSON message given before the first block
    is logged at the wall clock's time.
    """

    def __init__(
        self,
        path: str | PathLike,
        info: StreamInfo,
        *,
        queue_blocks: int = 256,
        chunk_seconds: float = 0.25,
        compression: str = "zstd",
        overwrite: bool = False,
        derived: bool = True,
    ) -> None:
        if queue_blocks < 1:
            raise ValueError(f"queue_blocks ({queue_blocks}) must be at least 1")
        if not chunk_seconds > 0:
            raise ValueError(f"chunk_seconds ({chunk_seconds}) must be positive")
        if compression not in _COMPRESSION:
            raise ValueError(f"compression {compression!r} is not one of {sorted(_COMPRESSION)}")
        self.path = Path(path)
        self.info = info
        self._queue_blocks = queue_blocks
        self._chunk_seconds = float(chunk_seconds)
        self._chunk_samples_max = max(1, math.ceil(chunk_seconds * info.fs_hz))
        chunk_bytes = self._chunk_samples_max * max(1, info.n_channels) * _MAX_VARINT_BYTES + 4096
        if derived:  # room for the derived topics' JSON too, so that samples still close a chunk
            chunk_bytes += (self._chunk_samples_max // max(1, math.ceil(info.fs_hz / topics.TRACE_RATE_HZ))
                            + self._chunk_samples_max // 8 + 2) * (100 + 90 * info.n_channels)

        self._file = _OsFile(self.path, overwrite)
        try:
            self._writer = Writer(
                self._file, chunk_size=chunk_bytes, compression=_COMPRESSION[compression],
                enable_data_crcs=True,  # guards the metadata too (fs_hz), which no chunk CRC covers
            )
            self._writer.start(profile="", library=f"ramdaq/{fmt.ramdaq_version()} {LIBRARY_IDENTIFIER}")
            self._writer.add_metadata(fmt.STREAM_METADATA, fmt.stream_info_to_metadata(info))
            if info.rig_toml:
                self._writer.add_attachment(
                    create_time=time.time_ns(), log_time=0, name=fmt.RIG_ATTACHMENT,
                    media_type=fmt.RIG_MEDIA_TYPE, data=info.rig_toml.encode(),
                )
            schema_id = self._writer.register_schema(
                fmt.BLOCK_SCHEMA_NAME, "protobuf", fmt.block_schema_data()
            )
            self._block_channel = self._writer.register_channel(fmt.BLOCK_TOPIC, "protobuf", schema_id)
            self._json_channels: dict[str, int] = {}
            self._json_channel(fmt.EVENTS_TOPIC)
            self._summary = topics.GageSummary(info) if derived and info.n_channels else None
            if self._summary is not None:
                self._json_channel(topics.GAGES_TOPIC)
                self._json_channel(topics.TRACE_TOPIC)
        except BaseException:
            self._file.close()
            raise

        self._q: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self._closed = False
        self._error: BaseException | None = None
        self._pending = 0  # blocks in the queue
        self._dropped: list[_Dropped] = []  # dropped blocks whose overflow event is not written
        self._last: tuple[int, int] | None = None  # (seq, next_sample) of the last block given
        self._last_t_ns = 0
        self._anchor: tuple[int, int] | None = None  # (UTC ns, device ns) of the first sample
        self._counts = dict.fromkeys(
            ("blocks", "samples", "message_bytes", "overflows", "dropped_samples", "gaps", "events"),
            0,
        )
        self._chunk_opened: float | None = None  # monotonic time of the open chunk's first message
        self._chunk_samples = 0
        self._view: list[tuple[int, int, int, bytes]] = []  # the derived topics' messages of the
        # open chunk (channel, device ns, log ns, JSON), written as chunks of their own after it
        self._thread = threading.Thread(target=self._run, name="ramdaq-recorder", daemon=True)
        self._thread.start()

    # -- caller side -------------------------------------------------------------------------
    def put(self, block: Block) -> bool:
        """Queue a block for writing; never blocks.

        Returns
        -------
        bool
            ``False`` if the queue was full and the block was dropped (counted in
            :attr:`overflows` and reported by an ``overflow`` event).

        Raises
        ------
        RecordingError
            The recorder is closed, or its writer thread failed.
        ValueError
            The block's channel count differs from the stream's, or its ``seq``,
            ``first_sample`` or ``t0_ns`` cannot be stored (negative, or beyond int64).
        """
        if block.n_channels != self.info.n_channels:
            raise ValueError(
                f"{self.path}: block seq {block.seq} has {block.n_channels} channels, "
                f"the stream has {self.info.n_channels}"
            )
        if block.seq < 0 or block.first_sample < 0 or not -(2**63) <= block.t0_ns < 2**63:
            raise ValueError(
                f"{self.path}: block seq {block.seq} first_sample {block.first_sample} t0_ns "
                f"{block.t0_ns}: seq and first_sample must be >= 0 and t0_ns fit in int64"
            )
        with self._lock:
            self._check_usable()
            if self._anchor is None:
                self._set_anchor(block)
            self._check_continuity(block)
            self._last_t_ns = block.t0_ns + round(block.n_samples / block.fs_hz * 1e9)
            if self._pending >= self._queue_blocks:
                self._dropped.append(_Dropped(block.seq, block.first_sample, block.n_samples, block.t0_ns))
                self._counts["overflows"] += 1
                self._counts["dropped_samples"] += block.n_samples
                return False
            self._pending += 1
            self._q.put(block)
        return True

    @property
    def t_end_ns(self) -> int:
        """Stream time just after the last sample put, ns (0 before the first block)."""
        return self._last_t_ns

    def event(self, kind: str, t_ns: int, **detail: Any) -> None:
        """Write an event to ``/ramdaq/events``: ``{"kind", "t_ns", "detail"}``.

        Parameters
        ----------
        kind : str
            ``gap``, ``overflow``, ``device_error``, ``note``, ...
        t_ns : int
            Device time of the event, ns.
        **detail
            JSON-serialisable facts.
        """
        self.write_json(fmt.EVENTS_TOPIC, fmt.make_event(kind, t_ns, detail), t_ns)

    def write_json(self, topic: str, obj: Any, t_ns: int) -> None:
        """Write a JSON message (schema encoding ``jsonschema``) on ``topic`` at device time ``t_ns``.

        The object is serialized here, so one that is not strict JSON raises ``ValueError`` or
        ``TypeError`` in the caller rather than in the writer thread.
        """
        data = fmt.encode_json(obj)
        with self._lock:
            self._check_usable()
            self._q.put(_Json(topic, data, int(t_ns), self._log_ns(int(t_ns))))

    def close(self) -> None:
        """Write everything queued, then the summary and footer, and close the file.

        Safe to call more than once.

        Raises
        ------
        RecordingError
            The writer thread or the footer failed (the file is finished as far as possible).
        """
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._q.put(_STOP)
        self._thread.join()
        failure = self._error
        try:
            self._writer.finish()
        except Exception as err:  # reported below; the file is closed regardless
            failure = failure or err
        finally:
            self._file.close()
        if failure is not None:
            raise RecordingError(
                f"{self.path}: recording failed ({type(failure).__name__}: {failure})"
            ) from failure

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: Any) -> None:
        if exc is not None and not self._closed and self._error is None:
            self.event("note", self._last_t_ns, message=f"recording ended by {exc_type.__name__}: {exc}")
        self.close()

    def __del__(self) -> None:
        if not getattr(self, "_closed", True):
            warnings.warn(f"Recorder for {self.path} was not closed", ResourceWarning, stacklevel=1)

    # -- state -------------------------------------------------------------------------------
    @property
    def overflows(self) -> int:
        """Blocks dropped because the queue was full."""
        return self._counts["overflows"]

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def stats(self) -> RecorderStats:
        with self._lock:
            return RecorderStats(bytes=self._file.tell(), queued=self._pending, **self._counts)

    def _check_usable(self) -> None:
        if self._closed:
            raise RecordingError(f"{self.path}: recorder is closed")
        if self._error is not None:
            raise RecordingError(
                f"{self.path}: writer thread failed ({type(self._error).__name__}: {self._error})"
            ) from self._error

    def _set_anchor(self, block: Block) -> None:
        """Take the wall clock, less the block's length, as the UTC of its first sample."""
        utc = time.time_ns() - round(block.n_samples / block.fs_hz * 1e9)
        self._anchor = (utc, block.t0_ns)
        self._q.put(_Meta(CLOCK_METADATA, {
            "utc_ns": str(utc), "device_ns": str(block.t0_ns),
            "meaning": "log_time = utc_ns + (device time - device_ns); publish_time = device time"}))

    def _log_ns(self, t_ns: int) -> int:
        """The UTC ``log_time`` of device time ``t_ns`` (the class docstring, *Times*)."""
        if self._anchor is None:
            return time.time_ns()
        utc, dev = self._anchor
        return max(utc + t_ns - dev, 0)

    def _check_continuity(self, block: Block) -> None:
        if self._last is not None:
            prev_seq, expected = self._last
            if block.seq != prev_seq + 1 or block.first_sample != expected:
                self._counts["gaps"] += 1
                detail = {
                    "after_seq": prev_seq, "seq": block.seq,
                    "missing_blocks": block.seq - prev_seq - 1,
                    "expected_sample": expected, "first_sample": block.first_sample,
                    "missing_samples": block.first_sample - expected,
                }
                event = fmt.make_event("gap", block.t0_ns, detail)
                self._q.put(_Json(fmt.EVENTS_TOPIC, fmt.encode_json(event), block.t0_ns,
                                  self._log_ns(block.t0_ns)))
        self._last = (block.seq, block.next_sample)

    # -- writer thread -----------------------------------------------------------------------
    def _run(self) -> None:
        try:
            while True:
                timeout = None
                if self._chunk_opened is not None:
                    timeout = max(0.0, self._chunk_opened + self._chunk_seconds - time.monotonic())
                try:
                    item = self._q.get(timeout=timeout)
                except queue.Empty:
                    self._flush_chunk()
                    continue
                if item is _STOP:
                    break
                if isinstance(item, Block):
                    self._write_block(item)
                elif isinstance(item, _Meta):
                    self._writer.add_metadata(item.name, item.data)
                else:
                    self._write_json(item)
                if self._dropped:
                    self._write_overflow_events()
            self._write_overflow_events()
            self._flush_chunk()  # the derived topics' last messages before finish() closes the file
        except BaseException as err:  # handed to the caller by put() and close()
            self._error = err

    def _json_channel(self, topic: str) -> int:
        channel = self._json_channels.get(topic)
        if channel is None:
            name, schema = topics.schema_for(topic, self.info)
            schema_id = self._writer.register_schema(name, "jsonschema", schema)
            channel = self._writer.register_channel(topic, "json", schema_id)
            self._json_channels[topic] = channel
        return channel

    def _add(self, channel: int, t_ns: int, log_ns: int, data: bytes, sequence: int = 0) -> None:
        before = self._file.tell()
        self._writer.add_message(channel, log_time=log_ns, data=data, publish_time=max(int(t_ns), 0),
                                 sequence=sequence)
        if self._file.tell() != before:  # the writer's byte limit finished a chunk
            self._chunk_opened, self._chunk_samples = None, 0
            self._write_view()
        elif self._chunk_opened is None:
            self._chunk_opened = time.monotonic()

    def _write_view(self) -> None:
        """The derived topics' messages held since the last chunk, as chunks of their own (the
        writer closes one at its byte limit too), so that a reader of the blocks steps over them
        by the chunk index without decompressing them (they are most of a recording's bytes)."""
        view, self._view = self._view, []
        for channel, t_ns, log_ns, data in view:
            self._writer.add_message(channel, log_time=log_ns, data=data,
                                     publish_time=max(t_ns, 0), sequence=0)
        if view:
            self._writer.flush()

    def _write_block(self, block: Block) -> None:
        data = fmt.encode_block(block)
        self._add(self._block_channel, block.t0_ns, self._log_ns(block.t0_ns), data,
                  block.seq & 0xFFFF_FFFF)
        if self._summary is not None:
            self._write_derived(block)
        self._chunk_samples += block.n_samples
        with self._lock:
            self._pending -= 1
            self._counts["blocks"] += 1
            self._counts["samples"] += block.n_samples
            self._counts["message_bytes"] += len(data)
        if self._chunk_samples >= self._chunk_samples_max:
            self._flush_chunk()

    def _write_derived(self, block: Block) -> None:
        """Hold the derived topics' messages of ``block`` for :meth:`_write_view`."""
        gages = self._json_channel(topics.GAGES_TOPIC)
        self._view.append((gages, max(int(block.t0_ns), 0), self._log_ns(block.t0_ns),
                           fmt.encode_json(self._summary.block(block))))
        trace = self._json_channel(topics.TRACE_TOPIC)
        for t_ns, msg in self._summary.trace(block):
            self._view.append((trace, int(t_ns), self._log_ns(t_ns), fmt.encode_json(msg)))

    def _write_json(self, item: _Json) -> None:
        self._add(self._json_channel(item.topic), item.t_ns, item.log_ns, item.data)
        if item.topic == fmt.EVENTS_TOPIC:
            with self._lock:
                self._counts["events"] += 1

    def _write_overflow_events(self) -> None:
        with self._lock:
            dropped, self._dropped = self._dropped, []
        runs: list[list[_Dropped]] = []
        for block in dropped:
            if runs and block.seq == runs[-1][-1].seq + 1:
                runs[-1].append(block)
            else:
                runs.append([block])
        for run in runs:
            detail = {
                "first_seq": run[0].seq, "last_seq": run[-1].seq, "blocks": len(run),
                "first_sample": run[0].first_sample, "samples": sum(b.n_samples for b in run),
                "queue_blocks": self._queue_blocks,
            }
            event = fmt.make_event("overflow", run[0].t0_ns, detail)
            self._write_json(_Json(fmt.EVENTS_TOPIC, fmt.encode_json(event), run[0].t0_ns,
                                   self._log_ns(run[0].t0_ns)))

    def _flush_chunk(self) -> None:
        self._writer.flush()  # finishes the chunk; _OsFile already handed every byte to the OS
        self._chunk_opened, self._chunk_samples = None, 0
        self._write_view()
