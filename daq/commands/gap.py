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
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ...analysis.gap.datamodel import P_CHANCE
from ...analysis.gap.diagnose import Diagnosis, Settings, diagnose
from ...analysis.gap.rigfit import model_level as rig_to_modes
from ...analysis.gap.sensors import DataChecks, check_trial
from ...analysis.gap.trialdata import ScaledCounts, TrialData, prepare
from ...analysis.model.rig import Gage, Rig, RigError
from ...drivers.block import StreamInfo
from ...drivers.mcap_replay import McapReplayDevice
from ..recording import BlockwiseOfflineTrigger, Recording, force_row, rig_of, rig_or_fail
from ..trigger import ImpactEvent, Trigger


@dataclass
class LoadedTrial:
    """A recording's gages, kept as the converter's counts: ``data`` (n_gages, n) in the rig's
    channel order (a :class:`~ramdaq.analysis.gap.trialdata.ScaledCounts`, or an array in m/s^2
    when the recording came read already), ``fs_hz``, trigger ``onsets_s``, the (possibly
    reduced) ``rig``, ``rails`` (low, high) per row in m/s^2 when the converter's bits are known,
    and the trigger's events. :attr:`x` is the whole trial in m/s^2, made when asked for."""

    rig: Rig
    data: ScaledCounts | np.ndarray
    fs_hz: float
    onsets_s: np.ndarray
    rails: tuple[np.ndarray, np.ndarray] | None
    events: list
    source: str

    @property
    def x(self) -> np.ndarray:
        """The whole trial, float64 (n_gages, n) m/s^2, NaN in gaps: built anew from the counts
        at each call (8 bytes a sample: hold it only while it is used)."""
        return self.data.full() if isinstance(self.data, ScaledCounts) else self.data


def load_trial(src: str | Path | Recording, rig: Rig | str | Path | None = None,
               progress: Callable[[str], None] | None = None) -> LoadedTrial:
    """Read a recording (or take one read), find its impacts, and line its channels up with the
    rig's gages. A file is read block by block (the trigger run over them as
    :func:`~ramdaq.daq.recording.read_recording` does) keeping only the gages' counts."""
    say = progress or (lambda s: None)
    path = src.path if isinstance(src, Recording) else src
    with McapReplayDevice(path) as dev:  # the summary only: refuse too few gages before reading
        _gages_present(path, dev.info, rig_of(path, dev.info, rig))
    if isinstance(src, Recording) and rig is None:
        rec = src
        info, rig = rec.info, rig_or_fail(rec)
        have = _gages_present(path, info, rig)
        rows = {g: i for i, g in enumerate(info.gages) if g}
        data = rec.gage_values([g.number for g in have])
        scale = rec.scale[[rows[g.number] for g in have]]
        first, impacts = rec.first_sample, list(rec.impacts)
    else:
        info, rig, have, data, scale, first, impacts = _read_gages(path, rig)
    n = data.shape[1]
    if n == 0:
        raise ValueError(f"{path}: the recording holds no samples")
    if len(have) < len(rig.gages):
        rig = replace(rig, gages=tuple(replace(g, channel=k) for k, g in enumerate(have)))
    bits = info.extra.get("adc_bits")
    rails = None
    if bits:
        rails = (-(2.0 ** (bits - 1)) * scale, (2.0 ** (bits - 1) - 1) * scale)
    onsets = np.array([ev.onset_s for ev in impacts]) - first / info.fs_hz
    say(f"{path}: {n / info.fs_hz:.1f} s of {len(have)} gages at {info.fs_hz:g} Hz, "
        f"{len(onsets)} impacts found")
    return LoadedTrial(rig, data, info.fs_hz, onsets, rails, impacts, str(path))


SMALL = np.iinfo(np.int16)
"""Counts that fit are kept as int16 (a 16-bit converter's always do)."""


