"""The diagnosis's shortcuts for cost give the very numbers of the long way: the prefit's
frequencies without the rest of a mode set, a prediction's right-hand side summed with its
normal equations, the Broyden update in row blocks. Exact equality, not a tolerance, where a
shortcut does the same floating-point operations on the same operands, only fewer others (a
cache, a reused buffer); a tolerance with its reason where a path is held against its closed
form."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ramdaq.analysis.gap.calibrate import NORMAL_ROWS, _broyden
from ramdaq.analysis.gap.effects import EFFECTS
from ramdaq.analysis.gap.forward import Forward
from ramdaq.analysis.gap.terms import Term
from ramdaq.daq.gap_trial import load_trial, trial_data

ROOT = Path(__file__).resolve().parents[1]


def _forward() -> Forward:
    td = trial_data(load_trial(ROOT / "recordings" / "albacore-water.mcap"))
    return Forward(td, np.full(td.n_gages, 1e-3))


def test_the_prefit_frequencies_are_the_mode_sets():
    """At constants spread over their bounds, with a term that changes the model (added mass)
    and one that changes the mode set (gage alignment: the long way itself), and failing alike
    where the model cannot be built."""
    fw = _forward()
    rng = np.random.default_rng(7)
    bound = np.array([p.bound for p in fw.params])
    thetas = [np.zeros(len(bound))] + [rng.uniform(-0.8, 0.8, len(bound)) * bound for _ in range(6)]
    am = EFFECTS["added_mass"]
    pl = am.placements(fw, None)[0]
    for th in thetas:
        np.testing.assert_array_equal(fw.frequencies(th), fw.modes(th).f_hz)
        t = Term(am, pl, np.array([0.7]))
        got, want = fw.frequencies(th, [t]), fw.modes(th, [t]).f_hz
        np.testing.assert_array_equal(got, want)
        assert not np.array_equal(got, fw.frequencies(th))     # the term is on: it can fail
    fw_fit = fw.fit(np.zeros(len(bound)))
    ga = EFFECTS["gage_alignment"]
    for pl in ga.placements(fw, fw_fit)[:2]:
        t = Term(ga, pl, pl.probes[0])
        np.testing.assert_array_equal(fw.frequencies(thetas[1], [t]), fw.modes(thetas[1], [t]).f_hz)


def test_a_design_solved_with_its_data_summed_in_is_the_design_solved_after():
    fw = _forward()
    th = np.zeros(len(fw.params))
    ms = fw.modes(th)
    data = fw.x0
    once = fw.block_design(fw.unit_blocks(ms), None, data=data)
    after = fw.block_design(fw.unit_blocks(ms), None)
    c1, p1 = once.solve(data)
    c2, p2 = after.solve(data)
    np.testing.assert_array_equal(c1, c2)
    np.testing.assert_array_equal(p1, p2)
    # another array is solved for itself, not with the first one's right-hand side
    other = 2.0 * data
    c3, _ = once.solve(other)
    np.testing.assert_array_equal(c3, after.solve(other)[0])
    assert not np.array_equal(c3, c1)


def test_the_broyden_update_in_row_blocks_is_the_column_one():
    rng = np.random.default_rng(3)
    n, p = NORMAL_ROWS + 1234, 7      # more rows than one block
    for step in (rng.normal(size=p), np.where(np.arange(p) == 2, 0.0, rng.normal(size=p))):
        J = rng.normal(size=(n, p))
        v = rng.normal(size=n)
        want = J.copy()
        ss = float(step @ step)
        for j in np.flatnonzero(step):
            want[:, j] += v * step[j] / ss
        _broyden(J, v, step)
        np.testing.assert_array_equal(J, want)


def test_a_pulse_response_after_the_contact_is_its_closed_form():
    """After the ram lets go (sample 0 at least the contact time T after it began) every mode
    is J(T) exp(lambda (t - T)) (a filter's own pole exp(lambda t)): the response computed from
    that directly, exp per sample and a complex product, against the segment-grid path (its
    real parts as one real product, exponentials as products of tables): equal within 1e-12
    of the largest sample (a few ulp of each exponential, summed over the modes)."""
    fw = _forward()
    ms = fw.modes(np.zeros(len(fw.params)))
    basis = fw.pulse_basis(ms)
    _, JT = basis
    k = np.arange(fw.td.n_s) / fw.td.fs_hz
    for tau0 in (ms.duration_s, 0.05, 0.5, 3.0):
        u, du = fw.pulse_response(ms, tau0, basis)
        lag = np.where(ms.exp_only, tau0, tau0 - ms.duration_s)
        Z = JT[:, None] * np.exp(ms.lam[:, None] * (lag[:, None] + k[None, :]))
        np.testing.assert_allclose(u, np.real(ms.A @ Z), rtol=0, atol=1e-12 * np.abs(u).max())
        np.testing.assert_allclose(du, np.real(ms.A @ (ms.lam[:, None] * Z)), rtol=0,
                                   atol=1e-12 * np.abs(du).max())


def test_the_decay_spectrum_is_made_once_per_weights():
    fw = _forward()
    first = fw.decay_spectrum()
    assert fw.decay_spectrum() is first
    fw.set_weights(fw.W * 2.0)
    again = fw.decay_spectrum()
    assert again is not first
    np.testing.assert_allclose(again[1], 4.0 * first[1], rtol=1e-12)  # power: twice the weights


def test_a_blows_first_contact_made_once_is_the_one_made_each_time(monkeypatch):
    """One blow fitted with its contact held and a second blow 26 ms later at 15 % (the contact
    test's trial): ``one_blow`` and ``second_blow`` make each first contact and each window's
    pole growth once; with both made afresh at every use (the long way, the contact's length
    handed as the grid's own number each time) they give the very same numbers."""
    from ramdaq.analysis.gap import contact
    from tests.test_contact import FS, _trial

    x, known, sig = _trial(0.026, 0.15)
    short = contact.second_blow(x, FS, 1.0, known, sig), contact.one_blow(x, FS, 1.0, known, sig)
    plain = contact.contact_response
    monkeypatch.setattr(contact, "contact_response",
                        lambda tau, poles, c, growth=None: plain(tau, poles, c))
    monkeypatch.setattr(contact, "_first", lambda made, tau, poles, c, growth: plain(tau, poles, c))
    long = contact.second_blow(x, FS, 1.0, known, sig), contact.one_blow(x, FS, 1.0, known, sig)
    assert short[0] is not None and short[0].rho > 0.05      # a second blow was measured
    assert short[0] == long[0]
    for a, b in zip(vars(short[1]).values(), vars(long[1]).values(), strict=True):
        np.testing.assert_array_equal(a, b)
