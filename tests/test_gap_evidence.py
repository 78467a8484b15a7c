"""The gap diagnosis' judgement of evidence: a gap must reproduce on the held-out impacts, each
gage x window is weighed by what it tells beyond the model's form tolerance, and a ram bounce's
delay is found blow by blow."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from ramdaq.analysis.gap.diagnose import diagnose
from ramdaq.analysis.gap.evidence import (
    GAP_CELL_Z,
    WINDOWS,
    GapMap,
    bands_for,
    cell_energies,
    cell_inflation,
    window_inflation,
)
from ramdaq.analysis.gap.forward import Forward
from ramdaq.analysis.gap.trialdata import prepare
from ramdaq.analysis.gap.verdict import detection_score
from ramdaq.analysis.model.response import half_sine_response
from ramdaq.analysis.model.rig import load_rig
from ramdaq.analysis.truth.trial import generate_trial

RIGS = Path(__file__).resolve().parents[1] / "recordings" / "rigs"


def _map(z: np.ndarray) -> GapMap:
    bands = bands_for(np.array([8.0, 24.0]), 100.0)
    e = np.ones_like(z)
    return GapMap(z, e, e, e, bands, tuple(range(1, z.shape[0] + 1)))


def test_a_gap_counts_only_where_the_held_out_impacts_reproduce_it():
    z_fit = np.zeros((4, 3, 3))
    z_fit[2, 1, 1] = 12.0                        # the fitted impacts' map: one strong cell
    z_held = np.zeros_like(z_fit)
    z_held[0, 0, 0] = 9.0                        # the held-out map: a strong cell elsewhere
    # only the cell both maps show counts, with the fitted map's score there
    assert detection_score(_map(z_fit), _map(z_held)) == 0.0
    z_held[0, 0, 0] = 0.0
    assert detection_score(_map(z_fit), _map(z_held)) == -np.inf
    z_held[2, 1, 1] = GAP_CELL_Z + 0.5           # now the same cell stands out held out too
    assert detection_score(_map(z_fit), _map(z_held)) == 12.0
    # one impact only: nothing to reproduce it on, the fitted map alone decides
    assert detection_score(_map(z_fit), None) == 12.0


@pytest.fixture(scope="module")
def trial():
    rig = load_rig(RIGS / "albacore.toml").with_medium("water")
    tt = generate_trial(rig, "double_hit", 0.5, seed=1234)
    x = tt.counts * tt.scale[:, None]
    td = prepare(x, tt.fs_hz, tt.onsets_s, tt.rig)
    return tt, td


def test_inflation_is_one_for_white_noise_and_grows_where_the_form_error_is(trial):
    _, td = trial
    fw = Forward(td, np.full(td.n_gages, 1e-3))
    rng = np.random.default_rng(5)
    n_rep = 8
    reps = rng.standard_normal((n_rep,) + td.x.shape) / fw.W       # unit variance once whitened
    bands = bands_for(np.array([6.8, 13.0, 59.6]), td.lowpass_hz)
    cells = cell_energies(fw, reps, bands)
    kw = window_inflation(fw, cells, td.fitted)
    n_fit = int(td.fitted.sum())
    for w, name in enumerate(WINDOWS):
        n = n_fit * len(range(*getattr(td.windows, name).indices(td.n_s)))
        # the mean of n_rep x n unit chi-square(1) draws: sd sqrt(2 / (n_rep n)); 5 sd
        assert np.all(kw[:, w] <= 1 + 5 * math.sqrt(2 / (n_rep * n))), (name, kw[:, w].max())
    kc = cell_inflation(fw, cells, bands, td.fitted)
    assert np.median(kc) < 1.1      # per cell: fewer bins, but still a mean of thousands
    # a form error on gage row 3, early window: 10 noise rms of a 13 Hz ring
    t = np.arange(td.n_s) / td.fs_hz
    form = np.zeros_like(reps)
    form[..., 3, td.windows.early] = 10 * np.sin(2 * np.pi * 13.0 * t[td.windows.early]) / fw.W[0, 3, 0]
    cells = cell_energies(fw, reps + form, bands)
    kw2 = window_inflation(fw, cells, td.fitted)
    # the sine's mean square is 50 noise variances on top of 1
    assert kw2[3, 1] == pytest.approx(51, rel=0.1)
    assert np.all(np.delete(kw2[:, 1], 3) <= 1 + 5 * math.sqrt(2 / (n_rep * n)))
    kc2 = cell_inflation(fw, cells, bands, td.fitted)
    b13 = int(np.searchsorted(bands.edges_hz, 13.0, side="right")) - 1
    assert kc2[3, b13, 1] > 10 * kw2[3, 1] / 2      # concentrated in its own band's cell


def test_a_band_without_a_bin_in_a_window_is_neutral_not_nan(trial):
    """A band narrower than a short window's bin spacing holds no spectral bin there: its cell
    expects and holds no energy, so its inflation is 1 and its score 0 -- not 0/0, which made
    every candidate's dBIC NaN on trials whose lowest bands are narrow."""
    from ramdaq.analysis.gap.evidence import Bands, gap_map

    _, td = trial
    fw = Forward(td, np.full(td.n_gages, 1e-3))
    n_pre = len(range(*td.windows.pre.indices(td.n_s)))
    df = td.fs_hz / n_pre                                   # the pre window's bin spacing, Hz
    lo = 1.25 * df                                          # a band between two bins: (1.25, 1.75) df
    bands = Bands(np.array([0.0, lo, lo + 0.5 * df, td.lowpass_hz]), ["low", "narrow", "rest"],
                  np.array([0.5 * lo, lo + 0.25 * df, 0.5 * td.lowpass_hz]))
    rng = np.random.default_rng(3)
    reps = rng.standard_normal((6, td.n_seg, td.n_gages, td.n_s)) / fw.W
    cells = cell_energies(fw, reps, bands)
    assert np.all(cells[..., 1, 0] == 0)                    # the premise: no bin, no energy
    kc = cell_inflation(fw, cells, bands, td.fitted)
    assert np.all(np.isfinite(kc)) and np.all(kc[:, 1, 0] == 1.0)
    m = gap_map(fw, reps[0], cells, bands, td.fitted)
    assert np.all(np.isfinite(m.z)) and np.all(m.z[:, 1, 0] == 0.0)


