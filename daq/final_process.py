"""A live trial's final analyses in a worker process of their own.

A final (:class:`~ramdaq.daq.analyzer.FinalJob`) is ~0.4 s of pure-Python-heavy CPU. Run on
a thread of the acquisition's process it shares one interpreter lock with the acquisition and
the first looks, so on a live trial its wall time grew past its CPU time. Here it runs in one
worker process (``spawn``: the session's process has threads, which ``fork`` would copy
half-held), started with the session, so the final and the acquisition run on two cores.

The worker is given the stream's info, the rig and the gage numbers once; each job sends its
record (a few MB of int32 counts: ~1 ms to pickle), and the result comes back without the
record (the session puts its own back). :func:`~ramdaq.daq.analyzer.run_job` is the same
function the in-process lane runs, so the numbers are the same to the last digit.

The worker ignores Ctrl-C (the terminal sends it to the whole process group; the session
ends the stream and then waits for the finals queued, as without a worker). A worker that
never came up raises :class:`WorkerUnavailable`: the session then runs the finals on its
thread, as without a worker, and says so. A worker that dies
(killed, out of memory, a crash in a C extension) raises :class:`WorkerDied` for the job it was
running; a new worker is started for the next job, and the session records the death as an
event and rejects that hit with the reason -- the trial goes on.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import signal
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool

from ..analysis.model.rig import Rig
from ..drivers.block import StreamInfo
from .analyzer import FinalDone, FinalJob, run_job

_STATE: tuple[StreamInfo, Rig, tuple[int, ...]] | None = None
"""In the worker: what every job is analysed against (set once by :func:`_start`)."""


class WorkerDied(RuntimeError):
    """The worker process died while it ran a final (its exit code in the message)."""


class WorkerUnavailable(RuntimeError):
    """The worker process never came up (its interpreter, its imports or its initializer
    failed: e.g. the calling script re-run by ``spawn`` as ``__mp_main__`` fails there): no
    job ever ran in it, so the job in hand may run on the calling thread instead."""


def _start(info: StreamInfo, rig: Rig, gages: tuple[int, ...]) -> None:
    """The worker's initializer: keep what every job needs; leave Ctrl-C to the session."""
    global _STATE
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _STATE = (info, rig, gages)


def _ready() -> None:
    """A no-op job submitted at start, so the worker's interpreter and imports load while the
    trial arms, not when its first blow's final is due."""


def run_final(job: FinalJob) -> tuple[FinalDone, float]:
    """In the worker: ``job`` done, its hit without the record (the session has it), and the
    worker's CPU seconds for it (``time.process_time``)."""
    assert _STATE is not None, "run_final runs in a FinalProcess worker"
    cpu = time.process_time()
    done = run_job(job, *_STATE)
    hit = dataclasses.replace(done.hit, event=dataclasses.replace(done.hit.event, record=None))
    return FinalDone(hit, done.doc), time.process_time() - cpu


class FinalProcess:
    """One worker process for finals; :meth:`run` blocks the calling thread (not the
    interpreter: it waits on a pipe) until the worker has done the job.

    ``target`` is what the worker runs per job (:func:`run_final`; a module-level function,
    as the worker imports it by name).
    """

    initializer: Callable[..., None] = staticmethod(_start)
    """What a new worker runs first, given (info, rig, gages)."""

    def __init__(self, info: StreamInfo, rig: Rig, gages: tuple[int, ...],
                 target: Callable[[FinalJob], tuple[FinalDone, float]] = run_final) -> None:
        self._args = (info, rig, gages)
        self.target = target
        self.deaths = 0
        self._came_up = False  # a worker has done a job (its start-up no-op at least)
        self._pool = self._new_pool()

    def _new_pool(self) -> ProcessPoolExecutor:
        pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=self.initializer, initargs=self._args)
        pool.submit(_ready).add_done_callback(self._up)  # the worker starts now
        return pool

    def _up(self, ready) -> None:
        if not ready.cancelled() and ready.exception() is None:
            self._came_up = True

    def run(self, job: FinalJob) -> tuple[FinalDone, float]:
        """``job``'s result (with the session's own event, record and all) and the worker's
        CPU seconds for it; :class:`WorkerDied` if the worker died meanwhile (a new one is
        started for the next job)."""
        try:
            done, cpu_s = self._pool.submit(self.target, job).result()
        except BrokenProcessPool as err:
            if not self._came_up:
                self._pool.shutdown(wait=False, cancel_futures=True)
                raise WorkerUnavailable(f"the finals' worker process did not start ({err})") \
                    from err
            self.deaths += 1
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = self._new_pool()
            raise WorkerDied(f"the finals' worker process died while it analysed hit "
                             f"{job.index} ({err})") from err
        return FinalDone(dataclasses.replace(done.hit, event=job.event), done.doc), cpu_s

    def close(self) -> None:
        """Stop the worker (after the job it is running, if any)."""
        self._pool.shutdown(wait=True, cancel_futures=True)
