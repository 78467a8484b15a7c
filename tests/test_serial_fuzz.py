"""Fuzzing the serial frame parser (hypothesis): random bytes, forged headers, and valid frame
streams with damaged frames and garbage between them, fed in random pieces (some reads end
exactly on a frame boundary: that is how a pty delivers a device that writes whole frames).

Every run checks: no exception; each example within its deadline; every frame returned is a
CRC-valid frame that really is in the input, in stream order; every intact frame comes back
(unless a frame the parser accepted overlaps it -- a CRC-16 lets one damaged frame in 65 536
through); and every byte is accounted for: ``bytes_in == bytes_framed + bytes_discarded``.

The default run is 200 examples per property. ``pytest -m slow`` (or ``RAMDAQ_LONG_FUZZ=1``)
runs 100 000 random inputs and 100 000 damaged streams; there hypothesis draws a seed and numpy
builds the input, since drawing every byte through hypothesis is a hundred times slower.
"""

from __future__ import annotations

import struct
import time
from datetime import timedelta

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ramdaq.drivers.serial_frames import (
    FLAG_END,
    HEADER_BYTES,
    MAX_PAYLOAD_BYTES,
    SYNC,
    FrameParser,
    crc16,
    crc16_reference,
    encode_frame,
)
from tests.conftest import skip_unless_long_fuzz

pytestmark = pytest.mark.timeout(120)

