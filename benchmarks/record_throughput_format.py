"""Throughput of the ramdaq.Block format: numpy encoder vs the protobuf runtime, size after zstd.

Sixty seconds of realistic data (16 accelerometer channels at 25.6 kHz in 50 ms blocks: a ram
blow every 5 s ringing four decaying modes, plus ADC noise, quantised to 24-bit counts) are
encoded by :func:`ramdaq.drivers.mcap_format.encode_block` and by the protobuf runtime
(``counts.extend(array.tolist())``), decoded, compressed as the recorder's 0.25 s chunks are, and
finally recorded end to end by :class:`ramdaq.daq.recorder.Recorder` into a temporary file.

    python benchmarks/record_throughput_format.py [--seconds 60]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import zstandard

from ramdaq.daq.recorder import Recorder
from ramdaq.drivers.block import Block, StreamInfo, sample_time_ns
from ramdaq.drivers.mcap_format import BlockProto, decode_block, encode_block

FS_HZ = 25_600.0
N_CH = 16
BLOCK_N = 1280  # 50 ms
FULL_SCALE = 2**23 - 1
MODES_HZ = np.array([8.7, 23.4, 61.0, 142.0])
ZETA = np.array([0.02, 0.015, 0.01, 0.01])
NOISE_COUNTS = 20.0  # rms ADC noise, counts (about 20 effective bits)


def realistic_counts(seconds: float, seed: int = 0) -> np.ndarray:
    """int32 counts, shape ``(16, seconds * 25600)``: a blow every 5 s plus noise."""
    rng = np.random.default_rng(seed)
    n = int(seconds * FS_HZ)
    amp = rng.uniform(0.02, 0.3, (N_CH, MODES_HZ.size)) * FULL_SCALE  # peak counts per mode
    phase = rng.uniform(0, 2 * np.pi, (N_CH, MODES_HZ.size))
    tt = np.arange(int(5.0 * FS_HZ)) / FS_HZ
    ring = np.zeros((N_CH, tt.size))  # the response to one blow, over the 5 s until the next
    for m, (f, z) in enumerate(zip(MODES_HZ, ZETA, strict=True)):
        w = 2 * np.pi * f
        ring += amp[:, m : m + 1] * np.exp(-z * w * tt) * np.sin(w * tt + phase[:, m : m + 1])
    x = rng.normal(0.0, NOISE_COUNTS, (N_CH, n))
    for i0 in range(int(1.0 * FS_HZ), n, tt.size):
        x[:, i0 : i0 + tt.size] += ring[:, : n - i0]
    return np.clip(np.round(x), -FULL_SCALE - 1, FULL_SCALE).astype(np.int32)


def blocks_of(counts: np.ndarray) -> list[Block]:
    scale = np.full(N_CH, 9.81 * 50 / FULL_SCALE)  # a 50 g accelerometer, m/s^2 per count
    return [
        Block(seq=k, first_sample=i, t0_ns=sample_time_ns(i, FS_HZ), fs_hz=FS_HZ,
              counts=np.ascontiguousarray(counts[:, i : i + BLOCK_N]), scale=scale)
        for k, i in enumerate(range(0, counts.shape[1], BLOCK_N))
    ]


def upb_encode(b: Block) -> bytes:
    msg = BlockProto(seq=b.seq, first_sample=b.first_sample, device_time_ns=b.t0_ns,
                     sample_rate_hz=b.fs_hz, n_channels=b.n_channels, n_samples=b.n_samples)
    msg.scale.extend(b.scale.tolist())
    msg.counts.extend(b.counts.ravel().tolist())
    return msg.SerializeToString()


def timed(fn, items) -> tuple[float, list]:
    t = time.perf_counter()
    out = [fn(x) for x in items]
    return time.perf_counter() - t, out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seconds", type=float, default=60.0)
    args = p.parse_args()
    blocks = blocks_of(realistic_counts(args.seconds))
    n_samples = sum(b.counts.size for b in blocks)
    print(f"{args.seconds:g} s of {N_CH} ch x {FS_HZ:g} Hz in {len(blocks)} blocks of {BLOCK_N}: "
          f"{n_samples / 1e6:.1f} M samples")

    t_np, ours = timed(encode_block, blocks)
    t_upb, theirs = timed(upb_encode, blocks)
    assert ours == theirs, "numpy encoder and protobuf runtime disagree"
    mb = sum(map(len, ours)) / 1e6
    for name, t in (("numpy encoder", t_np), ("upb extend(tolist())", t_upb)):
        print(f"encode  {name:22s} {t:6.3f} s  {mb / t:7.1f} MB/s  {n_samples / t / 1e6:6.1f} M samples/s")
    print(f"        numpy encoder is {t_upb / t_np:.1f}x faster")

    t_dec, back = timed(decode_block, ours)
    assert all(a.same_as(b) for a, b in zip(back, blocks, strict=True))
    print(f"decode  upb parse + __array__     {t_dec:6.3f} s  {mb / t_dec:7.1f} MB/s  "
          f"{n_samples / t_dec / 1e6:6.1f} M samples/s")

    per_chunk = 5  # 0.25 s chunks, as the recorder writes them
    chunks = [b"".join(ours[i : i + per_chunk]) for i in range(0, len(ours), per_chunk)]
    t = time.perf_counter()
    packed = sum(len(zstandard.compress(c)) for c in chunks)  # what mcap's writer calls (level 3)
    t_z = time.perf_counter() - t
    raw = sum(len(zstandard.compress(b"".join(b.counts.tobytes() for b in blocks[i : i + per_chunk])))
              for i in range(0, len(blocks), per_chunk))
    print(f"size    varint {mb * 1e6 / n_samples:.3f} B/sample, after zstd {packed / n_samples:.3f} "
          f"B/sample (raw int32 + zstd: {raw / n_samples:.3f}); zstd {mb / t_z:.0f} MB/s")

    info = StreamInfo(device="bench", fs_hz=FS_HZ, channels=tuple(f"g{c + 1:02d}" for c in range(N_CH)),
                      units=("m/s^2",) * N_CH, gages=tuple(range(1, N_CH + 1)))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.mcap"
        t = time.perf_counter()
        with Recorder(path, info, queue_blocks=len(blocks) + 1) as rec:
            for b in blocks:
                rec.put(b)
        t_rec = time.perf_counter() - t
        size = path.stat().st_size
    print(f"record  Recorder end to end {t_rec:6.3f} s for {args.seconds:g} s of stream "
          f"({args.seconds / t_rec:.0f}x real time); file {size / 1e6:.1f} MB, "
          f"{size / n_samples:.3f} B/sample, overflows {rec.overflows}")


if __name__ == "__main__":
    main()
