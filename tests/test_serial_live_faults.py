"""A serial front-end that goes quiet, vanishes or sends the wrong layout, as a new user met them
(issue: front-ends, /tmp/t7): a real pty, frames written by a thread as a front-end writes them,
the real SerialDevice and the live trial Session. What the session says is asserted line by line;
what the recording holds, event by event, at its stream time.

No timing is asserted: the front-end's pauses (1.5 s) are five times ``quiet_s`` (0.3 s), so
the silence is seen whatever the load; its stream time comes from the samples, not the clock.
"""

from __future__ import annotations

import os
import re
import threading
import time
import tty
from pathlib import Path

import numpy as np
import pytest

from ramdaq.daq.record import record
from ramdaq.daq.session import Session
from ramdaq.drivers.base import DeviceFault
from ramdaq.drivers.block import sample_time_ns
from ramdaq.drivers.can_frames import REJECTIONS
from ramdaq.drivers.errors import DeviceClosed
from ramdaq.drivers.fault_words import FaultWords, describe
from ramdaq.drivers.mcap_replay import McapReplayDevice
from ramdaq.drivers.serial_device import SerialDevice
from ramdaq.drivers.serial_frames import FLAG_END, encode_frame
from ramdaq.drivers.sim import SimDevice

pytestmark = pytest.mark.timeout(60)

RIG = Path(__file__).resolve().parent.parent / "recordings" / "rigs" / "albacore.toml"
FS, NS = 2048.0, 32  # the rig's rate; samples per frame


def _frames(first_seq: int, n: int, channels: int) -> bytes:
    rng = np.random.default_rng(first_seq)
    return b"".join(encode_frame(k, k * NS, rng.integers(-1000, 1000, (channels, NS)))
                    for k in range(first_seq, first_seq + n))


def _front_end(script: list) -> tuple[str, threading.Thread, threading.Event]:
    """A pty whose master side plays ``script`` once the event is set (the port opened: pyserial's
    open flushes what was waiting): bytes to write, or seconds to pause; then the port vanishes
    (both sides closed)."""
    master, slave = os.openpty()
    tty.setraw(slave)
    name = os.ttyname(slave)
    go = threading.Event()

    def play() -> None:
        go.wait(30)
        for step in script:
            if isinstance(step, bytes):
                os.write(master, step)
            else:
                time.sleep(step)
        os.close(master)
        os.close(slave)

    th = threading.Thread(target=play, name="front-end", daemon=True)
    th.start()
    return name, th, go


def _trial(tmp_path: Path, script: list, quiet_s: float = 0.3
           ) -> tuple[str, list[str], list[dict], object]:
    port, th, go = _front_end(script)
    dev = SerialDevice(port, rig=str(RIG), quiet_s=quiet_s, reconnect_s=0.1, give_up_s=0.5)
    dev.open()
    go.set()
    shown: list[str] = []
    out = Session(dev, record_path=tmp_path / "t.mcap", readout=False, log=shown.append).run()
    th.join(10)
    with McapReplayDevice(tmp_path / "t.mcap") as back:
        events = back.events()
    return f"serial://{port}", shown, events, out


def test_silence_then_data_then_vanish_said_when_they_happen(tmp_path):
    n = 16  # frames before and after the silence: 0.25 s of samples each
    garbage = b"\x00half a frame from before the connect\xeb\x90\x01"
    device, shown, events, out = _trial(tmp_path, [
        garbage + _frames(0, n, 16), 1.5, _frames(n, n, 16), 1.5])
    t_quiet = sample_time_ns(n * NS, FS) / 1e9
    said = [s for s in shown if s.startswith((device, "no data", "data from", "device"))]
    assert said[0] == f"no data from {device} for 0.3 s (stream time {t_quiet:.3f} s)"
    assert said[1].startswith(f"data from {device} again after ")
    assert said[2] == f"no data from {device} for 0.3 s (stream time {2 * t_quiet:.3f} s)"
    assert said[3].startswith(f"{device} at {2 * t_quiet:.3f} s: port {device[9:]} lost (")
    assert said[3].endswith("reconnecting every 0.1 s, giving up after 0.5 s")
    assert said[4] == (f"device ended the stream: serial: {device[9:]} vanished and did not "
                       "come back within 0.5 s")
    assert said[5] == "device faults: 2 silence(s) of the device, 1 lost port(s) or bus(es)"
    assert len(said) == 6 and out.notes  # the connect's stray bytes: recorded, not said
    ev = [(e["kind"], e["t_ns"]) for e in events]
    assert ev == [("resync", 0), ("no_data", sample_time_ns(n * NS, FS)),
                  ("data_back", sample_time_ns(n * NS, FS)),
                  ("no_data", sample_time_ns(2 * n * NS, FS)),
                  ("port_lost", sample_time_ns(2 * n * NS, FS)),
                  ("device_error", sample_time_ns(2 * n * NS, FS))]
    assert events[0]["detail"]["at_connect"] is True


