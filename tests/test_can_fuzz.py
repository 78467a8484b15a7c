"""Fuzzing the CAN frame parser and the cycle assembler with hypothesis.

Inputs: random frames (any identifier, flags, 0-64 bytes), and valid frames of the three shipped
layouts mutated (bits flipped, cut, padded, bytes replaced, identifier bits flipped); streams of a
group's frames dropped, doubled and swapped, from any SEQ (wrapping too). Every input must be
decoded or refused with a counted reason, decoded values must equal cantools' (the reference
twin), and the assembler must never deliver a sample that differs from what was sent.

The default run is 200 examples per property. ``pytest -m slow`` (or ``RAMDAQ_LONG_FUZZ=1``)
runs 100 000 frames through the parser and 20 000 streams through the assembler; hypothesis
draws a seed there and a seeded generator builds the input, as drawing every byte through
hypothesis is a hundred times slower. A timeout on every test catches a hang.
"""

from __future__ import annotations

from collections import Counter

import can
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from ramdaq.drivers.can_frames import REJECTIONS, CycleAssembler, FrameCodec
from tests.conftest import tallied_long_run

CODECS = {name: FrameCodec(name) for name in ("classic", "fd24", "fd16")}
NAMES = sorted(CODECS)
SHORT = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
TALLY: Counter = Counter()
pytestmark = pytest.mark.timeout(300)


def _pool(codec: FrameCodec, seed: int = 0, cycles: int = 8) -> list[can.Message]:
    """Valid frames of every group, random counts over the whole sample range."""
    rng, out = np.random.default_rng(seed), []
    for g, lay in codec.groups.items():
        b = lay.sample_bits
        counts = rng.integers(-(1 << b - 1), 1 << b - 1, (len(lay.channels), cycles * lay.samples_per_cycle))
        out += codec.messages(g, int(rng.integers(lay.seq_modulus)), counts.astype(np.int32))
    return out


POOLS = {name: _pool(codec) for name, codec in CODECS.items()}


