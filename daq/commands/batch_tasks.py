"""The per-recording tasks of ``ramdaq batch``: a recording's path in, typed result rows out,
and the recording's report folder written as ``ramdaq analyze`` / ``ramdaq gap`` write it.

Each task is a plain function of its :class:`TaskSpec` that never raises for a bad recording (its
:class:`TaskResult` says why, in one line) and knows nothing of dask: the same function runs on a
dask worker, in a process pool or in this process, and gives the same rows. Running it twice
(a worker killed mid-task, its task run again elsewhere) writes the same folder again.
"""

from __future__ import annotations

import functools
import hashlib
import math
import os
import socket
import time
from dataclasses import asdict, dataclass, field
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from ..mode_table import ModeEstimate, mode_rows

if TYPE_CHECKING:
    from ...analysis.gap.diagnose import Diagnosis

STATUSES = ("ok", "failed", "lost", "interrupted")
"""A recording's status in the table: analysed (``ok``); its task ran and the recording could
not be analysed (``failed``: corrupt, truncated, no rig ...); the workers running it died
``distributed.scheduler.allowed-failures`` times (``lost``); the batch was stopped before it
ran (``interrupted``). Only ``ok`` and ``failed`` are results of the recording itself."""


@dataclass(frozen=True)
class TaskSpec:
    """One recording to process: its absolute ``path`` (as the workers see it), its content
    ``sha256`` (hex), the report ``folder`` to write, whether to draw the PNG ``plots``, and the
    ``rig`` to hold it against (gap only: a rig file's absolute path or a shipped rig's name;
    ``""``: the rig the recording carries) with that rig's text's ``rig_sha256``."""

    path: str
    sha256: str
    folder: str
    plots: bool
    rig: str = ""
    rig_sha256: str = ""


@dataclass(frozen=True)
class GapRow:
    """A recording's gap diagnosis: the ``verdict``, the named ``effect`` (None unless
    explained), its detection score ``detection_z``, the gap on the fitted and held-out impacts
    (residual energy beyond the noise, in noise variances), the share of it the named effect
    closes (1 = all; None without one) with its 95 % interval on the held-out impacts, the
    effect's ``dbic``, and the strongest ``findings`` in physical terms (one line each, as the
    ``ramdaq gap`` summary prints them); ``answer`` the one answer of both layers (an effect's
    name, ``"none"`` or ``"unexplained"``, as ``ramdaq gap`` prints it and the benchmark scores
    it) and ``answered_by`` the layer that gave it (``"model"`` or ``"data"``)."""

    verdict: str
    effect: str | None
    detection_z: float | None
    gap_fitted: float
    gap_held_out: float
    closed_fitted: float | None
    closed_held_out: float | None
    closed_held_out_lo: float | None
    closed_held_out_hi: float | None
    dbic: float | None
    impacts: int
    findings: tuple[str, ...]
    answer: str | None = None
    answered_by: str | None = None


@dataclass(frozen=True)
class AnalyzeRow(ModeEstimate):
    """A row of ``analyze.parquet``: a :class:`~ramdaq.daq.mode_table.ModeEstimate` (one mode
    on one gage of one hit; the same numbers as ``ramdaq.analyze(...).rows()``) and what the
    table needs besides.

    Numbering, one convention in the CLI, this table and report.json: hits and modes count from
    0 (``hit`` is report.json's ``impacts[i].index`` and ``--impact``; ``mode`` is the index
    into report.json's ``analysis.modes`` and the CLI's ``mode 0``), gages by their rig numbers.
    ``mode`` is null where no mode was fitted (a gage with no decay, a hit not analysed) --
    ``fitted`` is False and ``reason`` says why -- as in ``ModeEstimate``.
    ``channel``: the recorded channel's name in the stream (``g01``, "" for a hit's row);
    ``source_channel``: its name in the file it was imported from ("" if not imported).
    ``decay_cut``: the hit's decay record was cut before the analysis window the trigger wants
    (report.json ``flags.too_short``: the next blow, a gap or the end of the record);
    ``decay_end``: what ended it (``decayed``, ``next_impact``, ``gap``, ``end``);
    ``record_samples`` / ``analysed_samples``: the hit's decay record and the leading part of it
    the analysis used (report.json's; the rest cropped to an FFT-fast length), null where the hit
    was not analysed."""

    channel: str = ""
    source_channel: str = ""
    decay_cut: bool = False
    decay_end: str = ""
    record_samples: int | None = None
    analysed_samples: int | None = None


