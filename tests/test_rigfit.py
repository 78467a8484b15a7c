"""The model level of the gap diagnosis: a trial's identified modes against its rig's model
(pairing, frequency, damping, MAC per gage body), the rig's constants calibrated to those modes,
and ``ramdaq rig fit`` writing the calibrated rig."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from ramdaq.analysis.gap.modal_level import compare, trial_modes
from ramdaq.analysis.gap.trialdata import prepare
from ramdaq.analysis.model.rig import load_rig
from ramdaq.drivers.sim import SimDevice

IMPACTS = [3.0 + 5.0 * i for i in range(6)]


def sim_trial(rig, seed=1):
    with SimDevice(rig, seed=seed, duration_s=IMPACTS[-1] + 5, impacts=IMPACTS, pace="fast") as dev:
        blocks = list(dev)
    return np.concatenate([b.counts * b.scale[:, None] for b in blocks], axis=1), blocks[0].fs_hz


@pytest.fixture(scope="module")
def albacore_air():
    return load_rig("albacore").with_medium("air")


@pytest.fixture(scope="module")
def nominal_modes(albacore_air):
    x, fs = sim_trial(albacore_air)
    td = prepare(x, fs, np.array(IMPACTS), albacore_air)
    return td, trial_modes(td)


def test_identified_modes_match_their_own_model(albacore_air, nominal_modes):
    td, tm = nominal_modes
    c = compare(tm, albacore_air)
    below = [f for f in c.model.f_hz if 0 < f < 0.9 * td.lowpass_hz]
    assert len(c.pairs) == len(below) == 3 and not c.unpaired_id
    for p in c.pairs:
        assert p.i_id == p.i_model
        # the identified frequency and damping scatter by their standard error (the impacts'
        # spread); 5 se: a Gaussian leaves that once in 1.7 million
        assert abs(p.f_model_hz - p.f_id_hz) < 5 * p.f_id_se_hz, p
        assert abs(p.zeta_model - p.zeta_id) < 5 * p.zeta_id_se, p
        # noise at 1e-4 of the signal leaves a shape error of that order: MAC 1 - 1e-8; 1e-3
        # leaves room for the weakest (hull) mode's lower signal-to-noise
        assert p.mac > 0.999 and p.mac_rudder > 0.999
    # the 88 Hz mode barely moves the hull: no hull MAC is claimed for it
    assert math.isnan(c.pairs[2].mac_hull) and c.pairs[0].mac_hull > 0.999


def test_a_mistuned_rig_pairs_by_shape_and_shows_its_error(albacore_air, nominal_modes):
    _, tm = nominal_modes
    soft = replace(albacore_air, stock=replace(albacore_air.stock, I_m4=albacore_air.stock.I_m4 * 0.7))
    c = compare(tm, soft)
    assert [p.i_model for p in c.pairs] == [0, 1, 2]
    # the 24.5 Hz mode is the stock's bending: 30 % less EI takes it down ~16 % (k_s ~ EI)
    assert -0.2 < c.pairs[1].df_rel < -0.1
    assert abs(c.pairs[0].df_rel) < 0.01
