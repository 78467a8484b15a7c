"""A trial, live or replayed: one device through recorder, trigger, analyzer and views.

Threads (the only place in ramdaq that starts them, besides the recorder's writer):

- the caller's thread reads the device and never waits on disk or analysis (but in a replay
  nobody watches, below): each block goes to
  the recorder's bounded queue, through the trigger (vectorised, far faster than real time), to
  the live views;
- two analyzer threads take work from the main loop through a bounded queue
  (:mod:`ramdaq.daq.jobqueue`): one every finished impact record (a final analysis; on a live
  device it hands the analysis to a worker process, :mod:`ramdaq.daq.final_process`, so that
  the final and the acquisition run on two cores, not on one interpreter lock), the other,
  while the rudder still rings, first looks at the decay so far -- so a final never holds up the
  next blow's first looks; the look thread shows a look itself as soon as it is done, under
  the session's lock, which the caller's thread holds while it takes a block. (A replay flat
  out with no looks and no view runs each final on the caller's thread instead, as its record
  closes, :attr:`Session.finals_inline`: nobody watches it, and the two threads' contention
  cost such a replay 5-9 % of its CPU.) A first look is
  asked for when the last one is done: the first after
  :data:`LOOK_CYCLES` periods of the predominant mode of free decay (the rig model's period,
  then the one the last sure look measured; ``first_look_s`` stands in for a period where the
  rig has no model), on the first block that ends by then; then one period more each until
  one is sure enough to show (:data:`LOOK_REL_SE`; such a look, if the one before is still
  running, waits behind it in the queue rather than for a block after it), then each time the
  decay has grown by :data:`LOOK_GROWTH` (and ``update_s`` at least). A later blow
  starts a period past the last blow's longest look that was not sure (its own standard error
  said how many were worth waiting for), so a look that cannot be sure does not hold the look thread
  when the one that can is due. When the analyzer falls behind a live device,
  first looks are skipped first, then finals run on a shorter, decimated decay, and last a
  final is left unanalysed -- each counted in the summary and written as an event; samples are
  never skipped, and the queue never holds more than its bound. A device that can wait
  (``pace == "fast"``: a replay, a simulator run flat out) waits for room instead, so its
  finals are always whole.

Final numbers come from the impact's complete record alone, so a replay of the recording
(``McapReplayDevice`` through the same session) gives the same impacts and the same numbers.
Results go into the recording on ``/ramdaq/impacts`` (detections), ``/ramdaq/results`` and,
at the end, ``/ramdaq/summary``.
"""

from __future__ import annotations

import dataclasses
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..analysis.impact import FirstLook
from ..analysis.model.rig import Rig, parse_rig
from ..analysis.model.rig_modes import modes_in
from ..drivers.base import FAULT_POLL_S, Device, DeviceFault
from ..drivers.block import Block, sample_time_ns
from ..drivers.errors import DeviceError, DeviceTimeout
from ..drivers.fault_words import FaultWords
from ..drivers.mcap_format import IMPACTS_TOPIC
from .analyzer import (
    UNSURE_REL_SE,
    AnalyzerLoad,
    FinalDone,
    FinalJob,
    HitResult,
    LookDone,
    LookJob,
    decay_skip_s,
    finite_json,
    hit_to_json,
    run_job,
    trial_summary,
)
from .final_process import FinalProcess, WorkerDied, WorkerUnavailable
from .heap import map_large_blocks
from .jobqueue import Admission, JobQueue, QueuePolicy
from .readout import LiveReadout, accepted_line
from .trigger import ImpactEvent, Trigger, TriggerSettings

if TYPE_CHECKING:  # the recorder (the MCAP writer) is imported only by a session that records
    from .recorder import Recorder

