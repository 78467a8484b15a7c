"""Plots of a gap diagnosis as matplotlib Figures: the gap map as heat maps, the gap in physical
terms (frequency, decrement, amplitude, envelope, rigid-body and line discrepancies, MAC) before
and after the named effect, the decays before and after it on the worst gages with their
residuals, and the ranking of candidates.

Built with :class:`matplotlib.figure.Figure`, not ``pyplot``: no backend is chosen at import and
a notebook shows the figures inline. Cells that were not computed are hatched grey, never the
colour of z = 0; the thresholds the diagnosis uses are marked on the colour bars.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import matplotlib as mpl
import numpy as np
from matplotlib.figure import Figure

from ...analysis.gap.diagnose import Diagnosis, Settings
from ...analysis.gap.evidence import GAP_CELL_Z, WINDOWS, GapMap
from ...analysis.gap.features import DECAY_WINDOWS, FEATURES, FeatureMap

DPI = 150
EFFECT_TEXT = {
    "added_mass": "added mass", "ambient_tone": "ambient tone", "clipping": "clipping",
    "double_hit": "double hit", "tiller": "tiller mode", "hull_coupling": "hull coupling",
    "friction": "friction", "gage_alignment": "gage alignment", "gage_sensitivity": "gage sensitivity",
    "highpass": "high-pass filter", "split_mode": "split mode", "time_skew": "time skew",
}
"""The gap effects' codes in words, for titles and tick labels."""
_NOT_COMPUTED = "0.8"


def effect_text(name: str) -> str:
    """An effect's (or a pair's, ``a+b``) name in words."""
    return " + ".join(EFFECT_TEXT.get(n, n.replace("_", " ")) for n in name.split("+"))


def _cmap(name: str) -> mpl.colors.Colormap:
    return mpl.colormaps[name].with_extremes(bad=_NOT_COMPUTED)


def _hatch_missing(ax, z: np.ndarray) -> None:
    """Hatch the cells of image ``z`` that hold no number."""
    for i, j in zip(*np.nonzero(~np.isfinite(z)), strict=True):
        ax.add_patch(mpl.patches.Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, hatch="///",
                                           edgecolor="0.55", lw=0))


def _mark(cbar, levels: dict[str, float]) -> None:
    """Threshold lines, labelled, on a colour bar: the labels on the bar's left, clear of its
    tick labels on the right (a label at z 3 sat on the tick label 2, one at 8 on the bar)."""
    for label, v in levels.items():
        cbar.ax.axhline(v, color="c", lw=1.5)
        if label:
            cbar.ax.text(-0.15, v, label, transform=cbar.ax.get_yaxis_transform(), va="center",
                         ha="right", fontsize=7, color="teal")


def _wrap(text: str, width: int) -> str:
    """A title broken into lines of at most ``width`` characters (a pair of effects' names made
    a panel's title run into its neighbour's)."""
    return "\n".join(textwrap.wrap(text, width)) or text


def _heat(fig: Figure, ax_row, m: GapMap, title: str, vmax: float) -> None:
    for k, ax in enumerate(ax_row):
        z = m.z[:, :, k]
        im = ax.imshow(np.ma.masked_invalid(z), aspect="auto", cmap=_cmap("magma"), vmin=-2,
                       vmax=vmax, origin="upper", interpolation="nearest")
        _hatch_missing(ax, z)
        ax.set_title(_wrap(f"{title}: {WINDOWS[k]}-blow window", 45), fontsize=9)
        ax.set_xticks(range(len(m.bands.labels)), m.bands.labels, rotation=45, ha="right", fontsize=7)
        ax.set_yticks(range(len(m.gage_numbers)), [f"gage {g}" for g in m.gage_numbers], fontsize=7)
    cbar = fig.colorbar(im, ax=ax_row, label="z (beyond noise)")
    _mark(cbar, {f"cell {GAP_CELL_Z:g}": GAP_CELL_Z, f"gap {Settings().z_gap:g}": Settings().z_gap})


