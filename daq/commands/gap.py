"""``ramdaq gap``: a recorded trial held against its rig's model -- where the gap lies, which
unmodelled effect causes it, how far adding it closes the gap on held-out impacts.

The recording (ramdaq's own or an imported one) is read whole
(:func:`ramdaq.daq.recording.read_recording`) through the same trigger as ``ramdaq analyze``
(a six-impact, 16-channel trial at 2 kHz is ~15 MB), gaps as NaN, and handed with the trigger's onsets to
:func:`ramdaq.analysis.gap.diagnose.diagnose`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ...analysis.gap.datamodel import CERTAIN, P_CHANCE, Finding, Layer
from ...analysis.gap.diagnose import Diagnosis, Settings
from ...analysis.gap.evidence import GAP_CELL_Z
from ...analysis.gap.rigfit import PINNED_SD
from ...analysis.gap.trialdata import TrialData
from ..analyzer import finite_json
from ..gap_layers import diagnose_trial
from ..gap_trial import LoadedTrial, load_trial
from ..heap import map_large_blocks, release_free_memory


def run_gap(path: str | Path, *, rig: str | Path | None = None, settings: Settings | None = None,
            progress: Callable[[str], None] | None = None, data_checks: bool = True,
            model_level: bool = True, **prep) -> tuple[LoadedTrial, TrialData, Diagnosis]:
    """Read a recording (:func:`~ramdaq.daq.gap_trial.load_trial`) and diagnose it
    (:func:`~ramdaq.daq.gap_layers.diagnose_trial`, every layer unless turned off). The trial
    returned holds no counts (``data`` None): they are let go before the effect search."""
    map_large_blocks()      # arrays of MBs freed go back to the OS at once (daq/heap.py)
    say = trimming(progress)
    return diagnose_trial(load_trial(path, rig, say), settings=settings, progress=say,
                          data_checks=data_checks, model_level=model_level, keep_counts=False, **prep)


NO_EFFECTS = "none"
"""``ramdaq gap --effects none``: no candidate effect of the library is scored or refitted; the
diagnosis is the data-only checks, the model level (the rig calibrated to the trial's modes and
its form error) and the map of what the calibrated rig leaves (``gap-benchmark --effects none``
is another thing: the generators' trials made without an effect)."""


def parse_effects(text: str | None) -> tuple[str, ...] | None:
    """``--effects``: comma-separated candidate effects as a tuple (None: every registered one;
    ``()`` for :data:`NO_EFFECTS`). Raises KeyError naming an unknown effect and the known
    ones, ValueError when ``none`` is given with effects."""
    from ...analysis.gap.effects import get_effect

    if not text or not text.strip():
        return None
    names = tuple(e.strip() for e in text.split(",") if e.strip())
    if NO_EFFECTS in (n.lower() for n in names):
        if len(names) > 1:
            raise ValueError(f"--effects {text!r}: '{NO_EFFECTS}' (no candidate effect) cannot be "
                             "given with effects")
        return ()
    for e in names:
        get_effect(e)
    return names


def trimming(progress: Callable[[str], None] | None) -> Callable[[str], None]:
    """``progress`` that first hands the C heap's free pages back to the OS
    (:func:`~ramdaq.daq.heap.release_free_memory`, milliseconds): the diagnosis says what it
    does next at the start of each of its phases (reading, model level, data-only checks,
    calibration, scoring, each refit), so what one phase freed below the heap's top -- blocks
    under the mmap threshold, freed out of order -- is not carried as resident into the next
    phase's peak (the 10-minute, 20-blow trial: 525 -> 509 MB max RSS)."""
    def say(msg: str) -> None:
        release_free_memory()
        if progress is not None:
            progress(msg)
    return say


def _pct(v: float) -> str:
    return "n/a" if not np.isfinite(v) else f"{100 * v:.0f} %"


def band_lines(td) -> list[str]:
    """What rings above the compared band (the data's own spectra), which the diagnosis does not
    compare: said, never cut silently; the three strongest lines."""
    if not td.ringing_above:
        return []
    more = len(td.ringing_above) - 3
    return [f"  not compared, ringing above the {td.lowpass_hz:.0f} Hz band: "
            + "; ".join(r.text() for r in td.ringing_above[:3]) + (f"; and {more} more" if more > 0 else "")]


def summary_lines(d: Diagnosis) -> list[str]:
    """A trial engineer's one-minute read of a diagnosis."""
    td = d.forward.td
    out = [f"gap diagnosis of {td.n_seg} impacts ({int(td.fitted.sum())} fitted, "
           f"{int((~td.fitted).sum())} held out), {td.n_gages} gages, compared up to "
           f"{td.lowpass_hz:.0f} Hz (analysed at {td.fs_hz:.0f} samples/s), in {d.seconds:.1f} s",
           *verdict_lines(d)]
    out += band_lines(td)
    out += rig_check_lines(d)
    out += answer_lines(d)
    zf = float(np.max(d.map_fit.z))
    out.append(f"  largest map cell z = {zf:.1f} on the fitted impacts{held_text(d)}")
    out += data_lines(d)
    out += model_level_lines(d)
    cal = ", ".join(f"{p.name} x{math.exp(t):.3f}"
                    for p, t in zip(d.forward.params, d.base.theta, strict=True)
                    if abs(t) > 0.01)
    then = "then, to the fitted impacts' time histories, " if d.model_level is not None else ""
    out.append(f"  {then}calibration moved: {cal or 'nothing beyond 1 %'}")
    if d.best:
        b = d.best
        loc = b.location
        where = ", ".join(f"{k} {v}" for k, v in (b.terms[0].to_json()["where"] or {}).items())
        out.append(f"  cause: {' + '.join(t.effect.label for t in b.terms)}"
                   + (f" ({where})" if where else ""))
        out += [f"    set aside: {p.text()}" for p in d.precedence]
        out += [f"    not confirmed: the data-only {c} check finds nothing beyond chance"
                for c in d.unconfirmed]
        for t in b.terms:
            ps = ", ".join(f"{n} = {v['value']:.4g}" + (f" {v['unit']}" if v["unit"] not in ("", "1") else "")
                           for n, v in t.to_json()["params"].items())  # a ratio has no unit to print
            if ps:
                out.append(f"    {t.effect.name}: {ps}")
        out.append(f"  where: gages {', '.join(map(str, loc['gages'])) or '-'}; band {loc['band']}; "
                   f"window {loc['window']}")
        lo, hi = b.closed_held_ci
        out.append(f"  gap closed: {_pct(b.closed_fit)} on fitted impacts, {_pct(b.closed_held)} on "
                   f"held-out (95 % {_pct(lo)} .. {_pct(hi)}); dBIC {b.dbic:.0f}")
    elif d.verdict == "unexplained" and d.signatures:
        out.append("  no candidate in the library explains it (none beats the calibrated model "
                   "by the BIC margin and shrinks the held-out gap)")
    if not d.signatures:
        out.append("  no candidate effect scored (--effects none): the gap is what the calibrated "
                   "rig leaves, read with the data-only checks and the model form")
    else:
        out.append("  ranking (signature z, then refit dBIC; negative is better):")
    refit = {c.name: c for c in d.candidates}
    for s in d.signatures[:6]:
        c = refit.get(s.effect.name)
        z = f"{s.z:6.1f}" if np.isfinite(s.z) else "     -"
        tail = f"  dBIC {c.dbic:9.1f}  closes {_pct(c.closed_held)} held out" if c else ""
        out.append(f"    {s.effect.name:17s} z {z}{tail}")
    pairs = [c for c in d.candidates if len(c.terms) == 2]
    for c in pairs:
        out.append(f"    {c.name:17s} (pair) dBIC {c.dbic:9.1f}  closes {_pct(c.closed_held)} held out")
    out += feature_lines(d)
    if d.modes_before:
        ms = "; ".join(f"{m['f_hz']:.3f} Hz delta {m['delta']:.4f}" for m in d.modes_before)
        out.append(f"  calibrated modes: {ms}")
    if d.best and d.best.modes_after:
        ms = "; ".join(f"{m['f_hz']:.3f} Hz delta {m['delta']:.4f}" for m in d.best.modes_after)
        out.append(f"  with {d.best.name}:    {ms}")
    out += [f"  note: {n}" for n in d.notes]
    return out


def held_text(d: Diagnosis) -> str:
    """The held-out impacts' part of the map line: their largest cell, and the largest cell of
    the fitted impacts' map that they reproduce (:attr:`Diagnosis.z_detect`, what the verdict
    holds against ``z_gap``) -- in words when there is none: no held-out cell is beyond
    :data:`~ramdaq.analysis.gap.evidence.GAP_CELL_Z` (the score is then -inf, never printed)."""
    if not d.map_held:
        return ""
    s = f", {float(np.max(d.map_held.z)):.1f} held out; "
    if np.isfinite(d.z_detect):
        return s + f"the largest the held-out impacts reproduce z = {d.z_detect:.1f}"
    return (s + f"no cell reproduces on the held-out impacts (none of theirs beyond z {GAP_CELL_Z:g}): "
            "nothing there to call a gap")


def rig_check_lines(d: Diagnosis) -> list[str]:
    """One line when the rig's rudder mass is far from what the trial's modes imply
    (:class:`~ramdaq.analysis.gap.rigfit.MassScale`): a unit or value error of the rig file,
    which no bound of the calibration reaches; none otherwise. Indented as the verdict's other
    lines (``rig fit`` prints it unindented, among its unindented lines)."""
    ml = d.model_level
    scale = None if ml is None or ml.fit is None else ml.fit.scale
    return [] if scale is None else [f"  {line}" for line in scale.check_lines()]  # as its neighbours


def model_level_lines(d: Diagnosis) -> list[str]:
    """What the model level did to the rig: the rig held against the trial, and each constant
    the trial's modes pin that moved by more than 1 % or ended at a bound (factor and posterior
    sd), and the ones held because the modes do not pin them. A user whose rig file was 20 %
    off saw only the second calibration's moves, which start from the corrected rig."""
    ml = d.model_level
    if ml is None:
        return []
    rig = d.forward.td.rig
    head = f"  model level: rig {rig.name!r} ({rig.medium})"
    if ml.fit is None:
        return [f"{head}: not calibrated ({ml.note})"]
    moved = [p for p in ml.fit.params if p.pinned and (abs(math.log(p.factor)) > 0.01 or p.at_bound)]
    held = [p.name for p in ml.fit.params if not p.pinned]
    text = ", ".join(f"{p.name} x{p.factor:.3f}"
                     + (f" +-{100 * p.sd:.1f} %" if math.isfinite(p.sd) else "")
                     + (" (loose)" if p.loose else "")
                     + (" AT ITS BOUND" if p.at_bound else "") for p in moved)
    out = [f"{head} calibrated to the trial's modes ({ml.fit.outcome()}): "
           f"{text or 'no constant moved beyond 1 %'}"]
    if any(p.loose for p in moved):
        out.append(f"    loose: fitted, but the modes leave it beyond +-{100 * PINNED_SD:.0f} % (1 sd)")
    if held:
        out.append(f"    held at the rig's values (the modes do not pin them): {', '.join(held)}")
    return out


def answer_lines(d: Diagnosis) -> list[str]:
    """Why the answer is not the model layer's own choice, when it is not."""
    a, model = d.answer, d.model_choice()
    if a is None or a.named == (model or "none"):
        return []
    alone = f"named {model}" if model and model != "unexplained" else ("found the gap unexplained"
                                                                       if model else "saw no gap")
    if a.by == "data":
        why = "the data-only finding takes precedence (it rests on the recorded values alone)"
    elif a.named in ("none", "unexplained"):
        why = ("it lies only where the rig calibrated to the trial's modes still misses them: not "
               "separable from the model's form error")
    else:
        why = (f"the trial's identified modes show {a.named} (against the rig calibrated to them), "
               "each a test against its own chance level")
    return [f"  the model layer alone {alone}; {why}"]


def data_lines(d: Diagnosis) -> list[str]:
    """The data-only section: what the recording says without the rig's stiffness or mass model,
    each finding with its layer, where, and its statistic against its chance level."""
    if d.data is None:
        return []
    dc = d.data
    modes = ", ".join(f"{f:.2f}" for f, s in zip(dc.modal.f_hz, dc.modal.steady, strict=True) if not s)
    out = [f"  data-only (no stiffness or mass model; free modes {modes or '-'} Hz; each check's "
           f"chance level is what a trial without the fault passes with probability {P_CHANCE:g}):"]
    if not dc.findings:
        return out + ["    nothing beyond chance (" + ", ".join(dc.looked) + ")"]
    return out + [finding_line(f) for f in dc.findings]


def finding_line(f: Finding) -> str:
    """One data-only finding: its layer, text, window, and its statistic against its chance
    level -- beyond it (``>``), or ``within`` it where the finding is that a law did not stand
    out (a model-form reading); with how much of its check's residual it closes on held-out
    impacts, where measured."""
    closes = (f"; closes {_pct(f.closed_held)} of its check's residual on held-out impacts "
              f"(95 % {_pct(f.closed_held_ci[0])} .. {_pct(f.closed_held_ci[1])})"
              if np.isfinite(f.closed_held) else "")
    beyond = ">" if f.statistic > f.chance_level else "within"
    stat = (f"statistic {f.statistic:.4g} {beyond} {f.chance_level:.3g}" if np.isfinite(f.statistic)
            else CERTAIN)
    return f"    [{f.layer}] {f.text} ({f.window} window; {stat}{closes})"

VERDICT_WIDTH = 120
"""The verdict's first line is at most about this long: the answer; what it rests on follows."""


def verdict_lines(d: Diagnosis) -> list[str]:
    """The verdict: a short first line, the answer (its words in capitals up to the first colon
    or parenthesis; what follows -- gage numbers, Hz, an effect's name -- as it is); the
    answer's finding on the next line when the first would be longer than
    :data:`VERDICT_WIDTH`; then the model form (:func:`form_lines`). The same words as
    :attr:`Diagnosis.headline` (gap.json's ``headline``), each said once."""
    head = verdict_head(d)
    cut = min((i for i in (head.find(":"), head.find(" (")) if i >= 0), default=len(head))
    head = head[:cut].upper() + head[cut:]
    out = [f"verdict: {head}"]
    if len(out[0]) > VERDICT_WIDTH:
        at = [i for i in (head.find(" -- "), head.find(" (", cut)) if i >= 0]
        if at:
            i = min(at)
            detail = head[i:].removeprefix(" -- ").strip()
            if detail.startswith("(") and detail.endswith(")"):
                detail = detail[1:-1]
            out = [f"verdict: {head[:i]}", f"  finding: {detail}"]
    return out + form_lines(d)


def verdict_head(d: Diagnosis) -> str:
    """The answer as the verdict line says it: :attr:`Diagnosis.headline` without the model
    level's statement (which :func:`form_lines` prints on its own lines)."""
    head = d.headline
    if d.model_level is not None:  # the headline is the answer, "; ", the model level's statement
        head = head.removesuffix("; " + d.model_level.statement(d.answer and d.answer.named))
    return head


def answer_verdict(d: Diagnosis) -> str:
    """gap.json's ``verdict``: the answer the terminal's verdict line gives (both layers:
    "explained by the data-only layer: gage_alignment", "no effect", "unexplained: gages ...",
    "explained"), without the finding and its statistic that follow it (``headline`` has
    them). The effect search's map alone says "no gap beyond noise", "explained" or
    "unexplained": that is ``map_verdict``."""
    head = verdict_head(d)
    cut = min((i for i in (head.find(" -- "), head.find(" (")) if i >= 0), default=len(head))
    return head[:cut].strip()


def form_lines(d: Diagnosis) -> list[str]:
    """The model level's statement (:meth:`~ramdaq.analysis.gap.rigfit.ModelLevel.statement`),
    one line per form error: what the rig calibrated to the trial's modes still misses (with
    the named effect's update on it when one was made), or why it was not calibrated. How the
    calibration ended is the model level's line (:func:`model_level_lines`), not repeated."""
    ml = d.model_level
    if ml is None:
        return []
    if ml.fit is None:
        return [f"  model form: not assessed ({ml.note})"]
    named = d.answer and d.answer.named
    if named in ml.updates:
        head, items = f"model form with {named}'s update on the rig", [e.text() for e in ml.updates[named]]
    else:
        head, items = "model form", [f.text() for f in ml.fit.form] + [m.text() for m in ml.fit.damping]
    if not items:
        data_form = [f for f in (d.data.findings if d.data is not None else ())
                     if f.layer == Layer.MODEL_FORM]
        if data_form:  # the modes agree, the gages' kinematics or shapes do not: say both
            gages = sorted({g for f in data_form for g in f.gages})
            return [f"  {head}: none in the modes beyond the identification's uncertainty; the "
                    f"data-only layer finds form error at gage{'s' if len(gages) > 1 else ''} "
                    f"{', '.join(map(str, gages))} (below)"]
        return [f"  {head}: none beyond the identification's uncertainty"]
    return [f"  {head}:"] + [f"    {t}" for t in items]


def feature_lines(d: Diagnosis, n: int = 5) -> list[str]:
    """The gap in physical terms: the strongest discrepancies of the calibrated model beyond
    the map's own chance level, and how far the named effect brings each feature back."""
    fm = d.features
    if fm is None:
        return []
    level = fm.list_level
    # one line per finding: the same feature of the same mode (or line) and window on several
    # gages is one discrepancy seen several times
    groups: dict[tuple, list[dict]] = {}
    for r in fm.strongest(10 * n):
        key = (r["feature"], r.get("band") or round(r["mode_hz"], 1), r["window"])
        groups.setdefault(key, []).append(r)
    rows = list(groups.values())[:n]
    head = (f"  in physical terms (read in {d.features_seconds:.1f} s; z against the replicate "
            f"simulations; listed beyond z {level:.1f}, which a trial of the calibrated model reaches "
            "anywhere on the map at most 1 time in 20)")
    if not rows:
        return [head + ": nothing stands out"]
    out = [head + ":"]
    if d.verdict == "no gap beyond noise":
        out.append("    (read finer than the verdict, which rests on the energy map and is set so that "
                   "trials with no unmodelled effect alarm at most 5 % of the time: what follows is the "
                   "model's own form error)")
    for g in rows:
        also = [str(r["gage"]) for r in g[1:] if r["gage"] is not None]
        out.append(f"    {g[0]['text']}" + (f"; also gages {', '.join(also)}" if also else ""))
    if d.best is not None and d.best.features is not None:
        before, after = fm.worst_by_feature(), d.best.features.worst_by_feature()
        moved = [k for k, v in before.items() if np.isfinite(v) and v > level]
        out.append(f"    with {d.best.name}, the largest z of each: " + ", ".join(
            f"{k} {before[k]:.1f} -> {after[k]:.1f}" for k in moved))
    return out


def write_report(d: Diagnosis, out: Path, *, plots: bool = True, source: str = "",
                 rig: dict | None = None) -> list[Path]:
    """gap.json (and the plots) in ``out``; ``source`` the recording, ``rig`` the rig it was held
    against (:func:`rig_record`)."""
    out.mkdir(parents=True, exist_ok=True)
    doc = d.to_json()
    # the answer the terminal prints, not the map's alone (which was "no gap beyond noise" beside
    # a printed "EXPLAINED BY THE DATA-ONLY LAYER"); the map's keeps its own key, next to it
    doc = {"verdict": answer_verdict(d), "map_verdict": doc.pop("verdict")} | doc | {
        "source": source, "rig": rig}
    files = [out / "gap.json"]
    files[0].write_text(json.dumps(finite_json(doc), indent=1, allow_nan=False))  # NaN: null
    if plots:
        from ..reports.gap_plots import plot_diagnosis
        files += plot_diagnosis(d, out)
    return files


def earlier_report(out: Path, overwrite: bool) -> list[Path]:
    """The files an earlier ``ramdaq gap`` left in ``out`` (gap.json, gap_*.png), checked before
    the minutes of a diagnosis: FileExistsError naming the folder and ``--overwrite`` when there
    are any and ``overwrite`` is not set (as ``ramdaq trial`` refuses an existing recording).
    NotADirectoryError when ``out`` is a file."""
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(20, "is not a folder; --out takes the folder gap.json goes in", str(out))
    found = sorted([*out.glob("gap.json"), *out.glob("gap_*.png")]) if out.is_dir() else []
    if found and not overwrite:
        raise FileExistsError(f"{out}/ holds an earlier gap diagnosis ({found[0].name}"
                              + (f" and {len(found) - 1} more" if len(found) > 1 else "")
                              + "); --overwrite replaces it")
    return found


def remove_stale(earlier: list[Path], written: list[Path]) -> list[Path]:
    """Delete the earlier run's files this run did not write again (its plots after a
    ``--no-plots`` run), so that the folder holds one diagnosis; returns them, for the line
    that says so."""
    kept = set(written)
    stale = [p for p in earlier if p not in kept and p.exists()]
    for p in stale:
        p.unlink()
    return stale


def rig_record(lt: LoadedTrial, given: str | Path | None) -> dict:
    """The rig a diagnosis was held against, for gap.json: its name, medium and where it came
    from (the file given with ``--rig``, or the one the recording carries)."""
    return {"name": lt.rig.name, "medium": lt.rig.medium,
            "from": str(given) if given else "the recording's own rig"}
