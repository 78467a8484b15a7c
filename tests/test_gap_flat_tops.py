"""Clipping read on the recorded values (issue 17): flat tops summed over every blow's extremes
(:func:`ramdaq.analysis.gap.signal_checks.flat_tops`), and a strong, held-out-closing flat top
answering before the model layer's effect (:func:`ramdaq.analysis.gap.layers.flat_tops_first`).

The trials are the simulated ALBACORE-in-water trial of the sensor-injection checks (six blows,
24-bit converter), clipped in plain numpy on its recorded values."""

from __future__ import annotations

import numpy as np
import pytest

from ramdaq.analysis.gap.datamodel import Finding, Layer
from ramdaq.analysis.gap.layers import PRECEDENCE_STRENGTH, answer, flat_tops_first
from ramdaq.analysis.gap.signal_checks import flat_top_level, flat_tops
from tests.sensor_injection import IMPACTS, simulate


@pytest.fixture(scope="module")
def trial():
    x, fs, gages = simulate(7)
    return x, fs, gages, np.array(IMPACTS)


def _clipped(x: np.ndarray, gages: list[int], gage: int, frac: float) -> np.ndarray:
    """``x`` with gage ``gage`` held within ``frac`` of its largest value (a converter's rails)."""
    y = x.copy()
    r = gages.index(gage)
    top = frac * np.max(np.abs(x[r]))
    y[r] = np.clip(x[r], -top, top)
    return y


def test_a_clean_trial_has_no_flat_top(trial):
    # chance level at P_CHANCE = 1e-3 over 16 gages: a clean trial raises one at most 1 in 1000
    x, fs, gages, on = trial
    assert flat_tops(x, fs, on, gages) == []


def test_rails_a_fifth_below_the_peak_are_found_on_the_clipped_gage_alone(trial):
    # at 80 % of gage 1's largest value each blow's first cycles touch the rails for 2-4 samples:
    # no single run is long (the longest-run test of one peak missed it), but every extreme is flat
    x, fs, gages, on = trial
    (f,) = flat_tops(_clipped(x, gages, 1, 0.8), fs, on, gages)
    assert f.gages == (1,) and f.layer is Layer.SENSOR
    assert f.statistic >= PRECEDENCE_STRENGTH * f.chance_level
    # the flat top is the rail, to the converter's step
    assert f.size == pytest.approx(0.8 * np.max(np.abs(x[gages.index(1)])), rel=1e-6)


def test_the_chance_level_grows_as_equal_neighbours_become_likely():
    # p = 0.0093 (a 24-bit converter under its noise) against p = 0.3 (a step a third of the
    # noise): the bound C(s+n-1, n-1) (1+s/n)^n p^s reaches 1e-3/16 at s = 5 and s = 45 (n = 12)
    assert flat_top_level(0.0093, 12, 16) == 5.0
    assert flat_top_level(0.3, 12, 16) == 45.0
    assert flat_top_level(0.999, 12, 16) == np.inf       # a converter too coarse to tell


def _flat_top(statistic: float, chance: float, closed: float) -> dict:
    return Finding(check="clipping", layer=Layer.SENSOR, gages=(8,), statistic=statistic,
                   chance_level=chance, size=6.68, unit="m/s^2", text="flat", window="peaks",
                   closed_held=closed).to_json()


def _candidate(name: str, gages: list[int], closed: float) -> dict:
    return {"name": name, "closed_held": closed, "closed_fit": closed, "dbic": -1e5,
            "location": {"gages": gages, "window": "all", "band_hz": 20.0, "effect_mode_hz": 20.0}}


def test_a_strong_flat_top_that_closes_held_out_answers_before_a_model_effect():
    # a modal clipping trial's flat tops at 3.1x their chance level, closing all of the free
    # model's misfit at the held-out peaks, against the model's hull_coupling+gage_alignment
    cands = [_candidate("hull_coupling+gage_alignment", [8, 2], 0.6)]
    clip = _flat_top(22.0, 7.0, 1.0)
    a = answer("hull_coupling+gage_alignment", cands, None, set(), [clip])
    assert a.named == "clipping" and a.by == "data" and a.location["gages"] == [8]


def test_a_weak_or_unclosing_flat_top_leaves_the_models_effect():
    cands = [_candidate("hull_coupling+gage_alignment", [8, 2], 0.6)]
    weak = _flat_top(9.0, 7.0, 1.0)                  # 1.3x its chance level
    unclosing = _flat_top(22.0, 7.0, 0.2)            # its rails explain a fifth held out
    for f in (weak, unclosing):
        assert flat_tops_first([f], "hull_coupling+gage_alignment") == []
        assert answer("hull_coupling+gage_alignment", cands, None, set(), [f]).named == \
            "hull_coupling+gage_alignment"
    # the model naming clipping itself keeps its own answer and place
    assert flat_tops_first([_flat_top(22.0, 7.0, 1.0)], "clipping") == []
