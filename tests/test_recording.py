"""Recorder -> MCAP file -> replay device, recover and info, on real files in tmp_path.

Samples are compared bit for bit (``Block.same_as``): the format stores integer counts and float64
scales, so there is nothing to tolerate.
"""

import dataclasses
import json
import os
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from ramdaq.daq.commands.info import describe_recording, format_info
from ramdaq.daq.errors import NotARamdaqRecording, RecordingError, TruncatedRecording
from ramdaq.daq.recorder import Recorder
from ramdaq.daq.recover import recover
from ramdaq.drivers.block import Block
from ramdaq.drivers.errors import DeviceNotFound, DeviceTimeout
from ramdaq.drivers.mcap_replay import McapReplayDevice
from ramdaq.drivers.registry import open_device
from tests.conftest import RIGS
from tests.recording_helpers import BLOCK_SAMPLES, FS_HZ, block, stream, stream_info

pytestmark = pytest.mark.timeout(60)


def _record(path, blocks, info=None, **kw):
    with Recorder(path, info or stream_info(), **kw) as rec:
        for b in blocks:
            assert rec.put(b)
    return rec


def _replay(path, **kw):
    with McapReplayDevice(path, **kw) as dev:
        return dev.info, list(dev), dev.events()


def test_round_trip_is_bit_identical_and_keeps_the_gap(tmp_path):
    """Blocks with the int32 extremes come back identical, and a gap comes back as a gap."""
    path = tmp_path / "trial.mcap"
    blocks = stream(30, seed=1, gap_after=19, gap_blocks=2)
    rec = _record(path, blocks)
    assert rec.stats.gaps == 1 and rec.stats.blocks == 30 and rec.overflows == 0

    info, back, events = _replay(path)
    assert info == stream_info()  # device, fs, channels, units, gages, rig_toml, extra
    assert len(back) == len(blocks) and all(a.same_as(b) for a, b in zip(back, blocks, strict=True))
    assert back[20].seq - back[19].seq == 3
    assert back[20].first_sample - back[19].next_sample == 2 * BLOCK_SAMPLES
    assert [e["kind"] for e in events] == ["gap"]
    assert events[0]["detail"] == {
        "after_seq": 19, "seq": 22, "missing_blocks": 2, "expected_sample": 20 * BLOCK_SAMPLES,
        "first_sample": 22 * BLOCK_SAMPLES, "missing_samples": 2 * BLOCK_SAMPLES,
    }
    assert events[0]["t_ns"] == blocks[20].t0_ns

    d = describe_recording(path)
    assert d.gaps == [(19, 2, 2 * BLOCK_SAMPLES)] and d.events == {"gap": 1}
    assert d.blocks == 30 and d.n_samples == 30 * BLOCK_SAMPLES and d.complete
    assert d.duration_s == 30 * BLOCK_SAMPLES / FS_HZ
    assert d.span_s == 32 * BLOCK_SAMPLES / FS_HZ
    text = format_info(d)
    assert "after seq 19: 2 block(s)" in text and "device" in text
    json.dumps(dataclasses.asdict(d))  # the CLI prints it as JSON


def test_info_names_the_carried_rig_and_medium():
    """``ramdaq info`` says which rig a recording carries and in which medium it was taken
    (the new user had to run analyze to learn it), in the words analyze's summary uses."""
    for name, rig in (("albacore-water", "albacore-like (rudder) in water"),
                      ("albacore-air", "albacore-like (rudder) in air")):
        d = describe_recording(RIGS.parent / f"{name}.mcap")
        assert d.rig == rig and f"rig        {rig}" in format_info(d)


def test_joined_blocks_are_the_same_samples_and_stop_at_a_gap(tmp_path):
    """``join_s`` (``ramdaq replay`` flat out): consecutive blocks come as one of at most
    ``join_s`` seconds, the same samples in order, never across a gap or a change of scale;
    only with ``pace="fast"``."""
    path = tmp_path / "trial.mcap"
    blocks = stream(30, seed=1, gap_after=19, gap_blocks=2)  # each with its own random scale
    blocks = [dataclasses.replace(b, scale=blocks[0].scale * (2 if k == 25 else 1))
              for k, b in enumerate(blocks)]
    _record(path, blocks)
    join_n = 4 * BLOCK_SAMPLES
    _, back, _ = _replay(path, join_s=join_n / FS_HZ)
    assert all(b.n_samples <= join_n for b in back) and len(back) < len(blocks)
    # no block across the gap (after seq 19) or the new scale (seq 25, and 26 after it)
    starts = {b.first_sample for b in back}
    assert {blocks[k].first_sample for k in (0, 20, 25, 26)} <= starts
    for b in back:  # each joined block is the recorded ones it starts with, side by side
        k = next(k for k, r in enumerate(blocks) if r.first_sample == b.first_sample)
        m = b.n_samples // BLOCK_SAMPLES
        assert b.seq == blocks[k].seq and b.t0_ns == blocks[k].t0_ns
        assert np.array_equal(b.counts, np.hstack([r.counts for r in blocks[k:k + m]]))
        assert all(np.array_equal(r.scale, b.scale) for r in blocks[k:k + m])
    assert sum(b.n_samples for b in back) == sum(b.n_samples for b in blocks)
    with pytest.raises(ValueError, match="join_s"):
        McapReplayDevice(path, pace="realtime", join_s=1.0)


