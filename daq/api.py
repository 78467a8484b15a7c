"""The Python API of a trial: a recording analysed as ``ramdaq analyze`` does, or held against its
rig's model as ``ramdaq gap`` does, with typed results and tables for a notebook.

::

    import ramdaq
    res = ramdaq.analyze("recordings/albacore-water.mcap")
    res.to_dataframe()          # one row per hit x gage x mode: f, delta, zeta, standard errors, verdict
    figs = res.figures(0)       # matplotlib Figures of hit 0 (decay, spectrum, mode shape, stock)
    gap = ramdaq.diagnose("recordings/sampson-water.mcap")
    gap.to_dataframe()          # one row per candidate explanation, best first

The numbers are those of the command line to the last digit when the process runs with one BLAS
thread (``import ramdaq`` sets ``OPENBLAS_NUM_THREADS=1`` when NumPy is not yet loaded;
:func:`analyze` warns once when it could not).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..analysis.impact import ImpactAnalysis
from ..analysis.model.rig import Rig
from .analyzer import HitResult, judge_event, trial_summary
from .mode_table import ModeEstimate, mode_rows
from .recording import Recording, optional_import, read_recording, rig_or_fail

if TYPE_CHECKING:  # the gap package (and its scipy.ndimage/optimize) only for ramdaq.diagnose
    from ..analysis.gap.diagnose import Diagnosis, Settings
    from ..analysis.gap.layers import Answer

__all__ = ["ModeEstimate", "TrialAnalysis", "Candidate", "TrialDiagnosis", "analyze", "analyze_hits",
           "diagnose", "as_recording"]

Source = str | PathLike | Recording


def as_recording(src: Source, rig: Rig | str | Path | None = None) -> Recording:
    """``src`` itself if it is a :class:`Recording` read with the same rig, else the file read."""
    if isinstance(src, Recording) and rig is None:
        return src
    path = src.path if isinstance(src, Recording) else src
    return read_recording(path, rig=rig)


@dataclass(frozen=True, eq=False)
class TrialAnalysis:
    """A recording's hits judged and analysed (``ramdaq analyze``): ``hits`` in time order, each
    with its trigger event, acceptance and :class:`~ramdaq.analysis.impact.ImpactAnalysis`."""

    recording: Recording
    rig: Rig
    hits: tuple[HitResult, ...]

    @property
    def analyses(self) -> list[ImpactAnalysis]:
        """The accepted hits' analyses."""
        return [h.analysis for h in self.hits if h.accepted and h.analysis is not None]

    def rows(self) -> list[ModeEstimate]:
        """One :class:`ModeEstimate` per hit x gage x mode (a rejected hit: one row); ``mode`` None
        and ``fitted`` False where no mode was fitted, as in ``ramdaq batch analyze``'s table."""
        return [r for h in self.hits for r in mode_rows(h)]

    def to_dataframe(self) -> Any:
        """:meth:`rows` as a ``pandas.DataFrame``, one column per :class:`ModeEstimate` field;
        ``mode`` a nullable integer column (``<NA>`` where none was fitted)."""
        pd = optional_import("pandas")
        df = pd.DataFrame([r.__dict__ for r in self.rows()])
        return df.astype({"mode": "Int64"}) if len(df) else df

    def summary(self) -> dict:
        """The trial summary of ``report.json`` (means and scatter over accepted hits)."""
        return trial_summary(list(self.hits))

    def figures(self, hit: int) -> dict[str, Any]:
        """The plots of accepted hit ``hit`` as matplotlib Figures, by kind (``decay``,
        ``spectrum``, ``modeshape``, ``stock``); the caller shows, saves or closes them."""
        from .reports.impact_plots import impact_figures

        h = self.hits[hit]
        if not h.accepted or h.analysis is None or h.event.record is None:
            raise ValueError(f"{self.recording.path}: hit {hit} was not analysed ({h.reason})")
        return impact_figures(h.analysis, decay_samples(h, self.rig), self.recording.fs_hz, self.rig)


def decay_samples(h: HitResult, rig: Rig) -> np.ndarray:
    """The gage rows of hit ``h``'s record from its decay's start (SI, shape (n_gages, n)); ``rig``
    is the recording's (kept for callers; the analysis knows its gages)."""
    rec, a = h.event.record, h.analysis
    i0 = round(a.decay_start_s * rec.fs_hz) - rec.first_sample
    return rec.values()[:len(a.gage_numbers), i0:]  # the gage rows come first, force channels after


def analyze_hits(rec: Recording, *, impact: int | None = None,
                 progress: Callable[[str], None] | None = None,
                 done: Callable[[HitResult], None] | None = None,
                 mode_hz: float | None = None) -> list[HitResult]:
    """Judge and analyse each of ``rec.impacts`` (or only hit ``impact``, the others marked "not
    requested") as a live trial does; ``progress`` hears of each hit before its analysis,
    ``done`` gets each analysed hit; ``mode_hz``: the mode the report's chain is run on."""
    rig = rig_or_fail(rec)
    if impact is not None and not 0 <= impact < len(rec.impacts):
        raise ValueError(f"{rec.path}: impact {impact} asked for, but {len(rec.impacts)} impacts found"
                         + (f" (numbered 0 to {len(rec.impacts) - 1})" if rec.impacts else ""))
    hits = []
    for k, ev in enumerate(rec.impacts):
        if impact is not None and k != impact:
            hits.append(HitResult(k, ev, False, "not requested", None))
            continue
        if progress:
            cut = f" (cut by a gap in the stream at {(ev.last_sample + 1) / rec.fs_hz:.3f} s)" \
                if ev.end_reason == "gap" else ""
            progress(f"impact {k} at {ev.onset_s:.3f} s: analysing "
                     f"{(ev.last_sample - ev.onset_sample) / rec.fs_hz:.1f} s of decay{cut}")
        hits.append(judge_event(k, ev, rec.info, rig, mode_hz=mode_hz))
        if done:
            done(hits[-1])
    return hits


