"""Plots of a gap diagnosis: the gap map as heat maps, the gap in physical terms (frequency,
decrement, amplitude, envelope, rigid-body and line discrepancies, MAC) before and after the
named effect, the decays before and after it on the worst gages, and the ranking of
candidates."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ...analysis.gap.diagnose import Diagnosis  # noqa: E402
from ...analysis.gap.evidence import WINDOWS, GapMap  # noqa: E402
from ...analysis.gap.features import DECAY_WINDOWS, FEATURES, FeatureMap  # noqa: E402


def _heat(ax_row, m: GapMap, title: str, vmax: float) -> None:
    for k, ax in enumerate(ax_row):
        im = ax.imshow(m.z[:, :, k], aspect="auto", cmap="magma", vmin=-2, vmax=vmax, origin="upper")
        ax.set_title(f"{title}: {WINDOWS[k]}", fontsize=9)
        ax.set_xticks(range(len(m.bands.labels)), m.bands.labels, rotation=45, fontsize=7)
        ax.set_yticks(range(len(m.gage_numbers)), [f"g{g}" for g in m.gage_numbers], fontsize=7)
    plt.colorbar(im, ax=ax_row, label="z (beyond noise)")


def plot_map(d: Diagnosis, out: Path) -> Path:
    maps = [(d.map_fit, "fitted")] + ([(d.map_held, "held out")] if d.map_held else [])
    if d.best and d.best.map_fit is not None:
        maps.append((d.best.map_fit, f"fitted, with {d.best.name}"))
    vmax = max(6.0, max(float(np.max(m.z)) for m, _ in maps))
    fig, axes = plt.subplots(len(maps), 3, figsize=(12, 3.6 * len(maps)), squeeze=False,
                             layout="constrained")
    for row, (m, t) in zip(axes, maps, strict=True):
        _heat(row, m, t, vmax)
    fig.suptitle(f"gap map (gage x band x window), verdict: {d.verdict}")
    path = out / "gap_map.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _feature_row(axes, fm: FeatureMap, title: str, vmax: float) -> None:
    cols = [f"{f:.1f} {w[0]}" for f in fm.mode_hz for w in DECAY_WINDOWS]
    gl = [f"g{g}" for g in fm.gage_numbers]
    kw = {"aspect": "auto", "cmap": "RdBu_r", "vmin": -vmax, "vmax": vmax, "interpolation": "nearest"}
    for ax, name in zip(axes, FEATURES, strict=False):
        z = fm.z[name].reshape(len(gl), -1)                 # modes x windows, windows fastest
        im = ax.imshow(np.ma.masked_invalid(z), **kw)
        ax.set_title(f"{title}: {name}", fontsize=8)
        ax.set_xticks(range(len(cols)), cols, rotation=60, fontsize=6)
        ax.set_yticks(range(len(gl)), gl, fontsize=6)
    ax = axes[len(FEATURES)]
    ax.imshow(np.ma.masked_invalid(fm.line_z), **kw)
    ax.set_title(f"{title}: lines before the blows", fontsize=8)
    ax.set_xticks(range(len(fm.bands.labels)), fm.bands.labels, rotation=60, fontsize=6)
    ax.set_yticks(range(len(gl)), gl, fontsize=6)
    ax = axes[len(FEATURES) + 1]
    ax.imshow(np.ma.masked_invalid(fm.mac_z.T), **kw)
    ax.set_title(f"{title}: MAC (z > 0: less alike)", fontsize=8)
    ax.set_xticks(range(len(fm.mode_hz)), [f"{f:.1f} Hz" for f in fm.mode_hz], rotation=60, fontsize=6)
    ax.set_yticks(range(len(DECAY_WINDOWS)), DECAY_WINDOWS, fontsize=6)
    plt.colorbar(im, ax=axes, label="z against the replicates", shrink=0.8)


def plot_features(d: Diagnosis, out: Path) -> Path | None:
    """The gap in physical terms as signed z heat maps (red: the trial above the model),
    calibrated model and, when named, with the effect."""
    rows = [(d.features, "calibrated")] if d.features else []
    if d.best and d.best.features is not None:
        rows.append((d.best.features, f"+ {d.best.name}"))
    if not rows:
        return None
    level = rows[0][0].list_level
    vmax = max(2 * level, 8.0)
    n = len(FEATURES) + 2
    fig, axes = plt.subplots(len(rows), n, figsize=(2.4 * n, 3.8 * len(rows)), squeeze=False,
                             layout="constrained")
    for ax_row, (fm, title) in zip(axes, rows, strict=True):
        _feature_row(ax_row, fm, title, vmax)
    fig.suptitle(f"the gap in physical terms (columns: mode Hz, e/l = early/late decay); beyond z "
                 f"{level:.1f} stands out of the whole map", fontsize=10)
    path = out / "gap_features.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_decays(d: Diagnosis, out: Path, n_gages: int = 3) -> Path:
    td = d.forward.td
    base = d.base.fit
    after = d.best.cal.fit if d.best else None
    excess = (d.map_fit.observed - d.map_fit.expected).sum(axis=(1, 2))
    worst = list(np.argsort(-excess)[:n_gages])
    segs = [int(np.flatnonzero(td.fitted)[0])] + ([int(np.flatnonzero(~td.fitted)[0])]
                                                  if (~td.fitted).any() else [])
    fig, axes = plt.subplots(len(worst), len(segs), figsize=(7 * len(segs), 2.6 * len(worst)),
                             squeeze=False, layout="constrained")
    t = np.arange(td.n_s) / td.fs_hz - (td.onsets_s[0] - td.seg_t0_s[0])
    for i, g in enumerate(worst):
        for k, s in enumerate(segs):
            ax = axes[i][k]
            ax.plot(t, td.x[s, g], color="0.6", lw=0.8, label="data")
            ax.plot(t, base.pred[s, g], color="C0", lw=0.8, label="calibrated model")
            if after is not None:
                ax.plot(t, after.pred[s, g], color="C3", lw=0.8, ls="--", label=f"+ {d.best.name}")
            kind = "fitted" if td.fitted[s] else "held out"
            ax.set_title(f"gage {td.gage_numbers[g]}, impact {s} ({kind})", fontsize=9)
            ax.set_ylabel("m/s^2")
            ax.axvline(0, color="k", lw=0.5)
    axes[-1][0].set_xlabel("s from the blow")
    axes[0][0].legend(fontsize=7, loc="upper right")
    path = out / "gap_decays.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_ranking(d: Diagnosis, out: Path) -> Path:
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
    sigs = [s for s in d.signatures if np.isfinite(s.z)]
    a.barh([s.effect.name for s in sigs][::-1], [s.z for s in sigs][::-1], color="C0")
    a.axvline(0, color="k", lw=0.5)
    a.set_xlabel("signature score z (charged for placements tried)")
    a.set_title("signature match")
    c = d.candidates
    b.barh([x.name for x in c][::-1], [x.dbic for x in c][::-1], color="C3")
    b.axvline(0, color="k", lw=0.5)
    b.set_xlabel("dBIC against the calibrated model (negative is better)")
    b.set_title("refit with the term")
    path = out / "gap_ranking.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_diagnosis(d: Diagnosis, out: Path) -> list[Path]:
    feats = plot_features(d, out)
    return [plot_map(d, out), *([feats] if feats else []), plot_decays(d, out), plot_ranking(d, out)]
