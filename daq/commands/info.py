"""Describe a recording: what it holds, what is missing from it, what happened while it was made.

``ramdaq info FILE`` prints :func:`format_info` of :func:`describe_recording`. The file is read
front to back once, block headers only (no samples are decoded), every chunk's CRC checked, so a
footer-less file from a killed recorder is described too, up to its torn tail, and a damaged one
around its damage: each damaged stretch is named by its byte offset and stepped over.
"""

from __future__ import annotations

import json
from collections import Counter
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any, NamedTuple

from mcap.records import Attachment, Channel, Message, Metadata

from ...drivers import mcap_format as fmt
from ...drivers.mcap_replay import Damage, RecordScanner
from ..errors import NotARamdaqRecording

__all__ = ["Gap", "DamagedStretch", "RecordingFacts", "describe_recording", "format_info"]


class Gap(NamedTuple):
    """Blocks missing from the stream: after block ``after_seq``, ``missing_blocks`` blocks and
    ``missing_samples`` samples per channel."""

    after_seq: int
    missing_blocks: int
    missing_samples: int


@dataclass(frozen=True)
class DamagedStretch:
    """A stretch of the data section stepped over: byte range ``start``..``end`` (``bytes`` long),
    ``what`` failed (``chunk``, ``record``, ``data section``), ``reason`` in one line, and the last
    block read before it (``after_seq``, -1 if none)."""

    start: int
    end: int
    bytes: int
    what: str
    reason: str
    after_seq: int


@dataclass
class RecordingFacts:
    """Facts about a ramdaq recording (:func:`describe_recording`); SI units, sample counts per
    channel.

    ``complete``: the data section was read to its end; ``tail_bytes`` and ``stopped_because``
    describe a torn file; ``footer``: the file ends with its footer; ``summary_ok`` and
    ``data_crc_ok``: the CRCs of the summary and of the data section matched (``None``: absent or
    not reached); ``damaged``: each damaged stretch stepped over. ``n_samples`` is recorded
    samples per channel, ``first_sample``/``last_sample`` the stream's indices, ``duration_s``
    recorded samples / fs, ``span_s`` first to last sample with the gaps; ``overflows`` and
    ``overflow_samples`` are blocks and samples the recorder dropped (``overflow_runs`` their
    ``(first_seq, last_seq)``); ``events`` counts events by kind; ``impacts`` are trigger
    detections and ``sim_impacts`` the simulator's truth; ``bytes_per_sample`` is file bytes per
    recorded sample and channel; ``recovery`` the ``ramdaq.recovery`` metadata with its
    ``damaged`` list parsed, if any.
    """

    path: str
    file_bytes: int
    complete: bool
    tail_bytes: int
    stopped_because: str | None
    footer: bool
    summary_ok: bool | None
    data_crc_ok: bool | None
    damaged: list[DamagedStretch]
    chunks: int
    device: str
    fs_hz: float
    channels: list[str]
    units: list[str]
    gages: list[int]
    n_channels: int
    extra: Any
    rig_toml_bytes: int
    rig: str
    ramdaq_version: str
    created_utc: str
    blocks: int
    n_samples: int
    first_sample: int
    last_sample: int
    duration_s: float
    span_s: float
    t0_ns: int | None
    gaps: list[Gap]
    missing_samples: int
    overflows: int
    overflow_samples: int
    overflow_runs: list[tuple[int, int]]
    events: dict[str, int]
    impacts: list[Any]
    sim_impacts: list[Any]
    bytes_per_sample: float | None
    recovery: dict[str, Any] | None


@dataclass
class _Scan:
    """What one pass over a recording's records collected."""

    topics: dict[int, str] = field(default_factory=dict)
    meta: dict[str, dict[str, str]] = field(default_factory=dict)
    rig: bytes = b""
    blocks: int = 0
    n_samples: int = 0
    overflow_blocks: int = 0
    overflow_samples: int = 0
    first: fmt.BlockHeader | None = None
    prev: fmt.BlockHeader | None = None
    gaps: list[Gap] = field(default_factory=list)
    overflow_runs: list[tuple[int, int]] = field(default_factory=list)
    events: Counter[str] = field(default_factory=Counter)
    impacts: list[Any] = field(default_factory=list)
    sim_impacts: list[Any] = field(default_factory=list)
    damaged: list[DamagedStretch] = field(default_factory=list)

    def add(self, record: object) -> None:
        """Take one record (or a :class:`Damage`) of the scan."""
        if isinstance(record, Damage):
            self.damaged.append(DamagedStretch(record.start, record.end, record.bytes, record.what,
                                               record.reason, self.prev.seq if self.prev else -1))
        elif isinstance(record, Channel):
            self.topics[record.id] = record.topic
        elif isinstance(record, Metadata):
            self.meta[record.name] = record.metadata
        elif isinstance(record, Attachment) and record.name == fmt.RIG_ATTACHMENT:
            self.rig = record.data
        elif isinstance(record, Message):
            self._message(self.topics.get(record.channel_id), record.data)

    def _message(self, topic: str | None, data: bytes) -> None:
        if topic == fmt.BLOCK_TOPIC:
            self._block(fmt.decode_header(data))
        elif topic == fmt.EVENTS_TOPIC:
            event = fmt.decode_json(data)
            self.events[event.get("kind", "?")] += 1
            if event.get("kind") == "overflow":
                detail = event["detail"]
                self.overflow_runs.append((int(detail["first_seq"]), int(detail["last_seq"])))
                self.overflow_blocks += int(detail.get("blocks", 0))
                self.overflow_samples += int(detail.get("samples", 0))
        elif topic == fmt.IMPACTS_TOPIC:
            self.impacts.append(fmt.decode_json(data))
        elif topic == fmt.SIM_IMPACTS_TOPIC:
            self.sim_impacts.append(fmt.decode_json(data))

    def _block(self, h: fmt.BlockHeader) -> None:
        prev = self.prev
        if prev is not None and (h.seq != prev.seq + 1 or h.first_sample != prev.next_sample):
            self.gaps.append(Gap(prev.seq, h.seq - prev.seq - 1, h.first_sample - prev.next_sample))
        self.first = self.first or h
        self.prev = h
        self.blocks += 1
        self.n_samples += h.n_samples


