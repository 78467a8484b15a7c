"""The live analyzer's job queue: bounded, with a stated policy for when the analyzer falls behind.

The queue has two lanes, each with its own analyzer thread: first looks and finals, so that a
long final never holds up the next blow's first looks. It holds the jobs waiting and the ones
running; its bound (:class:`QueuePolicy`) is on the bytes of samples those jobs hold together
and on the number of finals. A live trial cannot wait for the analyzer -- the device does not
stop -- so when the analyzer falls behind the queue *sheds* work, in this order:

1. **First looks go first.** A first look is queued only when no other look is waiting (one
   may be running: the session queues a blow's next look behind a running one only while none
   of the blow's looks has been sure, so that the look due next starts the moment the thread is
   free, not a block later) and its samples fit ``max_look_bytes`` (a look is the decay so far, at the full
   rate: 16 gages x 5 s at 25.6 kHz; at 2048 Hz a minute, never reached); a final whose record
   would take the queue past its bytes bound pushes the first look still waiting out of the
   queue.
2. **Then finals run coarse.** A final that arrives while another final is waiting or running
   (or whose record would take the queue past its bytes bound) is cut, on arrival, to the first
   ``coarse_decay_s`` of its free decay, and is analysed decimated to about ``coarse_rate_hz``
   (:class:`~ramdaq.daq.analyzer.Coarse`); its result says so.
3. **Last, a final is not analysed.** If the queue is still at its bound (``max_finals``
   finals, or ``max_bytes``), the hit is kept, rejected as "not analysed", with the reason.

Apart from the shedding, a live final from a stream at least twice as fast as ``live_rate_hz``
(the design rate, 2048 Hz) is analysed decimated to about it, its whole decay kept
(:class:`~ramdaq.daq.analyzer.Coarse` with nothing cut; its result says so): at 25.6 kHz a whole
30 s, 16-gage final held ~1 GB in the estimator's full-rate copies and took minutes of CPU, with
a blow every 30 s. A 2048 Hz stream is analysed as recorded.

Every look skipped and every final made coarse or left unanalysed is counted
(:class:`~ramdaq.daq.analyzer.AnalyzerLoad`, in the trial summary) and the session writes each
as an event into the recording. A source that can wait (a replay or a simulator run as fast as
possible) does not shed: :meth:`JobQueue.put_final` with ``wait=True`` blocks until there is
room, so its finals are always whole and its numbers those of the recording.
"""

from __future__ import annotations

import dataclasses
import threading
from collections import deque
from dataclasses import dataclass

from .analyzer import Coarse, FinalJob, LookJob
from .heap import release_free_memory


@dataclass(frozen=True)
class QueuePolicy:
    """Bounds of the analyzer queue and the coarse finals it falls back to.

    Attributes
    ----------
    max_bytes : int
        Bytes of samples the jobs waiting and running may hold together (a record of 16 gages
        x 30 s at 25.6 kHz is 49 MB of int32 counts; 256 MiB holds five of them).
    max_finals : int
        Finals waiting and running together.
    max_look_bytes : int
        Bytes of samples one first look may hold (float64 SI values of the gages from the
        decay's start): at 25.6 kHz a look at 17 s of decay held 57 MB, and its full-rate
        spectrum several times that, while the final's numbers were seconds away.
    coarse_decay_s : float
        Seconds of free decay a coarse final keeps (a 13 Hz mode rings 52 cycles in 4 s).
    coarse_rate_hz : float
        A coarse final is decimated by the largest whole factor that keeps at least this rate,
        Hz (the design rate: 12x at 25.6 kHz).
    live_rate_hz : float or None
        A live final from a stream at least twice this fast is decimated by the largest whole
        factor that keeps at least this rate, Hz, its whole decay kept (the modes sought are
        below a few hundred Hz; the rigs' anti-alias corners are below 1 kHz). None: never.
    """

    max_bytes: int = 256 * 2**20
    max_finals: int = 3
    max_look_bytes: int = 16 * 2**20
    coarse_decay_s: float = 4.0
    coarse_rate_hz: float = 2048.0
    live_rate_hz: float | None = 2048.0

    def __post_init__(self) -> None:
        if self.max_bytes <= 0 or self.max_finals < 1 or self.max_look_bytes <= 0:
            raise ValueError(f"QueuePolicy: max_bytes ({self.max_bytes}), max_finals "
                             f"({self.max_finals}) and max_look_bytes ({self.max_look_bytes}) "
                             "must be positive")
        if self.live_rate_hz is not None and not self.live_rate_hz > 0:
            raise ValueError(f"QueuePolicy: live_rate_hz ({self.live_rate_hz}) must be positive "
                             "or None")
        if not (self.coarse_decay_s > 0 and self.coarse_rate_hz > 0):
            raise ValueError(f"QueuePolicy: coarse_decay_s ({self.coarse_decay_s}) and "
                             f"coarse_rate_hz ({self.coarse_rate_hz}) must be positive")