RESULTS_TOPIC = "/ramdaq/results"
"""Per-hit final results (JSON, SI units) written into the recording by a live trial."""
# Points of a drawn decay envelope e^(-x): a chord over h time constants is off by at most h²/8
# relative, so 256 points keep it within 0.1 % (h <= 0.089) over 22 time constants, by which the
# envelope is e^-22 of its start, below any ADC's noise floor.
ENVELOPE_POINTS = 256
# Full rate in the view from the record's start (the trigger's pre-trigger window) to this long
# after the onset: the blow, a double hit, clipping and the first cycles of the decay, where the
# detail is; the rest of the decay is in the live min/max trace (rerun_view.LIVE_RATE_HZ rows/s).
FULL_RATE_AFTER_S = 1.0
LOOK_REL_SE = UNSURE_REL_SE
"""A first look is shown when the median over gages of its decrement's standard error relative
to the decrement is at most this (the estimator's own figure: a number +- 25 % at one sigma is
worth a glance, a wilder one is not); a gage above it is marked "unsure" in the readout."""
LOOK_EARLY = 0.1
"""A look due after k periods of free decay is taken on a block that ends this many periods
early (a block's end rarely falls on a period's)."""
LOOK_CYCLES = 2
"""Periods of the predominant mode of free decay before a blow's first look is tried: two
periods are the least from which a decrement (the ratio of successive peaks) can come at all."""
LOOK_PRE_MARGIN_S = 0.05
"""A first look's pre-trigger window ends this long before the blow's detection sample (which
comes after the blow's start by about the trigger's STA window, 10 ms by default), so that it holds
no part of the blow: the lines in it are the ones that rang before (an ambient hull tone),
which a look does not take as the predominant mode."""
LOOK_GROWTH = 0.5
"""Once a blow's look has been shown, the next is taken when its decay has grown by this
fraction (and by ``update_s`` at least): a look's numbers change only as its decay grows by a
fair part of itself (and not at all once the ringing is under the noise), and a look every
``update_s`` on a 14 s decay was 28 looks a blow at ~0.1 s CPU each -- most of a live trial's
CPU, taken from the finals and the next blow's first looks -- where 1.5x makes about 8."""
SUMMARY_TOPIC = "/ramdaq/summary"
"""The trial summary (:func:`~ramdaq.daq.analyzer.trial_summary`), written once at the end."""


@dataclass(frozen=True)
class JobFailed:
    """An analyzer job that raised: the job and its exception."""

    job: FinalJob | LookJob
    error: Exception


@dataclass(frozen=True)
class Notice:
    """Something the analyzer thread has to say (shown, noted, and written as an event of
    ``kind`` by the main loop, which owns the readout and the recorder)."""

    kind: str
    text: str


@dataclass(frozen=True)
class Shown:
    """When a hit's numbers were shown: hit ``index``, ``kind`` ("look" or "final"), the blow's
    onset sample in s of stream, and the wall clock then (``time.monotonic()``, s)."""

    index: int
    kind: str
    onset_s: float
    wall_s: float


@dataclass(frozen=True)
class JobTime:
    """One analyzer job's timing: ``kind`` ("look" or "final"), the blow's onset sample, one
    past the last sample the job had, when it was queued, started and ended
    (``time.monotonic()``, s) and the CPU spent on it (s): its thread's (``time.thread_time()``),
    or, for a final run in the worker process, the worker's (``time.process_time()``)."""

    kind: str
    onset_sample: int
    data_end: int
    queued_s: float
    start_s: float
    end_s: float
    cpu_s: float


@dataclass
class TrialOutcome:
    """What a session leaves: every hit judged and analysed, the trial summary, and counts."""

    hits: list[HitResult]
    summary: dict
    samples: int
    skipped_updates: int
    first_looks: int
    interrupted: bool
    recording: Path | None = None
    rrd: Path | None = None
    notes: list[str] = field(default_factory=list)
    load: AnalyzerLoad | None = None

    def results_json(self) -> list[dict]:
        """Final per-hit results, the numbers replay must reproduce exactly."""
        return [hit_to_json(h) for h in self.hits]


