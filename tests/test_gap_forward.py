"""The forward model leaves a blow out of a later segment only where it has rung out: below
``RUNG_OUT`` of its size, so the prediction is the full one to rounding."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import ramdaq.analysis.gap.forward as forward
from ramdaq.analysis.gap.forward import RUNG_OUT, Forward, _rung_out
from ramdaq.daq.gap_trial import load_trial, trial_data

ROOT = Path(__file__).resolve().parents[1]


def test_a_blow_is_rung_out_only_when_its_decay_is_below_the_bound():
    td = trial_data(load_trial(ROOT / "recordings" / "albacore-water.mcap"))
    fw = Forward(td, np.full(td.n_gages, 1e-3))
    ms = fw.modes(np.zeros(len(fw.params)))
    _, JT = fw.pulse_basis(ms)
    # the slowest mode's decay time: after 1 s it has lost little, after 60 of its time
    # constants (e^-60 ~ 1e-26) every mode is far below 1e-13
    tau = 1 / np.min(-ms.lam.real)
    assert not _rung_out(ms, JT * np.exp(ms.lam * 1.0), JT)
    assert _rung_out(ms, JT * np.exp(ms.lam * 60 * tau), JT)
    # in between, the answer is the bound's: every gage's sum of mode moduli (and rates)
    # against the same just after the blow
    A, lam = np.abs(ms.A), np.abs(ms.lam)
    for t in np.linspace(0, 60 * tau, 25):
        c = np.abs(JT * np.exp(ms.lam * t))
        ratio = max((A @ c).max() / (A @ np.abs(JT)).max(),
                    (A @ (c * lam)).max() / (A @ (np.abs(JT) * lam)).max())
        assert _rung_out(ms, JT * np.exp(ms.lam * t), JT) == (ratio <= RUNG_OUT)
    assert RUNG_OUT < 1e-12


def test_the_prediction_with_rung_out_blows_left_out_is_the_full_one(monkeypatch):
    """The sample trial with its blows' decays cut wherever they fall below the bound, against
    the same with nothing cut: the same forces and prediction to 1e-12 (rounding of the least
    squares is ~1e-15; what is cut is below 1e-13 of a blow)."""
    td = trial_data(load_trial(ROOT / "recordings" / "albacore-water.mcap"))
    fw = Forward(td, np.full(td.n_gages, 1e-3))
    th = np.zeros(len(fw.params))
    ms = fw.modes(th)
    # a small bound makes the second and later segments cut nothing; a large one cuts every
    # later segment -- the first must be exact, the second must differ (the test can fail)
    cut = fw.fit(th, modes=ms)
    monkeypatch.setattr(forward, "RUNG_OUT", -1.0)
    full = fw.fit(th, modes=ms)
    scale = np.max(np.abs(full.pred))
    assert np.max(np.abs(cut.pred - full.pred)) < 1e-12 * scale
    np.testing.assert_allclose(cut.force, full.force, rtol=1e-12)
    monkeypatch.setattr(forward, "RUNG_OUT", 1.0)
    crude = fw.fit(th, modes=ms)
    assert np.max(np.abs(crude.pred - full.pred)) > 1e-9 * scale


def test_the_blocks_a_pulse_writes_solve_as_the_dense_unit_responses():
    """A prediction made from only the (impact, segment) blocks a pulse writes is the one made
    from the dense unit responses, to the bit (the block form only leaves the zeros out), for
    the main blow alone and with a second, smaller contact 30 ms later (blocks written twice,
    a ratio other than 1); and a design solves many data as a fresh one would."""
    from ramdaq.analysis.gap.effects import EFFECTS
    from ramdaq.analysis.gap.terms import Term, placement

    td = trial_data(load_trial(ROOT / "recordings" / "albacore-water.mcap"))
    fw = Forward(td, np.full(td.n_gages, 1e-3))
    ms = fw.modes(np.zeros(len(fw.params)))
    pl = placement({"delays_ms": [30.0] * td.n_seg}, ("ratio",), ("1",), 0.0, 0.0, 1.0, [[0.2]])
    hit = EFFECTS["double_hit"]
    assert not hit.changes_units() and EFFECTS["friction"].changes_units()
    preds = []
    for terms in ([], [Term(hit, pl, np.array([0.2]))]):
        U, dU = fw.unit_responses(ms, terms)
        dense = fw.linear_design(U, dU, None)
        blocks = fw.block_design(fw.unit_blocks(ms, terms), None)
        for data in (fw.x0, 2 * fw.x0 + 1e-3):
            c1, p1 = dense.solve(data)
            c2, p2 = blocks.solve(data)
            np.testing.assert_array_equal(c1, c2)
            np.testing.assert_array_equal(p1, p2)
        again = fw.linear_design(U, dU, None).solve(2 * fw.x0 + 1e-3)
        np.testing.assert_array_equal(again[1], dense.solve(2 * fw.x0 + 1e-3)[1])
        preds.append(p2)
    assert np.max(np.abs(preds[0] - preds[1])) > 1e-6 * np.max(np.abs(preds[0]))   # the second contact shows


def test_a_friction_terms_prediction_from_blocks_is_its_dense_ones_to_the_bit(monkeypatch):
    """A friction term changes every impact's unit response in every later segment: its
    prediction made on the blocks a pulse writes (the friction's blocks added, each let go as
    the design takes it) is the one made from the dense unit responses, forces and all, to the
    bit; and with the friction off the blocks are the pulses' alone."""
    from ramdaq.analysis.gap.effects import EFFECTS
    from ramdaq.analysis.gap.effects.friction import Friction
    from ramdaq.analysis.gap.terms import Term

    td = trial_data(load_trial(ROOT / "recordings" / "albacore-water.mcap"))
    fw = Forward(td, np.full(td.n_gages, 1e-3))
    theta = np.zeros(len(fw.params))
    fric = EFFECTS["friction"]
    pl = fric.placements(fw, fw.fit(theta))[0]
    fits = {}
    for how in ("blocks", "dense"):
        if how == "dense":
            monkeypatch.setattr(Friction, "units_on_blocks", lambda *a: False)
        fits[how] = [fw.fit(theta, [Term(fric, pl, np.array([k]))]) for k in (0.0, 0.3)]
    for a, b in zip(fits["blocks"], fits["dense"], strict=True):
        np.testing.assert_array_equal(a.pred, b.pred)
        np.testing.assert_array_equal(a.force, b.force)
    # the friction moves the prediction, and off it is the model without the term
    off, on = fits["blocks"]
    assert np.max(np.abs(on.pred - off.pred)) > 1e-3 * np.max(np.abs(off.pred))
    np.testing.assert_array_equal(off.pred, fw.fit(theta).pred)
