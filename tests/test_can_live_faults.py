"""A CAN front-end that says nothing, or whose adapter vanishes (issue: front-ends, /tmp/t7):
python-can's virtual bus, and an slcan adapter on a real pty through the live trial Session.

No timing is asserted: pauses are several times ``quiet_s``; stream times come from samples.
"""

from __future__ import annotations

import os
import select
import subprocess
import sys
import threading
import time
import tty
import uuid

import pytest

from ramdaq.daq.session import Session
from ramdaq.drivers.can_device import CanDevice
from ramdaq.drivers.can_frames import FrameCodec
from ramdaq.drivers.emulators.can_emulator import CanEmulator, rig_with_adc_bits, slcan_line
from ramdaq.drivers.errors import DeviceTimeout
from ramdaq.drivers.mcap_replay import McapReplayDevice
from ramdaq.drivers.sim import SimDevice
from tests.conftest import RIGS

REPO = RIGS.parent.parent

pytestmark = pytest.mark.timeout(60)


@pytest.fixture(scope="module")
def rig16(tmp_path_factory):
    path = tmp_path_factory.mktemp("rig") / "r16.toml"
    path.write_text(rig_with_adc_bits((RIGS / "sampson.toml").read_text(), 16))
    return path


def test_nothing_on_a_virtual_bus_is_no_data_at_stream_time_zero(rig16):
    dev = CanDevice(f"virtual/{uuid.uuid4().hex}?quiet_s=0.2", dbc="classic", rig=str(rig16))
    with dev:
        faults = []
        for _ in range(4):  # 4 x 0.1 s: at least 0.2 s of nothing
            with pytest.raises(DeviceTimeout):
                dev.read(timeout=0.1)
            faults += dev.take_faults()
        time.sleep(0.3)
        with pytest.raises(DeviceTimeout):
            dev.read(timeout=0.1)
        faults += dev.take_faults()
    assert [(f.kind, f.t_ns, f.detail["quiet_s"]) for f in faults] == [("no_data", 0, 0.2)]


def _adapter(pause_s: float, wait_s: float = 5.0) -> tuple[str, threading.Thread]:
    """An slcan adapter on a pty: answers the host's commands, sends no frame, and vanishes
    ``pause_s`` after the host opened the channel (or after ``wait_s`` without a command)."""
    master, slave = os.openpty()
    tty.setraw(slave)

    def run() -> None:
        got = b""
        while b"O\r" not in got and select.select([master], [], [], wait_s)[0]:
            data = os.read(master, 100)
            got += data
            os.write(master, b"\r" * data.count(b"\r"))

    return _play(master, slave, run, pause_s, "slcan-adapter")


def _play(master: int, slave: int, run, linger_s: float, name: str) -> tuple[str, threading.Thread]:
    """``run()`` on a daemon thread, then the pty closed ``linger_s`` later (the adapter
    vanishes); the host's port name and the thread."""
    def play() -> None:
        run()
        time.sleep(linger_s)
        os.close(master)
        os.close(slave)

    th = threading.Thread(target=play, name=name, daemon=True)
    th.start()
    return os.ttyname(slave), th


def test_slcan_adapter_that_vanishes_ends_the_trial_as_a_failure(tmp_path, rig16):
    port, th = _adapter(pause_s=1.5)
    dev = CanDevice(f"slcan/{port}?sleep_after_open=0&quiet_s=0.3", dbc="classic", rig=str(rig16))
    shown: list[str] = []
    out = Session(dev, record_path=tmp_path / "t.mcap", readout=False, log=shown.append).run()
    th.join(10)
    device = f"can://slcan/{port}"
    said = [s for s in shown if s.startswith((device, "no data", "device"))]
    assert said[0] == f"no data from {device} for 0.3 s (stream time 0.000 s)"
    assert said[1].startswith(f"{device} at 0.000 s: CAN bus slcan/{port} lost (")
    assert said[2].startswith(f"device ended the stream: can: slcan/{port} lost (")
    assert said[2].endswith("): the device vanished")
    assert said[3] == "device faults: 1 silence(s) of the device, 1 lost port(s) or bus(es)"
    assert len(said) == 4 and out.notes and out.samples == 0  # cli: exit 1, the note on stderr
    with McapReplayDevice(tmp_path / "t.mcap") as back:
        events = back.events()
    assert [(e["kind"], e["t_ns"]) for e in events] == [("no_data", 0), ("bus_lost", 0),
                                                        ("device_error", 0)]