def describe_recording(path: str | PathLike) -> RecordingFacts:
    """Facts about a ramdaq recording, read in one pass (see :class:`RecordingFacts`).

    Raises
    ------
    NotARamdaqRecording
        Not an MCAP file, or one without ``ramdaq.stream`` metadata.
    """
    path = Path(path)
    scan = _Scan()
    with open(path, "rb") as f:
        scanner = RecordScanner(f, path)
        for record in scanner:
            scan.add(record)
    if fmt.STREAM_METADATA not in scan.meta:
        raise NotARamdaqRecording(f"{path}: not a ramdaq recording (no {fmt.STREAM_METADATA} metadata)")
    stream = scan.meta[fmt.STREAM_METADATA]
    try:
        info = fmt.stream_info_from_metadata(stream, scan.rig.decode())
    except NotARamdaqRecording as err:
        raise NotARamdaqRecording(f"{path}: {err}") from err
    first, prev = scan.first, scan.prev
    total_samples = scan.n_samples * info.n_channels
    return RecordingFacts(
        path=str(path), file_bytes=scanner.size, complete=scanner.complete,
        tail_bytes=scanner.tail_bytes, stopped_because=scanner.reason, footer=scanner.end.footer,
        summary_ok=scanner.end.summary_ok, data_crc_ok=scanner.data_crc_ok, damaged=scan.damaged,
        chunks=scanner.chunks, device=info.device, fs_hz=info.fs_hz, channels=list(info.channels),
        units=list(info.units), gages=list(info.gages), n_channels=info.n_channels,
        extra=info.extra, rig_toml_bytes=len(scan.rig), rig=_rig_line(path, scan.rig, info.extra),
        ramdaq_version=stream.get("ramdaq_version", "?"),
        created_utc=stream.get("created_utc", "?"), blocks=scan.blocks, n_samples=scan.n_samples,
        first_sample=first.first_sample if first else -1,
        last_sample=prev.next_sample - 1 if prev else -1,
        duration_s=scan.n_samples / info.fs_hz,
        span_s=(prev.next_sample - first.first_sample) / info.fs_hz if first and prev else 0.0,
        t0_ns=first.t0_ns if first else None, gaps=scan.gaps,
        missing_samples=sum(g.missing_samples for g in scan.gaps),
        overflows=scan.overflow_blocks, overflow_samples=scan.overflow_samples,
        overflow_runs=scan.overflow_runs, events=dict(scan.events), impacts=scan.impacts,
        sim_impacts=scan.sim_impacts,
        bytes_per_sample=scanner.size / total_samples if total_samples else None,
        recovery=_recovery(scan.meta.get("ramdaq.recovery")),
    )


def _recovery(meta: dict[str, str] | None) -> dict[str, Any] | None:
    """The ``ramdaq.recovery`` metadata with its ``damaged`` list parsed (``[]`` if absent)."""
    if meta is None:
        return None
    try:
        damaged = json.loads(meta.get("damaged", "[]"))
    except ValueError:
        damaged = [{"reason": f"unreadable damage list {meta['damaged']!r}"}]
    return {**meta, "damaged": damaged if isinstance(damaged, list) else []}


def _mb(n: int) -> str:
    return f"{n / 1e6:.1f} MB" if n >= 1e5 else f"{n} bytes"


def _wrap(label: str, items: list[str], width: int = 100) -> list[str]:
    """``label`` then ``items`` joined by ", ", wrapped between items (never inside one)."""
    lines, line = [], label
    for i, item in enumerate(items):
        piece = item + ("," if i < len(items) - 1 else "")
        if len(line) + len(piece) + 1 > width and line.strip():
            lines.append(line.rstrip())
            line = " " * len(label)
        line += piece + " "
    return [*lines, line.rstrip()]


