"""Salvage a recording whose writer was killed: copy every complete record into a finished file.

A recorder killed by SIGKILL, a power cut or a crash of Python leaves an MCAP file without its
summary and footer, and possibly with a torn last record. Such a file is read front to back
(``mcap.stream_reader.StreamReader``, the reader under ``NonSeekingReader``, in file order);
each chunk is opened and its CRC checked; copying stops cleanly at the first record that is
incomplete or corrupt, and everything before it - schemas, channels, messages, metadata,
attachments - is written to a new, finished file with a ``ramdaq.recovery`` metadata record saying
what happened::

    report = recover("trial.mcap", "trial.recovered.mcap")
    print(report.blocks, report.last_sample, report.truncated, report.tail_bytes)

:class:`RecordScanner` (the tolerant front-to-back reader) is shared with :mod:`ramdaq.daq.commands.info`.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime
from os import PathLike
from pathlib import Path
from typing import BinaryIO

import zstandard
from mcap.exceptions import McapError
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
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import Writer

from ramdaq.daq.errors import NotARamdaqRecording
from ramdaq.drivers import mcap_format as fmt
from ramdaq.drivers.errors import FrameError

__all__ = ["RecordScanner", "RecoverReport", "recover", "check_mcap_magic"]

# What a torn or corrupt tail raises inside the mcap reader: short reads (struct.error,
# EndOfFile), bad lengths (McapError), failed CRC (ValueError), truncated zstd or lz4 frames.
_TORN = (McapError, struct.error, ValueError, EOFError, zstandard.ZstdError, RuntimeError)


def check_mcap_magic(f: BinaryIO, path: str | PathLike) -> None:
    """Raise :class:`NotARamdaqRecording` unless ``f`` starts with the MCAP magic; rewinds ``f``."""
    head = f.read(len(fmt.MCAP_MAGIC))
    f.seek(0)
    if head != fmt.MCAP_MAGIC:
        raise NotARamdaqRecording(f"{path}: not an MCAP file (it does not start with the MCAP magic)")


class RecordScanner:
    """The data-section records of an MCAP file in file order, chunks opened, torn tail tolerated.

    Iterating yields ``Header``, ``Schema``, ``Channel``, ``Message``, ``Metadata``,
    ``Attachment`` and index records until the ``DataEnd`` record (then :attr:`complete` is
    true) or until a record is incomplete or corrupt (then :attr:`reason` says why). A chunk is
    yielded record by record, and only once it is whole and its CRC matches.

    Attributes
    ----------
    complete : bool
        The data section ended with its ``DataEnd`` record.
    reason : str
        Why reading stopped early, ``""`` if it did not.
    good_bytes : int
        Offset just past the last complete record.
    chunks : int
        Chunks read.
    """

    def __init__(self, f: BinaryIO, path: str | PathLike) -> None:
        check_mcap_magic(f, path)
        self._f = f
        self.path = path
        self.size = os.fstat(f.fileno()).st_size
        self.complete = False
        self.reason = ""
        self.good_bytes = 0
        self.chunks = 0

    def __iter__(self) -> Iterator[McapRecord]:
        reader = StreamReader(self._f, emit_chunks=True, record_size_limit=max(self.size, 1))
        records = reader.records
        while True:
            try:
                record = next(records)
                inner = breakup_chunk(record, validate_crc=True) if isinstance(record, Chunk) else None
            except StopIteration:
                self.reason = "footer reached without a DataEnd record"
                return
            except _TORN as err:
                if self.good_bytes == self.size:
                    self.reason = f"file ends after byte {self.size} with no DataEnd record or footer"
                else:
                    what = f"{type(err).__name__}: {err}" if str(err) else type(err).__name__
                    self.reason = f"torn or corrupt record after byte {self.good_bytes} ({what})"
                return
            self.good_bytes = self._f.tell()
            if inner is not None:
                self.chunks += 1
                yield from inner
            elif isinstance(record, DataEnd):
                self.complete = True
                return
            else:
                yield record

    @property
    def tail_bytes(self) -> int:
        """Bytes after the last complete record of the data section (0 if complete)."""
        return 0 if self.complete else self.size - self.good_bytes


@dataclass(frozen=True)
class RecoverReport:
    """What :func:`recover` salvaged.

    Attributes
    ----------
    src, dst : Path
        The damaged file and the finished copy.
    messages, blocks : int
        Messages (all topics) and ``/ramdaq/block`` messages copied.
    first_sample, last_sample : int
        Index of the first and the last recovered sample (``-1`` without blocks).
    samples : int
        Samples per channel recovered (fewer than ``last_sample - first_sample + 1`` if the
        recording has gaps).
    fs_hz : float
        Sample rate of the recovered blocks (0.0 without blocks).
    truncated : bool
        The source had no complete data section (its writer was killed).
    tail_bytes : int
        Bytes at the end of the source that could not be used: the chunk being written when
        the recorder died and anything after it.
    reason : str
        Why reading stopped, ``""`` if the source was complete.
    chunks, metadata, attachments : int
        Records of each kind copied.
    """

    src: Path
    dst: Path
    messages: int
    blocks: int
    first_sample: int
    last_sample: int
    samples: int
    fs_hz: float
    truncated: bool
    tail_bytes: int
    reason: str
    chunks: int
    metadata: int
    attachments: int

    @property
    def duration_s(self) -> float:
        """Seconds of samples recovered."""
        return self.samples / self.fs_hz if self.fs_hz else 0.0

    def __str__(self) -> str:
        lost = (f"the source had no footer; {self.tail_bytes} bytes of torn tail dropped ({self.reason})"
                if self.truncated else "the source was complete")
        return (f"{self.messages} messages, {self.blocks} blocks, samples {self.first_sample}.."
                f"{self.last_sample} ({self.duration_s:.3f} s); {lost}")


def recover(src: str | PathLike, dst: str | PathLike, *, overwrite: bool = False) -> RecoverReport:
    """Copy every complete record of a (possibly footer-less) MCAP file into a finished file.

    Parameters
    ----------
    src : str or PathLike
        The damaged recording. Read only.
    dst : str or PathLike
        The finished copy to create; an existing file is an error unless ``overwrite``.
    overwrite : bool
        Replace an existing ``dst``.

    Returns
    -------
    RecoverReport

    Raises
    ------
    NotARamdaqRecording
        ``src`` is not an MCAP file.
    """
    src, dst = Path(src), Path(dst)
    if dst.exists() and src.resolve() == dst.resolve():
        raise ValueError(f"{src}: recover needs a different destination file")
    n = dict.fromkeys(("messages", "blocks", "samples", "metadata", "attachments"), 0)
    first_sample, last_sample, fs_hz = -1, -1, 0.0
    with open(src, "rb") as fin:
        scanner = RecordScanner(fin, src)
        with open(dst, "wb" if overwrite else "xb") as fout:
            writer = Writer(fout)
            started = False
            schemas: dict[int, int] = {0: 0}
            channels: dict[int, tuple[int, str]] = {}
            for record in scanner:
                if not started:
                    header = record if isinstance(record, Header) else Header("", "")
                    writer.start(profile=header.profile, library=header.library or "ramdaq")
                    started = True
                if isinstance(record, Schema) and record.id not in schemas:
                    schemas[record.id] = writer.register_schema(record.name, record.encoding, record.data)
                elif isinstance(record, Channel) and record.id not in channels:
                    schema_id = schemas.get(record.schema_id, 0)
                    cid = writer.register_channel(
                        record.topic, record.message_encoding, schema_id, record.metadata
                    )
                    channels[record.id] = (cid, record.topic)
                elif isinstance(record, Message) and record.channel_id in channels:
                    cid, topic = channels[record.channel_id]
                    writer.add_message(
                        cid, log_time=record.log_time, data=record.data,
                        publish_time=record.publish_time, sequence=record.sequence,
                    )
                    n["messages"] += 1
                    if topic == fmt.BLOCK_TOPIC:
                        try:
                            h = fmt.decode_header(record.data)
                        except FrameError:
                            continue
                        n["blocks"] += 1
                        n["samples"] += h.n_samples
                        first_sample = h.first_sample if first_sample < 0 else first_sample
                        last_sample, fs_hz = h.next_sample - 1, h.fs_hz
                elif isinstance(record, Metadata):
                    writer.add_metadata(record.name, record.metadata)
                    n["metadata"] += 1
                elif isinstance(record, Attachment):
                    writer.add_attachment(
                        record.create_time, record.log_time, record.name, record.media_type,
                        record.data,
                    )
                    n["attachments"] += 1
            if not started:
                writer.start(profile="", library="ramdaq")
            writer.add_metadata("ramdaq.recovery", {
                "source": src.name,
                "truncated": str(not scanner.complete).lower(),
                "tail_bytes": str(scanner.tail_bytes),
                "reason": scanner.reason,
                "recovered_utc": datetime.now(UTC).isoformat(timespec="seconds"),
            })
            writer.finish()
    return RecoverReport(
        src=src, dst=dst, first_sample=first_sample, last_sample=last_sample, fs_hz=fs_hz,
        truncated=not scanner.complete, tail_bytes=scanner.tail_bytes, reason=scanner.reason,
        chunks=scanner.chunks, **n,
    )
