"""The CAN adapter through real python-can buses: emulator -> adapter -> recorder -> replay.

The simulator is the truth: a recording must hold its counts bit for bit, except the samples the
emulator made it lose, which must appear as gaps (``first_sample`` jumps of exactly those samples,
``gap`` events) with the faults logged as events.
"""

from __future__ import annotations

import heapq
import itertools
import json
import os
import re
import select
import subprocess
import sys
import threading
import time
import tty
import uuid
from pathlib import Path

import can
import cantools
import numpy as np
import pytest
from crccheck.crc import Crc8Autosar, Crc16CcittFalse

import ramdaq.drivers.can_frames as cf
from ramdaq.daq.recorder import Recorder
from ramdaq.drivers.base import DeviceFault
from ramdaq.drivers.can_device import CanDevice, parse_address
from ramdaq.drivers.emulators.can_emulator import (
    CanEmulator,
    Wire,
    rig_with_adc_bits,
    send_frames,
    slcan_line,
)
from ramdaq.drivers.errors import DeviceClosed, DeviceNotFound
from ramdaq.drivers.fault_words import describe
from ramdaq.drivers.mcap_replay import McapReplayDevice
from ramdaq.drivers.registry import open_device
from ramdaq.drivers.sim import SimDevice
from ramdaq.drivers.slcan_reader import SlcanReader

RIGS = Path(__file__).resolve().parent.parent / "recordings" / "rigs"
pytestmark = pytest.mark.timeout(60)


@pytest.fixture(scope="module")
def rigs(tmp_path_factory) -> dict[str, Path]:
    """The SAMPSON-like rig as a 24-bit (CAN FD) and a 16-bit (classic CAN) front-end."""
    tmp = tmp_path_factory.mktemp("rigs")
    text = (RIGS / "sampson.toml").read_text()
    (tmp / "r24.toml").write_text(text)
    (tmp / "r16.toml").write_text(rig_with_adc_bits(text, 16))
    return {"fd24": tmp / "r24.toml", "fd16": tmp / "r16.toml", "classic": tmp / "r16.toml"}


def _sim(rig: Path, duration_s: float = 1.0, seed: int = 3) -> SimDevice:
    return SimDevice(rig, seed=seed, duration_s=duration_s, impacts=[0.3], pace="fast")


def _truth(rig: Path, duration_s: float = 1.0, seed: int = 3) -> np.ndarray:
    with _sim(rig, duration_s, seed) as dev:
        return np.hstack([b.counts for b in dev])


def _record(dev: CanDevice, path: Path) -> None:
    with Recorder(path, dev.open()) as rec:
        for block in dev:
            rec.put(block)
            for f in dev.take_faults():
                rec.event(f.kind, f.t_ns, **f.detail)
        for f in dev.take_faults():
            rec.event(f.kind, f.t_ns, **f.detail)
    dev.close()


def _replay(path: Path):
    with McapReplayDevice(path) as rep:
        return list(rep), rep.events(), rep.info


def _virtual_trial(tmp: Path, dbc: str, rig: Path, emu_kw: dict | None = None, buses: int = 1,
                   pace: str = "fast", wires=None, idle_s: float = 0.5, tx_kw: dict | None = None,
                   reader=None, **dev_kw):
    """Emulator (a thread) on virtual buses -> CanDevice (its stream ended by ``idle_s`` of
    silence) -> Recorder -> replay. ``tx_kw``: more ``can.Bus`` arguments for the sending buses
    (``preserve_timestamps=True``: the frames arrive with the timestamps ``wires`` gave them).
    ``reader(dev)``: called once the device is open (to make its host misbehave)."""
    names = [f"ramdaq-{uuid.uuid4().hex[:8]}" for _ in range(buses)]
    extra = [f"virtual/{n}" for n in names[1:]]
    dev = CanDevice(f"virtual/{names[0]}", dbc=dbc, rig=str(rig), idle_s=idle_s, extra_buses=extra, **dev_kw)
    dev.open()
    if reader:
        reader(dev)
    emu = CanEmulator(cf.FrameCodec(dbc), _sim(rig), **(emu_kw or {}))
    tx = [can.Bus(interface="virtual", channel=n, **(tx_kw or {})) for n in names]
    by_group = {g: tx[i % buses] for i, g in enumerate(emu.codec.groups)}
    error: list[BaseException] = []

    def run() -> None:
        try:
            send_frames(wires(emu) if wires else emu.frames(), by_group, pace)
        except BaseException as err:  # handed to the test
            error.append(err)

    # "fast" has no timing to keep: every frame is queued on the virtual bus before the device
    # reads, so a starved sender thread (a loaded or niced test run) cannot look like the idle
    # bus (idle_s) that ends the stream; "realtime" sends beside the reading, as a front-end does
    th = threading.Thread(target=run, name="can-emulator")
    th.start()
    try:
        if pace == "fast":
            th.join()
        _record(dev, tmp / "trial.mcap")
    finally:
        th.join()
        for bus in tx:
            bus.shutdown()
    assert not error, error
    return emu, dev, *_replay(tmp / "trial.mcap")


