"""Describe a recording: what it holds, what is missing from it, what happened while it was made.

``ramdaq info FILE`` prints :func:`format_info` of :func:`describe_recording`. The file is read
front to back once, block headers only (no samples are decoded), every chunk's CRC checked, so a
footer-less file from a killed recorder is described too, up to its torn tail, and a damaged one
around its damage: each damaged stretch is named by its byte offset and stepped over.
"""

from __future__ import annotations

import json
from collections import Counter
from os import PathLike
from pathlib import Path
from typing import Any

from mcap.records import Attachment, Channel, Message, Metadata

from ...drivers import mcap_format as fmt
from ...drivers.mcap_replay import Damage, RecordScanner
from ..errors import NotARamdaqRecording

__all__ = ["describe_recording", "format_info"]


def describe_recording(path: str | PathLike) -> dict[str, Any]:
    """Facts about a ramdaq recording, as plain data.

    Returns
    -------
    dict
        ``path``, ``file_bytes``, ``complete`` (the data section was read to its end),
        ``tail_bytes`` and ``stopped_because`` (for a torn file), ``footer`` (the file ends with
        its footer), ``summary_ok`` and ``data_crc_ok`` (the CRCs of the summary and of the data
        section matched; ``None``: absent or not reached), ``damaged`` (list of ``{"start",
        "end", "bytes", "what", "reason", "after_seq"}``: byte range of each damaged stretch
        stepped over, which check failed, the last block before it), ``chunks``, ``device``,
        ``fs_hz``, ``channels``, ``units``, ``gages``, ``n_channels``, ``extra``,
        ``rig_toml_bytes``, ``ramdaq_version``, ``created_utc``, ``blocks``, ``n_samples`` (per
        channel, recorded), ``first_sample``, ``last_sample``, ``duration_s`` (recorded samples
        / fs), ``span_s`` (first to last sample, gaps included), ``t0_ns``, ``gaps`` (list of
        ``(after_seq, missing_blocks, missing_samples)``), ``missing_samples``, ``overflows`` and
        ``overflow_samples`` (blocks and samples the recorder dropped), ``events`` (count by
        kind), ``impacts`` (trigger detections), ``sim_impacts`` (simulator truth),
        ``bytes_per_sample`` (file bytes per recorded sample and channel), ``recovery`` (the
        ``ramdaq.recovery`` metadata, its ``damaged`` list parsed, if any).

    Raises
    ------
    NotARamdaqRecording
        Not an MCAP file, or one without ``ramdaq.stream`` metadata.
    """
    path = Path(path)
    topics: dict[int, str] = {}
    meta: dict[str, dict[str, str]] = {}
    rig = b""
    blocks = n_samples = overflow_blocks = overflow_samples = 0
    first: fmt.BlockHeader | None = None
    prev: fmt.BlockHeader | None = None
    gaps: list[tuple[int, int, int]] = []
    overflow_runs: list[tuple[int, int]] = []
    events: Counter[str] = Counter()
    impacts: list[Any] = []
    sim_impacts: list[Any] = []
    damaged: list[dict[str, Any]] = []
    with open(path, "rb") as f:
        scanner = RecordScanner(f, path)
        for record in scanner:
            if isinstance(record, Damage):
                damaged.append({"start": record.start, "end": record.end, "bytes": record.bytes,
                                "what": record.what, "reason": record.reason,
                                "after_seq": prev.seq if prev else -1})
            elif isinstance(record, Channel):
                topics[record.id] = record.topic
            elif isinstance(record, Metadata):
                meta[record.name] = record.metadata
            elif isinstance(record, Attachment) and record.name == fmt.RIG_ATTACHMENT:
                rig = record.data
            elif isinstance(record, Message):
                topic = topics.get(record.channel_id)
                if topic == fmt.BLOCK_TOPIC:
                    h = fmt.decode_header(record.data)
                    if prev is not None and (
                        h.seq != prev.seq + 1 or h.first_sample != prev.next_sample
                    ):
                        gaps.append((prev.seq, h.seq - prev.seq - 1, h.first_sample - prev.next_sample))
                    first = first or h
                    prev = h
                    blocks += 1
                    n_samples += h.n_samples
                elif topic == fmt.EVENTS_TOPIC:
                    event = fmt.decode_json(record.data)
                    events[event.get("kind", "?")] += 1
                    if event.get("kind") == "overflow":
                        detail = event["detail"]
                        overflow_runs.append((int(detail["first_seq"]), int(detail["last_seq"])))
                        overflow_blocks += int(detail.get("blocks", 0))
                        overflow_samples += int(detail.get("samples", 0))
                elif topic == fmt.IMPACTS_TOPIC:
                    impacts.append(fmt.decode_json(record.data))
                elif topic == fmt.SIM_IMPACTS_TOPIC:
                    sim_impacts.append(fmt.decode_json(record.data))
    if fmt.STREAM_METADATA not in meta:
        raise NotARamdaqRecording(f"{path}: not a ramdaq recording (no {fmt.STREAM_METADATA} metadata)")
    stream = meta[fmt.STREAM_METADATA]
    try:
        info = fmt.stream_info_from_metadata(stream, rig.decode())
    except NotARamdaqRecording as err:
        raise NotARamdaqRecording(f"{path}: {err}") from err
    file_bytes = scanner.size
    total_samples = n_samples * info.n_channels
    return {
        "path": str(path),
        "file_bytes": file_bytes,
        "complete": scanner.complete,
        "tail_bytes": scanner.tail_bytes,
        "stopped_because": scanner.reason,
        "footer": scanner.end.footer,
        "summary_ok": scanner.end.summary_ok,
        "data_crc_ok": scanner.data_crc_ok,
        "damaged": damaged,
        "chunks": scanner.chunks,
        "device": info.device,
        "fs_hz": info.fs_hz,
        "channels": list(info.channels),
        "units": list(info.units),
        "gages": list(info.gages),
        "n_channels": info.n_channels,
        "extra": info.extra,
        "rig_toml_bytes": len(rig),
        "ramdaq_version": stream.get("ramdaq_version", "?"),
        "created_utc": stream.get("created_utc", "?"),
        "blocks": blocks,
        "n_samples": n_samples,
        "first_sample": first.first_sample if first else -1,
        "last_sample": prev.next_sample - 1 if prev else -1,
        "duration_s": n_samples / info.fs_hz,
        "span_s": (prev.next_sample - first.first_sample) / info.fs_hz if first and prev else 0.0,
        "t0_ns": first.t0_ns if first else None,
        "gaps": gaps,
        "missing_samples": sum(g[2] for g in gaps),
        "overflows": overflow_blocks,
        "overflow_samples": overflow_samples,
        "overflow_runs": overflow_runs,
        "events": dict(events),
        "impacts": impacts,
        "sim_impacts": sim_impacts,
        "bytes_per_sample": file_bytes / total_samples if total_samples else None,
        "recovery": _recovery(meta.get("ramdaq.recovery")),
    }


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


