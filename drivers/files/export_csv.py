"""Export a recording's samples as CSV for another system, the form ``ramdaq import`` reads back.

::

    r = export_csv("trial.mcap", "trial.csv")                # m/s^2, every sample
    r = export_csv("trial.mcap", "trial.csv", units="g")     # gages in g (force stays in N)

The file:

* ``#`` comment lines first: the source, the rig's name, the rate, the samples written and the
  gaps, ``# medium: water`` (the recording's medium, which ``ramdaq import`` applies), ``# scale
  [SI unit per count]: g01=0.000116..., ...`` (each channel's scale as ``repr`` of the float,
  so the importer makes the recorded counts and scale again, exactly), the force channel if
  any; then each event the recording holds (device faults,
  interruptions) at its stream time (s from sample 0, the time column's clock), so nothing the
  recording says about its samples is lost on the way out;
* a header ``time [s],g01 [m/s^2],...,force [N]``: time first, one column per channel under its
  recorded name with its unit in brackets;
* one row per recorded sample: time ``sample / fs`` to 1e-7 s (a tenth of a sample up to
  1 MHz), values to 9 significant digits (a 24-bit converter's counts scaled to SI keep every
  count). A gap in the recording is a step of whole samples in the time column, as the
  importer reads a gap: no row is invented for the missing samples.

Written block by block (memory flat in the recording's length; the rows go to a side file
first, since the comment lines above them count the gaps) to a temporary file moved into place
when complete.
"""

from __future__ import annotations

import json
import os
import shutil
import tomllib
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np

from ..block import sample_time_ns
from ..mcap_replay import McapReplayDevice

__all__ = ["export_csv", "CsvExport", "G_M_S2"]

G_M_S2 = 9.80665
"""Standard gravity, m/s^2: a gage column in g is its m/s^2 over this."""


@dataclass(frozen=True)
class CsvExport:
    """What :func:`export_csv` wrote: its ``path``, ``rows`` (samples), ``channels``, the
    ``gaps`` (steps in the sample index) and ``missing`` samples they span, and ``events``
    copied into the comment lines."""

    path: Path
    rows: int
    channels: int
    gaps: int
    missing: int
    events: int


def _header(info, units: str) -> list[str]:
    names = []
    for name, unit in zip(info.channels, info.units, strict=True):
        names.append(f"{name} [{'g' if units == 'g' and unit == 'm/s^2' else unit}]")
    return ["time [s]", *names]


def _divisors(info, units: str) -> np.ndarray:
    return np.array([G_M_S2 if units == "g" and u == "m/s^2" else 1.0 for u in info.units])


def export_csv(src: str | PathLike, out: str | PathLike, *, units: str = "m/s^2") -> CsvExport:
    """Write every recorded sample of the MCAP recording ``src`` to the CSV file ``out``.

    ``units``: ``"m/s^2"`` (SI, the default) or ``"g"`` for the acceleration channels; a force
    channel stays in its recorded unit (N). Raises the reader's one-line error on a damaged or
    foreign file, and ``ValueError`` for another unit."""
    if units not in ("m/s^2", "g"):
        raise ValueError(f"export_csv: units {units!r}: 'm/s^2' or 'g'")
    out = Path(out)
    body, tmp = out.with_name(out.name + ".rows"), out.with_name(out.name + ".part")
    rows = gaps = missing = 0
    try:
        with McapReplayDevice(src) as dev, open(body, "w", encoding="utf-8", newline="\n") as f:
            info, events = dev.info, dev.events()
            rig, anti_alias = _rig_name(info, dev.rig_toml), _anti_alias(dev.rig_toml)
            div = _divisors(info, units)
            last = t_zero = scales = None
            for block in dev:
                if t_zero is None:  # the device clock's reading at sample 0, ns
                    t_zero = block.t0_ns - sample_time_ns(block.first_sample, block.fs_hz)
                if last is not None and block.first_sample != last:
                    gaps += 1
                    missing += block.first_sample - last
                last = block.next_sample
                scales = _same_scale(scales, block.scale)
                t = np.arange(block.first_sample, block.next_sample) / block.fs_hz
                table = np.column_stack([t, (block.values() / div[:, None]).T])
                np.savetxt(f, table, fmt=["%.7f"] + ["%.9g"] * info.n_channels, delimiter=",")
                rows += block.n_samples
        # the comment lines name the gaps, so they are written once the rows are known
        with open(tmp, "w", encoding="utf-8", newline="\n") as f, open(body, encoding="utf-8") as b:
            f.write(f"# ramdaq export of {Path(src).name}: rig {rig}, {info.fs_hz:g} Hz, "
                    f"device {info.device}\n")
            f.write(f"# {rows} samples of {info.n_channels} channels; {gaps} gap(s), {missing} "
                    "sample(s) missing (steps in the time column)\n")
            force = [c for c, u in zip(info.channels, info.units, strict=True) if u != "m/s^2"]
            if force:
                f.write(f"# force channel(s): {', '.join(force)} (ramdaq import --force-channel)\n")
            f.write(f"# medium: {info.extra.get('medium') or '(none recorded)'}\n")
            if anti_alias is not None:  # a channels-only re-import removes its delay from onsets
                f.write(f"# anti-alias: order {anti_alias[0]}, {anti_alias[1]!r} Hz\n")
            if scales is not None and len(scales):
                f.write("# scale [SI unit per count]: " + ", ".join(
                    f"{c}={s!r}" for c, s in zip(info.channels, scales.tolist(), strict=True)
                    if s == s) + "\n")
            for e in events:
                at = (e["t_ns"] - (t_zero or 0)) / 1e9
                f.write(f"# event {e['kind']} at {at:.6f} s: "
                        f"{json.dumps(e.get('detail', {}), default=str)}\n")
            f.write(",".join(_header(info, units)) + "\n")
            shutil.copyfileobj(b, f, 1 << 20)
    finally:
        body.unlink(missing_ok=True)
    os.replace(tmp, out)
    return CsvExport(out, rows, info.n_channels, gaps, missing, len(events))


def _same_scale(seen: np.ndarray | None, scale: np.ndarray) -> np.ndarray:
    """Each channel's scale (SI per count) if every block so far had the same one, else NaN."""
    scale = np.asarray(scale, np.float64)
    if seen is None:
        return scale.copy()
    return np.where(seen == scale, seen, np.nan)


def _anti_alias(rig_toml: str) -> tuple[int, float] | None:
    """The recorded rig's anti-alias filter, ``(order, corner Hz)`` from its ``[daq]``; None
    when it names none or cannot be read (then the CSV states none)."""
    try:
        daq = tomllib.loads(rig_toml).get("daq", {})
        order, hz = int(daq["anti_alias_order"]), float(daq["anti_alias_hz"])
    except (tomllib.TOMLDecodeError, KeyError, TypeError, ValueError, AttributeError):
        return None
    return (order, hz) if order > 0 and 0 < hz < float("inf") else None


def _rig_name(info, rig_toml: str) -> str:
    """The rig's name as the device recorded it (``StreamInfo.extra["rig_name"]``), else the
    name its recorded TOML gives (top level or ``[rig]``)."""
    if info.extra.get("rig_name"):
        return str(info.extra["rig_name"])
    try:
        doc = tomllib.loads(rig_toml)
    except tomllib.TOMLDecodeError:
        return "(unreadable)"
    return str(doc.get("name") or doc.get("rig", {}).get("name") or "(none recorded)")