def test_bounce_is_named_with_each_blows_delay(trial):
    tt, td = trial
    d = diagnose(td)
    assert d.best is not None and d.best.name == "double_hit", [c.name for c in d.candidates]
    term = d.best.terms[0]
    found = term.effect.pulses(term)[0][0]
    true = np.asarray(tt.effect.params["delays_s"])
    # to one sample of the record the diagnosis compares (3.4 ms at 292 Hz): a delay is read
    # from the phases of the modes below its 114 Hz corner, and trades against the blow's
    # calibrated duration (the richer simulator's contact is not the nominal half-sine's)
    step = 1 / td.fs_hz
    np.testing.assert_allclose(found, true, atol=step)
    assert term.value("ratio") == pytest.approx(0.3 * 0.5, rel=0.2)   # 0.3 x size (truth_effects)


def test_a_split_sits_about_the_calibrated_mode_or_beside_it(trial):
    """``centre = share`` keeps the halves' amplitude-weighted mean frequency at the calibrated
    mode (a narrow split read as one mode); ``centre`` 0 keeps the lower half there and puts the
    other ``split`` above it (a wide split, where the calibration locked on one peak)."""
    from ramdaq.analysis.gap.effects.base import Term
    from ramdaq.analysis.gap.effects.split_mode import SplitMode

    _, td = trial
    fw = Forward(td, np.full(td.n_gages, 1e-3))
    ms = fw.fit(np.zeros(len(fw.params))).modes
    pl = SplitMode().placements(fw, fw.fit(np.zeros(len(fw.params))))[0]
    i = int(np.argmin(np.abs(ms.f_hz - pl.mode_hz)))
    f = ms.f_hz[i]
    off = SplitMode().modes(ms, fw, Term(SplitMode(), pl, pl.x0))        # x0 is the effect off
    assert off.f_hz[i] == f and np.all(off.A[:, -1] == 0) and np.all(off.A[:, i] == ms.A[:, i])
    for s, share, c in [(0.03, 0.3, 0.3), (0.08, 0.5, 0.0), (0.08, 0.4, 1.0)]:
        out = SplitMode().modes(ms, fw, Term(SplitMode(), pl, np.array([s, share, c])))
        f_lo, f_hi = out.f_hz[i], out.f_hz[-1]
        assert f_hi / f_lo - 1 == pytest.approx(s / (1 - s * c), rel=1e-9)     # split apart
        assert f_lo == pytest.approx(f * (1 - s * c), rel=1e-9)
        np.testing.assert_allclose(out.A[:, i] + out.A[:, -1], ms.A[:, i], rtol=1e-12)
        np.testing.assert_allclose(out.A[:, -1], share * ms.A[:, i], rtol=1e-12)
        if c == share:
            assert (1 - share) * f_lo + share * f_hi == pytest.approx(f, rel=1e-9)


