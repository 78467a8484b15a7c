"""Tests for the parametric modal estimator (ramdaq.analysis.modal.identify) and decay verdicts.

SNR is A²/(2σ²) of each mode's initial amplitude (ramdaq.analysis.modal.crb's convention). Tolerances:
single-mode δ and f within 4 Cramér–Rao standard deviations (a 4σ event, probability 6·10⁻⁵ per
check for an efficient estimator); Monte-Carlo checks use 150 noise seeds, for which the sample
std has a relative standard error of 1/√(2·149) ≈ 5.8 %, so ±20 % is a 3.4σ tolerance.
"""

import numpy as np
import pytest

from ramdaq.analysis.modal.crb import crb_damped_sinusoid
from ramdaq.analysis.modal.identify import identify_modes
from ramdaq.analysis.modal.signal import (
    damped_sinusoids,
    decimate_valid,
    decimated_index,
    fir_gain,
    fir_noise_variance_factor,
)
from ramdaq.analysis.modal.varpro import _Problem
from ramdaq.analysis.modal.verdicts import Verdict, assess_decay, assess_decay_jointly

pytestmark = pytest.mark.timeout(120)

FS_HZ = 2048.0


def noise_std_from_periodogram(snr_db, amplitude=1.0):
    return amplitude / np.sqrt(2 * 10 ** (snr_db / 10))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_single_mode_at_40_db_within_four_crb(seed):
    rng = np.random.default_rng(seed)
    f0, d0, n = 24.5, 0.06, int(20 * FS_HZ / 24.5)
    sigma = noise_std_from_periodogram(40)
    x = damped_sinusoids(FS_HZ, n, [f0], [d0], [1.0], [rng.uniform(0, 2 * np.pi)])
    x = x + sigma * rng.standard_normal(n)
    tab = identify_modes(x, FS_HZ)
    crb = crb_damped_sinusoid(1.0, d0, f0, sigma, n, FS_HZ)
    assert len(tab) == 1
    assert abs(tab.delta[0] - d0) < 4 * crb.delta_std
    assert abs(tab.frequency_hz[0] - f0) < 4 * crb.f_std_hz
    assert tab.delta_se[0] == pytest.approx(crb.delta_std, rel=0.2)
    assert tab.zeta[0] == pytest.approx(d0 / np.hypot(2 * np.pi, d0), rel=0.01)


@pytest.mark.parametrize("n_channels", [1, 4])
def test_two_modes_three_percent_apart_are_separated(n_channels):
    rng = np.random.default_rng(5)
    f, d = [24.5, 24.5 * 1.03], [0.06, 0.07]
    n = int(30 * FS_HZ / 24.5)
    amp = np.abs(rng.normal(1.0, 0.3, (n_channels, 2)))
    x = damped_sinusoids(FS_HZ, n, f, d, amp, rng.uniform(0, 2 * np.pi, amp.shape))
    x = x + noise_std_from_periodogram(30) * rng.standard_normal(x.shape)
    tab = identify_modes(x, FS_HZ)
    assert len(tab) == 2
    np.testing.assert_allclose(tab.frequency_hz, f, rtol=2e-3)
    np.testing.assert_allclose(tab.delta, d, rtol=0.05)


def test_standard_errors_agree_with_monte_carlo():
    f0, d0, n, sigma = 24.5, 0.08, int(10 * FS_HZ / 24.5), noise_std_from_periodogram(25)
    est, se = [], []
    for seed in range(150):
        rng = np.random.default_rng(1000 + seed)
        x = damped_sinusoids(FS_HZ, n, [f0], [d0], [1.0], [rng.uniform(0, 2 * np.pi)])
        tab = identify_modes(x + sigma * rng.standard_normal(n), FS_HZ, n_modes=1,
                             per_channel=False)
        est.append([tab.delta[0], tab.frequency_hz[0]])
        se.append([tab.delta_se[0], tab.frequency_se_hz[0]])
    est, se = np.array(est), np.array(se)
    ratio = se.mean(axis=0) / est.std(axis=0, ddof=1)
    assert np.all((ratio > 0.8) & (ratio < 1.25)), ratio
    crb = crb_damped_sinusoid(1.0, d0, f0, sigma, n, FS_HZ)
    assert est[:, 0].std(ddof=1) < 1.25 * crb.delta_std  # efficient (offset fitted too)
    assert abs(est[:, 0].mean() - d0) < 4 * est[:, 0].std(ddof=1) / np.sqrt(150)


@pytest.mark.parametrize("n_channels", [1, 4])
def test_no_modes_are_invented_in_noise(n_channels):
    for seed in range(20):
        x = np.random.default_rng(seed).standard_normal((n_channels, 4096))
        assert len(identify_modes(x, FS_HZ)) == 0


def test_coloured_noise_does_not_widen_the_band():
    from scipy import signal as sp_signal

    from ramdaq.analysis.modal.signal import estimate_noise_std, significant_band_hz

    # Noise ~1.6 times the median-based white level below 700 Hz and ~0.3 above (a converter's
    # anti-alias roll-off): a white-noise threshold crosses it in every record.
    b, a = sp_signal.butter(4, 700.0, fs=FS_HZ)
    rng = np.random.default_rng(31)
    hits = 0
    for _ in range(20):
        w = rng.standard_normal((16, 12488))
        x = (sp_signal.lfilter(b, a, w, axis=-1) + 0.3 * w)[:, 200:]
        hits += significant_band_hz(x, FS_HZ, estimate_noise_std(x), false_alarm=0.05) is not None
    # At false_alarm 0.05, 20 records: 5 or more with probability 1.6 % (binomial); the
    # white-noise threshold alone gave 20 of 20.
    assert hits <= 4


def test_order_selection_on_albacore_like_record():
    rng = np.random.default_rng(7)
    f, d = [20.1, 24.5, 123.0], [0.07, 0.06, 0.05]
    amp = rng.normal(size=(8, 3)) * [0.3, 1.0, 0.1]
    ph = rng.uniform(0, 2 * np.pi, amp.shape)
    x = damped_sinusoids(FS_HZ, int(2 * FS_HZ), f, d, amp, ph)
    x = x + 0.01 * rng.standard_normal(x.shape)
    tab = identify_modes(x, FS_HZ)
    assert len(tab) == 3
    np.testing.assert_allclose(tab.frequency_hz, f, rtol=1e-3)
    np.testing.assert_allclose(tab.delta, d, rtol=0.03)
    np.testing.assert_allclose(tab.complex_amplitude, amp * np.exp(1j * ph), atol=0.01)
    shape = tab.mode_shape
    np.testing.assert_allclose(np.max(np.abs(shape), axis=0), 1.0)
    np.testing.assert_allclose(shape, tab.complex_amplitude / tab.complex_amplitude[
        np.argmax(tab.amplitude, axis=0), np.arange(3)], rtol=1e-12)
    # per-gage decrements (Eq 7) agree with the shared one within their errors
    ok = np.isfinite(tab.channel_delta[:, 1])
    assert ok.sum() >= 6
    z = (tab.channel_delta[ok, 1] - 0.06) / tab.channel_delta_se[ok, 1]
    assert np.all(np.abs(z) < 5)
    # reporting band
    tab_lo = identify_modes(x, FS_HZ, f_range_hz=(15.0, 30.0), per_channel=False)
    np.testing.assert_allclose(tab_lo.frequency_hz, f[:2], rtol=1e-3)