def test_cli_trial_on_a_vanished_slcan_adapter_exits_1_with_one_line(tmp_path, rig16):
    port, th = _adapter(pause_s=1.0, wait_s=60.0)  # the command's start-up is not timed
    url = f"can://slcan/{port}?sleep_after_open=0&quiet_s=0.3&dbc=classic&rig={rig16}"
    r = subprocess.run([sys.executable, "-m", "ramdaq", "trial", "--device", url, "--no-rerun",
                        "--out", str(tmp_path / "t.mcap"), "--quiet"], cwd=tmp_path,
                       env={**os.environ, "PYTHONPATH": str(REPO)}, capture_output=True,
                       text=True, timeout=90)
    th.join(10)
    assert r.returncode == 1, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(
        f"ramdaq trial: the device ended the stream: can: slcan/{port} lost ("), r.stderr
    assert f"no data from can://slcan/{port} for 0.3 s (stream time 0.000 s)" in r.stdout
    assert f"can://slcan/{port} at 0.000 s: CAN bus slcan/{port} lost (" in r.stdout



def _adapter_with_a_torn_first_line(rig, duration_s: float) -> tuple[str, threading.Thread]:
    """An slcan adapter whose first bytes after the host opened the channel are the tail of a
    line it was sending before (as the user's adapter was), then frames at real-time pace; it
    stays up 2 s after the last."""
    master, slave = os.openpty()
    tty.setraw(slave)
    sim = SimDevice(rig, seed=1, duration_s=duration_s, impacts=[], pace="fast")
    emu = CanEmulator(FrameCodec("classic"), sim)
    opened = threading.Event()

    def answer() -> None:  # the host's commands (S8, O, ...) each get a CR
        try:
            while (data := os.read(master, 100)):
                os.write(master, b"\r" * data.count(b"\r"))
                if b"O\r" in data:
                    opened.set()
        except OSError:
            return

    def run() -> None:
        threading.Thread(target=answer, daemon=True).start()
        opened.wait(10)
        os.write(master, b"100010000000000\r")  # the tail of a line cut by the connect
        with sim:
            t0 = time.monotonic()
            for w in emu.frames():
                if (wait := t0 + w.t_s - time.monotonic()) > 0:
                    time.sleep(wait)
                if (line := slcan_line(w.msg)) is not None:
                    os.write(master, line)

    return _play(master, slave, run, 2.0, "slcan-torn-first-line")


def test_a_torn_first_line_at_connect_is_recorded_not_said(tmp_path, rig16):
    port, th = _adapter_with_a_torn_first_line(rig16, duration_s=1.0)
    dev = CanDevice(f"slcan/{port}?sleep_after_open=0&idle_s=0.3", dbc="classic", rig=str(rig16))
    shown: list[str] = []
    out = Session(dev, record_path=tmp_path / "t.mcap", readout=False, log=shown.append).run()
    th.join(10)
    with McapReplayDevice(tmp_path / "t.mcap") as back:
        events = back.events()
    assert [(e["kind"], e["detail"]["at_connect"]) for e in events] == [("bad_frame", True)]
    assert [s for s in shown if s.startswith((f"can://slcan/{port}", "device"))] == [], shown
    assert out.samples == 3 * (2048 // 3) and not out.notes  # every whole 3-sample cycle of the second
