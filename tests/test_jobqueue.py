"""The analyzer queue's bound and its policy: first looks skipped first, then coarse finals, then
finals left unanalysed -- every one counted in the summary and written as an event."""

import json
import tracemalloc
from collections import Counter
from pathlib import Path

import pytest

from ramdaq.daq.analyzer import FinalJob, LookJob, analyze_event, coarsen, decay_skip_s
from ramdaq.daq.jobqueue import JobQueue, QueuePolicy, job_bytes
from ramdaq.daq.session import SUMMARY_TOPIC, Session
from ramdaq.daq.trigger import Trigger
from ramdaq.drivers.mcap_replay import McapReplayDevice
from ramdaq.drivers.sim import SimDevice

WATER = Path(__file__).parent.parent / "recordings" / "albacore-water.mcap"


def _events(rig, fs_hz: float, impacts: list[float], duration_s: float):
    dev = SimDevice(rig, medium="water", seed=2, duration_s=duration_s, impacts=impacts,
                    fs_hz=fs_hz)
    info = dev.open()
    trig, events = Trigger(info), []
    for block in dev:
        events += trig.process(block)
    return info, events + trig.flush()


@pytest.fixture(scope="module")
def one_blow(albacore):
    """A real 16-gage record at 2048 Hz: a blow at 3 s, 6 s of its decay."""
    info, (ev,) = _events(albacore, 2048.0, [3.0], 9.0)
    return info, ev


def test_looks_go_first_then_finals_run_coarse_then_are_refused(albacore, one_blow):
    info, ev = one_blow
    skip = round(decay_skip_s(albacore.with_medium("water")) * info.fs_hz)
    look = LookJob(ev.onset_sample, ev.record.values()[:, :2048])
    whole = ev.record.counts.nbytes
    # room for the whole record and a coarse one (0.5 s of decay), not for the look beside them
    policy = QueuePolicy(max_finals=2, coarse_decay_s=0.5, max_bytes=whole + look.x.nbytes - 1)
    q = JobQueue(policy, info.fs_hz, skip)
    assert q.put_look(look)
    assert not q.put_look(look)  # one look at a time: a second is not queued
    first = q.put_final(FinalJob(0, ev), wait=False)
    assert first.looks_dropped == (ev.onset_sample,)  # the waiting look made room
    assert first.job.coarse is None  # nothing ahead of it: analysed whole
    second = q.put_final(FinalJob(1, ev), wait=False)
    assert second.looks_dropped == ()
    assert second.job.coarse is not None and "1 final(s) ahead" in second.job.coarse.why
    # cut on arrival to the onset's skip plus 0.5 s of decay: the long record is not held
    n = ev.onset_sample + skip + 1024 - ev.record.first_sample
    assert second.job.event.record.counts.shape[1] == n
    third = q.put_final(FinalJob(2, ev), wait=False)
    assert third.job is None and third.refused.startswith("not analysed: the analyzer queue "
                                                          "was at its bound (2 of 2 finals")
    assert q.peak_finals == 2
    assert q.peak_bytes == job_bytes(first.job) + job_bytes(second.job) <= policy.max_bytes
    assert q.get(FinalJob) is first.job
    q.done(FinalJob)
    assert q.pending == 1


def test_a_look_runs_beside_a_final(albacore, one_blow):
    """Two lanes: a final running does not hold up the next blow's first look."""
    info, ev = one_blow
    q = JobQueue(QueuePolicy(), info.fs_hz, round(decay_skip_s(albacore) * info.fs_hz))
    q.put_final(FinalJob(0, ev), wait=False)
    assert q.get(FinalJob).index == 0  # running
    look = LookJob(ev.onset_sample, ev.record.values()[:, :2048])
    assert q.put_look(look) and q.looks_pending == 1
    assert q.get(LookJob) is look


