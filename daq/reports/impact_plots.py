"""Plots of one analysed impact, as matplotlib Figures (a notebook shows them inline; the report
writes them as PNG files): what a person would rather look at than read.

- ``decay``: per gage and mode, the log-envelope of the mode's own component against time with
  its fitted line -- the decrement shown is the one the eye can see;
- ``spectrum``: the rudder gages' spectrum with the identified modes marked and listed;
- ``modeshape``: the predominant mode as the gages measure it -- athwartship amplitude against
  height, seen from aft, and each gage's amplitude and phase;
- ``stock``: Report 1836's Figures 8 and 9 -- (d_v,alpha) and gamma along the stock.

The figures are built with :class:`matplotlib.figure.Figure`, not ``pyplot``: no backend is
chosen or needed, nothing is left open in a figure manager, and they draw in any thread.
"""

from __future__ import annotations

from collections.abc import Collection
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullLocator

from ...analysis import filters
from ...analysis.impact import ImpactAnalysis
from ...analysis.modal.peaks import bandpass_mode
from ...analysis.model.rig import Rig
from . import png

BODY_COLOURS = {"rudder": "tab:blue", "stock": "tab:orange", "hull": "tab:grey"}
DPI = 150
PNG_COMPRESSION = 3
"""zlib level of the PNGs: 3 wrote the 16-panel decay figure (2400 x 1710 px) in 2/3 of the
time of the default 6 (0.10 s against 0.15 s CPU through Pillow), the file 8 % larger."""


PLOT_KINDS = ("decay", "spectrum", "modeshape", "stock")
"""Every kind of impact plot (:func:`impact_figures`)."""


def impact_figures(a: ImpactAnalysis, x: np.ndarray, fs_hz: float, rig: Rig,
                   kinds: Collection[str] | None = None, *,
                   reuse: dict | None = None) -> dict[str, Figure]:
    """The plots of one impact by kind; ``x`` (n_gages, n) is the decay analysed (m/s^2) from
    ``a.decay_start_s``, rows in ``a.gage_numbers`` order. ``kinds``: those of
    :data:`PLOT_KINDS` to draw (default all; a kind the rig cannot give is left out).
    ``reuse``: a dict kept between calls that write the figures and drop them, whose decay
    figure is redrawn rather than built anew (:func:`decay_figure`)."""
    kinds = PLOT_KINDS if kinds is None else tuple(kinds)
    unknown = set(kinds) - set(PLOT_KINDS)
    if unknown:
        raise ValueError(f"unknown plot kind(s) {sorted(unknown)}; known: {', '.join(PLOT_KINDS)}")
    figs = {}
    if "decay" in kinds:
        figs["decay"] = decay_figure(a, x, fs_hz, reuse)
    if "spectrum" in kinds:
        figs["spectrum"] = spectrum_figure(a, x, fs_hz, rig)
    if "modeshape" in kinds and rig.structural:  # a channels-only rig has no gage positions
        figs["modeshape"] = modeshape_figure(a, rig)
    if "stock" in kinds and a.stock_curves:
        figs["stock"] = stock_figure(a, rig)
    return figs


def plot_impact(a: ImpactAnalysis, x: np.ndarray, fs_hz: float, rig: Rig, out_dir: Path,
                k: int, kinds: Collection[str] | None = None, *,
                reuse: dict | None = None) -> list[Path]:
    """Write the plots of impact ``k`` as ``impact{k}_{kind}.png`` (:func:`impact_figures`,
    ``kinds`` and ``reuse`` as there; one dict given to every impact of a trial draws them at
    about half the cost). Returns the files written."""
    out_dir.mkdir(parents=True, exist_ok=True)
    files = []
    for kind, fig in impact_figures(a, x, fs_hz, rig, kinds, reuse=reuse).items():
        files.append(out_dir / f"impact{k}_{kind}.png")
        if kind == "decay":
            write_decay_png(fig, files[-1], reuse)
        else:
            write_png(fig, files[-1])
    return files


PER_HIT = "per-hit"
"""The gid of the decay figure's figure-level texts that change from hit to hit."""


def _per_hit_artists(fig: Figure) -> list:
    """What of a decay figure (:func:`decay_figure`) is drawn anew for each hit, in drawing
    order: each used panel's curves, frame, y axis and title, then the legend and the heading.
    The rest -- backgrounds, x axes, axis labels, unused panels -- is the same for every hit
    whose decay is as long."""
    out = []
    for ax in fig.axes:
        if ax.collections:  # a used panel
            out += [*ax.collections, *ax.spines.values(), ax.yaxis, ax.title]
    return out + list(fig.legends) + [t for t in fig.texts if t.get_gid() == PER_HIT]


