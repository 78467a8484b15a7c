"""Tests for ramdaq.analysis.modal.peaks: the report's band-pass + successive-peak decrement."""

import numpy as np
import pytest

from ramdaq.analysis.modal.peaks import bandpass_mode, decrement_from_peaks
from ramdaq.analysis.modal.signal import damped_sinusoids

pytestmark = pytest.mark.timeout(60)

FS_HZ = 2048.0


def _decay(f_hz, delta, n_cycles, amplitude=1.0, phase=0.3):
    n = int(n_cycles * FS_HZ / f_hz)
    return damped_sinusoids(FS_HZ, n, [f_hz], [delta], [amplitude], [phase])


@pytest.mark.parametrize(("f_hz", "delta"), [(24.5, 0.06), (123.0, 0.05), (13.0, 0.12)])
@pytest.mark.parametrize("bandpass", [True, False])
def test_clean_single_mode_within_one_percent(f_hz, delta, bandpass):
    r = decrement_from_peaks(_decay(f_hz, delta, 40), FS_HZ, f_hz, bandpass=bandpass)
    assert r.delta == pytest.approx(delta, rel=0.01)
    assert r.delta_fit == pytest.approx(delta, rel=0.01)
    assert r.f_hz == pytest.approx(f_hz, rel=0.005)
    assert r.n_ratios >= 1


def test_ratios_q_periods_apart():
    x = _decay(24.5, 0.06, 40)
    r1 = decrement_from_peaks(x, FS_HZ, 24.5, q=1, bandpass=False)
    r3 = decrement_from_peaks(x, FS_HZ, 24.5, q=3, bandpass=False)
    assert r3.q == 3 and r3.n_ratios == r1.n_ratios - 2
    assert r3.delta == pytest.approx(r1.delta, rel=1e-3)


def test_bandpass_separates_a_distant_mode():
    n = int(40 * FS_HZ / 24.5)
    x = damped_sinusoids(FS_HZ, n, [24.5, 123.0], [0.06, 0.05], [1.0, 0.5], [0.3, 1.0])
    r = decrement_from_peaks(x, FS_HZ, 24.5)
    assert r.delta == pytest.approx(0.06, rel=0.02)
    y = bandpass_mode(x, FS_HZ, 24.5)
    assert y.shape == x.shape


def test_noisy_mode_error_is_covered_by_its_standard_error():
    rng = np.random.default_rng(11)
    x = _decay(24.5, 0.06, 40)
    x = x + 0.005 * rng.standard_normal(x.size)
    r = decrement_from_peaks(x, FS_HZ, 24.5)
    assert np.isfinite(r.std_error) and r.std_error > 0
    assert abs(r.delta - 0.06) < 5 * r.std_error + 0.002


def test_narrow_filter_on_heavy_damping_is_flagged():
    r = decrement_from_peaks(_decay(13.0, 0.17, 30), FS_HZ, 13.0, rel_bandwidth=0.05)
    assert r.filter_limited


@pytest.mark.parametrize(
    ("args", "kwargs", "match"),
    [
        ((np.zeros((2, 100)), FS_HZ, 24.5), {}, "1-D"),
        ((np.zeros(100), FS_HZ, 24.5), {"q": 0}, "q"),
        ((np.zeros(100), FS_HZ, 1000.0), {}, "f_hz"),
        ((np.zeros(100), FS_HZ, 24.5), {"rel_bandwidth": 2.0}, "rel_bandwidth"),
    ],
)
def test_bad_arguments(args, kwargs, match):
    with pytest.raises(ValueError, match=match):
        decrement_from_peaks(*args, **kwargs)


def test_too_few_peaks_raises():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="peaks"):
        decrement_from_peaks(rng.standard_normal(2000) * 1e-3, FS_HZ, 24.5, noise_std=1e-3)


