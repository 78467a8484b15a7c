"""A first look's latency: shown by the look thread the moment it is done, and a blow's first
look fitted at the order the previous blow's first sure look found."""

import threading

import numpy as np

from ramdaq.daq.analyzer import LookJob, run_job
from ramdaq.daq.session import Session, look_is_sure
from ramdaq.drivers.sim import SimDevice


def _two_blows(albacore) -> tuple[Session, list[LookJob]]:
    """Two blows 4 s apart on the ALBACORE-like rig in water; each look is run at once in this
    thread as the look thread would (:meth:`Session._run_one`), shown from there."""
    dev = SimDevice(albacore.with_medium("water"), duration_s=8.5, impacts=[3.0, 7.0], seed=4)
    session = Session(dev, readout=False)
    jobs = []

    def look_now(job):
        jobs.append(job)
        session._run_one(LookJob, job)
        return True

    session._jobs.put_look = look_now
    for block in dev:
        session._take(block, None)  # (no lock held: the look "thread" is this one)
    return session, jobs


def test_the_second_blows_first_looks_fit_the_order_the_first_blows_sure_look_found(albacore):
    """Blow 1's looks search the order; blow 2's first is given the number of modes blow 1's
    first sure look fitted, and the later ones search again. The fit of the order
    given is the searched fit's: on the same samples both reach the same least-squares
    optimum, so f and delta agree far inside their standard error (0.01 of it: the solver's
    convergence, not statistics)."""
    session, jobs = _two_blows(albacore)
    onsets = sorted({j.onset_sample for j in jobs})
    assert len(onsets) == 2
    first = [j for j in jobs if j.onset_sample == onsets[0]]
    second = [j for j in jobs if j.onset_sample == onsets[1]]
    assert all(j.n_modes is None for j in first)
    assert session._look_order is not None and session._look_order >= 1
    given = [j for j in second if j.n_modes is not None]
    assert given == [second[0]] and given[0].n_modes == session._look_order and len(second) > 1
    fs = session.info.fs_hz
    for job in given:
        a = run_job(job, session.info, session.rig, session._gages).look
        b = run_job(LookJob(job.onset_sample, job.x, job.pre), session.info, session.rig,
                    session._gages).look
        assert a is not None and b is not None and a.n_modes == job.n_modes, job.x.shape[1] / fs
        for n, (f, d, se) in b.gages.items():
            fa, da, _ = a.gages[n]
            if np.isfinite(se):
                assert abs(da - d) <= 0.01 * se and abs(fa - f) <= 1e-3 * abs(f), (n, fa, f, da, d)


def test_a_look_is_shown_by_the_look_thread_without_waiting_for_a_block(albacore):
    """A sure look done on the look thread is shown there at once: counted, and in ``shown``,
    before the stream's thread takes another block or drains the results."""
    session, job = _at_a_look_of_half_a_second(albacore)
    assert look_is_sure(run_job(job, session.info, session.rig, session._gages).look)
    t = threading.Thread(target=session._run_one, args=(LookJob, job))
    t.start()
    t.join(30)
    assert session.first_looks == 1 and [s.kind for s in session.shown] == ["look"]
    assert session._done.empty()


def test_a_look_done_while_a_block_is_taken_is_left_for_the_stream_thread(albacore):
    """While the stream's thread holds the session (taking a block), a done look does not wait
    for it: it is left in the results, which the stream's thread shows when it has the block."""
    session, job = _at_a_look_of_half_a_second(albacore)
    with session._lock:
        t = threading.Thread(target=session._run_one, args=(LookJob, job))
        t.start()
        t.join(30)  # the look's CPU, ~0.05 s
        assert not t.is_alive() and session.first_looks == 0 and not session._done.empty()
    session._drain(None)
    assert session.first_looks == 1


def _at_a_look_of_half_a_second(albacore) -> tuple[Session, LookJob]:
    """A session fed the simulator's blocks (one blow at 3 s, in water) up to the look it asks
    for with 0.5 s of decay (sure: the test above), and that look, not run: the session's
    looks are caught as they are asked for."""
    dev = SimDevice(albacore.with_medium("water"), duration_s=4.0, impacts=[3.0], seed=4)
    session = Session(dev, readout=False)
    jobs = []
    session._jobs.put_look = lambda job: jobs.append(job) or True
    blocks = iter(dev)
    while session.trigger.ringing is None or not jobs or jobs[-1].x.shape[1] < 0.5 * 2048:
        session._take(next(blocks), None)
    return session, jobs[-1]
