"""The live trial and its replay: the same pipeline, the same numbers."""

import json

import pytest
from rerun.chunk import RrdReader

from ramdaq.daq.rerun_view import RerunView
from ramdaq.daq.session import RESULTS_TOPIC, Session
from ramdaq.drivers.mcap_replay import McapReplayDevice
from ramdaq.drivers.sim import SimDevice


@pytest.fixture(scope="module")
def live(tmp_path_factory, request):
    rig = request.getfixturevalue("albacore")
    tmp = tmp_path_factory.mktemp("trial")
    dev = SimDevice(rig, duration_s=8.0, impacts=[2.5, 5.0], seed=21)
    view = RerunView(dev.open(), rrd_path=tmp / "trial.rrd")
    with view:
        outcome = Session(dev, record_path=tmp / "trial.mcap", view=view, readout=False).run()
    return tmp, outcome


def test_live_trial_finds_and_analyses_every_hit(live):
    _, outcome = live
    assert [h.index for h in outcome.hits] == [0, 1]
    # the simulator's blows are at 2.5 and 5 s (the trigger arms after its 2 s LTA window)
    assert [round(h.event.onset_s, 2) for h in outcome.hits] == [2.5, 5.0]
    assert all(h.accepted for h in outcome.hits)
    # the ALBACORE-like rig's predominant mode in air (24.5 Hz, Table 2a)
    assert outcome.summary["f_hz"]["mean"] == pytest.approx(24.5, rel=0.02)


def test_replay_gives_identical_impacts_and_numbers(live):
    """Replay through the same session: identical to the last digit (JSON text compared)."""
    tmp, outcome = live
    replayed = Session(McapReplayDevice(tmp / "trial.mcap"), readout=False).run()
    assert json.dumps(replayed.results_json()) == json.dumps(outcome.results_json())


def test_results_and_detections_are_in_the_recording(live):
    tmp, outcome = live
    with McapReplayDevice(tmp / "trial.mcap") as dev:
        results = dev.json_messages(RESULTS_TOPIC)
        detections = dev.json_messages("/ramdaq/impacts")
    assert [m.obj["index"] for m in results] == [0, 1]
    assert len(detections) == 2
    assert results[0].obj["analysis"]["f_hz"] == outcome.hits[0].analysis.f_hz


def test_headless_trial_rrd_has_the_live_view(live):
    tmp, _ = live
    paths = {ch.entity_path for ch in RrdReader(tmp / "trial.rrd").store().stream()}
    expected = {"/gages", "/impacts/markers", "/results/g04/delta",
                "/results/g04/f_hz", "/layout/gages", "/impacts/0/traces",
                "/impacts/0/decay/g04/envelope"}
    missing = {p for p in expected if p not in paths and p.lstrip("/") not in paths}
    assert not missing, sorted(paths)[:40]
