"""Tests for the parametric modal estimator (analysis.modal_id) and decay verdicts.

SNR is A²/(2σ²) of each mode's initial amplitude (analysis.damping's convention). Tolerances:
single-mode δ and f within 4 Cramér–Rao standard deviations (a 4σ event, probability 6·10⁻⁵ per
check for an efficient estimator); Monte-Carlo checks use 150 noise seeds, for which the sample
std has a relative standard error of 1/√(2·149) ≈ 5.8 %, so ±20 % is a 3.4σ tolerance.
"""

import numpy as np
import pytest

from analysis.damping import crb_damped_sinusoid
from analysis.modal_assess import Verdict, assess_decay
from analysis.modal_id import identify_modes
from analysis.modal_signal import damped_sinusoids
from analysis.modal_varpro import _Problem

pytestmark = pytest.mark.timeout(120)

FS_HZ = 2048.0


def _noise_std(snr_db, amplitude=1.0):
    return amplitude / np.sqrt(2 * 10 ** (snr_db / 10))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_single_mode_at_40_db_within_four_crb(seed):
    rng = np.random.default_rng(seed)
    f0, d0, n = 24.5, 0.06, int(20 * FS_HZ / 24.5)
    sigma = _noise_std(40)
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
    x = x + _noise_std(30) * rng.standard_normal(x.shape)
    tab = identify_modes(x, FS_HZ)
    assert len(tab) == 2
    np.testing.assert_allclose(tab.frequency_hz, f, rtol=2e-3)
    np.testing.assert_allclose(tab.delta, d, rtol=0.05)


def test_standard_errors_agree_with_monte_carlo():
    f0, d0, n, sigma = 24.5, 0.08, int(10 * FS_HZ / 24.5), _noise_std(25)
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
