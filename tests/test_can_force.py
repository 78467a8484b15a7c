"""A rig's force channel over CAN and serial (issue 18: a force channel as a channel kind
everywhere): a rig with ``[[forces]]`` streams its force in N through the frame descriptions
(the ``fd24_force`` DBC on python-can's virtual bus; the serial frames on a real pty), it is
recorded bit for bit as the simulator made it, and the trigger's force mode runs on it.
"""

from __future__ import annotations

import threading
import uuid
from pathlib import Path

import can
import numpy as np
import pytest

import ramdaq.drivers.can_frames as cf
from ramdaq.daq.trigger import Trigger
from ramdaq.drivers.can_device import CanDevice
from ramdaq.drivers.emulators.can_emulator import CanEmulator, send_frames
from ramdaq.drivers.registry import open_device
from ramdaq.drivers.rig_channels import force_scale_N, rig_channels
from ramdaq.drivers.sim import SimDevice
from tests.test_serial_device import emulator

pytestmark = pytest.mark.timeout(120)

REPO = Path(__file__).resolve().parent.parent
RIGS = REPO / "recordings" / "rigs"
FORCE = '\n[[forces]]\nname = "ram"\nchannel = 16\n'
BLOW_S, DURATION_S, SEED = 0.6, 2.0, 4


@pytest.fixture(scope="module")
def force_rig(tmp_path_factory) -> Path:
    """The ALBACORE-like rig (16 gages, 24 bits) with the ram's load cell on channel 17."""
    p = tmp_path_factory.mktemp("rig") / "albacore-force.toml"
    p.write_text((RIGS / "albacore.toml").read_text() + FORCE)
    return p


def _sim(rig: Path) -> SimDevice:
    return SimDevice(rig, seed=SEED, duration_s=DURATION_S, impacts=[BLOW_S], pace="fast")


def _truth(rig: Path) -> np.ndarray:
    with _sim(rig) as dev:
        return np.hstack([b.counts for b in dev])


def _check_stream(info, blocks, truth: np.ndarray) -> None:
    """Channel 17 is the ram in N (gage 0) at the rig's force scale, every count as the
    simulator made it, and the trigger finds the blow in force mode."""
    assert info.channels[-1] == "ram" and info.units[-1] == "N" and info.gages[-1] == 0
    assert info.units[:16] == ("m/s^2",) * 16
    counts = np.hstack([b.counts for b in blocks])
    np.testing.assert_array_equal(counts, truth[:, :counts.shape[1]])
    assert counts.shape[1] >= 0.9 * truth.shape[1]  # whole cycles/frames: at most one lost at the end
    trig = Trigger(info)
    events = [e for b in blocks for e in trig.process(b)] + trig.flush()
    assert trig.mode == "force" and len(events) == 1
    # the sim's force is not filtered; the trigger removes the rig's anti-alias delay: 2 samples
    assert abs(events[0].onset_s - BLOW_S) < 2 / info.fs_hz + trig.delay_s
    assert events[0].peak["ram"] > 0.5 * max(abs(truth[-1])) * blocks[0].scale[-1]


def test_rig_channels_put_the_force_after_the_gages(force_rig):
    from ramdaq.analysis.model.rig import load_rig

    rig = load_rig(force_rig)
    ch = rig_channels(rig)
    assert ch.names[-1] == "ram" and ch.units[-1] == "N" and len(ch.names) == 17
    # 4 times the rig's blow over the 24-bit ADC's range
    assert ch.scales[-1] == force_scale_N(rig) == 4 * rig.impact.peak_force_N / (2**23 - 1)
    with _sim(force_rig) as dev:  # the simulator streams the same
        assert dev.info.channels == ch.names and dev.info.units == ch.units
        np.testing.assert_array_equal(next(iter(dev)).scale, ch.scales)


def test_force_channel_over_can_fd_virtual_bus(force_rig):
    """fd24_force: the 16 gages in group 1 (fd24's frames), the ram in group 2."""
    name = f"ramdaq-{uuid.uuid4().hex[:8]}"
    dev = CanDevice(f"virtual/{name}", dbc="fd24_force", rig=str(force_rig), idle_s=0.5)
    info = dev.open()
    emu = CanEmulator(cf.FrameCodec("fd24_force"), _sim(force_rig))
    tx = can.Bus(interface="virtual", channel=name)
    error: list[BaseException] = []

    def run() -> None:
        try:
            send_frames(emu.frames(), dict.fromkeys(emu.codec.groups, tx), "fast")
        except BaseException as err:  # handed to the test
            error.append(err)

    th = threading.Thread(target=run, name="can-emulator")
    th.start()
    try:
        blocks = list(dev)
    finally:
        th.join()
        tx.shutdown()
        dev.close()
    assert not error, error
    assert info.extra["groups"] == {"1": list(range(1, 17)), "2": [17]}
    _check_stream(info, blocks, _truth(force_rig))


def test_sixteen_gage_rig_reads_only_the_gage_group(tmp_path):
    """The same DBC with a rig of 16 channels: group 1 only (the force group has no channel)."""
    dev = CanDevice(f"virtual/ramdaq-{uuid.uuid4().hex[:8]}", dbc="fd24_force",
                    rig=str(RIGS / "albacore.toml"), idle_s=0.2)
    assert sorted(dev.groups) == [1]


def test_force_channel_over_serial_pty(force_rig, tmp_path):
    """The serial emulator on a real pty sends the rig's 17 channels; the device names the
    ram's in N from the rig."""
    with emulator(tmp_path, "pty", duration=DURATION_S, impacts=[BLOW_S], rig=force_rig,
                  seed=SEED) as (_, address):
        with open_device(f"serial://{address}?rig={force_rig}") as dev:
            info, blocks = dev.info, list(dev)
    _check_stream(info, blocks, _truth(force_rig))
