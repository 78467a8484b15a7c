"""A blow struck into a ringing that the innovation scan cannot see, found by its energy.

The records here are plain numpy, not the simulator: damped sines that start from rest (a user's
generator, or a gage far from the ram whose response starts smoothly). At 25.6 kHz the kink of
such a start is below the noise per sample, so the AR filter predicts it and the second-contact
scan sees nothing; before the energy watch the trigger merged the blow into the last record (a
9.7 s "decay" holding two blows, analysed as three modes near 24 Hz)."""

from __future__ import annotations

import numpy as np
import pytest

from ramdaq.daq.trigger import Trigger
from ramdaq.drivers.array_device import ArrayDevice

pytestmark = pytest.mark.timeout(120)

NOISE = 0.005  # m/s^2 rms, white
F_HZ, DELTA = (24.0, 180.0), (0.045, 0.012)
SHAPES = np.array([[1.0, 0.3], [0.7, -0.4], [0.4, 0.5], [0.1, 0.2]])  # 4 gages x 2 modes


def ringing(fs: float, blows: list[tuple[float, float]], duration_s: float, seed: int = 0,
            f_hz=F_HZ, delta=DELTA, shapes=SHAPES) -> np.ndarray:
    """(n_gages, n) m/s^2: each blow (time s, size) a sum of damped sines from rest."""
    t = np.arange(int(duration_s * fs)) / fs
    x = np.zeros((shapes.shape[0], t.size))
    for t0, size in blows:
        tau = t[t >= t0] - t0
        for f, d, shape in zip(f_hz, delta, shapes.T, strict=True):
            x[:, t >= t0] += size * shape[:, None] * np.exp(-d * f * tau) * np.sin(2 * np.pi * f * tau)
    return x + NOISE * np.random.default_rng(seed).standard_normal(x.shape)


def events(x: np.ndarray, fs: float) -> list:
    scale = np.full(x.shape[0], 1e-6)  # 1 um/s^2 a count: far below the noise
    dev = ArrayDevice(np.round(x / scale[:, None]).astype(np.int32), scale, fs,
                      gages=tuple(range(1, x.shape[0] + 1)), block_s=0.1)
    with dev:
        trig = Trigger(dev.info)
        out = [e for b in dev for e in trig.process(b)]
    return out + trig.flush()


@pytest.mark.parametrize("fs", [25600.0, 2048.0])
def test_a_blow_into_the_last_ones_ringing_is_a_new_impact_at_any_rate(fs):
    # 5 s apart: the 24 Hz mode (1.08 /s) has decayed to ~1.5x the noise when the second blow,
    # 0.6 of the first, comes; its energy then rises ~100x within the 10 ms STA
    blows = [(1.0, 1.0), (6.0, 0.6), (11.0, 1.4)]
    got = events(ringing(fs, blows, 15.0), fs)
    assert len(got) == 3, [(e.onset_s, e.end_reason) for e in got]
    # a sine from rest leaves the noise within ~0.1 ms (0.6 x 2 pi 24 Hz x t = NOISE at 0.06
    # ms): the onsets within 1 ms of the blows
    assert np.allclose([e.onset_s for e in got], [t for t, _ in blows], atol=1e-3)
    assert got[0].end_reason == "next_impact"  # its record ends at the second blow
    assert not any(e.double_hit for e in got)  # the same blow is not counted twice


def test_a_free_decay_with_deep_beats_is_one_impact():
    # two modes 0.5 Hz apart, equally damped, with the same shape on every gage: beats to zero
    # on all gages at once for the whole decay, the deepest a ringing can do; the STA over the
    # envelope stays below 2.4 (a sine's peak factor 2 and the envelope's lag), far from the
    # watch's 6 (a watch at 2 would take a beat for a blow)
    fs = 25600.0
    shapes = np.array([[1.0, 1.0], [0.8, 0.8], [0.6, 0.6], [0.3, 0.3]])
    got = events(ringing(fs, [(1.0, 1.0)], 12.0, f_hz=(20.0, 20.5), delta=(0.01, 0.01),
                         shapes=shapes), fs)
    assert len(got) == 1, [(e.onset_s, e.end_reason) for e in got]
    assert got[0].end_reason in ("decayed", "flush")
