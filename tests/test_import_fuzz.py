"""Fuzzing the importers (CSV parser, UFF 58 and TDMS readers) with hypothesis.

Every input -- a valid small file mutated (bytes cut, inserted, overwritten, duplicated, the file
truncated), a CSV built from random cells, or random bytes -- must either import (and then give
well-formed blocks) or raise the importers' :class:`ImportFormatError` with a one-line message
naming the file; never another exception, and each within ``MAX_SECONDS`` of CPU time.

The default run (CI) tries ``SHORT`` examples per importer, derandomised so it is repeatable. The
long runs (``LONG`` = 100 000 inputs per importer) are marked ``slow``, out of the default run:
``pytest -m slow tests/test_import_fuzz.py`` runs them and prints how many inputs imported and
how many were refused (they also skip themselves unless ``-m slow`` or ``RAMDAQ_LONG_FUZZ=1``
asks for them, should the default run ever include slow tests).
"""

from __future__ import annotations

import io
import os
import time
from collections import Counter

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ramdaq.analysis.model.rig import load_rig
from ramdaq.drivers.files.import_common import ImportFormatError
from ramdaq.drivers.files.import_csv import CsvImportDevice
from ramdaq.drivers.files.import_tdms import TdmsImportDevice
from ramdaq.drivers.files.import_uff import UffImportDevice
from tests.test_imports import RIG, write_csv, write_tdms, write_uff58

