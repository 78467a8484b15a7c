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

Integrity
---------
Every check the file offers is made, on every read: each chunk's CRC (of its uncompressed
records), each attachment's CRC, the summary's CRC (in the footer) and, for files that carry one,
the data section's CRC (which also covers the metadata records). A replay steps over the chunks
that the summary's chunk index says hold no block (the live view's topics, in chunks of their
own since they were written so: three quarters of a recording's bytes) without decompressing
them: their bytes are read for the data section's CRC, which is what checks them. A record that fails one, or
does not parse, raises :class:`~ramdaq.drivers.mcap_format.CorruptRecording` naming the file,
the byte where the damaged record starts and the last block read before it; no sample of a
damaged chunk is ever handed out. :class:`RecordScanner` is the reader under it: strict for
replay, tolerant for ``ramdaq info`` and ``ramdaq recover``, which step over a damaged record to
the next intact chunk (:class:`Damage`) and read on.
"""

from __future__ import annotations

import os
import struct
import time
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from io import BytesIO
from os import PathLike
from pathlib import Path
from typing import Any, BinaryIO, NamedTuple

import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import (
    Attachment,
    Channel,
    Chunk,
    DataEnd,
    Header,
    McapRecord,
    Message,
    Metadata,
    Schema,
)
from mcap.stream_reader import CRCValidationError, breakup_chunk, get_chunk_data_stream

from . import mcap_format as fmt
from .base import TIMED_OUT, Device
from .block import Block, StreamInfo
from .errors import DeviceNotFound, FrameError

__all__ = ["McapReplayDevice", "JsonMessage", "RecordScanner", "Damage", "FileEnd", "read_file_end",
           "check_mcap_magic"]

_HEAD = struct.Struct("<BQ")  # every record: opcode, length of what follows
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # a message: channel id, sequence, log and publish time
_MESSAGE_AT = struct.Struct("<BQH")  # a chunk's record: opcode, length; a message's channel id
_MESSAGE_REST = struct.Struct("<IQQ")  # a message after its channel id: sequence, log, publish
_FOOTER = struct.Struct("<BQQQI")  # opcode, length (20), summary_start, summary_offset_start, crc
_DATA_END_BYTES = _HEAD.size + 4  # opcode, length, data_section_crc
_CHUNK_FIXED = struct.Struct("<QQQII")  # start, end time, uncompressed size, crc, len(compression)
_COMPRESSIONS = (b"zstd", b"lz4", b"")
_KNOWN = frozenset(int(o) for o in Opcode)
_PARSED = (Opcode.HEADER, Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE, Opcode.CHUNK,
           Opcode.ATTACHMENT, Opcode.METADATA, Opcode.DATA_END)
_OP_MESSAGE, _OP_CHANNEL, _OP_SCHEMA = int(Opcode.MESSAGE), int(Opcode.CHANNEL), int(Opcode.SCHEMA)
_NOT_PARSED = frozenset(int(o) for o in Opcode if o not in _PARSED)  # indexes, footer, ...
_SCAN_WINDOW = 1 << 20  # bytes searched at a time for the next intact chunk
# What a damaged record raises inside the mcap record parsers and the decompressors: short reads
# (EndOfFile, struct.error), bad lengths (McapError), a failed CRC or bad UTF-8 (ValueError),
# broken zstd or lz4 frames.
_DAMAGE = (McapError, struct.error, ValueError, EOFError, zstandard.ZstdError, RuntimeError)


class JsonMessage(NamedTuple):
    """A message of a JSON topic: its device time (ns; the record's ``publish_time``, which
    recordings made before ``log_time`` became UTC hold in ``log_time`` too) and decoded object."""

    t_ns: int
    obj: Any


# -- the file's end: footer and summary ---------------------------------------------------------
@dataclass(frozen=True)
class FileEnd:
    """What the end of an MCAP file says.

    Attributes
    ----------
    footer : bool
        The file ends with a footer record and the magic (its writer finished it).
    summary_ok : bool or None
        The summary section and the footer pass the footer's CRC; ``None`` without a footer or
        when the writer wrote no CRC.
    data_end : int or None
        Byte offset of the ``DataEnd`` record the footer points to (``None`` if unknown).
    data_crc : int
        The data section's CRC that record holds (0: none written, or no such record).
    """

    footer: bool
    summary_ok: bool | None
    data_end: int | None
    data_crc: int = 0


def check_mcap_magic(f: BinaryIO, path: str | PathLike) -> None:
    """Raise :class:`NotARamdaqRecording` unless ``f`` starts with the MCAP magic; rewinds ``f``."""
    f.seek(0)
    head = f.read(len(fmt.MCAP_MAGIC))
    f.seek(0)
    if not head:
        raise fmt.NotARamdaqRecording(f"{path}: empty (0 bytes), not a recording")
    if head != fmt.MCAP_MAGIC:
        raise fmt.NotARamdaqRecording(f"{path}: not an MCAP file (it does not start with the MCAP magic)")


def read_file_end(f: BinaryIO, size: int) -> FileEnd:
    """Read the footer of an MCAP file of ``size`` bytes and check the summary against its CRC."""
    magic = fmt.MCAP_MAGIC
    footer_at = size - len(magic) - _FOOTER.size
    if footer_at < len(magic):
        return FileEnd(False, None, None)
    f.seek(footer_at)
    tail = f.read(_FOOTER.size + len(magic))
    opcode, length, summary_start, _, crc = _FOOTER.unpack_from(tail)
    if opcode != Opcode.FOOTER or length != _FOOTER.size - _HEAD.size or not tail.endswith(magic):
        return FileEnd(False, None, None)
    start = summary_start or footer_at
    if not len(magic) + _DATA_END_BYTES <= start <= footer_at:
        return FileEnd(True, False, None)  # the footer's own fields are damaged
    summary_ok = None
    if crc:
        f.seek(start)
        summary_ok = zlib.crc32(f.read(footer_at + _FOOTER.size - 4 - start)) == crc
    data_end = start - _DATA_END_BYTES
    f.seek(data_end)
    raw = f.read(_DATA_END_BYTES)
    opcode, length = _HEAD.unpack_from(raw)
    if opcode != Opcode.DATA_END or length != _DATA_END_BYTES - _HEAD.size:
        return FileEnd(True, summary_ok, None)
    return FileEnd(True, summary_ok, data_end, struct.unpack_from("<I", raw, _HEAD.size)[0])


# -- the tolerant, CRC-checking front-to-back reader --------------------------------------------
@dataclass(frozen=True)
class Damage:
    """A stretch of a recording's data section that failed its check or did not parse.

    Attributes
    ----------
    start, end : int
        Byte offsets of the stretch: the damaged record's first byte, and where reading went on
        (the next intact chunk, or the ``DataEnd`` record).
    what : str
        ``"chunk"``, ``"record"`` (outside the chunks: metadata, attachment, index) or ``"data
        section"`` (the data section's CRC failed while every record passed its own checks).
    reason : str
        One line: the check that failed.
    """

    start: int
    end: int
    what: str
    reason: str

    @property
    def bytes(self) -> int:
        return self.end - self.start

    def __str__(self) -> str:
        if self.what == "data section":
            return f"{self.what}: {self.reason}"
        return f"{self.what} at byte {self.start} ({self.bytes} bytes skipped): {self.reason}"


def _stream(raw: bytes) -> ReadDataStream:
    """The body of the record ``raw`` (its opcode and length skipped) as ``mcap`` reads one."""
    return ReadDataStream(BytesIO(raw[_HEAD.size:]))


class _Bad(Exception):
    """A record at a given offset failed: why, and what it was."""

    def __init__(self, what: str, reason: str) -> None:
        super().__init__(reason)
        self.what = what


def _why(err: BaseException) -> str:
    text = " ".join(str(err).split())
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


class RecordScanner:
    """The data-section records of an MCAP file in file order, every check made, damage located.

    Iterating yields ``Header``, ``Schema``, ``Channel``, ``Message``, ``Metadata`` and
    ``Attachment`` records (a chunk's records only once it is whole and its CRC matches; index
    records are read and dropped) until the ``DataEnd`` record (then :attr:`complete` is true)
    or until the file ends inside a record, with no intact chunk after it (a torn tail: then
    :attr:`reason` says why). A damaged record (failed CRC, does not parse, impossible length)
    is, with ``strict``, a :class:`~ramdaq.drivers.mcap_format.CorruptRecording`; without, a
    :class:`Damage` is yielded in its place, listed in :attr:`damage`, and reading resumes at
    the next chunk that passes its CRC (or at the ``DataEnd`` record the footer points to).

    Attributes
    ----------
    size : int
        File size, bytes.
    end : FileEnd
        Footer and summary state.
    complete : bool
        The data section ended with its ``DataEnd`` record.
    reason : str
        Why reading stopped before a ``DataEnd`` record, ``""`` if it did not.
    good_bytes : int
        Offset just past the last intact record.
    chunks : int
        Intact chunks read.
    skip : frozenset of int
        Offsets of chunks to step over without decompressing them (a reader that knows, from
        the summary's chunk index, that they hold none of :attr:`topics`): only the data
        section's CRC checks them.
    skipped : int
        Chunks stepped over so.
    damage : list of Damage
        The damaged stretches stepped over.
    data_crc_ok : bool or None
        The data section's CRC matched (``None``: not reached, not written, or already damaged).
    """

    def __init__(self, f: BinaryIO, path: str | PathLike, *, strict: bool = False,
                 topics: frozenset[str] | None = None, skip: frozenset[int] = frozenset()) -> None:
        check_mcap_magic(f, path)
        self._f = f
        self.path = path
        self.strict = strict
        self.topics = topics  # messages of these topics only (None: all), see _chunk_records
        self.skip = skip  # offsets of chunks stepped over unread (none of their topics is read)
        self.skipped = 0
        self._channel_topic: dict[int, str] = {}
        self._wanted: set[int] = set()  # ids of the channels of ``topics``
        self._zstd: zstandard.ZstdDecompressor | None = None
        self.size = os.fstat(f.fileno()).st_size
        self.end = read_file_end(f, self.size)
        self.complete = False
        self.reason = ""
        self.good_bytes = len(fmt.MCAP_MAGIC)
        self.chunks = 0
        self.damage: list[Damage] = []
        self.data_crc_ok: bool | None = None

    @property
    def tail_bytes(self) -> int:
        """Bytes after the last intact record of the data section (0 if complete)."""
        return 0 if self.complete else self.size - self.good_bytes

    def __iter__(self) -> Iterator[McapRecord | Damage]:
        pos = len(fmt.MCAP_MAGIC)
        crc = zlib.crc32(fmt.MCAP_MAGIC)  # the data section's CRC, while nothing was skipped
        while True:
            if pos == self.size:
                self.reason = f"file ends after byte {self.size} with no DataEnd record or footer"
                return
            try:
                opcode, raw = self._record_at(pos)
                if opcode == Opcode.CHUNK and pos in self.skip:
                    records, self.skipped = [], self.skipped + 1
                else:
                    records = self._parse(opcode, raw)
            except _Bad as bad:
                if self.strict:
                    raise fmt.CorruptRecording(
                        f"{self.path}: damaged {bad.what} at byte {pos} ({bad})") from None
                resume = self._resync(pos)
                if resume is None:
                    self.reason = f"torn or damaged {bad.what} after byte {pos} ({bad})"
                    return
                self.damage.append(Damage(pos, resume, bad.what, str(bad)))
                yield self.damage[-1]
                pos = resume
                continue
            if opcode == Opcode.DATA_END:
                self._check_data_crc(records[0], crc, pos)
                self.complete, self.good_bytes = True, pos + len(raw)
                if self.data_crc_ok is False:
                    yield self.damage[-1]
                return
            if opcode == Opcode.FOOTER:
                self.reason = "footer reached without a DataEnd record"
                return
            crc = zlib.crc32(raw, crc)
            pos = self.good_bytes = pos + len(raw)
            yield from records

    def _check_data_crc(self, data_end: DataEnd, crc: int, pos: int) -> None:
        if not data_end.data_section_crc or self.damage:
            return
        self.data_crc_ok = data_end.data_section_crc == crc
        if self.data_crc_ok:
            return
        where = ("a record outside the chunks (metadata, attachment or index) is damaged"
                 if not self.skipped else "a record outside the chunks (metadata, attachment or "
                 f"index) or one of the {self.skipped} chunks of topics not read is damaged")
        reason = (f"the data section fails its CRC (expected {data_end.data_section_crc}, "
                  f"calculated {crc}) although every chunk read passed its own: {where}")
        if self.strict:
            raise fmt.CorruptRecording(f"{self.path}: {reason}")
        self.damage.append(Damage(len(fmt.MCAP_MAGIC), pos, "data section", reason))

    def _record_at(self, pos: int) -> tuple[int, bytes]:
        """Opcode and bytes (header included) of the record at ``pos``; ``_Bad`` if impossible."""
        self._f.seek(pos)
        head = self._f.read(_HEAD.size)
        if len(head) < _HEAD.size:
            raise _Bad("record", f"the file ends inside a record header ({len(head)} bytes)")
        opcode, length = _HEAD.unpack(head)
        what = "chunk" if opcode == Opcode.CHUNK else "record"
        if opcode not in _KNOWN:
            raise _Bad("record", f"unknown record type 0x{opcode:02x}")
        if length > self.size - pos - _HEAD.size:
            raise _Bad(what, f"a {length}-byte record runs past the end of the file")
        return opcode, head + self._f.read(length)

    def _parse(self, opcode: int, raw: bytes) -> list[McapRecord]:
        """The records a record holds (a chunk's, checked against its CRC); ``_Bad`` if damaged."""
        if opcode in _NOT_PARSED:  # index records and the like: read (for the CRC), dropped
            return []
        length = len(raw) - _HEAD.size
        try:
            if opcode == Opcode.CHUNK:
                records = (breakup_chunk(Chunk.read(_stream(raw)), validate_crc=True)
                           if self.topics is None else self._chunk_records(raw))
                self.chunks += 1
                return records
            if opcode == Opcode.ATTACHMENT:
                (crc,) = struct.unpack_from("<I", raw, len(raw) - 4)
                if crc and zlib.crc32(raw[_HEAD.size:-4]) != crc:
                    raise ValueError(f"attachment CRC {crc} does not match its bytes")
                return [Attachment.read(_stream(raw))]
            if opcode == Opcode.MESSAGE:
                return [Message.read(_stream(raw), length)]
            reader = {Opcode.HEADER: Header, Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel,
                      Opcode.METADATA: Metadata, Opcode.DATA_END: DataEnd}[Opcode(opcode)]
            return [reader.read(_stream(raw))]
        except _DAMAGE as err:
            raise _Bad("chunk" if opcode == Opcode.CHUNK else "record", _why(err)) from err

    def _chunk_data(self, raw: bytes) -> bytes:
        """The records of the chunk record ``raw`` (header included), uncompressed and checked
        against the chunk's CRC, as ``Chunk.read`` and ``get_chunk_data_stream`` give them and
        with their errors, without their copies: zstd through one decompressor kept for the
        file (a new one a chunk cost a fifth of a replay's reading), other compressions
        through ``mcap``."""
        at = _HEAD.size + _CHUNK_FIXED.size
        _, _, size, crc, n = _CHUNK_FIXED.unpack_from(raw, _HEAD.size)
        compression = raw[at:at + n]
        if compression not in (b"zstd", b""):
            stream, n_data = get_chunk_data_stream(Chunk.read(_stream(raw)), validate_crc=True)
            return stream.read(n_data)
        (n_data,) = struct.unpack_from("<Q", raw, at + n)
        start = at + n + 8
        if n_data > len(raw) - start:
            raise ValueError(f"the chunk's {n_data} bytes of records run past its record")
        view = memoryview(raw)[start:start + n_data]
        if compression == b"zstd":
            if self._zstd is None:
                self._zstd = zstandard.ZstdDecompressor()
            data = self._zstd.decompress(view, max_output_size=size)
        else:
            data = bytes(view)
        actual = zlib.crc32(data) if crc else 0
        if actual != crc:
            chunk = Chunk(compression=compression.decode(), data=bytes(view),
                          message_start_time=0, message_end_time=0, uncompressed_crc=crc,
                          uncompressed_size=size)
            raise CRCValidationError(expected=crc, actual=actual, record=chunk)
        return data

    def _chunk_records(self, raw: bytes) -> list[McapRecord]:
        """The records of the chunk record ``raw`` as ``breakup_chunk`` gives them (its CRC
        checked the same way), less the messages of topics other than :attr:`topics`, which
        are stepped over unparsed: a trial's recording holds ten view messages
        (``/ramdaq/gages/trace``) for each block, and parsing them was most of a replay's
        reading (so the loop over them is kept to one ``unpack`` and one test a record)."""
        data = self._chunk_data(raw)
        n = len(data)
        data += bytes(_MESSAGE_AT.size - _HEAD.size)  # so a message's channel id reads with its head
        records: list[McapRecord] = []
        pos, unpack, rest = 0, _MESSAGE_AT.unpack_from, _MESSAGE_REST.unpack_from
        known, wanted = self._channel_topic, self._wanted
        head, least, message = _HEAD.size, _MESSAGE_HEAD.size, _OP_MESSAGE  # locals: the loop's
        while pos < n:
            opcode, length, channel_id = unpack(data, pos)
            body = pos + head
            pos = body + length
            if pos > n or (opcode == message and length < least):
                raise ValueError(f"a chunk record of {length} bytes runs past its chunk's end")
            if opcode == message:
                if channel_id in wanted or channel_id not in known:
                    sequence, log_time, publish_time = rest(data, body + 2)
                    records.append(Message(channel_id=channel_id, log_time=log_time,
                                           data=data[body + least:pos],
                                           publish_time=publish_time, sequence=sequence))
            elif opcode == _OP_CHANNEL or opcode == _OP_SCHEMA:
                reader = Channel if opcode == _OP_CHANNEL else Schema
                record = reader.read(ReadDataStream(BytesIO(data[body:pos])))
                if isinstance(record, Channel):
                    known[record.id] = record.topic
                    if record.topic in self.topics:
                        wanted.add(record.id)
                    else:
                        wanted.discard(record.id)
                records.append(record)
        return records

    # -- stepping over damage ------------------------------------------------------------------
    def _resync(self, bad: int) -> int | None:
        """Where reading goes on after a damaged record at ``bad``: the next intact chunk, else
        the footer's ``DataEnd`` record, else ``None`` (a torn tail)."""
        data_end = self.end.data_end if self.end.data_end and self.end.data_end > bad else None
        found = self._next_chunk(bad + 1, data_end or self.size)
        return found if found is not None else data_end

    def _next_chunk(self, lo: int, hi: int) -> int | None:
        """Offset of the first chunk in ``[lo, hi)`` that parses and passes a non-zero CRC."""
        p = lo
        while p < hi:
            self._f.seek(p)
            buf = np.frombuffer(self._f.read(min(_SCAN_WINDOW + _HEAD.size, hi - p)), np.uint8)
            at = np.flatnonzero(buf[: max(len(buf) - _HEAD.size + 1, 0)] == Opcode.CHUNK)
            if at.size:
                lengths = buf[at[:, None] + np.arange(1, _HEAD.size)].copy().view("<u8")[:, 0]
                room = (hi - (p + at) - _HEAD.size).astype(np.uint64)  # >= 0: the header fits
                fits = (lengths >= _CHUNK_FIXED.size + 8) & (lengths <= room)
                for q in (p + at[fits]).tolist():
                    if self._intact_chunk(q):
                        return q
            p += _SCAN_WINDOW
        return None

    def _intact_chunk(self, q: int) -> bool:
        try:
            opcode, raw = self._record_at(q)
            body = raw[_HEAD.size:]
            *_, crc, n = _CHUNK_FIXED.unpack_from(body)
            if not crc or body[_CHUNK_FIXED.size:_CHUNK_FIXED.size + n] not in _COMPRESSIONS:
                return False
            (n_data,) = struct.unpack_from("<Q", body, _CHUNK_FIXED.size + n)
            if n_data != len(body) - _CHUNK_FIXED.size - n - 8:
                return False
            breakup_chunk(Chunk.read(ReadDataStream(BytesIO(body))), validate_crc=True)
        except (_Bad, *_DAMAGE):
            return False
        return opcode == Opcode.CHUNK


def _chunks_without(summary: Any, topic: str) -> frozenset[int]:
    """Offsets of the chunks that the summary's chunk index (checked by the summary's CRC) says
    hold no message of ``topic``: every channel its message indexes name is of another topic
    (a chunk indexed without them is not among them)."""
    other = {i for i, ch in summary.channels.items() if ch.topic != topic}
    return frozenset(c.chunk_start_offset for c in summary.chunk_indexes
                     if c.message_index_offsets and other.issuperset(c.message_index_offsets))


# -- the device ---------------------------------------------------------------------------------
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
    join_s : float
        With ``pace="fast"``: hand over consecutive recorded blocks joined into one of at most
        this many seconds, where they follow each other with no gap and the same scale (a
        block starts, as recorded, where a gap or a new scale does); its ``seq`` and ``t0_ns``
        are its first recorded block's. The samples are the same, in fewer, longer blocks: a
        replay flat out spends most of its non-analysis CPU per block (the trigger's filters,
        the readout), and the trigger gives the same events whatever the blocks' length.
        ``0`` (the default): the blocks exactly as recorded.

    Reading raises :class:`~ramdaq.drivers.mcap_format.CorruptRecording` at the first damaged
    record (see *Integrity* above), after the blocks before it.
    """

    kind = "mcap"

    def __init__(self, path: str | PathLike, *, pace: str = "fast", speed: float = 1.0,
                 join_s: float = 0.0) -> None:
        super().__init__()
        if pace not in ("fast", "realtime"):
            raise ValueError(f"mcap: pace {pace!r} must be 'fast' or 'realtime'")
        if not speed > 0:
            raise ValueError(f"mcap: speed ({speed}) must be positive")
        if not join_s >= 0 or (join_s and pace != "fast"):
            raise ValueError(f"mcap: join_s ({join_s}) must be >= 0, and 0 unless pace is 'fast'")
        self.join_s = float(join_s)
        self._error: BaseException | None = None  # a read error met while joining, raised next
        self.path = Path(path)
        self.pace = pace
        self.speed = float(speed)
        self._file: BinaryIO | None = None
        self._blocks: Iterator[Block] | None = None
        self._pending: Block | None = None
        self._start: tuple[float, int] | None = None  # (monotonic time, first sample) of block 0
        self._scanner: RecordScanner | None = None
        self._meta: dict[str, str] = {}
        self._channels: dict[int, str] = {}  # the summary's channels: id -> topic
        self._no_blocks: frozenset[int] = frozenset()  # offsets of the chunks without a block

    # -- Device hooks ------------------------------------------------------------------------
    def _open(self) -> StreamInfo:
        if not self.path.is_file():
            what = "is a directory, not a recording" if self.path.is_dir() else \
                "No such file or directory"  # as the commands that open the file say it
            raise DeviceNotFound(f"{self.path}: {what}")
        f = open(self.path, "rb")  # noqa: SIM115 - closed by _close, or below on failure
        try:
            info = self._read_info(f)
            self._scanner = RecordScanner(f, self.path, strict=True,
                                          topics=frozenset({fmt.BLOCK_TOPIC}), skip=self._no_blocks)
            self._blocks = self._iter_blocks(self._scanner, info.fs_hz)
        except BaseException:
            f.close()
            raise
        self._file = f
        return info

    def _read_info(self, f: BinaryIO) -> StreamInfo:
        """The stream description, from a summary that passed its CRC."""
        check_mcap_magic(f, self.path)
        end = read_file_end(f, os.fstat(f.fileno()).st_size)
        if not end.footer:
            if not self._stream_at_head(f):
                raise fmt.NotARamdaqRecording(
                    f"{self.path}: not a ramdaq recording (no footer, and no "
                    f"{fmt.STREAM_METADATA} metadata before its first message)")
            raise fmt.TruncatedRecording(
                f"{self.path}: recording has no footer (its recorder was killed?); "
                f"run `ramdaq recover {self.path}` to salvage it")
        if end.summary_ok is False:
            raise fmt.CorruptRecording(
                f"{self.path}: the summary section or footer fails its CRC check; the samples may "
                f"be intact: `ramdaq recover {self.path}` writes a new file from them")
        f.seek(0)
        try:
            reader = SeekingReader(f, validate_crcs=True)
            summary = reader.get_summary()
            meta = {m.name: m.metadata for m in reader.iter_metadata()}
            rig = next(
                (a.data for a in reader.iter_attachments() if a.name == fmt.RIG_ATTACHMENT), b""
            )
        except (*_DAMAGE, OSError) as err:
            raise fmt.CorruptRecording(f"{self.path}: unreadable MCAP summary ({_why(err)})") from err
        topics = {ch.topic: ch for ch in summary.channels.values()} if summary else {}
        if fmt.STREAM_METADATA not in meta or fmt.BLOCK_TOPIC not in topics:
            raise fmt.NotARamdaqRecording(
                f"{self.path}: not a ramdaq recording (no {fmt.STREAM_METADATA} metadata "
                f"or no {fmt.BLOCK_TOPIC} topic)"
            )
        self._meta = dict(meta[fmt.STREAM_METADATA])
        self._channels = {i: ch.topic for i, ch in summary.channels.items()}
        if end.summary_ok and end.data_crc:  # only where a CRC checks the chunk index that
            # says which chunks hold no block, and the data section's CRC the chunks stepped over
            self._no_blocks = _chunks_without(summary, fmt.BLOCK_TOPIC)
        try:
            return fmt.stream_info_from_metadata(meta[fmt.STREAM_METADATA], rig.decode())
        except (fmt.NotARamdaqRecording, UnicodeDecodeError) as err:
            raise fmt.NotARamdaqRecording(f"{self.path}: {err}") from err

    def _stream_at_head(self, f: BinaryIO) -> bool:
        """Whether the ``ramdaq.stream`` metadata, which a recorder writes before any message,
        is in the file: what ``ramdaq recover`` needs to salvage a footer-less file."""
        f.seek(0)
        for record in RecordScanner(f, self.path):
            if isinstance(record, Metadata) and record.name == fmt.STREAM_METADATA:
                return True
            if isinstance(record, Message):
                return False
        return False

    def _iter_blocks(self, scanner: RecordScanner, fs_hz: float) -> Iterator[Block]:
        """The block messages of the data section, in file order; a damaged record raises
        ``CorruptRecording`` saying which block was the last good one."""
        topics = dict(self._channels)  # the summary's: a skipped chunk may hold a Channel record
        last: Block | None = None
        records = iter(scanner)
        decode, block_topic = fmt.decode_block, fmt.BLOCK_TOPIC  # locals: looked up per record
        while True:
            try:
                record = next(records, None)
            except fmt.CorruptRecording as err:
                raise fmt.CorruptRecording(f"{err}; {self._read_so_far(last)}") from err
            if record is None:
                return
            if isinstance(record, Message):  # the most of them, so asked first
                if topics.get(record.channel_id) != block_topic:
                    continue
                try:
                    block = decode(record.data)
                except FrameError as err:
                    raise fmt.CorruptRecording(
                        f"{self.path}: a block message in the chunk ending at byte "
                        f"{scanner.good_bytes} does not decode ({err}); {self._read_so_far(last)}"
                    ) from err
                last = block
                yield block
            elif isinstance(record, Channel):
                topics[record.id] = record.topic

    def _read_so_far(self, last: Block | None) -> str:
        if last is None:
            return "no block was read before it"
        return (f"blocks were read up to seq {last.seq} (samples up to {last.next_sample - 1}, "
                f"{last.next_sample / last.fs_hz:.3f} s); `ramdaq recover {self.path}` copies "
                f"every intact chunk to a new file")

    def _read(self, timeout: float | None) -> Block | None:
        block = self._pending
        if block is None:
            if self._error is not None:
                err, self._error = self._error, None
                raise err
            block = next(self._blocks, None)
            if block is None:
                return None
        self._pending = None
        if self.join_s:
            return self._joined(block)
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

    def _joined(self, block: Block) -> Block:
        """``block`` and the recorded blocks that follow it with no gap and the same scale, as
        one block of at most ``join_s`` seconds; the first that does not fit waits in
        ``_pending``. A read error after the first block is raised by the next read, so that the
        blocks before it are handed over first."""
        limit = max(block.n_samples, round(self.join_s * block.fs_hz))
        parts, n, end, scale = [block], block.n_samples, block.next_sample, block.scale
        # the same scale: np.array_equal's test (shapes, then every element), asked once a
        # recorded block; a scale of the same bytes as the first block's passes it without the
        # comparison (identical bits are equal elements unless one is a NaN, which no scale
        # of the same bytes is let through as when it has none)
        same_bytes = None if np.isnan(scale).any() else scale.tobytes()
        blocks = self._blocks
        while n < limit:
            try:
                nxt = next(blocks, None)
            except Exception as err:  # noqa: BLE001 -- raised by the next read, as said
                self._error = err
                break
            if nxt is None:
                break
            m = nxt.counts.shape[1]
            if nxt.first_sample != end or n + m > limit or (
                    nxt.scale.tobytes() != same_bytes and (
                        nxt.scale.shape != scale.shape or not (nxt.scale == scale).all())):
                self._pending = nxt
                break
            parts.append(nxt)
            n, end = n + m, nxt.first_sample + m
        if len(parts) == 1:
            return block
        return Block(block.seq, block.first_sample, block.t0_ns, block.fs_hz,
                     np.concatenate([b.counts for b in parts], axis=1), block.scale)

    def _close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
        self._blocks = None

    # -- other topics ------------------------------------------------------------------------
    @property
    def metadata(self) -> dict[str, str]:
        """The ``ramdaq.stream`` metadata record as written (``created_utc``, ``ramdaq_version``,
        ...; see :mod:`ramdaq.drivers.mcap_format`)."""
        self.open()
        return dict(self._meta)

    @property
    def bytes_read(self) -> int:
        """Bytes of the file read so far by the block iterator (for a progress bar)."""
        return self._scanner.good_bytes if self._scanner is not None else 0

    @property
    def chunks_read(self) -> tuple[int, int]:
        """Chunks read so far by the block iterator: decompressed, and stepped over unread (the
        summary's chunk index says they hold no block)."""
        scanner = self._scanner
        return (scanner.chunks, scanner.skipped) if scanner is not None else (0, 0)

    @property
    def rig_toml(self) -> str:
        """The rig file recorded with the stream (``""`` if none)."""
        return self.info.rig_toml

    def json_messages(self, topic: str) -> list[JsonMessage]:
        """All messages of a JSON topic, in log-time order (``[]`` if the topic is absent);
        chunk CRCs checked. Times are device times (``publish_time``)."""
        self.open()
        with open(self.path, "rb") as f:
            reader = SeekingReader(f, validate_crcs=True)
            try:
                return [
                    JsonMessage(m.publish_time, fmt.decode_json(m.data))
                    for _, _, m in reader.iter_messages(topics=[topic])
                ]
            except (*_DAMAGE, OSError) as err:
                raise fmt.CorruptRecording(f"{self.path}: topic {topic}: {_why(err)}") from err

    def events(self) -> list[dict]:
        """The ``/ramdaq/events`` messages: ``{"kind", "t_ns", "detail"}`` dicts, in time order."""
        return [m.obj for m in self.json_messages(fmt.EVENTS_TOPIC)]
