"""A live trial's final analyses in a worker process of their own.

A final (:class:`~ramdaq.daq.analyzer.FinalJob`) is ~0.4 s of pure-Python-heavy CPU. Run on
a thread of the acquisition's process it shares one interpreter lock with the acquisition and
the first looks, so on a live trial its wall time grew past its CPU time. Here it runs in one
worker process, started with the session, so the final and the acquisition run on two cores.

The worker is a fresh interpreter running this module (``python -m
ramdaq.daq.final_process``) that talks pickles over two pipes; it imports ramdaq and nothing of
the caller's (``multiprocessing``'s ``spawn`` re-runs the calling script in the child, which,
in a script without a ``__main__`` guard, opened the device again; ``fork`` would copy the
session's threads half-held). It is given the stream's info, the rig and the gage numbers
once; each job sends its record (a few MB of int32 counts: ~1 ms to pickle), and the result
comes back without the record (the session puts its own back). :func:`run_final` runs
:func:`~ramdaq.daq.analyzer.run_job`, the function the in-process lane runs, so the numbers are
the same to the last digit.

The worker ignores Ctrl-C (the terminal sends it to the whole process group; the session
ends the stream and then waits for the finals queued, as without a worker). A worker that
never came up raises :class:`WorkerUnavailable`: the session then runs the finals on its
thread, as without a worker, and says so. A worker that dies (killed, out of memory, a crash in
a C extension) raises :class:`WorkerDied` for the job it was running; a new worker is started
for the next job, and the session records the death as an event and rejects that hit with the
reason -- the trial goes on.
"""

from __future__ import annotations

import dataclasses
import os
import pickle
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from typing import BinaryIO

import numpy as np

from ..analysis.model.rig import Rig
from ..drivers.block import StreamInfo
from .analyzer import FinalDone, FinalJob, run_job

_STATE: tuple[StreamInfo, Rig, tuple[int, ...]] | None = None
"""In the worker: what every job is analysed against (set once by :func:`_start`)."""
_READY = "ready"
"""What a worker sends once it has started (its imports done, its initializer run)."""
_PICKLE = pickle.HIGHEST_PROTOCOL


class WorkerDied(RuntimeError):
    """The worker process died while it ran a final (its exit code in the message)."""


class WorkerUnavailable(RuntimeError):
    """The worker process never came up (its interpreter, its imports or its initializer
    failed): no job ever ran in it, so the job in hand may run on the calling thread instead."""


def _start(info: StreamInfo, rig: Rig, gages: tuple[int, ...]) -> None:
    """The worker's initializer: keep what every job needs, and warm up (:func:`_warm`)."""
    global _STATE
    _STATE = (info, rig, gages)
    _warm(info, rig, gages)


