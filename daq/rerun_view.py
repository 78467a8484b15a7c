"""Live and recorded view of a ram trial in Rerun: gage traces, impacts, results and mode shapes.

:class:`RerunView` turns a stream of :class:`~ramdaq.drivers.block.Block` s into a Rerun recording, written
to an ``.rrd`` file (``rerun file.rrd`` opens it), served to Rerun's web viewer on localhost, or
streamed to a running viewer. Everything is on one timeline, ``time``: seconds since the stream's
first sample (a duration timeline, integer ns from the sample clock, never wall time).

Entity layout (``<k>`` the impact number, ``gXX`` the channel name)::

    gages                        live traces of every gage channel, one row per bucket of
                                 ~fs/live_rate_hz samples: series "gXX min", "gXX max" per channel
                                 (channels that are not gages: signals)
    impacts/markers, impacts/log  a point at each onset (green accepted, red rejected, grey pending)
                                 and a TextLog line per decision
    impacts/<k>                  AnyValues: onset_s, status, reason and the detector's flags
    impacts/<k>/traces           full-rate traces around impact k, one series per channel
    impacts/<k>/decay/gXX        the decay a result was fitted to, if given; .../envelope (+e, -e)
    impacts/<k>/mode             Arrows3D of the last mode shape of impact k (+ f_hz)
    results/gXX/{f_hz,delta,amplitude}, results/log   per-gage final estimates, also logged
    results/looks/{f_hz,delta}   first looks: one row per look, a series per gage ("gXX look")
    layout/{gages,axes,rudder,stock}   static gage positions coloured by body, axes, outline, in
                                 ship axes (``rudder``: the control surface, a stern plane too)
    layout/mode                  the mode shape at the time cursor: arrows along the sensing axes

Min/max rather than a plain decimated series: a 25.6 kHz trace in a plot a few thousand pixels wide
is drawn as a band per pixel anyway; each bucket's extremes give the same band and never hide a
peak, a clip or a spike, which keeping every n-th sample would alias or drop. A row holds
``[min, max]`` per channel (series "gXX min", "gXX max"), or the one sample when no decimation is
needed. All channels of a group share one entity and one time column: one entity per channel
cost a time stamp per value and a chunk per channel per batch, most of the file. The
viewer holds ~70 B per point, so the live traces are never full rate (16 ch x 100 rows/s x 2 is
3.2 k points/s, ~0.2 MB/s of viewer memory); full rate is only sent around impacts.

Few entities, few chunks: every row logged to an entity at its own moment becomes a chunk of its
own in the ``.rrd``, and the file's footer keeps a manifest entry per chunk in memory until the
file is closed (~1.7 kB each, Rerun 0.41). First looks come every ~0.5 s while a blow rings; logged
per gage (``results/gXX/...``) they were 32 chunks a look, ~8 MB/min of RSS and two thirds of the
file (``benchmarks/soak.py``); as one row of all gages under ``results/looks`` they are 2.
"""

from __future__ import annotations

import colorsys
import math
import os
import socket
import subprocess
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from urllib.parse import quote

import numpy as np

# Rerun's Rust side allocates with its own mimalloc, which hands a freed page back to the OS only
# after a purge delay, and only when the thread that owns it next calls into the allocator: in a
# live trial the logging and writer threads mostly sleep, so the copies of every blow's full-rate
# traces (16 ch x 1.2 s x 25.6 kHz x 8 B = 3.9 MB, held two or three times on the way to the file)
# stayed resident, +6 to +12 MB per minute of a 25.6 kHz trial with the view alone
# (``benchmarks/rerun_rss.py --pace 1``), flat with a purge delay of 0. mimalloc reads the option
# when rerun's library loads, hence before the import; a value already in the environment is kept,
# and the viewers started here (:func:`_run`) get the environment as it was.
PURGE_ENV = "MIMALLOC_PURGE_DELAY"
_SET_PURGE = PURGE_ENV not in os.environ
PURGE_APPLIED = "rerun_bindings" not in sys.modules
"""False when rerun was imported before this module, so the purge delay set here came too late."""
os.environ.setdefault(PURGE_ENV, "0")

