"""The driving-point FRFs of a trial whose rig has a force channel: ``report.json``'s ``frf``
section and its plot (``frf.png``), from the accepted hits' records
(:func:`ramdaq.analysis.modal.frf.h1_estimate`).

Each blow is taken from :data:`PRE_S` before its onset (the force's rising edge) for the length
of the shortest record among them -- the trigger's record runs to the decay's end, at most to
the next blow -- and at most :data:`MAX_WINDOW_S`: the window is set by time, so the resolution
(1 / window) does not shrink with the sample rate (a fixed 8192 samples was 1.64 s at 5000 Hz:
0.61 Hz bins, a 12.50 Hz mode peaking at 12.21 Hz and |H1| 7 % high from the ringing cut off).
The section says how many samples and blows it used, in SI units: H1 in (m/s^2)/N, frequencies
in Hz, phase in rad; it holds every bin up to the last one where H1 is given (above it the
force is more than 20 dB down and every gage's H1 is NaN), so its size follows the force's band.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ...analysis.modal.frf import FrfEstimate, h1_estimate
from ...analysis.model.rig import Rig
from ..analyzer import HitResult, finite_json

if TYPE_CHECKING:  # matplotlib is imported when a figure is drawn, not with the report
    from matplotlib.figure import Figure

__all__ = ["MAX_WINDOW_S", "PRE_S", "frf_figure", "frf_section", "plot_frf"]

PRE_S = 0.002
"""Taken before each onset, s: the onset is the force's rise less the anti-alias delay."""
MAX_WINDOW_S = 10.0
"""Longest FRF window, s: 0.1 Hz bins, five across the half-power band (2 zeta f) of a 12.5 Hz
mode of zeta 0.02, by which time such a mode has decayed by e^-16."""


def _rows(rig: Rig, channels: Sequence[str] | None) -> tuple[int | None, list[int], list[int]]:
    """The recorded rows of the rig's first force channel (None when not recorded) and of its
    gages, with those gages' numbers. ``channels``: the recording's channel names, row by row
    (an import may hold fewer than the rig declares); None: the rig's own, in DAQ order."""
    if channels is None:
        return rig.forces[0].channel, [g.channel for g in rig.gages_by_channel()], \
            [g.number for g in rig.gages_by_channel()]
    name = rig.forces[0].name
    f_row = channels.index(name) if name in channels else None
    gages = [g.number for g in rig.gages_by_channel() if f"g{g.number:02d}" in channels]
    return f_row, [channels.index(f"g{g:02d}") for g in gages], gages


def _blows(rig: Rig, hits: list[HitResult], channels: Sequence[str] | None
           ) -> tuple[np.ndarray, np.ndarray, list[int], float, list[int]]:
    """(force (n_blows, n), acceleration (n_blows, n_gages, n), hit indices, fs, gage numbers)
    of the accepted hits that kept their records."""
    use = [h for h in hits if h.accepted and h.event.record is not None]
    if not use:
        return np.zeros((0, 0)), np.zeros((0, 0, 0)), [], 0.0, []
    f_row, g_rows, gages = _rows(rig, channels)
    fs = use[0].event.record.fs_hz
    cuts = []
    for h in use:
        rec = h.event.record
        a = max(0, h.event.onset_sample - round(PRE_S * fs) - rec.first_sample)
        cuts.append((rec, a))
    n = min(round(MAX_WINDOW_S * fs), *(rec.counts.shape[1] - a for rec, a in cuts))
    f = np.stack([rec.counts[f_row, a:a + n] * rec.scale[f_row] for rec, a in cuts])
    x = np.stack([rec.counts[g_rows, a:a + n] * rec.scale[g_rows, None] for rec, a in cuts])
    return f, x, [h.index for h in use], fs, gages


def frf_section(rig: Rig, hits: list[HitResult], channels: Sequence[str] | None = None
                ) -> dict | None:
    """``report.json``'s ``frf``: per gage the H1 (magnitude, phase) and coherence against the
    rig's first force channel over the accepted hits, with the frequency of its largest
    ``|H1|`` above 1 Hz; ``None`` for a rig without a force channel, ``{"not_computed": why}``
    where there is nothing to compute it from (no accepted hit, the force not recorded).
    ``channels``: the recording's channel names row by row (``StreamInfo.channels``); None
    when its rows are the rig's DAQ channels."""
    if not rig.forces:
        return None
    if _rows(rig, channels)[0] is None:
        return {"not_computed": f"the rig's force channel {rig.forces[0].name!r} is not in the "
                                f"recording (its channels: {', '.join(channels)})"}
    force, accel, used, fs, gages = _blows(rig, hits, channels)
    if not used:
        return {"not_computed": "no accepted hit with its record"}
    try:
        est = h1_estimate(force, accel, fs)
    except ValueError as err:
        return {"not_computed": str(err)}
    return _to_json(rig, est, used, force.shape[1], fs, gages)


def _to_json(rig: Rig, est: FrfEstimate, used: list[int], n: int, fs: float,
             gages: list[int]) -> dict:
    names = [f"g{g:02d}" for g in gages]
    peaks = est.peak_hz(1.0)
    given = np.flatnonzero(np.any(np.isfinite(est.h1), axis=0))
    m = int(given[-1]) + 1 if given.size else est.f_hz.size  # bins above: NaN for every gage
    return {
        "force_channel": rig.forces[0].name, "units": {"h1": "(m/s^2)/N", "f_hz": "Hz",
                                                       "phase": "rad", "coherence": "1"},
        "estimator": "H1", "hits": used, "n_blows": est.n_blows, "samples": n,
        "window_s": n / fs, "pre_s": PRE_S, "exp_tau_s": est.exp_tau_s,
        "notes": list(est.notes), "f_hz": est.f_hz[:m].tolist(), "bins_total": int(est.f_hz.size),
        "gages": {g: {"peak_hz": float(peaks[i]),
                      "magnitude": finite_json(np.abs(est.h1[i, :m]).tolist()),
                      "phase_rad": finite_json(np.angle(est.h1[i, :m]).tolist()),
                      "coherence": finite_json(est.coherence[i, :m].tolist())}
                  for i, g in enumerate(names)},
    }


def frf_figure(section: dict) -> Figure:
    """|H1| (log) and coherence of every gage against frequency."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 6.5), layout="constrained")
    ax_h, ax_c = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    f = np.asarray(section["f_hz"])
    for g, d in section["gages"].items():
        mag = np.asarray(d["magnitude"], dtype=float)
        ax_h.semilogy(f[1:], mag[1:], lw=0.8, label=f"{g} (peak {d['peak_hz']:.2f} Hz)")
        ax_c.plot(f[1:], np.asarray(d["coherence"], dtype=float)[1:], lw=0.8)
    ax_h.set_ylabel("|H1|, (m/s^2)/N")
    ax_h.set_title(f"accelerance against {section['force_channel']}: H1 over "
                   f"{section['n_blows']} blow(s), {section['window_s']:.2f} s each")
    ax_h.legend(fontsize="small", ncols=2)
    ax_c.set_ylim(0, 1.05)
    ax_c.set_ylabel("coherence")
    ax_c.set_xlabel("frequency, Hz")
    if section["notes"]:
        ax_c.set_title("; ".join(section["notes"]), fontsize="small")
    return fig


def plot_frf(section: dict | None, out_dir: Path, dpi: int = 150) -> list[Path]:
    """Write ``frf.png`` for a computed section; the files written (none without one)."""
    if not section or "gages" not in section:
        return []
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "frf.png"
    frf_figure(section).savefig(path, dpi=dpi)
    return [path]
