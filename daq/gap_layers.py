"""The layers of a gap diagnosis run on a loaded trial, as ``ramdaq gap``, ``ramdaq batch gap``
and :func:`ramdaq.daq.api.diagnose` run them: the model level (the rig calibrated to the trial's
modes), the data-only checks, the effect search, and the one answer of both layers."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..analysis.gap.calibrate import ModeRef
from ..analysis.gap.diagnose import Diagnosis, Settings, diagnose
from ..analysis.gap.effects.base import rig_update
from ..analysis.gap.layers import Answer, answer
from ..analysis.gap.modal_level import structure_above
from ..analysis.gap.rigfit import ModelLevel, with_updates
from ..analysis.gap.rigfit import model_level as rig_to_modes
from ..analysis.gap.sensors import DataChecks, check_trial
from ..analysis.gap.trialdata import TrialData, declared_lines
from .gap_trial import LoadedTrial, trial_data

FORM_MIN_CLOSURE = 0.5
"""When the rig calibrated to the trial's modes still misses some of them (a model-form error),
an effect is named only if it closes at least half of the held-out impacts' gap: an effect that
closes less is fitting the model's form (a crude rig's detuned mode), not a cause in the trial."""


def diagnose_trial(lt: LoadedTrial, *, settings: Settings | None = None,
                   progress: Callable[[str], None] | None = None, data_checks: bool = True,
                   model_level: bool = True, keep_counts: bool = True,
                   **prep) -> tuple[LoadedTrial, TrialData, Diagnosis]:
    """Diagnose a loaded trial. With ``model_level`` the rig is first calibrated to the trial's
    identified modes (:func:`~ramdaq.analysis.gap.rigfit.model_level`) and the effect search
    runs on what that leaves; the diagnosis carries the model's form error. With
    ``data_checks`` the data-only layer (:func:`data_only`) runs too and its findings join the
    diagnosis; :attr:`Diagnosis.answer` is the one answer of both (:func:`one_answer`).
    Without ``keep_counts`` the trial's counts are let go once the data-only layer has read
    them (:meth:`LoadedTrial.release_counts`, of ``lt`` and of the trial returned), before the
    effect search, whose peak memory they would add to.
    The band compared is the rig's (:func:`~ramdaq.analysis.gap.trialdata.analysis_band`) unless
    the trial rings above it on several gages and its modes there show a split or a coupled hull
    mode (:func:`~ramdaq.analysis.gap.modal_level.structure_above`): then the data's band
    (``data_band``), up to those lines, so that the layers see the effect (``data_band=False``
    holds the rig's).
    Returns the trial (with the calibrated rig), its data as compared, and the diagnosis."""
    say = progress or (lambda s: None)
    given = lt
    td = trial_data(lt, **prep)
    if td.ringing_above and "data_band" not in prep:
        # the data ring above the rig's band: compared there where the modes show a structural
        # effect the rig's band leaves out (the other lines stay listed, as the rig's band costs less)
        wide = trial_data(lt, data_band=True, **prep)
        if wide.lowpass_hz > td.lowpass_hz and structure_above(wide, 0.9 * td.lowpass_hz):
            td, prep = wide, {**prep, "data_band": True}
        del wide  # not held through the search when the rig's band stands
    level = None
    settings = settings or Settings()
    if model_level:
        say(f"model level: identifying the modes of {td.n_seg} impacts, calibrating the rig to them")
        level = rig_to_modes(td)
        if level.fit is not None:
            lt = replace(lt, rig=level.fit.rig)
            # compared over the band the modes were identified and the rig calibrated on at the
            # least: a calibrated rig whose nominal blow leaves its rudder mode below the floor
            # put its band at 8.8 Hz, under the 13 Hz the trial rings with (a benchmark trial
            # failed on a one-sample pre window)
            td = trial_data(lt, min_corner_hz=td.rig_lowpass_hz, **prep)
            tm = level.modes    # the time-history calibration must not move the modes away from them
            settings = replace(settings, reference_modes=tuple(
                ModeRef(*map(float, m)) for m in zip(tm.f_hz, tm.f_se_hz, tm.zeta, tm.zeta_se, strict=True)))
            if level.fit.form:
                settings = replace(settings, min_closure=max(settings.min_closure, FORM_MIN_CLOSURE))
        n_form = 0 if level.fit is None else len(level.fit.form) + len(level.fit.damping)
        say(level.statement() if level.fit is None else  # the summary lists the form errors once
            f"model level: rig calibrated to the modes, {n_form} form error(s) left "
            "(listed under the verdict)")
    data, note = data_only(lt, td, prep.get("pre_s", 1.0), progress) if data_checks else (None, None)
    if not keep_counts:
        given.release_counts()
        lt.release_counts()
    d = diagnose(td, settings, progress)
    d.model_level, d.data = with_structure(level, d.candidates), data
    if note:
        d.notes.append(note)
    d.answer = one_answer(d)
    return lt, td, d


def one_answer(d: Diagnosis) -> Answer:
    """The one report's answer of both layers (:func:`ramdaq.analysis.gap.layers.answer`, the
    function the benchmark scores with): the model's choice, set aside where the rig calibrated
    to the trial's modes still misses them (model form), and a data-only finding's precedence."""
    form = d.model_level.form_gages() if d.model_level is not None else set()
    modes = d.model_level.form_modes() if d.model_level is not None else []
    cands = candidate_records(d)
    finds = [f.to_json() for f in d.data.findings] if d.data is not None else []
    splits = [s.to_json() for s in d.model_level.splits()] if d.model_level is not None else []
    coupled = [c.to_json() for c in d.model_level.coupled()] if d.model_level is not None else []
    return answer(d.model_choice(), cands, d.unexplained_where, form, finds, modes, splits, coupled)


def with_structure(level: ModelLevel | None, cands: list) -> ModelLevel | None:
    """The model level with the form error left by each structural candidate's update
    (:func:`~ramdaq.analysis.gap.rigfit.with_updates`): those that change the rig and act only
    where the calibrated rig misses the trial's modes, the only ones the form error could
    swallow (:func:`~ramdaq.analysis.gap.layers.model_answer`)."""
    if level is None or level.fit is None or not level.fit.form:
        return level
    form = level.form_gages()
    ups = {c.name: up for c in cands
           if set(c.location["gages"]) <= form and (up := rig_update(c.terms)) is not None}
    return with_updates(level, ups) if ups else level


def candidate_records(d: Diagnosis) -> list[dict]:
    """The candidates as the answer reads them: :meth:`Candidate.record`, ``location``, and the
    form error left with each structural one's update (``form_gages``, ``form_modes``)."""
    lvl = d.model_level
    return [c.record() | {"location": c.location} | (lvl.candidate_form(c.name) if lvl else {})
            for c in d.candidates]


def data_only(lt: LoadedTrial, td: TrialData, pre_s: float = 1.0,
              progress: Callable[[str], None] | None = None) -> tuple[DataChecks | None, str | None]:
    """The data-only checks (:func:`ramdaq.analysis.gap.sensors.check_trial`) of the recording at
    its own rate, on the impacts the diagnosis compares, with the pre-trigger window ``pre_s``
    (s); (None, why) when the trial leaves them nothing to read (too short a decay between
    blows)."""
    (progress or (lambda s: None))("data-only checks (free modal model, sensors, blows, ambient)")
    try:
        return check_trial(lt.x, lt.fs_hz, td.onsets_s, lt.rig.gages_by_channel(), pre_s=pre_s,
                           declared=declared_lines(lt.rig)), None
    except (ValueError, np.linalg.LinAlgError) as exc:
        return None, f"data-only checks not run: {exc}"