def _check_against_truth(blocks, events, truth: np.ndarray, missing: np.ndarray) -> None:
    """Counts bit for bit where delivered; the missing samples, and only they, are gaps."""
    idx = np.concatenate([np.arange(b.first_sample, b.next_sample) for b in blocks])
    np.testing.assert_array_equal(idx, np.flatnonzero(~missing[: truth.shape[1]]))
    np.testing.assert_array_equal(np.hstack([b.counts for b in blocks]), truth[:, idx])
    assert [b.seq for b in blocks] == list(range(len(blocks)))
    jumps = [b.first_sample - a.next_sample for a, b in zip(blocks, blocks[1:], strict=False)]
    gaps = [e["detail"]["missing_samples"] for e in events if e["kind"] == "gap"]
    assert gaps == [j for j in jumps if j]


# -- the codec -------------------------------------------------------------------------------
@pytest.mark.parametrize("dbc", sorted(cf.SHIPPED_DBC))
def test_codec_matches_cantools_and_crc_reference(dbc):
    codec = cf.FrameCodec(dbc)
    rng = np.random.default_rng(5)
    for g, lay in codec.groups.items():
        bits = lay.sample_bits
        counts = rng.integers(-(1 << bits - 1), 1 << bits - 1, (len(lay.channels), 6 * lay.samples_per_cycle))
        raw = codec.encode_cycles(g, 250, counts.astype(np.int32))
        np.testing.assert_array_equal(codec.decode_cycles(g, raw.reshape(6, -1)), counts)
        for msg in codec.messages(g, 65530, counts.astype(np.int32)):
            fast, ref = codec.decode(msg), codec.decode_reference(msg)
            assert (fast.seq, fast.slot) == (ref.seq, ref.slot)
            np.testing.assert_array_equal(fast.values, ref.values)
            np.testing.assert_array_equal(fast.channel, ref.channel)
            lay_f = codec.layouts[msg.arbitration_id]
            covered = msg.arbitration_id.to_bytes(2, "little") + bytes(msg.data[: lay_f.crc_at])
            crc = (Crc8Autosar if lay_f.crc_name.startswith("CRC8") else Crc16CcittFalse).calc(covered)
            assert int.from_bytes(msg.data[lay_f.crc_at :], "little") == crc
    assert cf.crc("CRC8_AUTOSAR", b"123456789") == 0xDF  # the CRC catalogue's check values
    assert cf.crc("CRC8_SAE_J1850", b"123456789") == 0x4B
    assert cf.crc("CRC16_CCITT_FALSE", b"123456789") == 0x29B1


