"""The record's end at the noise floor (daq/decay_end.py): where it falls on a known decay, that
noise alone is at the floor at once, and that blocks of any size give the same end."""

import math

import numpy as np
import pytest

from ramdaq.daq.decay_end import (
    HOLD_WINDOWS,
    FloorWatch,
    floor_threshold,
    noise_bandwidth_fraction,
)

FS = 2048.0
SIGMA = 0.005  # m/s^2 rms, the rigs' noise floor


def _decay(seed: int, n_s: float = 20.0, amp: float = 1.0, alpha: float = 0.45,
           f_hz: float = 13.0) -> tuple[np.ndarray, np.ndarray]:
    """Three gages ringing at ``f_hz`` (amplitudes amp, amp/2, amp/100) decaying at ``alpha``
    1/s from sample 0, in white noise ``SIGMA``; and the noiseless ringing power of gage 0."""
    rng = np.random.default_rng(seed)
    t = np.arange(round(n_s * FS)) / FS
    ring = np.exp(-alpha * t) * np.sin(2 * np.pi * f_hz * t)
    x = np.array([amp, amp / 2, amp / 100])[:, None] * ring + rng.normal(0, SIGMA, (3, t.size))
    return x, (amp * np.exp(-alpha * t)) ** 2 / 2


def _watch(min_n: int = 0) -> FloorWatch:
    return FloorWatch.begin(np.full(3, SIGMA ** 2), 0, min_n, FS, 1.0)


def test_noise_alone_is_at_the_floor_after_the_hold():
    """Every window of white noise passes the 3-sigma test but for 0.13 % of them: over 20
    seeds the end is the hold's last sample in all but (expected) 0.05 of them."""
    ends = []
    for seed in range(20):
        x = np.random.default_rng(seed).normal(0, SIGMA, (3, round(2 * FS)))
        w = _watch()
        ends.append(w.scan(lambda a, b, x=x: x[:, a:b], x.shape[1]))
    assert ends.count(HOLD_WINDOWS * w.window - 1) >= 19


def test_the_record_ends_where_the_ringing_sinks_into_the_noise():
    """A 1 m/s^2 ringing (46 dB over the noise) decaying at 0.45 1/s: the end lies where the
    loud gages' ringing power is at most the threshold's margin over the noise (a window
    of ringing 3 margins above the noise would fail), and no later than where the ringing is
    1 % of the noise power (then every window passes bar 0.13 %)."""
    x, power = _decay(1)
    w = _watch()
    end = w.scan(lambda a, b: x[:, a:b], x.shape[1])
    assert end is not None
    # the loud gages are watched, the one 40 dB down is not
    assert list(w.rows) == [0, 1]
    margin = floor_threshold(w.window, 1.0) - 1.0
    # mean over the two watched gages of ringing power / noise power, at the record's end
    rel = (power[end] + power[end] / 4) / 2 / SIGMA ** 2
    assert rel <= 3 * margin
    # (1 + 1/4) / 2 * amp^2 / 2 * exp(-2 alpha t) = 0.01 sigma^2
    t_quiet = math.log((1 + 0.25) / 4 / (0.01 * SIGMA ** 2)) / (2 * 0.45)
    assert end / FS <= t_quiet


def test_blocks_of_any_size_give_the_same_end():
    """Live, the watch sees the samples block by block; a replay in other blocks ends the
    record at the same sample (the windows are aligned to the onset, not to the blocks)."""
    x, _ = _decay(2)
    w = _watch(round(2 * FS))
    whole = w.scan(lambda a, b: x[:, a:b], x.shape[1])
    for block in (1, 37, 102, 4096):
        w = _watch(round(2 * FS))
        end = None
        for stop in range(block, x.shape[1] + block, block):
            end = w.scan(lambda a, b: x[:, a:b], min(stop, x.shape[1]))
            if end is not None:
                break
        assert end == whole, block


def test_the_minimum_length_holds_however_quiet():
    """Noise alone from the onset: the record still runs the minimum length (2 s) first."""
    x = np.random.default_rng(3).normal(0, SIGMA, (3, round(4 * FS)))
    w = _watch(round(2 * FS))
    end = w.scan(lambda a, b: x[:, a:b], x.shape[1])
    assert end is not None and end >= round(2 * FS)


@pytest.mark.parametrize(("anti_alias", "fs", "expected"), [
    # 4th-order Butterworth at 800 Hz: noise bandwidth 800 * (pi/8)/sin(pi/8) = 820.9 Hz
    ((4, 800.0), 2048.0, 820.9 / 1024),
    ((4, 800.0), 25600.0, 820.9 / 12800),
    (None, 2048.0, 1.0),  # no filter named: white to Nyquist
])
def test_noise_bandwidth_of_the_anti_alias_filter(anti_alias, fs, expected):
    assert noise_bandwidth_fraction(anti_alias, fs) == pytest.approx(expected, rel=1e-4)