import rerun as rr  # noqa: E402
import rerun.blueprint as rrb  # noqa: E402

from ..analysis.model.rig import Rig, parse_rig  # noqa: E402
from ..drivers.block import Block, StreamInfo  # noqa: E402
from .errors import ViewError  # noqa: E402

TIMELINE = "time"
BODY_COLORS = {"rudder": (60, 130, 230), "stock": (240, 150, 40), "hull": (150, 150, 150)}
STATUS_COLORS = {True: (40, 190, 80), False: (220, 50, 50), None: (160, 160, 160)}
SIGN_COLORS = ((60, 110, 230), (230, 70, 60))  # negative, positive modal displacement
LOCALHOST = "127.0.0.1"
# Live rows per second per channel, each [min, max] of its bucket: a 10 s window on a plot 1000
# pixels wide is 100 pixels a second, so every pixel column still holds its own bucket's band,
# at a twentieth of the file and viewer memory of 2000 rows/s. Full rate goes around each blow.
LIVE_RATE_HZ = 100.0


def _ns(sample: np.ndarray | int, fs_hz: float) -> np.ndarray:
    """Sample index -> time since stream start, ``timedelta64[ns]`` (rounded half up)."""
    return np.floor(np.asarray(sample, dtype=np.float64) * 1e9 / fs_hz + 0.5).astype("timedelta64[ns]")


def _gage_name(gage: str | int) -> str:
    return f"g{gage:02d}" if isinstance(gage, int | np.integer) else str(gage)


def rerun_binary() -> Path:
    """Path of the ``rerun`` executable shipped in the ``rerun-sdk`` wheel (CLI, viewer, web assets)."""
    import rerun_cli

    return Path(rerun_cli.__file__).resolve().parent / ("rerun.exe" if sys.platform == "win32" else "rerun")


def _listening(port: int, timeout_s: float = 0.0) -> bool:
    """True once something accepts TCP connections on localhost ``port`` (polled ``timeout_s`` s)."""
    deadline = time.monotonic() + timeout_s
    while True:
        with socket.socket() as s:
            s.settimeout(0.2)
            if s.connect_ex((LOCALHOST, port)) == 0:
                return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.05)


def check_ports(web_port: int, grpc_port: int) -> None:
    """Raise :class:`~ramdaq.daq.errors.ViewError` naming the port unless both ports are free on
    localhost: each is bound for real, as the servers will bind it (``SO_REUSEADDR``, so a
    connection of a previous run still in TIME_WAIT does not count as taken)."""
    if web_port == grpc_port:
        raise ViewError(f"Rerun web viewer and gRPC server cannot share port {web_port}")
    for port, what in ((grpc_port, "gRPC server"), (web_port, "web viewer")):
        with socket.socket() as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind((LOCALHOST, port))
            except OSError as err:
                raise ViewError(f"Rerun {what}: port {port} on {LOCALHOST} is taken by another "
                                f"program ({err.strerror})") from err


def _run(args: list[str], **kw: object) -> subprocess.Popen:
    """Start the wheel's ``rerun`` binary, quiet, in the environment without our purge delay."""
    env = {k: v for k, v in os.environ.items() if not (_SET_PURGE and k == PURGE_ENV)}
    return subprocess.Popen([str(rerun_binary()), *args], stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, **kw)