def test_more_candidates_are_refitted_only_while_none_closes_the_gap(trial):
    """Beyond the ``top_k`` strongest signatures, up to ``top_k_more`` further effects are
    refitted, in signature order, only while no refit closes ``close_enough`` of the gap."""
    from ramdaq.analysis.gap.diagnose import Settings
    from ramdaq.analysis.gap.verdict import closed_share

    _, td = trial
    d = diagnose(td, Settings(top_k=1, top_k_more=2))
    singles = [c for c in d.candidates if len(c.terms) == 1]
    assert closed_share(singles[0].record()) >= 0.8                 # the bounce closes its gap
    assert len(singles) == 1
    d = diagnose(td, Settings(top_k=1, top_k_more=2, close_enough=1.5))   # nothing closes 150 %
    live = [s.effect.name for s in d.signatures if s.placement is not None and s.z > -np.inf]
    # candidates come ranked by evidence, not in the order refitted
    assert {c.name for c in d.candidates if len(c.terms) == 1} == set(live[:3])


def test_the_refit_steps_stay_in_their_trust_region_and_still_converge():
    """A beat's phase makes a Gauss-Newton step land far beyond where its linearisation holds;
    the refit's steps are capped at ``max_step`` scales. On a decaying two-tone signal (the
    split mode's shape: frequencies f (1 -+ s/2), 8 Hz, 4 s, noise 1e-3 of the amplitude) the
    split is found from a start 40 % off it, and no step is longer than the cap."""
    from ramdaq.analysis.gap.calibrate import levenberg_marquardt

    t = np.arange(0.0, 4.0, 1 / 256)
    rng = np.random.default_rng(7)

    def signal(x: np.ndarray) -> np.ndarray:
        f, s, zeta = 8.0, x[0], x[1]
        env = np.exp(-2 * np.pi * f * zeta * t)
        return env * (np.sin(2 * np.pi * f * (1 - s / 2) * t) + np.sin(2 * np.pi * f * (1 + s / 2) * t))

    truth = np.array([0.05, 0.004])
    y = signal(truth) + 1e-3 * rng.standard_normal(t.size)
    seen: list[np.ndarray] = []

    def fun(x: np.ndarray) -> np.ndarray:
        seen.append(x.copy())
        return (signal(x) - y) / 1e-3

    scale = np.array([0.01, 0.002])
    res = levenberg_marquardt(fun, np.array([0.03, 0.01]), np.array([0.002, 0.0]), np.array([0.1, 0.05]),
                              scale, max_iter=100, max_step=3.0)
    # noise 1e-3 on 1024 samples of an O(1) signal: the split is known to ~1e-5; 1e-4 is 10 sd
    assert res.x[0] == pytest.approx(truth[0], abs=1e-4)
    assert res.x[1] == pytest.approx(truth[1], abs=1e-4)
    assert res.stop == "converged"
    # every trial point is the current one (an earlier trial point) plus a step of at most the
    # cap, or plus a difference step (rel_step 1e-3 of a scale)
    for k in range(1, len(seen)):
        nearest = min(np.linalg.norm((seen[k] - p) / scale) for p in seen[:k])
        assert nearest <= 3.0 + 1e-6, (k, nearest)


def test_a_brief_refit_never_differences_afresh():
    """``refresh=False`` (a start's brief refit): after its first Jacobian only Broyden steps,
    so a refit of ``p`` constants and ``max_iter`` steps costs at most 1 + p + max_iter
    predictions, and it never claims convergence. The same problem refreshed differences all
    three columns again at least once (its only way to converge), so it costs more."""
    from ramdaq.analysis.gap.calibrate import Stop, levenberg_marquardt

    t = np.linspace(0.0, 1.0, 20_000)
    rng = np.random.default_rng(5)
    y = 1.0 + 0.5 * np.exp(-2.0 * t) + 1e-2 * rng.standard_normal(t.size)
    calls = []

    def fun(x: np.ndarray) -> np.ndarray:
        calls.append(1)
        return (x[0] + x[1] * np.exp(-x[2] * t) - y) / 1e-2

    args = (np.array([0.9, 0.6, 1.5]), np.full(3, -10.0), np.full(3, 10.0), np.array([0.1, 0.1, 0.5]))
    brief = levenberg_marquardt(fun, *args, max_iter=6, refresh=False)
    n_brief = len(calls)
    assert n_brief == brief.nfev <= 1 + 3 + 6
    assert brief.stop in (Stop.SCREENED, Stop.ITERATION_LIMIT)
    calls.clear()
    full = levenberg_marquardt(fun, *args, max_iter=100)
    assert full.stop is Stop.CONVERGED and len(calls) > n_brief


