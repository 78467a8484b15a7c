"""Issue 17, the sensor layer's phase check against the gage's peers: a phase departure that no
one time skew fits is a channel's fault only where it stands out of the departures of the other
gages of its body at the same modes; where they depart as much, it is the mode shapes'
complexity (model form), which the body's gages share."""

from __future__ import annotations

import math

import numpy as np

from ramdaq.analysis.gap.datamodel import FreeModal, Layer
from ramdaq.analysis.gap.layers import answer
from ramdaq.analysis.gap.sensors import chain_phase
from tests.test_gap_phase_form import _bench_trial, _free_model

F_HZ = np.array([10.0, 25.0, 40.0, 60.0, 85.0, 110.0])
BODIES = ["rudder"] * 3 + ["hull"] * 3
NUMBERS = [1, 2, 3, 4, 5, 6]
LAG = -2 * math.pi * F_HZ * 0.5 / 2048.0
"""A half-sample delay's phase at each mode, rad."""
PATTERN = np.array([1, -1, 1, -1, 1, -1])
"""With :data:`LAG`, a departure no delay fits: +-0.25 rad alternating from mode to mode (12
phase floors of 0.02 rad each) about a delay's line."""


def _phases(departures: dict[int, np.ndarray]) -> FreeModal:
    """Six gages (rows 0-2 the rudder's, 3-5 the hull's), six modes, four impacts of real unit
    shapes at SNR 1000 (each phase known to 0.001 rad, under the 0.02 rad floor); row ``i``'s
    phase off by ``departures[i]`` (rad, per mode, the same at every impact)."""
    amp = np.ones((4, 6, 6), complex)
    for i, dep in departures.items():
        amp[:, i, :] *= np.exp(1j * dep)[None, :]
    return FreeModal(f_hz=F_HZ, delta=np.full(6, 0.1), f_se_hz=np.zeros(6), delta_se=np.zeros(6), amp=amp,
                     amp_se=np.full(amp.shape, 1e-3), noise=np.full((4, 6), 1e-3), t0_s=np.arange(4.0),
                     n_s=1000, fs_hz=2048.0, steady=np.zeros(6, bool))


def test_one_gages_misfit_among_quiet_peers_stays_unexplained():
    # gage 3 alone departs (a half-sample delay +-0.25 rad): its body's other gages sit within
    # the floor, so the departure is its channel's and it stays a sensor finding
    (f,) = chain_phase(_phases({2: LAG + 0.25 * PATTERN}), NUMBERS, BODIES)
    assert f.check == "chain_misfit" and f.gages == (3,) and f.layer is Layer.SENSOR
    assert answer(None, [], None, set(), [f.to_json()]).named == "unexplained"


def test_a_misfit_its_body_shares_is_model_form():
    # the rudder's three gages depart alike (a half-sample delay +-0.25 rad, at 0.8-1.2x as a
    # complex shape's scale varies with where a gage sits): gage 2's departure, no one delay's,
    # is within its body's (F about 1-2.5 against 3.4), model form; and the trial answers no
    # effect. Held against every other gage instead (the quiet hull's too) it would stand out
    d = LAG + 0.25 * PATTERN
    deps = {0: d, 1: 1.2 * d, 2: 0.8 * d}
    found = chain_phase(_phases(deps), NUMBERS, BODIES)
    assert found and all(f.check == "complex_phase" and f.layer is Layer.MODEL_FORM
                         and f.statistic <= f.chance_level for f in found)
    assert 2 in {f.gages[0] for f in found}
    assert answer(None, [], None, set(), [f.to_json() for f in found]).named == "none"
    alone = {f.gages[0]: f.check for f in chain_phase(_phases(deps), NUMBERS)}
    assert alone[2] == "chain_misfit"


def test_a_rattles_hull_misfits_are_form_and_a_gain_drift_is_not(tmp_path):
    """Modal development trials: a stock rattle (trial 3) leaves hull gages 15 and 16 with a phase
    no skew fits (100x the chi-square(1) level), which the hull's other gages share at the same
    modes (F 0.3 against 4.1): model form. A gain drifting through the trial on gage 8 (gain
    drift trial 3) departs some 400x as much as its body's other gages: still "unexplained" at
    gage 8."""
    lt, _ = _bench_trial("dev", "rattle", 3, tmp_path)
    gages = lt.rig.gages_by_channel()
    found = chain_phase(_free_model(lt), [g.number for g in gages], [g.body for g in gages])
    assert not [f for f in found if f.check == "chain_misfit"]
    assert {15, 16} <= {f.gages[0] for f in found if f.check == "complex_phase"}
    lt, truth = _bench_trial("dev", "gain_drift", 3, tmp_path)
    gages = lt.rig.gages_by_channel()
    found = chain_phase(_free_model(lt), [g.number for g in gages], [g.body for g in gages])
    misfit = [f for f in found if f.check == "chain_misfit"]
    assert [f.gages for f in misfit] == [tuple(truth["gages"])]
