"""Plots of one analysed impact, as PNG files: what a person would rather look at than read.

- ``decay``: each gage's free decay with the fitted envelope of the predominant mode;
- ``spectrum``: the rudder gages' spectrum with the identified modes marked;
- ``modeshape``: the predominant mode over the gage layout (elevation, x aft, z up);
- ``stock``: Report 1836's Figures 8 and 9 -- (d_v,alpha) and gamma along the stock.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import scipy.signal  # noqa: E402

from ...analysis.impact import ImpactAnalysis  # noqa: E402
from ...analysis.modal.peaks import bandpass_mode  # noqa: E402
from ...analysis.model.rig import Rig  # noqa: E402

BODY_COLOURS = {"rudder": "tab:blue", "stock": "tab:orange", "hull": "tab:grey"}


def plot_impact(a: ImpactAnalysis, x: np.ndarray, fs_hz: float, rig: Rig, out_dir: Path,
                k: int) -> list[Path]:
    """Write the four plots of impact ``k``; ``x`` (n_gages, n) is the decay analysed (m/s^2),
    rows in ``a.gage_numbers`` order. Returns the files written."""
    out_dir.mkdir(parents=True, exist_ok=True)
    files = [_decay(a, x, fs_hz, out_dir / f"impact{k}_decay.png"),
             _spectrum(a, x, fs_hz, rig, out_dir / f"impact{k}_spectrum.png"),
             _modeshape(a, rig, out_dir / f"impact{k}_modeshape.png")]
    if a.stock_curves:
        files.append(_stock(a, rig, out_dir / f"impact{k}_stock.png"))
    return files


def _decay(a: ImpactAnalysis, x: np.ndarray, fs_hz: float, path: Path) -> Path:
    m, p = a.modes, a.predominant
    row_of = {n: j for j, n in enumerate(a.active_gages)}
    t = np.arange(x.shape[1]) / fs_hz
    env = np.exp(-m.delta[p] * m.frequency_hz[p] * t)
    fig, axes = plt.subplots(4, 4, figsize=(16, 11), sharex=True)
    band = bandpass_mode(x, fs_hz, float(m.frequency_hz[p]))
    for i, (n, ax) in enumerate(zip(a.gage_numbers, axes.flat, strict=False)):
        ax.plot(t, x[i], lw=0.3, color="0.8")
        ax.plot(t, band[i], lw=0.4, color="0.2")
        title = f"gage {n}"
        if n in row_of:
            amp = abs(m.complex_amplitude[row_of[n], p])
            ax.plot(t, amp * env, "r", lw=1)
            ax.plot(t, -amp * env, "r", lw=1)
            g = a.gages.get(n)
            if g is not None and np.isfinite(g.delta):
                title += f": delta {g.delta:.4f} +- {g.delta_se:.1g}"
        else:
            title += f": {a.verdicts[n].code}"
        ax.set_title(title, fontsize=9)
    for ax in axes[-1]:
        ax.set_xlabel("time after decay start (s)")
    fig.suptitle(f"Free decay at {a.decay_start_s:.3f} s (grey: as recorded; black: band-passed "
                 f"around the {a.f_hz:.3f} Hz mode; red: its fitted envelope), m/s^2")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _spectrum(a: ImpactAnalysis, x: np.ndarray, fs_hz: float, rig: Rig, path: Path) -> Path:
    rows = [i for i, n in enumerate(a.gage_numbers) if rig.gage(n).body == "rudder"]
    nper = min(x.shape[1], int(8 * fs_hz))
    f, pxx = scipy.signal.welch(x[rows], fs_hz, nperseg=nper, axis=-1)
    fig, ax = plt.subplots(figsize=(11, 5))
    ax.semilogy(f, pxx.mean(axis=0), lw=0.8)
    for i, (fi, di) in enumerate(zip(a.modes.frequency_hz, a.modes.delta, strict=True)):
        ax.axvline(fi, color="r" if i == a.predominant else "0.6", ls="--", lw=0.8)
        ax.annotate(f"{fi:.2f} Hz\ndelta {di:.4f}", (fi, ax.get_ylim()[1]), fontsize=8,
                    va="top", ha="left")
    ax.set_xlim(0, min(fs_hz / 2, 1.5 * float(np.max(a.modes.frequency_hz))))
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"PSD, {rig.surface.body('rudder')} gages ((m/s^2)^2/Hz)")
    ax.set_title("Spectrum of the decay with the identified modes (red: predominant)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _modeshape(a: ImpactAnalysis, rig: Rig, path: Path) -> Path:
    m, p = a.modes, a.predominant
    shape = dict(zip(a.active_gages, m.mode_shape[:, p], strict=True))
    ref = shape.get(4, 1.0)
    fig, ax = plt.subplots(figsize=(8, 8))
    span = max(abs(c) for g in rig.gages for c in (g.position_m[0], g.position_m[2]))
    for g in rig.gages:  # in the surface's plane: x along the chord, z along the stock
        x, _, z = g.position_m
        ax.plot(x, z, "o", color=BODY_COLOURS[g.body])
        ax.annotate(str(g.number), (x, z), textcoords="offset points", xytext=(4, 4), fontsize=8)
        if g.number in shape:
            s = float(np.real(shape[g.number] * np.conj(ref) / abs(ref)))
            ax.arrow(x, z, 0.25 * span * s, 0, width=0.01 * span, color="r",
                     length_includes_head=True)
    ax.set_aspect("equal")
    sf, names = rig.surface, rig.surface.body
    stock = "up" if sf.is_rudder else "along the stock, to the hull"
    ax.set_xlabel("x, aft (m)")
    ax.set_ylabel(f"{'z' if sf.is_rudder else 'inboard'}, {stock} (m)")
    ax.set_title(f"Mode shape at {a.f_hz:.3f} Hz ({'athwartship' if sf.is_rudder else 'vertical'}"
                 f" amplitude, signed by gage 4)\n"
                 f"blue {names('rudder')}, orange stock, grey {names('hull')}")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _stock(a: ImpactAnalysis, rig: Rig, path: Path) -> Path:
    c, sf = a.stock_curves, rig.surface
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 6), sharey=True)
    ax1.plot(c["d_v_alpha"], c["z_stock_m"], "o-", label=f"stock (d_{sf.label('v')},alpha)")
    ax1.plot(c["d_hull"], c["z_hull_m"], "s--", label=f"{sf.body('hull')} gages 13, 14")
    for ax, key in ((ax1, "z_attach_bending_m"), (ax2, "z_attach_torsion_m")):
        if key in c:
            ax.axhline(c[key][0], color="0.6", ls=":", label="effective attachment")
    ax1.set_xlabel(f"(d_{sf.label('v')},alpha), mode amplitude")
    ax1.set_ylabel("z' above the rudder top (m)" if sf.is_rudder
                   else "z' along the stock from the plane's root (m)")
    ax1.set_title(f"Figure 8: bending, l = {a.stock_lengths.get('bending_m', float('nan')):.3f} m")
    ax1.legend()
    ax2.plot(c["gamma"], c["z_stock_m"], "o-")
    ax2.set_xlabel(f"{sf.label('gamma')}, mode amplitude per m")
    ax2.legend()
    ax2.set_title(f"Figure 9: torsion, l_T = {a.stock_lengths.get('torsion_m', float('nan')):.3f} m")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