def test_steady_tone_beside_the_decay_is_a_separate_undamped_mode():
    # SAMPSON: the hull bending at 2.18 Hz rings on through the impact's decay at 2.18 Hz.
    rng = np.random.default_rng(3)
    n = int(15 * FS_HZ)
    x = damped_sinusoids(FS_HZ, n, [2.18], [0.04], [[1.0], [0.7]], [[0.2], [1.0]])
    x = x + damped_sinusoids(FS_HZ, n, [2.18], [0.0], [[0.2], [0.1]], [[2.0], [2.5]])
    tab = identify_modes(x + 0.01 * rng.standard_normal(x.shape), FS_HZ)
    assert len(tab) == 2
    k = int(np.argmax(tab.delta))
    assert tab.delta[k] == pytest.approx(0.04, rel=0.05)
    assert abs(tab.delta[1 - k]) < 0.005


def test_dead_channel_is_left_out_and_decimation_path_agrees():
    rng = np.random.default_rng(9)
    n = 8192
    x = damped_sinusoids(FS_HZ, n, [13.0, 45.0], [0.12, 0.10], [[1.0, 0.3], [0.5, 0.5]],
                         [[0.0, 1.0], [2.0, 3.0]])
    x = np.vstack([x, np.zeros(n)]) + np.r_[0.01, 0.01, 0.0][:, None] * rng.standard_normal((3, n))
    full = identify_modes(x, FS_HZ)
    deci = identify_modes(x, FS_HZ, max_samples=4000)
    assert deci.info["decimation"] > 1 and full.info["decimation"] == 1
    assert np.all(np.isnan(full.complex_amplitude[2])) and np.isnan(full.noise_std[2])
    np.testing.assert_allclose(deci.frequency_hz, full.frequency_hz, rtol=1e-3)
    assert np.all(np.abs(deci.delta - full.delta) < 5 * deci.delta_se)
    np.testing.assert_allclose(deci.complex_amplitude[:2], full.complex_amplitude[:2], atol=0.02)
    np.testing.assert_allclose(deci.noise_std[:2], 0.01, rtol=0.2)


@pytest.mark.parametrize("method", ["esprit", "era"])
def test_starts_reach_the_same_optimum(method):
    rng = np.random.default_rng(4)
    x = damped_sinusoids(FS_HZ, 3000, [24.5, 25.2], [0.06, 0.07], [[1.0, 0.8], [0.4, 1.0]],
                         [[0.0, 1.0], [2.0, 3.0]]) + 0.01 * rng.standard_normal((2, 3000))
    a, b = identify_modes(x, FS_HZ), identify_modes(x, FS_HZ, method=method)
    np.testing.assert_allclose(b.frequency_hz, a.frequency_hz, rtol=1e-7)
    np.testing.assert_allclose(b.delta, a.delta, rtol=1e-5)


def test_normal_equations_match_an_explicit_jacobian():
    # The fast twin (4K × 4K normal equations) against a plainly built Kaufman Jacobian
    # −P⊥ (∂Φ/∂θᵢ) B, with ∂Φ/∂θᵢ by central differences.
    rng = np.random.default_rng(2)
    t = np.arange(700) / FS_HZ
    Y = (damped_sinusoids(FS_HZ, 700, [24.5, 30.0], [0.06, 0.1], rng.normal(size=(3, 2)))
         + 0.01 * rng.standard_normal((3, 700))).T
    prob, theta = _Problem(t, Y, True), np.array([24.4, 0.065, 30.1, 0.09])
    r, proj, B = prob.residual(theta)
    JtJ, Jtr = prob.normal_equations(theta, r, proj, B)
    Phi = proj.Phi
    perp = np.eye(t.size) - Phi @ np.linalg.pinv(Phi)
    cols = []
    for i in range(4):
        h = 1e-6 * max(abs(theta[i]), 1.0) * np.eye(4)[i]
        dPhi = (prob.residual(theta + h)[1].Phi - prob.residual(theta - h)[1].Phi) / (2 * h[i])
        cols.append((-perp @ dPhi @ B).ravel())
    J = np.stack(cols, axis=1)
    np.testing.assert_allclose(Jtr, J.T @ r.ravel(), rtol=1e-5)
    np.testing.assert_allclose(JtJ, J.T @ J, rtol=1e-5)


@pytest.mark.parametrize(
    ("x", "kwargs", "match"),
    [
        (np.full((2, 100), np.nan), {}, "non-finite"),
        (np.zeros((2, 10)), {}, "n_samples"),
        (np.zeros((2, 100)), {"method": "prony"}, "method"),
        (np.zeros((2, 100)), {"n_modes": 0}, "n_modes"),
    ],
)
def test_bad_arguments(x, kwargs, match):
    with pytest.raises(ValueError, match=match):
        identify_modes(x, FS_HZ, **kwargs)


def test_verdicts():
    rng = np.random.default_rng(0)
    n = int(20 * FS_HZ / 24.5)

    def decay(delta, amp=1.0):
        return damped_sinusoids(FS_HZ, n, [24.5], [delta], [amp], [0.3])

    noise = 0.01 * rng.standard_normal((6, n))
    x = np.vstack([
        decay(0.06) + noise[0],
        np.zeros(n),                              # dead
        np.clip(decay(0.06, 3.0), -1.0, 1.0),     # clipped
        decay(-0.03) + noise[3],                  # growing
        decay(0.0) + noise[4],                    # steady tone
        noise[5],                                 # no signal
    ])
    got = assess_decay(x, FS_HZ)
    assert [a.verdict for a in got] == [Verdict.OK, Verdict.DEAD, Verdict.CLIPPED,
                                        Verdict.NEGATIVE_DAMPING, Verdict.NO_DECAY,
                                        Verdict.NO_DECAY]
    assert all(isinstance(a.reason, str) and "\n" not in a.reason for a in got)
    assert got[0].delta == pytest.approx(0.06, rel=0.02)
    # at the converter's rail
    rail = assess_decay(np.clip(decay(0.06, 3.0), -2.0, 2.0), FS_HZ, adc_full_scale=2.0)
    assert rail[0].verdict is Verdict.CLIPPED and "rail" in rail[0].reason
    # two cycles only
    m = int(2 * FS_HZ / 24.5)
    short = damped_sinusoids(FS_HZ, m, [24.5], [0.06], [1.0]) + 0.01 * rng.standard_normal(m)
    assert assess_decay(short, FS_HZ)[0].verdict is Verdict.TOO_FEW_CYCLES