@dataclass(frozen=True)
class Admission:
    """What :meth:`JobQueue.put_final` did: the first looks it pushed out (their onsets,
    samples), the job as queued (coarse or not; ``None`` if refused) and why it was refused."""

    looks_dropped: tuple[int, ...]
    job: FinalJob | None
    refused: str = ""


def job_bytes(job: FinalJob | LookJob) -> int:
    """Bytes of samples a job holds."""
    if isinstance(job, LookJob):
        return job.x.nbytes
    rec = job.event.record
    return 0 if rec is None else rec.counts.nbytes


class JobQueue:
    """Jobs for the analyzer thread, bounded by ``policy``; thread-safe.

    ``fs_hz`` is the stream's rate and ``skip_n`` the samples from an onset to its free decay
    (:func:`~ramdaq.daq.analyzer.decay_skip_s`), to cut coarse finals' records on arrival.
    ``trim``: give the C heap's free pages back after each final (:meth:`done`); a replay that
    runs its finals one after another on one thread keeps them for the next instead.
    """

    def __init__(self, policy: QueuePolicy, fs_hz: float, skip_n: int) -> None:
        self.policy = policy
        self.fs_hz, self.skip_n = fs_hz, skip_n
        self._jobs: deque[FinalJob | LookJob] = deque()
        self._running: dict[type, FinalJob | LookJob | None] = {FinalJob: None, LookJob: None}
        self._held = 0  # bytes of the jobs waiting and running
        self._stopped = False
        self._cond = threading.Condition()
        self.peak_bytes = 0
        self.peak_finals = 0
        self.trim = True

    # -- the acquisition side -------------------------------------------------------------------
    def put_look(self, job: LookJob) -> bool:
        """Queue a first look unless another is waiting (one running does not count), or its
        samples would pass ``max_look_bytes`` or take the queue past its bytes bound; False if
        not queued."""
        with self._cond:
            if not self._look_fits(job_bytes(job)):
                return False
            self._add(job)
            return True

    def too_big_for_a_look(self, n_bytes: int) -> bool:
        """Whether ``n_bytes`` of samples pass ``max_look_bytes``: no look at them, ever (ask
        before copying them: at 25.6 kHz a long decay is tens of MB)."""
        return n_bytes > self.policy.max_look_bytes

    def put_final(self, job: FinalJob, *, wait: bool) -> Admission:
        """Queue a final: with ``wait``, block until it fits the bound (or the queue is empty);
        otherwise make room by the policy (module docstring)."""
        with self._cond:
            dropped = () if self._fits_bytes(job) else self._drop_looks()
            if wait:
                self._cond.wait_for(lambda: self._fits(job) or self._idle())
                self._add(job)
                return Admission(dropped, job)
            behind = self._finals()
            if behind or not self._fits_bytes(job):
                job = self._coarse(job, f"{behind} final(s) ahead in the analyzer" if behind
                                   else "its record would pass the queue's bytes bound")
            else:
                job = self._at_live_rate(job)
            if not (self._fits(job) or self._idle()):
                return Admission(dropped, None, self._full_reason(job))
            self._add(job)
            return Admission(dropped, job)

    def stop(self) -> None:
        """No more jobs: :meth:`get` returns None once the queue is empty."""
        with self._cond:
            self._stopped = True
            self._cond.notify_all()

    def join(self) -> None:
        """Wait until every job queued has been run."""
        with self._cond:
            self._cond.wait_for(self._idle)

    @property
    def pending(self) -> int:
        """Jobs waiting or running."""
        with self._cond:
            return len(self._jobs) + sum(j is not None for j in self._running.values())

    @property
    def looks_pending(self) -> int:
        """First looks waiting or running."""
        with self._cond:
            return self._looks()

    @property
    def looks_waiting(self) -> int:
        """First looks waiting (not yet running)."""
        with self._cond:
            return sum(isinstance(j, LookJob) for j in self._jobs)

    # -- the analyzer side ----------------------------------------------------------------------
    def get(self, kind: type[FinalJob] | type[LookJob]) -> FinalJob | LookJob | None:
        """The next job of ``kind``, the lane of the calling thread (it counts as held until
        :meth:`done`); None once stopped and no job of that kind is waiting."""
        with self._cond:
            self._cond.wait_for(lambda: self._next(kind) is not None or self._stopped)
            job = self._next(kind)
            if job is None:
                return None
            self._jobs.remove(job)
            self._running[kind] = job
            return job

    def done(self, kind: type[FinalJob] | type[LookJob]) -> None:
        """The running job of ``kind`` has finished: its samples are released; after a final,
        the C heap's free pages go back to the OS (:mod:`ramdaq.daq.heap`), on the calling
        analyzer thread, so that a trial's RSS follows what it holds, not its highest peak."""
        with self._cond:
            job = self._running[kind]
            if job is not None:
                self._held -= job_bytes(job)
                self._running[kind] = None
            self._cond.notify_all()
        if kind is FinalJob and self.trim:
            release_free_memory()

    # -- inside the lock ------------------------------------------------------------------------
    def _idle(self) -> bool:
        return not self._jobs and all(j is None for j in self._running.values())

    def _next(self, kind: type) -> FinalJob | LookJob | None:
        return next((j for j in self._jobs if isinstance(j, kind)), None)

    def _finals(self) -> int:
        return (sum(isinstance(j, FinalJob) for j in self._jobs)
                + (self._running[FinalJob] is not None))

    def _looks(self) -> int:
        return (sum(isinstance(j, LookJob) for j in self._jobs)
                + (self._running[LookJob] is not None))

    def _look_fits(self, n_bytes: int) -> bool:
        return (not any(isinstance(j, LookJob) for j in self._jobs)
                and n_bytes <= self.policy.max_look_bytes
                and self._held + n_bytes <= self.policy.max_bytes)

    def _fits_bytes(self, job: FinalJob) -> bool:
        return self._held + job_bytes(job) <= self.policy.max_bytes

    def _fits(self, job: FinalJob) -> bool:
        return self._finals() < self.policy.max_finals and self._fits_bytes(job)

    def _add(self, job: FinalJob | LookJob) -> None:
        self._jobs.append(job)
        self._held += job_bytes(job)
        self.peak_bytes = max(self.peak_bytes, self._held)
        self.peak_finals = max(self.peak_finals, self._finals())
        self._cond.notify_all()

    def _drop_looks(self) -> tuple[int, ...]:
        looks = tuple(j for j in self._jobs if isinstance(j, LookJob))
        for j in looks:
            self._jobs.remove(j)
            self._held -= job_bytes(j)
        return tuple(j.onset_sample for j in looks)

    def _coarse(self, job: FinalJob, why: str) -> FinalJob:
        """``job`` with its record cut to the coarse decay (a copy: the long one is freed)."""
        rec = job.event.record
        if rec is None:
            return job
        start = job.event.onset_sample + self.skip_n - rec.first_sample
        end = start + round(self.policy.coarse_decay_s * self.fs_hz)
        full_s = max(0, rec.counts.shape[1] - start) / self.fs_hz
        if end < rec.counts.shape[1]:
            rec = dataclasses.replace(rec, counts=rec.counts[:, :end].copy())
        coarse = Coarse(self.policy.coarse_decay_s, full_s, self.policy.coarse_rate_hz, why)
        return FinalJob(job.index, dataclasses.replace(job.event, record=rec), coarse)

    def _at_live_rate(self, job: FinalJob) -> FinalJob:
        """``job`` decimated to about ``live_rate_hz`` with its whole record, if the stream is
        at least twice as fast (the analyzer thread decimates it, row by row)."""
        rate, rec = self.policy.live_rate_hz, job.event.record
        if rate is None or rec is None or self.fs_hz < 2 * rate:
            return job
        start = job.event.onset_sample + self.skip_n - rec.first_sample
        full_s = max(0, rec.counts.shape[1] - start) / self.fs_hz
        why = (f"the stream's {self.fs_hz:g} Hz is more than twice the live analyzer's "
               f"{rate:g} Hz (its memory and time)")
        return FinalJob(job.index, job.event,
                        Coarse(rec.counts.shape[1] / self.fs_hz, full_s, rate, why))

    def _full_reason(self, job: FinalJob) -> str:
        p = self.policy
        return (f"not analysed: the analyzer queue was at its bound ({self._finals()} of "
                f"{p.max_finals} finals, {(self._held + job_bytes(job)) / 1e6:.0f} of "
                f"{p.max_bytes / 1e6:.0f} MB with this one)")