def map_figure(d: Diagnosis) -> Figure:
    """The gap map, z per gage x band x window, fitted and held-out impacts, and with the
    named effect."""
    maps = [(d.map_fit, "fitted")] + ([(d.map_held, "held out")] if d.map_held else [])
    if d.best and d.best.map_fit is not None:
        maps.append((d.best.map_fit, f"fitted, with {effect_text(d.best.name)}"))
    vmax = max(Settings().z_gap + 2, max(float(np.nanmax(m.z)) for m, _ in maps))
    fig = Figure(figsize=(13, 3.8 * len(maps)), layout="constrained")
    axes = fig.subplots(len(maps), 3, squeeze=False)
    for row, (m, t) in zip(axes, maps, strict=True):
        _heat(fig, row, m, t, vmax)
    fig.suptitle(f"gap map (gage x band x window); grey hatched: not computed\nthe map alone says: "
                 f"{d.verdict} (the diagnosis's answer, both layers, is gap.json's verdict)", fontsize=11)
    return fig


def _feature_row(fig: Figure, axes, fm: FeatureMap, title: str, vmax: float) -> None:
    cols = [f"{f:.1f} Hz {w}" for f in fm.mode_hz for w in DECAY_WINDOWS]
    gl = [f"gage {g}" for g in fm.gage_numbers]
    kw = {"aspect": "auto", "cmap": _cmap("RdBu_r"), "vmin": -vmax, "vmax": vmax,
          "interpolation": "nearest"}
    panels = [(fm.z[name].reshape(len(gl), -1), name, cols, gl) for name in FEATURES]
    panels += [(fm.line_z, "lines before the blows", fm.bands.labels, gl),
               (fm.mac_z.T, "MAC (z > 0: less alike)", [f"{f:.1f} Hz" for f in fm.mode_hz],
                list(DECAY_WINDOWS))]
    for k, (ax, (z, name, xl, yl)) in enumerate(zip(axes, panels, strict=False)):
        im = ax.imshow(np.ma.masked_invalid(z), **kw)
        _hatch_missing(ax, z)
        # the row's model (a pair of effects is long) once, above its first panel
        ax.set_title(f"{title}\n{name}" if k == 0 else name, fontsize=8, loc="left" if k == 0 else "center")
        ax.set_xticks(range(len(xl)), xl, rotation=60, ha="right", fontsize=6)
        ax.set_yticks(range(len(yl)), yl, fontsize=6)
    cbar = fig.colorbar(im, ax=axes, label="z against the replicates", shrink=0.8)
    _mark(cbar, {"listed": fm.list_level, "": -fm.list_level})


def features_figure(d: Diagnosis) -> Figure | None:
    """The gap in physical terms as signed z heat maps (red: the trial above the model),
    calibrated model and, when named, with the effect; None without replicates."""
    rows = [(d.features, "calibrated")] if d.features else []
    if d.best and d.best.features is not None:
        rows.append((d.best.features, f"+ {effect_text(d.best.name)}"))
    if not rows:
        return None
    level = rows[0][0].list_level
    vmax = max(2 * level, 8.0)
    n = len(FEATURES) + 2
    fig = Figure(figsize=(2.6 * n, 4.0 * len(rows)), layout="constrained")
    axes = fig.subplots(len(rows), n, squeeze=False)
    for ax_row, (fm, title) in zip(axes, rows, strict=True):
        _feature_row(fig, ax_row, fm, title, vmax)
    fig.suptitle(f"the gap in physical terms (columns: mode and early/late decay); beyond |z| "
                 f"{level:.1f} a cell stands out of the whole map; grey hatched: not judged", fontsize=10)
    return fig


