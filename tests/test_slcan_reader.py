"""The lean slcan reader through real pseudo-terminals, with python-can's slcan bus as the reference.

Opening and closing send the same bytes as python-can's ``slcanBus`` and fail the same way; a
Lawicel line is either a frame equal to python-can's (and to the frame it was made from), an error
frame (status), nothing (a reply) or a counted reason, never an exception; lines torn across reads
parse as if read at once; a port that vanishes raises ``OSError``.

Fuzzing as in ``test_can_fuzz``: 200 examples per property by default, ``pytest -m slow`` (or
``RAMDAQ_LONG_FUZZ=1``) sends 100 000 lines through both readers.
"""

from __future__ import annotations

import contextlib
import os
import select
import time
import tty
import warnings
from collections import Counter

import can
import numpy as np
import pytest
from can.interfaces.slcan import slcanBus
from can.util import CAN_FD_DLC, len2dlc
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ramdaq.drivers.slcan_reader import SlcanFrame, SlcanReader, parse_lines
from tests.conftest import tallied_long_run

pytestmark = pytest.mark.timeout(300)
SHORT = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
SENTINEL_ID = 0x15A5A5A5  # a remote frame ends each line's answer; no drawn frame has this identifier
SENTINEL = b"R15A5A5A50"
TALLY: Counter = Counter()