def write_decay_png(fig: Figure, path: Path, reuse: dict | None = None) -> None:
    """The decay figure written as :func:`write_png` does, in two layers: what is the same for
    every hit, drawn once and kept in ``reuse`` (if given) while the figure and its time axis
    are, then what is this hit's. A figure drawn anew is drawn in the same two layers, so that
    the PNG is the same pixel for pixel either way; the figure itself is left as it was (a
    notebook draws it whole)."""
    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    dpi, per_hit = fig.dpi, _per_hit_artists(fig)
    stamp = (fig.axes[0].get_xlim(), DPI)
    kept = None if reuse is None else reuse.get("decay_background")
    fig.set_dpi(DPI)
    for art in per_hit:
        art.set_animated(True)  # left out of canvas.draw
    try:
        if kept is not None and kept[0] is fig and kept[1] == stamp:
            canvas.restore_region(kept[2])
        else:
            canvas.draw()
            if reuse is not None:
                reuse["decay_background"] = (fig, stamp, canvas.copy_from_bbox(fig.bbox))
        for art in per_hit:
            fig.draw_artist(art)
        _write_canvas(canvas, path)
    finally:
        for art in per_hit:
            art.set_animated(False)
        fig.set_dpi(dpi)


def _write_canvas(canvas: FigureCanvasAgg, path: Path) -> None:
    """What ``canvas`` has drawn, into ``path`` as PNG: RGB when it is opaque, else RGBA."""
    rgba = np.asarray(canvas.buffer_rgba())
    png.write_png(path, rgba[..., :3] if rgba[..., 3].min() == 255 else rgba, DPI,
                  PNG_COMPRESSION)


def write_png(fig: Figure, path: Path) -> None:
    """``fig`` drawn at :data:`DPI` into ``path`` as an RGB PNG (RGBA if it is not opaque;
    :func:`~.png.write_png`): ``savefig`` wrote RGBA with alpha 255 throughout, through
    Pillow's per-row filter search, in twice the time."""
    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    dpi = fig.dpi
    fig.set_dpi(DPI)
    try:
        canvas.draw()
        _write_canvas(canvas, path)
    finally:
        fig.set_dpi(dpi)


PLOT_POINTS = 1200
"""Points per drawn curve at most (a panel is a few hundred pixels wide): longer curves are drawn
through :func:`thinned`'s envelope of their extremes, which looks the same."""