def _warm(info: StreamInfo, rig: Rig, gages: tuple[int, ...]) -> None:
    """One small analysis (a 2 s, 20 Hz free decay with noise on every gage, through the
    report's chain) before the first job, so that what a fresh interpreter pays on its first
    analysis (scipy's lazily loaded submodules, the LAPACK wrappers' first calls, the cached
    windows and filter designs) is paid here, at the session's start, not by the first blow's
    final. The estimators keep no state
    between calls (:mod:`ramdaq.analysis.modal.identify`, "Threads"), so no later number
    changes; a warm-up that fails leaves the worker as it was."""
    from ..analysis.impact import analyze_decay
    from ..analysis.modal.signal import damped_sinusoids

    fs, n = info.fs_hz, int(2 * info.fs_hz)
    rng = np.random.default_rng(0)
    # each gage its own amplitude: gages all alike are a pure translation, whose rotations the
    # report's chain cannot resolve (it stops there, and would leave the chain unwarmed)
    x = damped_sinusoids(fs, n, [20.0], [0.06], rng.uniform(0.5, 1.5, (len(gages), 1)))
    x += 1e-3 * rng.standard_normal(x.shape)
    try:
        analyze_decay(x, fs, rig, gages)
    except Exception:  # noqa: BLE001 -- only a warm-up: the jobs say what fails in them
        pass


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

    ``target`` is what the worker runs per job (:func:`run_final`) and :attr:`initializer`
    what it runs first, given (info, rig, gages); both module-level functions, which the worker
    imports by name (with the caller's ``sys.path``).
    """

    initializer: Callable[..., None] = staticmethod(_start)

    def __init__(self, info: StreamInfo, rig: Rig, gages: tuple[int, ...],
                 target: Callable[[FinalJob], tuple[FinalDone, float]] = run_final) -> None:
        self._args = (info, rig, gages)
        self.target = target
        self.deaths = 0
        self._came_up = False  # a worker has said it is ready
        self._proc: subprocess.Popen | None = None
        self._tx: BinaryIO | None = None
        self._rx: BinaryIO | None = None
        self._ready = False
        self._launch()

    def _launch(self) -> None:
        """Start a worker and send it what it needs; it answers :data:`_READY` when set up."""
        to_child_r, to_child_w = os.pipe()
        from_child_r, from_child_w = os.pipe()
        try:
            self._proc = subprocess.Popen(
                [sys.executable, "-m", __name__, str(to_child_r), str(from_child_w)],
                pass_fds=(to_child_r, from_child_w), stdin=subprocess.DEVNULL)
        finally:
            os.close(to_child_r)
            os.close(from_child_w)
        self._tx, self._rx = os.fdopen(to_child_w, "wb"), os.fdopen(from_child_r, "rb")
        self._ready = False
        try:
            pickle.dump(list(sys.path), self._tx, _PICKLE)
            pickle.dump((self.initializer, self.target, self._args), self._tx, _PICKLE)
            self._tx.flush()
        except OSError:  # it died at once: found by the first job
            pass

    def run(self, job: FinalJob) -> tuple[FinalDone, float]:
        """``job``'s result (with the session's own event, record and all) and the worker's
        CPU seconds for it; :class:`WorkerUnavailable` if the worker never came up,
        :class:`WorkerDied` if it died meanwhile (a new one is started for the next job)."""
        try:
            if not self._ready:
                if pickle.load(self._rx) != _READY:
                    raise EOFError("the worker's first answer was not 'ready'")
                self._ready = self._came_up = True
            pickle.dump(job, self._tx, _PICKLE)
            self._tx.flush()
            done, cpu_s = pickle.load(self._rx)
        except (EOFError, OSError, pickle.UnpicklingError) as err:
            code = self._end()
            if not self._came_up:
                raise WorkerUnavailable(f"the finals' worker process did not start (exit code "
                                        f"{code})") from err
            self.deaths += 1
            self._launch()
            raise WorkerDied(f"the finals' worker process died while it analysed hit "
                             f"{job.index} (exit code {code})") from err
        return FinalDone(dataclasses.replace(done.hit, event=job.event), done.doc), cpu_s

    def _end(self, timeout_s: float = 5.0) -> int | None:
        """Close the pipes and wait for the worker to exit (killed after ``timeout_s``); its
        exit code."""
        for f in (self._tx, self._rx):
            try:
                if f is not None:
                    f.close()
            except OSError:
                pass
        self._tx = self._rx = None
        if self._proc is None:
            return None
        try:
            return self._proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            return self._proc.wait()

    def close(self) -> None:
        """Stop the worker (it exits when its pipe closes, after the job it is running)."""
        self._end(timeout_s=60.0)


def _serve(rx: BinaryIO, tx: BinaryIO) -> int:
    """The worker's loop: set up, say ready, then one job in, one result out, until the pipe
    closes (a session gone before the worker was ready, or before its result, included)."""
    try:
        return _loop(rx, tx)
    except (BrokenPipeError, EOFError):
        return 0


def _loop(rx: BinaryIO, tx: BinaryIO) -> int:
    sys.path[:0] = [p for p in pickle.load(rx) if p not in sys.path]
    initializer, target, args = pickle.load(rx)
    initializer(*args)
    pickle.dump(_READY, tx, _PICKLE)
    tx.flush()
    while True:
        try:
            job = pickle.load(rx)
        except EOFError:
            return 0
        pickle.dump(target(job), tx, _PICKLE)
        tx.flush()


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the session's to handle
    _rx, _tx = os.fdopen(int(sys.argv[1]), "rb"), os.fdopen(int(sys.argv[2]), "wb")
    code = _serve(_rx, _tx)
    for _f in (_rx, _tx):
        try:
            _f.close()
        except BrokenPipeError:  # the session closed its end first: nothing left to say
            pass
    sys.exit(code)