def _read_gages(path: str | Path, rig: Rig | str | Path | None):
    """The recording read block by block: (stream info, rig, the rig's gages present, their
    samples as :class:`ScaledCounts` -- or m/s^2 if a block changes a gage's scale --, the first
    block's scale of those gages (SI per count), the stream index of column 0, the trigger's
    impacts). Only the gages' counts are kept, as
    int16 when every count fits."""
    with McapReplayDevice(path) as dev:
        info = dev.info
        the_rig = rig_of(path, info, rig)
        have = _gages_present(path, info, the_rig)
        row = {g: i for i, g in enumerate(info.gages) if g}
        rows = [row[g.number] for g in have]
        live = Trigger(info)  # armed as read_recording arms it: offline, on the record
        trig = BlockwiseOfflineTrigger(live, force_row(path, live.force_channel))
        impacts: list[ImpactEvent] = []
        parts: list[tuple[int, np.ndarray]] = []
        scale, same_scale, lo, hi = None, True, 0, 0
        for b in dev:
            impacts += trig.process(b)
            c = b.counts[rows]
            if scale is None:
                scale = b.scale[rows].copy()
            elif not np.array_equal(b.scale[rows], scale):
                same_scale = False
            if c.size:
                c_lo, c_hi = int(c.min()), int(c.max())
                lo, hi = min(lo, c_lo), max(hi, c_hi)
                if SMALL.min <= c_lo and c_hi <= SMALL.max:
                    c = c.astype(np.int16)
            parts.append((b.first_sample, c if same_scale else b.values()[rows]))
        impacts += trig.flush()
    if not parts:
        return info, the_rig, have, np.empty((len(have), 0)), np.full(len(have), np.nan), 0, impacts
    data = _joined(parts, same_scale, scale, lo, hi)
    return info, the_rig, have, data, scale, parts[0][0], impacts


def _joined(parts: list[tuple[int, np.ndarray | None]], same_scale: bool, scale: np.ndarray, lo: int,
            hi: int) -> ScaledCounts | np.ndarray:
    """The blocks' samples side by side at their stream index (as
    :func:`~ramdaq.daq.recording.read_recording` joins them), each block freed once copied."""
    first = parts[0][0]
    n = parts[-1][0] + parts[-1][1].shape[1] - first
    spans = [(f0 - first, f0 - first + c.shape[1]) for f0, c in parts]
    if not same_scale:    # a block changed a gage's scale: values in m/s^2
        x = np.full((len(scale), n), np.nan)
        for i, (f0, c) in enumerate(parts):
            x[:, f0 - first:f0 - first + c.shape[1]] = c if c.dtype.kind == "f" else c * scale[:, None]
            parts[i] = (f0, None)   # freed: a view would keep the block alive
        return x
    dtype = np.int16 if SMALL.min <= lo and hi <= SMALL.max else np.int32
    counts = np.zeros((len(scale), n), dtype=dtype)
    for i, (f0, c) in enumerate(parts):
        a = f0 - first
        counts[:, a:a + c.shape[1]] = c
        parts[i] = (f0, c[:, :0])
    missing, end = [], 0
    for a, b in sorted(spans):      # the columns no block covers
        if a > end:
            missing.append((end, a))
        end = max(end, b)
    return ScaledCounts(counts, scale, np.array(missing, dtype=np.int64).reshape(-1, 2))


def _gages_present(path: str | Path, info: StreamInfo, rig: Rig | None) -> list[Gage]:
    """The rig's gages the recording has, in the rig's channel order; three or more."""
    if rig is None:
        raise RigError(f"{path}: the recording carries no rig; pass one (--rig, rig=)")
    rig.require_structure("the gap diagnosis (a model of the structure); pass --rig")
    rows = {g for g in info.gages if g}
    have = [g for g in rig.gages_by_channel() if g.number in rows]
    if len(have) < 3:
        raise RigError(f"{path}: only {len(have)} of the rig's gages are in the recording "
                       f"(gages {sorted(rows)}); the gap diagnosis needs three or more")
    return have


def trial_data(lt: LoadedTrial, *, pre_s: float = 1.0, post_max_s: float = 4.0,
               held_out_every: int = 3) -> TrialData:
    return prepare(lt.data, lt.fs_hz, lt.onsets_s, lt.rig, pre_s=pre_s, post_max_s=post_max_s,
                   held_out_every=held_out_every, rails=lt.rails)


FORM_MIN_CLOSURE = 0.5
"""When the rig calibrated to the trial's modes still misses some of them (a model-form error),
an effect is named only if it closes at least half of the held-out impacts' gap: an effect that
closes less is fitting the model's form (a crude rig's detuned mode), not a cause in the trial."""


