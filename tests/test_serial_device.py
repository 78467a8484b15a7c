"""Serial back-end against the emulator: real processes, real ptys and loopback sockets, the real
pyserial stack, no mocks.

Each test runs ``python -m ramdaq.drivers.emulators.serial_emulator`` with a rig, seed and impacts, streams it
through :class:`SerialDevice` into :class:`Recorder` (the ``ramdaq record`` loop), replays the file
with :class:`McapReplayDevice`, and holds the samples against a :class:`SimDevice` with the same
rig, seed and impacts: bit for bit where they were delivered, and exactly the frames the emulator
dropped, corrupted or lost where they were not -- which the file must show as gaps and events.
"""

from __future__ import annotations

import json
import re
import select
import socket
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from ramdaq.daq.record import record
from ramdaq.daq.session import Session
from ramdaq.drivers.block import sample_time_ns
from ramdaq.drivers.emulators.serial_emulator import PtyPort
from ramdaq.drivers.errors import DeviceClosed, DeviceNotFound
from ramdaq.drivers.mcap_replay import McapReplayDevice
from ramdaq.drivers.registry import open_device
from ramdaq.drivers.serial_device import SerialDevice, split_url
from ramdaq.drivers.serial_frames import FLAG_END, encode_frame
from ramdaq.drivers.sim import SimDevice

pytestmark = pytest.mark.timeout(60)

REPO = Path(__file__).resolve().parent.parent
RIG = REPO / "recordings" / "rigs" / "albacore.toml"
SEED, DURATION, IMPACTS = 11, 3.0, [1.2]


@contextmanager
def emulator(tmp_path: Path, transport: str, *args: str, duration: float = DURATION,
             impacts: list[float] = IMPACTS, rig: Path = RIG, seed: int = SEED):
    """Start the emulator; yield ``(process, address)``; make sure it is gone afterwards."""
    where = ["--pty", "--link", str(tmp_path / "tty")] if transport == "pty" else [
        "--tcp", "127.0.0.1:0"]
    cmd = [sys.executable, "-m", "ramdaq.drivers.emulators.serial_emulator",
           *where, "--rig", str(rig),
           "--duration", str(duration), "--impacts", ",".join(map(str, impacts)), "--seed",
           str(seed), "--pace", "fast", "--linger", "5", *args]
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        address = proc.stdout.readline().strip()
        assert address, f"emulator did not start: {proc.stderr.read()}"
        yield proc, address
    finally:
        if proc.poll() is None:
            proc.terminate()
        proc.wait(10)
        proc.stdout.close()
        proc.stderr.close()


def summary(proc: subprocess.Popen) -> dict:
    out = proc.stdout.read()
    assert proc.wait(10) == 0, proc.stderr.read()
    return json.loads(out.strip().splitlines()[-1])


def truth(duration: float = DURATION, impacts: list[float] = IMPACTS
          ) -> tuple[np.ndarray, np.ndarray]:
    """The simulator's counts, shape (channels, samples), and scales."""
    with SimDevice(RIG, seed=SEED, duration_s=duration, impacts=impacts) as sim:
        return np.hstack([b.counts for b in sim]), sim._sensor.scale


def replay(path: Path) -> tuple[list, list[dict]]:
    with McapReplayDevice(path) as dev:
        return list(dev), dev.events()


def frames_missing(s: dict, total: int, *keys: str) -> np.ndarray:
    """Mask of the samples in the frames the emulator's summary lists under ``keys``."""
    mask = np.zeros(total, bool)
    n = s["frame_samples"]
    for key in keys:
        for k in s[key]:
            mask[k * n:(k + 1) * n] = True
    return mask