class Session:
    """Run ``device`` to its end (or Ctrl-C), recording and analysing as it goes.

    Parameters
    ----------
    device : Device
        Any back-end: the simulator, a front-end, or a recording replayed.
    record_path : Path, optional
        Write an MCAP recording here (live trials); ``None`` records nothing (replay).
    view : RerunView, optional
        Live Rerun view (its own ``.rrd`` or web viewer).
    readout : LiveReadout or False or None
        Terminal table; ``None`` makes one, ``False`` shows nothing.
    update_s : float
        Least stream seconds between looks at a ringing decay once one has been shown (they
        come as the decay grows by :data:`LOOK_GROWTH`).
    first_look_s : float
        Where the rig has no model to give the predominant mode's period: the seconds of free
        decay that stand in for one period (:data:`LOOK_CYCLES`).
    trigger_settings : TriggerSettings, optional
        The trigger's settings (default ``TriggerSettings()``).
    queue_policy : QueuePolicy, optional
        Bounds of the analyzer queue and its coarse finals (default ``QueuePolicy()``).
    shed : bool, optional
        Shed work when the analyzer falls behind (:mod:`ramdaq.daq.jobqueue`) rather than wait
        for it; default: shed unless the device can wait (``device.pace == "fast"``).
    looks : bool, optional
        Take first looks at each ringing decay; default: yes, except for a recording replayed
        flat out with no live view (``ramdaq replay`` without ``--realtime`` or a view), where
        nobody can watch a look before its final comes and the finals are what a replay
        reproduces (the looks cost ~10 % of such a replay's CPU).
    final_process : bool, optional
        Run the finals in a worker process (:mod:`ramdaq.daq.final_process`); default: yes for
        a device paced in real time (a live front-end, ``pace="realtime"``), whose finals would
        otherwise share the interpreter lock with the acquisition, and no for one that can wait
        (a replay or a simulator flat out: one core, no process to start). The numbers are the
        same either way.

    Held for the summary per hit: its numbers and its trigger event, without the samples (the
    recording has them), so that memory stays flat however long the trial.
    """

    def __init__(self, device: Device, *, record_path: str | Path | None = None,
                 overwrite: bool = False, view=None, readout: LiveReadout | bool | None = None,
                 update_s: float = 0.5, first_look_s: float = 0.1,
                 trigger_settings: TriggerSettings | None = None,
                 log: Callable[[str], None] | None = None,
                 queue_policy: QueuePolicy | None = None, shed: bool | None = None,
                 looks: bool | None = None, final_process: bool | None = None) -> None:
        self.device = device
        self.info = device.open()
        if not self.info.rig_toml:
            raise ValueError(f"{self.info.device}: the stream carries no rig; a trial needs one")
        rig = parse_rig(self.info.rig_toml, source=f"{self.info.device}:rig")
        medium = self.info.extra.get("medium")
        self.rig: Rig = rig.with_medium(medium) if medium and medium != rig.medium else rig
        self.record_path = Path(record_path) if record_path else None
        self.overwrite = overwrite
        self.view = view
        self.readout = (LiveReadout(self.info, adc_bits=self.info.extra.get("adc_bits"))
                        if readout is None else (readout or None))
        self.update_n = round(update_s * self.info.fs_hz)
        period = _model_period_s(self.rig)
        # samples per period of the predominant mode (first_look_s without a model), and the
        # periods of free decay the next blow's first look is tried at
        self._period_n = max(1.0, (period or first_look_s) * self.info.fs_hz)
        self._start_cycles = LOOK_CYCLES if period else 1
        self._look_cycles = self._start_cycles  # periods of the ringing hit's next look
        self._look_first_sure: float | None = None  # periods of its first sure look
        self._look_unsure = 0.0  # periods of its longest look not sure enough to show
        self._look_sure = False  # a first look of the ringing hit has been shown
        self._look_order: int | None = None  # modes in the last blow's first sure look
        self._look_tried = False  # a look at the ringing hit has been asked for
        self._ringing_onset: int | None = None  # onset sample of the latest blow that rang
        self.trigger = Trigger(self.info, trigger_settings)
        self.log = log
        self._jobs = JobQueue(queue_policy or QueuePolicy(), self.info.fs_hz,
                              round(decay_skip_s(self.rig) * self.info.fs_hz))
        self.shed = getattr(device, "pace", "realtime") != "fast" if shed is None else shed
        self.looks = (view is not None or getattr(device, "kind", "") != "mcap"
                      or getattr(device, "pace", "realtime") != "fast") if looks is None else looks
        self._final_process_wanted = (getattr(device, "pace", "realtime") == "realtime"
                                      if final_process is None else final_process)
        self._final_process: FinalProcess | None = None  # started by run()
        # a replay flat out that nobody watches (no looks, no view) runs each final on the
        # stream's thread as its record closes: no thread to hand it to, and the two threads'
        # contention cost a replay 5-9 % of its CPU (the finals' own included)
        self.finals_inline = (not self.shed and not self.looks and view is None
                              and not self._final_process_wanted)
        self._jobs.trim = not self.finals_inline  # (run(): the heap kept for the next final)
        self._done: queue.Queue[FinalDone | LookDone | JobFailed | Notice] = queue.Queue()
        # held by the stream's thread while it takes a block, and by the look thread while it
        # shows a look: the readout, the view and the looks' schedule are changed under it
        self._lock = threading.Lock()
        self.hits: list[HitResult] = []
        self.notes: list[str] = []
        self.samples = 0
        self.skipped_updates = 0
        self.first_looks = 0
        self.finals_coarse = 0
        self.finals_unanalysed = 0
        self._t_ns = 0  # device time of the latest block's first sample
        self.shown: deque[Shown] = deque(maxlen=4096)  # the latest numbers shown, for timing
        self.job_times: deque[JobTime] = deque(maxlen=4096)  # the latest jobs run, for timing
        self._queued: dict[int, float] = {}  # onset sample of a final queued -> when
        self.wall_at_start: float | None = None  # monotonic s when sample 0 would have come
        self._rec: Recorder | None = None
        self._truth_written = 0  # simulator truth messages already in the recording
        self._next_sample: int | None = None  # where the next block starts if there is no gap
        self._next_look = None
        self._n_events = 0
        self._ringing_hit: int | None = None  # the hit whose first looks are being shown
        self._onsets: dict[int, float] = {}  # hit index -> onset, s, as soon as it rings
        self._gage_rows = [i for i, g in enumerate(self.info.gages) if g]
        self._gages = tuple(self.info.gages[i] for i in self._gage_rows)
        self._fault_words = FaultWords(self.info.device, self.info.fs_hz)

    # -- the analyzer threads -----------------------------------------------------------------
    def _worker(self, kind: type[FinalJob] | type[LookJob]) -> None:
        while self._take_and_run(kind):
            pass

    def _take_and_run(self, kind: type[FinalJob] | type[LookJob]) -> bool:
        """Take the next job of ``kind`` from the queue (waiting for one), run it and mark it
        done; False once the queue is stopped and empty. The samples go with the job's result,
        not with a frame that lives on."""
        job = self._jobs.get(kind)
        if job is None:
            return False
        self._run_one(kind, job)
        del job
        self._jobs.done(kind)
        return True

    def _run_one(self, kind: type[FinalJob] | type[LookJob], job: FinalJob | LookJob) -> None:
        """Do ``job`` (in the finals' worker process if there is one), put its result (or its
        failure) for :meth:`_drain` (a look: show it, :meth:`_show_look_now`) and time it
        (:class:`JobTime`: the job's run, not the showing)."""
        wall, cpu = time.monotonic(), time.thread_time()
        worker_cpu = ran = None
        try:
            if kind is FinalJob and self._final_process is not None:
                try:
                    done, worker_cpu = self._final_process.run(job)
                except WorkerUnavailable as err:  # nothing ran there: this thread it is
                    self._final_process = None
                    self._done.put(Notice("analysis_worker_unavailable",
                                          f"finals run on the analyzer thread: {err}"))
                    done = run_job(job, self.info, self.rig, self._gages)
            else:
                done = run_job(job, self.info, self.rig, self._gages)
            ran = time.monotonic(), time.thread_time()
            if not (isinstance(done, LookDone) and self._show_look_now(done)):
                self._done.put(done)
        except Exception as err:  # never let the analyzer thread die silently
            self._done.put(JobFailed(job, err))
        finally:
            final = kind is FinalJob
            end, cpu_end = ran or (time.monotonic(), time.thread_time())
            cpu = cpu_end - cpu if worker_cpu is None else worker_cpu
            onset = job.event.onset_sample if final else job.onset_sample
            data_end = (job.event.last_sample + 1 if final else
                        onset + round(decay_skip_s(self.rig) * self.info.fs_hz) + job.x.shape[1])
            self.job_times.append(JobTime(
                "final" if final else "look", onset, data_end,
                self._queued.pop(onset, wall) if kind is FinalJob else wall, wall, end, cpu))

    def _show_look_now(self, done: LookDone) -> bool:
        """Show a look on the look thread as soon as it is done, not when the stream's thread
        next drains the results (after the next block: up to a block later, 0.05 s, most of a
        cycle of 13 Hz). False if the stream's thread is taking a block (it shows the look as
        it ends that block, :meth:`_stream`): the look thread never waits for it (on a loaded
        machine the stream's thread may be off its core for a while, and a device that can
        wait may hold it waiting for room that this look's own job still takes)."""
        if not self._lock.acquire(blocking=False):
            return False
        try:
            self._show_look(done.onset_sample, done.look)
        finally:
            self._lock.release()
        return True

    def _final_inline(self) -> None:
        """Run the final just queued on this thread (:attr:`finals_inline`)."""
        self._take_and_run(FinalJob)

    # -- the main loop ------------------------------------------------------------------------
    def run(self) -> TrialOutcome:
        """Stream the device to its end (or Ctrl-C), then wait for every final analysis."""
        if self.finals_inline:
            keep_heap()
        if self._final_process_wanted:
            try:
                self._final_process = FinalProcess(self.info, self.rig, self._gages)
            except (OSError, RuntimeError, ValueError) as err:  # no process: the thread it is
                self._say(f"finals run on the analyzer thread: no worker process ({err})")
                self.notes.append(f"no finals worker process: {err}")
        for kind, name in ((FinalJob, "ramdaq-finals"), (LookJob, "ramdaq-looks")):
            if not (kind is FinalJob and self.finals_inline):
                threading.Thread(target=self._worker, args=(kind,), name=name,
                                 daemon=True).start()
        rec = None
        if self.record_path:  # here: a replay records nothing and needs no MCAP writer
            from .recorder import Recorder

            rec = Recorder(self.record_path, self.info, overwrite=self.overwrite)
        self._rec = rec
        if self.readout:
            self.readout.__enter__()
        try:
            interrupted = self._stream(rec)
            self._end_of_stream(rec)
            self.hits.sort(key=lambda h: h.index)
            summary = trial_summary(self.hits, self.trigger.health, self.load)
            if rec:
                rec.write_json(SUMMARY_TOPIC, finite_json(summary), self._t_ns)
        finally:
            self._jobs.stop()
            if self._final_process is not None:
                self._final_process.close()
            if self.readout:
                self.readout.__exit__(None, None, None)
            if rec:
                rec.close()
            self.device.close()
        return TrialOutcome(self.hits, summary, self.samples, self.skipped_updates,
                            self.first_looks, interrupted, self.record_path, notes=self.notes,
                            load=self.load)

    @property
    def load(self) -> AnalyzerLoad:
        """What the analyzer did and skipped so far."""
        q = self._jobs
        return AnalyzerLoad(self.first_looks, self.skipped_updates, self.finals_coarse,
                            self.finals_unanalysed, q.peak_bytes, q.peak_finals,
                            q.policy.max_bytes, q.policy.max_finals)

    def _stream(self, rec: Recorder | None) -> bool:
        """Take every block of the device; True if Ctrl-C ended the stream."""
        try:
            while True:
                try:  # a timeout, so that what a quiet device reports is said at once
                    block = self.device.read(timeout=FAULT_POLL_S)
                except DeviceTimeout:
                    with self._lock:
                        self._show_faults(self.device.take_faults(), rec)
                    continue
                if block is None:
                    break
                with self._lock:
                    self._take(block, rec)
                if not self._done.empty():  # a look left while the block was being taken
                    with self._lock:
                        self._drain(rec)
        except KeyboardInterrupt as err:  # Ctrl-C, or SIGTERM raised as KeyboardInterrupt("SIGTERM")
            if rec:
                rec.event("interrupted", self._t_end(), reason=str(err) or "Ctrl-C")
            return True
        except DeviceError as err:  # the device gave up: keep what came, say why
            self._show_faults(self.device.take_faults(), rec)
            self._say(f"device ended the stream: {err}")
            if rec:
                rec.event("device_error", self._t_end(), message=str(err))
            self.notes.append(str(err))
        return False

    def _t_end(self) -> int:
        """Stream time just after the last sample taken, ns (0 before the first block)."""
        return 0 if self._next_sample is None else sample_time_ns(self._next_sample, self.info.fs_hz)

    def _show_faults(self, faults: list[DeviceFault], rec: Recorder | None,
                     recorded: bool = False) -> None:
        """Record the device's faults (unless ``store_block`` did) and say them in words."""
        self._fault_words.tell(faults, self._say, rec.event if rec and not recorded else None)

    def _take(self, block: Block, rec: Recorder | None) -> None:
        """One block through the recorder, the trigger, the first looks and the views."""
        if rec:
            from .record import store_block  # a dictionary look-up once imported

            self._truth_written, faults = store_block(
                rec, self.device, block, self._truth_written,
                wait_for_room=getattr(self.device, "pace", "realtime") == "fast")
        else:
            faults = self.device.take_faults()
        self._show_faults(faults, rec, recorded=True)
        gap = self._next_sample is not None and block.first_sample != self._next_sample
        self._next_sample = block.next_sample
        if self.wall_at_start is None:
            self.wall_at_start = time.monotonic() - block.next_sample / self.info.fs_hz
        self._t_ns = block.t0_ns
        self.samples += block.n_samples
        for ev in self.trigger.process(block):
            self._on_event(ev, rec)
        self._maybe_look(block.next_sample)
        if self.view is not None:
            self.view.log_block(block)
        if self.readout:
            self.readout.update(block, queue=rec.stats.queued if rec else 0,
                                overflows=rec.overflows if rec else 0, gap=gap,
                                impacts=list(self._onsets.values()))
        self._drain(rec)

    def _end_of_stream(self, rec: Recorder | None) -> None:
        """The last faults, the trigger's open event, and every final analysis still queued."""
        with self._lock:  # (the look thread shows its looks under it)
            self._show_faults(self.device.take_faults(), rec)  # faults reported with the last read
            for ev in self.trigger.flush():
                self._on_event(ev, rec)
            self._say(f"waiting for the analyzer to finish {self._jobs.pending} job(s)")
        self._jobs.join()
        with self._lock:
            self._drain(rec)
        tally = self._fault_words.tally()  # next to the trial's summary
        if tally:
            self._say(tally)

    def _on_event(self, ev: ImpactEvent, rec: Recorder | None) -> None:
        k = self._n_events
        self._n_events += 1
        self._onsets[k] = ev.onset_s
        if rec:
            rec.write_json(IMPACTS_TOPIC, ev.to_json(), ev.t_ns)
        flags = [f for f, on in (("not analysable", ev.not_analysable is not None),
                                 ("double hit", ev.double_hit), ("clipped", bool(ev.clipped)),
                                 ("short", ev.too_short)) if on]
        self._say(f"hit {k} at {ev.onset_s:.3f} s: {record_end(ev)} (peak {ev.snr_db:.0f} dB over the"
                  " noise before the blow" + (", " + ", ".join(flags) if flags else "")
                  + "): final analysis")
        if self.view is not None:
            self.view.log_impact(k, ev.onset_s, _flags(ev), None)
        self._queued[ev.onset_sample] = time.monotonic()
        self._admitted(self._jobs.put_final(FinalJob(k, ev), wait=not self.shed), ev, rec)
        if self.finals_inline:
            self._final_inline()
        self._next_look = None
        self._ringing_hit = None

    def _maybe_look(self, now: int) -> None:
        """Ask for a look at the ringing decay if one is due at the end of this block (sample
        ``now``): the first block that ends at most :data:`LOOK_EARLY` of a period before the
        look's time (a look at 2.9 periods is the look at 3)."""
        ringing = self.trigger.ringing
        if ringing is None:
            self._next_look = None
            return
        onset, end = ringing
        start = onset + round(decay_skip_s(self.rig) * self.info.fs_hz)
        if self._next_look is None:
            self._ringing_hit = self._n_events
            self._onsets[self._n_events] = onset / self.info.fs_hz
            self._say(f"hit {self._n_events} at {onset / self.info.fs_hz:.3f} s: ringing")
            if self.readout:
                self.readout.clear_results(f"hit {self._n_events}: ringing")
            self._look_cycles = self._start_cycles
            self._next_look = start + round(self._look_cycles * self._period_n)
            self._look_sure, self._look_first_sure, self._look_unsure = False, None, 0.0
            self._look_tried = False
        # the detection sample until the trigger has refined the onset, which the looks carry
        self._ringing_onset = onset
        self._onsets[self._ringing_hit] = onset / self.info.fs_hz
        if not self.looks:
            return
        early = round(LOOK_EARLY * self._period_n)
        # until a look of this blow is sure, the next waits behind a running one (it starts as
        # soon as the thread is free); after, a look is not asked for while one is pending
        busy = self._jobs.looks_pending if self._look_sure else self._jobs.looks_waiting
        if now + early < self._next_look or busy:
            return
        if self._look_sure:  # the decay half as long again, and update_s at least
            self._next_look = now + max(self.update_n, round(LOOK_GROWTH * (now - start)))
        else:  # one period more than this look has, at least
            self._look_cycles = max(self._look_cycles,
                                    int((now - start) / self._period_n + LOOK_EARLY)) + 1
            self._next_look = start + round(self._look_cycles * self._period_n)
        if self._jobs.too_big_for_a_look(8 * len(self._gage_rows) * (end - start)):
            self._next_look = float("inf")  # until the next blow rings (jobqueue's look bound)
            self._look_skipped(onset, "its decay so far passes the queue's bound for a look: "
                                      "no more looks at this blow")
            return
        try:
            x = self.trigger.recent(start, end)[self._gage_rows]
        except IndexError:
            return
        # a blow's first look fits the order the last blow's first sure look found (half the CPU
        # of the search for it; the schedule makes it as long as that one); should it not be
        # sure, the next searches, and so do the looks as the decay grows
        order = None if self._look_tried else self._look_order
        self._look_tried = True
        if not self._jobs.put_look(LookJob(onset, x, self._before_blow(onset), order)):
            self._look_skipped(onset, "its samples would pass the queue's bytes bound")

    def _before_blow(self, onset: int) -> np.ndarray | None:
        """The gage rows in the pre-trigger window before the blow detected at sample
        ``onset`` (SI units), ending :data:`LOOK_PRE_MARGIN_S` before it (the detection comes
        after the blow's start); None where the ring no longer holds them."""
        end = onset - round(LOOK_PRE_MARGIN_S * self.info.fs_hz)
        n = round(self.trigger.settings.pre_trigger_s * self.info.fs_hz)
        try:
            return self.trigger.recent(max(end - n, 0), end)[self._gage_rows]
        except IndexError:
            return None

    def _look_skipped(self, onset: int, why: str) -> None:
        self.skipped_updates += 1
        if self._rec:
            self._rec.event("look_skipped", self._t_ns, onset_sample=onset, reason=why)

    def _admitted(self, adm: Admission, ev: ImpactEvent, rec: Recorder | None) -> None:
        """Count and record what the queue did to take hit ``ev``'s final; a final it refused
        is this hit's result at once, rejected with the reason."""
        for onset in adm.looks_dropped:
            self._look_skipped(onset, "a final's record needed its room in the queue")
        job = adm.job
        k = self._n_events - 1
        if job is not None and job.coarse is not None:
            self.finals_coarse += 1
            self._say(f"hit {k}: {job.coarse.why}; its final runs on at most "
                      f"{job.coarse.decay_s:.3g} s of decay at about {job.coarse.rate_hz:g} Hz")
            if rec:
                rec.event("final_coarse", ev.t_ns, index=k, why=job.coarse.why,
                          decay_s=job.coarse.decay_s, rate_hz=job.coarse.rate_hz)
        if job is None:
            self._queued.pop(ev.onset_sample, None)
            self.finals_unanalysed += 1
            if rec:
                rec.event("final_unanalysed", ev.t_ns, index=k, reason=adm.refused)
            hit = HitResult(k, ev, False, adm.refused, None)
            self._show_final(hit, hit_to_json(hit), rec)

    def _drain(self, rec: Recorder | None) -> None:
        while True:
            try:
                done = self._done.get_nowait()
            except queue.Empty:
                return
            if isinstance(done, Notice):
                self._say(done.text)
                self.notes.append(done.text)
                if rec:
                    rec.event(done.kind, self._t_ns, message=done.text)
            elif isinstance(done, LookDone):
                self._show_look(done.onset_sample, done.look)
            elif isinstance(done, FinalDone):
                self._show_final(done.hit, done.doc, rec)
            elif isinstance(done.job, FinalJob):  # judge_event does not raise; should it, the hit stays
                job, err = done.job, done.error
                if isinstance(err, WorkerDied):
                    self._say(f"hit {job.index}: {err}; a new worker takes the next final")
                    if rec:
                        rec.event("analysis_worker_died", job.event.t_ns, index=job.index,
                                  message=str(err))
                hit = HitResult(job.index, job.event, False,
                                f"analysis failed: {type(err).__name__}: {err}", None)
                self._show_final(hit, hit_to_json(hit), rec)
            else:
                self._say(f"first look at the impact from sample {done.job.onset_sample} "
                          f"failed: {type(done.error).__name__}: {done.error}")

    def _show_look(self, onset: int, look: FirstLook | None) -> None:
        """Show a first look whose decrements are sure enough (:data:`LOOK_REL_SE`), unless a
        later blow already rings."""
        if look is None or onset != self._ringing_onset:
            return
        if not look_is_sure(look):
            self._look_unsure = max(self._look_unsure,
                                    look.duration_s * self.info.fs_hz / self._period_n)
            return
        self._look_sure = True
        self.first_looks += 1
        if self._look_first_sure is None:  # the next blow starts where this one became sure
            self._learn_schedule(look)
        self.shown.append(Shown(-1 if self._ringing_hit is None else self._ringing_hit, "look",
                                onset / self.info.fs_hz, time.monotonic()))
        if self.readout:
            self.readout.look(look.duration_s, {f"g{n:02d}": v for n, v in look.gages.items()},
                              hit=self._ringing_hit)
        if self.view is not None:
            t = onset / self.info.fs_hz + look.duration_s
            for n, (f, d, _) in look.gages.items():
                self.view.log_gage_result(len(self.hits), f"g{n:02d}", t, f, d, float("nan"),
                                          final=False)

    def _learn_schedule(self, look: FirstLook) -> None:
        """The first sure look of a blow: its predominant frequency gives the period the next
        blow's looks are timed in; the next blow's first look is tried one whole period past the
        longest look of this blow that was not sure (at least :data:`LOOK_CYCLES`), or where
        this blow's first was, if that was sure -- not at the sure look's own length, which a
        busy look thread may have made longer than it needed."""
        if np.isfinite(look.f_hz) and look.f_hz > 0:
            self._period_n = self.info.fs_hz / look.f_hz
        if self._look_unsure > 0:
            self._start_cycles = max(LOOK_CYCLES, int(self._look_unsure + LOOK_EARLY) + 1)
        self._look_first_sure = look.duration_s * self.info.fs_hz / self._period_n
        self._look_order = look.n_modes or None

    def _show_final(self, hit: HitResult, doc: dict, rec: Recorder | None) -> None:
        """Show and record one hit's final numbers; ``doc`` is its JSON, made on the analyzer
        thread (:func:`~ramdaq.daq.analyzer.hit_to_json`). The hit is kept without its samples."""
        self.hits.append(dataclasses.replace(hit, event=dataclasses.replace(hit.event, record=None)))
        self.shown.append(Shown(hit.index, "final", hit.event.onset_sample / self.info.fs_hz,
                                time.monotonic()))
        a = hit.analysis
        if rec:
            rec.write_json(RESULTS_TOPIC, {k: doc[k] for k in ("index", "accepted", "reason", "analysis")},
                           hit.event.t_ns)
        if a is None:
            self._say(f"hit {hit.index} at {hit.event.onset_s:.3f} s REJECTED: {hit.reason}")
        else:
            self._say(accepted_line(hit.index, hit.event.onset_s, a,
                                    self.rig.surface.label("v")))
            if self.readout and self._ringing_hit in (None, hit.index):
                self.readout.showing(f"hit {hit.index}: final")
                for n, g in a.gages.items():
                    self.readout.set_result(f"g{n:02d}", g.f_hz, g.delta, final=True,
                                            delta_se=g.delta_se)
                for n, v in a.verdicts.items():  # a look showed numbers the final did not take
                    if not v.ok:
                        self.readout.set_unused(f"g{n:02d}", v.code.text)
        if self.view is not None:
            ev = hit.event
            self.view.log_impact(hit.index, ev.onset_s, _flags(ev), hit.accepted, hit.reason)
            if ev.record is not None:  # full rate only around the blow
                rec_, fs = ev.record, self.info.fs_hz
                end = round((ev.onset_s + FULL_RATE_AFTER_S) * fs) - rec_.first_sample + 1
                self.view.log_full_rate(rec_.first_sample, rec_.values(max(end, 1)), fs,
                                        k=hit.index)
            if a is not None:
                self._log_decays(hit, a)
                k = a.predominant
                active = a.active_gages
                self.view.log_mode_shape(hit.index, a.f_hz, {
                    f"g{n:02d}": complex(s) for n, s in zip(active, a.modes.mode_shape[:, k],
                                                             strict=True)})

    def _log_decays(self, hit: HitResult, a) -> None:
        """Each gage's fitted envelope of the predominant mode over its decay, and its final
        frequency, decrement and amplitude, to the Rerun view. The decay itself is the full-rate
        trace already logged for the hit; the envelope, a smooth exponential, goes at
        ``ENVELOPE_POINTS`` points rather than at full rate."""
        m, k = a.modes, a.predominant
        t_rel = np.linspace(0.0, a.duration_s, ENVELOPE_POINTS)
        envelope = np.exp(-m.delta[k] * m.frequency_hz[k] * t_rel)
        amp = dict(zip(a.active_gages, m.amplitude[:, k], strict=True))
        t_end = a.decay_start_s + a.duration_s
        for n, g in a.gages.items():
            self.view.log_gage_result(hit.index, f"g{n:02d}", t_end, g.f_hz, g.delta,
                                      float(amp.get(n, np.nan)), final=True,
                                      decay_t_s=a.decay_start_s + t_rel,
                                      envelope=amp.get(n, np.nan) * envelope)

    def _say(self, text: str) -> None:
        if self.readout:
            self.readout.hit(text)
        elif self.log:
            self.log(text)