class Pty:
    """A pseudo-terminal: the test writes and reads the master side, an adapter opens ``path``."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            view = view[os.write(self.master, view) :]

    def read_all(self, quiet_s: float = 0.05) -> bytes:
        """What the adapter side wrote, until it is quiet for ``quiet_s``."""
        out = b""
        while select.select([self.master], [], [], quiet_s)[0]:
            out += os.read(self.master, 4096)
        return out

    def close(self) -> None:
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass


@pytest.fixture
def pty():
    p = Pty()
    yield p
    p.close()


def is_sentinel(msg: can.Message | SlcanFrame) -> bool:
    return msg.arbitration_id == SENTINEL_ID and msg.is_remote_frame and msg.is_extended_id and msg.dlc == 0


def fields(msg: can.Message | SlcanFrame) -> tuple:
    return (msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame, msg.is_error_frame, msg.is_fd,
            msg.bitrate_switch, msg.dlc, bytes(msg.data))


# -- opening and closing ---------------------------------------------------------------------
OPEN_CASES = {
    "plain": {}, "bitrate": dict(bitrate=500000), "listen-only": dict(listen_only=True),
    "bitrate-listen-only": dict(bitrate=1000000, listen_only=True), "btr": dict(btr="0014"),
    "bit-timing": dict(timing=can.BitTiming(f_clock=8_000_000, brp=1, tseg1=5, tseg2=2, sjw=1)),
    "bit-timing-fd": dict(timing=can.BitTimingFd(
        f_clock=80_000_000, nom_brp=1, nom_tseg1=119, nom_tseg2=40, nom_sjw=40, data_brp=1,
        data_tseg1=29, data_tseg2=10, data_sjw=10)),
    "ignored-options": dict(bitrate=250000, fd=True, data_bitrate=2000000, receive_own_messages=True),
}


@pytest.mark.parametrize("kw", list(OPEN_CASES.values()), ids=list(OPEN_CASES))
def test_open_and_close_send_what_python_can_sends(pty, kw):
    sent = {}
    for name, opener in (("python-can", slcanBus), ("reader", SlcanReader)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)  # python-can's word on btr
            bus = opener(channel=f"{pty.path}@57600", sleep_after_open=0, **kw)
        port = bus.serialPortOrig if name == "python-can" else bus.port
        assert port.baudrate == 57600
        opened = pty.read_all()
        bus.shutdown()
        sent[name] = opened, pty.read_all()
    assert sent["reader"] == sent["python-can"]
    assert sent["reader"][0].endswith(b"L\r" if kw.get("listen_only") else b"O\r")
    assert sent["reader"][1] == b"C\r"


def test_refusals_are_python_cans(pty, tmp_path):
    for kw in (dict(bitrate=123), dict(bitrate=500000, btr="0014"),
               dict(timing=can.BitTimingFd(f_clock=80_000_000, nom_brp=1, nom_tseg1=119, nom_tseg2=40,
                                           nom_sjw=40, data_brp=1, data_tseg1=14, data_tseg2=5, data_sjw=5))):
        raised = []
        for opener in (slcanBus, SlcanReader):
            with pytest.raises(can.CanInitializationError) as info, warnings.catch_warnings():
                warnings.simplefilter("ignore", DeprecationWarning)
                opener(channel=pty.path, sleep_after_open=0, **kw)
            raised.append((type(info.value.__cause__), str(info.value)))
            pty.read_all()
        assert raised[0] == raised[1] and raised[0][0] is ValueError
    for opener in (slcanBus, SlcanReader):
        with pytest.raises(can.CanInitializationError, match="could not open port"):
            opener(channel=str(tmp_path / "no-such-port"), sleep_after_open=0)
        with pytest.raises(ValueError, match="Must specify a serial port"):
            opener(channel="", sleep_after_open=0)


# -- what a line becomes ------------------------------------------------------------------------
D8, D64 = "0011223344556677", bytes(range(64)).hex().upper()
LINES = [  # line, expected: fields (id, ext, remote, error, fd, brs, dlc, data hex), None, "bad"
    ("t1238" + D8, (0x123, False, False, False, False, False, 8, D8)),
    ("t1230", (0x123, False, False, False, False, False, 0, "")),
    ("t7ff2abcd", (0x7FF, False, False, False, False, False, 2, "abcd")),
    ("t12320011BEEF", (0x123, False, False, False, False, False, 2, "0011")),  # adapter timestamp
    ("T1FFFFFFF1AA", (0x1FFFFFFF, True, False, False, False, False, 1, "aa")),
    ("x000001231FF", (0x123, True, False, False, False, False, 1, "ff")),     # CANdapter
    ("r1238", (0x123, False, True, False, False, False, 8, "")),
    ("R000001234", (0x123, True, True, False, False, False, 4, "")),
    ("d123F" + D64, (0x123, False, False, False, True, False, 64, D64)),
    ("b123a" + D64[:32], (0x123, False, False, False, True, True, 16, D64[:32])),
    ("D000001230", (0x123, True, False, False, True, False, 0, "")),
    ("B00000123C" + D64[:48], (0x123, True, False, False, True, True, 24, D64[:48])),
    ("FA0", (0x84, False, False, True, False, False, 8, "0030000000000000")),  # bus error, passive
    ("F84", (0x84, False, False, True, False, False, 8, "000C000000000000")),  # bus error, warning
    ("F40", (0x02, False, False, True, False, False, 8, "0000000000000000")),  # arbitration lost
    ("F09", (0x04, False, False, True, False, False, 8, "0001000000000000")),  # overruns
    ("F00", None), ("", None), ("z", None), ("Z", None), ("V1013", None), ("NRDQ1", None),
    ("t12", "bad"), ("t1238AABB", "bad"), ("t1238" + D8[:-1], "bad"), ("t1239" + D8 + "AA", "bad"),
    ("t8001AA", "bad"), ("T200000001AA", "bad"), ("t12 1AA", "bad"), ("t0x11AA", "bad"),
    ("t1232 AABB", "bad"), ("t1231AA123456789", "bad"), ("t1231AAt1231BB", "bad"),
    ("d123G" + D64, "bad"), ("r123", "bad"), ("F", "bad"), ("F0G", "bad"), ("hello", "bad"),
    ("\x00", "bad"), ("t1231\xff\xfe", "bad"), ("\u00e9t1231AA", "bad"),
]


@pytest.mark.parametrize("line, expected", LINES, ids=[repr(x[0][:14]) for x in LINES])
def test_line_rules(line, expected):
    got = parse_lines([line], 12.5)
    if expected is None:
        assert got == []
    elif expected == "bad":
        assert len(got) == 1 and got[0].startswith("unparseable slcan line")
    else:
        (frame,) = got
        assert fields(frame) == (*expected[:7], bytes.fromhex(expected[7])) and frame.timestamp == 12.5


# -- fuzzing: the reader against python-can's over pseudo-terminals --------------------------
class Pair:
    """python-can's slcan bus and the reader, each on its own pseudo-terminal."""

    def __init__(self) -> None:
        self.pc_pty, self.rd_pty = Pty(), Pty()
        self.bus = slcanBus(channel=self.pc_pty.path, sleep_after_open=0)
        self.reader = SlcanReader(self.rd_pty.path, sleep_after_open=0, read_every_s=0.0)
        # the reader stamps frames with the wall clock at its open, then the monotonic clock
        # (drivers/slcan_reader.py): its read windows are taken on that time base, which a
        # wall clock slewed or stepped since (NTP) leaves (a README run: a stamp 2.9 ms before
        # time.time() at the write, on this module-long pair)
        self.epoch = time.time() - time.monotonic()
        self.pc_pty.read_all(0.01)
        self.rd_pty.read_all(0.01)

    def python_can(self, lines: list[bytes]) -> list:
        """python-can's answer per line: a ``can.Message``, ``None`` (ignored) or ``"error"``.

        A line that is not UTF-8 is not sent: python-can fails on it, and for good (it keeps the
        undecodable bytes in its buffer, so every later read fails too).
        """
        utf8 = [_is_utf8(line) for line in lines]
        sent = [line for line, ok in zip(lines, utf8, strict=True) if ok]
        self.pc_pty.write(b"".join(line + b"\r" + SENTINEL + b"\r" for line in sent))
        out = []
        for ok in utf8:
            if not ok:
                out.append("error")
                continue
            try:
                msg = self.bus.recv(2.0)
            except Exception:  # noqa: BLE001 - any parse error of python-can's is its refusal
                msg = "error"
            assert msg is not None, "python-can lost a line"
            if isinstance(msg, can.Message) and is_sentinel(msg):
                out.append(None)
                continue
            out.append(msg)
            assert is_sentinel(self.bus.recv(2.0))
        return out

    def ours(self, lines: list[bytes]) -> tuple[list[list], float, float]:
        """The reader's items per line (0 or 1 each), and the window of the reads on the
        reader's time base (wall clock at open, then monotonic)."""
        t0 = self.epoch + time.monotonic()
        self.rd_pty.write(b"".join(line + b"\r" + SENTINEL + b"\r" for line in lines))
        per_line: list[list] = [[]]
        while len(per_line) <= len(lines):
            got = self.reader.recv_batch(2.0)
            assert got, "the reader lost a line"
            for item in got:
                if isinstance(item, SlcanFrame) and is_sentinel(item):
                    per_line.append([])
                else:
                    per_line[-1].append(item)
        return per_line[:-1], t0, self.epoch + time.monotonic()

    def close(self) -> None:
        self.bus.shutdown()
        self.reader.shutdown()
        self.pc_pty.close()
        self.rd_pty.close()


