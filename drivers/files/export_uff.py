"""Export a trial's identified modes and decay records as a Universal File for modal software.

::

    rig, hits = run_analysis("trial.mcap")
    export_uff("trial.uff", hits, rig, source="trial.mcap")

The file holds, in this order (all SI: m, s, m/s^2):

* **UFF 164** units: SI (metre, newton, kelvin).
* **UFF 15** nodes: one per gage of the rig, node number = gage number, coordinates = the gage's
  ``position_m`` in ship axes (x aft, y athwartship, z up, from the control surface's centre of
  mass; a stern plane's rig is turned back from its surface frame).
* **UFF 55** per accepted hit and identified mode: a complex mode shape (analysis type 3,
  complex eigenvalue first order; data characteristic 2, three translations per node; specific
  data type 8, displacement). The eigenvalue is ``lambda = -delta*f + j*2*pi*f`` (1/s, f the
  damped frequency in Hz, delta the logarithmic decrement), so ``f = Im(lambda)/(2 pi)`` and
  ``delta = -Re(lambda)/f``. Each gage's complex shape entry (normalised to 1 at the
  largest) sits on its sensing axis, the other two are zero; gages left out of the fit are left
  out of the record. Load case = hit index + 1, mode number = mode index + 1; ID line 1 gives f,
  delta and zeta in full, and marks the predominant mode (and the one ``mode_hz`` asked for).
* **UFF 58** per accepted hit and gage: the free-decay record the analysis used (function type 1,
  time response; ordinate acceleration in m/s^2, spec data type 12; response node = gage,
  direction = its sensing axis; even abscissa from the decay start, increment 1/fs). Load case =
  hit index + 1; ID line 4 holds the exact first sample and rate.

A channels-only rig (``ramdaq import`` without a rig) has no gage positions or sensing axes:
its file holds UFF 164 and the 58 decay records with direction 0 (scalar), and
:attr:`UffExport.left_out` says that the 15 nodes and 55 mode shapes were left out and why
(pyuff's 55 writer writes three values a node, so a scalar 55 is not an option).

Written ASCII (``binary=True``: 58b for the records) through pyuff, to a temporary file moved
into place when complete. UFF prints headers with 6 significant digits (E13.5) and double
ordinates with 13 (E20.12).
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np

from ...analysis.impact import ImpactAnalysis
from ...analysis.model.rig import Rig

__all__ = ["export_uff", "UffExport", "AXIS_CODES"]

AXIS_CODES = {"x": 1, "y": 2, "z": 3, "-x": -1, "-y": -2, "-z": -3}
"""UFF direction code of each rig sensing axis."""


@dataclass(frozen=True)
class UffExport:
    """What :func:`export_uff` wrote: its path, and how many hits, nodes, modes and records;
    ``left_out`` says what was not written and why (empty when nothing was left out)."""

    path: Path
    hits: int
    nodes: int
    modes: int
    records: int
    left_out: str = ""


def export_uff(path: str | PathLike, analysis_hits: Sequence, rig: Rig, *, source: str = "",
               binary: bool = False) -> UffExport:
    """Write the rig's gages, each accepted hit's modes and its decay records to a UFF file.

    Parameters
    ----------
    path : str or PathLike
        The ``.uff`` file to write (replaced if it exists).
    analysis_hits : sequence of ramdaq.daq.analyzer.HitResult
        From :func:`ramdaq.daq.commands.analyze.run_analysis`; only accepted hits with an analysis are
        written.
    rig : Rig
        Gage numbers, positions and sensing axes.
    source : str
        The recording's name, for ID line 5.
    binary : bool
        Write the 58 records as binary 58b (exact doubles, smaller, less widely read).

    Returns
    -------
    UffExport
    """
    import pyuff

    path = Path(path)
    stamp = time.strftime("%d-%b-%y %H:%M:%S").upper()
    id2 = f"ramdaq rig {rig.name} in {rig.medium}"[:80]
    id5 = (source or "ramdaq")[-80:]
    sets: list[dict] = [
        {"type": 164, "units_code": 1, "units_description": "SI", "temp_mode": 2,
         "length": 1.0, "force": 1.0, "temp": 1.0, "temp_offset": 273.15}]
    if rig.structural:
        sets.append(_node_set(rig))
    hits = modes = records = unwritten = 0
    for h in analysis_hits:
        if not h.accepted or h.analysis is None:
            continue
        hits += 1
        ids = {"id2": id2, "id3": stamp, "id5": id5}
        mode_sets = _mode_sets(h.index, h.analysis, rig, ids) if rig.structural else []
        unwritten += 0 if rig.structural else len(h.analysis.modes)
        record_sets = _decay_sets(h, rig, ids, binary)
        modes += len(mode_sets)
        records += len(record_sets)
        sets += mode_sets + record_sets
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    if tmp.exists():
        tmp.unlink()
    try:
        pyuff.UFF(str(tmp)).write_sets(sets, mode="add")  # "overwrite" misplaces a first 58b
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    left = "" if rig.structural else (
        f"UFF 15 (gage nodes) and 55 ({unwritten} mode shape{'' if unwritten == 1 else 's'}) left "
        f"out: rig {rig.name!r} describes only its channels, no gage positions or sensing axes; "
        f"the 58 decay records have direction 0")
    return UffExport(path, hits, len(rig.gages) if rig.structural else 0, modes, records, left)


def _node_set(rig: Rig) -> dict:
    """UFF 15: a node per gage at its position in ship axes, m."""
    return {"type": 15, "node_nums": [g.number for g in rig.gages],
         "def_cs": [0] * len(rig.gages), "disp_cs": [0] * len(rig.gages),
         "color": [0] * len(rig.gages),
         "x": [rig.surface.to_ship(g.position_m)[0] for g in rig.gages],
         "y": [rig.surface.to_ship(g.position_m)[1] for g in rig.gages],
         "z": [rig.surface.to_ship(g.position_m)[2] for g in rig.gages]}


def _mode_sets(index: int, a: ImpactAnalysis, rig: Rig, ids: dict) -> list[dict]:
    m = a.modes
    shapes = m.mode_shape
    gages = a.active_gages
    out = []
    for k in range(len(m)):
        f, delta, zeta = float(m.frequency_hz[k]), float(m.delta[k]), float(m.zeta[k])
        nodes, r = [], np.zeros((3, 0), complex)
        for n, s in zip(gages, shapes[:, k], strict=True):
            if not np.isfinite(s):
                continue
            code = AXIS_CODES[rig.surface.ship_axis(rig.gage(n).axis)]
            v = np.zeros((3, 1), complex)
            v[abs(code) - 1, 0] = s if code > 0 else -s
            nodes.append(n)
            r = np.hstack([r, v])
        if not nodes:
            continue
        mark = a.mode_tag(k).replace(" (", ", ").rstrip(")")
        out.append({
            "type": 55, "id1": f"mode {k + 1} of hit {index}: f {f:.6f} Hz, delta {delta:.6f}, "
                               f"zeta {zeta:.6f}{mark}"[:80],
            "id4": f"onset {a.onset_s:.6f} s, decay from {a.decay_start_s:.6f} s, "
                   f"{a.duration_s:.3f} s long"[:80],
            **ids, "model_type": 1, "analysis_type": 3, "data_ch": 2, "spec_data_type": 8,
            "load_case": index + 1, "mode_n": k + 1,
            "eig": complex(-delta * f, 2 * np.pi * f), "modal_a": 0j, "modal_b": 0j,
            "node_nums": nodes, "r1": r[0], "r2": r[1], "r3": r[2]})
    return out


def _decay_sets(h, rig: Rig, ids: dict, binary: bool) -> list[dict]:
    ev, a = h.event, h.analysis
    rec = ev.record
    if rec is None:
        return []
    fs = float(rec.fs_hz)
    first = round(a.decay_start_s * fs)
    i0 = first - rec.first_sample
    values = rec.values()[:, i0:]
    if values.shape[1] < 2:
        return []
    t = (first + np.arange(values.shape[1])) / fs
    out = []
    for row, n in enumerate(ev.gages):
        if not n:
            continue
        out.append({
            "type": 58, "binary": int(binary), "id1": f"g{n:02d} decay, hit {h.index}",
            "id4": f"first_sample {first} fs_hz {fs!r}"[:80], **ids,
            "func_type": 1, "func_id": len(out) + 1, "ver_num": 0, "load_case_id": h.index + 1,
            "rsp_ent_name": f"g{n:02d}", "rsp_node": n,
            "rsp_dir": AXIS_CODES[rig.surface.ship_axis(rig.gage(n).axis)] if rig.structural else 0,
            "ref_ent_name": "NONE", "ref_node": 0,
            "ref_dir": 0, "abscissa_spacing": 1, "x": t, "data": np.ascontiguousarray(values[row]),
            "abscissa_spec_data_type": 17, "abscissa_axis_lab": "time",
            "abscissa_axis_units_lab": "s", "ordinate_spec_data_type": 12,
            "ordinate_axis_lab": "acceleration", "ordinate_axis_units_lab": "m/s^2",
            "orddenom_spec_data_type": 0, "z_axis_spec_data_type": 0})
    return out