def decays_figure(d: Diagnosis, n_gages: int = 3) -> Figure:
    """The worst gages' decays, data drawn over the calibrated model (and the named effect's),
    each with its residual, data - model, below it (m/s^2)."""
    td = d.forward.td
    base = d.base.fit
    after = d.best.cal.fit if d.best else None
    excess = (d.map_fit.observed - d.map_fit.expected).sum(axis=(1, 2))
    worst = list(np.argsort(-excess)[:n_gages])
    segs = [int(np.flatnonzero(td.fitted)[0])] + ([int(np.flatnonzero(~td.fitted)[0])]
                                                  if (~td.fitted).any() else [])
    fig = Figure(figsize=(7 * len(segs), 3.6 * len(worst)), layout="constrained")
    grid = fig.add_gridspec(2 * len(worst), len(segs), height_ratios=[2.2, 1] * len(worst))
    t = np.arange(td.n_s) / td.fs_hz - (td.onsets_s[0] - td.seg_t0_s[0])
    for i, g in enumerate(worst):
        for k, s in enumerate(segs):
            ax = fig.add_subplot(grid[2 * i, k])
            res = fig.add_subplot(grid[2 * i + 1, k], sharex=ax)
            ax.plot(t, base.pred[s, g], color="C0", lw=1.0, label="calibrated model")
            res.plot(t, td.x[s, g] - base.pred[s, g], color="C0", lw=0.6)
            if after is not None:
                ax.plot(t, after.pred[s, g], color="C3", lw=1.0, ls="--",
                        label=f"with {effect_text(d.best.name)}")
                res.plot(t, td.x[s, g] - after.pred[s, g], color="C3", lw=0.6)
            ax.plot(t, td.x[s, g], color="k", lw=0.5, label="data", zorder=3)
            kind = "fitted" if td.fitted[s] else "held out"
            ax.set_title(f"gage {td.gage_numbers[g]}, impact {s} ({kind})", fontsize=9)
            ax.set_ylabel("m/s²")
            res.set_ylabel("residual (m/s²)", fontsize=8)
            for a in (ax, res):
                a.axvline(0, color="0.5", lw=0.5)
            ax.tick_params(labelbottom=False)
            if i == 0 and k == 0:
                ax.legend(fontsize=7, loc="upper right")
            if i == len(worst) - 1:
                res.set_xlabel("time from the blow (s)")
    return fig


def ranking_figure(d: Diagnosis) -> Figure:
    """Every effect's signature score and every candidate's ΔBIC (symmetric-log axis, so that
    -70 000 and +18 both show); an effect with no score is listed as such, not dropped."""
    fig = Figure(figsize=(12, 0.35 * max(len(d.signatures), len(d.candidates), 6) + 1.5),
                 layout="constrained")
    a, b = fig.subplots(1, 2)
    sigs = list(d.signatures)[::-1]
    z = np.array([s.z for s in sigs], float)
    y = np.arange(len(sigs))
    ok = np.isfinite(z)
    a.barh(y[ok], z[ok], color="C0")
    for yi in y[~ok]:
        a.text(0, yi, " no score (no placement to try)", va="center", fontsize=8, color="0.4")
    a.set_yticks(y, [effect_text(s.effect.name) for s in sigs], fontsize=8)
    a.set_ylim(-0.7, len(sigs) - 0.3)   # a row without a bar (no score) clear of the axis line
    a.axvline(0, color="k", lw=0.5)
    a.set_xlabel("signature score z (charged for the placements tried)")
    a.set_title("signature match")
    c = d.candidates[::-1]
    y = np.arange(len(c))
    best = d.best.name if d.best else None
    b.barh(y, [x.dbic for x in c], color=["C3" if x.name == best else "C1" for x in c])
    b.set_xscale("symlog", linthresh=10)
    for yi, x in zip(y, c, strict=True):
        b.annotate(f"{x.dbic:,.0f}", (x.dbic, yi), xytext=(3 if x.dbic >= 0 else -3, 0),
                   textcoords="offset points", ha="left" if x.dbic >= 0 else "right", va="center",
                   fontsize=7)
    b.set_yticks(y, [effect_text(x.name) for x in c], fontsize=8)
    b.yaxis.tick_right()
    b.axvline(0, color="k", lw=0.5)
    b.margins(x=0.25)
    b.set_ylim(-0.7, max(len(c), 1) - 0.3)
    b.set_xlabel("ΔBIC against the calibrated model\n(symmetric log; negative is better)")
    b.set_title(_wrap("refit with the effect" + (f" (red: named, {effect_text(best)})" if best else ""), 50))
    return fig


def diagnosis_figures(d: Diagnosis) -> dict[str, Figure]:
    """Every plot of a diagnosis by kind: ``map``, ``features`` (when there are replicates),
    ``decays``, ``ranking``."""
    figs = {"map": map_figure(d)}
    feats = features_figure(d)
    if feats is not None:
        figs["features"] = feats
    figs |= {"decays": decays_figure(d), "ranking": ranking_figure(d)}
    return figs


def plot_diagnosis(d: Diagnosis, out: Path) -> list[Path]:
    """Write :func:`diagnosis_figures` as ``gap_{kind}.png`` in ``out``; returns the files."""
    files = []
    for kind, fig in diagnosis_figures(d).items():
        files.append(out / f"gap_{kind}.png")
        fig.savefig(files[-1], dpi=DPI)
    return files