def _is_utf8(line: bytes) -> bool:
    try:
        line.decode()
    except UnicodeDecodeError:
        return False
    return True


@pytest.fixture(scope="module")
def pair():
    p = Pair()
    yield p
    p.close()


def lawicel(msg: can.Message, lower: bool = False, stamp: str = "", x: bool = False) -> bytes:
    """A frame as an adapter sends it."""
    if msg.is_fd:
        kind, dlc = ("b" if msg.bitrate_switch else "d"), f"{len2dlc(msg.dlc):X}"
    else:
        kind, dlc = ("r" if msg.is_remote_frame else "t"), str(msg.dlc)
    if msg.is_extended_id:
        kind = "x" if x and kind == "t" else kind.upper()
    body = (f"{msg.arbitration_id:08X}" if msg.is_extended_id else f"{msg.arbitration_id:03X}") + dlc
    body += "" if msg.is_remote_frame else bytes(msg.data).hex().upper()
    return (kind + (body.lower() if lower else body) + stamp).encode()


@st.composite
def messages(draw) -> can.Message:
    fd, ext = draw(st.booleans()), draw(st.booleans())
    remote = not fd and draw(st.booleans())
    n = draw(st.sampled_from(CAN_FD_DLC if fd else range(9)))
    ident = draw(st.integers(0, 0x1FFFFFFF if ext else 0x7FF).filter(lambda i: i != SENTINEL_ID))
    return can.Message(arbitration_id=ident, is_extended_id=ext,
                       is_remote_frame=remote, is_fd=fd, bitrate_switch=fd and draw(st.booleans()), dlc=n,
                       data=None if remote else draw(st.binary(min_size=n, max_size=n)))