def check_recording(path: Path, duration: float = DURATION, impacts: list[float] = IMPACTS
                    ) -> tuple[np.ndarray, list[dict]]:
    """Every recorded sample equals the simulator's; returns the mask of samples *not* recorded
    and the file's events, after checking the gap events account for exactly those samples."""
    ref, scale = truth(duration, impacts)
    blocks, events = replay(path)
    got = np.zeros(ref.shape[1], bool)
    for b in blocks:
        assert np.array_equal(b.counts, ref[:, b.first_sample:b.next_sample]), b.first_sample
        assert np.array_equal(b.scale, scale) and not got[b.first_sample:b.next_sample].any()
        got[b.first_sample:b.next_sample] = True
    gaps = [e["detail"] for e in events if e["kind"] == "gap"]
    inner_missing = np.count_nonzero(~got[: blocks[-1].next_sample])
    assert sum(g["missing_samples"] for g in gaps) == inner_missing
    return ~got, events


def live_trial(dev: SerialDevice, path: Path) -> list[str]:
    """Run ``dev`` through the live trial session (recorder, trigger, analyzer) into ``path``;
    return what the session showed live (the terminal readout shows the same lines)."""
    shown: list[str] = []
    Session(dev, record_path=path, readout=False, log=shown.append).run()
    return shown


def shown_faults(shown: list[str], device: str) -> list[str]:
    """The lines the session said about the device's faults (:mod:`ramdaq.drivers.fault_words`)."""
    return [line for line in shown if line.startswith(device + " at ")]


def kinds(events: list[dict]) -> dict[str, int]:
    out: dict[str, int] = {}
    for e in events:
        out[e["kind"]] = out.get(e["kind"], 0) + 1
    return out


# -- clean stream ----------------------------------------------------------------------------
def _after_start(events: list[dict]) -> list[dict]:
    """``events`` without the emulator's start-up silence: its start may outlast ``quiet_s`` on a
    loaded machine, and a silence before the first block heard is said (``no_data``, and
    ``data_back`` marked ``first``), at 0 s or at the end of a first partial block (15.6 ms at
    2048 Hz, as a floors run in a fresh environment had it); not these tests' subject."""
    start = {0} | {e["t_ns"] for e in events if e["kind"] == "data_back" and e["detail"].get("first")}
    return [e for e in events if not (e["kind"] in ("no_data", "data_back") and e["t_ns"] in start)]


@pytest.mark.parametrize("transport", ["pty", "tcp"])
def test_recording_equals_the_simulator_bit_for_bit(tmp_path, transport):
    path = tmp_path / "trial.mcap"
    with emulator(tmp_path, transport) as (proc, address):
        dev = open_device(f"serial://{address}?rig={RIG}")
        rec = record(dev, path, readout=False)
        s = summary(proc)
    missing, events = check_recording(path)
    events = _after_start(events)
    assert not missing.any() and rec.gaps == 0 and events == []
    assert s["samples_sent"] == round(DURATION * 2048) == rec.samples
    p = dev.parser
    assert (p.crc_errors, p.resyncs, p.bytes_discarded, p.bad_headers) == (0, 0, 0, 0)
    with SimDevice(RIG, seed=SEED) as sim, McapReplayDevice(path) as back:
        assert back.info.channels == sim.info.channels and back.info.gages == sim.info.gages
        assert back.info.rig_toml == sim.info.rig_toml and back.info.fs_hz == sim.info.fs_hz
        assert back.info.device == f"serial://{address}"


# -- faults ----------------------------------------------------------------------------------
@pytest.mark.parametrize("transport", ["pty", "tcp"])
def test_drops_corruption_and_garbage_become_gaps_and_events(tmp_path, transport):
    path = tmp_path / "faults.mcap"
    with emulator(tmp_path, transport, "--drop-every", "9", "--corrupt-every", "13",
                  "--garbage-every", "7") as (proc, address):
        dev = SerialDevice(address, rig=str(RIG))
        shown = live_trial(dev, path)
        s = summary(proc)
    missing, events = check_recording(path)
    assert s["dropped"] and s["corrupted"] and s["garbage"]
    assert np.array_equal(missing, frames_missing(s, missing.size, "dropped", "corrupted"))
    n = kinds(events)
    # one line per incident: a stream time with a fault shown once, whatever its parts (the
    # emulator's faults are whole frames apart, farther than fault_words.INCIDENT_S)
    said = shown_faults(shown, f"serial://{address}")
    assert len(said) == len({e["t_ns"] for e in events if e["kind"] in ("crc_error", "resync",
                                                                         "seq_gap")})
    assert dev.parser.crc_errors == len(s["corrupted"]) == sum(
        e["detail"]["count"] for e in events if e["kind"] == "crc_error")
    assert n["seq_gap"] == n["gap"]
    seq_gaps = [e["detail"] for e in events if e["kind"] == "seq_gap"]
    lost = set(s["dropped"]) | set(s["corrupted"])
    assert sum(g["missing_frames"] for g in seq_gaps) == len(lost)
    # one resync for each good frame reached across garbage or a corrupted frame, no other
    reached = {_next_good(k, lost) for k in s["garbage"]}
    reached |= {_next_good(k + 1, lost) for k in s["corrupted"]}
    assert n["resync"] == dev.parser.resyncs == len(reached)