def test_verdicts_from_the_joint_fit_equal_each_channel_judged_alone():
    """The verdicts read off one joint fit are those of each channel judged on its own (its own
    order search), and only the channels that are not ``ok`` were searched on their own: a
    usable channel's verdict costs no search of its own."""
    rng = np.random.default_rng(1)
    n = int(20 * FS_HZ / 24.5)
    modes = ([24.5, 61.0], [0.06, 0.02])

    def decay(amps, delta=None):
        return damped_sinusoids(FS_HZ, n, modes[0], delta or modes[1], amps,
                                rng.uniform(0, 2 * np.pi, 2))

    x = np.vstack([
        decay([1.0, 0.3]), decay([0.5, 0.6]), decay([0.05, 1.0]), decay([1.0, 0.0]),
        decay([1.0, 0.0], [-0.03, 0.02]),         # growing
        np.zeros(n),                               # no signal: noise only, below
    ]) + 0.01 * rng.standard_normal((6, n))
    joint = assess_decay_jointly(x, FS_HZ)
    alone = [assess_decay(x[c], FS_HZ)[0] for c in range(x.shape[0])]
    assert [a.verdict for a in joint.verdicts] == [a.verdict for a in alone]
    assert [a.verdict for a in joint.verdicts][:4] == [Verdict.OK] * 4
    not_ok = sum(a.verdict is not Verdict.OK for a in joint.verdicts)
    # the noise-only channel stops at the spectral-peak screen, before any fit
    assert joint.own_searches <= not_ok and joint.own_searches >= 1
    tab = joint.table
    for c, (a, b) in enumerate(zip(joint.verdicts[:4], alone[:4], strict=True)):
        # the channel's own fit, started from the shared poles or after its own search: two
        # fits of one channel's data that may differ in the weak modes they carry (those
        # significant in the joint fit, or found by the channel's search), so they agree to
        # within the estimate's standard error, not to rounding (seeds 1-5: at most 0.91 SE)
        j = joint.rows.index(c)
        k = int(np.nanargmin(np.abs(tab.channel_frequency_hz[j] - a.f_hz)))  # its dominant mode
        assert abs(a.f_hz - b.f_hz) < tab.channel_frequency_se_hz[j, k]
        assert abs(a.delta - b.delta) < tab.channel_delta_se[j, k]

# --- Fast paths (performance work): each must reproduce the plain computation it replaces. ---


def test_blocked_basis_matches_direct_exponentials():
    from ramdaq.analysis.modal.varpro import damped_basis, uniform_grid

    f, d = np.array([6.8, 59.8, 215.5, 334.0]), np.array([0.12, 0.015, 0.002, -0.01])
    for t in (np.arange(14296) / FS_HZ, (40 + 3 * np.arange(3000)) / FS_HZ):
        grid = uniform_grid(t)
        assert grid is not None
        blocked, direct = damped_basis(t, f, d, True, grid), damped_basis(t, f, d, True)
        np.testing.assert_allclose(blocked, direct, rtol=0, atol=1e-11 * np.max(np.abs(direct)))
    # an envelope beyond the clamp (e^300) takes the direct path: identical
    t = np.arange(2000) / FS_HZ
    f, d = np.array([300.0]), np.array([-2.0])
    np.testing.assert_array_equal(damped_basis(t, f, d, False, uniform_grid(t)), damped_basis(t, f, d, False))
    assert uniform_grid(np.sort(np.random.default_rng(0).uniform(0, 1, 500))) is None


def test_hankel_gram_recursion_and_partial_eigensolver_match_explicit():
    from ramdaq.analysis.modal.subspace import _hankel_gram, hankel_row_space

    rng = np.random.default_rng(8)
    for n_ch, n, L, cplx in ((1, 2000, 400, False), (5, 900, 300, False), (2, 60, 20, True)):
        y = rng.standard_normal((n_ch, n)) + (1j * rng.standard_normal((n_ch, n)) if cplx else 0)
        G = sum(np.lib.stride_tricks.sliding_window_view(r, L + 1).conj().T
                @ np.lib.stride_tricks.sliding_window_view(r, L + 1) for r in y)
        Gr = _hankel_gram(y, L)
        # every entry, the lower triangle included (it was once left uninitialised)
        np.testing.assert_allclose(Gr, G, rtol=0, atol=1e-13 * np.max(np.abs(G)))
        np.testing.assert_array_equal(Gr, Gr.conj().T)
        s_all, V_all = hankel_row_space(y, L)
        s_top, V_top = hankel_row_space(y, L, n_vectors=7)
        w = np.linalg.eigvalsh(G)[::-1]
        np.testing.assert_allclose(s_all**2, w, rtol=1e-10, atol=1e-10 * w[0])
        np.testing.assert_allclose(s_top, s_all[:7], rtol=1e-12)
        overlap = np.abs(np.sum(V_top.conj() * V_all[:, :7], axis=0))
        np.testing.assert_allclose(overlap, 1.0, atol=1e-10)


def test_held_poles_problem_is_the_theta_block_of_the_full_problem():
    from ramdaq.analysis.modal.varpro import damped_basis

    rng = np.random.default_rng(6)
    t = np.arange(3000) / FS_HZ
    Y = damped_sinusoids(FS_HZ, 3000, [13.0, 59.8, 120.0], [0.1, 0.015, 0.01],
                         rng.normal(size=(3, 3))) + 0.01 * rng.standard_normal((3, 3000))
    held = np.array([13.02, 0.11, 59.7, 0.016])
    free = np.array([120.3, 0.02])
    full_theta = np.r_[free, held]
    p_held = _Problem(t, Y.T, True, fixed=damped_basis(t, held[0::2], held[1::2], True))
    p_full = _Problem(t, Y.T, True)
    r_h, proj_h, B_h = p_held.residual(free)
    r_f, proj_f, B_f = p_full.residual(full_theta)
    np.testing.assert_allclose(r_h, r_f, atol=1e-12 * np.max(np.abs(Y)))
    np.testing.assert_allclose(B_h, B_f[:2], rtol=1e-10)
    JtJ_h, Jtr_h = p_held.normal_equations(free, r_h, proj_h, B_h)
    JtJ_f, Jtr_f = p_full.normal_equations(full_theta, r_f, proj_f, B_f)
    np.testing.assert_allclose(JtJ_h, JtJ_f[:2, :2], rtol=1e-9)
    np.testing.assert_allclose(Jtr_h, Jtr_f[:2], rtol=1e-7, atol=1e-9 * np.max(np.abs(Jtr_f)))