def test_one_corrupt_frame_is_one_line(tmp_path):
    good = _frames(0, 20, 16)
    size = len(good) // 20
    bad = bytearray(good)
    bad[10 * size + 30] ^= 0xFF  # a payload byte of frame 10
    device, shown, events, _ = _trial(tmp_path, [bytes(bad), 0.5], quiet_s=5.0)
    t = sample_time_ns(10 * NS, FS) / 1e9
    said = [s for s in shown if s.startswith(device)]
    assert said[0] == (f"{device} at {t:.3f} s: 1 corrupt frame dropped (CRC failed); "
                       f"{size} stray bytes skipped to the next frame; 32 samples (0.016 s) missing")
    assert said[1].startswith(f"{device} at {20 * NS / FS:.3f} s: port ")
    assert len(said) == 2
    kinds = [e["kind"] for e in events]
    assert kinds[:3] == ["crc_error", "resync", "seq_gap"]  # each still an event


def test_wrong_channel_count_said_once_and_counted(tmp_path):
    n = 100  # frames of 8 channels to a rig of 16
    device, shown, events, out = _trial(tmp_path, [_frames(0, n, 8), 1.0])
    said = [s for s in shown if s.startswith((device, "no data", "device"))]
    assert said[0] == f"{device} at 0.000 s: device sends 8 channels, the rig expects 16: frames refused"
    assert said[1].startswith(f"{device} at 0.000 s: port ")
    assert said[2].startswith("device ended the stream: ")
    assert said[3] == (f"device faults: {n} frame(s) refused for a wrong channel count, "
                       "1 lost port(s) or bus(es)")
    assert len(said) == 4  # and no "no data": the refused frames say why
    refused = [e["detail"] for e in events if e["kind"] == "frame_mismatch"]
    assert sum(d["frames"] for d in refused) == refused[-1]["total"] == n
    assert out.samples == 0


def test_refused_run_between_good_frames_counted_whole(tmp_path):
    """Ten frames of a wrong channel count between good ones, within one report interval: the
    first is said at once, and the closing count has all ten (the run's end reports the rest)."""
    end = encode_frame(50, 50 * NS, np.zeros((16, 0), dtype=np.int64), flags=FLAG_END)
    frames = _frames(0, 20, 16) + _frames(20, 10, 12) + _frames(30, 20, 16) + end
    device, shown, events, _ = _trial(tmp_path, [frames, 1.0])  # ends by its end frame
    tally = [s for s in shown if s.startswith("device faults: ")]
    assert len(tally) == 1 and "10 frame(s) refused for a wrong channel count" in tally[0]
    refused = [e["detail"] for e in events if e["kind"] == "frame_mismatch"]
    assert sum(d["frames"] for d in refused) == refused[-1]["total"] == 10


def test_record_loop_records_the_silence(tmp_path):
    """``ramdaq record``'s plain loop (``for block in device``) notes the silence too: the
    device reads itself with a timeout underneath."""
    n = 16
    port, th, go = _front_end([_frames(0, n, 16), 1.5, _frames(n, n, 16), 0.5])
    dev = SerialDevice(port, rig=str(RIG), quiet_s=0.3, reconnect_s=0.1, give_up_s=0.3)
    dev.open()
    go.set()
    with pytest.raises(DeviceClosed):
        record(dev, tmp_path / "r.mcap", readout=False)
    th.join(10)
    with McapReplayDevice(tmp_path / "r.mcap") as back:
        events = back.events()
    t = sample_time_ns(n * NS, FS)
    assert [(e["kind"], e["t_ns"]) for e in events][:2] == [("no_data", t), ("data_back", t)]