CI = settings(max_examples=200, deadline=timedelta(seconds=2), database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
LONG = settings(CI, max_examples=100_000)


# -- strategies ------------------------------------------------------------------------------
@st.composite
def frames(draw) -> bytes:
    """A valid frame: 1-16 channels, 0-40 samples (0 only as end of stream), random counts."""
    width = draw(st.sampled_from((2, 3, 4)))
    n_ch = draw(st.integers(1, 16))
    end = draw(st.booleans()) if draw(st.integers(0, 9)) == 0 else False
    n = 0 if end else draw(st.integers(1, 40))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    lim = 2 ** (8 * width - 1)
    counts = rng.integers(-lim, lim, size=(n_ch, n))
    return encode_frame(draw(st.integers(0, 2**32 - 1)), draw(st.integers(0, 2**64 - 1)), counts,
                        width=width, flags=FLAG_END if end else 0)


@st.composite
def forged_headers(draw) -> bytes:
    """Sync plus a header with a *valid* header CRC but any fields (absurd sizes, bad width or
    version), then some random bytes: must be refused at once or fail the payload CRC."""
    fields = struct.pack("<2sBBBBHIQ", SYNC, draw(st.sampled_from((1, 1, 1, 0, 2, 255))),
                         draw(st.integers(0, 255)), draw(st.sampled_from((2, 3, 4, 0, 1, 5, 255))),
                         draw(st.integers(0, 255)), draw(st.integers(0, 65535)),
                         draw(st.integers(0, 2**32 - 1)), draw(st.integers(0, 2**64 - 1)))
    return fields + crc16(fields).to_bytes(2, "little") + draw(st.binary(max_size=64))


@st.composite
def damaged(draw, frame: bytes) -> bytes:
    """``frame`` with one mutation: a flipped byte, a cut, an insertion, or only its head/tail."""
    i = draw(st.integers(0, len(frame) - 1))
    kind = draw(st.sampled_from(("flip", "delete", "insert", "head", "tail")))
    if kind == "flip":
        return frame[:i] + bytes([frame[i] ^ draw(st.integers(1, 255))]) + frame[i + 1:]
    if kind == "delete":
        return frame[:i] + frame[i + draw(st.integers(1, len(frame) - i)):]
    if kind == "insert":
        return frame[:i + 1] + draw(st.binary(min_size=1, max_size=40)) + frame[i + 1:]
    return frame[:i] if kind == "head" else frame[i + 1:]


@st.composite
def streams(draw) -> tuple[bytes, list[tuple[int, int]]]:
    """Frames, some damaged, with garbage between some; returns the bytes and the spans of the
    intact frames."""
    pieces, spans, pos = [], [], 0
    for _ in range(draw(st.integers(0, 12))):
        what = draw(st.sampled_from(("frame", "frame", "frame", "damaged", "garbage", "forged")))
        if what == "garbage":
            piece = draw(st.binary(min_size=1, max_size=80))
        elif what == "forged":
            piece = draw(forged_headers())
        else:
            piece = draw(frames())
            if what == "damaged":
                piece = draw(damaged(piece))
            else:
                spans.append((pos, pos + len(piece)))
        pieces.append(piece)
        pos += len(piece)
    return b"".join(pieces), spans


def cuts(data: bytes, at: list[int] = ()):
    """Feed boundaries: anywhere, and on the given offsets (frame boundaries)."""
    points = st.integers(0, len(data))
    if at:
        points = st.one_of(points, st.sampled_from(sorted(at)))
    return st.lists(points, max_size=8).map(sorted)


# -- the checks ------------------------------------------------------------------------------
def parse(data: bytes, at: list[int]) -> tuple[FrameParser, list]:
    parser, out, prev = FrameParser(), [], 0
    for c in [*at, len(data)]:
        out += parser.feed(data[prev:c])
        prev = c
    out += parser.flush()
    return parser, out


def check(data: bytes, at: list[int], intact: list[tuple[int, int]] | None = None) -> list:
    parser, out = parse(data, at)
    assert parser.pending == 0 and parser.bytes_in == len(data)
    assert parser.bytes_framed + parser.bytes_discarded == len(data)
    assert parser.frames == len(out)
    assert parser.resyncs == sum(f.skipped_bytes > 0 for f in out)
    assert sum(f.skipped_bytes for f in out) <= parser.bytes_discarded
    assert sum(f.failed_crc for f in out) <= parser.crc_errors
    spans, pos = [], 0
    for f in out:  # CRC-valid, really in the input, in order, not overlapping
        wire = encode_frame(f.seq, f.first_sample, f.counts, width=f.width, flags=f.flags)
        start = data.find(wire, pos)
        assert start >= 0, f"frame seq {f.seq} is not in the input after byte {pos}"
        spans.append((start, start + len(wire)))
        pos = start + len(wire)
    assert sum(b - a for a, b in spans) == parser.bytes_framed
    for a, b in intact or []:
        shadowed = any(s < b and a < e and (s, e) != (a, b) for s, e in spans)
        assert shadowed or (a, b) in spans, f"intact frame at bytes {a}..{b} was not recovered"
    return out


def _random_bytes(data: bytes, at: list[int]) -> None:
    check(data, at)


def _streams(sample: tuple[bytes, list[tuple[int, int]]], at: list[int]) -> None:
    data, intact = sample
    out = check(data, at, intact)
    if len(intact) == len(out) and sum(b - a for a, b in intact) == len(data):
        assert all(f.skipped_bytes == 0 and f.failed_crc == 0 for f in out)


random_inputs = st.binary(max_size=4096).flatmap(lambda d: st.tuples(st.just(d), cuts(d)))
sync_soup = st.lists(st.one_of(st.binary(max_size=24), st.just(SYNC), st.just(SYNC + b"\x01"),
                               forged_headers()), max_size=30).map(b"".join)
soup_inputs = sync_soup.flatmap(lambda d: st.tuples(st.just(d), cuts(d)))
stream_inputs = streams().flatmap(
    lambda s: st.tuples(st.just(s), cuts(s[0], [e for _, e in s[1]])))


@CI
@given(random_inputs)
def test_random_bytes(case):
    _random_bytes(*case)


@CI
@given(soup_inputs)
def test_sync_words_and_forged_headers(case):
    _random_bytes(*case)


@CI
@given(stream_inputs)
def test_streams_with_damage_and_garbage(case):
    _streams(*case)


# -- the long run: hypothesis draws a seed, numpy builds the input (100x cheaper to draw) ----
def seeded_stream(seed: int) -> tuple[bytes, list[tuple[int, int]]]:
    """Like :func:`streams`, built from one seed: frames, damaged frames, garbage, forgeries."""
    rng = np.random.default_rng(seed)
    pieces, spans, pos = [], [], 0
    for _ in range(rng.integers(0, 13)):
        what = rng.choice(["frame", "frame", "frame", "damaged", "garbage", "forged"])
        if what == "garbage":
            piece = rng.bytes(int(rng.integers(1, 81)))
        elif what == "forged":
            fields = struct.pack("<2sBBBBHIQ", SYNC, int(rng.choice([1, 1, 0, 2])),
                                 *(int(v) for v in rng.integers(0, 256, 3)),
                                 int(rng.integers(0, 65536)), 0, 0)
            piece = fields + crc16(fields).to_bytes(2, "little") + rng.bytes(int(rng.integers(65)))
        else:
            width, n_ch, n = int(rng.integers(2, 5)), int(rng.integers(1, 17)), int(rng.integers(41))
            lim = 2 ** (8 * width - 1)
            piece = encode_frame(int(rng.integers(2**32)), int(rng.integers(2**63)),
                                 rng.integers(-lim, lim, size=(n_ch, n)), width=width,
                                 flags=0 if n else FLAG_END)
            if what == "damaged":
                i, kind = int(rng.integers(len(piece))), rng.integers(5)
                piece = (piece[:i] + bytes([piece[i] ^ int(rng.integers(1, 256))]) + piece[i + 1:],
                         piece[:i] + piece[i + int(rng.integers(1, len(piece) - i + 1)):],
                         piece[:i + 1] + rng.bytes(int(rng.integers(1, 41))) + piece[i + 1:],
                         piece[:i], piece[i + 1:])[kind]
            else:
                spans.append((pos, pos + len(piece)))
        pieces.append(piece)
        pos += len(piece)
    return b"".join(pieces), spans


def seeded_bytes(seed: int) -> bytes:
    """Random bytes with sync words and sync-plus-version pairs sprinkled in."""
    rng = np.random.default_rng(seed)
    data = bytearray(rng.bytes(int(rng.integers(0, 4097))))
    for at in rng.integers(0, len(data) + 1, int(rng.integers(0, 20))):
        data[at:at] = SYNC + (b"\x01" if rng.integers(2) else b"")
    return bytes(data)


def seeded_cuts(seed: int, n: int, ends: list[int] = ()) -> list[int]:
    """Eight feed boundaries, some on the given offsets (the ends of intact frames)."""
    rng = np.random.default_rng(seed ^ 0x5EED)
    at = rng.integers(0, n + 1, 8).tolist()
    if ends:
        at[:4] = rng.choice(ends, 4).tolist()
    return sorted(at)


@pytest.fixture
def long_run(request: pytest.FixtureRequest) -> None:
    """The 100 000-example runs go only with ``pytest -m slow`` or ``RAMDAQ_LONG_FUZZ=1``."""
    skip_unless_long_fuzz(request)


def _bytes_from_seed(seed: int) -> None:
    data = seeded_bytes(seed)
    check(data, seeded_cuts(seed, len(data)))


def _stream_from_seed(seed: int) -> None:
    sample = seeded_stream(seed)
    _streams(sample, seeded_cuts(seed, len(sample[0]), [e for _, e in sample[1]]))


seeds = st.integers(0, 2**64 - 1)


@CI
@given(seeds)
def test_seeded_generators(seed):
    """The long run's generators, briefly, so they are known to work."""
    _bytes_from_seed(seed)
    _stream_from_seed(seed)


def _campaign(one, capsys: pytest.CaptureFixture) -> None:
    done, t = [], time.perf_counter()

    def case(seed: int) -> None:
        one(seed)
        done.append(seed)

    LONG(given(seeds)(case))()
    with capsys.disabled():
        print(f"\n{one.__name__}: {len(done)} inputs in {time.perf_counter() - t:.0f} s")
    assert len(done) >= 100_000


@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_random_bytes_long(long_run, capsys):
    _campaign(_bytes_from_seed, capsys)


@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_streams_with_damage_and_garbage_long(long_run, capsys):
    _campaign(_stream_from_seed, capsys)


# -- fixed cases -----------------------------------------------------------------------------
def test_crc16_check_value_and_reference_twin():
    """CRC-16/CCITT-FALSE check value (catalogue of parametrised CRC algorithms, Greg Cook)."""
    assert crc16(b"123456789") == crc16_reference(b"123456789") == 0x29B1
    rng = np.random.default_rng(5)
    for n in (0, 1, 2, 17, 1000):
        data = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        assert crc16(data) == crc16_reference(data)
        assert crc16(data[n // 2:], crc16(data[:n // 2])) == crc16(data)


@pytest.mark.parametrize("width", [2, 3, 4])
def test_round_trip_at_the_rails_byte_by_byte(width):
    lim = 2 ** (8 * width - 1)
    counts = np.array([[-lim, lim - 1, 0, -1], [1, -2, lim - 2, -lim + 1]])
    wire = encode_frame(2**32 + 5, 2**64 - 1, counts, width=width)
    parser = FrameParser()
    out = [f for b in wire for f in parser.feed(bytes([b]))]
    assert len(out) == 1 and out[0].seq == 5 and out[0].first_sample == 2**64 - 1
    assert out[0].counts.dtype == np.int32 and np.array_equal(out[0].counts, counts)
    assert len(wire) == HEADER_BYTES + counts.size * width + 2


def test_absurd_length_is_refused_not_waited_for():
    fields = struct.pack("<2sBBBBHIQ", SYNC, 1, 0, 4, 255, 4096, 0, 0)  # 4 MB payload
    assert 255 * 4096 * 4 > MAX_PAYLOAD_BYTES
    parser = FrameParser()
    assert parser.feed(fields + crc16(fields).to_bytes(2, "little")) == []
    assert parser.bad_headers == 1 and parser.pending < len(SYNC)
    good = encode_frame(1, 0, np.ones((2, 3), np.int32))
    assert [f.seq for f in parser.feed(good)] == [1] and parser.resyncs == 1


def test_read_ending_on_a_frame_whose_crc_ends_in_the_first_sync_byte():
    """Regression: a read that ends exactly after a frame whose last byte is 0xEB (the first
    sync byte) must not keep that byte as the start of the next sync word."""
    candidates = (np.array([[v, 1, 2], [3, 4, 5]], np.int32) for v in range(5000))
    counts = next(c for c in candidates if encode_frame(0, 0, c)[-1] == SYNC[0])
    a, b = encode_frame(0, 0, counts), encode_frame(1, 3, counts)
    assert a[-1] == SYNC[0]
    parser = FrameParser()
    assert len(parser.feed(a)) == 1 and parser.pending == 0
    assert len(parser.feed(b)) == 1
    assert (parser.bytes_discarded, parser.resyncs) == (0, 0)
    assert parser.bytes_framed == parser.bytes_in == len(a) + len(b)


def test_torn_frame_does_not_swallow_the_next_one():
    a, b = (encode_frame(1, 0, np.ones((16, 32), np.int32)),
            encode_frame(2, 32, np.ones((1, 1), np.int32)))
    parser = FrameParser()
    assert parser.feed(a[:100] + b) == []  # a's header asks for more bytes than b holds
    assert [f.seq for f in parser.flush()] == [2]
    assert parser.bytes_discarded == 100 and parser.resyncs == 1


@pytest.mark.parametrize("bad", [
    dict(counts=np.ones((2, 2), int), width=5), dict(counts=np.ones((0, 2), int)),
    dict(counts=np.ones((2, 0), int)), dict(counts=np.full((1, 1), 2**15), width=2),
    dict(counts=np.ones((1, 1), int), first_sample=-1), dict(counts=np.full((1, 1), 0.5)),
])
def test_encode_refuses_bad_frames(bad):
    kw = {"seq": 0, "first_sample": 0, **bad}
    with pytest.raises(ValueError, match="encode_frame"):
        encode_frame(kw.pop("seq"), kw.pop("first_sample"), kw.pop("counts"), **kw)