_BLAS_WARNED: list[bool] = []


def _check_blas_threads() -> None:
    if os.environ.get("OPENBLAS_NUM_THREADS") == "1" or _BLAS_WARNED:
        return
    _BLAS_WARNED.append(True)
    warnings.warn("OPENBLAS_NUM_THREADS is not 1 (NumPy was imported before ramdaq): numbers may "
                  "differ from the ramdaq command's in the last digits and fits run slower; "
                  "set OPENBLAS_NUM_THREADS=1 before starting Python", RuntimeWarning, stacklevel=3)


def analyze(src: Source, *, rig: Rig | str | Path | None = None, impact: int | None = None,
            progress: Callable[[str], None] | None = None) -> TrialAnalysis:
    """Analyse a recording (a path or a :class:`Recording`) as ``ramdaq analyze`` does.

    ``rig`` replaces the recorded rig (a :class:`Rig`, a shipped rig's name or a file);
    ``impact`` analyses that hit only. Raises ``RigError`` when there is no rig, ``ValueError``
    for an impact that is not there, ``RecordingError`` for a file that does not read.
    """
    _check_blas_threads()
    rec = as_recording(src, rig)
    return TrialAnalysis(rec, rig_or_fail(rec), tuple(analyze_hits(rec, impact=impact, progress=progress)))


@dataclass(frozen=True)
class Candidate:
    """One explanation the gap diagnosis tried: ``effect`` (``+`` joins a pair), ``dbic`` its
    evidence against the calibrated model (negative is better), ``gap_fitted`` and
    ``gap_held_out`` the gap it leaves (noise variances), ``closed_fitted`` and
    ``closed_held_out`` the share of the gap it closes (1 = all) with the held-out share's 95 %
    interval ``closed_held_out_lo`` .. ``_hi``; ``named`` when it is the diagnosis's answer."""

    rank: int
    effect: str
    named: bool
    dbic: float
    dbic_marginal: float
    gap_fitted: float
    gap_held_out: float
    closed_fitted: float
    closed_held_out: float
    closed_held_out_lo: float
    closed_held_out_hi: float


@dataclass(frozen=True, eq=False)
class TrialDiagnosis:
    """A recording held against its rig's model (``ramdaq gap``): the full
    :class:`~ramdaq.analysis.gap.diagnose.Diagnosis` and the recording it came from."""

    recording: Recording
    diagnosis: Diagnosis
    trial: Any = field(repr=False)
    """The :class:`~ramdaq.daq.gap_trial.LoadedTrial` the diagnosis read."""

    @property
    def verdict(self) -> str:
        """The model layer's verdict (``explained``, ``unexplained``, ...); :attr:`answer` is
        the report's answer of both layers."""
        return self.diagnosis.verdict

    @property
    def answer(self) -> Answer | None:
        """The one answer of both layers, as ``ramdaq gap`` prints it and the benchmark scores
        it (:func:`~ramdaq.analysis.gap.layers.answer`)."""
        return self.diagnosis.answer

    @property
    def effect(self) -> str | None:
        """The library effect the answer names; ``None`` for no effect or an unexplained gap."""
        a = self.diagnosis.answer
        if a is None:
            return self.diagnosis.best.name if self.diagnosis.best else None
        return None if a.named in ("none", "unexplained") else a.named

    def candidates(self) -> list[Candidate]:
        d = self.diagnosis
        best = d.best.name if d.best else None
        return [Candidate(k, c.name, c.name == best, c.dbic,
                          float("nan") if c.dbic_marginal is None else c.dbic_marginal,
                          c.gap_fit, c.gap_held, c.closed_fit, c.closed_held, *c.closed_held_ci)
                for k, c in enumerate(d.candidates)]

    def to_dataframe(self) -> Any:
        """:meth:`candidates` as a ``pandas.DataFrame``, best first."""
        return optional_import("pandas").DataFrame([c.__dict__ for c in self.candidates()])

    def figures(self) -> dict[str, Any]:
        """The diagnosis's plots as matplotlib Figures, by kind (``map``, ``features``,
        ``decays``, ``ranking``)."""
        from .reports.gap_plots import diagnosis_figures

        return diagnosis_figures(self.diagnosis)


def diagnose(src: Source, *, rig: Rig | str | Path | None = None, settings: Settings | None = None,
             progress: Callable[[str], None] | None = None) -> TrialDiagnosis:
    """Hold a recording against its rig's model as ``ramdaq gap`` does (minutes on two cores)."""
    from .gap_layers import diagnose_trial
    from .gap_trial import load_trial

    _check_blas_threads()
    rec = as_recording(src, rig)
    lt, _, d = diagnose_trial(load_trial(rec, progress=progress), settings=settings,
                              progress=progress)
    return TrialDiagnosis(rec, d, lt)