def test_joining_asks_np_array_equal_of_the_scales_not_their_bytes(tmp_path):
    """Joined or not as ``np.array_equal`` of the scales says, not as their bytes: a scale
    that differs from the first block's only in the sign of a zero is equal (joined, the first
    block's scale kept); a doubled one is not. (A NaN scale cannot be recorded: its
    scale-change event is not JSON.)"""
    path = tmp_path / "trial.mcap"
    base = stream(12, seed=2)
    zero, neg = base[0].scale.copy(), base[0].scale.copy()
    zero[0], neg[0] = 0.0, -0.0
    scales = [zero] * 3 + [neg] * 3 + [2 * zero] * 3 + [zero] * 3
    _record(path, [dataclasses.replace(b, scale=s) for b, s in zip(base, scales, strict=True)])
    _, back, _ = _replay(path, join_s=12 * BLOCK_SAMPLES / FS_HZ)
    assert [b.n_samples // BLOCK_SAMPLES for b in back] == [6, 3, 3]
    assert not np.signbit(back[0].scale[0])  # the first block's 0.0, not the -0.0


@pytest.mark.parametrize("compression", ["lz4", "none"])
def test_every_compression_replays_the_same_blocks(tmp_path, compression):
    """The replay's own chunk reader (zstd, none) and mcap's (lz4) give the blocks recorded,
    and a flipped byte in an uncompressed chunk's records fails its CRC as in a zstd one."""
    blocks = stream(12, seed=3)
    path = tmp_path / f"{compression}.mcap"
    _record(path, blocks, compression=compression)
    _, back, _ = _replay(path)
    assert len(back) == len(blocks) and all(a.same_as(b) for a, b in zip(back, blocks, strict=True))
    if compression != "none":
        return
    with open(path, "rb") as f:
        chunk = make_reader(f).get_summary().chunk_indexes[0]
    raw = bytearray(path.read_bytes())
    raw[chunk.chunk_start_offset + chunk.chunk_length - 5] ^= 0x01  # in its last record
    path.write_bytes(bytes(raw))
    with pytest.raises(RecordingError, match=r"damaged chunk at byte \d+ \(CRCValidationError: "
                                             r"crc validation failed in Chunk"):
        _replay(path)


def test_readable_with_only_mcap_and_mcap_protobuf(tmp_path):
    """Another program needs nothing from ramdaq: mcap + mcap_protobuf's DecoderFactory."""
    path = tmp_path / "trial.mcap"
    blocks = stream(12, seed=2)
    with Recorder(path, stream_info()) as rec:
        for b in blocks:
            rec.put(b)
        rec.event("note", blocks[3].t0_ns, message="hello")

    # -- from here on, no ramdaq code --
    from mcap_protobuf.decoder import DecoderFactory

    got = []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, msg in reader.iter_decoded_messages(topics=["/ramdaq/block"]):
            assert (schema.name, schema.encoding, channel.message_encoding) == (
                "ramdaq.Block", "protobuf", "protobuf")
            counts = np.array(msg.counts, dtype=np.int64).reshape(msg.n_channels, msg.n_samples)
            got.append((msg.seq, msg.first_sample, message.publish_time, message.sequence, counts,
                        np.array(msg.scale)))
    with open(path, "rb") as f:
        notes = [json.loads(m.data) for _, _, m in make_reader(f).iter_messages(topics=["/ramdaq/events"])]
    # -- end --

    assert len(got) == len(blocks)
    for (seq, first, publish_time, sequence, counts, scale), b in zip(got, blocks, strict=True):
        # publish_time is device time; log_time is UTC (tests/test_topics.py)
        assert (seq, first, publish_time, sequence) == (b.seq, b.first_sample, b.t0_ns, b.seq)
        assert np.array_equal(counts, b.counts) and np.array_equal(scale, b.scale)
    assert notes == [{"kind": "note", "t_ns": blocks[3].t0_ns, "detail": {"message": "hello"}}]


def test_chunks_hold_at_most_chunk_seconds(tmp_path):
    """A kill loses at most the open chunk: each chunk spans < 0.25 s of block start times
    (5 blocks of 50 ms: the recorder finishes a chunk as soon as 0.25 s of samples are in it).
    The live view's topics are in chunks of their own, each right after the blocks' chunk of
    the same time (a replay steps over them unread)."""
    path = tmp_path / "trial.mcap"
    _record(path, stream(40, seed=3, full_range=False), chunk_seconds=0.25)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    topic = {i: ch.topic for i, ch in summary.channels.items()}
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    spans = [(c.message_end_time - c.message_start_time) / 1e9 for c in chunks]
    held = [sorted(topic[i] for i in c.message_index_offsets) for c in chunks]
    assert len(chunks) == 16 and max(spans) < 0.25
    assert held == [["/ramdaq/block"], ["/ramdaq/gages", "/ramdaq/gages/trace"]] * 8
    pairs = zip(chunks[::2], chunks[1::2], strict=True)
    assert all(v.message_start_time == b.message_start_time for b, v in pairs)


def test_overflow_drops_counts_and_logs(tmp_path):
    """queue_blocks=2 and a burst: each put takes microseconds while the writer needs ~10 ms per
    1.6 M-sample block, so most of the burst cannot enter the queue. Which blocks are dropped
    depends on timing; that every drop is counted and logged does not."""
    path = tmp_path / "overflow.mcap"
    big = block(0, seed=4, n_samples=100_000)
    blocks = [Block(seq=k, first_sample=k * 100_000, t0_ns=k, fs_hz=FS_HZ, counts=big.counts,
                    scale=big.scale) for k in range(12)]
    with Recorder(path, stream_info(), queue_blocks=2) as rec:
        accepted = [rec.put(b) for b in blocks]
    dropped = [b.seq for b, ok in zip(blocks, accepted, strict=True) if not ok]
    assert len(dropped) >= 6
    assert rec.overflows == rec.stats.overflows == len(dropped)
    assert rec.stats.dropped_samples == 100_000 * len(dropped)
    with pytest.raises(RecordingError, match="recorder is closed"):
        rec.put(blocks[0])

    info, back, events = _replay(path)
    assert [b.seq for b in back] == [b.seq for b, ok in zip(blocks, accepted, strict=True) if ok]
    assert all(a.same_as(blocks[a.seq]) for a in back)
    overflows = [e["detail"] for e in events if e["kind"] == "overflow"]
    logged = [s for d in overflows for s in range(d["first_seq"], d["last_seq"] + 1)]
    assert sorted(logged) == dropped
    assert all(d["samples"] == 100_000 * d["blocks"] and d["queue_blocks"] == 2 for d in overflows)
    assert describe_recording(path).overflows == len(dropped)


def test_bad_blocks_are_refused_by_put(tmp_path):
    b = block(0)
    with Recorder(tmp_path / "bad.mcap", stream_info()) as rec:
        with pytest.raises(ValueError, match="bad.mcap: block seq 0 has 3 channels, the stream has 16"):
            rec.put(block(0, n_channels=3))
        with pytest.raises(ValueError, match="t0_ns fit in int64"):
            rec.put(Block(seq=0, first_sample=0, t0_ns=2**63, fs_hz=FS_HZ, counts=b.counts, scale=b.scale))
        assert rec.put(b)  # the recorder carries on


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_disk_full_is_not_hidden(tmp_path):
    """The file's descriptor is pointed at /dev/full (every write: ENOSPC), as if the disk
    filled mid-recording: put() then close() raise a one-line RecordingError naming the file."""
    path = tmp_path / "full.mcap"
    rec = Recorder(path, stream_info())
    full = os.open("/dev/full", os.O_WRONLY)
    os.dup2(full, rec._file._raw.fileno())  # fault injection at the OS level, not a mock
    os.close(full)
    deadline = time.monotonic() + 10
    with pytest.raises(RecordingError, match=r"full\.mcap: writer thread failed \(OSError: .*No space"):
        for k in range(10_000):  # the first chunk is written after 0.25 s of samples
            rec.put(block(k))
            time.sleep(0.002)
            assert time.monotonic() < deadline
    with pytest.raises(RecordingError, match=r"full\.mcap: recording failed") as err:
        rec.close()
    assert "\n" not in str(err.value)
    rec.close()  # closing twice is safe


def test_replay_streams_rather_than_loading_the_file(tmp_path):
    """The first block is returned after reading little more than the first chunk."""
    path = tmp_path / "long.mcap"
    _record(path, stream(60, seed=10))
    with McapReplayDevice(path) as dev:
        dev.read()
        assert dev._file.tell() < path.stat().st_size / 4


def test_file_is_finished_when_the_body_raises(tmp_path):
    path = tmp_path / "crash.mcap"
    blocks = stream(5, seed=5)
    with pytest.raises(RuntimeError, match="boom"), Recorder(path, stream_info()) as rec:
        for b in blocks:
            rec.put(b)
        raise RuntimeError("boom")
    _, back, events = _replay(path)  # has its footer, so it opens
    assert len(back) == 5
    assert events[-1]["kind"] == "note" and "RuntimeError: boom" in events[-1]["detail"]["message"]


def test_existing_file_is_not_overwritten(tmp_path):
    path = tmp_path / "trial.mcap"
    path.write_bytes(b"precious")
    with pytest.raises(FileExistsError):
        Recorder(path, stream_info())
    assert path.read_bytes() == b"precious"


def test_truncated_file_gives_one_line_error_suggesting_recover(tmp_path):
    path = tmp_path / "killed.mcap"
    _record(path, stream(20, seed=6))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(TruncatedRecording, match=r"no footer.*ramdaq recover .*killed\.mcap") as err:
        open_device(str(path))
    assert "\n" not in str(err.value)


def test_a_stub_cut_before_its_stream_metadata_is_not_sent_to_recover(tmp_path):
    """A file cut inside its header (the new user's 100-byte stub) has nothing ``ramdaq
    recover`` can salvage; replay must say it is not a recording, not send the user there."""
    path = tmp_path / "stub.mcap"
    _record(path, stream(20, seed=6))
    path.write_bytes(path.read_bytes()[:30])
    with pytest.raises(NotARamdaqRecording, match=r"stub\.mcap: not a ramdaq recording \(no footer"):
        open_device(str(path))


def test_replay_refuses_mcap_that_is_not_ramdaq(tmp_path):
    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        ch = w.register_channel("/other", "json", w.register_schema("x", "jsonschema", b"{}"))
        w.add_message(ch, log_time=1, data=b"{}", publish_time=1)
        w.finish()
    with pytest.raises(NotARamdaqRecording, match="other.mcap: not a ramdaq recording") as err:
        open_device(str(path))
    assert "\n" not in str(err.value)
    with pytest.raises(NotARamdaqRecording, match="other.mcap: not a ramdaq recording"):
        describe_recording(path)
    with pytest.raises(DeviceNotFound, match="missing.mcap: No such file or directory"):
        open_device(str(tmp_path / "missing.mcap"))


def test_recover_refuses_a_file_that_is_not_mcap(tmp_path):
    src, dst = tmp_path / "notes.txt", tmp_path / "out.mcap"
    src.write_text("rudder trial notes\n" * 10)
    with pytest.raises(NotARamdaqRecording, match=r"notes\.txt: not an MCAP file") as err:
        recover(src, dst)
    assert "\n" not in str(err.value) and not dst.exists()


def test_an_empty_file_is_said_to_be_empty(tmp_path):
    """Every reader says what a new user's empty file is, as ``batch`` did alone before."""
    empty = tmp_path / "e.mcap"
    empty.write_bytes(b"")
    with pytest.raises(NotARamdaqRecording, match=r"e\.mcap: empty \(0 bytes\), not a recording$"):
        describe_recording(empty)
    with pytest.raises(NotARamdaqRecording, match=r"e\.mcap: empty \(0 bytes\)"):
        recover(empty, tmp_path / "out.mcap")


@pytest.mark.parametrize("fraction", [0.001, 0.2, 0.45, 0.7, 0.99])
def test_recover_keeps_every_complete_chunk(tmp_path, fraction):
    """Cut anywhere in the data (even inside the header): recover writes a valid file whose
    blocks are an exact prefix of the recorded ones, missing at most the chunk that was cut (5
    blocks). The last cut, 0.99, falls in the last chunk: the summary after it (schemas of the
    derived topics included) is ~5 kB of this ~3 MB file, more than its last 0.1 %."""
    path, dst = tmp_path / "cut.mcap", tmp_path / "cut.recovered.mcap"
    blocks = stream(40, seed=7, full_range=False)
    _record(path, blocks)
    data = path.read_bytes()
    kept = int(len(data) * fraction)
    path.write_bytes(data[:kept])

    report = recover(path, dst)
    assert report.truncated and report.tail_bytes > 0 and report.reason
    with open(dst, "rb") as f:
        assert make_reader(f).get_summary() is not None  # finished: summary and footer
    if report.blocks:
        _, back, _ = _replay(dst)
        assert all(a.same_as(b) for a, b in zip(back, blocks, strict=False))
        assert report.blocks == len(back) and report.last_sample == back[-1].next_sample - 1
        # blocks are ~82 kB each: all but the cut chunk's 5 blocks (and the header) are back
        assert len(back) >= kept // 82_000 - 6
    else:
        assert fraction < 0.05


def test_recover_of_a_complete_file_copies_everything(tmp_path):
    path, dst = tmp_path / "ok.mcap", tmp_path / "copy.mcap"
    blocks = stream(10, seed=8, gap_after=4, gap_blocks=1)
    _record(path, blocks)
    report = recover(path, dst)
    assert not report.truncated and report.tail_bytes == 0 and report.blocks == 10
    assert report.samples == 10 * BLOCK_SAMPLES and report.duration_s == 10 * BLOCK_SAMPLES / FS_HZ
    info, back, events = _replay(dst)
    assert info == stream_info() and all(a.same_as(b) for a, b in zip(back, blocks, strict=True))
    assert [e["kind"] for e in events] == ["gap"]
    with pytest.raises(FileExistsError):
        recover(path, dst)


def test_json_topics_and_realtime_pace(tmp_path):
    path = tmp_path / "sim.mcap"
    blocks = stream(6, seed=9)
    truth = {"sample": 3000, "t_s": 3000 / FS_HZ, "peak_force_N": 2.5e4, "duration_s": 0.002,
             "location_m": [0.1, -0.2, 1.5]}
    with Recorder(path, stream_info()) as rec:
        for b in blocks:
            rec.put(b)
        rec.write_json("/ramdaq/sim/impacts", truth, blocks[2].t0_ns)
        with pytest.raises(ValueError):
            rec.write_json("/ramdaq/sim/impacts", {"peak_force_N": float("nan")}, 0)
    assert describe_recording(path).sim_impacts == [truth]

    dev = McapReplayDevice(path, pace="realtime", speed=3.0)
    with dev:
        assert dev.rig_toml == stream_info().rig_toml
        assert dev.json_messages("/ramdaq/sim/impacts") == [(blocks[2].t0_ns, truth)]
        assert dev.json_messages("/nothing") == []
        t = time.monotonic()
        first = dev.read()
        with pytest.raises(DeviceTimeout):
            dev.read(timeout=0.001)  # the next block is due ~17 ms later
        rest = list(dev)
        elapsed = time.monotonic() - t
    assert [b.seq for b in [first, *rest]] == list(range(6))
    # 6 blocks x 50 ms / speed 3 = 100 ms of stream; sleep may overshoot, never undershoot
    assert 0.095 <= elapsed < 2.0


def test_sim_device_back_to_back(tmp_path, albacore):
    """The simulator recorded and replayed: same StreamInfo (rig text included), same blocks."""
    from ramdaq.drivers.sim import SimDevice

    path = tmp_path / "albacore.mcap"
    with SimDevice(albacore, duration_s=1.0, impacts=[0.2]) as dev:
        info, blocks = dev.info, list(dev)
    _record(path, blocks, info=info)
    back_info, back, _ = _replay(path)
    assert back_info == info and len(back) == len(blocks)
    assert all(a.same_as(b) for a, b in zip(back, blocks, strict=True))


def test_a_rig_without_the_recorded_medium_says_the_medium_came_from_the_recording(tmp_path):
    """A water-only rig given for an air recording: refused in one line that names the missing
    section and says the air came from the recording (a new user could not tell, session 16)."""
    from ramdaq.analysis.model.rig import RigError, parse_rig
    from ramdaq.daq.recording import rig_of

    text = (RIGS / "albacore.toml").read_text()
    start = text.index("[damping.air]")
    water_only = (text[:start] + text[text.index("[damping.water]"):]).replace(
        'medium = "air"', 'medium = "water"', 1)
    rig = parse_rig(water_only, source="water-only.toml")
    info = dataclasses.replace(stream_info(), extra={"medium": "air"})
    with pytest.raises(RigError) as err:
        rig_of(tmp_path / "trial.mcap", info, rig)
    msg = str(err.value)
    assert "damping.air: missing" in msg and f"{tmp_path / 'trial.mcap'} was made in air" in msg
    assert "\n" not in msg
