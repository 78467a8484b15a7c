"""The report's plots: Figures, no backend chosen at import, a decay panel whose fitted line is the
envelope drawn, PNGs at 150 dpi."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

import ramdaq
from ramdaq.daq.api import decay_samples
from ramdaq.daq.reports.impact_plots import DPI, mode_components, mode_envelopes, plot_impact

WATER = Path(__file__).parent.parent / "recordings" / "albacore-water.mcap"


@pytest.fixture(scope="module")
def hit0() -> ramdaq.TrialAnalysis:
    return ramdaq.analyze(WATER, impact=0)


def test_importing_the_plots_leaves_the_backend_alone() -> None:
    code = ("import matplotlib; b = matplotlib.get_backend(); "
            "import ramdaq.daq.reports.impact_plots, ramdaq.daq.reports.gap_plots, sys; "
            "print(matplotlib.get_backend() == b, 'matplotlib.pyplot' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={"MPLBACKEND": "svg", "PATH": ""})
    assert out.stdout.split() == ["True", "False"]


def test_figures_by_kind(hit0: ramdaq.TrialAnalysis) -> None:
    figs = hit0.figures(0)
    assert set(figs) >= {"decay", "spectrum", "modeshape"}
    assert all(isinstance(f, Figure) for f in figs.values())
    with pytest.raises(ValueError, match="hit 1 was not analysed"):
        hit0.figures(1)


def test_decay_panel_line_is_the_envelope_drawn(hit0: ramdaq.TrialAnalysis) -> None:
    """Per gage and mode the log-envelope drawn falls at the rate of the fitted line drawn,
    -delta f: the decrement shown is the one the eye sees."""
    h = hit0.hits[0]
    a, fs = h.analysis, hit0.recording.fs_hz
    x = decay_samples(h, hit0.rig)
    env = mode_envelopes(mode_components(a, x, fs), fs, a.modes.frequency_hz)
    t = np.arange(x.shape[1]) / fs
    m, checked = a.modes, 0
    for j in range(len(a.active_gages)):
        for k in range(len(m.frequency_hz)):
            rate = m.channel_delta[j, k] * m.channel_frequency_hz[j, k]
            line = abs(m.complex_amplitude[j, k]) * np.exp(-rate * t)
            # where the mode stands 10x above the gage's noise, away from the filter's ends
            use = (t > 0.5) & (t < t[-1] - 1) & (line > 10 * m.noise_std[j])
            if use.sum() < 600:
                continue
            slope = np.polyfit(t[use], np.log(env[j, k, use]), 1)[0]
            # the envelope's relative noise there is <= 0.1 per sample, so the slope fitted over
            # >= 600 samples has a standard error well under 1 %: 2 % holds it
            assert -slope == pytest.approx(rate, rel=0.02), (a.active_gages[j], k)
            checked += 1
    assert checked >= 10


def test_a_decayed_mode_envelope_stays_at_the_noise_to_the_record_end() -> None:
    """A 47 Hz mode (delta 0.19: 1e-9 of its start after 2.5 s) over 5 s of noise: where it has
    decayed, the envelope drawn is the noise's, measured with the same estimator on the noise
    alone (median over the last second within a factor 3: the median of a Rayleigh envelope of
    ~200 independent band-limited values scatters by a few %). The FFT's Hilbert transform
    carried the ringing's abrupt start onto the record's quiet end and rose 1000x there."""
    fs, f, delta, n = 1000.0, 47.0, 0.1886, 5186
    t = np.arange(n) / fs
    noise = 2e-3 * np.random.default_rng(3).standard_normal(n)
    ring = 0.28 * np.exp(-delta * f * t) * np.cos(2 * np.pi * f * t + 0.4)
    both, alone = (mode_envelopes(v[None, None, :], fs, np.array([f]))[0, 0]
                   for v in (ring + noise, noise))
    last = t > t[-1] - 1.0
    assert np.median(both[last]) < 3 * np.median(alone[last])
    # where the ring stands far above the noise, its envelope; 10 %: the low-pass's start
    # transient (odd extension of the 2f image) is ~10 % for its first few 1 / (0.2 f)
    early = (t > 0.05) & (t < 0.5)
    np.testing.assert_allclose(both[early], 0.28 * np.exp(-delta * f * t[early]), rtol=0.1)


def test_pngs_at_150_dpi(hit0: ramdaq.TrialAnalysis, tmp_path: Path) -> None:
    h = hit0.hits[0]
    files = plot_impact(h.analysis, decay_samples(h, hit0.rig), hit0.recording.fs_hz, hit0.rig,
                        tmp_path, 0)
    assert DPI >= 150 and {f.name for f in files} >= {"impact0_decay.png", "impact0_spectrum.png",
                                                       "impact0_modeshape.png"}
    import matplotlib.image

    for f in files:
        fig_in = {"decay": 16, "spectrum": 11, "modeshape": 13, "stock": 11}[f.stem.split("_")[1]]
        assert matplotlib.image.imread(f).shape[1] == fig_in * DPI  # width px = inches x dpi


def test_a_decay_figure_redrawn_for_the_next_hit_is_the_one_drawn_anew(
        hit0: ramdaq.TrialAnalysis, tmp_path: Path) -> None:
    """``ramdaq analyze`` redraws one decay figure hit after hit (``reuse``): hit 1 drawn on the
    figure of hit 0 (its curves, legend and limits cleared) is, pixel for pixel, hit 1 drawn
    on a new figure -- nothing of hit 0 is left in it."""
    import matplotlib.image

    hit1 = ramdaq.analyze(WATER, impact=1)
    fs = hit0.recording.fs_hz
    h0, h1 = hit0.hits[0], next(h for h in hit1.hits if h.index == 1)
    fresh = plot_impact(h1.analysis, decay_samples(h1, hit1.rig), fs, hit1.rig, tmp_path / "new",
                        1, ("decay",))
    reuse: dict = {}
    plot_impact(h0.analysis, decay_samples(h0, hit0.rig), fs, hit0.rig, tmp_path / "re", 0,
                ("decay",), reuse=reuse)
    shared = reuse["decay_background"]
    redrawn = plot_impact(h1.analysis, decay_samples(h1, hit1.rig), fs, hit1.rig,
                          tmp_path / "re", 1, ("decay",), reuse=reuse)
    assert "decay" in reuse
    # hit 1's decay is a sample shorter than hit 0's: the layer every hit shares (drawn for
    # hit 0) was restored, not drawn again -- the pixels below compare that path
    assert reuse["decay_background"] is shared
    assert np.array_equal(matplotlib.image.imread(fresh[0]), matplotlib.image.imread(redrawn[0]))


def test_plots_a_channels_only_import_cannot_give_are_said(tmp_path: Path, capsys) -> None:
    """``--plots all`` on a channels-only import left out the mode-shape and stock plots without
    a word: report.json's ``skipped`` and the printed summary name each with why; the spectrum
    says it is the mean of all gages (it said 'of the rudder gages' with no rudder)."""
    from ramdaq.daq.commands.cli import main

    t = np.arange(0, 8, 1e-3)  # 1000 Hz
    rng = np.random.default_rng(3)
    ring = np.where(t >= 2, np.exp(-0.02 * 2 * np.pi * 20 * (t - 2)) * np.sin(2 * np.pi * 20 * (t - 2)), 0)
    acc = np.outer([1.0, 0.6], ring) + 1e-3 * rng.standard_normal((2, t.size))
    csv = tmp_path / "two.csv"
    csv.write_text("time [s],A1 [m/s^2],A2 [m/s^2]\n" + "\n".join(
        f"{t[k]:.4f},{acc[0, k]:.6f},{acc[1, k]:.6f}" for k in range(t.size)) + "\n")
    assert main(["import", str(csv)]) == 0
    assert main(["analyze", str(tmp_path / "two.mcap"), "--plots", "all",
                 "--out", str(tmp_path / "rep")]) == 0
    printed = capsys.readouterr().out
    report = __import__("json").loads((tmp_path / "rep" / "report.json").read_text())
    steps = {s["step"]: s["reason"] for s in report["skipped"]}
    assert "no gage positions" in steps["modeshape plot"] and "stock" in steps["stock plot"]
    assert "skipped: modeshape plot: a channels-only rig" in printed
    assert sorted(p.name for p in (tmp_path / "rep").glob("*.png")) == [
        "impact0_decay.png", "impact0_spectrum.png"]
    spectrum = ramdaq.analyze(tmp_path / "two.mcap", impact=0).figures(0)["spectrum"]
    assert "mean of all gages" in spectrum.axes[0].get_ylabel()


def test_png_written_without_pillow_reads_back_exactly(tmp_path: Path) -> None:
    """The plots' own PNG writer (zlib, no row filter): RGB and RGBA images read back by Pillow
    byte for byte, with the resolution recorded; anything else is refused, not written."""
    from PIL import Image

    from ramdaq.daq.reports.png import write_png

    rng = np.random.default_rng(5)
    for channels, mode in ((3, "RGB"), (4, "RGBA")):
        img = rng.integers(0, 256, (7, 11, channels), dtype=np.uint8)
        write_png(tmp_path / f"{mode}.png", img, 150)
        with Image.open(tmp_path / f"{mode}.png") as back:
            assert back.mode == mode and back.size == (11, 7)
            assert np.array_equal(np.asarray(back), img)
            # PNG records whole pixels per metre: 150 dpi is 5906 /m, 150.01 dpi read back
            assert back.info["dpi"][0] == pytest.approx(150, abs=0.02)
    with pytest.raises(ValueError, match="uint8"):
        write_png(tmp_path / "bad.png", np.zeros((2, 2, 3)), 150)