UNITS = {"onset_s": "s", "f_hz": "Hz", "f_se_hz": "Hz", "mode_f_hz": "Hz", "mode_f_se_hz": "Hz",
         "delta": "1", "delta_se": "1", "zeta": "1", "zeta_se": "1", "mode_delta": "1",
         "mode_delta_se": "1", "mode_zeta": "1", "mode_zeta_se": "1", "amplitude": "m/s^2",
         "phase_rad": "rad", "seconds": "s (wall)", "detection_z": "1 (z-score)",
         "gap_fitted": "noise variances", "gap_held_out": "noise variances",
         "closed_fitted": "1 (share)", "closed_held_out": "1 (share)",
         "closed_held_out_lo": "1 (share)", "closed_held_out_hi": "1 (share)", "dbic": "1",
         "hit": "index from 0", "mode": "index from 0", "gage": "rig gage number",
         "hits_found": "count", "hits_accepted": "count", "impacts": "count",
         "record_samples": "samples", "analysed_samples": "samples"}
"""Each numeric column's unit (schema metadata ``ramdaq.unit.COLUMN``); a column not here is
text, a flag or an identity (unit ``-``)."""


def analyze_rows(h, channels: tuple[str, ...], sources: dict[str, str]) -> tuple[AnalyzeRow, ...]:
    """The table rows of one hit: :func:`~ramdaq.daq.mode_table.mode_rows` with the recorded
    ``channels`` (the stream's names) and the import's ``sources`` (stream name -> source
    name)."""
    ev = h.event
    out = []
    for r in mode_rows(h):
        d = asdict(r)
        name = f"g{r.gage:02d}" if r.gage and f"g{r.gage:02d}" in channels else ""
        d.update(channel=name, source_channel=sources.get(name, ""), decay_cut=bool(ev.too_short),
                 decay_end=str(getattr(ev, "end_reason", "") or ""),
                 record_samples=getattr(h.analysis, "record_samples", None),
                 analysed_samples=getattr(h.analysis, "analysed_samples", None))
        out.append(AnalyzeRow(**d))
    return tuple(out)


@dataclass(frozen=True)
class TaskResult:
    """What one task gives back: the recording's identity (``recording`` path, content
    ``sha256``, ``method`` digest of the code that ran, ``plots``, the ``rig`` given and its
    ``rig_sha256``, both ``""`` for the recording's own), its ``status``
    (:data:`STATUSES`) with a one-line ``status_reason`` when not ok, the report ``folder``, which
    ``worker`` ran it (host:pid) in ``seconds`` (wall, s), its ``hits_found`` and
    ``hits_accepted`` (for gap: impacts found and compared), the ``rig_name`` and ``medium`` it
    was analysed with (the rig the recording carries, as report.json's ``rig`` and ``medium``;
    for gap the rig held), and its ``rows``
    (:class:`~ramdaq.daq.mode_table.ModeEstimate` for analyze, :class:`GapRow` for gap)."""

    recording: str
    sha256: str
    status: str
    status_reason: str = ""
    folder: str = ""
    plots: bool = False
    rig: str = ""
    rig_sha256: str = ""
    method: str = ""
    worker: str = ""
    seconds: float = 0.0
    hits_found: int = 0
    hits_accepted: int = 0
    rig_name: str = ""
    medium: str = ""
    rows: tuple = field(default=())

    @classmethod
    def not_run(cls, spec: TaskSpec, status: str, reason: str) -> TaskResult:
        """A recording whose task gave no result (``lost``, ``interrupted``)."""
        return cls(spec.path, spec.sha256, status, reason, spec.folder, spec.plots, spec.rig,
                   spec.rig_sha256)


@functools.cache
def method_digest() -> str:
    """sha256 (first 16 hex) of this installed ramdaq's source, rig and threshold files: two
    runs with the same digest ran the same code on the same rigs."""
    h = hashlib.sha256()
    for pkg in ("ramdaq", "ramdaq.analysis", "ramdaq.daq", "ramdaq.drivers", "ramdaq.rigs"):
        root = Path(str(resources.files(pkg)))
        own = ("*.py",) if pkg == "ramdaq" else ("**/*.py", "**/*.toml", "**/*.json", "**/*.dbc")
        for f in sorted({p for pat in own for p in root.glob(pat)}):
            h.update(f"{pkg}/{f.relative_to(root).as_posix()}\0".encode())
            h.update(f.read_bytes())
    return h.hexdigest()[:16]


def file_sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    """sha256 of a file's bytes, hex."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while b := f.read(chunk):
            h.update(b)
    return h.hexdigest()


def one_line(exc: BaseException, limit: int = 300) -> str:
    """An exception as one line in words: the first line of its message, which for ramdaq's
    own errors (a damaged recording, a bad rig, a file that cannot be read) names the file and
    what, whole (its advice comes last); any other exception is an ``internal error`` with its
    type and its message's first ``limit`` characters, a cut marked "..."."""
    from ...analysis.model.rig import RigError
    from ...drivers.errors import DeviceError
    from ...drivers.mcap_format import RecordingError

    text = str(exc).strip().splitlines()
    first = text[0] if text else ""
    if isinstance(exc, RigError | DeviceError | RecordingError | OSError | ValueError) and first:
        return first
    cut = first if len(first) <= limit else first[:limit].rsplit(" ", 1)[0] + " ..."
    return f"internal error ({type(exc).__name__}){': ' + cut if cut else ''}"