def test_buffer_reuse_does_not_change_fits(monkeypatch):
    from ramdaq.analysis.modal import varpro as modal_varpro

    rng = np.random.default_rng(12)
    t = np.arange(5000) / FS_HZ
    y = damped_sinusoids(FS_HZ, 5000, [24.5, 25.2, 90.0], [0.06, 0.07, 0.01],
                         rng.normal(size=(2, 3))) + 0.01 * rng.standard_normal((2, 5000))
    kwargs = {"f0_hz": [24.4, 25.3, 90.2], "delta0": [0.05, 0.08, 0.012]}
    a = modal_varpro.fit_modes_varpro(t, y, **kwargs)
    monkeypatch.setattr(modal_varpro._Problem, "release",
                        lambda self, proj, keep_residual=False: None)
    b = modal_varpro.fit_modes_varpro(t, y, **kwargs)
    for name in ("f_hz", "delta", "covariance", "amplitude", "rss"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


@pytest.mark.parametrize("noise", [1e-2, 1e-5])  # at 1e-5 the strong mode leaves Σr² < 1e-4 Σy²
def test_held_pole_fits_from_grams_match_formed_residuals(noise):
    from ramdaq.analysis.modal.varpro import HeldPoleFitter

    rng = np.random.default_rng(21)
    t = np.arange(6000) / FS_HZ
    f, d = np.array([24.5, 90.0]), np.array([0.06, 0.01])
    y = damped_sinusoids(FS_HZ, 6000, f, d, rng.normal(size=(4, 2))) \
        + noise * rng.standard_normal((4, 6000))
    w = np.full(4, 1.0 / noise)
    fits = []
    for grams in (False, True):
        held = HeldPoleFitter(t, y, f[1:], d[1:], weights=w, fit_offset=True, grams=grams)
        # a strong mode (Σr² ≪ Σy²: formed residuals), a noise candidate (Grams) and one
        # beside the held 90 Hz mode (its projected columns lose digits: formed again)
        fits.append([held.fit(np.r_[fc], np.r_[dc], f_bounds_hz=(0.1, 900.0),
                              delta_bounds=(-3.0, 3.0), chi2_tol=1e-3)
                     for fc, dc in ((24.4, 0.05), (300.0, 0.02), (90.02, 0.01))])
    for (f0, d0, rss0, _, _), (f1, d1, rss1, _, _) in zip(*fits, strict=True):
        # Both converge to 10⁻³ of the residual variance per degree of freedom: the poles
        # agree far inside their standard errors (≥ 10⁻⁵ Hz here), Σr² to ~10⁻⁹ of itself.
        np.testing.assert_allclose(f1, f0, rtol=1e-7)
        np.testing.assert_allclose(d1, d0, rtol=1e-4, atol=1e-6)
        np.testing.assert_allclose(rss1, rss0, rtol=1e-8)


def test_one_factorisation_significance_matches_drop_one_refits():
    from ramdaq.analysis.modal.order import ModeSelector
    from ramdaq.analysis.modal.varpro import fit_modes_varpro, linear_amplitudes

    rng = np.random.default_rng(10)
    t = np.arange(4000) / FS_HZ
    f, d = np.array([24.5, 24.5 * 1.01, 130.0, 0.3]), np.array([0.06, 0.07, 0.01, 0.5])
    y = damped_sinusoids(FS_HZ, 4000, f, d, rng.normal(size=(3, 4))) \
        + 0.01 * rng.standard_normal((3, 4000))
    fit = fit_modes_varpro(t, y, f, d)
    sel = ModeSelector(y, t, True, 100.0, 0.3, (0.1, 1000.0), np.ones(3))
    sel.fit = fit
    keep = [np.arange(4) != k for k in range(4)]
    refits = [sel._lr(linear_amplitudes(t, y, fit.f_hz[m], fit.delta[m])[2], fit) for m in keep]
    np.testing.assert_allclose(sel.significance(), refits, rtol=1e-6)


def _same_table(a, b):
    """Two ModeTables equal bit for bit (NaN where NaN), info included."""
    for name in a.__dataclass_fields__:
        u, v = getattr(a, name), getattr(b, name)
        if isinstance(u, dict):
            assert u.keys() == v.keys(), name
            for k in u:
                np.testing.assert_array_equal(u[k], v[k], err_msg=f"{name}[{k!r}]", strict=True)
        else:
            np.testing.assert_array_equal(u, v, err_msg=name, strict=True)


def _threading_records():
    rng = np.random.default_rng(21)
    f, d = [20.1, 24.5, 123.0], [0.07, 0.06, 0.05]
    amp = rng.normal(size=(6, 3)) * [0.3, 1.0, 0.1]
    multi = damped_sinusoids(FS_HZ, 3000, f, d, amp, rng.uniform(0, 2 * np.pi, amp.shape))
    multi = multi + 0.01 * rng.standard_normal(multi.shape)
    drift = 0.02 * np.arange(4000) / FS_HZ  # a drift too: the nuisance-term path
    single = damped_sinusoids(FS_HZ, 4000, [24.5, 59.8], [0.06, 0.02], [1.0, 0.3]) + drift
    single = single + 0.005 * rng.standard_normal(4000)
    return multi, single


def test_concurrent_calls_from_two_threads_equal_sequential_results():
    """Correctness, not timing: the live trial fits in an analyzer thread while the main thread
    reads the device, and its numbers must equal a replay's to the last bit. Two threads fit
    different records at the same time, repeatedly; every table equals the sequential one."""
    import threading

    records = _threading_records()
    sequential = [identify_modes(x, FS_HZ) for x in records]
    assert all(len(t) > 0 for t in sequential)
    rounds = 3
    results: list[list] = [[], []]
    errors: list[BaseException] = []
    start = threading.Barrier(2)

    def work(i):
        try:
            start.wait()
            for _ in range(rounds):
                results[i].append(identify_modes(records[i], FS_HZ))
        except BaseException as err:  # noqa: BLE001 - re-raised in the main thread
            errors.append(err)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=100)
    assert not errors, errors
    assert not any(t.is_alive() for t in threads)
    for i in range(2):
        assert len(results[i]) == rounds
        for tab in results[i]:
            _same_table(tab, sequential[i])
    # and sequentially again afterwards, in the other order: nothing carried between calls
    for x, ref in reversed(list(zip(records, sequential, strict=True))):
        _same_table(identify_modes(x, FS_HZ), ref)


