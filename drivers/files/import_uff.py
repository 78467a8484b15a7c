"""Import time records of a Universal File (UFF dataset 58, ASCII or 58b binary) as a device.

::

    with open_device("trial.uff", rig=rig) as dev:     # or .unv; UffImportDevice(...)
        for block in dev:
            ...

Each type 58 record is one channel's time response (function type 1, or 0 "general" with a
time abscissa), real, evenly spaced (an uneven abscissa is accepted when its points are on one
grid). A record's channel is its response node, which is the gage number unless ``channels=``
maps it (``{"101": 1}``); a node measured in several directions is named ``"node:dir"``
(``"5:+2"``) and must be mapped. The unit is the ordinate's axis-units label (m/s^2 or g; a
missing label is taken as m/s^2 when the ordinate is an acceleration, spec data type 12). A
record of an excitation force (spec data type 13; N, kN or lbf) is the channel
``"force NODE:DIR"`` (``"force 1:+2"``), imported as the rig's force channel with
``force_channel=``.

Records sharing a start time (``abscissa_min``) form one segment, which must hold every channel
once with equal lengths; segments at different start times are streamed in time order with gaps
between them (ramdaq's own ``export_uff`` decay records come back this way). The increment and
start are printed with six significant digits (``E13.5``), so the rate is ``1/abscissa_inc``
snapped to the fewest digits within that precision (``4.88281E-04`` gives 2048 Hz) and a start
to the nearest sample. ASCII ordinates carry 13 digits (``E20.12``): values that came from an
ADC still give their exact counts.

The file is read with pyuff; anything pyuff cannot read, a record whose point count disagrees
with its data (a truncated file), and a file without type 58 records are refused in one line.

The medium is read where the file states it (:func:`~ramdaq.drivers.files.import_common.stated_medium`):
``medium: water`` (or ``= air``) in a 151 or 164 header's text or a 58 record's ID line, or
ramdaq's own export's ID line 2, ``ramdaq rig NAME in water``.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .import_common import FileImportDevice, ImportFormatError, SourceTable, snap_rate, stated_medium

__all__ = ["UffImportDevice", "read_uff_table"]

_INC_PRECISION = 6e-6  # relative: E13.5 keeps six significant digits
_FUNC_TYPES = {0: "general", 1: "time response", 2: "auto spectrum", 3: "cross spectrum",
               4: "frequency response function", 5: "transmissibility", 6: "coherence",
               9: "power spectral density"}
_FORCE_TYPE = 13  # ordinate spec data type "excitation force"
_SPEC_TYPES = {8: "displacement", 11: "velocity", 13: "excitation force", 15: "pressure",
               2: "stress", 3: "strain", 5: "temperature"}


class UffImportDevice(FileImportDevice):
    """A UFF file's type 58 time records streamed as blocks (back-end name ``"uff"``).

    Parameters
    ----------
    path : str or PathLike
        The ``.uff`` / ``.unv`` file.
    rig : Rig or path
        The rig of the trial.
    channels : mapping of str to int, optional
        Response node (``"101"``, or ``"101:+2"``) -> gage number; only these are imported.
    medium : str, optional
        Override the rig's medium.
    block_s : float
        Longest block, s.
    """

    kind = "uff"

    def _load(self) -> SourceTable:
        return read_uff_table(self.path)


class _Record:
    __slots__ = ("number", "node", "direction", "unit", "start", "inc", "data", "force", "label")

    def __init__(self, number: int, node: int, direction: int, unit: str | None, start: float,
                 inc: float, data: np.ndarray, force: bool = False, label: str = "") -> None:
        self.number, self.node, self.direction, self.unit = number, node, direction, unit
        self.start, self.inc, self.data, self.force = start, inc, data, force
        self.label = label  # ID line 1 ("Accel 1", "Hammer"): another name of the channel


def read_uff_table(path: Path) -> SourceTable:
    """Read the type 58 records of a UFF file into a :class:`SourceTable`."""
    import pyuff

    try:
        uff = pyuff.UFF(str(path))
        types = [int(t) for t in uff.get_set_types()]
    except Exception as err:  # pyuff on a damaged file: any exception, one line
        raise ImportFormatError(f"{path}: not a readable UFF file ({type(err).__name__}: "
                                f"{err})") from err
    if not types:
        raise ImportFormatError(f"{path}: not a UFF file (no records between '    -1' lines)")
    with open(path, "rb") as f:
        f.seek(max(0, path.stat().st_size - 82))
        tail = f.read().rstrip(b" \r\n")
    if not tail.endswith(b"    -1"):
        raise ImportFormatError(f"{path}: truncated: the last record lacks its closing -1 line")
    wanted = [i for i, t in enumerate(types) if t == 58]
    texts: list[tuple[str, str]] = []
    if not wanted:
        raise ImportFormatError(f"{path}: no type 58 (function at nodal DOF) records; the file "
                                f"holds types {', '.join(str(t) for t in sorted(set(types)))}")
    records = []
    for i in wanted:
        try:
            d = uff.read_sets(i)
        except Exception as err:
            raise ImportFormatError(f"{path}: record {i + 1} (type 58) is unreadable "
                                    f"({type(err).__name__}: {err})") from err
        records.append(_check_record(d, i + 1, path))
        texts += [(f"UFF record {i + 1} (type 58) ID line {k[-1]}", str(d.get(k, ""))) for k in _ID_LINES]
    texts += [(f"UFF record {i + 1} (type {types[i]}) {k}", str(v)) for i in range(len(types))
              if types[i] in (151, 164) for k, v in _read_header(uff, i).items()]
    table = _table(records, path, len(types))
    table.notes |= stated_medium(_media(texts), str(path))
    return table


_ID_LINES = ("id1", "id2", "id3", "id4", "id5")
_STATED = re.compile(r"\bmedium\s*[:=]\s*([A-Za-z]+)", re.IGNORECASE)
_OWN_ID2 = re.compile(r"^ramdaq rig .* in (air|water)$")  # ramdaq export_uff's ID line 2


def _read_header(uff, i: int) -> dict:
    """The text fields of header record ``i`` (151: model, description, program...; 164: the
    units' description); {} when pyuff cannot read it (a header is not what is imported)."""
    try:
        d = uff.read_sets(i)
    except Exception:  # noqa: BLE001 - only its medium is looked for
        return {}
    return {k: v for k, v in d.items() if isinstance(v, str) and k != "type"}


def _media(texts: list[tuple[str, str]]) -> list[tuple[str, str]]:
    """Each ``(where, medium)`` a UFF file's header texts state: ``medium: water`` (or
    ``medium = air``) in any of them, or ramdaq's own ``ramdaq rig NAME in water`` ID line 2."""
    out = [(w, m[1]) for w, t in texts for m in _STATED.finditer(t)]
    out += [(w, m[1]) for w, t in texts if w.endswith(" ID line 2") and (m := _OWN_ID2.match(t.strip()))]
    return out


def _check_record(d: dict, number: int, path: Path) -> _Record:
    where = f"{path}: record {number} (type 58)"
    try:
        func = int(d["func_type"])
        ord_type = int(d["ord_data_type"])
        n = int(d["num_pts"])
        even = int(d["abscissa_spacing"])
        node, direction = int(d["rsp_node"]), int(d["rsp_dir"])
        x_type = int(d.get("abscissa_spec_data_type", 0))
        y_type = int(d.get("ordinate_spec_data_type", 0))
        label = str(d.get("ordinate_axis_units_lab", "")).strip()
        id1 = str(d.get("id1", "")).strip()
        data = np.asarray(d["data"])
    except (KeyError, TypeError, ValueError, OverflowError) as err:
        raise ImportFormatError(f"{where}: incomplete header ({type(err).__name__}: {err})") \
            from None
    if func not in (0, 1):
        raise ImportFormatError(f"{where}: function type {func} "
                                f"({_FUNC_TYPES.get(func, 'not a time response')}) is not a time "
                                f"response")
    if x_type not in (0, 1, 17):
        raise ImportFormatError(f"{where}: the abscissa is not time (spec data type {x_type})")
    if ord_type not in (2, 4) or np.iscomplexobj(data):
        raise ImportFormatError(f"{where}: complex ordinates (data type {ord_type}); a time "
                                f"record is real")
    if y_type in _SPEC_TYPES and y_type != _FORCE_TYPE:
        raise ImportFormatError(f"{where}: node {node} records {_SPEC_TYPES[y_type]}, not "
                                f"acceleration")
    if data.ndim != 1 or data.size != n or n == 0:
        raise ImportFormatError(f"{where}: header says {n} points but {data.size} follow (a "
                                f"truncated file?)")
    if even:
        start, inc = float(d["abscissa_min"]), float(d["abscissa_inc"])
    else:
        x = np.asarray(d["x"], dtype=np.float64)
        if x.size != n or n < 2:
            raise ImportFormatError(f"{where}: uneven abscissa with {x.size} points for {n} values")
        start, inc = float(x[0]), float((x[-1] - x[0]) / (n - 1))
        if not inc > 0 or np.max(np.abs((x - start) / inc - np.arange(n))) > 0.1:
            raise ImportFormatError(f"{where}: the uneven abscissa is not on one sample grid")
    if not (abs(start) < 4e9 and 1e-9 <= inc <= 1e3):
        raise ImportFormatError(f"{where}: abscissa start {start} s, increment {inc} s unusable")
    unit = None if label.upper() in ("", "NONE") else label
    return _Record(number, node, direction, unit, start, inc,
                   np.asarray(data, dtype=np.float64), force=y_type == _FORCE_TYPE,
                   label="" if id1.upper() in ("", "NONE") else id1)


def _channel_name(r: _Record, dirs: dict[int, set[int]]) -> str:
    """``"5"``, ``"5:+2"`` where node 5 has records in several directions, ``"force 5:+2"``
    for a force record (not a gage name: mapped by ``force_channel=``). A record's ID line 1
    (``"Accel 1"``, ``"Hammer"``), where unique, names it too (:attr:`SourceTable.aliases`)."""
    if r.force:
        return f"force {r.node}:{r.direction:+d}"
    return str(r.node) if len(dirs[r.node]) == 1 else f"{r.node}:{r.direction:+d}"


def _table(records: list[_Record], path: Path, n_sets: int) -> SourceTable:
    inc0 = records[0].inc
    for r in records:
        if abs(r.inc / inc0 - 1) > 2 * _INC_PRECISION:
            raise ImportFormatError(f"{path}: record {r.number} has abscissa increment {r.inc} s, "
                                    f"record {records[0].number} {inc0} s")
    fs = snap_rate(1.0 / float(np.mean([r.inc for r in records])), _INC_PRECISION)
    dirs: dict[int, set[int]] = {}
    for r in records:
        dirs.setdefault(r.node, set()).add(r.direction)

    def name(r: _Record) -> str:
        return _channel_name(r, dirs)

    t0 = min(r.start for r in records)
    segments: dict[int, dict[str, _Record]] = {}
    for r in records:
        k = round((r.start - t0) * fs)
        seg = segments.setdefault(k, {})
        if name(r) in seg:
            raise ImportFormatError(f"{path}: records {seg[name(r)].number} and {r.number} are "
                                    f"both node {name(r)} starting at {r.start:g} s")
        seg[name(r)] = r
    starts = sorted(segments)
    first = segments[starts[0]]
    names = list(first)
    for k in starts:
        seg = segments[k]
        if set(seg) != set(names):
            odd = sorted(set(seg) ^ set(names))[0]
            raise ImportFormatError(f"{path}: the records starting at {k / fs + t0:g} s and at "
                                    f"{starts[0] / fs + t0:g} s differ in node {odd}")
        lengths = {r.data.size for r in seg.values()}
        if len(lengths) > 1:
            r = max(seg.values(), key=lambda r: r.data.size)
            raise ImportFormatError(f"{path}: records starting at {k / fs + t0:g} s differ in "
                                    f"length ({sorted(lengths)} points; record {r.number})")
    index_parts, prev_end = [], -1
    for k in starts:
        n = next(iter(segments[k].values())).data.size
        if k <= prev_end:
            raise ImportFormatError(f"{path}: the records starting at {k / fs + t0:g} s overlap "
                                    f"the ones before")
        index_parts.append(k + np.arange(n, dtype=np.int64))
        prev_end = k + n - 1
    units = [first[nm].unit for nm in names]
    for k in starts:
        for nm in names:
            if segments[k][nm].unit != first[nm].unit:
                raise ImportFormatError(f"{path}: node {nm} is in {segments[k][nm].unit!r} in "
                                        f"record {segments[k][nm].number}, "
                                        f"{first[nm].unit!r} in record {first[nm].number}")

    def read(i: int) -> np.ndarray:
        return np.concatenate([segments[k][names[i]].data for k in starts])

    labels = [first[nm].label for nm in names]
    aliases = {lb: nm for lb, nm in zip(labels, names, strict=True)
               if lb and labels.count(lb) == 1 and lb not in names}
    return SourceTable(names=names, units=units, sample_index=np.concatenate(index_parts),
                       fs_hz=fs, t0_s=t0, read=read, fmt="uff58", aliases=aliases,
                       notes={"records": len(records), "uff_sets": n_sets,
                              "record_segments": len(starts)})
