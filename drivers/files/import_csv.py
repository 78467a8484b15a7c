"""Import a CSV recording (a time column and one column per gage) as a device.

::

    with open_device("trial.csv", rig=rig) as dev:       # or CsvImportDevice("trial.csv", rig=rig)
        for block in dev:
            ...

The file
--------
UTF-8 text (a byte-order mark is allowed), lines ending in LF or CRLF:

* optional comment lines starting with ``#`` before the header, and a header block (``key;value``
  lines, a title, blank lines): the column names are the last line above the first row of
  numbers with as many fields (the line before when that is a units row), the lines above it are
  skipped and counted in ``notes["skipped_lines"]``;
* a header of column names separated by ``,``, ``;`` or a tab (the most frequent of the three
  in the header is the delimiter); the **first column is time**, the others are channels named
  like gages (``g01``, ``gage 1``, ``1``) unless ``channels=`` maps them. A file without a time
  column: with ``fs_hz=`` (``--fs``) and a first column not named like a time (``time``, ``t``,
  ``Zeit``, ``timestamp``, any name with a time unit), every column is a channel and row ``k``
  is sample ``k`` (``notes["time_column"]`` is None);
* units either in the names, ``"g01 [m/s^2]"`` or ``"g01 (g)"``, or in a row right after the
  header whose first cell is not a number (``s,m/s^2,g,...``). Time is in s, ms or us, stated
  there or by the column's name (``time_s``, ``t_ms``), else given as ``time_unit=``
  (``--time-unit``): a time column that says no unit is an error, never taken as seconds.
  Channels are in m/s^2 or g, a force channel in N, kN or lbf. A channel without a unit is taken
  as m/s^2 (a force channel: its rig unit), and said so in ``StreamInfo.extra``;
* one row per sample, no thousands separators; a decimal point, or with a ``;`` or tab
  delimiter a decimal comma (``0,000200``; ``notes["decimal"] = ","``). A decimal comma in a
  comma-separated file (quoted ``"1,5"``) is refused naming its line, column and why. An empty
  cell or ``nan`` is a missing sample: an error naming its line and column, or with ``allow_gaps=``
  (``--allow-gaps``) a gap: that row is not streamed. Blank lines and ``#`` lines are skipped.

The rate fitted to the time column must be the rig's ``daq.sample_rate_hz`` unless ``fs_hz=``
(``--fs``) states it.

The times must lie on one sample grid: the rate is fitted to them and snapped to the value
with the fewest digits that keeps every row within 0.1 sample of its grid point (times printed
with six decimals at 2048 Hz give 2048.0 exactly). Times rounded to a coarser printed step
(0.1 ms at 2048 Hz: 0.20 sample) may lie half that step further from their grid point
(``notes["time_resolution_s"]``), the rate fitted over the whole span.
A step of a whole number of samples is a gap
(those samples are missing); a time off the grid, repeated or going back is refused naming the
line, as are a row with too few or too many fields and a cell that is not a number.

Parsing is numpy's C reader on 4 MB pieces; a piece it refuses (empty cells, a bad cell) is
parsed again line by line, which finds the line to name. Memory: the whole table as float64.
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Callable, Mapping
from os import PathLike

import numpy as np

from ...analysis.model.rig import Rig
from .import_common import FileImportDevice, ImportFormatError, SourceTable, option, snap_rate

__all__ = ["CsvImportDevice", "read_csv_table", "sample_grid"]

_CHUNK_BYTES = 4 << 20
_SLOW_BYTES = 64 << 10  # pieces numpy refuses are halved down to this, then read line by line
_GRID_TOL = 0.1  # samples: how far a row's time may lie from its grid point
_NUMBER = re.compile(r"^[+-]?(?:(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|nan|inf|infinity)$",
                     re.IGNORECASE)
_COMMA_NUMBER = re.compile(r"^[+-]?(?:\d+,\d*|,\d+)(?:[eE][+-]?\d+)?$")
_SCAN_LINES = 1000  # content lines searched for the first data row below a header block
_NAME_UNIT = re.compile(r"^(.*?)\s*[\[(]\s*([^\])]*?)\s*[\])]$")
_TIME_UNITS = {"s": 1.0, "sec": 1.0, "ms": 1e-3, "us": 1e-6, "\u00b5s": 1e-6}
_TIME_NAME = re.compile(r"^(?:t|time|zeit)[\s_\-/]+(s|sec|ms|us|\u00b5s)$", re.IGNORECASE)


class CsvImportDevice(FileImportDevice):
    """A CSV file streamed as blocks (back-end name ``"csv"``).

    Parameters
    ----------
    path : str or PathLike
        The CSV file.
    rig : Rig or path
        The rig of the trial.
    channels : mapping of str to int, optional
        Column name -> gage number; only these columns are imported.
    medium : str, optional
        Override the rig's medium.
    block_s : float
        Longest block, s.
    fs_hz : float, optional
        Sample rate, Hz, instead of the one fitted to the time column (needed for one row);
        the rows must lie on its grid. Needed when the rig's rate differs.
    time_unit : {"s", "ms", "us"}, optional
        The time column's unit when its header does not say it.
    force_channel, allow_gaps, sensitivity
        As :class:`FileImportDevice`.
    """

    kind = "csv"

    def __init__(self, path: str | PathLike, *, rig: Rig | str | PathLike,
                 channels: Mapping[str, int] | None = None, medium: str | None = None,
                 block_s: float = 0.1, fs_hz: float | None = None, time_unit: str | None = None,
                 force_channel: str | None = None, allow_gaps: bool = False,
                 sensitivity: float | Mapping[str, float] | None = None) -> None:
        super().__init__(path, rig=rig, channels=channels, medium=medium, block_s=block_s,
                         fs_hz=fs_hz, force_channel=force_channel, allow_gaps=allow_gaps,
                         sensitivity=sensitivity)
        if time_unit is not None and time_unit not in _TIME_UNITS:
            raise ValueError(f"csv: time_unit {time_unit!r} is not one of s, ms, us")
        self.time_unit = time_unit

    def _load(self) -> SourceTable:
        return read_csv_table(self.path.read_bytes(), str(self.path), fs_hz=self.fs_hz,
                              time_unit=self.time_unit, rate_hint=self.rig.daq.sample_rate_hz)


def read_csv_table(data: bytes, name: str = "<csv>", *, fs_hz: float | None = None,
                   time_unit: str | None = None, rate_hint: float | None = None) -> SourceTable:
    """Parse CSV bytes into a :class:`SourceTable`; see the module docstring for the format.
    ``rate_hint`` (Hz, the rig's) is the rate taken when the times allow it (:func:`sample_grid`).

    Raises
    ------
    ImportFormatError
        One line naming ``name``, the line of the file and what is wrong.
    """
    nul = data.find(b"\x00")
    if nul >= 0:
        raise ImportFormatError(f"{name}: not a text file (byte {nul} is NUL)")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise ImportFormatError(f"{name}: not UTF-8 text (byte {err.start})") from None
    lines = _Lines(text)
    skipped = _skip_header_block(lines)
    header_no, header = lines.next_content(skip_comments=True)
    if header is None:
        raise ImportFormatError(f"{name}: empty file (no header line)")
    delim = max((",", ";", "\t"), key=header.count)
    if header.count(delim) == 0:
        raise ImportFormatError(f"{name}: line {header_no}: the header has one column; expected "
                                f"time and channels separated by ',', ';' or a tab")
    names, units = [], []
    for cell in header.split(delim):
        cell = cell.strip().strip('"').strip()
        m = _NAME_UNIT.match(cell)
        names.append(m.group(1) if m else cell)
        units.append(m.group(2) if m else None)
    ncols = len(names)
    if any(not n for n in names):
        raise ImportFormatError(f"{name}: line {header_no}: column {names.index('') + 1} has no "
                                f"name")
    if len(set(names)) != ncols:
        dup = next(n for n in names if names.count(n) > 1)
        raise ImportFormatError(f"{name}: line {header_no}: column name {dup!r} appears twice")
    mark = lines.pos
    row_no, row = lines.next_content(skip_comments=True)
    first_cell = row.split(delim)[0].strip().strip('"').strip() if row is not None else ""
    if first_cell and not _NUMBER.match(first_cell) and not (
            delim != "," and _COMMA_NUMBER.match(first_cell)):
        cells = [c.strip().strip('"').strip() for c in row.split(delim)]
        if len(cells) != ncols:
            raise ImportFormatError(f"{name}: line {row_no}: units row has {len(cells)} fields, "
                                    f"expected {ncols}")
        units = [u or c or None for u, c in zip(units, cells, strict=True)]
    else:
        lines.pos, lines.number = mark, header_no
    notes: dict = {"delimiter": delim, "time_column": names[0], **_stated_header(text, name)}
    if skipped:
        notes["skipped_lines"] = skipped
    if delim != "," and "," in text[lines.pos:]:  # a decimal comma: ',' is no delimiter here
        text = text[:lines.pos] + text[lines.pos:].replace(",", ".")
        notes["decimal"] = ","
    table, line_of_row = _parse_rows(text, lines.pos, lines.number, delim, names, name)
    if table.shape[0] > 1 and not text.endswith(("\n", "\r")):
        # a file cut off mid-line: its last row's last value may be a cut number (-0.152 of
        # -0.15203...), read as data; the row is left out, and the import says so
        notes["cut_last_line"] = int(line_of_row[-1])
        table, line_of_row = table[:-1], line_of_row[:-1]
    if table.shape[0] == 0:
        raise ImportFormatError(f"{name}: no data rows after the header")
    where = lambda r: f"line {line_of_row[r]}"  # noqa: E731
    if fs_hz is not None and time_unit is None and not _time_like(names[0], units[0]):
        # no column names a time: every column is a channel, the rows are samples at --fs
        notes["time_column"] = None
        return SourceTable(names=names, units=units, sample_index=np.arange(table.shape[0]),
                           fs_hz=float(fs_hz), t0_s=0.0, read=lambda i: table[:, i], fmt="csv",
                           notes={**notes, "time_gaps": 0}, where=where)
    scale = _TIME_UNITS[_time_unit(names[0], units[0], time_unit, name)]
    t = table[:, 0] * scale
    res = printed_resolution(table[:, 0])
    steps, digits = significant_step(table[:, 0])
    # printed to N significant digits (%g) rather than to fixed decimals: the column's one
    # resolution is its smallest values' and most rows are printed coarser than it (a fixed-
    # decimals column's rows are mostly at its resolution, a round value or two coarser)
    if digits and np.median(steps) > res:
        res = np.maximum(res, steps)
        notes["time_digits"] = digits
    index, fs, grid = sample_grid(t, fs_hz, where, name, rate_hint=rate_hint,
                                  resolution_s=res * scale)
    return SourceTable(names=names[1:], units=units[1:], sample_index=index, fs_hz=fs,
                       t0_s=float(t[0]), read=lambda i: table[:, i + 1], fmt="csv",
                       notes={**notes, **grid}, where=where)


_TIME_LIKE = re.compile(r"^(?:t|time|times|zeit|timestamp|time[\s_\-]?stamp|sec|seconds)"
                        r"(?:[\s_\-/.].*)?$", re.IGNORECASE)


def _time_like(column: str, unit: str | None) -> bool:
    """The first column is a time: its unit is a time unit, or its name is a time's
    (``time``, ``t``, ``Zeit``, ``timestamp``, ``time_s``, ...)."""
    if unit is not None and unit.strip().lower() in _TIME_UNITS:
        return True
    return bool(_TIME_LIKE.match(column.strip()))


def printed_resolution(t: np.ndarray) -> float:
    """The step the times were printed to, in their own unit: the largest power of ten (1e-9
    .. 1) that every value is a multiple of (within 1e-6 of it); 0.0 when none is, i.e. the
    times were printed with more than 9 decimals (full precision)."""
    if t.size == 0:
        return 0.0
    sample = _sampled(t)
    for d in range(10):
        if _whole(sample * 10.0**d):
            return 10.0**-d
    return 0.0


def significant_step(t: np.ndarray) -> tuple[np.ndarray, int]:
    """Each time's printing step, in its own unit, if the column was printed to a number of
    significant digits (C's ``%g``, numpy's and many exports' default; a spreadsheet's General):
    ``10^(e - N + 1)`` with ``e`` the value's decimal exponent, for the fewest digits ``N`` (1 to
    15) that every value is printed to (within 1e-6 of a multiple, as
    :func:`printed_resolution`); a zero's step is 0, a missing time's NaN. Returns the steps (as
    ``t``) and ``N``, 0 (and no steps) when no ``N`` up to 15 fits. A ``%g`` column's steps grow
    with the time (0.0001 s from 10 s on, 0.001 s from 100 s), which one resolution misses."""
    sample = _sampled(t)
    v = sample[np.isfinite(sample) & (sample != 0)]     # a missing time is refused later, by row
    e = np.floor(np.log10(np.abs(v)))
    for n in range(1, 16):
        if v.size and _whole(v * 10.0 ** (n - 1 - e)):
            with np.errstate(divide="ignore", invalid="ignore"):
                ea = np.floor(np.log10(np.abs(t)))
            return np.where(t != 0, 10.0 ** (ea - n + 1), 0.0), n
    return np.zeros_like(t), 0


def _sampled(t: np.ndarray) -> np.ndarray:
    """``t``, or every k-th value of it down to 100 000 values (a column's printing, read on a
    sample of its rows)."""
    return t if t.size <= 100_000 else t[:: -(-t.size // 100_000)]


def _whole(x: np.ndarray) -> bool:
    """Whether every value of ``x`` is a whole number, within 1e-6 (1e-15 relative beyond 1e9)."""
    return bool(np.all(np.abs(x - np.rint(x)) < 1e-6 * np.maximum(1.0, 1e-9 * np.abs(x))))


_MEDIUM_LINE = re.compile(r"^#\s*medium:\s*(\S+)", re.MULTILINE)
_ANTI_ALIAS_LINE = re.compile(r"^#\s*anti-alias:\s*order\s+(\S+),\s*(\S+)\s*Hz", re.MULTILINE)
_SCALE_LINE = re.compile(r"^#\s*scale \[SI unit per count\]:(.*)$", re.MULTILINE)


def _stated_header(text: str, name: str) -> dict:
    """What the ``#`` lines at the top of the file state for a re-import, as ``ramdaq
    export-csv`` writes them: ``{"medium": "water"}`` from ``# medium: water`` and
    ``{"scales": {"g01": 1.2e-4, ...}}`` (SI unit per count) from ``# scale [SI unit per
    count]: g01=..., ...``, ``{"anti_alias": (4, 800.0)}`` from ``# anti-alias: order 4, 800.0
    Hz`` (the recorded rig's filter, which a channels-only rig then names); empty when they
    are not there. A stated medium other than air or
    water, or a scale that is not a positive number, is refused naming it."""
    end = 0
    while end < len(text) and (text.startswith("#", end) or text[end] in "\r\n"):
        nl = text.find("\n", end)
        end = len(text) if nl < 0 else nl + 1
    top, out = text[:end], {}
    m = _MEDIUM_LINE.search(top)
    if m and m.group(1) != "(none":
        if m.group(1) not in ("air", "water"):
            raise ImportFormatError(f"{name}: '# medium: {m.group(1)}': expected air or water")
        out["medium"] = m.group(1)
    m = _ANTI_ALIAS_LINE.search(top)
    if m:
        try:
            order, hz = int(m.group(1)), float(m.group(2))
        except ValueError:
            order, hz = 0, math.nan
        if not (0 < order <= 16 and 0 < hz < math.inf):
            raise ImportFormatError(f"{name}: '{m.group(0)}': expected '# anti-alias: order N, F Hz'")
        out["anti_alias"] = (order, hz)
    m = _SCALE_LINE.search(top)
    if m:
        scales = {}
        for item in filter(None, (i.strip() for i in m.group(1).split(","))):
            key, _, value = item.rpartition("=")
            try:
                scales[key.strip()] = float(value)
            except ValueError:
                scales[key.strip()] = math.nan
            if not key.strip() or not 0 < scales[key.strip()] < math.inf:
                raise ImportFormatError(f"{name}: '# scale' line: {item!r} is not CHANNEL=SCALE "
                                        f"with a positive scale")
        out["scales"] = scales
    return out


def _time_unit(column: str, stated: str | None, given: str | None, name: str) -> str:
    """The time column's unit (a key of ``_TIME_UNITS``): the one its header or units row
    states (``"t [ms]"``, ``"time (us)"``), else its name's suffix (``time_s``, ``t_ms``), else
    ``given`` (``--time-unit``). Stated and given must agree; neither is an error."""
    if stated is None:
        m = _TIME_NAME.match(column.strip())
        stated = m.group(1) if m else None
    if stated is not None:
        unit = stated.strip().lower()
        if unit not in _TIME_UNITS:
            if not _time_like(column, None):  # a data column first: the file has no time column
                raise ImportFormatError(
                    f"{name}: no time column (the first column, {column!r}, is in {stated!r}, "
                    f"not s, ms or us): give the rate, {option('fs_hz=', '--fs')} HZ")
            raise ImportFormatError(f"{name}: time column {column!r} is in {stated!r}; expected "
                                    f"s, ms or us")
        if given is not None and _TIME_UNITS[given] != _TIME_UNITS[unit]:
            raise ImportFormatError(f"{name}: time column {column!r} says {stated!r}, but the time "
                                    f"unit given is {given!r}")
        return unit
    if given is None:
        hint = "" if _time_like(column, None) else (
            f"; a file without a time column: give its rate, {option('fs_hz=', '--fs')} HZ")
        raise ImportFormatError(f"{name}: time column {column!r} does not say its unit; name it "
                                f"like time_s, 't [ms]', 'time (us)', or give "
                                f"{option('time_unit=', '--time-unit')} s|ms|us{hint}")
    return given


def _data_row(line: str) -> tuple[str, int] | None:
    """``(delimiter, fields)`` if ``line`` is a row of numbers (decimal commas allowed with a
    ``;`` or tab delimiter), else None."""
    for d in ("\t", ";", ","):
        if d not in line:
            continue
        cells = [c.strip().strip('"').strip() for c in line.split(d)]
        if cells[0] and all(not c or _NUMBER.match(c) or (d != "," and _COMMA_NUMBER.match(c))
                            for c in cells):
            return d, len(cells)
    return None


def _units_like(line: str, delim: str) -> bool:
    """A units row: its first cell (the time column's) is a time unit, bracketed or not."""
    first = line.split(delim)[0].strip().strip('"').strip().strip("[]()").strip().lower()
    return first in _TIME_UNITS


def _skip_header_block(lines: _Lines) -> dict | None:
    """Move ``lines`` past a header block (``key;value`` lines, a title) above the column
    names: the column names are the last line above the first row of numbers with as many
    fields (the one before it when that is a units row). Returns ``{"count", "first",
    "last"}`` (file lines) of the lines skipped, or None; nothing moves when no row of numbers
    is found in the first lines (the reader then names what is wrong)."""
    probe = _Lines(lines.text)
    seen: list[tuple[int, int, str | None]] = []  # (line number, pos before it, line or None)
    prev = 0
    while len(seen) < _SCAN_LINES:
        before = probe.pos
        no, line = probe.next_content(skip_comments=True)
        if line is None:
            return None
        if no > prev + 1:
            seen.append((no - 1, before, None))  # a blank or comment line: a break
        prev = no
        found = _data_row(line)
        if found is not None:
            break
        seen.append((no, before, line))
    else:
        return None
    delim, ncols = found
    run = []
    for item in reversed(seen):
        if item[2] is None or len(item[2].split(delim)) != ncols:
            break
        first = item[2].split(delim)[0].strip().strip('"').strip()
        if _NUMBER.match(first) or _COMMA_NUMBER.match(first):
            return None  # a row of data with a bad cell: the reader names it
        run.insert(0, item)
    if not run:
        return None
    header = run[-2] if len(run) >= 2 and _units_like(run[-1][2], delim) else run[-1]
    skip = [item for item in seen if item[0] < header[0] and item[2] is not None]
    if not skip:
        return None
    lines.pos, lines.number = header[1], header[0] - 1
    return {"count": len(skip), "first": skip[0][0], "last": skip[-1][0]}


class _Lines:
    """Walks the text line by line from ``pos`` (1-based line ``number`` of the last line read)."""

    def __init__(self, text: str) -> None:
        self.text, self.pos, self.number = text, 0, 0

    def next_content(self, skip_comments: bool) -> tuple[int, str | None]:
        while self.pos < len(self.text):
            end = self.text.find("\n", self.pos)
            end = len(self.text) if end < 0 else end
            line = self.text[self.pos:end].rstrip("\r")
            self.pos, self.number = end + 1, self.number + 1
            if line.strip() and not (skip_comments and line.lstrip().startswith("#")):
                return self.number, line
        return self.number + 1, None


def _parse_rows(text: str, pos: int, line_no: int, delim: str, names: list[str],
                name: str) -> tuple[np.ndarray, np.ndarray]:
    """All data rows (n_rows, n_cols) float64 and the file line of each row (1-based)."""
    parts: list[tuple[np.ndarray, np.ndarray]] = []
    while pos < len(text):
        end = text.find("\n", min(pos + _CHUNK_BYTES, len(text)))
        end = len(text) if end < 0 else end + 1
        chunk = text[pos:end]
        _parse_piece(chunk, line_no + 1, delim, names, name, parts)
        pos, line_no = end, line_no + chunk.count("\n") + (not chunk.endswith("\n"))
    if not parts:
        return np.empty((0, len(names))), np.empty(0, np.int64)
    return np.concatenate([a for a, _ in parts]), np.concatenate([r for _, r in parts])


def _parse_piece(chunk: str, first: int, delim: str, names: list[str], name: str,
                 parts: list[tuple[np.ndarray, np.ndarray]]) -> None:
    """numpy's reader on a piece of whole lines; where it refuses, halves down to 64 kB, then
    line by line (which names the line)."""
    if not chunk.strip():
        return
    if "#" not in chunk and '"' not in chunk:
        try:
            arr = np.loadtxt(io.StringIO(chunk), delimiter=delim, dtype=np.float64, ndmin=2,
                             comments=None)
        except Exception:  # any refusal: read again below, in smaller pieces
            arr = None
        if arr is not None and arr.shape[1] == len(names):
            lines = chunk.split("\n")
            rows = first + np.flatnonzero([bool(s.strip()) for s in lines])
            if rows.size == arr.shape[0]:
                parts.append((arr, rows))
                return
    mid = chunk.find("\n", len(chunk) // 2)
    if len(chunk) > _SLOW_BYTES and 0 <= mid < len(chunk) - 1:
        _parse_piece(chunk[:mid + 1], first, delim, names, name, parts)
        _parse_piece(chunk[mid + 1:], first + chunk.count("\n", 0, mid + 1), delim, names, name,
                     parts)
    else:
        parts.append(_parse_slow(chunk, first, delim, names, name))


def _parse_slow(chunk: str, first: int, delim: str, names: list[str],
                name: str) -> tuple[np.ndarray, np.ndarray]:
    """Line by line: empty cells are NaN, anything else not a number is named."""
    ncols = len(names)
    values: list[list[float]] = []
    rows: list[int] = []
    for k, line in enumerate(chunk.split("\n")):
        line = line.rstrip("\r")
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        cells = next(csv.reader([line], delimiter=delim)) if '"' in line else line.split(delim)
        if len(cells) != ncols:
            raise ImportFormatError(f"{name}: line {first + k}: {len(cells)} fields, expected "
                                    f"{ncols} (a truncated or damaged line?)")
        row = []
        for j, cell in enumerate(cells):
            c = cell.strip().strip('"').strip()
            if not c:
                row.append(math.nan)
            elif _NUMBER.match(c):
                row.append(float(c))
            else:
                hint = (" (a decimal comma? they are read with a ';' or tab delimiter, not "
                        "with ',')" if _COMMA_NUMBER.match(c) else "")
                raise ImportFormatError(f"{name}: line {first + k}, column {names[j]!r}: "
                                        f"{c[:24]!r} is not a number{hint}")
        values.append(row)
        rows.append(first + k)
    return np.array(values, dtype=np.float64).reshape(-1, ncols), np.array(rows, np.int64)


def sample_grid(t: np.ndarray, fs_hz: float | None, where: Callable[[int], str],
                name: str, rate_hint: float | None = None,
                resolution_s: float | np.ndarray = 0.0
                ) -> tuple[np.ndarray, float, dict]:
    """Place rows with times ``t`` (s) on one sample grid; refuse a non-uniform clock.

    Parameters
    ----------
    t : numpy.ndarray
        Time of each row, s.
    fs_hz : float, optional
        The rate, Hz; by default fitted to ``t`` and snapped to the value with the fewest
        digits that keeps every row within 0.05 sample (see :func:`snap_rate`).
    where : callable
        ``where(row)`` -> where that row is in the file (``"line 12"``), for messages.
    name : str
        The file, for messages.
    rate_hint : float, optional
        A rate, Hz, taken instead of the snapped one when it keeps every row as close to its
        grid point (a short file's times allow many rates; the rig's is the one meant).
    resolution_s : float or numpy.ndarray
        The step the times were printed to, s (:func:`printed_resolution`; one per row where it
        grows with the time, :func:`significant_step`): a time rounded to
        it lies up to half of it off its sample, so where a row is off its grid point by more
        than 0.1 sample, rows may lie that much further (0.1 ms at 2048 Hz: 0.10 sample more).
        Refused when that leaves no room to tell neighbouring samples apart.

    Returns
    -------
    index : numpy.ndarray
        int64 sample index of each row, 0 for the first; a step above 1 is a gap.
    fs_hz : float
        The rate, Hz.
    notes : dict
        ``{"time_gaps": n}``, and ``"time_resolution_s"`` when the rounding of the times
        widened the grid tolerance.
    """
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # odd times: refused
        bad = ~np.isfinite(t)
        if bad.any():
            r = int(np.argmax(bad))
            raise ImportFormatError(f"{name}: {where(r)}: the time is missing or not "
                                    f"finite")
        dt = np.diff(t)
        if dt.size and np.any(dt <= 0):
            r = int(np.argmax(dt <= 0)) + 1
            raise ImportFormatError(f"{name}: {where(r)}: time {float(t[r])!r} s does not come "
                                    f"after the previous row's {float(t[r - 1])!r} s")
        rel = t - t[0]
        if fs_hz is None:
            fs = _fitted_rate(rel, dt, name, rate_hint, float(np.max(resolution_s)))
        else:
            fs = float(fs_hz)
            if not fs > 0:
                raise ValueError(f"fs_hz ({fs_hz}) must be positive")
            if dt.size and abs(fs * _mean_step(dt) - 1) > 0.01:  # printed steps: ~1e-3
                raise ImportFormatError(f"{name}: the time column's sample rate is "
                                        f"{1 / _mean_step(dt):.6g} Hz, not the {fs:g} Hz "
                                        f"stated ({option('fs_hz=', '--fs')})")
        pos = rel * fs
        if pos[-1] > 2**40:
            raise ImportFormatError(f"{name}: the time column spans {pos[-1]:.3g} samples")
        n = np.rint(pos)
        grid_tol = _GRID_TOL
        off = np.abs(pos - n) > grid_tol
        res_fs = np.asarray(resolution_s) * fs      # one for the column, or one per row
        if off.any() and np.max(res_fs) > 0.01:  # rows off by their printed rounding?
            grid_tol = _GRID_TOL + 0.5 * res_fs
            coarse = np.atleast_1d(grid_tol >= 0.4)
            if coarse.any():
                r = int(np.argmax(coarse))
                res = float(np.atleast_1d(resolution_s)[r])
                at = f" from {where(r)} on" if np.ndim(resolution_s) else ""
                raise ImportFormatError(f"{name}: the times are printed to {res:g} s{at}, "
                                        f"{res * fs:.2f} samples at {fs:g} Hz: too "
                                        f"coarse to place each row on its sample")
            off = np.abs(pos - n) > grid_tol
        if off.any():
            r = int(np.argmax(off))
            raise ImportFormatError(f"{name}: {where(r)}: time {float(t[r])!r} s is "
                                    f"{pos[r] - n[r]:+.2f} samples off the {fs:g} Hz grid from "
                                    f"{float(t[0])!r} s (a non-uniform time column)")
        index = n.astype(np.int64)
        dn = np.diff(index)
        if dn.size and np.any(dn < 1):
            r = int(np.argmax(dn < 1)) + 1
            raise ImportFormatError(f"{name}: {where(r)}: time {float(t[r])!r} s falls on the "
                                    f"same sample as the previous row at {fs:g} Hz")
        notes = {"time_gaps": int(np.count_nonzero(dn > 1))}
        if np.any(grid_tol > _GRID_TOL):  # rounding that widened the tolerance: said
            notes["time_resolution_s"] = float(np.max(resolution_s))
        return index, fs, notes


def _fitted_rate(rel: np.ndarray, dt: np.ndarray, name: str, rate_hint: float | None,
                 resolution_s: float) -> float:
    """The rate, Hz, fitted to the times ``rel`` (s from the first row; steps ``dt``) and
    snapped (see :func:`sample_grid`)."""
    if rel.size < 2:
        raise ImportFormatError(f"{name}: one data row gives no sample rate; give "
                                f"{option('fs_hz=', '--fs')}")
    fs_fit = 1.0 / _mean_step(dt)
    if rel[-1] * fs_fit > 2**40:
        raise ImportFormatError(f"{name}: the time column spans {rel[-1] * fs_fit:.3g} samples")
    # printed times round each step (6 decimals at 2048 Hz: 0.000488 or 0.000489 s), so
    # the mean step is off by up to a rounding over its run: good for a stretch, not for a
    # whole trial with gaps. Fit on a stretch short enough to count its samples right, then on one 8x
    # longer with that rate, until the whole column is counted.
    k = 256
    while True:
        m = min(k, rel.size)
        n = np.rint(rel[:m] * fs_fit)
        if np.dot(rel[:m], rel[:m]) > 0:
            fs_fit = float(np.dot(n, rel[:m]) / np.dot(rel[:m], rel[:m]))
        if m == rel.size:
            break
        k *= 8
    if not 1e-3 <= fs_fit <= 1e9:
        raise ImportFormatError(f"{name}: the time column gives a sample rate of "
                                f"{fs_fit:g} Hz")
    tol = 0.5 * (_GRID_TOL + 0.5 * resolution_s * fs_fit) / max(float(rel[-1] * fs_fit),
                                                                  1.0)
    return rate_hint if rate_hint and abs(rate_hint / fs_fit - 1) <= tol else \
        snap_rate(fs_fit, tol)


def _mean_step(dt: np.ndarray) -> float:
    """The sampling step, s, from the steps ``dt`` (s) between rows: the mean over the steps
    below 1.5 median (a gap's step left out). Times rounded as printed round each step, but the
    mean over a run of steps is its span over its count, exact up to one rounding: the median
    step (0.0005 s for 2048 Hz printed to 0.1 ms) is not."""
    small = dt[dt < 1.5 * float(np.median(dt))]
    return float(np.mean(small)) if small.size else float(np.median(dt))