def test_classic_crc_catches_every_error_of_up_to_three_bits():
    codec = cf.FrameCodec("classic")
    msg = codec.messages(1, 7, np.arange(24, dtype=np.int32).reshape(8, 3))[0]
    good, missed = bytes(msg.data), 0
    for k in (1, 2, 3):
        for bits in itertools.combinations(range(64), k):
            data = bytearray(good)
            for b in bits:
                data[b // 8] ^= 1 << (b % 8)
            msg.data = data
            missed += codec.check(msg) != "bad_crc"
    assert missed == 0


def test_bus_load_table_is_the_documented_one():
    assert cf.capacity_rst() in cf.__doc__
    # ISO 11898-1 field lengths: 8-byte classic frame 111 bits (+24 stuff bits at worst);
    # 64-byte FD frame: 30 nominal-rate bits, 549 data-rate bits without dynamic stuffing
    assert cf.frame_bits(8, stuffing="none") == (111, 0) and cf.frame_bits(8) == (135, 0)
    assert cf.frame_bits(64, fd=True, stuffing="none") == (30, 549)
    # 16 ch x 2.048 kHz: two classic buses of 8 channels each (<80 % at worst), or one FD bus
    assert 8 * 2048 / 3 * cf.frame_time_s(8, 1e6) == pytest.approx(0.737, abs=0.001)
    assert 16 * 2048 / 20 * cf.frame_time_s(64, 1e6, 8e6, stuffing="none") < 0.17


@pytest.mark.parametrize("edit, match", [
    (lambda t: t.replace("SG_ SEQ : 0|8@1+", "SG_ SEQX : 0|8@1+", 1), "no SEQ signal"),
    (lambda t: t.replace("CH01_S0 : 8|16@1-", "CH01_S0 : 15|16@0-", 1), "little-endian"),
    (lambda t: t.replace("SG_ CH01_S2 :", "SG_ CH02_S2 :", 1), "cover each channel"),
    (lambda t: t.replace('"CRC8_AUTOSAR"', '"CRC3"', 1), "RamdaqCrc"),
], ids=["no-seq", "big-endian", "uncovered", "unknown-crc"])
def test_bad_layouts_are_refused(tmp_path, edit, match):
    path = tmp_path / "bad.dbc"
    path.write_text(edit((cf.DBC_DIR / "ramdaq_classic.dbc").read_text()))
    with pytest.raises(ValueError, match=match):
        cf.FrameCodec(path)


def test_address_options_and_refusals(rigs, tmp_path):
    assert parse_address("slcan//dev/pts/3?rig=a+b.toml&bus=virtual/1&sleep_after_open=0") == (
        "slcan", "/dev/pts/3", {"rig": "a b.toml", "sleep_after_open": 0}, ["virtual/1"])
    with pytest.raises(ValueError, match="24 bits, ramdaq_classic.dbc carries 16-bit"):
        CanDevice("virtual/x", rig=str(rigs["fd24"]))
    with pytest.raises(ValueError, match="channels 1-12 are not whole groups of ramdaq_fd24.dbc"):
        CanDevice("virtual/x", dbc="fd24", channels=12)
    master, slave = os.openpty()
    try:
        with pytest.raises(ValueError, match="Invalid bitrate"):  # python-can's own refusal
            open_device(f"can://slcan/{os.ttyname(slave)}?sleep_after_open=0&bitrate=123")
        for extra, kind in (({}, SlcanReader), ({"can_filters": [{"can_id": 0x110, "can_mask": 0x7F0}]},
                                                can.interfaces.slcan.slcanBus)):
            dev = CanDevice(f"slcan/{os.ttyname(slave)}?sleep_after_open=0", bus_options=extra)
            dev.open()
            assert type(dev._buses[0]) is kind  # the lean reader, python-can's bus to filter
            dev.close()
    finally:
        os.close(master)
        os.close(slave)
    with pytest.raises(DeviceNotFound, match="cannot open"):
        open_device(f"can://slcan/{tmp_path}/no-such-port?sleep_after_open=0")
    dev = CanDevice(f"virtual/x?dbc=fd24&rig={rigs['fd24']}&fs_hz=1024&block_s=0.1&receive_own_messages=1")
    info = dev.open()
    dev.close()
    assert (dev.fs_hz, dev.block_n, dev.bus_options) == (1024.0, 102, {"receive_own_messages": 1})
    assert info.channels[0] == "g01" and info.units[0] == "m/s^2" and info.rig_toml
    assert info.extra["groups"] == {"1": list(range(1, 17))}


# -- virtual buses (emulator in a thread) -----------------------------------------------------
@pytest.mark.parametrize("dbc", ["classic", "fd24", "fd16"])
def test_stream_is_recorded_bit_for_bit(tmp_path, rigs, dbc):
    emu, dev, blocks, events, info = _virtual_trial(tmp_path, dbc, rigs[dbc])
    truth = _truth(rigs[dbc])
    _check_against_truth(blocks, events, truth, emu.missing(truth.shape[1]))
    # A starved host (the suite at load 10+) may read a group's frames late: the device then says
    # ``delayed_frames`` and places them where SEQ says -- a true report of the host's timing, not
    # a fault of the stream; the counts above are still bit for bit. Nothing else may be reported.
    assert not [e for e in events if e["kind"] not in ("gap", "delayed_frames")]
    assert all(e["detail"]["frames"] > 0 for e in events if e["kind"] == "delayed_frames")
    assert dev.counters["frames"] == dev.counters["good_frames"]
    with _sim(rigs[dbc]) as sim:
        np.testing.assert_array_equal(blocks[0].scale, sim.read().scale)
        assert info.channels == sim.info.channels and info.rig_toml == sim.info.rig_toml


def test_a_late_backlog_is_never_read_as_seq_wraps(tmp_path, rigs):
    """The failure of test_stream_is_recorded_bit_for_bit[classic] at load 3-4, fed without timing:
    the sender (fast pace, twice real time) stalls 0.8 s before cycle 611 and then goes on, its SEQ
    unbroken, nothing lost. Held against the sample clock (683 cycles/s) the frames after the stall
    end up 0.8 x 683 - 36 = 510 cycles late: two 8-bit SEQ periods (512 cycles) within the 0.1 s
    (68 cycles) tolerance. They were read as a silence of two wraps: a seq_gap of 1536 samples the
    emulator never dropped, and sample 1833 (cycle 611) and every later one placed 1536 later.
    SEQ going on from the group's is lateness, never wraps: placed where SEQ says, bit for bit,
    with a delayed_frames event that says the whole wraps it could not rule out."""
    stall_s, stall_cycle, t_host = 0.8, 611, 1.0e6  # t_host: any host clock origin

    def stalled(emu):
        for w in emu.frames():
            w.msg.timestamp = t_host + w.t_s / 2 + (stall_s if w.cycle >= stall_cycle else 0.0)
            yield w

    emu, dev, blocks, events, _ = _virtual_trial(tmp_path, "classic", rigs["classic"], wires=stalled,
                                                 tx_kw=dict(preserve_timestamps=True))
    truth = _truth(rigs["classic"])
    assert not emu.missing(truth.shape[1])[: 682 * 3].any()  # the emulator lost no whole cycle
    _check_against_truth(blocks, events, truth, emu.missing(truth.shape[1]))
    assert {e["kind"] for e in events} == {"delayed_frames"}
    delayed = [e["detail"] for e in events]
    assert sorted(d["group"] for d in delayed) == [1, 2]  # each group judged on its own
    assert all(d["whole_wraps_late"] == 2 and d["late_s"] > 0.7 for d in delayed)
    words = describe(DeviceFault("delayed_frames", 0, delayed[0]), "can", 2048.0)
    assert "none lost" in words and "2 whole counter wrap(s)" in words


def test_a_host_stall_between_two_groups_frames_is_no_silence(tmp_path, rigs):
    """The failure of test_faults_leave_the_recording_consistent[classic] in CI: every frame
    queued, the reading host stalled longer than ``group_timeout_s`` after a frame of group 1 and
    before the next of group 2. Group 1 had then been quiet that long by the host's clock while
    group 2 had just delivered, and was declared silent to the end. A silence is also the others
    delivering ``group_timeout_s`` of samples past it: here group 1 stands one cycle behind."""
    stall_s, timeout_s = 0.4, 0.15

    def stall_once(dev):
        bus, reads = dev._buses[0], [0]
        recv = bus.recv

        def stalling_recv(timeout=None):
            msg = recv(timeout)
            reads[0] += 1
            if reads[0] == 1000:  # then the next read puts group 1 a cycle ahead of group 2
                time.sleep(stall_s)
            return msg
        bus.recv = stalling_recv

    emu, dev, blocks, events, _ = _virtual_trial(tmp_path, "classic", rigs["classic"],
                                                 reader=stall_once, group_timeout_s=timeout_s)
    truth = _truth(rigs["classic"])
    _check_against_truth(blocks, events, truth, emu.missing(truth.shape[1]))
    assert not [e for e in events if e["kind"] not in ("gap", "delayed_frames")]


@pytest.mark.parametrize("dbc", ["classic", "fd24"])
def test_faults_leave_the_recording_consistent(tmp_path, rigs, dbc):
    kw = dict(drop_every=97, corrupt_every=211, wrong_dlc_every=503, unrelated_every=300,
              error_frame_every=400, bus_off_at_s=0.6, bus_off_s=0.1)
    emu, dev, blocks, events, _ = _virtual_trial(tmp_path, dbc, rigs[dbc], kw)
    truth = _truth(rigs[dbc])
    assert emu.missing(truth.shape[1]).sum() > 100
    _check_against_truth(blocks, events, truth, emu.missing(truth.shape[1]))
    kinds = {e["kind"] for e in events}
    assert {"gap", "seq_gap", "bad_crc", "wrong_dlc", "unrelated_frame", "error_frame", "bus_off",
            "bus_recovered"} <= kinds
    last = {e["kind"]: e["detail"] for e in events}  # each counted kind's last report has its total
    inj = emu.injected
    assert (last["bad_crc"]["total"], last["wrong_dlc"]["total"]) == (inj["corrupt"], inj["wrong_dlc"])
    assert (last["unrelated_frame"]["total"], last["error_frame"]["total"]) == (
        inj["unrelated"], inj["error_frame"])
    reports = [e for e in events if e["kind"] == "unrelated_frame"]
    assert sum(e["detail"]["count"] for e in reports) == inj["unrelated"] and len(reports) <= 3


def test_two_buses_feed_one_trial(tmp_path, rigs):
    emu, dev, blocks, events, info = _virtual_trial(tmp_path, "classic", rigs["classic"],
                                                    dict(drop_every=301), buses=2)
    truth = _truth(rigs["classic"])
    _check_against_truth(blocks, events, truth, emu.missing(truth.shape[1]))
    assert len(info.extra["buses"]) == 2 and info.device.count("virtual/") == 2


def test_duration_ends_the_stream(tmp_path, rigs):
    emu, dev, blocks, events, _ = _virtual_trial(tmp_path, "fd24", rigs["fd24"], duration_s=0.5)
    truth = _truth(rigs["fd24"])
    _check_against_truth(blocks, events, truth, np.arange(truth.shape[1]) >= 1024)


def test_silent_group_times_out_and_comes_back(tmp_path, rigs):
    def mute_group_2(emu):  # bus 2 unplugged from 0.3 to 0.8 s of stream time
        for w in emu.frames():
            if w.group == 2 and 0.3 <= w.t_s < 0.8:
                emu.lost[2].add(w.cycle)
                continue
            yield w

    emu, dev, blocks, events, _ = _virtual_trial(
        tmp_path, "classic", rigs["classic"], buses=2, pace="realtime", wires=mute_group_2,
        group_timeout_s=0.15)
    truth = _truth(rigs["classic"])
    _check_against_truth(blocks, events, truth, emu.missing(truth.shape[1]))
    assert [e["detail"]["group"] for e in events if e["kind"] == "group_timeout"] == [2]


def test_bus_off_longer_than_a_seq_wrap(tmp_path, rigs):
    """0.5 s off a classic bus is 341 cycles, more than the 8-bit SEQ's 256: counted by time."""
    # the bus is silent for the whole bus-off: an idle_s of 0.5 s ended the stream whenever the
    # first frame after it came a scheduler's jitter late (CI, with smoke and floors beside it)
    emu, dev, blocks, events, _ = _virtual_trial(tmp_path, "classic", rigs["classic"],
                                                 dict(bus_off_at_s=0.2, bus_off_s=0.5), pace="realtime",
                                                 idle_s=1.5)
    truth = _truth(rigs["classic"])
    _check_against_truth(blocks, events, truth, emu.missing(truth.shape[1]))
    assert [e["kind"] for e in events if e["kind"].startswith("bus_")] == ["bus_off", "bus_recovered"]


def test_a_lone_bad_seq_is_not_believed(tmp_path, rigs):
    codec = cf.FrameCodec("fd24")

    def with_outlier(emu):
        for i, w in enumerate(emu.frames()):
            if i == 500:  # a frame that passes the CRC but claims cycle +1000
                g = w.msg.arbitration_id - 0x210
                counts = np.zeros((16, 20), np.int32)
                bogus = codec.messages(1, 1000 + i // 16, counts)[g]
                yield Wire(w.group, w.t_s, bogus)
            yield w

    emu, dev, blocks, events, _ = _virtual_trial(tmp_path, "fd24", rigs["fd24"], wires=with_outlier)
    truth = _truth(rigs["fd24"])
    _check_against_truth(blocks, events, truth, emu.missing(truth.shape[1]))
    assert dev.counters["seq_outlier"] == 1


def _kinds(events: list[dict]) -> dict[str, int]:
    out: dict[str, int] = {}
    for e in events:
        out[e["kind"]] = out.get(e["kind"], 0) + 1
    return out


def _split_at_gap(blocks) -> tuple[list, list]:
    """The blocks before the first gap and from it on."""
    cut = next(i + 1 for i, (a, b) in enumerate(zip(blocks, blocks[1:], strict=False))
               if b.first_sample != a.next_sample)
    return blocks[:cut], blocks[cut:]


def _offset_from_truth(blocks, truth: np.ndarray, limit: int) -> int:
    """The one shift ``d`` (|d| <= limit) with every block's counts equal to the truth's samples
    ``first_sample + d`` onwards, all channels at once (groups re-anchored alike)."""
    first = blocks[0]
    hits = [d for d in range(-limit, limit + 1) if 0 <= first.first_sample + d
            and first.next_sample + d <= truth.shape[1]
            and np.array_equal(first.counts, truth[:, first.first_sample + d : first.next_sample + d])]
    assert len(hits) == 1, f"blocks match the truth at shifts {hits[:5]} within +-{limit}"
    for b in blocks:
        np.testing.assert_array_equal(b.counts, truth[:, b.first_sample + hits[0] : b.next_sample + hits[0]])
    return hits[0]


@pytest.mark.parametrize("dbc, seq_offset", [("classic", 100), ("fd24", 65536 - 5000)])
def test_a_twin_sender_is_a_bus_fault_and_never_placed(tmp_path, rigs, dbc, seq_offset):
    """Issue 22, item 3: a second front-end with the same identifiers and valid CRCs (its own
    samples, its SEQ counter elsewhere) on the bus from 0.3 to 0.7 s, its cycles half a cycle
    after the real one's. It used to drive the sample index away by SEQ periods on every switch
    between the two; now it is a bus fault, none of its samples is placed, and the real stream
    is recorded bit for bit throughout -- no gap, nothing moved."""
    codec = cf.FrameCodec(dbc)
    sent = []

    def with_twin(emu):
        half = 0.5 * codec.groups[1].samples_per_cycle / 2048.0
        with SimDevice(rigs[dbc], seed=99, duration_s=1.0, impacts=[0.5], pace="fast") as sim:
            twin = CanEmulator(codec, sim, seq_offset=seq_offset)
            theirs = (Wire(w.group, w.t_s + half, w.msg) for w in twin.frames() if 0.3 <= w.t_s < 0.7)
            for w in heapq.merge(emu.frames(), theirs, key=lambda w: w.t_s):
                sent.append(w.t_s != round(w.t_s / (2 * half)) * 2 * half)
                yield w

    emu, dev, blocks, events, _ = _virtual_trial(tmp_path, dbc, rigs[dbc], pace="realtime", wires=with_twin)
    truth = _truth(rigs[dbc])
    _check_against_truth(blocks, events, truth, emu.missing(truth.shape[1]))
    assert not emu.missing(truth.shape[1])[: blocks[-1].next_sample].any()  # nothing lost at all
    n_twin, groups = sum(sent), len(codec.groups)
    # every twin frame dropped: as the foreign sender's, or (if the emulator thread stalled while
    # the twin was being found, so the real frames were held late) as outliers beside them
    assert n_twin > 100 and dev.counters["foreign_frame"] + dev.counters["seq_outlier"] == n_twin
    assert dev.counters["foreign_frame"] >= 0.9 * n_twin
    k = _kinds(events)
    assert k.get("foreign_sender") == k.get("foreign_sender_gone") == groups and "gap" not in k
    assert not {"seq_gap", "gap_unknown", "conflicting_frame"} & set(k)
    came = [e for e in events if e["kind"] == "foreign_sender"]
    went = [e for e in events if e["kind"] == "foreign_sender_gone"]
    cycle_ns = codec.groups[1].samples_per_cycle / 2048.0 * 1e9
    assert all(abs(e["t_ns"] - 0.3e9) <= 4 * cycle_ns for e in came)  # found within 3 of its cycles
    assert all(abs(e["t_ns"] - 0.7e9) <= 2 * cycle_ns for e in went)  # it left when it went quiet
    assert sum(e["detail"]["frames_dropped"] for e in went) == dev.counters["foreign_frame"]


# -- slcan over a pseudo-terminal, the emulator a real process ---------------------------------
def _emulator(rig: Path, dbc: str, report: Path, *args: str) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "ramdaq.drivers.emulators.can_emulator",
         "--interface", "slcan", "--rig", str(rig),
         "--dbc", dbc, "--duration", "1", "--impacts", "0.3", "--seed", "3", "--report", str(report),
         "--linger", "10", *args], stdout=subprocess.PIPE, text=True, cwd=RIGS.parent.parent)
    line = proc.stdout.readline().split()
    assert line[:1] == ["SLCAN"], line
    return proc, line[1]


