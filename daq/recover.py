"""Salvage a recording whose writer was killed, or whose bytes were damaged: copy every intact
record into a finished file.

A recorder killed by SIGKILL, a power cut or a crash of Python leaves an MCAP file without its
summary and footer, and possibly with a torn last record; a bad disk or a faulty copy flips bits
anywhere. Such a file is read front to back by
:class:`~ramdaq.drivers.mcap_replay.RecordScanner`, which checks every chunk's CRC, steps over a
damaged record to the next intact chunk and stops at a torn tail. Everything intact - schemas,
channels, messages, metadata, attachments - is written to a new, finished file with a
``ramdaq.recovery`` metadata record saying what was left out and why::

    report = recover("trial.mcap", "trial.recovered.mcap")
    print(report.blocks, report.last_sample, report.truncated, report.tail_bytes, report.damage)

The samples of a damaged chunk are lost (the recovered file has a gap there, which ``ramdaq
info`` shows); the chunks after it are kept. A file without ramdaq's stream metadata (not a
recording, or cut inside its first record) is refused and no output is left behind.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from datetime import UTC, datetime
from os import PathLike
from pathlib import Path

from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema
from mcap.writer import Writer

from ..drivers import mcap_format as fmt
from ..drivers.errors import FrameError
from ..drivers.mcap_replay import Damage, RecordScanner
from .errors import NotARamdaqRecording

__all__ = ["RecoverReport", "recover"]


@dataclass(frozen=True)
class Skipped:
    """A damaged stretch of the source that :func:`recover` left out, and the blocks either side.

    Attributes
    ----------
    damage : Damage
        Where it is (bytes) and which check failed.
    after_seq, next_seq : int
        ``seq`` of the last block copied before it and of the first after it (-1: none).
    missing_samples : int
        Samples per channel between those two blocks that the damage took (and any device gap
        that happened to fall there); 0 when either side has no block.
    """

    damage: Damage
    after_seq: int = -1
    next_seq: int = -1
    missing_samples: int = 0

    def to_json(self) -> dict:
        d = self.damage
        return {"start": d.start, "end": d.end, "what": d.what, "reason": d.reason,
                "after_seq": self.after_seq, "next_seq": self.next_seq,
                "missing_samples": self.missing_samples}

    def __str__(self) -> str:
        lost = (f", {self.missing_samples} samples lost after block seq {self.after_seq}"
                if self.next_seq >= 0 and self.after_seq >= 0 else "")
        return f"{self.damage}{lost}"


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
        Why reading stopped, ``""`` if the source's data section was read to its end.
    chunks, metadata, attachments : int
        Records of each kind copied.
    skipped : tuple of Skipped
        Damaged stretches left out, with what each cost.
    data_crc_failed : bool
        The source's data-section CRC failed although every record passed its own checks: a
        record without a CRC of its own (the stream metadata, the header) may be damaged, and
        was copied as it was (said in the ``ramdaq.recovery`` metadata, and by ``ramdaq info``).
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
    skipped: tuple[Skipped, ...] = ()
    data_crc_failed: bool = False

    @property
    def duration_s(self) -> float:
        """Seconds of samples recovered."""
        return self.samples / self.fs_hz if self.fs_hz else 0.0

    def __str__(self) -> str:
        lost = (f"the source had no footer; {self.tail_bytes} bytes of torn tail dropped ({self.reason})"
                if self.truncated else "the source's data section was read to its end")
        damaged = "".join(f"; DAMAGED {s}" for s in self.skipped)
        if self.data_crc_failed:
            damaged += f"; WARNING: {_DATA_CRC_FAILED}"
        return (f"{self.messages} messages, {self.blocks} blocks, samples {self.first_sample}.."
                f"{self.last_sample} ({self.duration_s:.3f} s); {lost}{damaged}")


_DATA_CRC_FAILED = ("the source's data-section CRC failed although every chunk passed its own: "
                    "its stream metadata or header may be damaged, and was copied as it was")


class _Copy:
    """Writes the intact records of the source into a new MCAP file, counting what it copies."""

    def __init__(self, fout) -> None:
        self.writer = Writer(fout, enable_data_crcs=True)
        self.started = False
        self.schemas: dict[int, int] = {0: 0}
        self.channels: dict[int, tuple[int, str]] = {}
        self.n = dict.fromkeys(("messages", "blocks", "samples", "metadata", "attachments"), 0)
        self.first_sample, self.fs_hz = -1, 0.0
        self.last: fmt.BlockHeader | None = None
        self.skipped: list[Skipped] = []
        self.data_crc_failed = False
        self.has_stream = False

    def start(self, header: Header) -> None:
        if not self.started:
            self.writer.start(profile=header.profile, library=header.library or "ramdaq")
            self.started = True

    def add(self, record) -> None:
        self.start(record if isinstance(record, Header) else Header("", ""))
        if isinstance(record, Damage) and record.what == "data section":
            self.data_crc_failed = True
        elif isinstance(record, Damage):
            self.skipped.append(Skipped(record, self.last.seq if self.last else -1))
        elif isinstance(record, Schema) and record.id not in self.schemas:
            self.schemas[record.id] = self.writer.register_schema(record.name, record.encoding,
                                                                  record.data)
        elif isinstance(record, Channel) and record.id not in self.channels:
            cid = self.writer.register_channel(record.topic, record.message_encoding,
                                               self.schemas.get(record.schema_id, 0), record.metadata)
            self.channels[record.id] = (cid, record.topic)
        elif isinstance(record, Message) and record.channel_id in self.channels:
            self._message(record)
        elif isinstance(record, Metadata):
            self.writer.add_metadata(record.name, record.metadata)
            self.n["metadata"] += 1
            self.has_stream |= record.name == fmt.STREAM_METADATA
        elif isinstance(record, Attachment):
            self.writer.add_attachment(record.create_time, record.log_time, record.name,
                                       record.media_type, record.data)
            self.n["attachments"] += 1

    def _message(self, record: Message) -> None:
        cid, topic = self.channels[record.channel_id]
        self.writer.add_message(cid, log_time=record.log_time, data=record.data,
                                publish_time=record.publish_time, sequence=record.sequence)
        self.n["messages"] += 1
        if topic != fmt.BLOCK_TOPIC:
            return
        try:
            h = fmt.decode_header(record.data)
        except FrameError:
            return
        for i, s in enumerate(self.skipped):  # the first block after a damaged stretch
            if s.next_seq < 0:
                missing = h.first_sample - self.last.next_sample if self.last else 0
                self.skipped[i] = Skipped(s.damage, s.after_seq, h.seq, missing)
        self.n["blocks"] += 1
        self.n["samples"] += h.n_samples
        self.first_sample = h.first_sample if self.first_sample < 0 else self.first_sample
        self.last, self.fs_hz = h, h.fs_hz


def recover(src: str | PathLike, dst: str | PathLike, *, overwrite: bool = False) -> RecoverReport:
    """Copy every intact record of a killed or damaged MCAP recording into a finished file.

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
        ``src`` is not an MCAP file, or holds no ``ramdaq.stream`` metadata (then ``dst`` is
        not left behind).
    """
    src, dst = Path(src), Path(dst)
    if dst.exists() and src.resolve() == dst.resolve():
        raise ValueError(f"{src}: recover needs a different destination file")
    with open(src, "rb") as fin:
        scanner = RecordScanner(fin, src)
        with open(dst, "wb" if overwrite else "xb") as fout:
            try:
                copy = _copy(scanner, fout, src)
            except BaseException:
                fout.close()
                dst.unlink(missing_ok=True)
                raise
    return RecoverReport(
        src=src, dst=dst, first_sample=copy.first_sample,
        last_sample=copy.last.next_sample - 1 if copy.last else -1, fs_hz=copy.fs_hz,
        truncated=not scanner.complete, tail_bytes=scanner.tail_bytes, reason=scanner.reason,
        chunks=scanner.chunks, skipped=tuple(copy.skipped), data_crc_failed=copy.data_crc_failed,
        **copy.n,
    )


def _copy(scanner: RecordScanner, fout, src: Path) -> _Copy:
    """Every record ``scanner`` yields into ``fout``, then the ``ramdaq.recovery`` metadata."""
    copy = _Copy(fout)
    for record in scanner:
        copy.add(record)
    if not copy.has_stream:
        raise NotARamdaqRecording(
            f"{src}: nothing to recover: no {fmt.STREAM_METADATA} metadata in its "
            f"{scanner.size} bytes (not a ramdaq recording, or cut inside its first records)")
    copy.writer.add_metadata("ramdaq.recovery", {
        "source": src.name,
        "truncated": str(not scanner.complete).lower(),
        "tail_bytes": str(scanner.tail_bytes),
        "reason": scanner.reason,
        "damaged": json.dumps([s.to_json() for s in copy.skipped]),
        "data_crc": "failed" if copy.data_crc_failed else {True: "ok", None: "none"}[scanner.data_crc_ok],
        "recovered_utc": datetime.now(UTC).isoformat(timespec="seconds"),
    })
    copy.writer.finish()
    return copy