def run_gap(path: str | Path, *, rig: str | Path | None = None, settings: Settings | None = None,
            progress: Callable[[str], None] | None = None, data_checks: bool = True,
            model_level: bool = True, **prep) -> tuple[LoadedTrial, TrialData, Diagnosis]:
    """Diagnose a recording. With ``model_level`` the rig is first calibrated to the trial's
    identified modes (:func:`~ramdaq.analysis.gap.rigfit.model_level`) and the effect search
    runs on what that leaves; the diagnosis carries the model's form error. With
    ``data_checks`` the data-only layer (:func:`data_only`) runs too and its findings join the
    diagnosis."""
    say = progress or (lambda s: None)
    lt = load_trial(path, rig, progress)
    td = trial_data(lt, **prep)
    level = None
    settings = settings or Settings()
    if model_level:
        say(f"model level: identifying the modes of {td.n_seg} impacts, calibrating the rig to them")
        level = rig_to_modes(td)
        if level.fit is not None:
            lt = replace(lt, rig=level.fit.rig)
            td = trial_data(lt, **prep)
            if level.fit.form:
                settings = replace(settings, min_closure=max(settings.min_closure, FORM_MIN_CLOSURE))
        say(level.statement())
    data, note = data_only(lt, td, prep.get("pre_s", 1.0), progress) if data_checks else (None, None)
    d = diagnose(td, settings, progress)
    d.model_level, d.data = level, data
    if note:
        d.notes.append(note)
    if level is not None and d.best is not None and level.absorbs(d.best.location["gages"]):
        d.notes.append(f"{d.best.name} at gages {', '.join(map(str, d.best.location['gages']))} would "
                       "close the gap, but the rig calibrated to the trial's modes still misses them "
                       "there: not separable from the model's form error, not named")
        d.verdict, d.best = "unexplained", None
    return lt, td, d


def data_only(lt: LoadedTrial, td: TrialData, pre_s: float = 1.0,
              progress: Callable[[str], None] | None = None) -> tuple[DataChecks | None, str | None]:
    """The data-only checks (:func:`ramdaq.analysis.gap.sensors.check_trial`) of the recording at
    its own rate, on the impacts the diagnosis compares, with the pre-trigger window ``pre_s``
    (s); (None, why) when the trial leaves them nothing to read (too short a decay between
    blows)."""
    (progress or (lambda s: None))("data-only checks (free modal model, sensors, blows, ambient)")
    try:
        return check_trial(lt.x, lt.fs_hz, td.onsets_s, lt.rig.gages_by_channel(), pre_s=pre_s), None
    except (ValueError, np.linalg.LinAlgError) as exc:
        return None, f"data-only checks not run: {exc}"


def _pct(v: float) -> str:
    return "n/a" if not np.isfinite(v) else f"{100 * v:.0f} %"


def summary_lines(d: Diagnosis) -> list[str]:
    """A trial engineer's one-minute read of a diagnosis."""
    td = d.forward.td
    out = [f"gap diagnosis of {td.n_seg} impacts ({int(td.fitted.sum())} fitted, "
           f"{int((~td.fitted).sum())} held out), {td.n_gages} gages, compared up to "
           f"{td.lowpass_hz:.0f} Hz at {td.fs_hz:.0f} Hz, in {d.seconds:.1f} s",
           f"verdict: {_headline(d)}"]
    zf = float(np.max(d.map_fit.z))
    held = (f", {float(np.max(d.map_held.z)):.1f} held out; the largest the held-out impacts reproduce "
            f"z = {d.z_detect:.1f}" if d.map_held else "")
    out.append(f"  largest map cell z = {zf:.1f} on the fitted impacts{held}")
    out += data_lines(d)
    cal = ", ".join(f"{p.name} x{math.exp(t):.3f}"
                    for p, t in zip(d.forward.params, d.base.theta, strict=True)
                    if abs(t) > 0.01)
    out.append(f"  calibration moved: {cal or 'nothing beyond 1 %'}")
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
            ps = ", ".join(f"{n} = {v['value']:.4g} {v['unit']}" for n, v in t.to_json()["params"].items())
            if ps:
                out.append(f"    {t.effect.name}: {ps}")
        out.append(f"  where: gages {', '.join(map(str, loc['gages'])) or '-'}; band {loc['band']}; "
                   f"window {loc['window']}")
        lo, hi = b.closed_held_ci
        out.append(f"  gap closed: {_pct(b.closed_fit)} on fitted impacts, {_pct(b.closed_held)} on "
                   f"held-out (95 % {_pct(lo)} .. {_pct(hi)}); dBIC {b.dbic:.0f}")
    elif d.verdict == "unexplained":
        out.append("  no candidate in the library explains it (none beats the calibrated model "
                   "by the BIC margin and shrinks the held-out gap)")
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
    for f in dc.findings:
        out.append(f"    [{f.layer}] {f.text} ({f.window} window; statistic {f.statistic:.4g} > "
                   f"{f.chance_level:.3g})")
    return out

def _headline(d: Diagnosis) -> str:
    """The verdict in capitals, the model level's statement as it is (gage numbers, Hz)."""
    verdict, _, form = d.headline.partition("; ")
    return verdict.upper() + (f"; {form}" if form else "")


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


def write_report(d: Diagnosis, out: Path, *, plots: bool = True, source: str = "") -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    doc = d.to_json() | {"source": source}
    files = [out / "gap.json"]
    files[0].write_text(json.dumps(doc, indent=1))
    if plots:
        from ..reports.gap_plots import plot_diagnosis
        files += plot_diagnosis(d, out)
    return files
