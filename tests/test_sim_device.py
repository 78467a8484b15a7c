"""The simulated device: block stream contract, determinism, pacing, impacts on command."""

import time

import numpy as np
import pytest

from ramdaq.drivers.block import sample_time_ns
from ramdaq.drivers.errors import DeviceClosed, DeviceNotFound
from ramdaq.drivers.registry import open_device
from ramdaq.drivers.sim import SimDevice


def _all(dev):
    with dev:
        return list(dev)


def test_stream_is_contiguous_and_described(albacore):
    blocks = _all(SimDevice(albacore, duration_s=1.0, impacts=[0.3], block_s=0.05))
    fs = albacore.daq.sample_rate_hz
    assert sum(b.n_samples for b in blocks) == round(1.0 * fs)
    for i, (a, b) in enumerate(zip(blocks, blocks[1:], strict=False)):
        assert b.seq == a.seq + 1 == i + 1
        assert b.first_sample == a.next_sample
        assert b.t0_ns == sample_time_ns(b.first_sample, fs)
    assert blocks[0].counts.shape[0] == 16 and blocks[0].counts.dtype == np.int32


def test_deterministic_under_seed_and_pace(albacore):
    """Same seed -> same counts, fast or real-time; another seed -> different noise."""
    kw = dict(duration_s=0.3, impacts=[0.1], block_s=0.05)
    fast = _all(SimDevice(albacore, seed=7, **kw))
    t = time.monotonic()
    paced = _all(SimDevice(albacore, seed=7, pace="realtime", **kw))
    elapsed = time.monotonic() - t
    other = _all(SimDevice(albacore, seed=8, **kw))
    assert all(a.same_as(b) for a, b in zip(fast, paced, strict=True))
    assert not all(a.same_as(b) for a, b in zip(fast, other, strict=True))
    # real-time pacing cannot deliver 0.3 s of samples much sooner than 0.3 s
    assert elapsed >= 0.25


def test_impact_rings_the_rudder_and_is_recorded_as_truth(albacore):
    dev = SimDevice(albacore, duration_s=1.0, impacts=[0.5], noise=False)
    blocks = _all(dev)
    x = np.hstack([b.values() for b in blocks])
    fs = albacore.daq.sample_rate_hz
    before, after = x[:, : int(0.5 * fs)], x[:, int(0.5 * fs):]
    assert np.abs(before).max() == 0  # no ambient on this rig, no noise: silence before the hit
    assert np.abs(after).max() > 1.0  # a 20 kN blow on a 2.9 t rudder: m/s^2 and more
    assert dev.delivered_impacts[0].t_s == 0.5


def test_impact_on_command(albacore):
    dev = SimDevice(albacore, duration_s=0.5, noise=False, block_s=0.05)
    with dev:
        first = dev.read()
        blow = dev.impact()
        rest = list(dev)
    assert blow.t_s == pytest.approx(first.n_samples / albacore.daq.sample_rate_hz)
    assert np.abs(first.values()).max() == 0
    assert np.abs(rest[0].values()).max() > 0


def test_noise_floor_matches_rig(albacore):
    """Noise-only stream: rms within 5 % of the rig's floor, after the anti-alias filter
    (which passes 800/1024 of the band; the 5 % is the statistics of 16 x 20k samples plus it)."""
    blocks = _all(SimDevice(albacore, duration_s=10.0, anti_alias=False))
    x = np.hstack([b.values() for b in blocks])
    assert np.std(x) == pytest.approx(albacore.daq.noise_m_s2_rms, rel=0.05)


def test_registry_and_lifecycle(albacore):
    dev = open_device("sim", rig=albacore, duration_s=0.1)
    assert dev.info.channels[0] == "g01" and dev.info.rig_toml == albacore.text
    dev.close()
    dev.close()  # safe twice
    with pytest.raises(DeviceClosed):
        dev.read()
    with pytest.raises(DeviceNotFound, match="no device back-end named 'nope'"):
        open_device("nope")


def test_sampson_ambient_tone_before_the_hit(sampson):
    """The SAMPSON-like rig's hull vibrates at 2.18 Hz before any impact (Report Figure 6a)."""
    blocks = _all(SimDevice(sampson, duration_s=4.0, noise=False))
    x = np.hstack([b.values() for b in blocks])
    fs = sampson.daq.sample_rate_hz
    spec = np.abs(np.fft.rfft(x[12] * np.hanning(x.shape[1])))
    f = np.fft.rfftfreq(x.shape[1], 1 / fs)
    # the spectral peak is within one bin (0.25 Hz) of 2.18 Hz
    assert abs(f[np.argmax(spec)] - 2.18) <= 0.25