def test_no_uninitialised_memory_reaches_the_results(monkeypatch):
    """Every np.empty the estimator allocates is poisoned with NaN (integers with their maximum):
    the results must not change by one bit. Uninitialised memory read by mistake holds whatever
    an earlier allocation (of any thread) left there, so it fails only now and then otherwise."""
    records = _threading_records()
    clean = [identify_modes(x, FS_HZ) for x in records]
    clean_verdicts = assess_decay(records[0][:2], FS_HZ)
    real_empty, real_empty_like = np.empty, np.empty_like

    def poison(a):
        if a.dtype.kind in "fc":
            a.fill(np.nan)
        elif a.dtype.kind in "iu":
            a.fill(np.iinfo(a.dtype).max)
        return a

    monkeypatch.setattr(np, "empty", lambda *a, **k: poison(real_empty(*a, **k)))
    monkeypatch.setattr(np, "empty_like", lambda *a, **k: poison(real_empty_like(*a, **k)))
    assert np.isnan(np.empty(3)).all()
    for x, ref in zip(records, clean, strict=True):
        _same_table(identify_modes(x, FS_HZ), ref)
    assert assess_decay(records[0][:2], FS_HZ) == clean_verdicts


def test_cached_window_is_read_only():
    from ramdaq.analysis.modal.signal import _kaiser14

    w, _ = _kaiser14(256)
    with pytest.raises(ValueError, match="read-only"):
        w[0] = 1.0


def test_fit_started_in_a_corner_of_the_box_leaves_it():
    # A ramp (drift) fitted by one mode started at (f_min, δ_max): the Gauss–Newton step points
    # out of the corner in both coordinates. The fit must hold f on its bound and bring δ down,
    # not stop where the clipped step vanishes.
    from ramdaq.analysis.modal.varpro import fit_modes_varpro

    t = np.arange(4096) / FS_HZ
    y = 0.05 * t + 0.0025 * np.random.default_rng(1).standard_normal(t.size)
    fit = fit_modes_varpro(t, y[None], [0.25], [3.0], f_bounds_hz=(0.25, 1000.0),
                           delta_bounds=(-3.0, 3.0))
    assert fit.success and fit.n_eval < 100
    assert fit.f_hz[0] == 0.25 and fit.delta[0] < 1.0
    stuck = fit_modes_varpro(t, y[None], [0.25], [3.0], f_bounds_hz=(0.25, 1000.0),
                             delta_bounds=(3.0 - 1e-9, 3.0))  # δ pinned: the corner's residual
    assert fit.rss[0] < 0.9 * stuck.rss[0]


# -- real decays: a drift, every parameter at a bound, fewer modes than asked (issue 18) ----------
def _hammer_like(drift: str, seed: int = 0) -> tuple[np.ndarray, float]:
    """4096 samples at 1280 Hz: modes at 34.05 Hz (zeta 0.023 %) and 212.1 Hz (0.09 %), as the
    impact-hammer record of issue 18, white noise, and a slow drift under one cycle."""
    fs, n = 1280.0, 4096
    t = np.arange(n) / fs
    x = (np.exp(-0.023e-2 * 2 * np.pi * 34.05 * t) * np.sin(2 * np.pi * 34.05 * t)
         + 0.3 * np.exp(-0.09e-2 * 2 * np.pi * 212.1 * t) * np.sin(2 * np.pi * 212.1 * t)
         + np.random.default_rng(seed).normal(0, 0.01, n))
    if drift == "sine":
        x += 2 * np.sin(2 * np.pi * 0.3 * t + 0.5)
    elif drift == "exp":
        x += 2 * np.exp(-t / 0.8)
    return x, fs


@pytest.mark.parametrize("drift", ["sine", "exp"])
def test_drift_term_chosen_by_the_likelihood_ratio(drift):
    """A drift of 2 (200 x the noise) under one cycle hid the 212 Hz mode and made the 34 Hz
    zeta's standard error 100 x larger; with trend columns chosen by the same likelihood-ratio
    test as the modes, both modes come back as without the drift."""
    clean = identify_modes(_hammer_like("none")[0], 1280.0)
    assert clean.info["trend_terms"] == 1  # no drift: no trend beyond the constant
    x, fs = _hammer_like(drift)
    table = identify_modes(x, fs)
    assert table.info["trend_terms"] > 2
    assert table.frequency_hz == pytest.approx([34.05, 212.1], abs=0.01)
    truth = np.array([0.023e-2, 0.09e-2])
    # within 4 standard errors of the truth; the trend's few columns cost the modes next to
    # nothing, so the standard error stays within 20 % of the drift-free record's
    assert np.all(np.abs(table.zeta - truth) < 4 * table.zeta_se)
    assert np.all(table.zeta_se < 1.2 * clean.zeta_se)


def test_every_parameter_at_a_bound_is_a_step_of_zero_not_a_lapack_error():
    """A 0 x 0 system reached LAPACK (``_flapack.error``) when every coordinate was held at a
    bound; it is a zero step, which the iteration judges as a Karush-Kuhn-Tucker point."""
    from ramdaq.analysis.modal.varpro import _damped_step

    u, info = _damped_step(np.eye(2), np.array([1.0, -1.0]), 0.1, np.array([0.0, 1.0]),
                           np.zeros(2), np.ones(2))
    assert info == 0 and np.array_equal(u, np.zeros(2))
    x, fs = _hammer_like("sine")
    force = np.zeros_like(x)
    force[:6] = 100 * np.sin(np.pi * np.arange(6) / 6)
    # the force + response from sample 5: an answer (a table, empty with its reason if
    # nothing is significant beside the force's lone sample), never an exception
    table = identify_modes(np.vstack([force, x])[:, 5:], fs)
    assert len(table) >= 1 or table.info["reason"]


def test_explicit_n_modes_that_finds_fewer_says_so():
    x, fs = _hammer_like("none")
    table = identify_modes(x, fs, n_modes=8)
    assert 1 <= len(table) < 8
    assert table.info["fewer_modes"].startswith(f"n_modes=8 asked, {len(table)} found")


