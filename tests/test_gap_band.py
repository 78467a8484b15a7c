"""The diagnosis band does not jump when the rig is off by the field's +-25 %: the highest mode
compared and the low-pass corner move with the rig's frequencies, never to another mode."""

from __future__ import annotations

import itertools

import pytest

from ramdaq.analysis.gap.rigfit import get_value, set_value
from ramdaq.analysis.gap.trialdata import RIG_SPREAD, analysis_band, default_max_hz
from ramdaq.analysis.model.rig import load_rig
from ramdaq.daq.commands.gap_bench import PERTURBED

FS = 2048.0
# a frequency ratio moves at most (1 + u) / (1 - u) when stiffnesses and masses are each off by
# up to u (f goes as sqrt(k / m)); the next mode up or down is >= 3.6x away in these rigs, so a
# ratio inside this bound is the same mode, outside it another one
RATIO = (1 + RIG_SPREAD) / (1 - RIG_SPREAD)


def _vertices(rig):
    """The rig with every perturbed constant (the benchmark's: masses, inertias, stiffnesses,
    each hull mode's frequency and modal mass) at 1 - u or 1 + u: the box's corners, where a
    ratio of two frequencies is furthest from the nominal's."""
    names = list(PERTURBED) + [f"hull.modes[{k}].{key}" for k in range(len(rig.hull_modes))
                               for key in ("frequency_hz", "modal_mass_kg")]
    for signs in itertools.product((1 - RIG_SPREAD, 1 + RIG_SPREAD), repeat=len(names)):
        r = rig
        for name, s in zip(names, signs, strict=True):
            r = set_value(r, name, get_value(r, name) * s)
        yield r


@pytest.mark.parametrize("name,medium", [("albacore", "water"), ("albacore", "air"),
                                         ("sampson", "water")])
def test_band_holds_its_modes_under_a_25_percent_rig_error(name, medium):
    """At every corner of the +-25 % box the highest mode compared is the nominal rig's highest,
    moved (ratio within RATIO), and the corner moves no more: with the cut at 5x the rig's own
    predominant mode, ALBACORE's 59.8 Hz mode (4.6x its 13 Hz mode in water) was dropped and the
    corner fell from 113.6 Hz to 24 Hz (ratio 0.21)."""
    rig = load_rig(name).with_medium(medium)
    c0, m0 = analysis_band(rig, FS)
    n = 0
    for r in _vertices(rig):
        c, m = analysis_band(r, FS)
        assert 1 / RATIO < max(m) / max(m0) < RATIO, (name, medium, m0, m)
        assert 1 / RATIO < c / c0 < RATIO, (name, medium, c0, c)
        n += 1
    assert n >= 128


def test_default_cut_is_five_times_the_predominant_mode_widened_by_the_ratio_bound():
    """5x the predominant mode, times (1 + u) / (1 - u): 8.33x at +-25 %, 5x with an exact rig."""
    assert default_max_hz(13.0) == pytest.approx(5 * 13.0 * 1.25 / 0.75)
    assert default_max_hz(13.0, spread=0.0) == pytest.approx(65.0)
    with pytest.raises(ValueError, match="spread"):
        default_max_hz(13.0, spread=1.0)


def test_nominal_bands_are_unchanged():
    """The stock rigs' next modes above the kept ones sit at 13.7-16.7x their predominant modes,
    beyond the widened cut: their corners are those of the 5x rule (pinned here, Hz, to 0.1)."""
    for (name, medium), corner in {("albacore", "water"): 113.6, ("albacore", "air"): 171.7,
                                   ("sampson", "water"): 54.2}.items():
        assert analysis_band(load_rig(name).with_medium(medium), FS)[0] == pytest.approx(corner, abs=0.05)
