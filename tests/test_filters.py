"""ramdaq.analysis.filters against scipy.signal, whose functions it stands in for on the replay
path (the tests may import scipy.signal; the replay does not).

Tolerances: a design is the same sequence of floating-point operations as scipy's, so it agrees
to a few units in the last place (rtol 1e-14). A filter's output is the same sum in another
order (a LAPACK banded solve, which may fuse a multiply and an add, for scipy's C loop): each
step rounds to ~1e-16, and a resonant section (poles at radius r) carries an error for about
1 / (1 - r) samples, ~100 for the narrowest band-pass here, four passes in a forward-backward
pair: ~1e-13 of the output's scale, so 1e-12 of its largest value.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import scipy.signal as ss

from ramdaq.analysis import filters as flt

FS = 2048.0
RNG = np.random.default_rng(20261128)
DESIGN = dict(rtol=1e-14, atol=0.0)


def close_to_scale(got: np.ndarray, want: np.ndarray, rel: float = 1e-12) -> None:
    """``got`` equals ``want`` within ``rel`` of ``want``'s largest magnitude (see the module
    docstring for why a filter's output is compared to its scale)."""
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=0.0, atol=rel * float(np.max(np.abs(want))))


@pytest.mark.parametrize("order,corner", [(1, 100.0), (3, 500.0), (4, 800.0), (8, 300.0),
                                          (2, [10.4, 15.6]), (3, [100.0, 200.0]), (4, [20.0, 30.0])])
def test_butter_is_scipys(order, corner):
    btype = "bandpass" if isinstance(corner, list) else "lowpass"
    b, a = flt.butter(order, corner, FS)
    b0, a0 = ss.butter(order, corner, btype, fs=FS)
    np.testing.assert_allclose(b, b0, **DESIGN)
    np.testing.assert_allclose(a, a0, **DESIGN)
    np.testing.assert_allclose(flt.butter(order, corner, FS, output="sos"),
                               ss.butter(order, corner, btype, fs=FS, output="sos"), **DESIGN)


@pytest.mark.parametrize("corner", [0.0, 1024.0, [30.0, 20.0], [10.0, 1500.0]])
def test_butter_refuses_a_corner_outside_the_band(corner):
    with pytest.raises(ValueError, match="inside"):
        flt.butter(2, corner, FS)


def test_sosfilt_with_state_is_scipys():
    sos = ss.butter(3, [40.0, 60.0], "bandpass", fs=FS, output="sos")
    x = RNG.standard_normal((5, 3000))
    zi = RNG.standard_normal((sos.shape[0], 5, 2))
    want, _ = ss.sosfilt(sos, x, axis=-1, zi=zi)
    close_to_scale(flt.sosfilt(sos, x, zi), want)
    close_to_scale(flt.sosfilt(sos, x), ss.sosfilt(sos, x, axis=-1))


@pytest.mark.parametrize("band", [(10.4, 15.6), (200.0, 300.0)])
def test_sosfiltfilt_is_scipys(band):
    sos = ss.butter(2, band, "bandpass", fs=FS, output="sos")
    t = np.arange(20000) / FS
    x = np.exp(-0.4 * t) * np.sin(2 * np.pi * 13.0 * t) + 0.01 * RNG.standard_normal((16, t.size))
    close_to_scale(flt.sosfiltfilt(sos, x), ss.sosfiltfilt(sos, x, axis=-1))
    close_to_scale(flt.sosfiltfilt(sos, x[3]), ss.sosfiltfilt(sos, x[3]))
    np.testing.assert_allclose(flt.sosfilt_zi(sos), ss.sosfilt_zi(sos), **DESIGN)


def test_sosfiltfilt_refuses_a_record_shorter_than_its_padding():
    sos = ss.butter(2, [10.0, 20.0], "bandpass", fs=FS, output="sos")
    with pytest.raises(ValueError, match="padding"):
        flt.sosfiltfilt(sos, np.ones(15))


@pytest.mark.parametrize("n", [1, 20, 2048])
def test_exp_filter_is_scipys_lfilter(n):
    c = 1.0 / n
    x = RNG.standard_normal((16, 5000)) ** 2
    prev = RNG.random(16)
    want, _ = ss.lfilter([c, 0.0], [1.0, c - 1.0], x, axis=-1, zi=((1.0 - c) * prev)[:, None])
    close_to_scale(flt.exp_filter(x, c, prev), want)