def _state(d: dict[str, Any]) -> str:
    """The file's state in a few words: complete, or what is wrong with it."""
    parts = []
    if d["damaged"]:
        parts.append(f"DAMAGED: {len(d['damaged'])} damaged stretch(es), "
                     f"{_mb(sum(x['bytes'] for x in d['damaged']))} unreadable")
    if d["summary_ok"] is False:
        parts.append("summary DAMAGED (fails its CRC)")
    if not d["footer"]:
        parts.append(f"NO FOOTER, {_mb(d['tail_bytes'])} torn tail")
    elif not d["complete"]:
        parts.append(f"footer intact but the data section is unreadable for its last "
                     f"{_mb(d['tail_bytes'])}")
    elif parts:
        parts.append("footer intact")
    return ", ".join(parts) or "complete"


def _gap_cause(d: dict[str, Any], seq: int) -> str:
    """Why the blocks after ``seq`` are missing: a damaged chunk, the recorder, or the device."""
    if any(x["after_seq"] == seq for x in d["damaged"]):
        return "DAMAGED chunk"
    if d["recovery"] and any(x.get("after_seq") == seq for x in d["recovery"]["damaged"]):
        return "damaged chunk left out by recover"
    if any(a <= seq + 1 <= b for a, b in d["overflow_runs"]):
        return "recorder overflow"
    return "device"


def format_info(d: dict[str, Any]) -> str:
    """Readable text of :func:`describe_recording`'s result, one fact per line."""
    bps = f", {d['bytes_per_sample']:.2f} bytes/sample" if d["bytes_per_sample"] else ""
    lines = [
        f"{d['path']}  ({_mb(d['file_bytes'])}{bps}, {_state(d)})",
        f"device     {d['device']}   created {d['created_utc']}   ramdaq {d['ramdaq_version']}",
        f"stream     {d['n_channels']} channels at {d['fs_hz']:g} Hz: {d['duration_s']:.3f} s "
        f"recorded ({d['n_samples']} samples/channel) in {d['blocks']} blocks, "
        f"samples {d['first_sample']}..{d['last_sample']}",
        *_wrap(
            "channels   ",
            [f"{c} ({f'gage {g}, ' if g else ''}{u})"
             for c, u, g in zip(d["channels"], d["units"], d["gages"], strict=True)],
        ),
    ]
    if d["gaps"]:
        lines.append(f"gaps       {len(d['gaps'])}, {d['missing_samples']} samples missing:")
        for seq, nb, ns in d["gaps"]:
            lines.append(
                f"           after seq {seq}: {nb} block(s), {ns} samples "
                f"({ns / d['fs_hz']:.3f} s), {_gap_cause(d, seq)}"
            )
    else:
        lines.append("gaps       none")
    lines.append(
        f"overflows  {d['overflows']} blocks ({d['overflow_samples']} samples) dropped by the recorder"
    )
    kinds = ", ".join(f"{k} {n}" for k, n in sorted(d["events"].items())) or "none"
    lines.append(f"events     {kinds}")
    lines.append(f"impacts    {len(d['impacts'])} detected, {len(d['sim_impacts'])} simulated (truth)")
    if d["recovery"]:
        r = d["recovery"]
        skipped = f", {len(r['damaged'])} damaged stretch(es) left out" if r["damaged"] else ""
        lines.append(f"recovered  from {r.get('source')} ({r.get('tail_bytes')} bytes of torn tail "
                     f"dropped{skipped})")
    if d["recovery"] and d["recovery"].get("data_crc") == "failed":
        lines.append("WARNING    the source's data-section CRC failed although every chunk passed "
                     "its own: its stream metadata or header may be damaged")
    for x in d["damaged"]:
        lines.append(f"DAMAGED    {x['what']} at byte {x['start']} ({x['bytes']} bytes skipped, after "
                     f"block seq {x['after_seq']}): {x['reason']}")
    if d["damaged"] or d["summary_ok"] is False:
        lines.append(f"WARNING    replay, analyze and gap refuse this file; `ramdaq recover {d['path']}` "
                     f"copies every intact record to a new one")
    elif not d["complete"]:
        lines.append(f"WARNING    {d['stopped_because']}; run `ramdaq recover {d['path']}`")
    return "\n".join(lines)