def _next_good(k: int, lost: set[int]) -> int:
    while k in lost:
        k += 1
    return k


def test_unplug_and_replug_over_socket(tmp_path):
    """The bridge vanishes mid-frame for 0.6 s: port_lost, port_back with the exact gap, the
    torn frame discarded, and the stream goes on bit for bit."""
    path = tmp_path / "unplug.mcap"
    with emulator(tmp_path, "tcp", "--unplug-at", "1.0", "--unplug-for", "0.6") as (proc, address):
        dev = SerialDevice(address, rig=RIG, reconnect_s=0.05, give_up_s=10)
        shown = live_trial(dev, path)
        s = summary(proc)
    missing, events = check_recording(path)
    said = shown_faults(shown, f"serial://{address}")
    assert len(said) == 2 and " lost (" in said[0] and " back after " in said[1]
    assert s["torn"] and s["lost"]
    assert np.array_equal(missing, frames_missing(s, missing.size, "torn", "lost"))
    n = kinds(events)
    assert n["port_lost"] == n["port_back"] == n["gap"] == 1 and "seq_gap" not in n
    back = next(e for e in events if e["kind"] == "port_back")
    assert back["detail"]["gap_frames"] == len(s["torn"]) + len(s["lost"])
    assert back["detail"]["gap_samples"] == np.count_nonzero(missing) == 32 * (
        back["detail"]["gap_frames"]) >= 0.6 * 2048
    assert back["t_ns"] == sample_time_ns(int(np.argmax(missing)), 2048.0)
    assert dev.parser.resyncs == 1  # the torn half frame, discarded when the port went
    assert not missing[-100:].any()


def test_unplug_and_replug_pty_behind_a_stable_link(tmp_path):
    """A replugged pty is a new /dev/pts/N; the emulator's symlink keeps the name, as udev's
    /dev/serial/by-id does. Bytes in flight when a pty hangs up may be lost: the gap covers at
    least the unplugged frames, and the file accounts for it."""
    path = tmp_path / "unplug.mcap"
    with emulator(tmp_path, "pty", "--unplug-at", "1.0", "--unplug-for", "0.6") as (proc, address):
        dev = SerialDevice(address, rig=RIG, reconnect_s=0.05, give_up_s=10)
        record(dev, path, readout=False)
        s = summary(proc)
    missing, events = check_recording(path)
    assert (missing >= frames_missing(s, missing.size, "torn", "lost")).all()
    assert kinds(events)["port_lost"] == kinds(events)["port_back"] == 1
    assert not missing[-100:].any()


def test_port_that_never_comes_back_ends_the_stream_naming_the_url(tmp_path):
    with emulator(tmp_path, "tcp", duration=60.0) as (proc, address):
        dev = SerialDevice(address, rig=RIG, reconnect_s=0.05, give_up_s=0.5)
        with dev:
            first = dev.read(timeout=5)
            proc.kill()
            t = time.monotonic()
            with pytest.raises(DeviceClosed, match=re.escape(address)) as err:
                while True:
                    dev.read(timeout=5)
        assert time.monotonic() - t < 5 and "\n" not in str(err.value)
        assert first.first_sample == 0
        assert [f.kind for f in dev.take_faults()][-1] == "port_lost"