def _mutate(msg: can.Message, ops: list[tuple[str, int, int]]) -> can.Message:
    data = bytearray(msg.data)
    ident = msg.arbitration_id
    for op, a, b in ops:
        if op == "flip" and data:
            i = a % (8 * len(data))
            data[i // 8] ^= 1 << (i % 8)
        elif op == "cut":
            del data[a % (len(data) + 1) :]
        elif op == "pad":
            data += bytes([b & 0xFF]) * (1 + a % 8)
        elif op == "byte" and data:
            data[a % len(data)] = b & 0xFF
        elif op == "id":
            ident ^= 1 << (a % 11)
    return can.Message(arbitration_id=ident, is_extended_id=msg.is_extended_id, is_fd=msg.is_fd,
                       data=data)


_OPS = ("flip", "cut", "pad", "byte", "id")


@st.composite
def frames(draw) -> tuple[FrameCodec, can.Message]:
    """A random frame, or a valid one mutated."""
    name = draw(st.sampled_from(NAMES))
    if draw(st.booleans()):
        ident = draw(st.one_of(st.integers(0, 0x1FFFFFFF), st.sampled_from(sorted(CODECS[name].layouts))))
        return CODECS[name], can.Message(
            arbitration_id=ident & 0x1FFFFFFF, is_extended_id=draw(st.booleans()), is_fd=draw(st.booleans()),
            is_remote_frame=draw(st.booleans()), is_error_frame=draw(st.booleans()),
            data=draw(st.binary(max_size=64)))
    ops = draw(st.lists(st.tuples(st.sampled_from(_OPS), st.integers(0, 511), st.integers(0, 255)),
                        max_size=4))
    return CODECS[name], _mutate(draw(st.sampled_from(POOLS[name])), ops)


def seeded_frame(seed: int) -> tuple[FrameCodec, can.Message]:
    """The same kinds of input as :func:`frames`, built from a seed."""
    rng = np.random.default_rng(seed)
    name = NAMES[rng.integers(3)]
    codec = CODECS[name]
    if rng.integers(2):
        ids = sorted(codec.layouts)
        ident = int(ids[rng.integers(len(ids))] if rng.integers(2) else rng.integers(0x20000000))
        flags = rng.integers(2, size=4).astype(bool)
        return codec, can.Message(arbitration_id=ident, is_extended_id=flags[0], is_fd=flags[1],
                                  is_remote_frame=flags[2], is_error_frame=flags[3],
                                  data=rng.bytes(int(rng.integers(65))))
    pool = POOLS[name]
    ops = [(_OPS[rng.integers(5)], int(rng.integers(512)), int(rng.integers(256)))
           for _ in range(rng.integers(5))]
    return codec, _mutate(pool[rng.integers(len(pool))], ops)


def _parse(codec: FrameCodec, msg: can.Message) -> None:
    fast, ref = codec.decode(msg), codec.decode_reference(msg)
    TALLY[fast if isinstance(fast, str) else "decoded"] += 1
    if isinstance(fast, str):
        assert fast in REJECTIONS and ref == fast
        return
    lay = codec.groups[fast.group]
    lo, hi = -(1 << lay.sample_bits - 1), (1 << lay.sample_bits - 1) - 1
    assert fast.values.dtype == np.int32 and ((fast.values >= lo) & (fast.values <= hi)).all()
    assert 0 <= fast.seq < lay.seq_modulus and (fast.seq, fast.slot) == (ref.seq, ref.slot)
    np.testing.assert_array_equal(fast.values, ref.values)


@SHORT
@given(frames())
def test_parser_decodes_or_refuses_every_frame(case):
    _parse(*case)


@SHORT
@given(st.sampled_from(NAMES), st.data())
def test_up_to_three_flipped_bits_are_always_caught(name, data):
    """CRC-8/AUTOSAR over a classic frame's 80 bits and CRC-16/CCITT-FALSE over an FD frame have
    Hamming distance 4 (the classic case is also checked exhaustively in test_can_device)."""
    msg = data.draw(st.sampled_from(POOLS[name]))
    bits = data.draw(st.sets(st.integers(0, 8 * len(msg.data) - 1), min_size=1, max_size=3))
    assert CODECS[name].check(_mutate(msg, [("flip", b, 0) for b in bits])) == "bad_crc"


def seeded_stream(seed: int) -> tuple[FrameCodec, int, np.ndarray, list]:
    """A group's frames for 1-40 cycles from any SEQ, some dropped, doubled or swapped."""
    rng = np.random.default_rng(seed)
    codec = CODECS[NAMES[rng.integers(3)]]
    g = sorted(codec.groups)[rng.integers(len(codec.groups))]
    lay = codec.groups[g]
    b, n = lay.sample_bits, int(rng.integers(1, 41))
    counts = rng.integers(-(1 << b - 1), 1 << b - 1, (len(lay.channels), n * lay.samples_per_cycle))
    counts = counts.astype(np.int32)
    msgs = codec.messages(g, int(rng.integers(lay.seq_modulus)), counts)
    wire = [(k // len(lay.frames), m) for k, m in enumerate(msgs)]
    keep = rng.random(len(wire)) >= rng.choice([0.0, 0.01, 0.1, 0.5])
    if rng.integers(4) == 0:  # a burst: whole cycles lost, a SEQ jump
        start = rng.integers(len(wire))
        keep[start : start + rng.integers(1, 5 * len(lay.frames))] = False
    wire = [w for w, k in zip(wire, keep, strict=True) if k]
    for _ in range(rng.integers(7)):
        if len(wire) > 1:
            i = int(rng.integers(len(wire) - 1))
            if rng.integers(2):
                wire[i], wire[i + 1] = wire[i + 1], wire[i]
            else:
                wire.insert(i, wire[i])
    return codec, g, counts, wire


def _assemble(codec: FrameCodec, g: int, counts: np.ndarray, wire: list) -> None:
    """Deliver only whole cycles, each equal to what was sent; every whole cycle after the first
    frame's cycle is delivered."""
    lay = codec.groups[g]
    asm = CycleAssembler(lay)
    TALLY["streams"] += 1
    for k, msg in wire:
        layout, seq = codec.check(msg)
        if asm.base is None:
            asm.start(seq)
            first_k, first_cycle = k, asm.base
        TALLY[asm.put(seq, layout.slot, msg.data) or "placed"] += 1
    if asm.base is None:
        return
    asm.finish()
    TALLY.update(asm.problems)
    assert not asm.notes  # one sender, no clock: no foreign sender, no wrap or gap judged by time
    asm.decode(codec)
    T, ids, seen = lay.samples_per_cycle, {f.frame_id for f in lay.frames}, {}
    for k, m in wire:
        seen.setdefault(k, set()).add(m.arbitration_id)
    complete = {k for k, got in seen.items() if got == ids}
    delivered = set()
    for start, end, got in asm.runs:
        k0 = start // T - first_cycle + first_k
        np.testing.assert_array_equal(got, counts[:, k0 * T : k0 * T + end - start])
        delivered |= set(range(k0, k0 + (end - start) // T))
    assert delivered <= complete and {k for k in complete if k > first_k} <= delivered


@SHORT
@given(st.integers(0, 2**63 - 1))
@example(97654)  # found by the long run: a jump's first frame, then a late frame of the jump
@example(103522)  # found by the long run: test_cycle_after_a_jump_past_a_straggler_is_delivered
@example(29224)  # found by CI: test_a_straggler_after_a_jump_of_the_window_is_placed
def test_assembler_never_delivers_a_wrong_sample(seed):
    _assemble(*seeded_stream(seed))


def _placed(codec: FrameCodec, g: int, first_seq: int, wire: list) -> tuple[CycleAssembler, list]:
    """Group ``g``'s frames of ``wire`` put into an assembler started at SEQ ``first_seq``, the
    stream finished: the assembler and each frame's problem (None: placed)."""
    asm = CycleAssembler(codec.groups[g])
    asm.start(first_seq)
    problems = []
    for _, m in wire:
        layout, seq = codec.check(m)
        problems.append(asm.put(seq, layout.slot, m.data))
    asm.finish()
    return asm, problems


def test_cycle_after_a_jump_past_a_straggler_is_delivered():
    """Regression (long run, seed 103522): fd24, cycles 3-5 lost (a SEQ jump of 4), and the
    jump's first frame came before a straggler of cycle 2. The straggler used to make that first
    frame a lone outlier, so the complete cycle 6 was never delivered (20 samples lost)."""
    codec = CODECS["fd24"]
    lay = codec.groups[1]
    counts = np.random.default_rng(7).integers(-(1 << 23), 1 << 23, (16, 8 * lay.samples_per_cycle))
    msgs = codec.messages(1, 7385, counts.astype(np.int32))
    by_cycle = [msgs[k * 16 : (k + 1) * 16] for k in range(8)]
    order = ([(0, s) for s in range(16)] + [(1, s) for s in range(16)] + [(2, s) for s in range(4)]
             + [(6, 0), (2, 5)] + [(6, s) for s in range(1, 16)] + [(7, s) for s in range(16)])
    wire = [(k, by_cycle[k][s]) for k, s in order]
    _assemble(codec, 1, counts, wire)  # every complete cycle after the first delivered, bit for bit
    asm, problems = _placed(codec, 1, 7385, wire)
    asm.decode(codec)
    assert problems == [None] * len(wire) and not asm.problems
    assert [(r[0], r[1]) for r in asm.runs] == [(7385 * 20, 7387 * 20), (7391 * 20, 7393 * 20)]
    assert asm.lost == [[7387, 4, 1]]  # cycle 2 incomplete, 3-5 never seen


def test_a_straggler_after_a_jump_of_the_window_is_placed():
    """Regression (CI, seed 29224): classic, cycles 7-8 lost, so the next cycle heard is 3 (the
    window) past cycle 6, and its first frame came before cycle 6's last. That frame used to make
    cycle 6 final by SEQ distance alone, so its straggler was a late_frame and a cycle sent whole
    was lost. A cycle is final once frames of ``window`` later cycles arrived: here one had."""
    codec = CODECS["classic"]
    lay = codec.groups[1]
    n_slots = len(lay.frames)
    b = lay.sample_bits
    shape = (len(lay.channels), 12 * lay.samples_per_cycle)
    counts = np.random.default_rng(3).integers(-(1 << b - 1), 1 << b - 1, shape)
    msgs = codec.messages(1, 124, counts.astype(np.int32))
    by_cycle = [msgs[k * n_slots : (k + 1) * n_slots] for k in range(12)]
    order = ([(k, s) for k in range(6) for s in range(n_slots)] + [(6, s) for s in range(n_slots - 1)]
             + [(9, 0), (6, n_slots - 1)]
             + [(k, s) for k in range(9, 12) for s in range(n_slots) if (k, s) != (9, 0)])
    wire = [(k, by_cycle[k][s]) for k, s in order]
    _assemble(codec, 1, counts, wire)  # every complete cycle after the first delivered, bit for bit
    asm, problems = _placed(codec, 1, 124, wire)
    assert problems == [None] * len(wire) and not asm.problems
    assert asm.lost == [[131, 2, 0]]  # cycles 7-8, never seen


@pytest.fixture
def long_run(request: pytest.FixtureRequest, capsys: pytest.CaptureFixture):
    """Long runs only with ``pytest -m slow`` or ``RAMDAQ_LONG_FUZZ=1`` (CI runs every test)."""
    yield from tallied_long_run(request, capsys, TALLY, "inputs")


_LONG = dict(deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_parser_long_run(long_run):
    given(st.integers(0, 2**63 - 1))(settings(max_examples=100_000, **_LONG)(
        lambda seed: _parse(*seeded_frame(seed))))()
    assert sum(long_run.values()) >= 100_000 and long_run["decoded"] and long_run["bad_crc"]


@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_assembler_long_run(long_run):
    given(st.integers(0, 2**63 - 1))(settings(max_examples=20_000, **_LONG)(
        lambda seed: _assemble(*seeded_stream(seed))))()
    assert long_run["streams"] >= 20_000 and long_run["late_frame"] and long_run["duplicate_frame"]