def test_giving_up_is_not_convergence():
    """A cost with a cusp at the start (sqrt|x|): the differenced slope points downhill but
    every step it proposes raises the cost, so the solver gives up where it began, and says so
    instead of calling it converged."""
    from ramdaq.analysis.gap.calibrate import Stop, levenberg_marquardt

    def fun(x: np.ndarray) -> np.ndarray:
        return np.array([1.0 + 1e3 * np.sqrt(abs(x[0] - 0.5))])

    res = levenberg_marquardt(fun, np.array([0.5]), np.array([0.0]), np.array([1.0]),
                              np.array([0.1]), max_iter=100)
    assert res.stop is Stop.GAVE_UP
    assert res.x[0] == 0.5


def test_the_normal_equations_in_row_blocks_are_the_whole_products():
    """The LM step's normal equations are summed over blocks of rows of the scaled Jacobian
    (no scaled copy of it whole): over 2.5 blocks of rows they equal ``Js' Js`` and ``Js' r``
    of the whole scaled copy to the rounding of the sums (1e-12 of their scale: 1e5 terms each
    ~1e-16 relative), and a Jacobian of fewer rows than a block is the one product exactly."""
    from ramdaq.analysis.gap.calibrate import NORMAL_ROWS, _normal_equations

    rng = np.random.default_rng(2)
    J = rng.standard_normal((NORMAL_ROWS * 5 // 2, 7))
    r = rng.standard_normal(len(J))
    scale = np.exp(rng.normal(0, 2, 7))
    A, g = _normal_equations(J, r, scale)
    Js = J * scale
    assert np.allclose(A, Js.T @ Js, rtol=0, atol=1e-12 * np.abs(Js.T @ Js).max())
    assert np.allclose(g, Js.T @ r, rtol=0, atol=1e-12 * np.abs(Js).sum(axis=0).max())
    A1, g1 = _normal_equations(J[:1000], r[:1000], scale)
    assert np.array_equal(A1, Js[:1000].T @ Js[:1000]) and np.array_equal(g1, Js[:1000].T @ r[:1000])


def test_a_pulse_long_before_its_contact_stays_finite_and_exact(trial):
    """A strongly damped mode's response to a contact that begins long after a segment's start
    (a second hit; an overdamped calibrated hull mode) is J(T) e^{lambda (t - T)} after the
    contact and nothing before it -- not an overflow of e^{-lambda lag} at the segment's start."""
    _, td = trial
    fw = Forward(td, np.full(td.n_gages, 1e-3))
    ms = fw.fit(np.zeros(len(fw.params))).modes.copy()
    ms.lam[0] = -3000.0 + 1j * ms.lam[0].imag          # |lambda lag| = 1500 at lag -0.5 s
    E, JT = fw.pulse_basis(ms)
    T = ms.duration_s
    for tau0 in (-0.5, -0.01, 0.02):
        u, _ = fw.pulse_response(ms, tau0, (E, JT))
        t = tau0 + np.arange(td.n_s) / td.fs_hz
        after = t >= T + 1e-9
        lag = np.where(ms.exp_only[:, None], t[None, after], t[None, after] - T)
        direct = np.real(ms.A @ (JT[:, None] * np.exp(ms.lam[:, None] * lag)))
        assert np.all(np.isfinite(u))
        assert np.all(u[:, t <= 0] == 0)
        # the same sums in another order: rounding only (1e-9 of the largest response)
        assert np.max(np.abs(u[:, after] - direct)) <= 1e-9 * np.max(np.abs(direct))


def test_a_pulse_is_exact_at_every_sample_wherever_its_contact_falls(trial):
    """Each sample of a contact's response is 0 before the contact, the closed form J(t) during
    it and J(T) e^{lambda (t - T)} after it, wherever the contact falls between samples --
    also where a sample sits on t = 0 or t = T to within an ulp, where the segment's clock
    ``t`` and the decay's clock ``t - T`` may put it on different sides."""
    _, td = trial
    fw = Forward(td, np.full(td.n_gages, 1e-3))
    ms = fw.fit(np.zeros(len(fw.params))).modes
    E, JT = fw.pulse_basis(ms)
    T, dt = ms.duration_s, 1 / td.fs_hz
    taus = [c + e for k in (0, 1, 2, 7, 40) for c in (T - k * dt, -k * dt)
            for e in (-2e-16, -1e-16, 0.0, 1e-16, 2e-16, 0.37 * dt)]
    for tau0 in taus:
        u, _ = fw.pulse_response(ms, tau0, (E, JT))
        t = tau0 + np.arange(td.n_s) / td.fs_hz
        ref = np.zeros_like(u)
        during, after = (t > 0) & (t < T), t >= T
        ref[:, during] = (np.real(ms.A @ half_sine_response(ms.lam, T, t[during]))
                          + ms.feed[:, None] * np.sin(math.pi / T * t[during]))
        ref[:, after] = np.real(ms.A @ (JT[:, None] * np.exp(ms.lam[:, None] * (t[after] - T))))
        # J is continuous at 0 and T, so a sample an ulp to either side differs by rounding
        # only (1e-9 of the largest response); a sample left unset would be off by O(1)
        assert np.max(np.abs(u - ref)) <= 1e-9 * np.max(np.abs(ref)), tau0


def test_a_split_is_only_placed_where_the_widest_split_is_resolved(trial):
    """Two modes are told apart only when further apart than the half-power bandwidth 2 zeta: a
    mode damped beyond what the widest fitted split resolves gets no split placement."""
    from dataclasses import replace

    from ramdaq.analysis.gap.effects.base import compared_modes
    from ramdaq.analysis.gap.effects.split_mode import MAX_SPLIT, SplitMode

    _, td = trial
    fw = Forward(td, np.full(td.n_gages, 1e-3))
    fit = fw.fit(np.zeros(len(fw.params)))
    modes = compared_modes(fw, fit)
    placed = {pl.key["mode_hz"] for pl in SplitMode().placements(fw, fit)}
    assert placed == {round(f, 3) for _, f in modes}          # the rig's modes are all lightly damped
    i, f = modes[0]
    ms = fit.modes.copy()
    w = abs(ms.lam[i])
    zeta = 0.6 * MAX_SPLIT                                    # 2 zeta = 1.2 x the widest split
    ms.lam[i] = w * (-zeta + 1j * math.sqrt(1 - zeta**2))
    placed = {pl.key["mode_hz"] for pl in SplitMode().placements(fw, replace(fit, modes=ms))}
    assert round(ms.f_hz[i], 3) not in placed and len(placed) == len(modes) - 1


def test_the_blockwise_score_basis_projects_as_a_dense_qr_of_the_design_does(trial):
    """The score basis is kept block by block (the impacts' columns only where they ring, the
    Jacobian dense) and projects by normal equations applied twice: the same projection as an
    orthonormal basis of the whole stacked design, to rounding."""
    import scipy.linalg

    from ramdaq.analysis.gap.calibrate import Calibration, Stop
    from ramdaq.analysis.gap.evidence import ScoreBasis

    _, td = trial
    fw = Forward(td, np.full(td.n_gages, 1e-3))
    fit = fw.fit(np.zeros(len(fw.params)))
    fitted = np.flatnonzero(td.fitted)
    N = fitted.size * td.n_gages * td.n_s
    rng = np.random.default_rng(3)
    jac = rng.standard_normal((N, 3))     # dense directions, as the calibration's Jacobian is
    cal = Calibration(np.zeros(len(fw.params)), [], fit, 0.0, 0.0, jac, 3, 1, Stop.NOTHING_TO_FIT)
    reps = rng.standard_normal((6,) + td.x.shape) / fw.W
    basis = ScoreBasis(fw, cal, reps)
    # the dense reference: every column alive somewhere in the fitted segments, stacked
    U, dU, _ = cal.columns(fw)
    w = fw.mask[fitted] * fw.W[fitted]
    cols = [(c[fitted] * w).ravel() for c in list(U) + list(dU)]
    B = np.column_stack([c for c in cols if c.any()] + [jac])
    Q = scipy.linalg.qr(B, mode="economic")[0]
    D = rng.standard_normal((4, N)) + (B @ rng.standard_normal((B.shape[1], 4))).T
    ref = D - (D @ Q) @ Q.T
    # normal equations lose at most cond^2 eps of |D| a pass: 1.4e-9 at this design's cond 2.5e3
    np.testing.assert_allclose(basis.project(D), ref, rtol=0, atol=1e-9 * np.abs(D).max())
    Rw = np.nan_to_num(reps[:, fitted] * fw.W[fitted]).reshape(len(reps), -1)
    np.testing.assert_allclose(basis.reps_dot(ref), Rw @ ref.T, rtol=1e-12, atol=1e-9)


def test_the_replicates_made_from_unit_blocks_are_the_dense_forms_to_the_last_bit(trial):
    """The replicates' model-form change is made segment by segment from the unit blocks a
    pulse writes (no dense (n_imp, n_seg, n_g, n_s) difference touched whole per replicate):
    the same numbers, bit for bit, as ``force . (U_r - U)`` over the dense unit responses, and
    the design they are re-solved with is the one the dense unit responses make."""
    from ramdaq.analysis.gap.calibrate import Calibration, Stop
    from ramdaq.analysis.gap.evidence import DECAY_TOL_PER_FORM_TOL, noise_model, replicate_residuals

    _, td = trial
    fw = Forward(td, np.full(td.n_gages, 1e-3))
    fit = fw.fit(np.zeros(len(fw.params)))
    cal = Calibration(np.zeros(len(fw.params)), [], fit, 0.0, 0.0, None, 0, 1, Stop.NOTHING_TO_FIT)
    noise = noise_model(fw, fit.resid)
    got = replicate_residuals(fw, cal, noise, 3, seed=5, form_tol=0.02)
    rng = np.random.default_rng(5)
    U, dU, extra = cal.columns(fw)
    design = fw.linear_design(U, dU, extra)
    for r in range(3):       # the dense form, as the replicates were made before
        x = fit.pred + noise.draw(rng, td.n_seg)
        ms = fit.modes.copy()
        xi = rng.standard_normal(ms.A.shape) + 1j * rng.standard_normal(ms.A.shape)
        ms.A = ms.A * (1 + 0.02 * xi / math.sqrt(2))
        ms.lam = ms.lam + ms.lam.real * DECAY_TOL_PER_FORM_TOL * 0.02 * rng.standard_normal(ms.lam.shape)
        Ur = fw.unit_responses(ms)[0] - U
        x = x + np.tensordot(fit.force, Ur, axes=1)
        want = np.where(fw.mask, x - design.solve(x)[1], np.nan)
        assert np.array_equal(got[r], want, equal_nan=True)


def test_the_prediction_rate_and_score_basis_from_blocks_are_the_dense_ones_to_the_bit(trial, monkeypatch):
    """A calibration's prediction rate (a time skew's template) and a score basis's design are
    made from the unit blocks a pulse writes (a friction term's added), not from the dense unit
    responses: the same numbers to the bit, with no term and with a friction term."""
    from ramdaq.analysis.gap.calibrate import Calibration, Stop
    from ramdaq.analysis.gap.effects import EFFECTS
    from ramdaq.analysis.gap.evidence import ScoreBasis
    from ramdaq.analysis.gap.terms import Term

    _, td = trial
    fw = Forward(td, np.full(td.n_gages, 1e-3))
    theta = np.zeros(len(fw.params))
    fric = EFFECTS["friction"]
    pl = fric.placements(fw, fw.fit(theta))[0]
    N = int(td.fitted.sum()) * td.n_gages * td.n_s
    jac = np.random.default_rng(4).standard_normal((N, 2))
    reps = np.zeros((2,) + td.x.shape)
    for terms in ([], [Term(fric, pl, np.array([0.3]))]):
        fit = fw.fit(theta, terms)
        got = {}
        for how in ("blocks", "dense"):
            if how == "dense":
                monkeypatch.setattr(Forward, "term_blocks", lambda *a, **k: None)
            cal = Calibration(theta, terms, fit, 0.0, 0.0, jac, 2, 1, Stop.NOTHING_TO_FIT)
            got[how] = cal.pred_rate(fw), ScoreBasis(fw, cal, reps)
        monkeypatch.undo()
        np.testing.assert_array_equal(got["blocks"][0], got["dense"][0])
        b, d = got["blocks"][1], got["dense"][1]
        assert b.n_lin == d.n_lin and len(b.blocks) == len(d.blocks)
        for (i1, X1), (i2, X2) in zip(b.blocks, d.blocks, strict=True):
            np.testing.assert_array_equal(i1, i2)
            np.testing.assert_array_equal(X1, X2)
        assert np.abs(got["blocks"][0]).max() > 0