def keep_heap() -> bool:
    """For a replay that runs its finals one after another on one thread
    (:attr:`Session.finals_inline`): the C heap keeps up to 256 MB free for the next final, and
    only arrays of 32 MB or more get their own mapping (:func:`~ramdaq.daq.heap.map_large_blocks`).
    glibc's defaults gave the pages of each final's arrays back (its trim threshold, and the
    trim after each final a live trial makes) and faulted them in again for the next: the
    10-minute, 20-blow replay took ~420 000 page faults and 0.95 s of system CPU, ~100 000 and
    0.35 s so, at the same highest RSS (203 MB). False where the C library cannot (not glibc)."""
    return map_large_blocks(32 << 20, 256 << 20)


def _model_period_s(rig: Rig) -> float | None:
    """Period of the predominant mode the rig's model predicts in its medium, s; None for a
    rig without a structure (a channels-only rig) or whose model gives no finite mode."""
    if not rig.structural:
        return None
    try:
        f = modes_in(rig, rig.medium).predominant_hz
    except (ValueError, ArithmeticError, np.linalg.LinAlgError):
        return None
    return 1.0 / f if np.isfinite(f) and f > 0 else None


_ENDS = {"decayed": "decay at the noise floor after {:.1f} s",
         "max_length": "record at its longest, {:.1f} s",
         "next_impact": "record cut by the next blow after {:.1f} s",
         "gap": "record cut by a gap in the stream after {:.1f} s",
         "flush": "stream ended {:.1f} s after the blow"}


def record_end(ev: ImpactEvent) -> str:
    """Why and when a hit's record closed, in a few words: its decay reached the noise floor,
    or the next blow, a gap, the record's longest or the stream's end cut it (s after onset)."""
    after_s = (ev.last_sample + 1) / ev.fs_hz - ev.onset_s
    return _ENDS.get(ev.end_reason, ev.end_reason + " after {:.1f} s").format(after_s)


def look_is_sure(look: FirstLook) -> bool:
    """True if the median over gages of the decrement's relative standard error is at most
    :data:`LOOK_REL_SE` (gages whose error the estimator could not give left out)."""
    rel = [se / abs(d) for _, d, se in look.gages.values() if d and np.isfinite(se)]
    return bool(rel) and float(np.median(rel)) <= LOOK_REL_SE


def _flags(ev: ImpactEvent) -> dict:
    """An impact's flags for the live view, one type per flag."""
    return {"double_hit": ev.double_hit, "clipped": bool(ev.clipped),
            "clipped_channels": ", ".join(ev.clipped), "too_short": ev.too_short}