def thinned(t: np.ndarray, y: np.ndarray, n_max: int = PLOT_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """``(t, y)`` with at most about ``n_max`` points: the minimum and the maximum of each of
    ``n_max // 2`` consecutive bins, in time order (NaNs kept as gaps), so that a noisy curve
    keeps its band and every spike; short curves are returned as they are."""
    n = y.size
    if n <= n_max:
        return t, y
    m = -(-n // (n_max // 2))  # samples per bin
    n_bins = -(-n // m)
    pad = n_bins * m - n
    yb = np.concatenate([y, np.full(pad, np.nan)]).reshape(n_bins, m)
    tb = np.concatenate([t, np.full(pad, t[-1])]).reshape(n_bins, m)
    finite = np.isfinite(yb)
    has = finite.any(axis=1)
    lo_i = np.argmin(np.where(finite, yb, np.inf), axis=1)
    hi_i = np.argmax(np.where(finite, yb, -np.inf), axis=1)
    first, second = np.minimum(lo_i, hi_i), np.maximum(lo_i, hi_i)
    rows = np.arange(n_bins)
    tt = np.stack([tb[rows, first], tb[rows, second]], axis=1).ravel()
    yy = np.stack([yb[rows, first], yb[rows, second]], axis=1)
    yy[~has] = np.nan
    return tt, yy.ravel()


def mode_components(a: ImpactAnalysis, x: np.ndarray, fs_hz: float) -> np.ndarray:
    """Each mode's own component on each used gage: the decay less the offset and the other
    fitted modes, band-passed around the mode (m/s^2), shape (n_active, n_modes, n)."""
    m = a.modes
    rows = [a.gage_numbers.index(n) for n in a.active_gages]
    t = np.arange(x.shape[1]) / fs_hz
    lam = -m.delta * m.frequency_hz + 2j * np.pi * m.frequency_hz
    each = np.real(m.complex_amplitude[:, :, None] * np.exp(lam[None, :, None] * t))
    rest = x[rows] - m.offset[:, None] - each.sum(axis=1)
    out = np.empty_like(each)
    for k, f in enumerate(m.frequency_hz):
        bw = min(0.4, 1.6 * (fs_hz / 2 - f) / f)  # keep the upper edge below Nyquist
        out[:, k] = bandpass_mode(rest + each[:, k], fs_hz, float(f), rel_bandwidth=bw)
    return out


def mode_envelopes(comp: np.ndarray, fs_hz: float, f_hz: np.ndarray) -> np.ndarray:
    """Envelope of each mode's component (``comp`` (n_gages, n_modes, n), any unit; the same
    shape and unit back) by complex demodulation: shifted down by the mode's frequency and
    low-passed (zero-phase Butterworth, 2nd order, at a fifth of it: half the band-pass's width),
    twice the modulus. Unlike the FFT's Hilbert transform, whose 1/t tail carries the abrupt
    start of a ringing across the record (and, circularly, onto its quiet end: a decayed mode's
    envelope rose 1000x in the last second), its edge effects stay within the filter's time."""
    t = np.arange(comp.shape[-1]) / fs_hz
    out = np.empty(comp.shape)
    for k, f in enumerate(np.asarray(f_hz, dtype=float)):
        z = comp[:, k] * np.exp(-2j * np.pi * f * t)
        sos = filters.butter(2, 0.2 * f, fs_hz, output="sos")
        out[:, k] = 2 * np.hypot(filters.sosfiltfilt(sos, z.real), filters.sosfiltfilt(sos, z.imag))
    return out


def decay_figure(a: ImpactAnalysis, x: np.ndarray, fs_hz: float,
                 reuse: dict | None = None) -> Figure:
    """Per gage a panel; per mode in it the envelope of the mode's own component (solid, log
    scale) and the envelope of its fitted decay, |a| exp(-delta f t) (dashed). With ``reuse``
    (a dict kept between calls), the figure of the previous call with the same panels is
    redrawn with this impact's curves rather than built anew (its panels and ticks are most
    of the figure's cost): that earlier figure is then this one."""
    m = a.modes
    row_of = {n: j for j, n in enumerate(a.active_gages)}
    comp = mode_components(a, x, fs_hz)
    env = mode_envelopes(comp, fs_hz, m.frequency_hz)
    for k, f in enumerate(m.frequency_hz):  # the filters' end effect: about one bandwidth's time
        env[:, k, max(1, x.shape[1] - round(fs_hz / (0.4 * f))):] = np.nan
    t = np.arange(x.shape[1]) / fs_hz
    fig, axes = _decay_panels(a, reuse)
    colours = [f"C{k}" for k in range(len(m.frequency_hz))]
    floor = np.nanmax(env) * 1e-4  # four decades below the largest envelope
    # the panels share x: one call sets all 16 (a call on each set every panel 16 times); the
    # span a whole tenth of a second, so that the hits of a trial (decays a sample or so apart
    # in length) share the time axis and the layer drawn once (write_decay_png)
    span = np.ceil(t[-1] * 10 - 1e-9) / 10
    axes[0].set_xlim(-0.05 * span, 1.05 * span)
    for ax, n in zip(axes, a.gage_numbers, strict=False):
        if n not in row_of:
            continue
        j = row_of[n]
        top = floor
        curves, fits, fit_colours = [], [], []
        for k, c in enumerate(colours):
            amp = abs(m.complex_amplitude[j, k])
            d, f = m.channel_delta[j, k], m.channel_frequency_hz[j, k]
            tt, yy = thinned(t, np.maximum(env[j, k], floor))
            curves.append(np.column_stack([tt, yy]))
            top = max(top, float(np.nanmax(yy, initial=floor)))
            if np.isfinite(d) and amp > 0:  # a straight line on log axes: two points draw it
                ends = t[[0, -1]]
                fits.append(np.column_stack([ends, amp * np.exp(-d * f * ends)]))
                fit_colours.append(c)
                top = max(top, amp)
        # one collection of a panel's envelopes and one of its fitted lines, not a Line2D each:
        # a line made by ax.plot and drawn cost about 1 ms, and a figure has ~100 of them
        ax.add_collection(LineCollection(curves, colors=colours, linewidths=0.8),
                          autolim=False)
        if fits:
            ax.add_collection(LineCollection(fits, colors=fit_colours, linewidths=1.2,
                                             linestyles="--"), autolim=False)
        # the limits set, not found by autoscaling every line (a fifth of the figure's build):
        # the curves' span, with the 5 % margins autoscaling gave (in decades on the log axis)
        ax.set_ylim(floor, top * (top / floor) ** 0.05)
        g = a.gages.get(n)
        title = f"gage {n}"
        if g is not None and np.isfinite(g.delta):
            title += f": δ = {g.delta:.4f} ± {g.delta_se:.1g} at {g.f_hz:.2f} Hz"
        else:  # not a number: said, never drawn as zero
            title += f": δ of the {a.f_hz:.2f} Hz mode not measured"
        # y given: the title is not moved clear of top tick labels (there are none), which
        # measured every tick label of the panel and was a third of the figure's drawing
        ax.set_title(title, fontsize=9, y=1.0)
    labels = [f"{f:.2f} Hz, δ = {d:.4f}{a.mode_tag(k)}"
              for k, (f, d) in enumerate(zip(m.frequency_hz, m.delta, strict=True))]
    proxies = [Line2D([], [], color=c) for c in colours]
    fig.legend(proxies, labels, loc="upper right", bbox_to_anchor=(0.99, 1.0), ncols=len(labels),
               fontsize=9,
               title="solid: envelope of the mode's own component in the data; dashed: its fitted "
                     "decay |a| exp(−δ f t)", title_fontsize=9)
    fig.suptitle(f"Free decay from {a.decay_start_s:.3f} s, per mode", x=0.01,
                 ha="left").set_gid(PER_HIT)
    return fig


def _decay_panels(a: ImpactAnalysis, reuse: dict | None) -> tuple[Figure, np.ndarray]:
    """The decay figure's panels without curves: those of ``reuse["decay"]`` emptied if they
    were laid out for the same gages, used and unused alike (then the curves, legend and limits
    are cleared; the titles are set anew), else new ones (kept in ``reuse``, if given)."""
    unused = tuple((n, a.verdicts[n].code) for n in a.gage_numbers
                   if n not in a.active_gages)
    key = (tuple(a.gage_numbers), tuple(a.active_gages), unused)
    if reuse is not None and reuse.get("decay", (None,))[0] == key:
        _, fig, axes = reuse["decay"]
        for leg in list(fig.legends):
            leg.remove()
        for ax in axes:
            for curves in list(ax.collections):
                curves.remove()
        return fig, axes
    n_col = 4
    n_row = -(-len(a.gage_numbers) // n_col)
    height = 2.6 * n_row + 1
    # A fixed layout (inches kept for the titles, legend and labels): the constrained layout
    # measured every tick label of every panel, and cost more than all the rest of the figure.
    fig = Figure(figsize=(16, height))
    FigureCanvasAgg(fig)  # its own Agg canvas: a figure redrawn keeps its renderer (16 MB)
    fig.subplots_adjust(left=0.055, right=0.99, bottom=0.6 / height, top=1 - 1.05 / height,
                        hspace=0.32, wspace=0.2)
    axes = fig.subplots(n_row, n_col, sharex=True, squeeze=False).ravel()
    for ax, (n, code) in zip(axes, ((n, dict(unused).get(n)) for n in a.gage_numbers),
                             strict=False):
        if code is not None:
            ax.text(0.5, 0.5, f"gage {n} not used:\n{code.text}",
                    ha="center", va="center", transform=ax.transAxes, color="0.4")
            ax.set_facecolor("0.93")
            ax.tick_params(left=False, labelleft=False)
            continue
        ax.set_yscale("log")
        ax.yaxis.set_minor_locator(NullLocator())  # decades suffice (minor log ticks: costly)
        # few ticks: each is three lines and a label built on the first draw, and the ticks of
        # the 16 panels were most of the figure's drawing
        ax.yaxis.set_major_locator(LogLocator(numticks=4))
        ax.yaxis.set_major_formatter(FuncFormatter(_decade))
        ax.xaxis.set_major_locator(MaxNLocator(4))
    for ax in axes[len(a.gage_numbers):]:
        ax.set_visible(False)
    # one label for each axis of all the panels, at a fixed place: a label per row and per
    # column was 8 texts to draw each hit (text is most of the drawing: glyph by glyph), and
    # placed by their ticks' boxes they measured every tick label of every panel
    fig.supxlabel("time after the decay's start (s)", y=0.15 / height, va="bottom")
    fig.supylabel("envelope of each mode (m/s²)", x=0.005, ha="left")
    if reuse is not None:
        reuse["decay"] = (key, fig, axes)
    return fig, axes


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _decade(v: float, _pos: int | None = None) -> str:
    """A log axis's tick label ``v`` as plain text, ``10⁻³`` (a decade; "" between): the
    default's mathtext ``$10^{-3}$`` built a TeX parser on the first figure, ~0.2 s CPU."""
    if not v > 0:
        return ""
    e = round(float(np.log10(v)))
    return f"10{str(e).translate(_SUPERSCRIPT)}" if np.isclose(v, 10.0 ** e) else ""


def spectrum_figure(a: ImpactAnalysis, x: np.ndarray, fs_hz: float, rig: Rig) -> Figure:
    """Mean power spectral density of the rudder gages' decay (Welch, 8 s segments at most) on
    log-log axes, each identified mode a numbered line listed in the legend."""
    rows = [i for i, n in enumerate(a.gage_numbers) if rig.gage(n).body == "rudder"]
    which = f"the {rig.surface.body('rudder')} gages" if rows and rig.structural else "all gages"
    rows = rows if rows and rig.structural else list(range(len(a.gage_numbers)))
    nper = min(x.shape[1], int(8 * fs_hz))
    import scipy.signal  # only here: ~0.5 s of imports (scipy.stats with it) the decay plot needs not

    f, pxx = scipy.signal.welch(x[rows], fs_hz, nperseg=nper, axis=-1)
    p = pxx.mean(axis=0)
    fm = a.modes.frequency_hz
    fig = Figure(figsize=(11, 5), layout="constrained")
    ax = fig.subplots()
    lo, hi = 0.5 * float(np.min(fm)), min(fs_hz / 2, 1.5 * float(np.max(fm)))
    keep = (f >= lo) & (f <= hi)
    ax.loglog(f[keep], p[keep], lw=0.8, color="0.2")
    for k, (fk, dk) in enumerate(zip(fm, a.modes.delta, strict=True)):
        pred = k == a.chain_mode  # the mode the chain ran on stands out
        ax.axvline(fk, color="C3" if pred else f"C{k % 3}", ls="--", lw=1.2 if pred else 0.8,
                   label=f"{k + 1}: {fk:.2f} Hz, δ = {dk:.4f}{a.mode_tag(k)}")
        ax.annotate(str(k + 1), (fk, 1.0), xycoords=("data", "axes fraction"), xytext=(3, -12),
                    textcoords="offset points", fontsize=9)
    top = float(np.max(p[keep]))
    ax.set_ylim(max(float(np.percentile(p[keep], 5)) / 3, top * 1e-7), top * 3)
    ax.set_xlim(lo, hi)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"PSD, mean of {which} ((m/s²)²/Hz)")
    ax.set_title("Spectrum of the free decay with the identified modes", y=1.0)
    ax.legend(fontsize=9, loc="lower left")
    return fig


def _reference(shape: dict[int, complex]) -> complex:
    """Gage 4's component (the report's reference), else the largest."""
    return shape.get(4) or max(shape.values(), key=abs)


def modeshape_figure(a: ImpactAnalysis, rig: Rig) -> Figure:
    """The mode the chain ran on (:attr:`~ramdaq.analysis.impact.ImpactAnalysis.chain_mode`:
    the predominant one unless ``mode_hz`` chose another) at the decay's start: left, each
    athwartship gage's amplitude in phase with the reference gage (m/s^2) against its height,
    seen from aft; right, every used gage's amplitude (m/s^2) with its phase against the
    reference, one row per gage."""
    m, p = a.modes, a.chain_mode
    amp = dict(zip(a.active_gages, m.complex_amplitude[:, p], strict=True))
    ref = _reference(amp)
    turn = np.conj(ref) / abs(ref)
    fig = Figure(figsize=(13, 6.5), layout="constrained")
    ax, bars = fig.subplots(1, 2)
    marks = {"rudder": "o", "stock": "s", "hull": "^"}
    placed: dict[float, int] = {}  # labels at one height, stacked so that none overprints
    for n, c in amp.items():
        g = rig.gage(n)
        if abs(g.direction[1]) < 0.9:  # not athwartship: only in the right panel
            continue
        x, z = float(np.real(c * turn)) * np.sign(g.direction[1]), g.position_m[2]
        ax.plot([0, x], [z, z], color=BODY_COLOURS[g.body], lw=2, alpha=0.6)
        ax.plot(x, z, marks[g.body], color=BODY_COLOURS[g.body], ms=7)
        k = placed.get(z, 0)
        placed[z] = k + 1
        ax.annotate(str(n), (x, z), xytext=(5, 5 - 13 * k), textcoords="offset points", fontsize=8)
    ax.axvline(0, color="k", lw=0.5)
    sf = rig.surface  # drawn in the surface's plane: z along the stock
    across = "athwartship" if sf.is_rudder else "vertical"
    ax.set_xlabel(f"{across} amplitude in phase with gage {4 if 4 in amp else '(largest)'} (m/s²)")
    ax.set_ylabel("z, up (m)" if sf.is_rudder else "inboard, along the stock to the hull (m)")
    ax.set_title(f"{across} gages seen from aft", fontsize=10, y=1.0)
    shown = {rig.gage(n).body for n in amp if abs(rig.gage(n).direction[1]) >= 0.9}
    for body, mk in marks.items():  # a legend of the bodies drawn only
        if body in shown:
            ax.plot([], [], mk, color=BODY_COLOURS[body], label=sf.body(body))
    if shown:
        ax.legend(fontsize=8, loc="best")
    order = sorted(amp, key=lambda n: (-rig.gage(n).position_m[2], n))
    y = np.arange(len(order))
    bars.barh(y, [abs(amp[n]) for n in order], color=[BODY_COLOURS[rig.gage(n).body] for n in order])
    for yi, n in zip(y, order, strict=True):
        bars.annotate(f"{round(float(np.degrees(np.angle(amp[n] * turn)))):+d}°", (abs(amp[n]), yi),
                      xytext=(3, 0), textcoords="offset points", va="center", fontsize=8)
    bars.set_yticks(y, [f"gage {n} ({sf.body(rig.gage(n).body)}, x {rig.gage(n).position_m[0]:+.2f}, "
                        f"z {rig.gage(n).position_m[2]:+.2f} m)" for n in order], fontsize=8)
    bars.invert_yaxis()
    bars.margins(x=0.15)
    bars.set_xlabel("amplitude (m/s²); label: phase against the reference gage")
    bars.set_title("every used gage", fontsize=10, y=1.0)
    fig.suptitle(f"Mode at {a.f_hz:.3f} Hz{a.mode_tag(p)}, δ = {m.delta[p]:.4f}, at the decay's start")
    return fig


def stock_figure(a: ImpactAnalysis, rig: Rig) -> Figure:
    """Report 1836's Figures 8 and 9: the bending amplitude (d_v,alpha) and the torsion gamma
    along the stock, with the effective attachment heights (named as the rig's surface names them)."""
    c, sf = a.stock_curves, rig.surface
    fig = Figure(figsize=(11, 6), layout="constrained")
    ax1, ax2 = fig.subplots(1, 2, sharey=True)
    ax1.plot(c["d_v_alpha"], c["z_stock_m"], "o-", label=f"stock (d_{sf.label('v')},alpha)")
    ax1.plot(c["d_hull"], c["z_hull_m"], "s--", label=f"{sf.body('hull')} gages 13, 14")
    for ax, key in ((ax1, "z_attach_bending_m"), (ax2, "z_attach_torsion_m")):
        if key in c:
            ax.axhline(c[key][0], color="0.6", ls=":", label="effective attachment")
    ax1.set_xlabel(f"(d_{sf.label('v')},alpha), mode amplitude")
    ax1.set_ylabel("z' above the rudder top (m)" if sf.is_rudder
                   else "z' along the stock from the plane's root (m)")
    ax1.set_title(f"Figure 8: bending, l = {a.stock_lengths.get('bending_m', float('nan')):.3f} m",
                  y=1.0)
    ax1.legend()
    ax2.plot(c["gamma"], c["z_stock_m"], "o-")
    ax2.set_xlabel(f"{sf.label('gamma')}, mode amplitude per m")
    ax2.legend()
    ax2.set_title(f"Figure 9: torsion, l_T = {a.stock_lengths.get('torsion_m', float('nan')):.3f} m",
                  y=1.0)
    return fig