SHORT = 200
LONG = 100_000
MAX_SECONDS = 5.0
"""CPU seconds (this thread's) one input may take: a runaway loop, not a slow machine. Wall time
failed a 1-byte input at 8 s on a machine at load 20 while its CPU time was small."""
_COMMON = dict(deadline=None, database=None, suppress_health_check=list(HealthCheck))
short = settings(max_examples=SHORT, derandomize=True, **_COMMON)
long = settings(max_examples=LONG, **_COMMON)
DEVICES = {"csv": CsvImportDevice, "uff": UffImportDevice, "tdms": TdmsImportDevice}


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A folder, the rig, and small valid files of each format to mutate."""
    d = tmp_path_factory.mktemp("fuzz")
    rng = np.random.default_rng(1)
    step = 1.1690623668802712e-04
    x = np.round(rng.normal(0, 40, (3, 48))) * step
    x[1, 5] = np.nan
    csv = write_csv(d / "base.csv", np.arange(48) / 2048, x, ["g01", "g02", "gage 3"],
                    units=["m/s^2", "g", "m/s^2"]).read_bytes()
    xf = x.copy()
    xf[1, 5] = 0.0
    uff = [write_uff58(d / "base.uff", xf[:2, :24], [1, 2], binary=b).read_bytes()
           for b in (False, True)]
    tdms = write_tdms(d / "base.tdms", xf[:2], ["g01", "g02"], segment=16).read_bytes()
    return d, load_rig(RIG), {"csv": [csv], "uff": uff, "tdms": [tdms]}


def check(work, fmt: str, data: bytes, tally: Counter) -> None:
    """Import ``data`` as a ``fmt`` file: it imports, or it is refused in one line."""
    d, rig, _ = work
    path = d / f"input.{fmt}"
    path.write_bytes(data)
    t = time.thread_time()
    try:
        with DEVICES[fmt](path, rig=rig, allow_gaps=True) as dev:  # the gap path fuzzed too
            info, prev = dev.info, None
            for b in dev:
                assert b.counts.dtype == np.int32 and b.counts.shape[0] == info.n_channels
                assert np.all(np.isfinite(b.scale)) and np.all(b.scale > 0)
                assert b.fs_hz == info.fs_hz and b.n_samples > 0
                assert prev is None or b.first_sample > prev.first_sample + prev.n_samples - 1
                prev = b
        tally["imported"] += 1
    except ImportFormatError as err:
        msg = str(err)
        assert "\n" not in msg and str(path) in msg, msg
        tally["refused"] += 1
    assert time.thread_time() - t < MAX_SECONDS


_TOKENS = [b",", b";", b"\t", b"\n", b"\r\n", b"nan", b"-", b"1e308", b"-1e-320", b"inf", b"",
           b"#", b'"', b"    -1\n", b"    58\n", b"TDSm", b"\xff\xff\xff\xff", b"\x00\x00\x00\x00",
           b"g01", b" [g]", b"0.000488281", b"\xc3", b"        12"]


@st.composite
def mutated(draw, bases: list[bytes]) -> bytes:
    """A valid file with 1-6 edits: cut, insert, overwrite, truncate, duplicate."""
    b = bytearray(draw(st.sampled_from(bases)))
    for _ in range(draw(st.integers(1, 6))):
        op = draw(st.integers(0, 4))
        p = draw(st.integers(0, len(b)))
        if op == 0:
            del b[p:p + draw(st.integers(1, 64))]
        elif op == 1:
            b[p:p] = draw(st.one_of(st.sampled_from(_TOKENS), st.binary(max_size=12)))
        elif op == 2 and b:
            b[min(p, len(b) - 1)] = draw(st.integers(0, 255))
        elif op == 3:
            del b[p:]
        else:
            q = draw(st.integers(0, len(b)))
            b[p:p] = b[q:q + draw(st.integers(1, 200))]
    return bytes(b)


_CELL = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-10**12, 10**12).map(str),
    st.sampled_from(["", "nan", " 1.5 ", "1,5", "1e999", "0x10", "1_0", '"2.0"', "abc", "-"]),
    st.text(max_size=4))
_NAME = st.sampled_from(["time", "t [ms]", "g01", "g02 [g]", "gage 3 (m/s^2)", "4", "g17",
                         "Accel", "g01", "g05 [V]", ""])


@st.composite
def csv_from_cells(draw) -> bytes:
    """Header, optional units row and rows of random cells, mostly on a plausible time grid."""
    delim = draw(st.sampled_from([",", ";", "\t"]))
    ncols = draw(st.integers(1, 4))
    head = [draw(_NAME) for _ in range(ncols)]
    lines = [delim.join(head)]
    if draw(st.booleans()):
        lines.append(delim.join(draw(st.sampled_from(["s", "m/s^2", "g", "V", ""]))
                                for _ in range(ncols)))
    for i in range(draw(st.integers(0, 30))):
        n = ncols + draw(st.sampled_from([0, 0, 0, 0, -1, 1]))
        t = repr(i / 2048) if draw(st.integers(0, 9)) else draw(_CELL)
        lines.append(delim.join([t] + [draw(_CELL) for _ in range(max(n - 1, 0))]))
    return ("\n".join(lines) + draw(st.sampled_from(["\n", "", "\r\n"]))).encode(
        "utf-8", "surrogatepass")


@st.composite
def csv_on_grid(draw) -> bytes:
    """A well-formed CSV of random values (any magnitude, NaN, empty): mostly imports."""
    unit = draw(st.sampled_from(["m/s^2", "g"]))
    rows = [f"time [s],g01 [{unit}],g02"]
    values = st.one_of(st.floats(allow_infinity=False), st.just(""),
                       st.integers(-2**40, 2**40).map(lambda k: k * 1e-4))
    for i in range(draw(st.integers(1, 40))):
        a, b = draw(values), draw(values)
        rows.append(f"{i / 2048!r},{a if isinstance(a, str) else repr(a)},"
                    f"{b if isinstance(b, str) else repr(b)}")
    return ("\n".join(rows) + "\n").encode()


@st.composite
def tdms_from_values(draw) -> bytes:
    """A well-formed TDMS file of random channels (type, length, values, properties)."""
    from nptdms import ChannelObject, TdmsWriter

    n = draw(st.integers(1, 40))
    dtype = draw(st.sampled_from([np.float64, np.float32, np.int16, np.int32]))
    values = st.floats(allow_infinity=False, width=64 if dtype == np.float64 else 32) \
        if dtype in (np.float64, np.float32) else st.integers(-2**15, 2**15 - 1)
    channels = []
    for name in draw(st.lists(st.sampled_from(["g01", "g02", "gage 3", "4", "Accel", "time"]),
                              min_size=1, max_size=3, unique=True)):
        props = {"unit_string": draw(st.sampled_from(["m/s^2", "g", "V", ""]))}
        if draw(st.integers(0, 5)):
            props["wf_increment"] = draw(st.sampled_from([1 / 2048, 1e-3, 0.0, -1.0, 1e-12]))
        data = np.array([draw(values) for _ in range(n)], dtype=dtype)
        if name == "time":
            data = np.arange(n) / 1000.0
        channels.append(ChannelObject("g", name, data, properties=props))
    buf = io.BytesIO()
    with TdmsWriter(buf) as w:
        w.write_segment(channels)
    return buf.getvalue()


def _inputs(fmt: str, bases: list[bytes]) -> st.SearchStrategy[bytes]:
    prefix = {"csv": b"time,g01\n", "uff": b"    -1\n    58\n", "tdms": b"TDSm"}[fmt]
    parts = [mutated(bases), st.binary(max_size=2048),
             st.binary(max_size=512).map(lambda b: prefix + b)]
    if fmt == "csv":
        parts += [csv_from_cells(), csv_on_grid()]
    if fmt == "tdms":
        parts.append(tdms_from_values())
    return st.one_of(*parts)


def _run(work, fmt: str, cfg: settings) -> Counter:
    tally: Counter = Counter()

    @cfg
    @given(data=_inputs(fmt, work[2][fmt]))
    def one(data: bytes) -> None:
        check(work, fmt, data, tally)

    one()
    return tally


@pytest.mark.parametrize("fmt", list(DEVICES))
def test_fuzz_short(work, fmt):
    tally = _run(work, fmt, short)
    assert sum(tally.values()) >= SHORT
    assert tally["refused"] > 0 and tally["imported"] > 0  # both paths were exercised


def _long_run_wanted(config: pytest.Config) -> bool:
    return os.environ.get("RAMDAQ_LONG_FUZZ") == "1" or config.getoption("markexpr") == "slow"


@pytest.mark.slow
@pytest.mark.timeout(3600)
@pytest.mark.parametrize("fmt", list(DEVICES))
def test_fuzz_long(work, fmt, request, capsys):
    if not _long_run_wanted(request.config):
        pytest.skip("long fuzz run: pytest -m slow (or RAMDAQ_LONG_FUZZ=1)")
    t = time.perf_counter()
    tally = _run(work, fmt, long)
    with capsys.disabled():
        print(f"\n{fmt}: {sum(tally.values())} inputs in {time.perf_counter() - t:.0f} s: "
              f"{tally['imported']} imported, {tally['refused']} refused, no other outcome")
    assert sum(tally.values()) >= LONG


def test_valid_bases_import(work):
    """The files the fuzzer mutates are themselves importable (so mutations start from valid)."""
    for fmt, bases in work[2].items():
        for data in bases:
            tally: Counter = Counter()
            check(work, fmt, data, tally)
            assert tally["imported"] == 1, fmt