def test_gauss_newton_gain_from_grams_matches_formed_residual():
    from ramdaq.analysis.modal import varpro as modal_varpro

    rng = np.random.default_rng(22)
    t = np.arange(6000) / FS_HZ
    y = damped_sinusoids(FS_HZ, 6000, [24.5, 90.0], [0.06, 0.01], rng.normal(size=(3, 2))) \
        + 0.01 * rng.standard_normal((3, 6000))
    w = np.full(3, 100.0)
    f, d = np.array([24.45, 90.1, 300.0]), np.array([0.055, 0.011, 0.02])  # off the optimum
    gain = modal_varpro.gauss_newton_gain(t, y, f, d, weights=w, fit_offset=True)
    prob = modal_varpro._Problem(t, (y * w[:, None]).T, True)
    theta = np.ravel(np.column_stack([f, d]))
    resid, proj, B = prob.residual(theta)
    ref = modal_varpro._gauss_newton_decrease(*prob.normal_equations(theta, resid, proj, B))
    # Tᵀr = TᵀY − (ΦᵀT)ᵀB rounds relative to ‖Y‖/‖r‖ (~10³ here): ~10⁻¹² of the gain.
    assert gain > 0
    np.testing.assert_allclose(gain, ref, rtol=1e-9)


def test_nested_trend_fits_from_one_factorisation_match_separate_fits():
    from ramdaq.analysis.modal.identify import _nested_rss
    from ramdaq.analysis.modal.varpro import linear_amplitudes

    rng = np.random.default_rng(23)
    t = np.arange(4000) / FS_HZ
    f, d = np.array([24.5, 90.0]), np.array([0.06, 0.01])
    y = damped_sinusoids(FS_HZ, 4000, f, d, rng.normal(size=(3, 2))) \
        + 0.2 * (t / t[-1]) ** 2 + 0.01 * rng.standard_normal((3, 4000))  # a drift
    rss = _nested_rss(t, y, f, d, 1, 3)
    ref = [linear_amplitudes(t, y, f, d, fit_offset=k)[2] for k in (1, 2, 3)]
    # The same least-squares fits, summed differently: equal to rounding (Σr² ~ 0.4 of Σy²
    # here after the drift, ~1e-4 without it: no digits lost either way).
    np.testing.assert_allclose(rss, ref, rtol=1e-9)
    assert np.all(rss[0] > rss[2])  # the drift is taken up


def test_channels_fitted_together_from_one_start_equal_their_own_fits():
    from ramdaq.analysis.modal.varpro import fit_channels_varpro, fit_modes_varpro

    rng = np.random.default_rng(24)
    t = np.arange(5000) / FS_HZ
    y = damped_sinusoids(FS_HZ, 5000, [24.5, 90.0], [0.06, 0.01], rng.normal(size=(3, 2))) \
        + 0.01 * rng.standard_normal((3, 5000))
    kw = {"fit_offset": True, "f_bounds_hz": (0.5, 1000.0), "delta_bounds": (-3.0, 3.0)}
    start = (np.array([24.4, 90.1]), np.array([0.05, 0.012]))
    got = fit_channels_varpro(t, y, *start, **kw)
    for c, fc in enumerate(got):
        ref = fit_modes_varpro(t, y[c : c + 1], *start, **kw)
        # Both converged to rounding from the same start (the first evaluation computed for
        # all channels at once, summed in another order): equal far inside a standard error.
        np.testing.assert_allclose(fc.f_hz, ref.f_hz, rtol=1e-10)
        np.testing.assert_allclose(fc.delta, ref.delta, rtol=1e-7)
        np.testing.assert_allclose(fc.covariance, ref.covariance, rtol=1e-6)
        np.testing.assert_allclose(fc.rss, ref.rss, rtol=1e-10)


def test_channel_fits_stopped_by_their_standard_error_lie_far_inside_it():
    from ramdaq.analysis.modal.varpro import fit_channels_varpro, fit_modes_varpro

    rng = np.random.default_rng(25)
    t = np.arange(6000) / FS_HZ
    f, d = np.array([24.5, 90.0]), np.array([0.06, 0.01])
    y = damped_sinusoids(FS_HZ, 6000, f, d, rng.normal(size=(4, 2))) \
        + 0.05 * rng.standard_normal((4, 6000))
    kw = {"fit_offset": True, "f_bounds_hz": (0.5, 1000.0), "delta_bounds": (-3.0, 3.0)}
    start = (f * (1 + 2e-4), d * 1.05)  # a joint fit's poles: off each channel's own by ~1 SE
    got = fit_channels_varpro(t, y, *start, se_tol=1e-4, **kw)
    evals = 0
    for c, fc in enumerate(got):
        ref = fit_modes_varpro(t, y[c : c + 1], *start, **kw)  # converged to rounding
        se = np.sqrt(np.diag(ref.covariance))
        # Stopped where Gauss-Newton promises < 1e-4 s² more: Δθᵀ Cov⁻¹ Δθ ≲ 1e-4, so each of
        # f and δ within ~0.01 of its standard error (0.02 allowed: Gauss-Newton's promise
        # undershot the remaining decrease by up to 2x where measured, a factor 1.4 in θ).
        assert np.all(np.abs(fc.f_hz - ref.f_hz) <= 0.02 * se[0::2])
        assert np.all(np.abs(fc.delta - ref.delta) <= 0.02 * se[1::2])
        assert fc.success
        evals += ref.n_eval - fc.n_eval
    assert evals > 0  # and it saved evaluations


def test_a_long_single_channel_is_searched_on_a_decimated_copy_and_refitted_on_itself():
    rng = np.random.default_rng(26)
    n = 12288  # 6 s at 2048 Hz: over 8192 samples, a band of ~80 Hz allows a factor of 3 or more
    f, d = np.array([6.9, 13.0, 60.0]), np.array([0.12, 0.1, 0.015])
    y = damped_sinusoids(FS_HZ, n, f, d, [1.0, 2.0, 1.5], [0.3, 1.0, 2.0]) \
        + 0.01 * rng.standard_normal(n)
    auto = identify_modes(y, FS_HZ, per_channel=False)
    assert auto.info["search_decimation"] >= 3
    np.testing.assert_allclose(auto.frequency_hz, f, rtol=1e-3)
    # The modes it selected, refitted on the record itself to rounding: the fit of that order
    # on the record (one channel, order given: no search copy), to far inside a standard error.
    known = identify_modes(y, FS_HZ, per_channel=False, n_modes=3)
    assert "search_decimation" not in known.info
    assert np.all(np.abs(auto.delta - known.delta) <= 1e-3 * known.delta_se)
    assert np.all(np.abs(auto.frequency_hz - known.frequency_hz) <= 1e-3 * known.frequency_se_hz)


