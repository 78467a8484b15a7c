"""Tests for ramdaq.analysis.modal.crb: δ ↔ ζ and the Cramér–Rao bound."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from ramdaq.analysis.modal.crb import (
    crb_damped_sinusoid,
    crb_damped_sinusoids,
    damping_ratio_from_decrement,
    decrement_from_damping_ratio,
    fisher_information_damped_sinusoids,
)

pytestmark = pytest.mark.timeout(60)


def test_decrement_of_known_damping_ratio():
    # ζ = 0.01 → δ = 2π·0.01/√(1 − 10⁻⁴) (exact), ≈ 2πζ for light damping.
    assert decrement_from_damping_ratio(0.01) == pytest.approx(
        2 * math.pi * 0.01 / math.sqrt(1 - 1e-4), rel=1e-15
    )
    # Report 1836's ALBACORE average in air, δ = 0.0684: ζ ≈ δ/2π to 0.006 %.
    assert damping_ratio_from_decrement(0.0684) == pytest.approx(0.0684 / (2 * math.pi), rel=1e-3)


@given(st.floats(min_value=-0.99, max_value=0.99, allow_nan=False))
def test_round_trip(zeta):
    assert damping_ratio_from_decrement(decrement_from_damping_ratio(zeta)) == pytest.approx(
        zeta, abs=1e-12
    )


def test_arrays_keep_shape():
    d = np.array([[0.05, 0.1], [0.2, 0.0]])
    z = damping_ratio_from_decrement(d)
    assert z.shape == d.shape
    np.testing.assert_allclose(decrement_from_damping_ratio(z), d, atol=1e-14)


@pytest.mark.parametrize("zeta", [1.0, -1.0, 1.5, float("nan")])
def test_no_decrement_without_oscillation(zeta):
    with pytest.raises(ValueError, match="zeta"):
        decrement_from_damping_ratio(zeta)


def test_crb_frequency_matches_closed_form_for_undamped_complex_exponential():
    # Rife & Boorstyn: var(ω̂) ≥ 6σ²/(A² N (N² − 1)) rad²/sample² for A e^{j(ωn+φ)} in circular
    # noise of total variance σ². The δ-derivative is orthogonal to the ω-derivative, so a free δ
    # leaves the frequency bound unchanged.
    A, sigma, N, fs = 1.3, 0.2, 500, 1000.0
    b = crb_damped_sinusoid(A, 0.0, 37.0, sigma, N, fs, complex_signal=True)
    var_w = 6 * sigma**2 / (A**2 * N * (N**2 - 1))
    assert b.f_std_hz == pytest.approx(math.sqrt(var_w) * fs / (2 * math.pi), rel=1e-6)


def test_fisher_matrix_against_finite_differences():
    fs, N, sigma = 2048.0, 600, 0.05
    theta = np.array([1.0, 0.4, 24.5, 0.06])  # A, φ, f, δ

    def model(p):
        t = np.arange(N) / fs
        return p[0] * np.exp(-p[3] * p[2] * t) * np.cos(2 * np.pi * p[2] * t + p[1])

    h = np.array([1e-6, 1e-6, 1e-6, 1e-7])
    D = np.stack(
        [(model(theta + h[i] * np.eye(4)[i]) - model(theta - h[i] * np.eye(4)[i])) / (2 * h[i])
         for i in range(4)], axis=1,
    )
    F = fisher_information_damped_sinusoids(1.0, 0.06, 24.5, sigma, N, fs, phase_rad=0.4)
    np.testing.assert_allclose(F, D.T @ D / sigma**2, rtol=1e-5)


def test_crb_scales_with_noise_and_is_joint_for_two_modes():
    b1 = crb_damped_sinusoid(1.0, 0.06, 24.5, 0.01, 2048, 2048.0)
    b2 = crb_damped_sinusoid(1.0, 0.06, 24.5, 0.02, 2048, 2048.0)
    assert b2.delta_std == pytest.approx(2 * b1.delta_std, rel=1e-9)
    assert b1.covariance.shape == (4, 4)
    # A second mode 3 % away raises the first mode's bound (they share information).
    pair = crb_damped_sinusoids([1.0, 1.0], [0.06, 0.07], [24.5, 25.235], 0.01, 2048, 2048.0)
    assert pair[0].delta_std > b1.delta_std
    assert pair[0].covariance.shape == (8, 8)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"noise_std": 0.0}, "noise_std"), ({"n_samples": 2}, "n_samples"), ({"fs_hz": -1.0}, "fs_hz")],
)
def test_crb_rejects_bad_arguments(kwargs, match):
    args = {"amplitude": 1.0, "delta": 0.05, "f_hz": 20.0, "noise_std": 0.1, "n_samples": 100,
            "fs_hz": 1000.0} | kwargs
    with pytest.raises(ValueError, match=match):
        crb_damped_sinusoid(**args)
