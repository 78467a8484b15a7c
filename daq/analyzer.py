"""From a detected impact to its numbers, and from all of a trial's impacts to its summary.

The same functions serve ``ramdaq analyze`` (offline, a recording replayed through the trigger)
and the live trial: one implementation, so live and replay cannot drift apart. A live trial's
analyzer thread takes typed jobs (:class:`FinalJob`, :class:`LookJob`) and gives back typed
results (:class:`FinalDone`, :class:`LookDone`) through :func:`run_job`.

A final run while the analyzer is behind may be *coarse* (:class:`Coarse`: its free decay cut
short and decimated, :mod:`ramdaq.daq.jobqueue` says when), as is a live final from a stream far
above the design rate (decimated, nothing cut); the hit's result says so.

Each hit is accepted or rejected with a reason: a blow the trigger saw but could not place
(still arming, or its onset at a gap), a double hit, an overload (clipped channels), a decay too
short to measure, an analysis that found no usable decay, or one that failed. The trial summary
gives, per gage and per motion, the mean decrement over accepted hits with its scatter --
Report 1836's Table 2b "percent deviation from average", done automatically -- and, when the
stream's health is known, its gaps and the time the trigger was blind.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..analysis.impact import FirstLook, ImpactAnalysis, NoSuchMode, analyze_decay, first_look
from ..analysis.model.rig import Rig
from ..analysis.onset import contact_duration_s
from ..drivers.block import StreamInfo
from .trigger import NO_BLOW, ImpactEvent, StreamHealth

MIN_DECAY_S = 0.25
"""Shortest free decay analysed, s: fewer than a few periods of a 13 Hz mode is no decrement."""
NOT_ANALYSABLE = "blow seen but not analysable"
"""How the reason of a hit the trigger saw but could not place begins."""


@dataclass(frozen=True)
class HitResult:
    """One hit: its trigger event, whether it counts, why not, and its analysis if any;
    ``coarse`` says how the analysis was made coarser than the record allowed ("" if not)."""

    index: int
    event: ImpactEvent
    accepted: bool
    reason: str
    analysis: ImpactAnalysis | None
    coarse: str = ""


@dataclass(frozen=True)
class Coarse:
    """How a final is made cheaper when the analyzer is behind: its free decay cut to the first
    ``decay_s`` s (of ``full_decay_s`` s recorded) and decimated by the largest whole factor
    that keeps the rate at or above ``rate_hz`` (Hz); ``why`` says how far behind it was."""

    decay_s: float
    full_decay_s: float
    rate_hz: float
    why: str


@dataclass(frozen=True)
class FinalJob:
    """Judge and analyse hit ``index`` from its complete record (``event.record``), coarsely
    if ``coarse`` is given."""

    index: int
    event: ImpactEvent
    coarse: Coarse | None = None


@dataclass(frozen=True, eq=False)
class LookJob:
    """A first look at a decay still ringing: ``x`` the gage rows from the decay's start to the
    latest sample (SI units, shape (n_gages, n_samples)) of the impact whose onset is sample
    ``onset_sample`` of the stream; ``pre`` the same rows before the blow (None if not held);
    ``n_modes`` the order to fit where it is known (None: searched, as a final does)."""

    onset_sample: int
    x: np.ndarray
    pre: np.ndarray | None = None
    n_modes: int | None = None


@dataclass(frozen=True)
class FinalDone:
    """A final job's result: the hit judged, analysed if accepted, and its JSON record
    (:func:`hit_to_json`), made on the analyzer thread so that nothing about one hit's numbers
    can stop the acquisition."""

    hit: HitResult
    doc: dict


@dataclass(frozen=True)
class LookDone:
    """A first look's result (``None`` if the decay so far gave no usable numbers)."""

    onset_sample: int
    look: FirstLook | None


def run_job(job: FinalJob | LookJob, info: StreamInfo, rig: Rig,
            gages: tuple[int, ...]) -> FinalDone | LookDone:
    """Do one analyzer job; ``gages`` are the report gage numbers of ``LookJob.x``'s rows."""
    if isinstance(job, FinalJob):
        hit = judge_event(job.index, job.event, info, rig, job.coarse)
        try:
            return FinalDone(hit, hit_to_json(hit))
        except Exception as err:  # noqa: BLE001 -- a hit whose numbers cannot be written is rejected, not lost
            hit = HitResult(hit.index, hit.event, False,
                            f"analysis failed: {type(err).__name__}: {err}", None, hit.coarse)
            return FinalDone(hit, hit_to_json(hit))
    try:
        look = first_look(job.x, info.fs_hz, rig, gages, pre=job.pre, n_modes=job.n_modes)
    except ValueError:
        look = None
    return LookDone(job.onset_sample, look)