def _missing_from_report(report: dict, n: int) -> np.ndarray:
    idx, gone = np.arange(n), np.zeros(n, dtype=bool)
    for g, cycles in report["lost"].items():
        T = report["samples_per_cycle"][g]
        gone |= np.isin(idx // T, cycles) | (idx >= report["cycles_sent"][g] * T)
    return gone


@pytest.mark.parametrize("dbc, faults", [
    ("classic", ["--drop-every", "150", "--garble-every", "211", "--wrong-dlc-every", "307",
                 "--unrelated-every", "400"]),
    ("fd24", ["--corrupt-every", "101", "--garble-every", "77", "--pace", "realtime"]),
])
def test_slcan_emulator_process(tmp_path, rigs, dbc, faults):
    proc, port = _emulator(rigs[dbc], dbc, tmp_path / "truth.json", "--pace", "fast", *faults)
    try:
        dev = open_device(f"can://slcan/{port}?sleep_after_open=0&bitrate=1000000&idle_s=0.5",
                          dbc=dbc, rig=str(rigs[dbc]))
        _record(dev, tmp_path / "trial.mcap")
        assert proc.wait(10) == 0
    finally:
        proc.kill()
    report = json.loads((tmp_path / "truth.json").read_text())
    blocks, events, _ = _replay(tmp_path / "trial.mcap")
    truth = _truth(rigs[dbc])
    _check_against_truth(blocks, events, truth, _missing_from_report(report, truth.shape[1]))
    totals = {e["kind"]: e["detail"]["total"] for e in events if "total" in e["detail"]}
    assert totals["bad_frame"] == report["injected"]["garble"]
    assert all(e["detail"]["reason"].startswith("unparseable slcan line '")
               for e in events if e["kind"] == "bad_frame")
    assert totals.get("wrong_dlc", 0) == report["injected"].get("wrong_dlc", 0)
    assert totals.get("bad_crc", 0) == report["injected"].get("corrupt", 0)


def test_slcan_line_faults_from_a_pty(tmp_path, rigs):
    """Torn, merged, non-ASCII, status, reply, remote and unrelated lines written by the test to a
    pseudo-terminal: each counted, the frames they cost are gaps, the rest bit for bit."""
    emu = CanEmulator(cf.FrameCodec("classic"), _sim(rigs["classic"]))
    lines, bad = [], 0
    for k, w in enumerate(emu.frames()):
        line = slcan_line(w.msg)
        if k in (300, 600, 601, 900):
            emu.lost[w.group].add(w.cycle)
            bad += k != 601
        lines.append({300: line[:9] + b"\r", 600: line[:-1],  # torn; its "\r" lost: merged with 601
                      900: line[:5] + b"\xff" + line[6:]}.get(k, line))
        if k == 100:  # status (bus error, error passive), zero status, replies: one error frame
            lines += [b"FA0\r", b"F00\r", b"\a", b"z\r", b"\r", b"V1013\r"]
        elif k == 200:  # a remote frame with a sample frame's identifier, another node's frame
            lines += [b"r1108\r", b"t7E8804410D3700000000\r"]
            bad += 1
    stream = b"".join(lines)
    master, slave = os.openpty()
    tty.setraw(slave)

    def write() -> None:  # once the adapter opened the channel, in pieces
        got = b""
        while b"O\r" not in got:
            if not select.select([master], [], [], 5.0)[0]:
                return  # never opened: the test fails on what it read
            got += os.read(master, 100)
        for at in range(0, len(stream), 777):
            os.write(master, stream[at : at + 777])

    th = threading.Thread(target=write, name="slcan-writer", daemon=True)
    th.start()
    try:
        dev = open_device(f"can://slcan/{os.ttyname(slave)}?sleep_after_open=0&idle_s=0.5", dbc="classic",
                          rig=str(rigs["classic"]))
        _record(dev, tmp_path / "trial.mcap")
    finally:
        th.join(10)
        os.close(master)
        os.close(slave)
    blocks, events, _ = _replay(tmp_path / "trial.mcap")
    truth = _truth(rigs["classic"])
    _check_against_truth(blocks, events, truth, emu.missing(truth.shape[1]))
    totals = {e["kind"]: e["detail"]["total"] for e in events if "total" in e["detail"]}
    assert (totals["bad_frame"], totals["error_frame"], totals["unrelated_frame"]) == (bad, 1, 1)
    assert {"bus_off", "bus_lost"}.isdisjoint(e["kind"] for e in events)
    assert any(e["detail"].get("reason", "").startswith("unparseable slcan line") for e in events
               if e["kind"] == "bad_frame")
    # every sample frame but the 4 lines lost (600 and 601 are one), plus status, remote, unrelated
    assert dev.counters["frames"] == k + 1 - 4 + 3


# classic: silent 0.1 s, so SEQ from 0 claims 170 cycles (0.25 s) more than time says (with 0.3 s
# it would agree with time within the 0.1 s tolerance: a restart SEQ cannot be told from a jump
# then). fd24 with a 0.3 s tolerance: the emulator, a process on a shared 2-core box, was seen to
# send up to 0.2 s behind its sample clock just before the silence, which shortens it on arrival
# by as much -- the estimate is only as good as the arrival times.
@pytest.mark.parametrize("dbc, silent_s, tolerance_s", [("classic", 0.1, 0.1), ("fd24", 0.5, 0.3)])
def test_a_restarted_front_end_is_re_anchored_from_the_host_clock(tmp_path, rigs, dbc, silent_s,
                                                                  tolerance_s):
    """The front-end restarts at 0.4 s: silent a while, then its SEQ counts from 0 again (slcan,
    the emulator its own process). SEQ cannot say how long the gap was; the samples after it are
    placed where the frames' arrival times put them (all groups alike, never onto samples already
    placed), and a gap_unknown event gives that estimate, what SEQ said and the uncertainty.
    Before the restart, bit for bit."""
    proc, port = _emulator(rigs[dbc], dbc, tmp_path / "truth.json", "--pace", "realtime",
                           "--restart-at", "0.4", "--restart-s", str(silent_s))
    try:
        dev = open_device(f"can://slcan/{port}?sleep_after_open=0&idle_s=1&clock_tolerance_s={tolerance_s}",
                          dbc=dbc, rig=str(rigs[dbc]))
        _record(dev, tmp_path / "trial.mcap")
        assert proc.wait(10) == 0
    finally:
        proc.kill()
    report = json.loads((tmp_path / "truth.json").read_text())
    blocks, events, _ = _replay(tmp_path / "trial.mcap")
    truth = _truth(rigs[dbc])
    assert report["injected"]["restart"] == 1
    at = [e["t_ns"] for e in events if e["kind"] == "gap_unknown"][:1]
    before = [b for b in blocks if at and b.t0_ns < at[0]]
    after = blocks[len(before):]
    assert _offset_from_truth(before, truth, 0) == 0
    T = report["samples_per_cycle"]["1"]
    assert before[-1].next_sample <= 0.4 * 2048 + T
    unknown = [{**e["detail"], "group": 0} for e in events if e["kind"] == "gap_unknown"]
    assert len(unknown) == len(report["lost"]) and unknown.count(unknown[0]) == len(unknown)
    assert unknown[0]["uncertainty_samples"] == round(tolerance_s * 2048)
    shift = _offset_from_truth(after, truth, unknown[0]["uncertainty_samples"])  # all channels alike
    missing = _missing_from_report(report, truth.shape[1])
    true_gap = int(np.flatnonzero(~missing[before[-1].next_sample :])[0])
    recorded_gap = after[0].first_sample - before[-1].next_sample
    assert unknown[0]["estimated_samples"] == recorded_gap == true_gap - shift


@pytest.mark.parametrize("tolerance_s", [0.1, 0.2])
def test_silence_longer_than_the_seq_period_over_slcan(tmp_path, rigs, tolerance_s):
    """Issue 22, item 4: classic CAN over slcan, 0.6 s of silence (a bus-off the Lawicel protocol
    cannot report) is 410 cycles, more than the 8-bit SEQ's 256; it was recorded as 154 (462
    samples) and every later sample placed 0.375 s early. The frames' arrival times count the wrap:
    the gap is exact. With a clock tolerance of 0.2 s (over half the SEQ period, 0.1875 s) the
    wraps cannot be told: the samples are re-anchored from the host clock and a gap_unknown event
    says so -- never a silent guess."""
    proc, port = _emulator(rigs["classic"], "classic", tmp_path / "truth.json", "--pace", "realtime",
                           "--duration", "1.5", "--bus-off-at", "0.4", "--bus-off-s", "0.6")
    try:
        dev = open_device(f"can://slcan/{port}?sleep_after_open=0&idle_s=2&clock_tolerance_s={tolerance_s}",
                          dbc="classic", rig=str(rigs["classic"]))
        _record(dev, tmp_path / "trial.mcap")
        assert proc.wait(10) == 0
    finally:
        proc.kill()
    report = json.loads((tmp_path / "truth.json").read_text())
    blocks, events, _ = _replay(tmp_path / "trial.mcap")
    truth = _truth(rigs["classic"], 1.5)
    missing = _missing_from_report(report, truth.shape[1])
    gap = np.flatnonzero(missing[: blocks[-1].next_sample])
    assert 0.6 * 2048 - 3 <= len(gap) == gap[-1] - gap[0] + 1 <= 0.6 * 2048 + 3  # > 256 cycles of 3
    k = _kinds(events)
    if tolerance_s == 0.1:
        _check_against_truth(blocks, events, truth, missing)
        wraps = [e["detail"] for e in events if e["kind"] == "seq_wrap"]
        assert [w["wraps"] for w in wraps] == [1, 1] and "gap_unknown" not in k  # both groups
        assert all(abs(w["timing_error_samples"]) <= 0.1 * 2048 for w in wraps)
        return
    before, after = _split_at_gap(blocks)
    assert _offset_from_truth(before, truth, 0) == 0
    unknown = [{**e["detail"], "group": 0} for e in events if e["kind"] == "gap_unknown"]
    assert len(unknown) == 2 and unknown[0] == unknown[1] and "seq_wrap" not in k  # groups alike
    assert unknown[0]["seq_says_samples"] == len(gap) - 256 * 3  # SEQ alone: the wrap not seen
    assert unknown[0]["uncertainty_samples"] == round(0.2 * 2048)
    shift = _offset_from_truth(after, truth, unknown[0]["uncertainty_samples"])
    assert unknown[0]["estimated_samples"] == len(gap) - shift


def test_emulator_gone_ends_the_stream(tmp_path, rigs):
    proc, port = _emulator(rigs["fd24"], "fd24", tmp_path / "truth.json", "--pace", "realtime",
                           "--duration", "30")
    dev = open_device(f"can://slcan/{port}?sleep_after_open=0", dbc="fd24", rig=str(rigs["fd24"]))
    first = dev.read(timeout=5)
    proc.kill()
    proc.wait(5)
    rest = []
    with pytest.raises(DeviceClosed, match=re.escape(f"can: slcan/{port} lost (")):
        while True:  # the samples assembled are handed out, then the vanished adapter is said
            rest.append(dev.read(timeout=5))
    faults = dev.take_faults()
    dev.close()
    assert first.first_sample == 0 and sum(b.n_samples for b in rest) < 30 * 2048
    assert [f.kind for f in faults if f.kind == "bus_lost"] == ["bus_lost"]


@pytest.mark.timeout(300)  # hang guard: a full trial with its analysis on a loaded 2-core box
def test_ramdaq_trial_against_the_slcan_emulator(tmp_path, rigs):
    from ramdaq.daq.commands.cli import main

    proc, port = _emulator(rigs["fd24"], "fd24", tmp_path / "truth.json", "--pace", "fast",
                           "--duration", "4.5", "--impacts", "2.5")
    try:
        rc = main(["trial", "--device", f"can://slcan/{port}?sleep_after_open=0&dbc=fd24&rig="
                   f"{rigs['fd24']}&idle_s=0.5", "--out", str(tmp_path / "t.mcap"), "--no-rerun",
                   "--quiet", "--json", str(tmp_path / "hits.json")])
    finally:
        proc.kill()
    assert rc == 0
    hits = json.loads((tmp_path / "hits.json").read_text())
    assert len(hits) == 1 and hits[0]["onset_s"] == pytest.approx(2.5, abs=0.01)
    _, events, info = _replay(tmp_path / "t.mcap")
    assert info.device.startswith("can://slcan/") and not events  # (a gap disarms the trigger 2 s)


@pytest.mark.skipif(not Path("/sys/class/net/vcan0").exists(), reason="no vcan0 on this kernel")
def test_socketcan_vcan0(tmp_path, rigs):
    proc = subprocess.Popen(
        [sys.executable, "-m", "ramdaq.drivers.emulators.can_emulator",
         "--interface", "socketcan", "--channel", "vcan0",
         "--rig", str(rigs["fd24"]), "--dbc", "fd24", "--duration", "1", "--impacts", "0.3", "--seed", "3",
         "--pace", "realtime", "--drop-every", "97"], stdout=subprocess.PIPE, text=True)
    dev = open_device("can://socketcan/vcan0?idle_s=0.5&fd=1", dbc="fd24", rig=str(rigs["fd24"]))
    _record(dev, tmp_path / "trial.mcap")
    proc.wait(10)
    blocks, _, _ = _replay(tmp_path / "trial.mcap")
    idx = np.concatenate([np.arange(b.first_sample, b.next_sample) for b in blocks])
    np.testing.assert_array_equal(np.hstack([b.counts for b in blocks]), _truth(rigs["fd24"])[:, idx])


def test_cantools_reads_the_shipped_layouts():
    for name in cf.SHIPPED_DBC.values():
        db = cantools.database.load_file(str(cf.DBC_DIR / name))
        assert db.messages and all(m.length in (8, 64) for m in db.messages)
