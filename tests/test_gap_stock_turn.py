"""The stock's top turning with the rudder (``modal_level.stock_turns``): a steering gear of
finite stiffness, which every rig with a rigid gear leaves at zero whatever its masses, inertias
and stiffnesses -- the stock's twist between the rudder and the hull is kinematics, not a
constant -- and which the calibration that absorbs the lowered torsion mode does not absorb."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ramdaq.analysis.gap.layers import answer
from ramdaq.analysis.gap.modal_level import TURN_FORM, compare, coupled_modes, stock_turns
from ramdaq.analysis.gap.rigfit import get_value, set_value
from ramdaq.analysis.model.rig import load_rig
from tests.test_gap_structure import modes_of, with_tiller

TILLER_HZ = 60.0


def test_a_tiller_turns_the_stock_top_by_its_law():
    rig = load_rig("albacore").with_medium("air")
    tm = modes_of(with_tiller(rig, TILLER_HZ))
    (t,) = stock_turns(tm, rig)
    assert t.kind == "tiller" and t.statistic > t.chance
    # a gear as stiff as the stock with the tiller's own mode at 60 Hz turns the stock's top by
    # k_s / (k_s + k_g - J_t w^2) = 1 / (2 - (f / 60)^2) of the rudder's rotation: the model's
    # own kinematics, to the 2 % damping's phase and the identification's 1e-4 shape errors
    for f, q in zip(t.modes_hz, t.turn, strict=True):
        if f < TILLER_HZ:
            assert abs(q - 1 / (2 - (f / TILLER_HZ) ** 2)) < 0.01, (f, q)
    rudder = {g.number for g in rig.gages_by_channel() if g.body != "hull"}
    assert t.gages and set(t.gages) <= rudder
    # reported beside the hull modes, as the model level's coupled list carries it
    assert any(c.kind == "tiller" for c in coupled_modes(tm, rig, compare(tm, rig)))


def test_no_constant_of_the_rig_turns_the_stock_top():
    rig = load_rig("albacore").with_medium("air")
    assert stock_turns(modes_of(rig), rig) == []
    # a rig whose masses, inertias and stiffnesses are off by 25 % (a trial of the one held
    # against the other): the modes move, the twist's kinematics do not
    off = rig
    for name, fac in (("stock.J_m4", 0.75), ("stock.I_m4", 1.25), ("rudder.Iz_kg_m2", 1.25),
                      ("rudder.mass_kg", 0.75)):
        off = set_value(off, name, fac * get_value(off, name))
    assert stock_turns(modes_of(off), rig) == []


def test_a_stock_that_does_not_twist_as_the_rig_says_raises_none():
    rig = load_rig("albacore").with_medium("air")
    tm = modes_of(with_tiller(rig, TILLER_HZ))
    # the stock's gages reading their own field at half the rig's kinematics (the modal
    # family's stock follows the rudder's field at 30-70 %): the twist is no line from the
    # rudder to a turning top, whatever the top does
    stock = np.array([g.body == "stock" for g in rig.gages_by_channel()])
    half = replace(tm, shapes=np.where(stock[:, None], 0.5 * tm.shapes, tm.shapes))
    assert stock_turns(half, rig) == []


def test_a_turning_stock_answers_tiller_where_the_model_names_nothing():
    turn = {"f_hz": 46.2, "zeta": 0.013, "modes_hz": [23.0, 46.2], "turn": [0.69, 0.77],
            "statistic": 13.5, "chance_level": 1.0, "gages": [8, 4, 1, 3], "kind": "tiller"}
    cands = [{"name": "tiller", "dbic": -5.0, "dbic_marginal": None, "closed_held": 0.4,
              "closed_fit": 0.4, "location": {"gages": [1, 3], "window": "all", "band_hz": 46.0}},
             {"name": "gage_sensitivity", "dbic": -50.0, "dbic_marginal": None, "closed_held": 0.9,
              "closed_fit": 0.9, "location": {"gages": [3], "window": "all", "band_hz": 46.0}}]
    form = {1, 3, 8}
    assert answer("unexplained", cands, None, form, [], (), [], []).named == "none"
    for model in ("unexplained", None):       # the gap taken for the rig's form, or no gap at all
        a = answer(model, cands, None, form, [], (), [], [turn])
        assert a.named == "tiller" and a.location["gages"] == [8, 4, 1, 3]
        assert a.location["effect_mode_hz"] == 46.2 and a.closed_held == 0.4
    # an effect the model names stands (a gage's sensitivity is judged by the data layer)
    assert answer("gage_sensitivity", cands, None, set(), [], (), [], [turn]).named == "gage_sensitivity"
    assert TURN_FORM < min(turn["turn"])