_CHARS = list(b"0123456789abcdefABCDEFGtTrRdDbBxXFzZVN _-+\n\x00") + [0xC3, 0xA9, 0xFF]


def mutate(line: bytes, ops: list[tuple[str, int, int]]) -> bytes:
    b = bytearray(line)
    for op, i, c in ops:
        i %= len(b) + 1
        if op == "cut":
            del b[i:]
        elif op == "drop" and i < len(b):
            del b[i]
        elif op == "set" and i < len(b):
            b[i] = _CHARS[c % len(_CHARS)]
        elif op == "insert":
            b.insert(i, _CHARS[c % len(_CHARS)])
        elif op == "dup":
            b[i:i] = b[i : i + 1 + c % 20]
    return bytes(b)


_OPS = ("cut", "drop", "set", "insert", "dup")
_OTHER = [b"", b"z", b"Z", b"V1013", b"NRDQ1", b"F00", b"F84", b"F", b"Fxx", b"hello", b"\xff"]


@st.composite
def line_cases(draw) -> tuple[bytes, can.Message | None]:
    """A line, and the frame it says when it was not mutated."""
    if draw(st.integers(0, 9)) == 0:
        return draw(st.sampled_from(_OTHER)), None
    msg = draw(messages())
    stamp = draw(st.sampled_from(["", "", "1A2B", "00ff12ab"]))
    line = lawicel(msg, draw(st.booleans()), stamp, draw(st.booleans()))
    ops = draw(st.lists(st.tuples(st.sampled_from(_OPS), st.integers(0, 200), st.integers(0, 255)),
                        max_size=3))
    return (mutate(line, ops), None) if ops else (line, msg)


def check_against_python_can(pair: Pair, cases: list[tuple[bytes, can.Message | None]]) -> None:
    """Where the reader takes a line python-can takes it alike; where python-can refuses it, the
    reader counts it; a line made from a frame is that frame; timestamps fall in the read's
    window on the reader's time base."""
    lines = [c[0] for c in cases]
    ref = pair.python_can(lines)
    ours, t0, t1 = pair.ours(lines)
    for (line, msg), theirs, mine in zip(cases, ref, ours, strict=True):
        assert len(mine) <= 1, (line, mine)
        got = mine[0] if mine else None
        TALLY["bad" if isinstance(got, str) else "nothing" if got is None else
              "error_frame" if got.is_error_frame else "frame"] += 1
        if isinstance(got, SlcanFrame):
            assert t0 <= got.timestamp <= t1
            if not got.is_error_frame:
                assert isinstance(theirs, can.Message) and fields(got) == fields(theirs), line
        if theirs == "error":
            assert isinstance(got, str), line
        if msg is not None:
            assert isinstance(got, SlcanFrame) and fields(got) == fields(msg), line


@SHORT
@given(st.lists(line_cases(), min_size=1, max_size=8))
def test_reader_agrees_with_python_can(pair, cases):
    check_against_python_can(pair, cases)


@SHORT
@given(st.lists(line_cases(), min_size=1, max_size=30), st.lists(st.integers(1, 64), min_size=1, max_size=20),
       st.sampled_from([b"\r", b"\a"]))
def test_torn_reads_parse_as_one_read(pair, cases, cuts, end):
    """The stream written in pieces, each read before the next is written: the same items as
    the whole stream parsed at once (a BELL ends a line as a CR does)."""
    stream = b"".join(c[0].replace(b"\r", b"").replace(b"\a", b"") + end for c in cases)
    text = stream.decode("latin-1").replace("\a", "\r")
    want = parse_lines(text.split("\r")[:-1], 0.0)
    got, at, k = [], 0, 0
    while at < len(stream):
        piece = stream[at : at + cuts[k % len(cuts)]]
        at, k = at + len(piece), k + 1
        pair.rd_pty.write(piece)
        assert select.select([pair.reader.fileno()], [], [], 2.0)[0]
        got += pair.reader.recv_batch(0.0)
    while len(got) < len(want):  # what was written but not yet read
        more = pair.reader.recv_batch(1.0)
        assert more, "the reader lost lines"
        got += more
    assert [g if isinstance(g, str) else fields(g) for g in got] == [
        w if isinstance(w, str) else fields(w) for w in want]


