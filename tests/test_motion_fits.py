"""The motion fits: each combined signal's own modes, reached from the gages' joint poles."""

import numpy as np
import pytest

from ramdaq.analysis.modal.varpro import fit_modes_varpro
from ramdaq.analysis.report1836.motion_fits import fit_signals_at_poles

FS, N = 512.0, 3072
F, D = np.array([6.0, 13.0]), np.array([0.12, 0.10])


def _decays(rng: np.random.Generator, amps: np.ndarray, noise: float) -> np.ndarray:
    """(n_channels, N): sum of the modes (F, D) with complex amplitudes ``amps`` (n_ch, 2)."""
    t = np.arange(N) / FS
    s = -D * F + 2j * np.pi * F
    x = np.real(amps @ np.exp(s[:, None] * t[None, :]))
    return x + noise * rng.standard_normal(x.shape)


@pytest.fixture(scope="module")
def gages():
    rng = np.random.default_rng(7)
    amps = np.array([[1.0, 2.0 - 1.0j], [0.5j, -1.5], [0.8, 0.3 + 0.2j]])
    return _decays(rng, amps, 0.01)


def _converged(y: np.ndarray, f0: np.ndarray, d0: np.ndarray):
    fit = fit_modes_varpro(np.arange(N) / FS, y[None, :], f0, d0, fit_offset=1)
    return fit, np.sqrt(np.diag(fit.covariance))


def test_each_signal_reaches_its_own_least_squares_fit(gages):
    """Started at poles off by several standard errors (the gages' joint fit stands in), each
    combination's estimate is its own converged variable-projection fit: within 2 % of a
    standard error (the iteration stops when a step is under 1 %, and Gauss-Newton converges
    quadratically), with the same standard errors (to 1 %)."""
    signals = np.array([gages[0] - gages[1], 0.3 * gages[0] + 0.7 * gages[2], gages[1]])
    f0, d0 = F * (1 + 2e-4), D * (1 - 0.01)
    fits = fit_signals_at_poles(signals, FS, f0, d0)
    for y, got in zip(signals, fits, strict=True):
        ref, se = _converged(y, f0, d0)
        assert got.method == "gauss-newton"
        assert np.all(np.abs(got.f_hz - ref.f_hz) <= 0.02 * se[0::2])
        assert np.all(np.abs(got.delta - ref.delta) <= 0.02 * se[1::2])
        assert got.delta_se == pytest.approx(se[1::2], rel=0.01)
        assert got.f_se_hz == pytest.approx(se[0::2], rel=0.01)


def test_amplitudes_combine_as_the_signals(gages):
    """The amplitudes at the joint poles are linear in the data: a combination's are the same
    combination of the gages' (to rounding)."""
    w = np.array([0.4, -1.3, 2.0])
    fits = fit_signals_at_poles(np.vstack([gages, w @ gages]), FS, F, D)
    combined = sum(wi * fi.amplitude for wi, fi in zip(w, fits[:3], strict=True))
    assert np.allclose(fits[3].amplitude, combined, rtol=1e-9, atol=1e-12)


def test_a_mode_absent_from_a_signal_is_not_estimated(gages):
    """Only the 13 Hz mode in the signal: the 6 Hz one is NaN (not above the noise), the 13 Hz
    one estimated; with ``modes=(1,)`` only mode 1 is asked for; noise alone gives none."""
    rng = np.random.default_rng(3)
    one = _decays(rng, np.array([[0.0, 1.0]]), 0.01)[0]
    noise = 0.01 * rng.standard_normal(N)
    a, b, c = fit_signals_at_poles(np.array([one, gages[0], noise]), FS, F, D, modes=(1,))
    assert np.isnan(a.delta[0]) and np.isfinite(a.delta[1])
    assert np.isnan(b.delta[0]) and np.isfinite(b.delta[1])  # mode 0 not asked for
    assert c.method == "none" and np.all(np.isnan(c.delta))


@pytest.mark.parametrize(("f_factor", "method"), [(1.05, "gauss-newton"),
                                                   (1.2, "levenberg-marquardt")])
def test_a_start_too_far_for_gauss_newton_falls_back_to_levenberg_marquardt(gages, f_factor,
                                                                            method):
    """Frequencies 5 % off (2 to 4 cycles of phase over the 6 s record): Gauss-Newton
    with its halved steps still gets there; 20 % off it does not within its 8 steps, and the
    Levenberg-Marquardt fit does: both the converged answer (2 % of a standard error)."""
    got = fit_signals_at_poles(gages[:1], FS, F * f_factor, D)[0]
    ref, se = _converged(gages[0], F, D)
    assert got.method == method
    assert np.all(np.abs(got.delta - ref.delta) <= 0.02 * se[1::2])
    assert np.all(np.abs(got.f_hz - ref.f_hz) <= 0.02 * se[0::2])


def test_bad_inputs_are_named():
    with pytest.raises(ValueError, match="signals"):
        fit_signals_at_poles(np.full((1, 100), np.nan), FS, F, D)
    with pytest.raises(ValueError, match="f_hz"):
        fit_signals_at_poles(np.zeros((1, 100)), FS, F, D[:1])
    with pytest.raises(ValueError, match="n_samples"):
        fit_signals_at_poles(np.zeros((1, 8)), FS, F, D)


def test_a_steps_terms_from_grams_equal_the_explicit_ones(gages):
    """A Gauss-Newton step's terms (rss, Schur complement, T^T r, Kaufman weights) from Grams
    equal those from the projected columns and residual to rounding (1e-9 relative: the Grams
    lose at most ~4 of 16 digits, kept so by the rss >= 1e-4 y^T y gate), one mode free and the
    other held; and a signal the modes fit too closely for the Grams (rss under 1e-4 of y^T y)
    takes the explicit path."""
    from ramdaq.analysis.report1836.motion_fits import _Held

    t = np.arange(N) / FS
    held = _Held(t, gages, F, D, np.array([1]), 1)
    f, d = F[1:] * (1 + 1e-4), D[1:] * (1 + 0.02)  # off the joint poles, as a step lands
    for s in range(gages.shape[0]):
        gram, explicit = held._gram_terms(s, f, d), held._explicit_terms(s, f, d)
        assert gram is not None, f"signal {s}: noise 0.01 on amplitudes ~1 keeps rss > 1e-4 y^T y"
        assert gram[0] == pytest.approx(explicit[0], rel=1e-9)
        for a, b in zip(gram[1:], explicit[1:], strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * np.abs(b).max())
    clean = _Held(t, _decays(np.random.default_rng(1), np.array([[1.0, 1.0]]), 1e-6), F, D,
                  np.array([1]), 1)
    assert clean._gram_terms(0, F[1:], D[1:]) is None  # rss ~ 1e-12 y^T y: the Grams refuse
    assert clean.terms(0, F[1:], D[1:])[0] == pytest.approx(clean._explicit_terms(0, F[1:], D[1:])[0])
