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


def test_a_replay_flat_out_takes_no_first_looks_unless_asked(live):
    """``ramdaq replay`` flat out has nobody to show a first look to before the final: it takes
    none (every hit still gets its final); asked (``looks=True``) it takes them as live."""
    tmp, outcome = live
    quiet = Session(McapReplayDevice(tmp / "trial.mcap"), readout=False)
    replayed = quiet.run()
    assert not quiet.looks and replayed.first_looks == 0 and quiet.skipped_updates == 0
    assert not [j for j in quiet.job_times if j.kind == "look"]
    assert [h.index for h in replayed.hits] == [0, 1]
    asked = Session(McapReplayDevice(tmp / "trial.mcap"), readout=False, looks=True)
    asked.run()
    assert [j for j in asked.job_times if j.kind == "look"]


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


@pytest.fixture(scope="module")
def floor_trial(tmp_path_factory, request):
    """Water, two 1 kN blows 8 s apart: the first decay (32 dB over the noise) reaches the
    noise floor about 7 s after its blow, before the second."""
    from ramdaq.drivers.sim import Impact

    rig = request.getfixturevalue("albacore").with_medium("water")
    ram = rig.impact
    blows = [Impact(t, 1000.0, ram.duration_s, ram.location_m, ram.direction) for t in (3.0, 11.0)]
    tmp = tmp_path_factory.mktemp("floor")
    dev = SimDevice(rig, duration_s=14.0, impacts=blows, seed=21)
    return tmp, Session(dev, record_path=tmp / "floor.mcap", readout=False).run()


def test_a_record_closes_at_the_noise_floor_and_replays_identically(floor_trial):
    """The first hit's record ends where its decay reached the noise floor, before the next
    blow (not at it); a replay ends it at the same sample and gives the same numbers."""
    tmp, outcome = floor_trial
    first, second = (h.event for h in outcome.hits)
    assert first.end_reason == "decayed" and first.last_sample < second.onset_sample
    assert first.decay_s == pytest.approx((first.last_sample - first.onset_sample) / first.fs_hz)
    assert all(h.accepted for h in outcome.hits)
    replayed = Session(McapReplayDevice(tmp / "floor.mcap"), readout=False).run()
    assert [h.event.to_json() for h in replayed.hits] == [h.event.to_json() for h in outcome.hits]
    assert json.dumps(replayed.results_json()) == json.dumps(outcome.results_json())


@pytest.mark.parametrize("trial", ["live", "floor_trial"])
def test_a_replay_of_joined_blocks_is_the_live_trial(trial, request):
    """``ramdaq replay`` flat out hands the recorded 50 ms blocks over joined into 1 s ones
    (``join_s``): the same events (records closed at the next blow, at the noise floor, at the
    end) and the same numbers, to the last digit."""
    tmp, outcome = request.getfixturevalue(trial)
    name = "trial.mcap" if trial == "live" else "floor.mcap"
    replayed = Session(McapReplayDevice(tmp / name, join_s=1.0), readout=False).run()
    assert [h.event.to_json() for h in replayed.hits] == [h.event.to_json() for h in outcome.hits]
    assert json.dumps(replayed.results_json()) == json.dumps(outcome.results_json())


def test_first_looks_are_tried_at_two_then_three_periods_of_the_predominant_mode(albacore):
    """The look schedule (no analyzer: each look is done at once and never sure): a blow's
    first look has two periods of the rig model's predominant mode (13.0 Hz in water, Table
    2a) of free decay, the next three, each on the first block (0.05 s) that ends at most a
    tenth of a period before it."""
    water = albacore.with_medium("water")
    dev = SimDevice(water, duration_s=4.0, impacts=[3.0], seed=4)
    session = Session(dev, readout=False)
    looks = []
    session._jobs.put_look = lambda job: looks.append(job) or True
    for block in dev:
        session._take(block, None)
    fs, period = dev.info.fs_hz, 1 / 13.0
    decay = [job.x.shape[1] / fs for job in looks]
    assert session._period_n == pytest.approx(period * fs, rel=0.01)
    assert len(decay) >= 2 and looks[0].onset_sample == pytest.approx(3.0 * fs, abs=2)
    block = dev.block_n / fs
    for got, periods in zip(decay, (2, 3), strict=False):
        assert (periods - 0.1) * period - 1 / fs <= got < periods * period + block + 1 / fs, got


