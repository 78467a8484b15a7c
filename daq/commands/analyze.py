"""``ramdaq analyze``: a recording replayed through the trigger and the analyzer into a trial
report -- a JSON document of every number with units and standard errors, PNG plots, and a
summary table for the terminal.

The recording is read (:func:`ramdaq.daq.recording.read_recording`), block by block, through the
same :class:`~ramdaq.daq.trigger.Trigger` and :func:`~ramdaq.daq.analyzer.judge_event` as a live
trial (:func:`ramdaq.daq.api.analyze_hits`).
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Callable, Collection
from functools import partial
from pathlib import Path

import numpy as np

from ...analysis.impact import mode_tag
from ...analysis.model.geometry import gage_geometry
from ...analysis.model.rig import Rig
from ...analysis.model.structure import added_mass
from ...analysis.model.surface import Surface
from ...analysis.model.units import from_si
from ..analyzer import UNSURE_REL_SE, HitResult, analysis_to_json, finite_json, trial_summary
from ..trigger import NO_BLOW

MODEL_MOTIONS = ("v", "gamma", "alpha")
"""The model's motion names; ``report.json``'s ``surface.motions`` gives what the rig calls each
(a stern plane's w, beta, alpha), and every key of its analyses uses those names."""

UNITS = {"f_hz": "Hz", "delta": "1", "C": "N s/m", "c": "N m s/rad", "length": "m",
         "mass": "kg", "inertia": "kg m^2", "time": "s"}


def run_analysis(path: str | Path, *, impact: int | None = None,
                 progress: Callable[[str], None] | None = None,
                 bars: bool | None = False, mode_hz: float | None = None) -> tuple[Rig, list[HitResult]]:
    """Read ``path`` through the trigger and analyse each hit (or only hit ``impact``); with
    ``bars`` (``None``: when standard error is a terminal) a progress bar over the reading and
    one over the hits. ``mode_hz`` (``--mode-hz``): the report's chain on the mode nearest it
    in each hit instead of the most energetic one; ValueError, in one line, when it is
    within the resolution of no identified mode in any hit (a hit where only it fails is
    rejected with the reason)."""
    # here, not with the module: ramdaq replay imports this module for its summary only
    from ..api import analyze_hits
    from ..recording import read_recording, rig_or_fail
    from .progress import bytes_bar, progress_bar

    if mode_hz is not None and not (math.isfinite(mode_hz) and mode_hz > 0):
        raise ValueError(f"--mode-hz {mode_hz:g}: a frequency in Hz above 0")
    name = Path(path).name
    with bytes_bar(f"reading {name}", Path(path).stat().st_size, show=bars) as update:
        rec = read_recording(path, progress=update)
    rig = rig_or_fail(rec)
    n = len(rec.impacts) if impact is None else 1
    with progress_bar(f"analysing {name}", n, unit="hits", show=bars if n > 1 else False) as advance:
        hits = analyze_hits(rec, impact=impact, progress=progress, done=lambda h: advance(),
                            mode_hz=mode_hz)
    if mode_hz is None:
        return rig, hits
    key = f"mode_hz {mode_hz:g}: "
    missed = [h for h in hits if not h.accepted and key in (h.reason or "")]
    if missed and not any(h.accepted for h in hits):
        raise ValueError(f"--mode-hz {mode_hz:g}: in no hit of {name}: "
                         + (missed[0].reason or "").split(key, 1)[1])
    return rig, hits


def virtual_inertias(rig: Rig, f_air_hz: float | None = None,
                     f_water_hz: float | None = None) -> dict:
    """Eq 19-21 from the rig's geometry; Eq 18 when both trials' frequencies are given. A rig
    without water damping (a surface tested in air only, as the report's stern planes) has none:
    the dict holds only ``not_computed``, the reason."""
    if "water" not in rig.damping:
        return {"not_computed": f"rig {rig.name} has no [damping.water]: tested in air only, "
                                "so no virtual inertias (as Report 1836 for its stern planes)"}
    add = added_mass(rig.with_medium("water"))
    out = {"m_vir_eq19_kg": add["m_vir"], "Iz_vir_eq20_kg_m2": add["Iz_vir"],
           "Ix_vir_eq21_kg_m2": add["Ix_vir"]}
    if f_air_hz and f_water_hz:
        eq18 = rig.rudder.mass_kg * ((f_air_hz / f_water_hz) ** 2 - 1)
        out |= {"m_vir_eq18_kg": eq18, "f_air_hz": f_air_hz, "f_water_hz": f_water_hz,
                "eq18_vs_eq19_pct": 100 * (eq18 / add["m_vir"] - 1)}
    return out


def _earlier_plots(out: Path) -> list[Path]:
    """The PNGs ``write_analysis`` writes (``impact{k}_{kind}.png``, ``frf.png``) already in
    ``out``."""
    return sorted(p for p in out.glob("*.png") if p.name == "frf.png"
                  or re.fullmatch(r"impact\d+_[a-z]+\.png", p.name))


def check_air_twin(rig: Rig, air_rig: Rig, air_path: str | Path) -> None:
    """Eq 18 needs the same surface in air and in water: ValueError naming what does not fit
    when ``rig`` (the analysed trial's) is not in water, ``air_rig`` (``--air``'s) not in air,
    or they are not the same rig."""
    if rig.medium != "water":
        raise ValueError(f"--air {air_path}: the analysed trial is in {rig.medium}, and Eq 18 "
                         f"wants a water trial with its in-air twin")
    if air_rig.medium != "air":
        raise ValueError(f"--air {air_path}: that trial is in {air_rig.medium}, not air")
    if air_rig.name != rig.name:
        raise ValueError(f"--air {air_path}: its rig is {air_rig.name!r}, not the water trial's "
                         f"{rig.name!r}; Eq 18 compares one surface in air and in water")


def recorded_channels(path: str | Path) -> tuple[str, ...]:
    """The recording's channel names, row by row (its stream's, which an import may give fewer
    of than its rig declares)."""
    from ...drivers.mcap_replay import McapReplayDevice

    with McapReplayDevice(path) as dev:
        return dev.info.channels


def build_report(path: str | Path, rig: Rig, hits: list[HitResult],
                 air: tuple[Rig, list[HitResult]] | None = None) -> dict:
    """The trial report as a JSON-serialisable dict (every NaN or infinity written as ``None``)."""
    from ..reports.frf_report import frf_section  # (not imported by ramdaq replay)

    summary = trial_summary(hits)
    f_other = trial_summary(air[1])["f_hz"]["mean"] if air else None
    f_here = summary["f_hz"]["mean"]
    vi = None
    if rig.structural:
        vi = virtual_inertias(rig, f_other, f_here) if air and rig.medium == "water" else \
            virtual_inertias(rig)
    surface = rig.surface
    return finite_json({
        "recording": str(path), "rig": rig.name, "medium": rig.medium,
        "surface": {"kind": surface.kind, "motions": {m: surface.label(m) for m in MODEL_MOTIONS}},
        "geometry_m": gage_geometry(rig).__dict__ if rig.structural else None,
        "skipped": _skipped(rig, hits),
        "units": UNITS,
        "impacts": [{"index": h.index, "onset_s": h.event.onset_s, "accepted": h.accepted,
                     "reason": h.reason, "flags": {"double_hit": h.event.double_hit,
                                                   "clipped": list(h.event.clipped),
                                                   "too_short": h.event.too_short},
                     "snr_db": finite_json(h.event.snr_db),
                     "analysis": _in_words(surface, analysis_to_json(h.analysis)) if h.analysis
                     else None}
                    for h in hits],
        "summary": surface.relabel(summary),
        "virtual_inertias": vi,
        "rig_agreement": _rig_agreement(rig, f_here),
        # driving-point H1 where the rig has a force channel; rows as recorded
        "frf": frf_section(rig, hits, recorded_channels(path)) if rig.forces else None,
    })


def _rig_agreement(rig: Rig, f_hz: float | None) -> dict | None:
    """The record's mean predominant frequency (Hz) against the rig model's modes
    (:func:`~ramdaq.analysis.model.rig_modes.rig_agreement`), None for a channels-only rig or
    no accepted hit."""
    from ...analysis.model.rig_modes import rig_agreement

    if not rig.structural or f_hz is None or not np.isfinite(f_hz) or f_hz <= 0:
        return None
    a = rig_agreement(rig, f_hz)
    return {"medium": a.medium, "f_record_hz": a.f_record_hz, "nearest_model_hz": a.nearest_hz,
            "predominant_model_hz": a.predominant_hz, "ratio": a.ratio, "agrees": a.agrees,
            "warning": a.warning()}


def _in_words(surface: Surface, analysis: dict) -> dict:
    """One hit's analysis (:func:`analysis_to_json`) with its keys and notes named as the rig's
    surface names them."""
    out = surface.relabel(analysis)
    out["notes"] = [surface.words(n) for n in analysis["notes"]]
    return out


def _skipped(rig: Rig, hits: list[HitResult]) -> list[dict]:
    """The chain's steps skipped on any accepted hit, once each (the rig's layout decides them,
    so every hit skips the same), as ``{"step", "reason"}``; the rig and Eq 18-21 likewise."""
    seen: dict[str, str] = {}
    for h in hits:
        if h.analysis is not None:
            seen |= {s.step: s.reason for s in h.analysis.skipped}
    if not rig.structural:
        seen["virtual inertias (Eq 18-21)"] = f"rig {rig.name!r} describes no structure"
    return [{"step": k, "reason": v} for k, v in seen.items()]


HITS_AGREE_P = 1e-3
"""A summary row whose hits scatter more than their standard errors allow at this chance (a
mode fitted at different frequencies in different hits, a gage that changed) is marked."""


def format_summary(report: dict, units: str = "si") -> str:
    """A readable table: each hit, then per gage and motion the mean decrement and scatter."""
    kind = report.get("surface", {}).get("kind", "rudder").replace("_", " ") \
        if report.get("geometry_m") else "channels only"
    lines = [f"{report['recording']}: rig {report['rig']} ({kind}) in {report['medium']}"]
    for imp in report["impacts"]:
        a = imp["analysis"]
        if a:
            tag = partial(mode_tag, predominant=a["predominant_mode"], chosen=a.get("chosen_mode"),
                          mode_hz=a.get("mode_hz_asked"))
            asked = "" if a.get("chosen_mode") is None else tag(a["chosen_mode"])
            lines.append(f"  hit {imp['index']} at {imp['onset_s']:8.3f} s  accepted   "
                         f"f = {a['f_hz']:.3f} Hz{asked}  delta_modal = {_fmt(a['damping']['delta_modal'])}")
            lines += [f"    {g}: f = {_fmt(d['f_hz'], '.4f')} +- {_fmt(d['f_se_hz'], '.2g')} Hz, "
                      f"delta = {_fmt(d['delta'])} +- {_fmt(d['delta_se'], '.2g')}, zeta = "
                      f"{_fmt(d['zeta'], '.4%')} +- {_pct(d['zeta_se'])}"
                      for g, d in a["gages"].items()]
            if len(a["modes"]) > 1:  # the gage rows are the chain's mode's: list every mode
                lines += [f"    mode {i}{tag(i)}"
                          f", all gages: f = {_fmt(m['f_hz'], '.4f')} +- {_fmt(m['f_se_hz'], '.2g')}"
                          f" Hz, delta = {_fmt(m['delta'])} +- {_fmt(m['delta_se'], '.2g')}, zeta = "
                          f"{_fmt(m['zeta'], '.4%')} +- {_pct(m['zeta_se'])}"
                          for i, m in enumerate(a["modes"])]
            lines += [f"    note: {n}" for n in a.get("notes", ())]
        elif imp["reason"] == "not requested":  # --impact named another hit
            lines.append(f"  hit {imp['index']} at {imp['onset_s']:8.3f} s  not analysed "
                         f"(not requested)")
        else:
            lines.append(f"  hit {imp['index']} at {imp['onset_s']:8.3f} s  REJECTED   "
                         f"{imp['reason']}")
    lines += summary_table(report["summary"], units)
    lines += motions_not_used(report["impacts"], report["summary"])
    for s in report.get("skipped", []):
        lines.append(f"skipped: {s['step']}: {s['reason']}")
    agree = report.get("rig_agreement") or {}
    if agree.get("warning"):
        lines.append(f"WARNING {agree['warning']}")
    vi = report["virtual_inertias"]
    if vi is None:
        return "\n".join(lines)
    surface = Surface(kind=report.get("surface", {}).get("kind", "rudder"))
    conv = (lambda v, q: from_si(v, q)) if units == "report" else (lambda v, q: v)
    mu, iu = ("ton s^2/ft", "ft ton s^2") if units == "report" else ("kg", "kg m^2")
    if "not_computed" in vi:
        lines.append(f"\nvirtual inertias: {vi['not_computed']}")
        return "\n".join(lines)
    lines.append(surface.label(
        f"\nthe rig's added mass (from its geometry, not measured): virtual mass, Eq 19: "
        f"{conv(vi['m_vir_eq19_kg'], 'mass'):.4g} {mu}; "
        f"(I_z)_vir, Eq 20: {conv(vi['Iz_vir_eq20_kg_m2'], 'inertia'):.4g} {iu}; "
        f"(I_x)_vir, Eq 21 (reconstructed): {conv(vi['Ix_vir_eq21_kg_m2'], 'inertia'):.4g} {iu}"))
    if "m_vir_eq18_kg" in vi:
        lines.append(f"virtual mass, Eq 18 (air {vi['f_air_hz']:.3f} Hz, water "
                     f"{vi['f_water_hz']:.3f} Hz): {conv(vi['m_vir_eq18_kg'], 'mass'):.4g} {mu},"
                     f" {vi['eq18_vs_eq19_pct']:+.1f} % against Eq 19")
    return "\n".join(lines)


HULL_MOTION_GAGES = {"alpha_b": (13, 14), "v_b": (13, 14), "gamma_b": (5, 13)}
"""The gages each hull motion is computed from (the analysis' hull motions: alpha_b by Eq 8 from
13 and 14, v_b at the stock's attachment from 13 and alpha_b, gamma_b from 5 and 13);
:data:`~ramdaq.analysis.impact.MOTION_GAGES` gives the rudder motions'."""


def motions_not_used(impacts: list[dict], summary: dict) -> list[str]:
    """For each motion the summary averages over fewer than all accepted hits (tester8:
    ``delta_alpha_b`` with n = 1 of 5 and no word why): the hits it was not taken from, each
    with the hit's own note on that motion (no decrement of the mode, its fit failed, a gage
    unusable) or that the hit records none, and the verdicts of the gages it rests on.
    ``impacts``: the per-hit results as written (``report.json``'s, ``--json``'s);
    ``summary``: the trial summary with the hits' own motion names."""
    from ...analysis.impact import MOTION_GAGES

    ok = [i for i in impacts if i.get("accepted") and i.get("analysis")]
    hull = summary.get("delta_hull_motion") or summary.get("delta_fixed_portion_motion") or {}
    out = []
    for key, rows, rests in (("motions", summary.get("delta_motion") or {}, MOTION_GAGES),
                             ("hull_motions", hull, HULL_MOTION_GAGES)):
        for m, d in rows.items():
            if d.get("n", 0) >= len(ok) or not any(m in (i["analysis"].get(key) or {}) or _note_on(i, m)
                                                   for i in ok):
                continue
            why: dict[str, list[str]] = {}   # the same reason in several hits: said once
            for i in ok:
                if ((i["analysis"].get(key) or {}).get(m) or {}).get("delta") is None:
                    why.setdefault(_why_not(i, key, m, rests.get(m, ())), []).append(str(i["index"]))
            out.append(f"  delta_{m}: n = {d.get('n', 0)} of {len(ok)} accepted hits; not from "
                       + "; ".join(f"hit{'s' if len(h) > 1 else ''} {', '.join(h)}: {w}"
                                   for w, h in why.items()))
    return out


def _note_on(imp: dict, m: str) -> str | None:
    """The hit's note on motion ``m`` (what follows ``m: ``), or None."""
    return next((n.split(": ", 1)[1] for n in imp["analysis"].get("notes", ()) if n.startswith(f"{m}: ")),
                None)


def _why_not(imp: dict, key: str, m: str, gages: tuple[int, ...]) -> str:
    """Why hit ``imp`` has no decrement of motion ``m``, with its gages' verdicts: each gage's
    own decay (a motion combines its gages, in which a mode may cancel though each rings)."""
    why = _note_on(imp, m) or ("computed, but no decrement recorded and no note why"
                               if m in (imp["analysis"].get(key) or {}) else
                               "not computed from its gages (the hit records no note why)")
    v = imp["analysis"].get("verdicts") or {}
    gv = ", ".join(f"g{g:02d} {v[f'g{g:02d}']['verdict']}" for g in gages if f"g{g:02d}" in v)
    return why + (f" (its gages' own decays: {gv})" if gv else "")


def _fmt(v: float | None, spec: str = ".4f") -> str:
    """A report number as text; ``None`` (not measured) as ``-``."""
    return "-" if v is None else format(v, spec)


def _pct(v: float | None) -> str:
    """A standard error of a ratio in percent to two significant digits (``.2%`` printed a
    0.0025 % one as 0.00 %); ``None`` as ``-``."""
    return "-" if v is None else f"{100 * v:.2g}%"


def _row_marks(d: dict) -> list[str]:
    """What a summary row's mean over hits does not say by itself: hits that differ beyond
    their own standard errors (:data:`HITS_AGREE_P`), and hits each at the noise level (median
    relative error above :data:`~ramdaq.daq.analyzer.UNSURE_REL_SE`, the live readout's
    "unsure")."""
    out = []
    if (d.get("p_agree") or 1.0) < HITS_AGREE_P:
        out.append(f"the hits differ beyond their own standard errors (chance {d['p_agree']:.1e}): "
                   "not one number; see each hit above")
    rel = d.get("rel_se") or []
    if rel and float(np.median(rel)) > UNSURE_REL_SE:
        out.append(f"unsure: each hit's own standard error is {100 * min(rel):.0f}-"
                   f"{100 * max(rel):.0f} % of it (more than {100 * UNSURE_REL_SE:.0f} %: near "
                   "the noise)")
    return out


def summary_table(s: dict, units: str = "si") -> list[str]:
    """Lines of the trial summary: per motion and gage the mean decrement over accepted hits
    with its standard deviation; C and c in SI or, with ``units="report"``, ton/ft units."""
    lines = []
    st = s.get("stream")
    if st:  # what the trigger could not see, before the table so that it is not missed
        lines.append(f"\nstream: {st['gaps']} gap(s), {st['missing_s']:.3f} s missing; the "
                     f"trigger was blind {st['blind_s']:.3f} s and arming {st['arming_s']:.3f} s")
    if s.get("not_analysable"):
        lines.append(f"{s['not_analysable']} onset(s) seen but not analysable (among the rejected)")
    no_blow = sum((r or "").startswith(NO_BLOW) for r in s.get("rejected", {}).values())
    if no_blow:
        lines.append(f"{no_blow} of them no blow: no band of the gages rang more after the onset "
                     "than before (a mode that stops ringing by friction fires the trigger too)")
    arming = sum("trigger still arming" in (r or "") for r in s.get("rejected", {}).values())
    if arming:
        lines.append(f"{arming} blow(s) came before the trigger's long-term average was full: "
                     "not analysable live or in a replay (the trial's own trigger); "
                     "`ramdaq analyze` arms on the whole record and analyses them")
    if not s["hits"]:
        lines.append("no blow found: the trigger never fired (no load cell crossed its level, and "
                     "no gages' short-term power rose above their background on enough gages at "
                     "once; a gage that never rings, dead or on a node, is one of them)")
    skipped = sum(r == "not requested" for r in s.get("rejected", {}).values())
    lines += [f"\n{s['accepted']} of {s['hits'] - skipped} {'requested ' if skipped else ''}hits "
              f"accepted{f' ({skipped} more not analysed)' if skipped else ''}. Mean over "
              f"accepted hits (+- std, n):", "  quantity          mean        std     n"]

    def row(name: str, d: dict, fmt: str = "{:.4f}") -> None:
        if d["mean"] is None:
            return
        std = "-" if d["std"] is None else fmt.format(d["std"])
        lines.append(f"  {name:14s} {fmt.format(d['mean']):>9s} {std:>10s} {d['n']:5d}")
        lines.extend(f"  {'':14s} ^ {mark}" for mark in _row_marks(d))

    row("f (Hz)", s["f_hz"], "{:.3f}")
    for m, d in s["delta_motion"].items():
        row(f"delta_{m}", d)
    row("delta_modal", s["delta_modal"])
    # the hull section's motions (a stern plane's fixed portion's: its summary is relabelled)
    for m, d in (s.get("delta_hull_motion") or s.get("delta_fixed_portion_motion") or {}).items():
        row(f"delta_{m}", d)
    for g, d in s["delta_gage"].items():
        row(f"delta {g}", d)
    for g, why in (s.get("gages_not_used") or {}).items():
        lines.append(f"  {g} not used in any accepted hit: {why}")
    for key, q in (("C_N_s_per_m", "damping_translational"), ("c_N_m_s_per_rad",
                                                               "damping_rotational")):
        d = dict(s[key])
        name = key.split("_")[0]
        if units == "report" and d["mean"] is not None:
            d = {**d, "mean": from_si(d["mean"], q),
                 "std": None if d["std"] is None else from_si(d["std"], q)}
            name += " (ton s/ft)" if key.startswith("C") else " (ft ton s)"
        else:
            name += " (N s/m)" if key.startswith("C") else " (N m s/rad)"
        row(name, d, "{:.4g}")
    if s["C_N_s_per_m"]["mean"] is not None or s["c_N_m_s_per_rad"]["mean"] is not None:
        lines.append("  C, c: Eq 16 and 17, each putting the predominant mode's whole decay on one "
                     "dashpot (the report's reading), not a rig's separate dashpots")
    if s.get("delta_hull_motion"):
        lines.append("  *_b: the hull's own motion at the rudder (gages 5, 13, 14; Eq 8-13)")
    lines += [f"  hit {i} is in these means on a short decay: its record ended {why}"
              for i, why in (s.get("cut_short") or {}).items()]
    return lines


def json_default(o: object) -> object:
    """numpy scalars and arrays as JSON, anything else as its text (``json.dumps(default=)``)."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


DEFAULT_PLOTS = ("decay",)
"""The plots ``ramdaq analyze`` draws unless asked for others (``--plots``): each hit's decay
panels, where every gage's decrement is seen; the spectrum, mode shape and stock figures (each
about as dear to draw as the hit's whole analysis) on request."""


def plot_kinds(spec: str | None, *, off: bool = False) -> bool | tuple[str, ...]:
    """``--plots`` (comma-separated kinds, or ``all``) and ``--no-plots`` as
    :func:`write_analysis`'s ``plots``; an unknown kind is an error naming the known ones."""
    if off:
        return False
    if not spec:
        return True
    from ..reports.impact_plots import PLOT_KINDS

    kinds = PLOT_KINDS if spec.strip() == "all" else tuple(k.strip() for k in spec.split(",")
                                                           if k.strip())
    unknown = [k for k in kinds if k not in PLOT_KINDS]
    if unknown or not kinds:
        raise ValueError(f"--plots {spec!r}: unknown kind(s) {unknown}; known: "
                         f"{', '.join(PLOT_KINDS)} or all")
    return kinds


def _plots_not_drawn(kinds: Collection[str], rig: Rig, hits: list[HitResult]) -> list[dict]:
    """The plot kinds asked for that this rig or these hits cannot give, each with why, as
    report.json's ``skipped`` entries (``--plots all`` on a channels-only import left them out
    without a word)."""
    out = []
    if "modeshape" in kinds and not rig.structural:
        out.append({"step": "modeshape plot",
                    "reason": "a channels-only rig has no gage positions or directions"})
    if "stock" in kinds and not any(h.analysis is not None and h.analysis.stock_curves
                                    for h in hits):
        out.append({"step": "stock plot", "reason": "no accepted hit has the stock's gages "
                    "(Report 1836's Figures 8 and 9 need gages along the stock)"})
    return out


def write_analysis(path: str | Path, rig: Rig, hits: list[HitResult], out: Path, *,
                   plots: bool | Collection[str] = True,
                   air: tuple[Rig, list[HitResult]] | None = None) -> tuple[dict, list[Path]]:
    """The folder ``ramdaq analyze`` writes: ``report.json`` (:func:`build_report`; replaced
    whole, so a run killed while writing leaves the last complete one) and each accepted hit's
    PNGs: ``plots`` True draws :data:`DEFAULT_PLOTS`, False none, else the kinds named
    (:data:`~ramdaq.daq.reports.impact_plots.PLOT_KINDS`). Returns the report and the files
    written."""
    from ..api import decay_samples  # (not imported by ramdaq replay)
    from ..reports.frf_report import plot_frf

    report = build_report(path, rig, hits, air)
    out.mkdir(parents=True, exist_ok=True)
    for old in _earlier_plots(out):  # a report folder holds one run: no plots of an earlier one
        old.unlink()
    kinds = DEFAULT_PLOTS if plots is True else () if plots is False else tuple(plots)
    report.setdefault("skipped", []).extend(_plots_not_drawn(kinds, rig, hits))
    tmp = out / f".report.json.{os.getpid()}"
    tmp.write_text(json.dumps(report, indent=1, default=json_default))
    os.replace(tmp, out / "report.json")
    files = [out / "report.json"]
    if kinds:  # the driving-point FRFs (one figure a trial, none without a force channel) too
        files += plot_frf(report["frf"], out)
        from ..reports.impact_plots import plot_impact

        reuse: dict = {}  # one decay figure redrawn hit after hit (its panels: half its cost)
        for h in hits:
            if h.accepted and h.analysis is not None and h.event.record is not None:
                files += plot_impact(h.analysis, decay_samples(h, rig), h.event.record.fs_hz, rig,
                                     out, h.index, kinds, reuse=reuse)
    return report, files