def test_the_early_look_at_held_fits_decides_as_the_converged_test(monkeypatch):
    from ramdaq.analysis.modal import identify, order, varpro

    # seed 33: the threshold raised for the decimated copy's coloured noise (noise_colour 1.12)
    # leaves a noise candidate for the held fit in 5 of seeds 27-35 (27, used before, none)
    rng = np.random.default_rng(33)
    n = 6000  # 12 gages: searched on a copy decimated by 2, as a hit is; noise candidates tried
    f, d = np.array([6.9, 13.0, 60.0, 215.0]), np.array([0.12, 0.1, 0.015, 0.002])
    x = damped_sinusoids(FS_HZ, n, f, d, rng.normal(size=(12, 4))) \
        + 0.02 * rng.standard_normal((12, n))
    two = damped_sinusoids(FS_HZ, 2508, [24.5, 24.745], [0.06, 0.07], [1.0, 0.8], [0.4, 2.0]) \
        + 0.005 * rng.standard_normal(2508)  # two modes 1 % apart, 40 dB
    evals = []
    close = varpro.HeldFit.close

    def counted(self):
        evals.append(self.run.n_eval)
        close(self)

    monkeypatch.setattr(varpro.HeldFit, "close", counted)
    # The linear screen at the noise's χ² 1e-3 quantile (ord22) rejects these records' noise
    # candidates before any held fit; at its median (about the former 0.25 x threshold) they
    # reach the held fit and its early look, which is what this test is about.
    monkeypatch.setattr(identify, "_SCREEN_FALSE_ALARM", 0.5)
    runs, look = {}, order._EARLY_REJECT
    for early in (look, 0.0):  # 0: never rejected early (Λ_p + 1 > 0)
        monkeypatch.setattr(order, "_EARLY_REJECT", early)
        evals.clear()
        runs[early] = ([identify_modes(y, FS_HZ, per_channel=False) for y in (x, two)],
                       sum(evals))
    (with_look, n_with), (without, n_without) = runs[look], runs[0.0]
    for a, b in zip(with_look, without, strict=True):
        # the same decisions, hence the same fits, to the bit
        np.testing.assert_array_equal(a.frequency_hz, b.frequency_hz)
        np.testing.assert_array_equal(a.delta, b.delta)
    assert len(with_look[0]) == 4 and len(with_look[1]) == 2
    assert n_with < n_without  # and the look saved held-fit evaluations


def test_a_held_fit_advanced_in_parts_reaches_the_point_of_one_fit_to_the_bit():
    """The order search looks at a held-pole fit after one iteration and continues it from
    there: 1 + 2 + the rest iterations end where one fit does, bit for bit (a noise candidate
    against three held modes, whose path takes step doublings)."""
    from ramdaq.analysis.modal.varpro import HeldPoleFitter

    rng = np.random.default_rng(5)
    n = 3000
    f, d = np.array([13.0, 60.0, 215.0]), np.array([0.1, 0.015, 0.002])
    y = damped_sinusoids(FS_HZ, n, f, d, rng.normal(size=(4, 3))) \
        + 0.02 * rng.standard_normal((4, n))
    t = np.arange(n) / FS_HZ
    kw = {"f_bounds_hz": (0.5, 500.0), "delta_bounds": (-3.0, 3.0), "chi2_tol": 1e-3}
    held = HeldPoleFitter(t, y, f, d, weights=np.full(4, 50.0), fit_offset=True, grams=True)
    whole = held.fit(np.array([101.0]), np.array([0.05]), **kw)
    run = held.start(np.array([101.0]), np.array([0.05]), **kw)
    parts = [run.advance(1), run.advance(2), run.advance(97)]
    run.close()
    assert parts[0][4] < whole[4]  # the first look is part-way
    for a, b in zip(parts[-1], whole, strict=True):
        np.testing.assert_array_equal(a, b)


def test_each_channels_band_at_once_equals_each_channel_alone_to_the_bit():
    """The verdicts' no-peak screen tests every channel's spectrum at once: the same band, to
    the bit, as the band test run on each channel alone (strong, weak, coloured-noise-only and
    white-noise-only rows; 4 record lengths tested, several floor blocks)."""
    from scipy import signal as sps

    from ramdaq.analysis.modal.identify import channel_periodograms
    from ramdaq.analysis.modal.signal import (
        estimate_noise_std,
        significant_band,
        significant_bands_alone,
    )

    rng = np.random.default_rng(3)
    fs, n = 2048.0, 20000
    x = damped_sinusoids(fs, n, [13.0, 215.0], [0.05, 0.02], rng.normal(size=(4, 2)))
    x[2] *= 0.003  # weak: near the noise
    x = x + 0.01 * rng.standard_normal(x.shape)
    x[3] = sps.lfilter(*sps.butter(4, 0.3), 0.01 * rng.standard_normal(n))  # coloured noise only
    x = np.vstack([x, 0.01 * rng.standard_normal(n)])  # white noise only
    sig = estimate_noise_std(x)
    got = significant_bands_alone(fs, sig, 1e-4, channel_periodograms(x), n)
    want = [significant_band(x[c : c + 1], fs, sig[c : c + 1], 1e-4, None) for c in range(5)]
    assert [None if np.isnan(g) else g for g in got] == want
    assert np.isfinite(got[0]) and np.isnan(got[4])  # a strong decay is seen, white noise not


@pytest.mark.parametrize("factor, m", [(2, 1), (3, 100), (3, 4096), (3, 10_000)])
def test_decimate_valid_up_to_max_outputs_equals_the_whole_records_first_outputs(factor, m):
    """A search copy decimated only as far as it is kept (identify's cropped 14 s copies) holds
    the whole record's first outputs to the bit, and decimated_index names the whole record's
    outputs without filtering (m = 10 000: more than the record gives, all of them)."""
    x = np.random.default_rng(5).standard_normal((3, 12_001))
    y, idx, taps = decimate_valid(x, 2048.0, factor, 270.0)
    yp, idxp, tapsp = decimate_valid(x, 2048.0, factor, 270.0, max_outputs=m)
    k = min(m, idx.size)
    assert yp.shape == (3, k)
    assert np.array_equal(yp, y[:, :k]) and np.array_equal(idxp, idx[:k])
    assert np.array_equal(tapsp, taps)
    assert np.array_equal(decimated_index(x.shape[1], 2048.0, factor, 270.0), idx)


