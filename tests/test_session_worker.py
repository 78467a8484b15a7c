"""A live trial's finals in a worker process: the same numbers as a replay on one thread, and a
worker that dies is an event and a rejected hit, not the end of the trial."""

import json

import pytest

from ramdaq.daq.session import Session
from ramdaq.drivers.mcap_replay import McapReplayDevice
from ramdaq.drivers.sim import SimDevice

from .worker_helpers import cannot_start, die_on_hit_0


@pytest.fixture(scope="module")
def worker_trial(tmp_path_factory, request):
    rig = request.getfixturevalue("albacore")
    tmp = tmp_path_factory.mktemp("worker")
    dev = SimDevice(rig, duration_s=7.0, impacts=[2.5, 4.8], seed=21)
    session = Session(dev, record_path=tmp / "trial.mcap", readout=False, final_process=True)
    return tmp, session, session.run()


def test_finals_in_a_worker_process_are_the_replays_to_the_last_digit(worker_trial):
    tmp, session, outcome = worker_trial
    assert session._final_process is not None and session._final_process.deaths == 0
    assert [h.index for h in outcome.hits] == [0, 1] and all(h.accepted for h in outcome.hits)
    replay = Session(McapReplayDevice(tmp / "trial.mcap"), readout=False)
    # a replay flat out runs its finals on the stream's own thread
    assert replay._final_process_wanted is False and replay.finals_inline
    assert json.dumps(replay.run().results_json()) == json.dumps(outcome.results_json())
    # the worker's own CPU is what the job times hold (a thread waiting on a pipe spends ~none)
    assert all(j.cpu_s > 0.05 for j in session.job_times if j.kind == "final")


def test_a_worker_that_dies_is_an_event_and_the_trial_goes_on(albacore, tmp_path):
    dev = SimDevice(albacore, duration_s=7.0, impacts=[2.5, 4.8], seed=21)
    session = Session(dev, record_path=tmp_path / "t.mcap", readout=False, final_process=True)
    session._final_process_wanted = False  # started below, with the target that dies
    from ramdaq.daq.final_process import FinalProcess

    session._final_process = FinalProcess(session.info, session.rig, session._gages,
                                          target=die_on_hit_0)
    outcome = session.run()
    first, second = outcome.hits
    assert not first.accepted and "worker process died" in first.reason
    assert second.accepted  # a new worker took the next final
    assert session._final_process.deaths == 1
    with McapReplayDevice(tmp_path / "t.mcap") as rec:
        died = [e for e in rec.events() if e["kind"] == "analysis_worker_died"]
    assert [e["detail"]["index"] for e in died] == [0]


def test_a_worker_that_cannot_start_leaves_the_finals_on_the_thread(albacore, monkeypatch):
    from ramdaq.daq import session as session_module

    def cannot(*args, **kwargs):
        raise OSError("Resource temporarily unavailable")

    monkeypatch.setattr(session_module, "FinalProcess", cannot)
    dev = SimDevice(albacore, duration_s=4.5, impacts=[2.5], seed=21)
    session = Session(dev, readout=False, final_process=True)
    outcome = session.run()
    assert session._final_process is None and [h.accepted for h in outcome.hits] == [True]
    assert outcome.notes == ["no finals worker process: Resource temporarily unavailable"]


def test_a_worker_that_never_comes_up_leaves_the_finals_on_the_thread(albacore, tmp_path):
    """Nothing ran in the worker: the final in hand and the next run on the analyzer thread,
    said in the notes and as an event; every hit analysed."""
    from ramdaq.daq.final_process import FinalProcess

    class NeverUp(FinalProcess):
        initializer = staticmethod(cannot_start)

    dev = SimDevice(albacore, duration_s=7.0, impacts=[2.5, 4.8], seed=21)
    session = Session(dev, record_path=tmp_path / "t.mcap", readout=False, final_process=True)
    session._final_process_wanted = False
    session._final_process = NeverUp(session.info, session.rig, session._gages)
    outcome = session.run()
    assert [h.accepted for h in outcome.hits] == [True, True]
    assert session._final_process is None
    assert len(outcome.notes) == 1 and "did not start" in outcome.notes[0]
    with McapReplayDevice(tmp_path / "t.mcap") as rec:
        kinds = [e["kind"] for e in rec.events()]
    assert kinds.count("analysis_worker_unavailable") == 1