def test_once_a_look_is_shown_the_next_comes_as_the_decay_grows_by_half(albacore):
    """After a blow's first sure look, each next look is asked for when the decay has grown by
    LOOK_GROWTH (0.5) of itself and by update_s (0.5 s) at least -- on the first block (0.05 s)
    that ends by then, less a tenth of a period -- not every update_s to the ringing's end.
    Looks run at once here, in the main thread (the look after the first sure one was asked for
    a period on, before that one was known to be sure)."""
    from ramdaq.daq.analyzer import run_job
    from ramdaq.daq.session import LOOK_EARLY, LOOK_GROWTH

    water = albacore.with_medium("water")
    dev = SimDevice(water, duration_s=12.0, impacts=[3.0], seed=4)
    session = Session(dev, readout=False)
    lengths, sure_at = [], []

    def look_now(job):
        shown = session.first_looks
        lengths.append(job.x.shape[1])
        session._done.put(run_job(job, session.info, session.rig, session._gages))
        session._drain(None)
        if session.first_looks > shown and not sure_at:
            sure_at.append(len(lengths) - 1)
        return True

    session._jobs.put_look = look_now
    for block in dev:
        session._take(block, None)
    fs = dev.info.fs_hz
    early, block_n = LOOK_EARLY * session._period_n, dev.block_n
    after = lengths[sure_at[0] + 1:]  # the look after it was asked for before it was known sure
    assert len(after) >= 4  # 0.4 s .. ~9 s of decay: about 0.9, 1.4, 2.1, 3.2, 4.7, 7.1 s
    for a, b in zip(after, after[1:], strict=False):
        due = a + max(session.update_n, round(LOOK_GROWTH * a))
        assert due - early - 1 <= b < due + block_n + 1, (a / fs, b / fs)


def test_a_look_is_shown_when_the_blow_was_first_seen_before_its_onset_was_refined(albacore):
    """Blocks of 10 samples: the trigger sees a blow a block before it has the look-ahead to
    refine its onset (the session first sees the detection sample); the looks, taken later,
    carry the refined onset and must still be shown as this blow's (they were dropped as a
    previous blow's). Looks run at once here, in the main thread."""
    from ramdaq.daq.analyzer import run_job

    water = albacore.with_medium("water")
    dev = SimDevice(water, duration_s=3.6, impacts=[3.0], seed=4, block_s=10 / 2048)
    session = Session(dev, readout=False)
    first_seen = []

    def look_now(job):
        first_seen.append(session._ringing_onset)
        session._done.put(run_job(job, session.info, session.rig, session._gages))
        return True

    session._jobs.put_look = look_now
    for block in dev:
        if session.trigger.ringing and not first_seen:
            first_seen.append(session.trigger.ringing[0])
        session._take(block, None)
    assert first_seen[0] != first_seen[1]  # the detection sample, then the refined onset
    assert session.first_looks >= 1
    assert {s.onset_s for s in session.shown} == {first_seen[1] / dev.info.fs_hz}


def test_a_hits_headline_gives_its_mode_errors_and_damping_ratio(live):
    """The analyst's line at each accepted hit: which mode, f and delta with their standard
    errors from the joint fit, zeta in %, Eq 7's modal decrement and the v motion's."""
    from ramdaq.daq.readout import accepted_line

    _, outcome = live
    hit = outcome.hits[0]
    a = hit.analysis
    k = a.predominant
    line = accepted_line(hit.index, hit.event.onset_s, a)
    assert line.startswith(f"hit 0 at 2.500 s accepted: mode {k}, f = {a.f_hz:.3f} Hz (se ")
    assert f"zeta {100 * a.modes.zeta[k]:.2f} %" in line
    assert f"delta_modal (Eq 7) = {a.damping['delta_modal']:.4f}" in line
    assert f"delta_v (motion v) = {a.motions['v_2_6'].delta:.4f} (se " in line


def test_a_hits_record_says_why_it_closed(live):
    """tester10: every hit read "decay ended" though the next blow had cut its record. The blows
    2.5 s apart in air (24.5 Hz, delta 0.058: ~14 s to the floor) cut hit 0's record at the next
    blow; the stream's end closes the last one."""
    from ramdaq.daq.session import record_end

    _, outcome = live
    first, last = outcome.hits[0].event, outcome.hits[-1].event
    assert first.end_reason == "next_impact"
    assert record_end(first).startswith("record cut by the next blow after 2.")
    assert last.end_reason == "flush" and record_end(last).startswith("stream ended ")