def test_rows_at_once_equal_each_row_alone_to_the_bit():
    from ramdaq.analysis.modal.peaks import decrements_from_peaks

    rng = np.random.default_rng(7)
    fs = 2048.0
    x = damped_sinusoids(fs, 6000, [13.0, 60.0], [0.1, 0.02], rng.normal(size=(5, 2)))
    x = x + 0.01 * rng.standard_normal(x.shape)
    x[4] = 1e-3 * rng.standard_normal(6000)  # noise only: fewer than 3 peaks above it
    got = decrements_from_peaks(x, fs, 13.0)
    for row, g in zip(x, got, strict=True):
        try:
            ref = decrement_from_peaks(row, fs, 13.0)
        except ValueError as e:
            assert isinstance(g, ValueError) and str(g) == str(e)
            continue
        # The same filter, noise estimate and peaks, row by row: equal, not merely close.
        assert (g.delta, g.std_error, g.n_ratios) == (ref.delta, ref.std_error, ref.n_ratios)
        np.testing.assert_array_equal(g.peak_times_s, ref.peak_times_s)
    assert isinstance(got[4], ValueError)
    assert sum(isinstance(g, ValueError) for g in got) == 1


def test_rows_given_their_noise_equal_rows_estimating_it_to_the_bit():
    """A hit's gages pass the verdicts' noise std (the same periodogram median): same result;
    a noise vector that does not match the rows is refused."""
    from ramdaq.analysis.modal.peaks import decrements_from_peaks
    from ramdaq.analysis.modal.signal import estimate_noise_std

    rng = np.random.default_rng(8)
    fs = 2048.0
    x = damped_sinusoids(fs, 6000, [13.0, 60.0], [0.1, 0.02], rng.normal(size=(3, 2)))
    x = x + 0.01 * rng.standard_normal(x.shape)
    got = decrements_from_peaks(x, fs, 13.0, noise_std=estimate_noise_std(x))
    for g, ref in zip(got, decrements_from_peaks(x, fs, 13.0), strict=True):
        assert (g.delta, g.std_error, g.n_ratios) == (ref.delta, ref.std_error, ref.n_ratios)
    # Noise said 30x larger: the peaks' 5-sigma floor moves, so the peaks read do (the given
    # noise is the one used).
    other = decrements_from_peaks(x, fs, 13.0, noise_std=30 * estimate_noise_std(x))
    assert any(o.n_ratios != g.n_ratios for o, g in zip(other, got, strict=True))
    with pytest.raises(ValueError, match="noise_std"):
        decrements_from_peaks(x, fs, 13.0, noise_std=np.ones(2))


def test_rows_band_passed_already_as_filtering_them_and_combinations_to_rounding():
    """A hit's gages are band-passed once (bandpass_rows) and its motions, linear combinations
    of the gages, are the same combinations of the band-passed gages: the peak decrements equal
    those that filter the rows themselves (to the bit for the rows, to rounding for the
    combinations: the filter is linear); rows of another shape are refused."""
    from ramdaq.analysis.modal.peaks import bandpass_rows, decrements_from_peaks

    rng = np.random.default_rng(9)
    fs = 2048.0
    x = damped_sinusoids(fs, 6000, [13.0, 60.0], [0.1, 0.02], rng.normal(size=(4, 2)))
    x = x + 0.01 * rng.standard_normal(x.shape)
    xb = bandpass_rows(x, fs, 13.0)
    np.testing.assert_array_equal(xb[1], bandpass_mode(x[1], fs, 13.0))  # the same filter
    for g, ref in zip(decrements_from_peaks(x, fs, 13.0, bandpassed=xb),
                      decrements_from_peaks(x, fs, 13.0), strict=True):
        assert (g.delta, g.std_error, g.n_ratios) == (ref.delta, ref.std_error, ref.n_ratios)
    A = np.array([[0.5, -0.5, 0.0, 0.0], [0.3, 0.0, 0.7, 0.0], [0.0, 1.0, 0.0, -1.0]])
    got = decrements_from_peaks(A @ x, fs, 13.0, bandpassed=A @ xb)
    for g, ref in zip(got, decrements_from_peaks(A @ x, fs, 13.0), strict=True):
        assert g.n_ratios == ref.n_ratios
        # rounding only: ~1e-16 of the signal in each filtered sample, through a log-line fit
        assert g.delta == pytest.approx(ref.delta, rel=1e-9)
        assert g.std_error == pytest.approx(ref.std_error, rel=1e-9)
    # the rows given are the ones read (silent rows: no peaks), not x filtered again
    assert all(isinstance(g, ValueError) for g in decrements_from_peaks(x, fs, 13.0,
                                                                        bandpassed=0 * xb))
    with pytest.raises(ValueError, match="bandpassed"):
        decrements_from_peaks(x, fs, 13.0, bandpassed=xb[:2])