def test_record_loop_says_each_fault_as_it_comes(tmp_path):
    """``ramdaq record`` tells a corrupt frame in the same one line a live trial does (it used to
    record it and say nothing until the summary)."""
    good = _frames(0, 20, 16)
    size = len(good) // 20
    bad = bytearray(good)
    bad[10 * size + 30] ^= 0xFF  # a payload byte of frame 10
    port, th, go = _front_end([bytes(bad), 0.5])
    dev = SerialDevice(port, rig=str(RIG), quiet_s=5.0, reconnect_s=0.1, give_up_s=0.3)
    dev.open()
    go.set()
    said: list[str] = []
    with pytest.raises(DeviceClosed):
        record(dev, tmp_path / "r.mcap", readout=False, say=said.append)
    th.join(10)
    device = f"serial://{port}"
    t = sample_time_ns(10 * NS, FS) / 1e9
    assert said[0] == (f"{device} at {t:.3f} s: 1 corrupt frame dropped (CRC failed); "
                       f"{size} stray bytes skipped to the next frame; 32 samples (0.016 s) missing")


def test_every_fault_a_driver_reports_has_words():
    """Each fault kind the drivers emit (found in their source) is told in words, not as the
    fallback that spells the kind and its dict."""
    src = "".join(p.read_text() for p in (RIG.parents[2] / "drivers").glob("*.py"))
    kinds = set(re.findall(r'(?:_fault|_count|SeqNote|_drop_side)\("([a-z_]+)"', src))
    kinds |= set(re.findall(r'return "([a-z_]+_frame)"', src)) | set(REJECTIONS)
    assert {"no_data", "port_lost", "bus_lost", "frame_mismatch", "late_frame"} <= kinds
    for kind in sorted(kinds):
        words = describe(DeviceFault(kind, 0, {"count": 2}), "dev", FS)
        assert words and "(count 2)" not in words, (kind, words)  # the fallback spells the dict


def test_fault_lines_hide_connect_noise_and_group_one_incident():
    w = FaultWords("serial://x", FS)
    connect = DeviceFault("resync", 0, {"bytes_discarded": 1096, "at_connect": True})
    crc = DeviceFault("crc_error", 5 * 10**9, {"count": 1})
    resync = DeviceFault("resync", 5 * 10**9, {"bytes_discarded": 1560})
    gap = DeviceFault("seq_gap", 5 * 10**9, {"missing_samples": 32})
    assert w.lines([connect]) == []
    assert w.lines([crc, resync]) == ["serial://x at 5.000 s: 1 corrupt frame dropped (CRC failed); "
                                      "1560 stray bytes skipped to the next frame"]
    assert w.lines([gap]) == []  # the same incident, reported with the next block
    assert w.tally() == "device faults: 1 corrupt frame(s), 1 gap(s) in the frame sequence"
    can = FaultWords("can://slcan/x", FS)  # a CAN frame of the wrong length and the cycle it lost
    dlc = DeviceFault("wrong_dlc", sample_time_ns(10128, FS), {"count": 1, "id": "0x40f", "dlc": 6})
    lost = DeviceFault("seq_gap", sample_time_ns(10126, FS), {"missing_samples": 3})
    assert can.lines([dlc, lost]) == ["can://slcan/x at 4.944 s: 1 frame of the wrong length "
                                      "dropped (id 0x40f, 6 bytes); 3 samples (0.001 s) missing"]


class _CtrlCAfter(SimDevice):
    """The simulator, until Ctrl-C comes during the read of block ``n``."""

    def __init__(self, n: int) -> None:
        super().__init__(RIG, seed=1, duration_s=10.0, impacts=[], pace="fast")
        self.n = n

    def _read(self, timeout):
        if self._seq_read == self.n:
            raise KeyboardInterrupt
        self._seq_read += 1
        return super()._read(timeout)

    _seq_read = 0


def test_interrupted_event_carries_the_stream_time(tmp_path):
    out = Session(_CtrlCAfter(7), record_path=tmp_path / "c.mcap", readout=False).run()
    with McapReplayDevice(tmp_path / "c.mcap") as back:
        events = back.events()
    assert out.interrupted and out.samples > 0
    assert [(e["kind"], e["t_ns"]) for e in events] == [("interrupted", sample_time_ns(out.samples, FS))]


def test_quiet_s_is_a_query_key_and_must_be_positive():
    assert SerialDevice("/dev/ttyNONE?quiet_s=2.5").quiet_s == 2.5
    assert SerialDevice("/dev/ttyNONE").quiet_s == 1.0  # drivers.base.QUIET_S
    with pytest.raises(ValueError, match=r"^serial: quiet_s \(0.0\) must be positive$"):
        SerialDevice("/dev/ttyNONE?quiet_s=0")