def test_a_line_without_end_is_cut_and_counted(pair):
    pair.rd_pty.write(b"\xff" * 300)
    got = pair.reader.recv_batch(1.0)
    assert len(got) == 1 and got[0].startswith("unparseable slcan line")
    pair.rd_pty.write(b"t1231AA\r" + SENTINEL + b"\r")
    got = []
    while len(got) < 2:
        got += pair.reader.recv_batch(1.0)
    assert fields(got[0]) == (0x123, False, False, False, False, False, 1, b"\xaa")


def test_vanished_port_raises(pty):
    reader = SlcanReader(pty.path, sleep_after_open=0, read_every_s=0.0)
    try:
        pty.write(b"t1231AA\r")
        assert len(reader.recv_batch(1.0)) == 1
        pty.close()  # the adapter unplugged
        with pytest.raises(OSError):
            for _ in range(10):
                reader.recv_batch(0.2)
    finally:
        with contextlib.suppress(can.CanError):  # "C" cannot reach an unplugged adapter
            reader.shutdown()
        reader.shutdown()  # a second time: nothing


def test_a_reader_waits_its_period_and_its_timeout(pty):
    reader = SlcanReader(pty.path, sleep_after_open=0, read_every_s=0.05)
    try:
        t = time.monotonic()
        assert reader.recv_batch(0.1) == [] and 0.09 < time.monotonic() - t < 1.0
        pty.write(b"t1231AA\r")
        assert len(reader.recv_batch(1.0)) == 1
        pty.write(b"t1231BB\r")
        assert reader.recv_batch(0.0) == []  # inside the period: not read yet
        t = time.monotonic()
        assert len(reader.recv_batch(1.0)) == 1 and time.monotonic() - t < 0.5
    finally:
        reader.shutdown()


# -- long run ------------------------------------------------------------------------------------
def seeded_cases(seed: int, n: int = 10) -> list[tuple[bytes, can.Message | None]]:
    """The same kinds of line as :func:`line_cases`, built from a seed."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        if rng.integers(10) == 0:
            out.append((_OTHER[rng.integers(len(_OTHER))], None))
            continue
        fd, ext = bool(rng.integers(2)), bool(rng.integers(2))
        remote = not fd and bool(rng.integers(2))
        size = int(rng.choice(CAN_FD_DLC if fd else range(9)))
        ident = int(rng.integers(0x20000000 if ext else 0x800))
        msg = can.Message(arbitration_id=ident if ident != SENTINEL_ID else 0, is_extended_id=ext,
                          is_remote_frame=remote, is_fd=fd, bitrate_switch=fd and bool(rng.integers(2)),
                          dlc=size, data=None if remote else rng.bytes(size))
        line = lawicel(msg, bool(rng.integers(2)), ["", "1A2B", "00ff12ab"][rng.integers(3)],
                       bool(rng.integers(2)))
        ops = [(_OPS[rng.integers(5)], int(rng.integers(200)), int(rng.integers(256)))
               for _ in range(rng.integers(4))]
        out.append((mutate(line, ops), None) if ops else (line, msg))
    return out


@pytest.fixture
def long_run(request: pytest.FixtureRequest, capsys: pytest.CaptureFixture):
    """Long runs only with ``pytest -m slow`` or ``RAMDAQ_LONG_FUZZ=1`` (CI runs every test)."""
    yield from tallied_long_run(request, capsys, TALLY, "lines")


@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_reader_long_run(pair, long_run):
    given(st.integers(0, 2**63 - 1))(settings(max_examples=10_000, deadline=None, database=None,
                                              suppress_health_check=[HealthCheck.too_slow])(
        lambda seed: check_against_python_can(pair, seeded_cases(seed))))()
    assert sum(long_run.values()) >= 100_000 and long_run["frame"] and long_run["bad"]