@pytest.mark.timeout(300)  # hang guard: two full analyses run side by side on a 2-core box
def test_cli_trial_over_serial_gives_the_simulator_trials_numbers(tmp_path):
    """``ramdaq trial --device serial://...`` against the emulator, with garbage on the line:
    every garbage burst is shown live and logged as a resync, no sample is lost, and the final
    numbers equal those of the same trial run straight from the simulator."""
    out, results = tmp_path / "trial.mcap", tmp_path / "results.json"
    with emulator(tmp_path, "tcp", "--garbage-every", "25", duration=6.0,
                  impacts=[3.0]) as (proc, address):
        cli = subprocess.Popen([sys.executable, "-m", "ramdaq.daq.commands.cli", "trial", "--device",
                                f"serial://{address}?rig={RIG}", "--no-rerun", "--out", str(out),
                                "--json", str(results)],
                               cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
        try:  # meanwhile, the same trial straight from the simulator
            direct = Session(SimDevice(RIG, seed=SEED, duration_s=6.0, impacts=[3.0]),
                             readout=False).run()
            stdout, stderr = cli.communicate(timeout=240)
        finally:
            cli.kill()
        s = summary(proc)
    assert cli.returncode == 0, stderr
    assert stdout.count("stray bytes skipped to the next frame") == len(s["garbage"]) > 0
    missing, events = check_recording(out, duration=6.0, impacts=[3.0])
    events = _after_start(events)
    assert not missing.any() and kinds(events) == {"resync": len(s["garbage"])}
    assert len(direct.hits) == 1
    assert _canonical(results.read_text()) == _canonical(json.dumps(direct.results_json(),
                                                                     default=_plain))


def _plain(o: object) -> object:
    return o.tolist() if isinstance(o, np.ndarray | np.generic) else str(o)


def _canonical(text: str) -> str:
    """JSON text in one spelling (NaN compares equal to NaN here)."""
    return json.dumps(json.loads(text), sort_keys=True)


# -- repeated, stale and foreign frames (issue 22, item 2) ----------------------------------
_N = 32  # samples per frame
_OURS = np.random.default_rng(1).integers(-2**23, 2**23, (8, 2, _N)).astype(np.int32)
_OTHER = np.random.default_rng(2).integers(-2**23, 2**23, (8, 2, _N)).astype(np.int32)
# name -> frames in wire order as (seq, device first sample, counts), and the expected
# (stream first sample, counts) of what is placed, with the faults expected (kind -> count)
_A = [(k, k * _N, _OURS[k]) for k in range(8)]
_SCRIPTS = {
    "repeat": ([_A[0], _A[1], _A[2], _A[1], _A[3], _A[4], _A[5]],
               [(k * _N, _OURS[k]) for k in range(6)], {"repeated_frame": 1}),
    "repeated span": ([*_A[:4], *_A[1:4], *_A[4:6]],
                      [(k * _N, _OURS[k]) for k in range(6)], {"repeated_frame": 1}),
    "stale frame behind": ([*_A[:3], (1, _N, _OTHER[1]), *_A[3:6]],
                           [(k * _N, _OURS[k]) for k in range(6)], {"stale_frame": 1}),
    "foreign frame ahead": ([*_A[:3], (7777, 10**9, _OTHER[0]), *_A[3:6]],
                            [(k * _N, _OURS[k]) for k in range(6)], {"stale_frame": 1}),
    "restart": ([*_A[:4], *[(k, k * _N, _OTHER[k]) for k in range(3)]],
                [*[(k * _N, _OURS[k]) for k in range(4)], *[((4 + k) * _N, _OTHER[k]) for k in range(3)]],
                {"stream_restart": 1}),
    "lost frame": ([_A[0], _A[1], _A[3], _A[4]],
                   [(k * _N, _OURS[k]) for k in (0, 1, 3, 4)], {"seq_gap": 1}),
}


def _serve_frames(tmp_path: Path, wire: bytes) -> tuple[list, list]:
    """``wire`` written to a real pty once a SerialDevice opened it; the blocks and faults."""
    port = PtyPort(tmp_path / "tty")

    def write() -> None:
        if port.wait_reader(10.0):
            port.send(wire)
            port.finish(5.0)

    th = threading.Thread(target=write, name="pty-writer", daemon=True)
    th.start()
    try:
        with SerialDevice(port.address, channels=2, fs_hz=2048.0) as dev:
            blocks = list(dev)  # to the end-of-stream frame
            faults = dev.take_faults()
    finally:
        th.join(10)
        port.unplug()
    return blocks, faults


@pytest.mark.parametrize("name", list(_SCRIPTS))
def test_a_frame_out_of_place_never_moves_the_samples(tmp_path, name):
    """Issue 22, item 2: frames 0,1,2,1,3,... were taken for a device restart -- frame 1's data
    landed at samples 96-127 and everything after moved 64 samples. A repeat (the same bytes again)
    is dropped and logged; a stale or foreign frame that fits neither the stream nor the frame
    after it is dropped and logged; a genuine restart (its next frame continues it) is still
    followed, after the last sample; a lost frame is still a gap. Nothing placed is ever moved."""
    frames, placed, kinds_expected = _SCRIPTS[name]
    last_seq, last_first, _ = frames[-1]
    wire = b"".join(encode_frame(seq, first, counts) for seq, first, counts in frames)
    wire += encode_frame(last_seq + 1, last_first + _N, np.zeros((2, 0), np.int32), flags=FLAG_END)
    blocks, faults = _serve_frames(tmp_path, wire)
    got = {b.first_sample + i: b.counts[:, i] for b in blocks for i in range(b.n_samples)}
    want = {first + i: counts[:, i] for first, counts in placed for i in range(_N)}
    assert sorted(got) == sorted(want)
    assert all(np.array_equal(got[i], want[i]) for i in want)
    assert kinds([{"kind": f.kind} for f in faults]) == kinds_expected
    detail = faults[0].detail
    if name == "repeat":
        assert detail == {"frames": 1, "first_seq": 1, "last_seq": 1, "samples": _N, "placed_at": _N}
    elif name == "repeated span":
        assert detail == {"frames": 3, "first_seq": 1, "last_seq": 3, "samples": 3 * _N, "placed_at": _N}
        assert faults[0].t_ns == sample_time_ns(4 * _N, 2048.0)
    elif name == "restart":
        assert detail["continues_at"] == 4 * _N and detail["gap_unknown"] and detail["gap_samples"] == 0


class RepeatingProxy:
    """A TCP proxy on 127.0.0.1 between a reader and ``upstream``, as a flaky Ethernet link:
    once ``after`` bytes went through, it sends the last ``span`` bytes again."""

    def __init__(self, upstream: str, after: int, span: int) -> None:
        host, _, port = upstream.removeprefix("socket://").rpartition(":")
        self.upstream = (host, int(port))
        self.after, self.span, self.repeated = after, span, 0
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.address = f"socket://127.0.0.1:{self.listener.getsockname()[1]}"
        self.thread = threading.Thread(target=self._run, name="repeating-proxy", daemon=True)
        self.thread.start()

    def _run(self) -> None:
        client, _ = self.listener.accept()
        up = socket.create_connection(self.upstream)
        sent, tail = 0, b""
        with client, up:
            while True:
                ready, _, _ = select.select([up, client], [], [], 10.0)
                if not ready or client in ready and not client.recv(4096):
                    return  # the reader closed: so does the link
                if up in ready:
                    data = up.recv(65536)
                    if not data:
                        try:
                            client.shutdown(socket.SHUT_WR)
                        except OSError:  # the reader already went: the link is closed either way
                            return
                        continue
                    client.sendall(data)
                    tail = (tail + data)[-self.span:]
                    sent += len(data)
                    if sent >= self.after and not self.repeated:
                        client.sendall(tail)
                        self.repeated = len(tail)


def test_a_link_that_repeats_a_span_moves_nothing(tmp_path):
    """Issue 22, item 2: a TCP link that sent a 5 000-byte span twice made 36 192 samples per
    channel land 46.9 ms late (taken for a device restart). Now the repeated frames are dropped
    and logged, the torn edges of the span are resyncs, and the recording equals the simulator's
    bit for bit with no gap."""
    path = tmp_path / "repeat.mcap"
    with emulator(tmp_path, "tcp") as (proc, address):
        proxy = RepeatingProxy(address, after=100_000, span=5000)
        rec = record(SerialDevice(proxy.address, rig=RIG), path, readout=False)
        s = summary(proc)
    proxy.thread.join(10)
    assert proxy.repeated == 5000 and rec.gaps == 0
    missing, events = check_recording(path)
    assert not missing.any() and s["samples_sent"] == rec.samples
    n = kinds(events)
    assert n.get("repeated_frame") == 1 and n.get("resync", 0) >= 1
    assert not {"gap", "seq_gap", "stream_restart", "stale_frame"} & set(n)
    rep = next(e for e in events if e["kind"] == "repeated_frame")["detail"]
    frame_bytes = 22 + 16 * 32 * 3 + 2
    assert 5000 // frame_bytes - 1 <= rep["frames"] <= 5000 // frame_bytes  # whole frames in the span
    assert rep["samples"] == 32 * rep["frames"]


# -- arguments -------------------------------------------------------------------------------
def test_url_options_are_split_from_pyserials():
    assert split_url("socket://127.0.0.1:5?rig=a%20b.toml&logging=debug&fs_hz=100") == (
        "socket://127.0.0.1:5?logging=debug", {"rig": "a b.toml", "fs_hz": "100"})
    assert split_url("/dev/ttyUSB0") == ("/dev/ttyUSB0", {})
    with pytest.raises(ValueError, match="channels"):
        SerialDevice("/dev/null?channels=x")
    with pytest.raises(ValueError, match="fs_hz given both"):
        SerialDevice("/dev/null?fs_hz=1", fs_hz=2)
    with pytest.raises(ValueError, match="rig's 16"):
        SerialDevice("/dev/null", rig=RIG, channels=4)


def test_missing_port_is_not_found_naming_it(tmp_path):
    with pytest.raises(DeviceNotFound, match=re.escape(str(tmp_path / "nope"))):
        open_device(f"serial://{tmp_path / 'nope'}")


def test_record_says_a_lost_port_when_it_is_lost_and_records_why_it_ended(tmp_path):
    """``ramdaq record`` from a front-end killed mid-stream: nothing was said until the
    give-up (the port_lost fault waited for a block that never came) and neither port_lost nor
    device_error was in the file. Now the loss is said at once -- well before the give-up --
    and both are recorded, then the give-up is raised with the file finished."""
    path, said, give_up = tmp_path / "killed.mcap", [], 2.0
    with emulator(tmp_path, "tcp", "--pace", "realtime", duration=60.0) as (proc, address):
        dev = SerialDevice(address, rig=RIG, reconnect_s=0.05, give_up_s=give_up)
        killer = threading.Timer(0.5, proc.kill)
        started = []

        def first_block(_block):
            if not started:
                started.append(killer.start())

        with pytest.raises(DeviceClosed, match=re.escape(address)):
            record(dev, path, readout=False, progress=first_block,
                   say=lambda line: said.append((time.monotonic(), line)))
        ended = time.monotonic()
    lost = [t for t, line in said if " lost (" in line]
    # said once, when lost: at least the give-up minus one fault poll (0.25 s) before the end
    assert len(lost) == 1 and ended - lost[0] >= give_up - 0.25 - 0.1, said
    blocks, events = replay(path)
    n = kinds(events)
    assert blocks and n["port_lost"] == 1 and n["device_error"] == 1, n
    end = next(e for e in events if e["kind"] == "device_error")
    assert address in end["detail"]["message"] and end["t_ns"] == sample_time_ns(
        blocks[-1].next_sample, 2048.0)