@pytest.mark.parametrize("factor, band, n", [(2, 270.0, 3000), (2, 270.0, 3001), (3, 200.0, 3002)])
def test_decimate_from_first_is_exact_on_damped_sinusoids_from_the_first_sample(factor, band, n):
    """from_first (the NLS data of long records): outputs at samples 0, factor, ... up to the
    last whose window the record holds, each exactly the damped sum times fir_gain of the
    returned taps (to rounding, 1e-13 of the amplitude: a sum of ~20-40 products), the same
    noise spectrum as the linear-phase filter (fir_noise_variance_factor within 1e-5: the
    minimum-phase design matches |H| to ~1e-6), and the first outputs of a record read only
    as far as max_outputs equal the whole record's to the bit."""
    fs = 2048.0
    t = np.arange(n) / fs
    s = np.array([-0.1 * 13 + 2j * np.pi * 13, -0.02 * 60 + 2j * np.pi * 60])
    a = np.array([1 + 0.5j, 0.3 - 0.2j])
    x = np.vstack([np.real(a @ np.exp(s[:, None] * t)),
                   np.random.default_rng(2).standard_normal(n)])
    y, idx, taps = decimate_valid(x, fs, factor, band, from_first=True)
    n_taps = (taps.size + 1) // 2
    assert idx[0] == 0 and np.all(np.diff(idx) == factor)
    assert idx[-1] + n_taps <= n < idx[-1] + factor + n_taps  # every window inside, none left
    model = np.real((a * fir_gain(taps, np.exp(s / fs))) @ np.exp(s[:, None] * idx / fs))
    assert np.max(np.abs(y[0] - model)) < 1e-13 * np.sum(np.abs(a))
    _, _, lin = decimate_valid(x, fs, factor, band)
    f = np.array([13.0, 60.0, 0.9 * band])
    np.testing.assert_allclose(fir_noise_variance_factor(taps, factor, f, fs),
                               fir_noise_variance_factor(lin, factor, f, fs), rtol=1e-5)
    yp, idxp, _ = decimate_valid(x, fs, factor, band, max_outputs=40, from_first=True)
    assert np.array_equal(yp, y[:, :40]) and np.array_equal(idxp, idx[:40])


@pytest.mark.parametrize("rows, n", [(16, 29_138), (11, 14_587), (3, 4_285), (2, 28_672), (1, 29_179)])
def test_rfft_rows_equals_numpys_rfft(rows, n):
    """Two rows packed into one complex transform (lengths with a prime factor over 7, where
    pocketfft runs Bluestein's algorithm) give numpy's rfft to rounding; smooth lengths and
    one row are numpy's own, to the bit. The rows have 80 dB between a decay's start and its
    noise, so the noise bins' digits are what the tolerance guards: 1e-14 of the larger norm
    of a row's pair (a row's error is its partner's rounding too) is ~5x the FFT's own
    rounding (~2e-15 measured), far below any bin that matters."""
    from ramdaq.analysis.modal.signal import _largest_prime_factor, rfft_rows

    rng = np.random.default_rng(7)
    x = 1e4 * np.exp(-np.arange(n) / 3000.0) * rng.standard_normal((rows, n))
    x += rng.standard_normal((rows, n))
    x[0] *= 1e-3  # a quiet row paired with a strong one
    want = np.fft.rfft(x, axis=-1)
    got = rfft_rows(x)
    assert got.shape == want.shape
    if rows == 1 or _largest_prime_factor(n) <= 7:
        assert np.array_equal(got, want)
    else:
        norm = np.linalg.norm(x, axis=-1)
        pair = np.maximum(norm, norm[np.minimum(np.arange(rows) ^ 1, rows - 1)])  # with its partner
        assert np.max(np.abs(got - want) / pair[:, None]) < 1e-14
        assert not np.array_equal(got, want)  # the packed path ran


def test_fast_length_below_is_the_longest_7_smooth_length():
    """The longest length <= n with no prime factor over 7, against a plain downward search
    (every n to 5000 and a replay's decay lengths); n itself when it is one; bad n refused."""
    from ramdaq.analysis.modal.signal import _largest_prime_factor, fast_length_below

    for n in [*range(1, 5000), 28_860, 29_138, 29_578, 28_672, 1_000_000]:
        m = n
        while _largest_prime_factor(m) > 7:
            m -= 1
        assert fast_length_below(n) == m, n
    assert fast_length_below(29_578) == 29_400  # 2^3 3 5^2 7^2: 178 samples dropped
    with pytest.raises(ValueError, match="length 0"):
        fast_length_below(0)


def test_identify_modes_given_the_verdicts_noise_equals_its_own():
    """The verdicts' screen hands ``identify_modes`` its periodograms and the noise std read
    from them (one median a channel, not taken again): the table equals the one computed without
    the noise std, to the bit (one channel flat: left out by both)."""
    from ramdaq.analysis.modal.identify import channel_periodograms
    from ramdaq.analysis.modal.signal import noise_std_from_periodogram

    rng = np.random.default_rng(3)
    n = 4_285  # a length rfft_rows packs
    x = damped_sinusoids(FS_HZ, n, [13.0, 45.0], [0.12, 0.10], rng.normal(size=(4, 2)))
    x = x + 0.01 * rng.standard_normal(x.shape)
    x[2] = 0.0
    pg = channel_periodograms(x)
    sig = noise_std_from_periodogram(pg[n])
    a = identify_modes(x, FS_HZ, periodograms=pg)
    b = identify_modes(x, FS_HZ, periodograms=pg, noise_std=sig)
    assert len(a) == 2
    for name in ("frequency_hz", "delta", "delta_se", "complex_amplitude", "channel_delta", "noise_std"):
        assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), name


def test_band_decimation_decimates_as_far_as_the_band_allows_at_the_same_estimates():
    """band_decimation (a final's): a record over max_samples decimated by the whole factor its
    band allows (3 here: 2048 Hz, band up to ~250 Hz), not the least that fits (2), and the
    order search run on those data cropped (search_decimation set: not the whole NLS data).
    Both are efficient estimators of the same record, so they differ by a small fraction of a
    standard error (measured ~0.05 SE on simulated 14 s hits; 0.5 SE bounds it with margin),
    and their standard errors by the FIRs' noise factors only (a few %)."""
    rng = np.random.default_rng(19)
    n = 30_000
    x = damped_sinusoids(FS_HZ, n, [13.0, 200.0], [0.10, 0.02], [[1.0, 0.3], [0.5, 0.8]],
                         [[0.0, 1.0], [2.0, 3.0]]) + 0.01 * rng.standard_normal((2, n))
    kw = {"max_samples": 30_000, "search_max_samples": 8_000, "per_channel": False}
    least = identify_modes(x, FS_HZ, **kw)
    band = identify_modes(x, FS_HZ, band_decimation=True, **kw)
    assert least.info["decimation"] == 2
    assert band.info["decimation"] == int(FS_HZ // (2.5 * band.info["band_hz"])) == 3
    assert band.info["search_decimation"] == 3
    assert len(band) == len(least) == 2
    assert np.all(np.abs(band.delta - least.delta) < 0.5 * least.delta_se)
    assert np.all(np.abs(band.frequency_hz - least.frequency_hz) < 0.5 * least.frequency_se_hz)
    np.testing.assert_allclose(band.delta_se, least.delta_se, rtol=0.1)
