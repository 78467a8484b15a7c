"""Streams for the recording tests: seeded, reproducible blocks with int32 extremes.

Not a test module. ``block(k, seed)`` depends only on its arguments, so a test can rebuild any
block a child process recorded.
"""

from __future__ import annotations

import numpy as np

from ramdaq.drivers.block import Block, StreamInfo, sample_time_ns

FS_HZ = 25_600.0
N_CHANNELS = 16
BLOCK_SAMPLES = 1280  # 50 ms at 25.6 kHz
T0_NS = 1_700_000_000_000_000_000  # device clock of sample 0 (an epoch-like value)
EXTREMES = np.array([0, -1, 1, 2**31 - 1, -(2**31), 2**23 - 1, -(2**23)], dtype=np.int32)
RIG_TOML = '[rig]\nname = "test-rig"\n\n[daq]\nsample_rate_hz = 25600\n'


def stream_info(n_channels: int = N_CHANNELS, fs_hz: float = FS_HZ) -> StreamInfo:
    return StreamInfo(
        device="test",
        fs_hz=fs_hz,
        channels=tuple(f"g{c + 1:02d}" for c in range(n_channels)),
        units=("m/s^2",) * (n_channels - 1) + ("N",),
        gages=tuple(range(1, n_channels)) + (0,),
        rig_toml=RIG_TOML,
        extra={"seed": 7, "adc_bits": 24, "note": "unit test", "ratio": 0.1},
    )


def block(k: int, seed: int = 0, *, seq: int | None = None, first_sample: int | None = None,
          n_samples: int = BLOCK_SAMPLES, n_channels: int = N_CHANNELS,
          fs_hz: float = FS_HZ, full_range: bool = True) -> Block:
    """Block ``k`` of a stream: random counts (full int32 range, or 24-bit) with the int32
    extremes written into channel 0; ``seq``/``first_sample`` default to an unbroken stream."""
    rng = np.random.default_rng([seed, k])
    lo, hi = (-(2**31), 2**31) if full_range else (-(2**23), 2**23)
    counts = rng.integers(lo, hi, size=(n_channels, n_samples), dtype=np.int64).astype(np.int32)
    m = min(n_samples, EXTREMES.size)
    counts[0, :m] = EXTREMES[:m]
    seq = k if seq is None else seq
    first = k * n_samples if first_sample is None else first_sample
    scale = 10.0 ** rng.uniform(-7, -3, n_channels)
    return Block(seq=seq, first_sample=first, t0_ns=T0_NS + sample_time_ns(first, fs_hz),
                 fs_hz=fs_hz, counts=counts, scale=scale)


def stream(n_blocks: int, seed: int = 0, *, gap_after: int | None = None, gap_blocks: int = 0,
           **kw) -> list[Block]:
    """``n_blocks`` blocks; after block ``gap_after`` the device skips ``gap_blocks`` blocks."""
    out = []
    for k in range(n_blocks):
        j = k + gap_blocks if gap_after is not None and k > gap_after else k
        out.append(block(j, seed, **kw))
    return out
