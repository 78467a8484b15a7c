"""The ramdaq.Block wire format: the numpy encoder against the protobuf runtime, and metadata.

The fast encoder is the twin of ``BlockProto(...).SerializeToString()``: the tests hold its bytes
*identical* to the runtime's (not merely parse-equal), over random int32 including the extremes and
every varint length boundary. No tolerance anywhere: the format is lossless integers.
"""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from ramdaq.drivers.block import Block, StreamInfo
from ramdaq.drivers.errors import FrameError
from ramdaq.drivers.mcap_format import (
    BlockProto,
    NotARamdaqRecording,
    decode_block,
    decode_header,
    encode_block,
    stream_info_from_metadata,
    stream_info_to_metadata,
)
from tests.recording_helpers import block, stream_info

pytestmark = pytest.mark.timeout(120)

INT32 = st.integers(-(2**31), 2**31 - 1)


def _reference(b: Block) -> bytes:
    """What the protobuf runtime serializes for the same block."""
    return BlockProto(
        seq=b.seq, first_sample=b.first_sample, device_time_ns=b.t0_ns, sample_rate_hz=b.fs_hz,
        n_channels=b.n_channels, n_samples=b.n_samples, scale=b.scale.tolist(),
        counts=b.counts.ravel().tolist(),
    ).SerializeToString()


def _check(b: Block) -> None:
    data = encode_block(b)
    assert data == _reference(b)
    msg = BlockProto.FromString(data)
    assert np.array_equal(np.array(msg.counts, dtype=np.int64), b.counts.ravel().astype(np.int64))
    assert (msg.seq, msg.first_sample, msg.device_time_ns) == (b.seq, b.first_sample, b.t0_ns)
    back = decode_block(data)
    assert back.same_as(b)
    assert back.counts.dtype == np.int32 and back.counts.shape == b.counts.shape
    h = decode_header(data)
    assert (h.seq, h.first_sample, h.t0_ns, h.fs_hz, h.n_channels, h.n_samples) == (
        b.seq, b.first_sample, b.t0_ns, b.fs_hz, b.n_channels, b.n_samples)


@settings(max_examples=300, deadline=None)
@given(
    counts=hnp.arrays(
        np.int32,
        st.tuples(st.integers(0, 4), st.integers(0, 70)),
        elements=st.one_of(INT32, st.sampled_from([0, -1, 1, 2**31 - 1, -(2**31), 63, -64, 64])),
    ),
    seq=st.integers(0, 2**64 - 1),
    first_sample=st.integers(0, 2**64 - 1),
    t0_ns=st.integers(-(2**63), 2**63 - 1),
    fs_hz=st.floats(1e-3, 1e7, allow_nan=False),
    data=st.data(),
)
@example(counts=np.zeros((0, 0), np.int32), seq=0, first_sample=0, t0_ns=0, fs_hz=1.0, data=None)
def test_encoder_matches_protobuf_runtime(counts, seq, first_sample, t0_ns, fs_hz, data):
    n_ch = counts.shape[0]
    if data is None:
        scale = np.ones(n_ch)
    else:
        scale = np.array(data.draw(st.lists(st.floats(allow_nan=False), min_size=n_ch, max_size=n_ch)),
                         dtype=np.float64)
    _check(Block(seq=seq, first_sample=first_sample, t0_ns=t0_ns, fs_hz=fs_hz, counts=counts, scale=scale))


def test_every_varint_length_boundary():
    """Zigzag values 2**(7k) - 1 and 2**(7k) are where the varint grows a byte; all of them, both
    signs, in one block larger than the encoder's internal piece size (65536 samples)."""
    z = np.array([(1 << (7 * k)) + d for k in range(1, 5) for d in (-1, 0)] + [0, 1, 2**32 - 1],
                 dtype=np.uint64)
    x = np.where(z % 2 == 0, z // 2, -(z.astype(np.int64) + 1) // 2).astype(np.int32)  # unzigzag
    rng = np.random.default_rng(3)
    counts = rng.integers(-(2**31), 2**31, size=(3, 30_000), dtype=np.int64).astype(np.int32)
    counts[:, : x.size] = x
    counts[2, -x.size :] = x
    _check(Block(seq=1, first_sample=2, t0_ns=3, fs_hz=25600.0, counts=counts, scale=np.ones(3)))


def test_realistic_blocks_match():
    for k in range(3):
        _check(block(k, seed=11, full_range=False))
        _check(block(k, seed=12, full_range=True))


def test_noncontiguous_counts_are_encoded_in_channel_major_order():
    base = block(0, seed=5)
    b = Block(seq=0, first_sample=0, t0_ns=1, fs_hz=base.fs_hz, counts=base.counts[:, ::2],
              scale=base.scale)
    assert not b.counts.flags.c_contiguous
    _check(b)


def test_decode_rejects_malformed_messages():
    with pytest.raises(FrameError, match="not a ramdaq.Block"):
        decode_block(b"\x42\xff")  # length-delimited field running past the end
    bad = BlockProto(n_channels=2, n_samples=3, scale=[1.0, 1.0], counts=[1, 2, 3]).SerializeToString()
    with pytest.raises(FrameError, match="3 counts and 2 scales for 2 channels x 3 samples"):
        decode_block(bad)


def test_negative_seq_is_refused():
    b = block(0)
    with pytest.raises(ValueError, match="seq and first_sample must be >= 0"):
        encode_block(Block(seq=-1, first_sample=0, t0_ns=0, fs_hz=1.0, counts=b.counts, scale=b.scale))


def test_stream_info_metadata_round_trip():
    info = stream_info()
    meta = stream_info_to_metadata(info)
    assert all(isinstance(k, str) and isinstance(v, str) for k, v in meta.items())
    assert meta["fs_hz"] == "25600.0" and meta["channels"].startswith('["g01"')
    assert stream_info_from_metadata(meta, info.rig_toml) == info
    odd = StreamInfo(device="x", fs_hz=1 / 3, channels=("a",), units=("N",), gages=(0,))
    assert stream_info_from_metadata(stream_info_to_metadata(odd)) == odd  # repr(float) is exact


def test_incomplete_metadata_is_not_a_ramdaq_recording():
    meta = stream_info_to_metadata(stream_info())
    del meta["channels"]
    with pytest.raises(NotARamdaqRecording, match="ramdaq.stream metadata is incomplete"):
        stream_info_from_metadata(meta)
