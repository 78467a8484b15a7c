"""What test_session_worker's finals workers run in place of ramdaq's own: module-level (a
worker imports them by name), in a module that imports little (each worker imports it)."""

import os

from ramdaq.daq.final_process import run_final


def die_on_hit_0(job):
    """In the worker: exit at once on hit 0 (a crash the worker cannot report), else run."""
    if job.index == 0:
        os._exit(3)
    return run_final(job)


def cannot_start(*args):
    """A worker's initializer that fails (a worker that never comes up)."""
    raise RuntimeError("no start")