def _state(d: RecordingFacts) -> str:
    """The file's state in a few words: complete, or what is wrong with it."""
    parts = []
    if d.damaged:
        parts.append(f"DAMAGED: {len(d.damaged)} damaged stretch(es), "
                     f"{_mb(sum(x.bytes for x in d.damaged))} unreadable")
    if d.summary_ok is False:
        parts.append("summary DAMAGED (fails its CRC)")
    if not d.footer:
        parts.append(f"NO FOOTER, {_mb(d.tail_bytes)} torn tail")
    elif not d.complete:
        parts.append(f"footer intact but the data section is unreadable for its last "
                     f"{_mb(d.tail_bytes)}")
    elif parts:
        parts.append("footer intact")
    return ", ".join(parts) or "complete"


def _impacts_line(d: RecordingFacts) -> str:
    """The impacts a live trigger wrote into the recording (and the simulator's truth): a file
    recorded without one (``ramdaq record``, ``import``) holds none, which is not "no blow" --
    ``replay`` and ``analyze`` find them in the samples."""
    sim = f", {len(d.sim_impacts)} simulated (truth)" if d.sim_impacts else ""
    if not d.impacts:
        return (f"impacts    none written by a live trigger{sim} (the file may still hold blows: "
                "ramdaq replay or analyze detects them)")
    return f"impacts    {len(d.impacts)} detected by the live trigger{sim}"


def _gap_cause(d: RecordingFacts, seq: int) -> str:
    """Why the blocks after ``seq`` are missing: a damaged chunk, the recorder, or the device."""
    if any(x.after_seq == seq for x in d.damaged):
        return "DAMAGED chunk"
    if d.recovery and any(x.get("after_seq") == seq for x in d.recovery["damaged"]):
        return "damaged chunk left out by recover"
    if any(a <= seq + 1 <= b for a, b in d.overflow_runs):
        return "recorder overflow"
    return "device"


def _rig_line(path: Path, toml: bytes, extra: Any) -> str:
    """The carried rig in a few words: its name, whether it describes the structure, the
    recorded medium; or why there is none to read."""
    from ...analysis.model.rig import RigError, parse_rig

    if not toml:
        return "none carried (analysis needs one: --rig)"
    try:
        rig = parse_rig(toml.decode(), source=f"{path}:rig.toml")
    except (RigError, UnicodeDecodeError) as err:
        return f"unreadable ({err})"
    medium = extra.get("medium") if isinstance(extra, dict) else None
    return f"{rig.name} ({rig.described}) in {medium or rig.medium}"


def format_info(d: RecordingFacts) -> str:
    """Readable text of :func:`describe_recording`'s result, one fact per line."""
    bps = f", {d.bytes_per_sample:.2f} bytes/sample" if d.bytes_per_sample else ""
    lines = [
        f"{d.path}  ({_mb(d.file_bytes)}{bps}, {_state(d)})",
        f"device     {d.device}   created {d.created_utc}   ramdaq {d.ramdaq_version}",
        f"rig        {d.rig}",
        f"stream     {d.n_channels} channels at {d.fs_hz:g} Hz: {d.duration_s:.3f} s "
        f"recorded ({d.n_samples} samples/channel) in {d.blocks} blocks, "
        f"samples {d.first_sample}..{d.last_sample}",
        *_wrap(
            "channels   ",
            [f"{c} ({f'gage {g}, ' if g else ''}{u})"
             for c, u, g in zip(d.channels, d.units, d.gages, strict=True)],
        ),
    ]
    if d.gaps:
        lines.append(f"gaps       {len(d.gaps)}, {d.missing_samples} samples missing:")
        for seq, nb, ns in d.gaps:
            lines.append(
                f"           after seq {seq}: {nb} block(s), {ns} samples "
                f"({ns / d.fs_hz:.3f} s), {_gap_cause(d, seq)}"
            )
    else:
        lines.append("gaps       none")
    lines.append(
        f"overflows  {d.overflows} blocks ({d.overflow_samples} samples) dropped by the recorder"
    )
    kinds = ", ".join(f"{k} {n}" for k, n in sorted(d.events.items())) or "none"
    lines.append(f"events     {kinds}")
    lines.append(_impacts_line(d))
    if d.recovery:
        r = d.recovery
        skipped = f", {len(r['damaged'])} damaged stretch(es) left out" if r["damaged"] else ""
        lines.append(f"recovered  from {r.get('source')} ({r.get('tail_bytes')} bytes of torn tail "
                     f"dropped{skipped})")
    if d.recovery and d.recovery.get("data_crc") == "failed":
        lines.append("WARNING    the source's data-section CRC failed although every chunk passed "
                     "its own: its stream metadata or header may be damaged")
    for x in d.damaged:
        lines.append(f"DAMAGED    {x.what} at byte {x.start} ({x.bytes} bytes skipped, after "
                     f"block seq {x.after_seq}): {x.reason}")
    if d.damaged or d.summary_ok is False:
        lines.append(f"WARNING    replay, analyze and gap refuse this file; `ramdaq recover {d.path}` "
                     f"copies every intact record to a new one")
    elif not d.complete:
        lines.append(f"WARNING    {d.stopped_because}; run `ramdaq recover {d.path}`")
    return "\n".join(lines)