def failure_reason(exc: BaseException, path: str) -> str:
    """:func:`one_line` without the recording's path in front (the row names it)."""
    text = one_line(exc)
    return text[len(path) + 2:] if text.startswith(f"{path}: ") else text


def _worker() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def _finish(spec: TaskSpec, t0: float, **kw) -> TaskResult:
    return TaskResult(spec.path, spec.sha256, folder=spec.folder, plots=spec.plots, rig=spec.rig,
                      rig_sha256=spec.rig_sha256, method=method_digest(), worker=_worker(),
                      seconds=time.perf_counter() - t0, **kw)


def analyze_task(spec: TaskSpec) -> TaskResult:
    """``ramdaq analyze`` of one recording: its report folder written, its rows returned (one
    per hit x gage x mode, :class:`~ramdaq.daq.mode_table.ModeEstimate`). A recording that
    cannot be analysed is a ``failed`` result naming why."""
    from .analyze import run_analysis, write_analysis

    t0 = time.perf_counter()
    try:
        rig, hits = run_analysis(spec.path)
        write_analysis(spec.path, rig, hits, Path(spec.folder), plots=spec.plots)
    except Exception as exc:  # a recording that breaks the analysis is a row, not a crash
        return _finish(spec, t0, status="failed", status_reason=failure_reason(exc, spec.path))
    channels, sources = _stream_names(spec.path)
    rows = tuple(r for h in hits for r in analyze_rows(h, channels, sources))
    return _finish(spec, t0, status="ok", hits_found=len(hits),
                   hits_accepted=sum(h.accepted for h in hits), rig_name=rig.name,
                   medium=rig.medium, rows=rows)


def _stream_names(path: str) -> tuple[tuple[str, ...], dict[str, str]]:
    """The recording's channel names and, for an import, each one's source channel name."""
    from ...drivers.mcap_replay import McapReplayDevice

    with McapReplayDevice(path) as dev:
        info = dev.info
    imported = info.extra.get("import", {}).get("channels", {})
    return info.channels, {k: str(v.get("source", "")) for k, v in imported.items()}


def gap_task(spec: TaskSpec) -> TaskResult:
    """``ramdaq gap`` of one recording with the default settings, held against ``spec.rig`` (or
    the rig it carries): its report folder (gap.json, plots) written, its :class:`GapRow`
    returned. A recording that cannot be diagnosed is a ``failed`` result naming why."""
    from .gap import rig_record, run_gap, write_report

    t0 = time.perf_counter()
    try:
        lt, td, d = run_gap(spec.path, rig=spec.rig or None)
        write_report(d, Path(spec.folder), plots=spec.plots, source=spec.path,
                     rig=rig_record(lt, spec.rig or None))
        row = gap_row(d)
    except Exception as exc:  # a recording that breaks the diagnosis is a row, not a crash
        return _finish(spec, t0, status="failed", status_reason=failure_reason(exc, spec.path))
    return _finish(spec, t0, status="ok", hits_found=len(lt.onsets_s), hits_accepted=int(td.n_seg),
                   rows=(row,))


def _finite(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(v) else float(v)


def gap_row(d: Diagnosis, n_findings: int = 5) -> GapRow:
    """A :class:`~ramdaq.analysis.gap.diagnose.Diagnosis` as one row."""
    b = d.best
    lo, hi = b.closed_held_ci if b else (None, None)
    fm = d.features
    return GapRow(verdict=d.verdict, effect=b.name if b else None, detection_z=_finite(d.z_detect),
                  gap_fitted=float(d.gap_fit), gap_held_out=float(d.gap_held),
                  closed_fitted=_finite(b.closed_fit) if b else None,
                  closed_held_out=_finite(b.closed_held) if b else None,
                  closed_held_out_lo=_finite(lo), closed_held_out_hi=_finite(hi),
                  dbic=_finite(b.dbic) if b else None, impacts=int(d.forward.td.n_seg),
                  findings=tuple(r["text"] for r in fm.strongest(n_findings)) if fm else (),
                  answer=d.answer.named if d.answer else None,
                  answered_by=d.answer.by if d.answer else None)


TASKS = {"analyze": analyze_task, "gap": gap_task}
"""The task of each ``ramdaq batch`` kind."""
ROWS = {"analyze": AnalyzeRow, "gap": GapRow}
"""The row type of each kind."""
