"""The data-only checks of a trial: what its recording says about its sensors, its blows and its
ambient without any stiffness or mass model -- gage positions and sensing axes only.

Each check is a plain function over arrays returning :class:`~ramdaq.analysis.gap.datamodel.Finding`
objects, each with its statistic and the level the statistic exceeds by chance with probability
``P_CHANCE`` on a trial without the fault (Bonferroni over everything the check looked at):

- :func:`rigid_gain` -- spatial redundancy: each rudder or hull gage's free mode shapes
  predicted from the other gages of its body by rigid-body kinematics (the least-squares,
  minimum-variance reconstruction of Kullaa 2010 with the rigid-body motions as the subspace
  Kerschen et al. 2005 take from a PCA of healthy data): a gain is an amplitude ratio consistent
  over every mode and impact, a dead gage one near zero;
- :func:`chain_phase` -- channel timing and the signal chain: a gage's phase against the other
  gages, mode by mode, is ``-2 pi f tau`` for a time skew ``tau`` and ``atan(fc / f)`` for a
  first-order high-pass (AC coupling) at ``fc``;
- :func:`flat_tops` -- clipping: runs of equal samples at a segment's extreme;
- :func:`pre_trigger_lines` -- lines before the blows (an ambient tone), after the previous
  blow's decay is taken out with the free modal model;
- :func:`double_hits` -- the early window at full rate: a second blow of the ram, its delay and
  size relative to the first;
- :func:`~ramdaq.analysis.gap.homogeneity.homogeneity` -- the same modes, frequencies and damping
  at blows of different force: friction, amplitude-dependent damping or stiffness.
- :func:`~ramdaq.analysis.gap.invariance.gain_invariance` -- time invariance: each gage's gain,
  impact by impact, the same over every mode;
- :func:`~ramdaq.analysis.gap.invariance.line_persistence` -- a line steady through the decays
  but gone before the next blow (neither a mode nor an ambient line);
- :func:`~ramdaq.analysis.gap.invariance.one_gage_lines` -- spatial coherence: a line of the
  early window on one gage alone (no structure moves one gage alone).

Shapes: ``x`` (n_g, n) m/s^2 at the recorded rate, gages in DAQ channel order; ``gages`` the
rig's :class:`~ramdaq.analysis.model.rig.Gage` per row.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.stats

from ..model.rig import Gage
from .datamodel import P_CHANCE, Finding, FreeModal, Layer, closure_of, free_modal_model
from .features import rigid_projector
from .homogeneity import homogeneity
from .invariance import gain_invariance, line_persistence, one_gage_lines, one_gage_poles
from .signal_checks import (
    EARLY_FROM_S,
    DeclaredLine,
    clip_closure,
    dead_or_noisy,
    double_hits,
    flat_tops,
    pre_trigger_lines,
)
from .verdict import UNEXPLAINED_CLOSURE

PHASE_FLOOR_RAD = 0.02
"""Phase scatter accepted on top of each estimate's standard error: the free shapes of a real
structure are slightly complex (non-proportional damping). Measured on clean trials of the truth
simulator (ALBACORE in water and in air, SAMPSON): well-measured entries' phases sit up to
0.01-0.04 rad off their mode's, mean over six blows; a 1.5 Hz high-pass leads by 0.12 rad at
13 Hz, a 3-sample skew at 2 kHz lags by 0.55 rad at 60 Hz."""
PHASE_MIN_RAD = 0.1
"""Least phase a reported skew or high-pass turns some measured mode by (5x the floor, 2.5x the
largest mean departure measured on clean trials; a clean SAMPSON trial of the truth simulator
otherwise reads its 2.2 and 4.4 Hz modes' complexity as a 0.1-0.15 Hz high-pass)."""
GAIN_FLOOR = 0.005
"""Relative amplitude scatter accepted on top of the standard errors in the rigid-body
reconstruction (gage positions are known to a few millimetres on metre baselines)."""
MIN_ENTRY_SNR = 20.0
"""A shape entry is used by the phase and gain checks when its amplitude is this many standard
errors (its phase then known to 0.05 rad)."""
RIDE_SNR = 10.0
"""The least entry SNR of the gain check on the modes a body rides rigidly
(:func:`_rigid_modes`): a gain reads each entry's component along its mode's phase, which noise
does not bias, and the prediction's own noise biases the gain low by about ``1/SNR^2`` (1 % at
10, a fifth of a 5 % gain's se from one impact). The hull modes that carry the rudder rigidly
are weak on it (issue 17, modal development seed 52002: a 9.7 Hz hull mode at SNR 14-24 on the
rudder gages left one rigid mode at 20, and a x1.40 gain on gage 8 was not found)."""


@dataclass(frozen=True)
class DataChecks:
    """The data-only layer's result: the free modal model and every finding beyond its chance
    level (``findings``); ``looked`` names the checks run."""

    modal: FreeModal
    findings: list[Finding]
    looked: tuple[str, ...]

    def to_json(self) -> dict:
        m = self.modal
        return {"checks": list(self.looked), "p_chance": P_CHANCE,
                "free_modes": [{"f_hz": round(float(f), 4), "delta": round(float(d), 5)}
                               for f, d in zip(m.f_hz, m.delta, strict=True)],
                "findings": [f.to_json() for f in self.findings]}


def check_trial(x: np.ndarray, fs_hz: float, onsets_s: np.ndarray, gages: Sequence[Gage], *,
                pre_s: float = 1.0, declared: Sequence[DeclaredLine] = ()) -> DataChecks:
    """Every data-only check of a trial. A dead or clipped gage is left out of the poles'
    identification and of every shape check (its harmonics are no modes, its shapes are cut);
    a gage with a timing or high-pass finding is left out of the rigid-body reconstruction of
    its neighbours (its complex shapes would bend theirs). A double hit is looked for on the
    gages that are not clipped. ``declared``: the lines the rig declares (its ``[[ambient]]``),
    reported as present when the data show them as declared
    (:func:`~ramdaq.analysis.gap.signal_checks.declared_match`)."""
    numbers = tuple(g.number for g in gages)
    found = dead_or_noisy(x, fs_hz, onsets_s, numbers, pre_s=pre_s)
    dead = {g for f in found if f.check == "dead" for g in f.gages}
    live = [i for i, n in enumerate(numbers) if n not in dead]
    found += flat_tops(_rows(x, live), fs_hz, onsets_s, [numbers[i] for i in live], pre_s=pre_s)
    gone = {g for f in found if f.check in ("dead", "clipping") for g in f.gages}
    rows = tuple(i for i, n in enumerate(numbers) if n in gone)
    fm = free_modal_model(x, fs_hz, onsets_s, pre_s=pre_s, exclude_rows=rows)
    found = [_with_clip_closure(f, x, fs_hz, onsets_s, numbers, fm) for f in found]
    timing = [f for f in chain_phase(fm, numbers, [g.body for g in gages]) if not set(f.gages) & gone]
    found += timing + rigid_gain(fm, gages, skip=gone | {g for f in timing for g in f.gages})
    found += pre_trigger_lines(x, fs_hz, onsets_s, numbers, fm, pre_s=pre_s, declared=declared)
    keep = [i for i in range(len(numbers)) if i not in rows]
    found += double_hits(_rows(x, keep), fs_hz, onsets_s, [numbers[i] for i in keep], fm)
    found += homogeneity(x, fm, numbers, skip_rows=rows,
                         lines_hz=[f.mode_hz[0] for f in found
                                   if f.check in ("ambient_tone", "declared_ambient") and f.mode_hz],
                         early_from_s=early_window_from(found))
    found += gain_invariance(fm, numbers, skip_rows=rows)
    found += line_persistence(x, fm, onsets_s, numbers, pre_s=pre_s, skip_rows=rows)
    found += one_gage_lines(x, fm, onsets_s, numbers, skip_rows=rows)
    found += one_gage_poles(fm, numbers, skip_rows=rows)
    return DataChecks(modal=fm, findings=found,
                      looked=("dead", "noisy", "gain", "rigid_body", "time_skew", "highpass", "clipping",
                              "ambient_tone", "double_hit", "homogeneity", "gain_invariance",
                              "line_persistence", "one_gage_line"))


def early_window_from(found: Sequence[Finding]) -> float:
    """Where the homogeneity check's early window starts, s after each onset
    (:func:`~ramdaq.analysis.gap.homogeneity.early_shift`): :data:`EARLY_FROM_S`, or as long
    after a second blow of the ram that the double-hit check found and whose own correction
    closes half its residual on held-out blows (a fixed second blow that repeats blow after
    blow, not a one-blow misfit: :data:`~ramdaq.analysis.gap.verdict.UNEXPLAINED_CLOSURE`, the
    half the layers ask of it). The same guard after the second contact as after the first: a
    window that holds the second blow's onset holds a step in every mode's amplitude and phase,
    which a pole refitted with constant amplitudes reads as a frequency change -- a linear
    structure struck twice then looks amplitude-dependent (issue 17, modal development seed
    57003: a second blow 20.5 ms after the first at 34 % read as a 25.4 Hz mode 1.9 % higher
    early than late at 5.2x its chance level, which set the double hit at 453x aside). After
    both contacts the response is two free decays of the same poles, whose frequencies a linear
    mode keeps."""
    hits = [f for f in found if f.check == "double_hit" and f.closed_held is not None
            and math.isfinite(f.closed_held) and f.closed_held >= UNEXPLAINED_CLOSURE]
    delays = [v for f in hits for name, v, _ in f.more if name == "delay_s" and math.isfinite(v)]
    return EARLY_FROM_S + max(delays) if delays else EARLY_FROM_S


def _with_clip_closure(f: Finding, x: np.ndarray, fs_hz: float, onsets_s: np.ndarray,
                       numbers: Sequence[int], fm: FreeModal) -> Finding:
    """A clipping finding with its closure on the held-out blows (:func:`clip_closure`); any
    other finding as it is."""
    if f.check != "clipping":
        return f
    closed, ci = clip_closure(x[numbers.index(f.gages[0])], fs_hz, onsets_s, fm)
    return replace(f, closed_held=closed, closed_held_ci=ci)


def _rows(x: np.ndarray, rows: list[int]) -> np.ndarray:
    """``x[rows]``, without a copy when that is every row (a 10-minute trial is 160 MB)."""
    return x if rows == list(range(x.shape[0])) else x[rows]


# ---------------------------------------------------------------- channel timing and chain


def _departures(fm: FreeModal) -> tuple[np.ndarray, np.ndarray]:
    """Each shape entry's phase off its mode's (mod pi: a real mode's entries are in or out of
    phase), rad, and its standard error, (n_imp, n_g, K). The reference is the median over the
    well-measured gages, so a few faulty ones do not move it."""
    a = fm.amp
    th = 0.5 * np.angle(np.sum(a**2, axis=1, keepdims=True))
    dep = _wrap(np.angle(a) - th)
    snr = fm.snr()
    good = snr >= MIN_ENTRY_SNR
    with warnings.catch_warnings():          # a mode no gage measures well has no reference
        warnings.simplefilter("ignore", RuntimeWarning)
        med = np.nanmedian(np.where(good, dep, np.nan), axis=1, keepdims=True)
    dep = _wrap(dep - np.nan_to_num(med))
    se = np.sqrt(1.0 / np.maximum(snr, 1e-12) ** 2 + PHASE_FLOOR_RAD**2)
    good &= ~fm.steady[None, None, :]
    return np.where(good, dep, np.nan), se


def _wrap(phi: np.ndarray) -> np.ndarray:
    """Phase wrapped into [-pi/2, pi/2) (mod pi)."""
    return (phi + math.pi / 2) % math.pi - math.pi / 2


TAU_GRID_SAMPLES = np.arange(-8.0, 8.0001, 0.02)
"""Time skews tried, in samples of the recorded rate (a skew beyond 8 samples would be an
error of the acquisition's channel order, not a sensor's)."""
FC_GRID_HZ = np.concatenate([[0.0], np.geomspace(0.05, 20.0, 400)])
"""First-order high-pass corners tried, Hz."""


def chain_phase(fm: FreeModal, numbers: Sequence[int],
                bodies: Sequence[str] | None = None) -> list[Finding]:
    """Per gage, its phase off the other gages across all modes and impacts, held against a
    time skew (``phi = -2 pi f tau``) and a first-order high-pass (``phi = atan(fc / f)``).

    Statistic: the drop in the phases' chi-square (each departure over its standard error
    ``1/SNR`` with :data:`PHASE_FLOOR_RAD`) when the better-fitting of the two is added; under no
    fault it is chi-square with 1 degree of freedom (one parameter fitted), so its chance level is
    that distribution's ``P_CHANCE / (2 n_g)`` quantile (two models, every gage). A skew or a
    corner is reported only when it turns some measured mode by :data:`PHASE_MIN_RAD`. Its
    closure: the share of the phase chi-square beyond its noise expectation (one a
    well-measured entry) the same model takes out on impacts it was not fitted on
    (:func:`_chain_closure`). A departure no law fits (``chain_misfit``) must also stand out of
    the departures of the gages that share its body (``bodies``, per row; all other gages when
    not given) at the same modes (:func:`_beside_peers`), else it is model form."""
    dep, se = _departures(fm)
    peers = _peers(numbers, bodies)
    level = float(scipy.stats.chi2.isf(P_CHANCE / (2 * len(numbers)), 1))
    out = []
    for g, num in enumerate(numbers):
        phi, s = dep[:, g, :], se[:, g, :]
        ok = np.isfinite(phi)
        if ok.sum() < 2:
            continue
        w = np.where(ok, 1.0 / s**2, 0.0)
        phi = np.where(ok, phi, 0.0)
        chi0 = float(np.sum(w * phi**2))
        c_tau, c_fc = _chain_costs(phi, w, fm.f_hz, fm.fs_hz)
        i, k = int(np.argmin(c_tau)), int(np.argmin(c_fc))
        tau_s = TAU_GRID_SAMPLES / fm.fs_hz
        f_ok = fm.f_hz[np.any(ok, axis=0)]
        # a skew or a corner too small to turn any measured mode by PHASE_MIN_RAD is not told
        # from the shapes' own complexity
        big_tau = 2 * math.pi * f_ok.max() * abs(tau_s[i]) >= PHASE_MIN_RAD
        big_fc = math.atan(FC_GRID_HZ[k] / f_ok.min()) >= PHASE_MIN_RAD
        drop_tau, drop_fc = (chi0 - c_tau[i]) * big_tau, (chi0 - c_fc[k]) * big_fc
        modes = tuple(float(v) for v in f_ok)
        if max(drop_tau, drop_fc) <= level:
            continue
        skew = drop_tau >= drop_fc
        misfit = _law_misfit(num, float(c_tau[i]), int(ok.sum()), len(numbers), drop_tau, level,
                             modes) if skew else None
        if misfit is not None:
            out.append(_beside_peers(misfit, dep / se, g, peers[g], len(numbers)) or misfit)
            continue
        drop, resid = (drop_tau, float(c_tau[i])) if skew else (drop_fc, float(c_fc[k]))
        scattered = _scattered(num, drop, resid, int(ok.sum()), len(numbers), modes)
        if scattered is not None:
            out.append(scattered)
            continue
        closed = _chain_closure(phi, w, ok, fm.f_hz, fm.fs_hz, skew)
        if skew:
            tau = float(tau_s[i])
            found = _finding("time_skew", num, drop_tau, level, tau, "s", modes,
                             f"gage {num} runs {1e3 * tau:+.2f} ms ({tau * fm.fs_hz:+.1f} samples) "
                             "off the other gages: its phase is linear in frequency over the modes")
        else:
            fc = float(FC_GRID_HZ[k])
            found = _finding("highpass", num, drop_fc, level, fc, "Hz", modes,
                             f"gage {num} leads the other gages as a first-order high-pass at "
                             f"{fc:.2f} Hz would (AC coupling or drift filter)")
        out.append(replace(found, closed_held=closed[0], closed_held_ci=closed[1]))
    return out


def _law_misfit(num: int, resid: float, n_entries: int, n_gages: int, drop: float, level: float,
                modes: tuple[float, ...]) -> Finding | None:
    """A gage whose phases depart from the other gages' (``drop`` beyond ``level``) and whose
    best time skew leaves a residual chi-square ``resid`` beyond chance over its
    ``n_entries - 1`` degrees of freedom (one delay fitted; the chi-square's upper
    ``P_CHANCE / (2 n_g)`` quantile, both laws and every gage) that is also larger than what the
    delay took out (``resid - dof > drop``: the law explains less than half of the departure
    beyond noise -- the phase floor is not exact, and a large skew's residual grows with it: a
    truth-family 4-sample skew left 3.3x the level, 0.4 % of its drop): a skew is one delay, a phase
    linear in frequency at every mode and impact, and a pure delay bends nothing else the free
    model reads, so its law fits to the phases' noise (development trials of both families: the
    residual at 0.36-0.42 of that level) -- a phase it does not fit is "unexplained" at that
    gage, not the nearest library effect (issue 17: a modal friction trial read as gage 15 "runs
    -2.50 ms"; development seed 58000, friction, read skews on gages 9, 13, 14 whose residuals
    were 52-168 times that level). Not applied to the high-pass: its corner adds a slow pole
    the free modal model does not hold, which bends the low modes' identified phases (a modal
    1.5 Hz high-pass on six gages left 60-100x the level), so a poor fit there is no evidence
    against the law. None when the skew fits."""
    dof = n_entries - 1
    if dof < 1:
        return None
    fit_level = float(scipy.stats.chi2.isf(P_CHANCE / (2 * n_gages), dof))
    if resid <= fit_level or resid - dof <= drop:
        return None
    return Finding(check="chain_misfit", layer=Layer.SENSOR, gages=(num,), statistic=float(drop),
                   chance_level=level, size=resid / dof, unit="chi2/dof", window="decay",
                   mode_hz=modes, p_chance=P_CHANCE,
                   more=(("residual_chi2", resid, ""), ("residual_level", fit_level, ""),
                         ("dof", float(dof), "")),
                   text=f"gage {num}'s phase departs from the other gages' but no one time skew fits "
                        f"it over its modes and impacts (residual chi-square {resid:.0f} over {dof} "
                        f"dof, chance level {fit_level:.0f}): unexplained at gage {num}",
                   null="chi-square, 1 dof (phase departures over their standard errors)")


def _peers(numbers: Sequence[int], bodies: Sequence[str] | None) -> list[list[int]]:
    """Per row, the other rows its phases are held against: those of its body (``bodies``, per
    row), or every other row when the bodies are not given."""
    n = len(numbers)
    if bodies is None:
        return [[j for j in range(n) if j != i] for i in range(n)]
    return [[j for j in range(n) if j != i and bodies[j] == bodies[i]] for i in range(n)]


def _beside_peers(f: Finding, z: np.ndarray, g: int, peers: list[int], n_gages: int) -> Finding | None:
    """A phase finding ``f`` of row ``g`` held against the departures of its ``peers`` (rows) at
    the same modes: None when it stands out of them, else a model-form ``complex_phase`` finding
    (the shapes' complexity, which every gage of the body shares), never a sensor's. ``z``:
    every entry's departure over its standard error (n_imp, n_g, K), NaN where not measured.

    A structure whose damping is not proportional has complex modes wherever two of them are
    close (a hull mode beside a rudder mode, a cluster of hull modes): every gage of the body
    that carries them departs from 0 or pi, mode by mode, at a scale the phase noise does not
    give and by an amount set by where it sits, which no one law of a channel fits. A fault of
    one channel (a gain drifting through the trial, a resonance of its mount) departs at that
    gage alone. Not knowing the shapes' scale, the gage's mean squared departure is tested
    against its peers' at the modes it measures as a ratio of two variances:
    ``F = mean(z_g^2) / max(1, mean(z_peers^2))`` (the peers' at least the noise's 1) against the
    F(n_g, n_peers) distribution's ``P_CHANCE / n_gages`` upper quantile (every gage; ``n`` the
    entries measured). Modal development and check trials (issue 17): a gain drifting on gage
    8 (seed 65003) departs 406x its body's others (level 2.7); the departures of friction, of
    rattles (but one rudder gage of check seed 161000) and of a high-pass gage the skew law
    was fitted to are 0.2-3.6x their body's (levels 3.7-13). With no peer of its body measured
    at its modes, every other gage is its peer; with none at all the finding stands."""
    zg = z[:, g, :]
    modes = np.isfinite(zg).any(axis=0)
    mine = zg[np.isfinite(zg)] ** 2
    theirs = _measured(z, peers, modes)
    if not theirs.size:
        theirs = _measured(z, [j for j in range(z.shape[1]) if j != g], modes)
    if not theirs.size:
        return None
    stat = float(mine.mean() / max(1.0, theirs.mean()))
    level = float(scipy.stats.f.isf(P_CHANCE / n_gages, mine.size, theirs.size))
    if stat > level:
        return None
    num = f.gages[0]
    return Finding(check="complex_phase", layer=Layer.MODEL_FORM, gages=(num,), statistic=stat,
                   chance_level=level, size=f.size, unit=f.unit, window="decay", mode_hz=f.mode_hz,
                   p_chance=P_CHANCE, more=f.more + (("misfit_chi2", f.statistic, ""),),
                   text=f"gage {num}'s phase departs from the other gages' and no one time skew fits it, "
                        f"but it departs only {stat:.1f}x as much as its body's other gages at the same "
                        f"modes (chance level {level:.1f}): the mode shapes' complexity, which the body's "
                        "gages share (model form), not a sensor's",
                   null="F(n_g, n_peers): the gage's mean squared phase departure over its peers'")


def _measured(z: np.ndarray, rows: list[int], modes: np.ndarray) -> np.ndarray:
    """The squared departures ``z**2`` of ``rows`` at ``modes`` ((K,) bool) that are measured,
    flat."""
    v = z[:, rows][:, :, modes]
    return v[np.isfinite(v)] ** 2


def _scattered(num: int, drop: float, resid: float, n_entries: int, n_gages: int,
               modes: tuple[float, ...]) -> Finding | None:
    """A gage whose phases depart from the other gages' beyond their noise (``drop`` beyond the
    chi-square(1) level) but not beyond the scatter its own departures keep about the best law:
    None when the law stands, else a model-form finding (the shapes' complexity), never a
    sensor's.

    The phase standard errors hold the noise only; a structure's modes are complex wherever its
    damping is not proportional (close modes, a hull mode beside a rudder mode), and a gage's
    departure is then set by where it sits, mode by mode, at a scale the noise does not give.
    A fixed channel (a time skew, a first-order high-pass) is one law at every mode and impact,
    so what it leaves is noise; a departure of the shapes' own leaves a residual of the
    departure's own size. Not knowing that scale, the law is tested as a regression with an
    unknown variance: ``F = drop / s^2`` with ``s^2 = max(1, resid / (n - 1))`` (the residual
    chi-square per degree of freedom after the one fitted parameter, at least the noise's 1)
    against the F(1, n - 1) distribution's ``P_CHANCE / (2 n_g)`` upper quantile (two laws,
    every gage), which tends to the chi-square(1) level when ``n`` is large and the residual is
    noise (with few entries it is above it: 34 against 17 at 15 dof). Modal development and
    check trials (issue 17): real high-passes (0.75-3 Hz on 4-6 gages) and skews (0.5-4
    samples) leave 0.1-5 per dof and F 90 and more; the departures of a stock rattle, a crack,
    friction and a gain drift that the high-pass law was fitted to on other gages left 60-430
    per dof and F 3-13 against levels 39-89; a rattle's 0.2-sample skew F 19 against 59, and a
    weak line's 0.14 Hz corner F 31 against 34. The cost: the weakest gage of a 0.75 Hz
    high-pass (check seed 154000, gage 10, F 29 against 39) is read as form, its other gages
    still as the high-pass."""
    dof = n_entries - 1
    if dof < 1:
        return None
    scale = max(1.0, resid / dof)
    level = float(scipy.stats.f.isf(P_CHANCE / (2 * n_gages), 1, dof))
    if drop / scale > level:
        return None
    return Finding(check="complex_phase", layer=Layer.MODEL_FORM, gages=(num,),
                   statistic=float(drop / scale), chance_level=level, size=resid / dof,
                   unit="chi2/dof", window="decay", mode_hz=modes, p_chance=P_CHANCE,
                   more=(("drop_chi2", drop, ""), ("residual_chi2", resid, ""), ("dof", float(dof), "")),
                   text=f"gage {num}'s phase departs from the other gages' beyond noise, but no one "
                        f"time skew or high-pass fits it beyond its own scatter ({resid / dof:.0f} "
                        "per dof): the mode shapes' complexity (model form), not a sensor's",
                   null="F(1, n-1): the law's chi-square drop over the residual per dof")


def _chain_costs(phi: np.ndarray, w: np.ndarray, f_hz: np.ndarray,
                 fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """The phases' chi-square ``sum w (phi - model)^2`` for every skew of
    :data:`TAU_GRID_SAMPLES` and every corner of :data:`FC_GRID_HZ`; ``phi``, ``w`` (n_imp, K)
    (rad, 1/rad^2; weight 0 where not measured)."""
    f = f_hz[None, :]
    tau_s = TAU_GRID_SAMPLES / fs_hz
    c_tau = np.array([np.sum(w * _wrap(phi + 2 * math.pi * f * t) ** 2) for t in tau_s])
    c_fc = np.array([np.sum(w * _wrap(phi - np.arctan(fc / f)) ** 2) for fc in FC_GRID_HZ])
    return c_tau, c_fc


def _chain_closure(phi: np.ndarray, w: np.ndarray, ok: np.ndarray, f_hz: np.ndarray, fs_hz: float,
                   skew: bool) -> tuple[float, tuple[float, float]]:
    """The share of the phase chi-square (beyond one per measured entry) that a skew (``skew``)
    or a high-pass takes out on impacts it was not fitted on: each impact in turn held out, the
    model fitted on the others (:func:`closure_of`, units the held-out entries); NaN when no
    held-out impact has a measured entry."""
    f = f_hz[None, :]
    before, after = [], []
    for j in range(phi.shape[0]):
        rest = np.arange(phi.shape[0]) != j
        if not ok[j].any() or not ok[rest].any():
            continue
        c_tau, c_fc = _chain_costs(phi[rest], w[rest], f_hz, fs_hz)
        if skew:
            model = -2 * math.pi * f[0] * TAU_GRID_SAMPLES[int(np.argmin(c_tau))] / fs_hz
        else:
            model = np.arctan(FC_GRID_HZ[int(np.argmin(c_fc))] / f[0])
        before += list((w[j] * phi[j] ** 2)[ok[j]])
        after += list((w[j] * _wrap(phi[j] - model) ** 2)[ok[j]])
    return closure_of(np.array(before), np.array(after), np.ones(len(before)))


def _finding(check: str, num: int, stat: float, level: float, size: float, unit: str,
             modes: tuple[float, ...], text: str) -> Finding:
    """A timing or signal-chain finding on one gage."""
    return Finding(check=check, layer=Layer.SENSOR, gages=(num,), statistic=float(stat),
                   chance_level=level, size=size, unit=unit, text=text, window="decay",
                   mode_hz=modes, p_chance=P_CHANCE,
                   null="chi-square, 1 dof (phase departures over their standard errors)")


# ---------------------------------------------------------------- spatial redundancy


def rigid_gain(fm: FreeModal, gages: Sequence[Gage], *, skip: set[int] = frozenset()) -> list[Finding]:
    """Each gage of a rigid body (the rudder, the hull) whose free shapes the body's other gages
    predict by rigid-body kinematics: its gain ``g`` (least squares over every mode and impact
    of ``a = g p``, ``p`` the prediction from the others, each entry weighted by the inverse of
    its variance) and ``z = (g - 1) / se(g)``; a gain is reported when ``|z|`` passes the normal
    distribution's two-sided ``P_CHANCE / n`` quantile (``n`` gages tested). Shapes are read as
    real modes (each entry's component along its mode's phase), so a small phase error barely
    moves them. The suspect is the gage whose removal leaves the others most consistent (a
    faulty gage bends every prediction it enters, a far one most); it is taken out and the rest
    tested again. Gages numbered in ``skip`` are left out."""
    out = []
    for body in ("rudder", "hull"):
        rows = [i for i, g in enumerate(gages) if g.body == body and g.number not in skip]
        if len(rows) < 2 or rigid_projector(list(gages), np.array(rows)) is None:
            continue
        out += _body_gains(fm, gages, rows)
    return out


def _real_modes(fm: FreeModal) -> tuple[np.ndarray, np.ndarray]:
    """Each shape entry's component along its mode's phase (n_imp, n_g, K) m/s^2, and its
    standard error."""
    a = fm.amp
    th = 0.5 * np.angle(np.sum(a**2, axis=1, keepdims=True))
    return np.real(a * np.exp(-1j * th)), fm.amp_se


def _body_gains(fm: FreeModal, gages: Sequence[Gage], rows: list[int]) -> list[Finding]:
    """A body's gain findings over all its modes (:func:`_body_gains_on`); when the body deforms
    in some of them (a flexible-body finding), again on the modes in which it moves rigidly
    but for one gage (:func:`_rigid_modes`), when two or more are: the hull's low modes carry
    the rudder along as one rigid body however its own modes bend it (the modal family's
    rudder moves as one in its hull modes), and a gain is one ratio at every mode, so those
    modes tell it. The flexible-body finding stays (the body's form in its other modes)."""
    G = {i: np.concatenate([gages[i].direction, np.cross(gages[i].position_m, gages[i].direction)])
         for i in rows}
    out = _body_gains_on(fm, gages, rows, G, fm.steady)
    if not any(f.check == "flex" for f in out):
        return out
    low, bent = _rigid_modes(fm, G, rows, RIDE_SNR)
    first_bent = float(fm.f_hz[bent].min()) if bent.any() else math.inf
    # a body rides rigidly, quasi-statically, below its first own mode: a weakly read mode above
    # the lowest one it is measured to bend in that passes as rigid at RIDE_SNR is not kept
    # (modal check seed 151000: a 228 Hz rudder mode, weak on its gages, passed as rigid and its
    # bending was read as gage 4's gain varying by mode); one rigid at MIN_ENTRY_SNR too stays
    rigid = low & ((fm.f_hz < first_bent) | _rigid_modes(fm, G, rows)[0])
    if rigid.sum() == 1:
        rigid |= _unread_below(fm, G, rows, first_bent)
    if rigid.sum() < 2 or rigid.sum() == (~fm.steady).sum():
        return out
    gains = [f for f in _body_gains_on(fm, gages, rows, G, ~rigid, RIDE_SNR) if f.check == "gain"]
    return gains + out


def _unread_below(fm: FreeModal, G: dict, rows: list[int], first_bent: float) -> np.ndarray:
    """(K,) bool: the modes (not steady) below ``first_bent`` (Hz, the lowest mode the body is
    measured to bend in) that the rigid-body test could not read at :data:`RIDE_SNR` (fewer
    than three of the body's gages read, whichever is left out). A body rides rigidly,
    quasi-statically, below its first own mode, so a hull mode there carries it as one: with
    a single mode shown rigid a gain is not told from the body's shape, and these modes, weak
    as they are, are the second reading of the same ratio that :func:`_mode_spread` then tests
    (issue 17, modal development seed 52005: a x1.40 gain on gage 8 read 1.373 +- 0.012 on the
    one rigid 13.6 Hz mode and 1.39 +- 0.08 on a 5.4 Hz hull mode the rudder's gages read at
    SNR 7-12, and was not found)."""
    a, se = _real_modes(fm)
    out = np.zeros(fm.n_modes, dtype=bool)
    for k in np.flatnonzero(~fm.steady & (fm.f_hz < first_bent)):
        only = np.ones(fm.n_modes, dtype=bool)
        only[k] = False
        z = [_largest_z(a, se, G, [r for r in rows if r != c], only, RIDE_SNR) for c in rows]
        out[k] = not any(math.isfinite(v) for v in z + [_largest_z(a, se, G, rows, only, RIDE_SNR)])
    return out


def _rigid_modes(fm: FreeModal, G: dict, rows: list[int],
                 min_snr: float = MIN_ENTRY_SNR) -> tuple[np.ndarray, np.ndarray]:
    """(K,) bool each: the modes (not steady) in which the body's gages ``rows`` move as one rigid
    body, or do so with one and the same gage left out: in each mode alone, the largest gain z
    of the others (each predicted from the rest) within the normal's two-sided chance level,
    Bonferroni over the gages and modes. A gain is one gage's at every mode, so the modes kept
    are those of the gage whose removal leaves the most modes rigid (a bent mode may look rigid
    but for another gage, where its bending is largest); and the modes it is measured to bend in
    (the largest z finite and beyond the level whichever gage is left out)."""
    a, se = _real_modes(fm)
    k_all = np.flatnonzero(~fm.steady)
    level = float(scipy.stats.norm.isf(P_CHANCE / (2 * len(rows) * max(1, k_all.size))))
    whole = np.zeros(fm.n_modes, dtype=bool)
    bent = np.zeros(fm.n_modes, dtype=bool)
    but = np.zeros((len(rows), fm.n_modes), dtype=bool)
    for k in k_all:
        only = np.ones(fm.n_modes, dtype=bool)
        only[k] = False
        z = [_largest_z(a, se, G, rows, only, min_snr)]
        z += [_largest_z(a, se, G, [r for r in rows if r != c], only, min_snr) for c in rows]
        whole[k] = z[0] <= level
        but[:, k] = [v <= level for v in z[1:]]
        bent[k] = min(z) > level and math.isfinite(min(z))
    best = int(np.argmax(np.sum(but | whole, axis=1)))
    return whole | but[best], bent


def _largest_z(a: np.ndarray, se: np.ndarray, G: dict, rows: list[int], skip: np.ndarray,
               min_snr: float = MIN_ENTRY_SNR) -> float:
    """The largest gain z among ``rows``, each predicted from the others on the modes not in
    ``skip``; a gage whose entries are too weak to read there (:data:`MIN_ENTRY_SNR`) is passed
    over (in one low mode a gage near its node is), infinite when one is not determined by the
    others' rigid-body motion or fewer than three are read."""
    zs = []
    for i in rows:
        others = [r for r in rows if r != i]
        if _prediction(a, se, G, i, others, skip) is None:
            return math.inf
        e = _gain_of(a, se, G, i, others, skip, min_snr=min_snr)
        if e is not None:
            zs.append(abs(e[0] - 1) / e[1])
    return max(zs) if len(zs) >= 3 else math.inf


def _body_gains_on(fm: FreeModal, gages: Sequence[Gage], rows: list[int], G: dict,
                   skip_modes: np.ndarray, min_snr: float = MIN_ENTRY_SNR) -> list[Finding]:
    """A body's gain, rigid-body and flexible-body findings read on the modes not in
    ``skip_modes`` ((K,) bool; the steady poles at least)."""
    a, se = _real_modes(fm)
    out, live = [], list(rows)
    while len(live) > 2:
        res = {i: e for i in live
               if (e := _gain_of(a, se, G, i, [r for r in live if r != i], skip_modes, min_snr=min_snr))}
        if not res:
            return out
        level = float(scipy.stats.norm.isf(P_CHANCE / (2 * len(res))))
        if max(abs(g - 1) / s for g, s in res.values()) <= level:
            return out
        rest = {c: _spread_without(a, se, G, live, c, skip_modes, min_snr) for c in res}
        i = min(rest, key=rest.get)
        g, s = res[i]
        z = abs(g - 1) / s
        if z <= level:
            return out
        if rest[i] > level:
            # no one gage's removal leaves the others rigid: the body itself deforms (a flexible
            # rudder's shapes, issue 17's modal family) -- the rig's form, blamed on no gage
            # (its statistic the others' largest gain z, else -- a pair only each other checks --
            # the suspect's own)
            stat = rest[i] if math.isfinite(rest[i]) else z
            return out + [_flex_finding(fm, gages, live, stat, level, skip_modes)]
        num = gages[i].number
        live.remove(i)
        spread, spread_level = _mode_spread(a, se, G, i, live, skip_modes, min_snr)
        if not math.isfinite(spread):  # one mode: a gain is not told from the body's shape
            return out + [_flex_finding(fm, gages, live + [i], z, level, skip_modes)]
        if spread > spread_level:      # a gain is one ratio at every mode; this is the body's shape
            out.append(_rigid_finding(fm, gages[i], spread, spread_level, skip_modes))
            continue
        what = f"gain x{g:.3f} against its body's rigid-body motion"
        if g < 0:
            # the data cannot tell a gage wired backwards from a rig file giving its axis the
            # wrong sign (a new user's rig with gage 4 on -y was read as a confident sensor fault)
            what += (" (its polarity reversed: the gage wired backwards, or its axis in the rig "
                     "file of the wrong sign)")
        elif g < 1:            # a tilted gage reads cos(tilt) of its axis where nothing sees across it
            what += f" (or its axis tilted {math.degrees(math.acos(g)):.0f} deg)"
        found = _gain_finding(fm, num, z, level, g, f"gage {num}: {what} (se {s:.3f})", skip_modes)
        closed, ci = _gain_closure(a, se, G, i, live, skip_modes, min_snr)
        out.append(replace(found, closed_held=closed, closed_held_ci=ci))
    return out


def _spread_without(a: np.ndarray, se: np.ndarray, G: dict, live: list[int], c: int,
                    steady: np.ndarray, min_snr: float = MIN_ENTRY_SNR) -> float:
    """The largest gain z among the gages ``live`` other than ``c``, each predicted from the
    rest without ``c``: how inconsistent the body stays if ``c`` is the faulty one; infinite
    when one of them is no longer predicted without ``c``."""
    rest = [r for r in live if r != c]
    es = [_gain_of(a, se, G, i, [r for r in rest if r != i], steady, min_snr=min_snr) for i in rest]
    if any(e is None for e in es):
        # a gage only ``c`` checked (the hull's two vertical gages check each other alone):
        # the fault is not told between them, ``c`` is not singled out
        return math.inf
    return max((abs(e[0] - 1) / e[1] for e in es), default=0.0)


def _gain_of(a: np.ndarray, se: np.ndarray, G: dict, i: int, others: list[int],
             steady: np.ndarray, min_entries: int = 2,
             impacts: np.ndarray | None = None, min_snr: float = MIN_ENTRY_SNR) -> tuple[float, float] | None:
    """(gain, its standard error) of row ``i`` against its prediction from the rows ``others``,
    or None when they do not determine its rigid-body motion. Steady poles are left out; so are
    the impacts not in ``impacts`` ((n_imp,) bool, default all)."""
    pred = _prediction(a, se, G, i, others, steady, min_snr)
    if pred is None:
        return None
    p, var, ok = pred
    if impacts is not None:
        ok = ok & impacts[:, None]
    if ok.sum() < min_entries:
        return None
    w = np.where(ok, 1.0 / var, 0.0)
    den = float(np.sum(w * p**2))
    return float(np.sum(w * p * a[:, i, :]) / den), math.sqrt(1.0 / den)


def _prediction(a: np.ndarray, se: np.ndarray, G: dict, i: int, others: list[int],
                steady: np.ndarray, min_snr: float = MIN_ENTRY_SNR
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Row ``i``'s real mode shapes predicted from the rows ``others`` by rigid-body kinematics
    (n_imp, K) m/s^2, the variance of ``a[:, i] - p`` and the entries well measured (not steady,
    :data:`MIN_ENTRY_SNR`); None when ``others`` do not determine ``i``'s rigid-body motion."""
    Go = np.array([G[r] for r in others])
    rank = np.linalg.matrix_rank
    if not others or rank(np.vstack([Go, G[i]]), tol=1e-9) > rank(Go, tol=1e-9):
        return None
    h = G[i] @ np.linalg.pinv(Go)                                   # prediction weights (n_o,)
    p = np.einsum("o,jok->jk", h, a[:, others, :])
    var = se[:, i, :] ** 2 + np.einsum("o,jok->jk", h**2, se[:, others, :] ** 2)
    var = var + (GAIN_FLOOR * p) ** 2
    ok = (p**2 >= min_snr**2 * var) & ~steady[None, :]
    return p, var, ok


def _gain_closure(a: np.ndarray, se: np.ndarray, G: dict, i: int, others: list[int],
                  steady: np.ndarray, min_snr: float = MIN_ENTRY_SNR) -> tuple[float, tuple[float, float]]:
    """The share of row ``i``'s rigid-body misfit (``a - p`` over its standard error, beyond one
    per entry) that its gain takes out on impacts it was not fitted on: each impact in turn
    held out, the gain fitted on the others (:func:`closure_of`, units the entries; a held-out
    impact whose entries are too weak to read adds none -- a weak blow of four, the model
    layer's one held out, often has none). NaN when not measured."""
    pred = _prediction(a, se, G, i, others, steady, min_snr)
    if pred is None or a.shape[0] < 2:
        return math.nan, (math.nan, math.nan)
    p, var, ok = pred
    y = a[:, i, :]
    before, after = [], []
    for j in range(a.shape[0]):
        g = _gain_of(a, se, G, i, others, steady, impacts=np.arange(a.shape[0]) != j, min_snr=min_snr)
        if g is None or not ok[j].any():
            continue
        before += list(((y[j] - p[j]) ** 2 / var[j])[ok[j]])
        after += list(((y[j] - g[0] * p[j]) ** 2 / var[j])[ok[j]])
    return closure_of(np.array(before), np.array(after), np.ones(len(before)))


def _mode_spread(a: np.ndarray, se: np.ndarray, G: dict, i: int, others: list[int],
                 steady: np.ndarray, min_snr: float = MIN_ENTRY_SNR) -> tuple[float, float]:
    """How far row ``i``'s gain differs from mode to mode: the chi-square of the per-mode gains
    about their weighted mean, each gain's variance its standard error squared plus
    :data:`GAIN_FLOOR` squared; and its chance level, the chi-square(K - 1) upper ``P_CHANCE``
    quantile (K modes with a gain). With fewer than two such modes a gain cannot be told from
    the body's shape: (inf, 0), read as the body's."""
    gk, vk = [], []
    for k in range(a.shape[2]):
        one = np.zeros_like(steady)
        one[k] = True
        e = _gain_of(a, se, G, i, others, ~one | steady, min_entries=1, min_snr=min_snr)
        if e is not None:
            gk.append(e[0])
            vk.append(e[1] ** 2 + (GAIN_FLOOR * e[0]) ** 2)
    if len(gk) < 2:            # one mode: a gain is not told from the body's shape
        return math.inf, 0.0
    gk, w = np.array(gk), 1.0 / np.array(vk)
    mean = float(np.sum(w * gk) / np.sum(w))
    return float(np.sum(w * (gk - mean) ** 2)), float(scipy.stats.chi2.isf(P_CHANCE, len(gk) - 1))


def _rigid_finding(fm: FreeModal, gage: Gage, stat: float, level: float, skip: np.ndarray) -> Finding:
    """A gage its body's other gages do not predict by rigid-body kinematics with one gain for
    all modes: the rig's rigid body is not what moves there (a flexible part, a wrong position
    or body in the rig file), a model-form finding, not a sensor's."""
    return Finding(check="rigid_body", layer=Layer.MODEL_FORM, gages=(gage.number,),
                   statistic=stat, chance_level=level, size=float("nan"), unit="",
                   window="decay", mode_hz=tuple(float(f) for f in fm.f_hz[~skip]),
                   text=f"gage {gage.number} does not move with the {gage.body}'s other gages as one "
                        "rigid body, and not by one gain at every mode (a flexible part, or its "
                        "position or body in the rig)",
                   null="chi-square of per-mode gains about their mean, K-1 dof")


def _flex_finding(fm: FreeModal, gages: Sequence[Gage], rows: list[int], stat: float,
                  level: float, skip: np.ndarray) -> Finding:
    """A body whose gages no rigid-body motion fits with one faulty gage taken out (or, with one
    measured mode, whose misfit no gain is told from): its shapes bend, the rig's rigid body is
    the model's form there, not a sensor fault. ``stat`` a gain z beyond the normal's chance
    level ``level``: the largest left among the others, or the suspect's own."""
    body = gages[rows[0]].body
    nums = tuple(sorted(gages[r].number for r in rows))
    return Finding(check="flex", layer=Layer.MODEL_FORM, gages=nums, statistic=float(stat),
                   chance_level=level, size=float("nan"), unit="", window="decay",
                   mode_hz=tuple(float(f) for f in fm.f_hz[~skip]),
                   text=f"the {body}'s gages {', '.join(map(str, nums))} do not move as one rigid body "
                        "and no single gage's removal makes them: the body deforms in its modes "
                        "(model form of the rigid-body assumption, not a sensor fault)",
                   null="normal (largest gain z of the others, one gage left out)")


def _gain_finding(fm: FreeModal, num: int, z: float, level: float, g: float, text: str,
                  skip: np.ndarray) -> Finding:
    return Finding(check="gain", layer=Layer.SENSOR, gages=(num,), statistic=float(z),
                   chance_level=level, size=g, unit="ratio", text=text, window="decay",
                   mode_hz=tuple(float(f) for f in fm.f_hz[~skip]), p_chance=P_CHANCE,
                   null="normal (gain estimate over its standard error)")