def test_fir_filter_is_scipys_lfilter_valid_part():
    b = np.array([1.0, -1.7, 0.9, -0.05])
    x = RNG.standard_normal((3, 400))
    close_to_scale(flt.fir_filter(b, x), ss.lfilter(b, [1.0], x, axis=-1)[:, 3:])
    assert flt.fir_filter(b, x[:, :3]).shape == (3, 0)


def test_sosfreqz_and_group_delay_are_scipys():
    sos = ss.butter(4, 800.0, fs=FS, output="sos")
    for worN in (4096, [13.0, 500.0]):
        f0, h0 = ss.sosfreqz(sos, worN=worN, fs=FS)
        f, h = flt.sosfreqz(sos, worN, FS)
        np.testing.assert_allclose(f, f0, **DESIGN)
        np.testing.assert_allclose(h, h0, rtol=1e-13)  # a product of section responses
    b, a = ss.butter(4, 800.0, fs=FS)
    np.testing.assert_allclose(flt.group_delay(b, a, [1e-6 * FS, 100.0], FS),
                               ss.group_delay((b, a), w=[1e-6 * FS, 100.0], fs=FS)[1], rtol=1e-13)


@pytest.mark.parametrize("width", [0.05, 0.3])
def test_fir_design_is_scipys(width):
    n, beta = flt.kaiserord(80.0, width)
    assert (n, beta) == ss.kaiserord(80.0, width)
    n |= 1
    h = flt.firwin_kaiser(n, 341.3, beta, FS)
    np.testing.assert_allclose(h, ss.firwin(n, 341.3, window=("kaiser", beta), fs=FS), **DESIGN)
    # the homomorphic minimum phase goes through FFTs of 2**k points (numpy's here, scipy.fft
    # there): ~1e-12 of the largest tap
    close_to_scale(flt.minimum_phase(h), ss.minimum_phase(h, method="homomorphic", half=False), 1e-11)
    for sym in (True, False):
        np.testing.assert_allclose(flt.kaiser(n, 14.0, sym=sym), ss.windows.kaiser(n, 14.0, sym=sym),
                                   **DESIGN)


@pytest.mark.parametrize("q", [2, 3, 5])
@pytest.mark.parametrize("n", [73, 1000, 1001])
def test_downsample_fir_is_scipys_upfirdn(q, n):
    h = ss.firwin(31, 200.0, fs=FS)
    x = RNG.standard_normal((4, n))
    close_to_scale(flt.downsample_fir(h, x, q), ss.upfirdn(h, x, up=1, down=q, axis=-1), 1e-14)


@pytest.mark.parametrize("distance", [1, 2.5, 94])
def test_find_peaks_is_scipys(distance):
    t = np.arange(29000) / FS
    for trial in range(20):
        y = np.exp(-0.3 * t) * np.sin(2 * np.pi * 13.0 * t) + 0.02 * RNG.standard_normal(t.size)
        if trial % 2:  # rounded: flat tops (plateaus) of every width
            y = np.round(y, 2)
        np.testing.assert_array_equal(flt.find_peaks(y, distance), ss.find_peaks(y, distance=distance)[0])
    with pytest.raises(ValueError, match="distance"):
        flt.find_peaks(y, 0.5)


def test_a_replay_does_not_import_scipy_signal():
    code = ("import sys, ramdaq.daq.commands.cli, ramdaq.daq.session, ramdaq.drivers.mcap_replay, "
            "ramdaq.daq.commands.analyze, ramdaq.analysis.impact; print('scipy.signal' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    assert out.stdout.strip() == "False"


def test_exp_filter_block_by_block_is_the_whole_record_to_the_bit():
    x = RNG.standard_normal((3, 3000)) ** 2
    whole = flt.exp_filter(x, 1 / 400, np.zeros(3))
    prev, parts = np.zeros(3), []
    for a, b in [(0, 1), (1, 700), (700, 701), (701, 3000)]:
        parts.append(flt.exp_filter(x[:, a:b], 1 / 400, prev))
        prev = parts[-1][:, -1]
    assert np.array_equal(np.hstack(parts), whole)