DEFAULT_CONTACT_S = 0.005
"""A blow's contact, s, where neither a force channel nor the rig's ``[impact]`` says it: a
hammer's or a light ram's (the rigs' rams last 5 ms)."""


def decay_skip_s(rig: Rig, force: np.ndarray | None = None, fs_hz: float | None = None) -> float:
    """Time after the onset before the free decay is taken, s: the blow's contact plus 10 ms for
    the anti-alias filter to settle. The contact is measured on ``force`` (N from the onset,
    shape (n,), at ``fs_hz``) where the stream has a force channel, else twice the rig's nominal
    ram duration (for a ram that dwells), else twice :data:`DEFAULT_CONTACT_S`."""
    if force is not None and fs_hz:
        contact = contact_duration_s(force, fs_hz)
        if np.isfinite(contact):
            return contact + 0.010
    nominal = rig.impact.duration_s if rig.impact is not None else DEFAULT_CONTACT_S
    return 2 * nominal + 0.010


def _force_from_onset(event: ImpactEvent, info: StreamInfo) -> np.ndarray | None:
    """The first force channel's samples from the onset on (N), or None without one."""
    rows = [i for i, u in enumerate(info.units) if u == "N"]
    rec = event.record
    if not rows or rec is None:
        return None
    i0 = max(0, event.onset_sample - rec.first_sample)
    return rec.counts[rows[0], i0:] * rec.scale[rows[0]]