class RerunView:
    """A Rerun recording of one stream; a lifetime: create, log, :meth:`close` (or use ``with``).

    Parameters
    ----------
    info : StreamInfo
        The stream: channel names, sample rate (Hz), rig text (for the gage layout).
    application_id : str
        Rerun application id (viewers group recordings and remember blueprints by it).
    recording_name : str, optional
        Human-readable name shown in the viewer.
    rrd_path : Path, optional
        Write the recording to this ``.rrd`` file (overwritten). The default when no display.
        :meth:`close` finishes it (footer); a process killed before that (SIGKILL, power cut)
        leaves it without one.
    serve_web : bool
        Serve Rerun's web viewer on ``http://127.0.0.1:<web_port>`` (a child ``rerun`` process bound to
        localhost only) fed by a gRPC server in this process on ``127.0.0.1:<grpc_port>``.
    web_port, grpc_port : int
        Localhost TCP ports of the web viewer (HTTP) and of the gRPC server; both are checked
        (:func:`check_ports`) before anything starts.
    connect : str, optional
        Also stream to a running viewer, e.g. ``"rerun+http://127.0.0.1:9876/proxy"``.
    live_rate_hz : float
        Rows per second per channel of the live gage traces (each row ``[min, max]``; default
        ``LIVE_RATE_HZ``).
    live_batch_s : float
        Stream seconds of live rows gathered per ``send_columns`` call (viewer latency, s); fewer,
        bigger chunks cost less CPU and file.
    footer : bool
        Finish the ``.rrd`` with Rerun's footer (a manifest of every chunk: random access, and
        ``rerun rrd verify`` passes). Rerun keeps that manifest in memory until :meth:`close`,
        ~1.7 kB per chunk written, so a long trial's RSS grows with it: a live trial writes
        ~500 chunks a minute (5 a second of live traces, the rest per blow and look), ~0.9 MB
        per minute (``benchmarks/rerun_rss.py --no-footer`` shows the difference); ``False``
        for sessions of hours, and ``rerun rrd optimize`` adds a footer afterwards.
    memory_limit : str
        Buffer limit of the gRPC server (late-joining web viewers replay it) and of a spawned native
        viewer, e.g. ``"25%"`` of RAM or ``"2GB"``; the oldest data is dropped beyond it.

    With none of ``rrd_path``, ``serve_web``, ``connect``: a native viewer is spawned when a display
    exists (bound to localhost, reused if already there, left open after :meth:`close`), otherwise
    ``ValueError``. A taken port, an ``.rrd`` that cannot be created or a web viewer that does
    not start raise :class:`~ramdaq.daq.errors.ViewError` (an unwritable folder: ``OSError``).
    Not thread-safe: log from one thread.
    """

    def __init__(self, info: StreamInfo, *, application_id: str = "ramdaq",
                 recording_name: str | None = None, rrd_path: Path | None = None,
                 serve_web: bool = False, web_port: int = 9090, grpc_port: int = 9876,
                 connect: str | None = None, live_rate_hz: float = LIVE_RATE_HZ,
                 live_batch_s: float = 0.2, footer: bool = True,
                 memory_limit: str = "25%") -> None:
        if live_rate_hz <= 0:
            raise ValueError(f"live_rate_hz must be positive, got {live_rate_hz}")
        if serve_web:
            check_ports(web_port, grpc_port)
        self.info = info
        self.rig: Rig | None = parse_rig(info.rig_toml, "<stream>") if info.rig_toml else None
        self.bucket = max(1, round(info.fs_hz / live_rate_hz))  # samples per live row
        self._batch_rows = max(1, math.ceil(live_batch_s * info.fs_hz / self.bucket))
        self._pending: list[tuple[np.ndarray, np.ndarray]] = []  # (times, rows) not yet sent
        self._tail: np.ndarray | None = None  # counts of an incomplete bucket, from _tail_start
        self._pending_rows = self._tail_start = self._last_sample = self._last_k = 0
        # first looks: one column per gage channel, keyed "gXX" by its report gage number
        self._look_cols = {_gage_name(g): j for j, g in enumerate(g for g in info.gages if g)}
        self._look: tuple[float, np.ndarray] | None = None  # (t_s, [f_hz; delta] per gage) unsent
        self._scale = np.ones(info.n_channels)
        self._onsets: dict[int, float] = {}
        self._closed = False
        self.rrd_path = Path(rrd_path) if rrd_path is not None else None
        self.web_url: str | None = None
        self.grpc_url: str | None = None
        self._web_proc: subprocess.Popen | None = None
        # live entity -> its channels' rows in the stream
        self._groups = {path: np.flatnonzero([bool(g) == want for g in info.gages])
                        for path, want in (("gages", True), ("signals", False))}
        self._groups = {p: rows for p, rows in self._groups.items() if rows.size}

        self.rec = rr.RecordingStream(application_id, make_default=False)
        self.rec.set_log_tick_enabled(False)  # only the sample-clock timeline
        self.rec.set_log_time_enabled(False)
        sinks: list = []
        if self.rrd_path is not None:
            self.rrd_path.parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(self.rrd_path, write_footer=footer))
        if serve_web:
            server = rr.GrpcServerSink(LOCALHOST, grpc_port, server_memory_limit=memory_limit)
            sinks.append(server)
            self.grpc_url = server.uri
        if connect:
            sinks.append(rr.GrpcSink(connect))
        if not sinks:
            if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                          or os.environ.get("WAYLAND_DISPLAY")):
                raise ValueError("RerunView: no display; give rrd_path, serve_web=True or connect=")
            self.grpc_url = f"rerun+http://{LOCALHOST}:{grpc_port}/proxy"
            if not _listening(grpc_port):
                _run(["--bind", LOCALHOST, "--port", str(grpc_port), "--memory-limit", memory_limit,
                      "--expect-data-soon"], start_new_session=True)
                _listening(grpc_port, 10.0)
            sinks.append(rr.GrpcSink(self.grpc_url))
        try:
            self.rec.set_sinks(*sinks, default_blueprint=self.blueprint())
        except RuntimeError as err:  # how rerun reports an .rrd it cannot create
            raise ViewError(f"Rerun view did not start ({' '.join(str(err).split())})") from err
        if recording_name:
            self.rec.send_recording_name(recording_name)
        self.rec.send_property("stream", rr.AnyValues(
            device=info.device, fs_hz=info.fs_hz, channels=list(info.channels),
            units=list(info.units), live_bucket_samples=self.bucket,
            rig_name=self.rig.name if self.rig else ""))
        self._log_static()
        if serve_web:
            try:
                self._start_web(web_port)
            except BaseException:
                self.close()
                raise

    # ----------------------------------------------------------------- setup
    def blueprint(self) -> rrb.Blueprint:
        """Default layout: gage traces and impacts (tabs), results, 3-D gage layout, event log."""
        chans = [c for c, g in zip(self.info.channels, self.info.gages, strict=True) if g]
        f_hz, delta = ([f"results/{c}/{q}" for c in chans] + [f"results/looks/{q}"]
                       for q in ("f_hz", "delta"))
        series = rrb.Tabs(
            rrb.TimeSeriesView(name="Gages (min/max)", origin="gages",
                               contents=["$origin/**", "impacts/markers"]),
            rrb.TimeSeriesView(name="Impacts (full rate, decays)", origin="impacts",
                               contents=["$origin/**", "- impacts/markers"]))
        results = rrb.Horizontal(rrb.TimeSeriesView(name="Frequency (Hz)", contents=f_hz),
                                 rrb.TimeSeriesView(name="Log decrement", contents=delta))
        side = rrb.Vertical(rrb.Spatial3DView(name="Gage layout / mode shape", origin="layout"),
                            rrb.TextLogView(name="Events", contents=["impacts/log", "results/log"]))
        return rrb.Blueprint(rrb.Horizontal(rrb.Vertical(series, results, row_shares=[3, 2]), side,
                                            column_shares=[3, 2]),
                             rrb.TimePanel(timeline=TIMELINE), collapse_panels=False)

    def _log_static(self) -> None:
        """Series styling and, when the stream has a rig, the 3-D layout (all static)."""
        names = ["min", "max"] if self.bucket > 1 else ["value"]
        for path, rows in self._groups.items():  # per channel a hue, its min and max lines alike
            chans = [self.info.channels[i] for i in rows]
            self.rec.log(path, rr.SeriesLines(colors=[self._hue(i) for i in rows for _ in names],
                                              widths=1.0, names=[f"{c} {m}" for c in chans for m in names]),
                         static=True)
        self.rec.log("impacts/markers", rr.SeriesPoints(markers="diamond", marker_sizes=6.0,
                                                        names="impact"), static=True)
        gage_rows = [i for i, g in enumerate(self.info.gages) if g]
        for q in ("f_hz", "delta"):
            self.rec.log(f"results/looks/{q}", rr.SeriesPoints(
                markers="circle", marker_sizes=2.5, colors=[self._hue(i) for i in gage_rows],
                names=[f"{self.info.channels[i]} look" for i in gage_rows]), static=True)
        if self.rig is None:
            return
        self.rec.log("layout", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        gages = self.rig.gages_by_channel()
        sf = self.rig.surface  # the layout is drawn in ship axes, a stern plane's stock athwartship
        pos = np.array([sf.to_ship(g.position_m) for g in gages])
        size = self._extent()
        self.rec.log("layout/gages", rr.Points3D(
            pos, radii=0.012 * size, colors=[BODY_COLORS[g.body] for g in gages],
            labels=[f"g{g.number:02d} ({sf.body(g.body)}, {sf.ship_axis(g.axis)})" for g in gages]),
            static=True)
        self.rec.log("layout/axes", rr.Arrows3D(
            origins=pos, vectors=[0.05 * size * np.array(sf.to_ship(g.direction)) for g in gages],
            colors=[BODY_COLORS[g.body] for g in gages], radii=0.002 * size), static=True)
        r = self.rig.rudder
        self.rec.log("layout/rudder", rr.Boxes3D(
            half_sizes=np.abs(sf.to_ship((r.chord_m / 2, r.thickness_m / 2, r.span_m / 2))),
            colors=BODY_COLORS["rudder"], labels=f"{sf.title} (approx.)"), static=True)
        self.rec.log("layout/stock", rr.LineStrips3D(
            [[sf.to_ship((r.stock_x_m, 0.0, r.attach_z_m)),
              sf.to_ship((r.stock_x_m, 0.0, self.rig.hull_attach_z_m))]],
            colors=BODY_COLORS["stock"], radii=0.004 * size), static=True)

    def _hue(self, i: int) -> tuple[int, int, int]:
        """Channel ``i``'s colour: hues evenly spaced over the channels."""
        return tuple(int(255 * v) for v in colorsys.hsv_to_rgb(i / self.info.n_channels, 0.75, 0.9))

    def _extent(self) -> float:
        """Largest span of the gage layout along any axis, m (1 m without a rig)."""
        if self.rig is None:
            return 1.0
        pos = np.array([g.position_m for g in self.rig.gages])
        return float(max(np.ptp(pos, axis=0).max(), 0.1))

    def _start_web(self, web_port: int) -> None:
        """Start the bundled web viewer (HTTP, localhost only) pointing at our gRPC server."""
        self._web_proc = _run(["--serve-web", "--bind", LOCALHOST, "--web-viewer-port", str(web_port),
                               self.grpc_url])
        if not _listening(web_port, 15.0) or self._web_proc.poll() is not None:
            self._stop_web()
            raise ViewError(f"Rerun web viewer did not start on {LOCALHOST}:{web_port}")
        self.web_url = f"http://{LOCALHOST}:{web_port}/?url={quote(self.grpc_url, safe='')}"

    def _stop_web(self) -> None:
        proc, self._web_proc = self._web_proc, None
        if proc is not None:
            proc.terminate()
            try:
                proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5.0)

    # ----------------------------------------------------------------- data
    def _at(self, t_s: float) -> None:
        self.rec.set_time(TIMELINE, duration=np.timedelta64(int(math.floor(t_s * 1e9 + 0.5)), "ns"))

    def _send_rows(self, path: str, t: np.ndarray | rr.TimeColumn, rows: np.ndarray) -> None:
        if not isinstance(t, rr.TimeColumn):
            t = rr.TimeColumn(TIMELINE, duration=t)
        self.rec.send_columns(path, indexes=[t], columns=rr.Scalars.columns(scalars=rows))

    def log_block(self, block: Block) -> None:
        """Log one block as min/max-decimated traces under ``gages/gXX``.

        Buckets of ``self.bucket`` samples are aligned to the absolute sample index, so block edges
        do not matter; an incomplete last bucket waits for the next block (or is sent alone if the
        next block does not follow on, or at :meth:`close`). Each bucket's row is stamped with the
        time of its first sample. Rows go out every ``live_batch_s`` of stream, one ``send_columns``
        call per channel.
        """
        self._send_look()
        counts, start = block.counts, block.first_sample
        if self._tail is not None:
            if self._tail_start + self._tail.shape[1] == start:
                counts, start = np.concatenate([self._tail, counts], axis=1), self._tail_start
                self._tail = None
            else:
                self._flush_tail()
        n, b = counts.shape[1], self.bucket
        self._last_sample = max(self._last_sample, start + n)
        self._scale = block.scale
        end = max(((start + n) // b) * b - start, 0)  # samples up to the last whole-bucket boundary
        if end < n:
            self._tail, self._tail_start = counts[:, end:], start + end
        if end == 0:
            return
        head = (-start) % b  # a partial first bucket only after a gap (or an unaligned start)
        edges = np.unique(np.concatenate([[0], np.arange(head, end, b)]))
        self._emit(counts[:, :end], start, edges)

    def _emit(self, counts: np.ndarray, start: int, edges: np.ndarray) -> None:
        """Reduce ``counts`` to one row per bucket starting at ``edges``; queue, send when due."""
        scale = self._scale[:, None]
        if self.bucket == 1:
            rows = counts * scale
        else:
            lo = np.minimum.reduceat(counts, edges, axis=1) * scale
            hi = np.maximum.reduceat(counts, edges, axis=1) * scale
            rows = np.stack([np.minimum(lo, hi), np.maximum(lo, hi)], axis=2)  # scale may be < 0
        self._pending.append((_ns(start + edges, self.info.fs_hz), rows))
        self._pending_rows += len(edges)
        if self._pending_rows >= self._batch_rows:
            self._send_pending()

    def _send_pending(self) -> None:
        if not self._pending:
            return
        t = rr.TimeColumn(TIMELINE, duration=np.concatenate([p[0] for p in self._pending]))
        rows = np.concatenate([p[1] for p in self._pending], axis=1)  # (n_ch, n_rows[, 2])
        self._pending, self._pending_rows = [], 0
        for path, chans in self._groups.items():  # (n_rows, n_chans x width), channel-major
            self._send_rows(path, t, np.moveaxis(rows[chans], 0, 1).reshape(rows.shape[1], -1))

    def _flush_tail(self) -> None:  # the carried incomplete bucket becomes a row of its own
        if self._tail is not None and self._tail.shape[1]:
            self._emit(self._tail, self._tail_start, np.array([0]))
        self._tail = None

    def log_full_rate(self, first_sample: int, values: np.ndarray, fs_hz: float,
                      k: int | None = None) -> None:
        """Log full-rate traces around an impact under ``impacts/<k>/traces`` (a series per channel).

        ``values`` (n_channels, n) are SI (m/s^2, N) in channel order, sampled at ``fs_hz`` Hz from
        stream sample ``first_sample``; ``k`` defaults to the last impact given to :meth:`log_impact`.
        """
        self._send_look()
        values = np.asarray(values, dtype=np.float64)
        if values.ndim != 2 or values.shape[0] != self.info.n_channels:
            raise ValueError(f"values must be ({self.info.n_channels}, n), got {values.shape}")
        k = self._last_k if k is None else k
        t = _ns(first_sample + np.arange(values.shape[1]), fs_hz)
        path = f"impacts/{k}/traces"
        self.rec.log(path, rr.SeriesLines(colors=[self._hue(i) for i in range(self.info.n_channels)],
                                          widths=1.0, names=list(self.info.channels)), static=True)
        self._send_rows(path, t, values.T)

    def log_impact(self, k: int, onset_s: float, flags: Mapping[str, object] | None = None,
                   accepted: bool | None = None, reason: str = "") -> None:
        """Mark impact ``k`` at ``onset_s`` s: a point on ``impacts/markers``, a TextLog line on
        ``impacts/log`` and its facts as AnyValues on ``impacts/<k>``. ``accepted`` None = pending;
        call again with the decision (the later call wins at the same time)."""
        self._send_look()
        flags = {n: (v.item() if isinstance(v, np.generic) else v) for n, v in (flags or {}).items()}
        self._onsets[k], self._last_k = float(onset_s), k
        self._at(onset_s)
        self.rec.log("impacts/markers", rr.Scalars(0.0), rr.SeriesPoints(colors=STATUS_COLORS[accepted]))
        state = {True: "accepted", False: "REJECTED", None: "pending"}[accepted]
        raised = ", ".join(name for name, v in flags.items() if v is True)
        text = f"impact {k} at {onset_s:.4f} s: {state}" + (f" [{raised}]" if raised else "") + (
            f" - {reason}" if reason else "")
        self.rec.log("impacts/log", rr.TextLog(text, level="WARN" if accepted is False else "INFO"))
        facts = {n: (v if isinstance(v, bool | int | float | str) else str(v)) for n, v in flags.items()}
        self.rec.log(f"impacts/{k}", rr.AnyValues(onset_s=float(onset_s), status=state.lower(),
                                                  reason=reason or "-", **facts))
        self.rec.reset_time()

    def log_gage_result(self, k: int, gage: str | int, t_s: float, f_hz: float, delta: float,
                        amplitude: float, final: bool, decay_t_s: np.ndarray | None = None,
                        decay: np.ndarray | None = None, envelope: np.ndarray | None = None) -> None:
        """Log one gage's estimate for impact ``k`` at time ``t_s`` s.

        A final result (``final=True``) gets a point each on ``results/gXX/f_hz`` (Hz),
        ``results/gXX/delta`` (log decrement, -) and ``results/gXX/amplitude`` (SI), drawn as
        large diamonds, and a ``results/log`` line. A first look (``final=False``) of a gage
        channel goes into the row of ``results/looks/f_hz`` and ``results/looks/delta`` at
        ``t_s``, one column per gage (the gages a look does not give are NaN, not drawn); the row
        is sent once a call for another time, or any other logging call, comes (at the latest
        with the next block). A value that is not a finite number (a first look's amplitude) is
        not logged. With ``decay_t_s`` (s since stream start, shape (n,)) and ``decay``
        (SI, (n,)) the fitted signal goes to ``impacts/<k>/decay/gXX``; ``envelope`` ((n,) amplitude,
        drawn as +e and -e, or (n, 2)) to ``impacts/<k>/decay/gXX/envelope``.
        """
        g = _gage_name(gage)
        look = not final and g in self._look_cols
        if look:
            self._add_look(g, t_s, f_hz, delta)
        else:
            self._send_look()
        style = rr.SeriesPoints(markers="diamond" if final else "circle", marker_sizes=6 if final else 2.5)
        self._at(t_s)
        for name, v in (("f_hz", f_hz), ("delta", delta), ("amplitude", amplitude)):
            if math.isfinite(v) and not (look and name != "amplitude"):
                self.rec.log(f"results/{g}/{name}", rr.Scalars(float(v)), style)
        if final:
            self.rec.log("results/log", rr.TextLog(
                f"impact {k} {g}: f = {f_hz:.4g} Hz, delta = {delta:.4g}, amplitude = {amplitude:.4g}"))
        self.rec.reset_time()
        if decay_t_s is None:
            return
        t = np.floor(np.asarray(decay_t_s, dtype=np.float64) * 1e9 + 0.5).astype("timedelta64[ns]")
        if decay is not None:
            self._send_rows(f"impacts/{k}/decay/{g}", t, np.asarray(decay, dtype=np.float64))
        if envelope is not None:
            env = np.asarray(envelope, dtype=np.float64)
            env = np.stack([env, -env], axis=1) if env.ndim == 1 else env
            self.rec.log(f"impacts/{k}/decay/{g}/envelope",
                         rr.SeriesLines(names=["+envelope", "-envelope"], colors=[(200, 200, 200)] * 2),
                         static=True)
            self._send_rows(f"impacts/{k}/decay/{g}/envelope", t, env)

    def _add_look(self, g: str, t_s: float, f_hz: float, delta: float) -> None:
        """Put gage ``g``'s first look into the look row at ``t_s`` (sending an older row)."""
        if self._look is not None and self._look[0] != t_s:
            self._send_look()
        if self._look is None:
            self._look = (t_s, np.full((2, len(self._look_cols)), np.nan))
        self._look[1][:, self._look_cols[g]] = (f_hz, delta)

    def _send_look(self) -> None:
        """Send the gathered first-look row: one row on each of ``results/looks/{f_hz,delta}``."""
        if self._look is None:
            return
        (t_s, row), self._look = self._look, None
        self._at(t_s)
        for q, values in zip(("f_hz", "delta"), row, strict=True):
            self.rec.log(f"results/looks/{q}", rr.Scalars(values))
        self.rec.reset_time()

    def log_mode_shape(self, k: int, f_hz: float, shape: Mapping[str | int, complex | float]) -> None:
        """Draw a mode shape on the gage layout: arrows from each gage along its sensing axis.

        ``shape`` maps gage (``"g04"`` or 4) to a complex or real modal amplitude. Complex shapes are
        made real by projecting on the phase of the largest component (so the sign is the phase
        relative to it); the largest arrow is 30 % of the layout size. Logged to ``layout/mode``
        (what the 3-D view shows) and ``impacts/<k>/mode``, at impact ``k``'s onset if known.
        """
        if self.rig is None:
            raise ValueError("log_mode_shape needs the rig: the stream's rig_toml is empty")
        self._send_look()
        by_name = {f"g{g.number:02d}": g for g in self.rig.gages}
        items = [(by_name[_gage_name(key)], complex(v)) for key, v in shape.items()]
        if not items:
            return
        amps = np.array([v for _, v in items])
        real = (amps * np.exp(-1j * np.angle(amps[np.argmax(np.abs(amps))]))).real
        rel = real / (float(np.abs(real).max()) or 1.0)
        length = 0.3 * self._extent()
        arrows = rr.Arrows3D(
            origins=[self.rig.surface.to_ship(g.position_m) for g, _ in items],
            vectors=[length * r * np.array(self.rig.surface.to_ship(g.direction))
                     for (g, _), r in zip(items, rel, strict=True)],
            colors=[SIGN_COLORS[int(r >= 0)] for r in rel],
            labels=[f"g{g.number:02d} {r:+.2f}" for (g, _), r in zip(items, rel, strict=True)],
            radii=0.006 * self._extent())
        self._at(self._onsets.get(k, self._last_sample / self.info.fs_hz))
        self.rec.log("layout/mode", arrows)
        self.rec.log(f"impacts/{k}/mode", arrows, rr.AnyValues(f_hz=float(f_hz), impact=k))
        self.rec.reset_time()

    # ----------------------------------------------------------------- lifetime
    def flush(self) -> None:
        """Send the queued live rows and first look now (e.g. when the stream pauses) and flush
        the sinks."""
        self._send_look()
        self._send_pending()
        self.rec.flush(timeout_sec=30.0)

    def close(self) -> None:
        """Send the pending partial bucket, flush, finish the file (footer) and stop serving.

        Safe to call twice. A web viewer already open keeps what it received.
        """
        if self._closed:
            return
        self._closed = True
        try:
            self._flush_tail()
            self.flush()
            self.rec.disconnect()
        finally:
            self._stop_web()

    def __enter__(self) -> RerunView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