def test_a_look_past_its_bound_is_not_queued(albacore, one_blow):
    """A first look is the decay so far at the full rate; past ``max_look_bytes`` it is not
    queued, and the session can ask before copying the samples. The default bound holds a
    30 s decay of 16 gages at 2048 Hz (nothing changes there) but not at 25.6 kHz."""
    info, ev = one_blow
    look = LookJob(ev.onset_sample, ev.record.values()[:, :2048])
    q = JobQueue(QueuePolicy(max_look_bytes=look.x.nbytes - 1), info.fs_hz, 0)
    assert q.too_big_for_a_look(look.x.nbytes) and not q.put_look(look)
    assert q.looks_pending == 0
    default = JobQueue(QueuePolicy(), info.fs_hz, 0)
    assert not default.too_big_for_a_look(16 * 30 * 2048 * 8)
    assert default.too_big_for_a_look(16 * 30 * 25600 * 8)
    assert default.put_look(look)


def test_a_record_past_the_bytes_bound_runs_coarse_alone(albacore, one_blow):
    info, ev = one_blow
    whole = ev.record.counts.nbytes
    q = JobQueue(QueuePolicy(max_bytes=whole // 2, coarse_decay_s=1.0), info.fs_hz,
                 round(decay_skip_s(albacore) * info.fs_hz))
    adm = q.put_final(FinalJob(0, ev), wait=False)
    assert adm.job.coarse is not None and "bytes bound" in adm.job.coarse.why
    assert q.peak_bytes == job_bytes(adm.job) < whole // 2


@pytest.fixture(scope="module")
def fast_blow(albacore):
    """A real 16-gage record at 25.6 kHz: a blow at 3 s, 5 s of its decay."""
    info, (ev,) = _events(albacore, 25600.0, [3.0], 8.0)
    return info, ev


def test_a_live_final_at_25600_hz_runs_whole_at_the_design_rate(albacore, fast_blow):
    """Nothing ahead of it, yet a live 25.6 kHz final is decimated 12x with its whole decay.
    The decimation goes row by row from the counts, so it never holds the gages' full-rate
    decay in float64 (16 x 5 s x 25.6 kHz x 8 B = 16 MB): numpy's allocations, traced, peak
    below a quarter of that (one row is a sixteenth, the decimated output a twelfth). A source
    that can wait (replay) is analysed as recorded."""
    water = albacore.with_medium("water")
    info, ev = fast_blow
    skip = round(decay_skip_s(water) * info.fs_hz)
    job = JobQueue(QueuePolicy(), info.fs_hz, skip).put_final(FinalJob(0, ev), wait=False).job
    assert job.coarse is not None and job.event.record is ev.record  # nothing cut or copied
    rec, i0 = ev.record, ev.onset_sample + skip - ev.record.first_sample
    tracemalloc.start()
    try:
        y, fs, _ = coarsen(rec.counts[:16, i0:], info.fs_hz, job.coarse, rec.scale[:16])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    n = rec.counts.shape[1] - i0
    assert (fs, y.shape) == (info.fs_hz / 12, (16, -(-n // 12)))
    assert peak < 16 * n * 8 / 4
    hit = analyze_event(0, job.event, info, water, job.coarse)
    assert hit.accepted, hit.reason
    decay = f"{n / info.fs_hz:.2f} s"
    assert hit.coarse.startswith(f"coarse: {decay} of the {decay} decay, decimated 12x to "
                                 "2133.33 Hz (the stream's 25600 Hz is more than twice")
    replay = JobQueue(QueuePolicy(), info.fs_hz, skip).put_final(FinalJob(0, ev), wait=True).job
    assert replay.coarse is None


def test_a_coarse_final_at_25600_hz_keeps_the_mode(albacore, fast_blow):
    """12x decimation and 4 s of a 25.6 kHz decay: the same mode as the whole record at the
    design rate, within four of the two fits' combined standard errors (a 1-in-15 000 event
    for Gaussian errors), and said so in the result."""
    water = albacore.with_medium("water")
    info, ev = fast_blow
    q = JobQueue(QueuePolicy(), info.fs_hz, round(decay_skip_s(water) * info.fs_hz))
    q.put_final(FinalJob(0, ev), wait=False)  # something ahead: the next one runs coarse
    job = q.put_final(FinalJob(1, ev), wait=False).job
    coarse = analyze_event(1, job.event, info, water, job.coarse)
    assert coarse.accepted, coarse.reason
    assert coarse.coarse.startswith("coarse: 4.00 s of the") and "decimated 12x" in coarse.coarse
    info2, (ref_ev,) = _events(albacore, 2048.0, [3.0], 8.0)
    ref = analyze_event(0, ref_ev, info2, water)
    k, kr = coarse.analysis.predominant, ref.analysis.predominant
    se = (coarse.analysis.modes.frequency_se_hz[k] ** 2
          + ref.analysis.modes.frequency_se_hz[kr] ** 2) ** 0.5
    assert abs(coarse.analysis.f_hz - ref.analysis.f_hz) < 4 * se


def test_a_live_trial_with_a_slow_analyzer_sheds_work_and_counts_it(albacore, tmp_path):
    """Blows every 1.5 s, streamed as fast as the simulator goes (~40x real time) but treated
    as live (``shed=True``): a whole 16-gage final takes about a second of CPU, so the analyzer
    falls far behind for real. The queue never holds more than its bound, every blow is a hit,
    and the summary's counts are the recording's events."""
    impacts = [2.5 + 1.5 * k for k in range(9)]
    dev = SimDevice(albacore, medium="water", seed=4, duration_s=16.5, impacts=impacts)
    policy = QueuePolicy(max_finals=2, coarse_decay_s=0.5)
    out = Session(dev, record_path=tmp_path / "t.mcap", readout=False, queue_policy=policy,
                  shed=True).run()
    load = out.load
    assert len(out.hits) == len(impacts) and [h.index for h in out.hits] == list(range(9))
    assert load.peak_finals <= 2 and load.peak_bytes <= policy.max_bytes
    assert load.finals_coarse + load.finals_unanalysed > 0  # it did fall behind
    assert not out.hits[0].coarse  # the first final had nothing ahead of it
    coarse = {h.index for h in out.hits if h.coarse}
    unanalysed = {h.index for h in out.hits if h.reason.startswith("not analysed")}
    assert (len(coarse), len(unanalysed)) == (load.finals_coarse, load.finals_unanalysed)
    with McapReplayDevice(tmp_path / "t.mcap") as rec:
        kinds = Counter(e["kind"] for e in rec.events())
        coarse_events = {e["detail"]["index"] for e in rec.events() if e["kind"] == "final_coarse"}
        (summary,) = rec.json_messages(SUMMARY_TOPIC)
    assert kinds["final_coarse"] == load.finals_coarse and coarse_events == coarse
    assert kinds["final_unanalysed"] == load.finals_unanalysed
    assert kinds["look_skipped"] == load.looks_skipped
    assert summary.obj == json.loads(json.dumps(out.summary))
    assert summary.obj["analyzer"]["finals_coarse"] == load.finals_coarse


def test_a_source_that_can_wait_never_sheds(albacore):
    """The same blows from a device run flat out, not told to shed: it waits for the analyzer,
    so every final is whole, as in a replay."""
    dev = SimDevice(albacore, medium="water", seed=4, duration_s=8.0, impacts=[2.5, 4.0, 5.5])
    policy = QueuePolicy(max_finals=1)
    out = Session(dev, readout=False, queue_policy=policy).run()
    assert [h.coarse for h in out.hits] == ["", "", ""]
    assert out.load.finals_unanalysed == 0 and out.load.peak_finals == 1


def test_a_replay_flat_out_keeps_the_heap_between_finals_and_a_live_trial_trims_it(
        albacore, monkeypatch):
    """The heap's free pages go back to the OS after each final of a live trial (its RSS follows
    what it holds); a replay that runs its finals one after another on one thread keeps them for
    the next final (giving them back and faulting them in again was most of its system CPU)."""
    from ramdaq.daq import jobqueue

    trims = []
    monkeypatch.setattr(jobqueue, "release_free_memory", lambda: trims.append(1) or True)
    queue = JobQueue(QueuePolicy(), 2048.0, 0)
    assert queue.trim  # the default: a live trial's
    queue.done(FinalJob)  # no job running: only the trim
    queue.done(LookJob)  # never after a look
    queue.trim = False
    queue.done(FinalJob)
    assert trims == [1]
    trims.clear()
    replay = Session(McapReplayDevice(WATER, pace="fast"), readout=False)
    outcome = replay.run()
    assert replay.finals_inline and len(outcome.hits) == 3 and trims == []
    assert not Session(SimDevice(albacore, medium="water", duration_s=1.0), readout=False).finals_inline