def coarsen(x: np.ndarray, fs_hz: float, coarse: Coarse,
            scale: np.ndarray | None = None) -> tuple[np.ndarray, float, str]:
    """The free decay ``x`` (n_gages, n_samples) cut to ``coarse.decay_s`` and decimated (FIR
    anti-alias filter, zero phase) by ``floor(fs_hz / coarse.rate_hz)``: the samples, their
    rate (Hz), and a sentence saying what was done and why. With ``scale`` (n_gages,), ``x``
    is counts and each row is multiplied by its scale first. Row by row: at most one row is
    held at the full rate in float64 (a whole 30 s, 16-gage decay at 25.6 kHz is 98 MB)."""
    from scipy import signal  # only a coarse final decimates

    keep = min(x.shape[1], round(coarse.decay_s * fs_hz))
    q = max(1, int(fs_hz // coarse.rate_hz))
    scale = np.ones(x.shape[0]) if scale is None else scale
    rows = [x[i, :keep] * scale[i] for i in range(x.shape[0])] if q == 1 else [
        signal.decimate(x[i, :keep] * scale[i], q, ftype="fir", zero_phase=True)
        for i in range(x.shape[0])]
    y = np.stack(rows)
    text = (f"coarse: {keep / fs_hz:.2f} s of the {coarse.full_decay_s:.2f} s decay"
            + (f", decimated {q}x to {fs_hz / q:g} Hz" if q > 1 else "") + f" ({coarse.why})")
    return y, fs_hz / q, text


def analyze_event(index: int, event: ImpactEvent, info: StreamInfo, rig: Rig,
                  coarse: Coarse | None = None, mode_hz: float | None = None) -> HitResult:
    """Judge and analyse one trigger event that carries its record; with ``coarse``, on the
    shorter, decimated decay it describes (:func:`coarsen`); with ``mode_hz``, the chain on the
    mode nearest it (:func:`~ramdaq.analysis.impact.chosen_mode`)."""
    if event.not_analysable:
        said = event.not_analysable
        return HitResult(index, event, False,
                         said if said.startswith(NO_BLOW) else f"{NOT_ANALYSABLE}: {said}", None)
    if event.double_hit:
        return HitResult(index, event, False, f"double hit: second contact at "
                         f"{event.second_onset_s:.3f} s", None)
    if event.clipped:
        return HitResult(index, event, False, f"overload: clipped on {', '.join(event.clipped)}",
                         None)
    rec = event.record
    if rec is None:
        return HitResult(index, event, False, "no record kept for this event", None)
    start = event.onset_sample + round(decay_skip_s(rig, _force_from_onset(event, info),
                                                    info.fs_hz) * info.fs_hz)
    i0 = start - rec.first_sample
    n = rec.counts[:1, i0:].shape[1]  # decay samples (a view: nothing copied)
    # The trigger's too_short only says the record was cut (next blow, gap, end of stream)
    # before the ringing died; what counts here is whether enough decay remains to measure.
    if n < MIN_DECAY_S * info.fs_hz:
        return HitResult(index, event, False,
                         f"decay too short: {n / info.fs_hz:.2f} s "
                         f"(< {MIN_DECAY_S} s, ended by {event.end_reason})", None)
    gage_rows = [i for i, g in enumerate(info.gages) if g]
    scale = rec.scale[gage_rows]
    # the gage rows as a view where they are contiguous (no copy of the counts before scaling)
    lo, hi = (gage_rows[0], gage_rows[-1] + 1) if gage_rows else (0, 0)
    counts = (rec.counts[lo:hi, i0:] if gage_rows == list(range(lo, hi))
              else rec.counts[gage_rows, i0:])
    if coarse is None:
        x, fs, text = counts * scale[:, None], info.fs_hz, ""
    else:  # no full-rate copy at all
        x, fs, text = coarsen(counts, info.fs_hz, coarse, scale)
    pre = rec.counts[gage_rows, :max(event.onset_sample - rec.first_sample, 0)] * scale[:, None]
    try:
        result = analyze_decay(x, fs, rig, tuple(info.gages[i] for i in gage_rows),
                               onset_s=event.onset_s, decay_start_s=start / info.fs_hz,
                               adc_full_scale=_full_scale(info, scale), pre=pre,
                               pre_fs_hz=info.fs_hz, mode_hz=mode_hz)
    except ValueError as err:  # NoSuchMode: the decay is fine, the mode asked for is not in it
        why = str(err) if isinstance(err, NoSuchMode) else f"no usable decay: {err}"
        return HitResult(index, event, False, why, None, text)
    if event.end_reason == "gap":  # the record, not the ringing, ended: say where and why
        result = replace(result, notes=(*result.notes, (
            f"decay cut by a gap in the stream at {(event.last_sample + 1) / info.fs_hz:.3f} s: "
            f"{n / info.fs_hz:.2f} s of it analysed")))
    return HitResult(index, event, True, "", result, text)


def judge_event(index: int, event: ImpactEvent, info: StreamInfo, rig: Rig,
                coarse: Coarse | None = None, mode_hz: float | None = None) -> HitResult:
    """:func:`analyze_event`; if the analysis raises, the hit is rejected as "analysis failed:
    <exception>": a blow the trigger saw never vanishes from the trial."""
    try:
        return analyze_event(index, event, info, rig, coarse, mode_hz)
    except Exception as err:  # any failure is this hit's verdict, not the end of the trial
        return HitResult(index, event, False,
                         f"analysis failed: {type(err).__name__}: {err}", None,
                         "" if coarse is None else f"coarse ({coarse.why})")


def _full_scale(info: StreamInfo, scale: np.ndarray) -> float | None:
    bits = info.extra.get("adc_bits")
    if not bits:
        return None
    return float(np.min(np.abs(scale)) * (2 ** (bits - 1) - 1))


UNSURE_REL_SE = 0.25
"""A gage's first-look decrement whose standard error is more than this fraction of itself is
marked "unsure" (a gage at the noise level); the session shows a look only when the median gage
is within it (``session.LOOK_REL_SE``), and a trial summary row whose hits are
mostly above it is marked."""


def is_sure(delta: float, delta_se: float) -> bool:
    """A decrement worth showing as a gage's number so far: a decay (``delta`` > 0) whose
    standard error is within :data:`UNSURE_REL_SE` of it (False for a NaN error)."""
    return bool(delta > 0 and delta_se / delta <= UNSURE_REL_SE)


def _mean_scatter(values: list[float], se: list[float] | None = None) -> dict:
    """Mean, scatter (std) and count of the finite ``values``, each one's deviation from the
    mean (%); with their standard errors ``se``, ``rel_se``: each one's error relative to it
    (those finite), and ``p_agree``: the chance that hits measuring one number scatter as much
    (chi-square of the values about their weighted mean, over n - 1 degrees of freedom), None
    where fewer than two values have one."""
    pairs = [(x, e) for x, e in zip(values, se or [math.nan] * len(values), strict=True)
             if np.isfinite(x)]
    v = np.array([x for x, _ in pairs])
    if v.size == 0:
        return {"mean": None, "std": None, "n": 0, "deviation_pct": [], "rel_se": [], "p_agree": None}
    mean = float(v.mean())
    se_v = np.array([e for _, e in pairs])
    rel = [float(e / abs(x)) for x, e in pairs if math.isfinite(e) and x != 0]
    return {"mean": mean, "std": float(v.std(ddof=1)) if v.size > 1 else None, "n": int(v.size),
            "deviation_pct": [float(100 * (x / mean - 1)) for x in v], "rel_se": rel,
            "p_agree": _p_agree(v, se_v)}


def _p_agree(v: np.ndarray, se: np.ndarray) -> float | None:
    """Chance of a chi-square about the weighted mean as large as ``v``'s with errors ``se``."""
    ok = np.isfinite(se) & (se > 0)
    if ok.sum() < 2:
        return None
    from scipy.special import chdtrc

    w = 1 / se[ok] ** 2
    mean = float(np.sum(w * v[ok]) / np.sum(w))
    return float(chdtrc(int(ok.sum()) - 1, float(np.sum(w * (v[ok] - mean) ** 2))))


@dataclass(frozen=True)
class AnalyzerLoad:
    """What a live trial's analyzer did and left undone: first looks shown and skipped (the
    analyzer had other work, or a final pushed them out of the queue), finals run coarse and
    finals not analysed at all (the queue was at its bound); the most the queue held (jobs
    waiting or running: bytes of samples, and finals) against its bounds."""

    looks_shown: int
    looks_skipped: int
    finals_coarse: int
    finals_unanalysed: int
    peak_bytes: int
    peak_finals: int
    max_bytes: int
    max_finals: int

    def to_json(self) -> dict:
        return {"looks_shown": self.looks_shown, "looks_skipped": self.looks_skipped,
                "finals_coarse": self.finals_coarse, "finals_unanalysed": self.finals_unanalysed,
                "peak_MB": self.peak_bytes / 1e6, "peak_finals": self.peak_finals,
                "max_MB": self.max_bytes / 1e6, "max_finals": self.max_finals}


CUT_ENDS = {"gap": "a gap in the stream", "flush": "the stream's end"}
"""Ends of a record that cut a hit's decay by accident. A record cut by the next blow is the
trial's design (the blows come faster than the ringing dies) and is said in each hit's line."""


def cut_short(h: HitResult) -> str:
    """Why an analysed hit's decay is shorter than the trigger's record would have been: its
    record cut by a gap or the stream's end (seconds of record after the onset, and which);
    '' if it was not."""
    ev = h.event
    if not ev.too_short or ev.end_reason not in CUT_ENDS:
        return ""
    return (f"{(ev.last_sample + 1 - ev.onset_sample) / ev.fs_hz:.1f} s after the blow, cut by "
            f"{CUT_ENDS[ev.end_reason]}")


def trial_summary(hits: list[HitResult], stream: StreamHealth | None = None,
                  load: AnalyzerLoad | None = None) -> dict:
    """Per gage and per motion: mean decrement over accepted hits, its standard deviation and
    each hit's percent deviation from the mean; the predominant frequency likewise. How many
    blows were seen but not analysable, and, given the trigger's ``stream`` health, its gaps,
    missing, blind and arming time (s); given the analyzer's ``load``, the work it skipped or
    made coarse, and which hits were coarse; the accepted hits whose record a gap or the stream's
    end cut short (:func:`cut_short`), which the means include."""
    ok = [h.analysis for h in hits if h.accepted and h.analysis is not None]
    gages = sorted({n for a in ok for n in a.gages})
    motions = sorted({m for a in ok for m in a.motions})
    return {
        "hits": len(hits), "accepted": len(ok),
        "rejected": {h.index: h.reason for h in hits if not h.accepted},
        "not_analysable": sum(h.event.not_analysable is not None for h in hits),
        "stream": None if stream is None else stream.to_json(),
        "analyzer": None if load is None else load.to_json(),
        "coarse": {h.index: h.coarse for h in hits if h.coarse},
        "cut_short": {h.index: why for h in hits if h.accepted and (why := cut_short(h))},
        "f_hz": _mean_scatter([a.f_hz for a in ok]),
        "delta_gage": {f"g{n:02d}": _mean_scatter([a.gages[n].delta for a in ok if n in a.gages],
                                                  [a.gages[n].delta_se for a in ok if n in a.gages])
                       for n in gages},
        "delta_motion": {m: _mean_scatter([a.motions[m].delta for a in ok if m in a.motions],
                                          [a.motions[m].delta_se for a in ok if m in a.motions])
                         for m in motions},
        "delta_modal": _mean_scatter([a.damping["delta_modal"] for a in ok]),
        "delta_hull_motion": {m: _mean_scatter([a.hull_motions[m].delta for a in ok
                                                if m in a.hull_motions],
                                               [a.hull_motions[m].delta_se for a in ok
                                                if m in a.hull_motions])
                              for m in sorted({m for a in ok for m in a.hull_motions})},
        "C_N_s_per_m": _mean_scatter([a.damping["C_N_s_per_m"] for a in ok]),
        "c_N_m_s_per_rad": _mean_scatter([a.damping["c_N_m_s_per_rad"] for a in ok]),
        "gages_not_used": gages_not_used(ok),
    }


def gages_not_used(ok: list) -> dict[str, str]:
    """The gages no accepted hit took (``g15`` -> the first hit's verdict on it, in words), so a
    summary without them says why: a stock gage that saw no free decay, a dead channel."""
    used = {n for a in ok for n in a.gages}
    out: dict[str, str] = {}
    for a in ok:
        for n in a.gage_numbers:
            if n not in used and f"g{n:02d}" not in out:
                v = a.verdicts[n]
                out[f"g{n:02d}"] = f"{v.code}: {v.reason}" if v.reason else str(v.code)
    return dict(sorted(out.items()))


def finite_json(obj: object) -> object:
    """``obj`` (dicts, lists, tuples, numbers, strings) with every number a plain Python one and
    every NaN or infinity ``None``, so that the JSON written is valid (``allow_nan=False``)."""
    kind = type(obj)  # the plain types first (most of the ~700 values of a hit), no isinstance
    if kind is float:
        return obj if math.isfinite(obj) else None
    if kind is str or kind is int or obj is None:
        return obj
    if isinstance(obj, dict):
        return {k: finite_json(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite_json(v) for v in obj]
    if isinstance(obj, bool | np.bool_ | int | np.integer):
        return bool(obj) if isinstance(obj, bool | np.bool_) else int(obj)
    if isinstance(obj, float | np.floating):  # numpy's, and float subclasses
        return float(obj) if math.isfinite(obj) else None
    return obj


def analysis_to_json(a: ImpactAnalysis) -> dict:
    """Every number of one impact, SI, with standard errors (a number the analysis could not
    give is ``None``)."""
    m = a.modes
    return {
        "onset_s": a.onset_s, "decay_start_s": a.decay_start_s, "decay_duration_s": a.duration_s,
        "record_samples": a.record_samples, "analysed_samples": a.analysed_samples,
        "predominant_mode": a.predominant, "chosen_mode": a.chosen, "mode_hz_asked": a.mode_hz,
        "f_hz": a.f_hz,
        "modes": [{"f_hz": finite_json(m.frequency_hz[i]), "f_se_hz": finite_json(m.frequency_se_hz[i]),
                   "delta": finite_json(m.delta[i]), "delta_se": finite_json(m.delta_se[i]),
                   "zeta": finite_json(m.zeta[i]), "zeta_se": finite_json(m.zeta_se[i]),
                   "shape": {f"g{n:02d}": [finite_json(float(abs(s))), finite_json(float(np.angle(s)))]
                             for n, s in zip(a.active_gages, m.mode_shape[:, i], strict=True)}}
                  for i in range(len(m))],
        "verdicts": {f"g{n:02d}": v.to_json() for n, v in a.verdicts.items()},
        "gages": {f"g{n:02d}": d.to_json() for n, d in sorted(a.gages.items())},
        "motions": {k: d.to_json() for k, d in a.motions.items()},
        "relative_to_hull": {k: d.to_json() for k, d in a.relative.items()},
        "hull_motions": {k: d.to_json() for k, d in a.hull_motions.items()},
        "alpha1_over_gamma1": finite_json(a.alpha1_over_gamma1),
        "damping": a.damping.to_json(),
        "stock_lengths_m": a.stock_lengths,
        "table2b": finite_json(a.table2b()),
        "hull_table": finite_json(a.hull_table()),
        "notes": list(a.notes),
        "skipped": [s.to_json() for s in a.skipped],
    }


def hit_to_json(hit: HitResult) -> dict:
    """One hit as the results topic, ``replay --json`` and the live trial write it."""
    return finite_json({"index": hit.index, "onset_sample": hit.event.onset_sample,
                        "onset_s": hit.event.onset_s, "accepted": hit.accepted, "reason": hit.reason,
                        "coarse": hit.coarse or None,
                        "analysis": analysis_to_json(hit.analysis) if hit.analysis else None})
