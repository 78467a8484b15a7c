"""A blow's next first look waits behind a running one until a look of the blow is sure."""

import numpy as np
import pytest

from ramdaq.daq.analyzer import LookJob
from ramdaq.daq.jobqueue import JobQueue, QueuePolicy
from ramdaq.daq.session import Session
from ramdaq.drivers.sim import SimDevice


def test_a_look_may_wait_behind_a_running_one_but_not_behind_a_waiting_one():
    q = JobQueue(QueuePolicy(), 2048.0, 0)
    looks = [LookJob(0, np.zeros((2, 8))) for _ in range(3)]
    assert q.put_look(looks[0]) and q.get(LookJob) is looks[0]  # running
    assert q.put_look(looks[1]) and q.looks_waiting == 1 and q.looks_pending == 2
    assert not q.put_look(looks[2])  # one waits already


def test_the_next_look_of_a_blow_not_yet_sure_is_queued_while_the_first_runs(albacore):
    """The first look (two periods of 13 Hz in water) is taken by the look thread and runs on
    (it never ends here); the look due at three periods is queued behind it on the first block
    that ends by then, not skipped until a block after the first is done; nothing more is
    queued while that one waits."""
    dev = SimDevice(albacore.with_medium("water"), duration_s=4.0, impacts=[3.0], seed=4)
    session = Session(dev, readout=False)
    q, queued = session._jobs, []
    put = q.put_look

    def put_and_run_the_first(job):
        ok = put(job)
        if ok:
            queued.append(job)
            if len(queued) == 1:
                assert q.get(LookJob) is job  # the look thread takes it and is busy with it
        return ok

    q.put_look = put_and_run_the_first
    for block in dev:
        session._take(block, None)
    fs, period = dev.info.fs_hz, 1 / 13.0
    block = dev.block_n / fs
    assert [j.onset_sample for j in queued] == [queued[0].onset_sample] * 2
    for job, periods in zip(queued, (2, 3), strict=True):
        got = job.x.shape[1] / fs
        assert (periods - 0.1) * period - 1 / fs <= got < periods * period + block + 1 / fs, got
    assert q.looks_waiting == 1 and q.looks_pending == 2
    assert session.skipped_updates == 0
    assert pytest.approx(session._period_n, rel=0.01) == period * fs
