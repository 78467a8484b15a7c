"""The modal generator family (issue 17): it shares nothing with the diagnosis's model, its
trials are seeded and physical, its effects act where they say; the homogeneity check across
blows of different force; the "unexplained" verdict for a gap no library effect closes."""

from __future__ import annotations

import ast
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ramdaq.analysis.truth import modal_family as mf
from tests.blow_helpers import FS_HZ, ONSETS_S, rung_mode, unit_amplitude

ROOT = Path(__file__).resolve().parents[1]
RIG = (ROOT / "recordings" / "rigs" / "albacore.toml").read_text()
HZ = [13.0, 45.0, 80.0]   # ALBACORE-like in water, as plain numbers


def test_the_generator_imports_nothing_of_the_diagnosis_or_its_model():
    """Its own imports are the standard library, numpy and scipy; importing it loads no module
    of ramdaq's model, gap diagnosis or truth simulator."""
    tree = ast.parse((ROOT / "analysis" / "truth" / "modal_family.py").read_text())
    mods = {n.module.split(".")[0] if n.level == 0 else "." for n in ast.walk(tree)
            if isinstance(n, ast.ImportFrom)}
    mods |= {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert mods <= {"__future__", "math", "tomllib", "collections", "dataclasses", "numpy", "scipy"}, mods
    banned = ("ramdaq.analysis.model", "ramdaq.analysis.gap", "ramdaq.analysis.truth.trial",
              "ramdaq.analysis.truth.structure", "ramdaq.analysis.truth.effects",
              "ramdaq.analysis.truth.integrate")
    code = ("import sys, ramdaq.analysis.truth.modal_family\n"
            f"bad = [m for m in sys.modules if m.startswith({banned!r})]\n"
            "assert not bad, bad\n")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


@pytest.fixture(scope="module")
def clean():
    return mf.generate(RIG, HZ, "none", 0.0, seed=3)


def test_trial_is_seeded_quantised_and_physical(clean):
    again = mf.generate(RIG, HZ, "none", 0.0, seed=3)
    assert np.array_equal(clean.counts, again.counts)
    assert not np.array_equal(clean.counts, mf.generate(RIG, HZ, "none", 0.0, seed=4).counts)
    # 16-bit converter, the largest blow near HEADROOM of the range on every channel
    assert clean.adc_bits == 16 and np.abs(clean.counts).max() <= 2**15
    peak = np.abs(clean.counts).max(axis=1) / 2**15
    assert np.all((peak > 0.3) & (peak < 0.5)), peak
    # blows of different force: 0.5x to 2x the rig's nominal 20 kN, each +-3 %
    assert clean.peaks_N.min() < 0.55 * 2e4 and clean.peaks_N.max() > 1.9 * 2e4
    f, z = np.array(clean.modes).T
    assert np.all((z >= 0.005) & (z <= 0.05))
    # the rudder's modes within 7 % of the numbers handed in, two or three hull modes 4-15 Hz
    assert np.all(np.abs(f[:3] / HZ - 1) <= 0.07) and 2 <= f[3:].size <= 3
    assert np.all((f[3:] >= 4) & (f[3:] <= 15))


@pytest.mark.parametrize("effect", ["gage_sensitivity", "time_skew", "sensor_resonance", "gain_drift",
                                    "mains_pickup"])
def test_a_channel_effect_acts_on_its_gages_only(clean, effect):
    """Streams are split by purpose: with a channel's effect the other channels' counts are
    the clean trial's, bit for bit (their full scale is set by their own peaks)."""
    tr = mf.generate(RIG, HZ, effect, 1.0, seed=3)
    rows = [i for i, g in enumerate(tr.gage_numbers) if g in tr.effect.gages]
    other = [i for i in range(len(tr.gage_numbers)) if i not in rows]
    assert rows and np.array_equal(tr.counts[other], clean.counts[other])
    assert not np.allclose(tr.acc[rows], clean.acc[rows], atol=0.01)
    assert tr.effect.expect == ("unexplained" if effect in mf.OUTSIDE else effect)


def test_structural_and_nonlinear_effects_act_through_the_modes(clean):
    for effect in ("crack", "rattle", "friction", "hull_coupling"):
        tr = mf.generate(RIG, HZ, effect, 1.0, seed=3)
        d = np.sqrt(np.mean((tr.acc - clean.acc) ** 2, axis=1) / np.mean(clean.acc**2, axis=1))
        rows = [i for i, g in enumerate(tr.gage_numbers) if g in tr.effect.gages]
        # at least 5 % of the clean ringing's rms on the gages it names (size 1 is plain)
        assert rows and d[rows].max() > 0.05, (effect, d.round(3))


def _departure(tr, clean) -> np.ndarray:
    """Per gage: the rms of the trial less its clean twin (same seed: the same structure, blows
    and noise), as a fraction of the clean trial's rms, (n_gages,)."""
    return np.sqrt(np.mean((tr.acc - clean.acc) ** 2, axis=1) / np.mean(clean.acc**2, axis=1))


@pytest.fixture(scope="module")
def water_hz():
    """ALBACORE's rudder modes in water as ``ramdaq gap benchmark`` hands them to the family
    (about 13, 60 and 216 Hz: the third rung little by a 3-8 ms blow)."""
    from ramdaq.analysis.model.rig import load_rig
    from ramdaq.daq.commands.gap_bench import rudder_modes_hz

    return rudder_modes_hz(load_rig(ROOT / "recordings" / "rigs" / "albacore.toml").with_medium("water"))


AMPLITUDE_LAWS = ("crack", "rattle", "friction")
"""Effects that act in the predominant mode's own equation, at amplitudes set from its blow."""


def test_an_amplitude_law_acts_in_every_trial_where_it_says(water_hz):
    """Twenty seeds of the rig in water at the smallest benchmark size (0.5): the crack opens and
    the stop is struck in every trial -- the trial departs from its clean twin by 5 % or more of
    its ringing, an effect "plain on an oscillogram" (where the crack sat on a 204-227 Hz mode
    the blow barely rings, seeds 27 and 37 departed by 3.8-4.8 %, and benchmark seeds by 0-3 %:
    no effect in the data, scored as a missed one) -- and
    the gage where the departure is largest is among the gages the truth names (where the data
    show it, whatever part of the structure the law stands for). About 20 s."""
    for seed in range(20, 40):
        clean = mf.generate(RIG, water_hz, "none", 0.0, seed=seed)
        for effect in AMPLITUDE_LAWS:
            tr = mf.generate(RIG, water_hz, effect, 0.5, seed=seed)
            d = _departure(tr, clean)
            # Coulomb friction acts at every amplitude; a crack or a stop only beyond its own
            assert effect == "friction" or d.max() > 0.05, (effect, seed, d.round(3))
            # where: the departure itself (m/s^2; every gage has the same noise floor, so also
            # in noise units), largest on a named gage
            rms = np.sqrt(np.mean((tr.acc - clean.acc) ** 2, axis=1))
            assert tr.gage_numbers[int(np.argmax(rms))] in tr.effect.gages, (
                effect, seed, tr.effect.gages, (rms / rms.max()).round(2))


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="unknown effect 'tiller'"):
        mf.generate(RIG, HZ, "tiller")
    with pytest.raises(ValueError, match="size must be finite"):
        mf.generate(RIG, HZ, "crack", -1.0)
    with pytest.raises(ValueError, match="needs key"):
        mf.gages_from_toml("name = 'x'\n")


Q0 = unit_amplitude(20.0)
"""The unit blow's displacement amplitude of :func:`_blows`' mode: impulse / w."""


def _blows(law: dict, seed: int = 0):
    """Three gages of one 20 Hz mode (zeta 1 %) rung by six blows of 0.5-2x, through the modal
    family's own integrator with ``law`` (:func:`~ramdaq.analysis.truth.modal_family.nonlinear_mode`'s
    keywords; linear when empty); white noise at 1e-4 of the largest peak."""
    q = rung_mode(20.0, 0.01, law)
    x = np.outer([1.0, 0.6, -0.4], q)
    x += 1e-4 * np.abs(x).max() * np.random.default_rng(seed).standard_normal(x.shape)
    return x, FS_HZ, ONSETS_S


LAWS = {"linear": {}, "friction": {"coulomb": 2e-4},
        "crack": {"crack_at": 0.5 * Q0, "crack_drop": 0.15},
        "rattle": {"stop_at": 0.5 * Q0, "stop_k": 1.0}}
"""The modal family's nonlinear laws at about its size 0.5: Coulomb friction stopping the median
blow's ringing in about 1.5 s, a crack opening at half the unit blow's amplitude with a 15 %
stiffness drop, a stop at half that amplitude as stiff as the mode."""


@pytest.mark.parametrize("law", list(LAWS))
def test_homogeneity_tells_friction_from_a_crack_or_rattle(law):
    """The same mode rung by blows of 0.5-2x. Linear: its decrement and frequency do not move
    with the amplitude (no finding, at P_CHANCE = 1e-3 after Bonferroni over the slopes). With
    Coulomb friction the decrement per cycle grows as 1/amplitude within the decays and the
    frequency stays (Coulomb's law, the library's friction); a crack (softening) or a stop
    (stiffening) moves the frequency with the amplitude by some per cent instead (no library
    effect). Each beyond its chance level; about 1 s each."""
    from ramdaq.analysis.gap.datamodel import free_modal_model
    from ramdaq.analysis.gap.homogeneity import STIFF_MIN, homogeneity
    from ramdaq.analysis.gap.layers import data_effect

    x, fs, onsets = _blows(LAWS[law])
    fm = free_modal_model(x, fs, onsets)
    found = homogeneity(x, fm, (1, 2, 3))
    if law == "linear":
        assert found == [], [f.text for f in found]
        return
    (f,) = found
    assert f.check == "homogeneity" and f.layer == "nonlinearity" and f.statistic > f.chance_level
    more = {m[0]: m[1] for m in f.more}
    # the law's mode is the 20 Hz one, within the crack's or the stop's shift of it
    assert abs(f.mode_hz[0] - 20.0) < 1.0 and 1 in f.gages
    if law == "friction":
        assert "coulomb_law_z" in more and abs(more["frequency_change"]) < STIFF_MIN, f.text
        assert data_effect(f.to_json()) == "friction"
    else:
        # softening for the crack, stiffening for the stop
        assert "stiffness_law_z" in more and (more["frequency_change"] < 0) == (law == "crack"), f.text
        assert abs(more["frequency_change"]) >= STIFF_MIN
        assert data_effect(f.to_json()) == "unexplained"


def test_coulombs_law_false_alarm_rate_on_clean_decays_is_at_most_nominal():
    """Issue 17: the per-cycle regression's Coulomb z was optimistic (the cycles' envelopes share
    their noise through the band filter and the analytic signal). With the error allowing for
    the correlated cycles, linear decays (one 20 Hz mode, six blows of 0.5-2x) under white
    noise at 0.3 % and 1 % of the largest peak (about 100 and 12 cycles read), 150 seeds each,
    pass z = 1.645 (one-sided 5 %) no more often than 5 %: the rate's two-sided 95 %
    Clopper-Pearson interval must reach down to 5 % (measured 2 of 300, 0.08-2.4 %: the z is
    conservative, its standard deviation 0.5-0.8). The pooled per-cycle z fails the same test
    (measured 28 of 300, 6.3-13.1 %; standard deviation 1.3-1.9). And with no noise to speak of
    (1e-4) the reading's own bias is well below the size floor COULOMB_MIN. About 4 s."""
    import dataclasses

    import scipy.signal
    import scipy.stats

    from ramdaq.analysis.gap.datamodel import free_modal_model
    from ramdaq.analysis.gap.homogeneity import COULOMB_MIN, correlated_cycles, decay_laws

    x0, fs, onsets = _blows(LAWS["linear"])
    fm0 = free_modal_model(x0, fs, onsets)
    dt = 1 / fs
    t = np.arange(x0.shape[1]) * dt
    force = mf.half_sine(onsets, np.array([1.0, 0.5, 2.0, 0.7, 1.4, 1.0]), 0.004, t)
    clean = np.outer([1.0, 0.6, -0.4], scipy.signal.lfilter(*mf.mode_filter(20.0, 0.01, dt), force))
    peak = np.abs(clean).max()
    z, alpha = [], 0.05
    for level in (3e-3, 1e-2):
        # the noise floor the cycles are read down to follows the noise (the free model's residual)
        fm = dataclasses.replace(fm0, noise=fm0.noise * level / 1e-4)
        for seed in range(150):
            x = clean + level * peak * np.random.default_rng(1000 + seed).standard_normal(clean.shape)
            (w,) = decay_laws(x, fm, [0], [0], (1, 2, 3))
            z.append(w.z_coulomb)

    def lower(z: np.ndarray) -> tuple[int, float]:
        """Alarms at ``alpha`` and the rate's Clopper-Pearson lower 2.5 % bound."""
        k = int(np.sum(z > scipy.stats.norm.isf(alpha)))
        return k, float(scipy.stats.beta.ppf(0.025, k, z.size - k + 1)) if k else 0.0

    k, lo = lower(np.array(z))
    assert lo <= alpha, (k, len(z), lo)
    # the pooled per-cycle z (without the correlated cycles) is above nominal
    k_pooled, lo_pooled = lower(np.array(z) * math.sqrt(correlated_cycles(20.0)))
    assert lo_pooled > alpha, (k_pooled, lo_pooled)
    # no noise to speak of: what remains is the reading's own bias, well below the floor
    (w,) = decay_laws(clean + 1e-4 * peak * np.random.default_rng(0).standard_normal(clean.shape),
                      fm0, [0], [0], (1, 2, 3))
    assert abs(w.coulomb_size) < 0.5 * COULOMB_MIN, w


@pytest.mark.parametrize(("coulomb", "named"), [(2e-5, False), (6e-5, True)])
def test_coulombs_law_below_its_size_floor_is_not_named_friction(coulomb, named):
    """Issue 17: the Coulomb law had no size floor (the stiffness law has STIFF_MIN). On the
    low-noise decays of :func:`_blows` a weak friction reads beyond chance either way (z about
    6 and 27 against 3.8); at 2e-5 it adds 8 % to the decrement at the smallest amplitude read,
    under COULOMB_MIN (10 %, twice the reading's own bias on clean decays), and is not named
    friction (the trial's other slopes still find it not homogeneous: "unexplained"); at 6e-5 it
    adds 34 % and is. Under 1 s each."""
    from ramdaq.analysis.gap.datamodel import free_modal_model
    from ramdaq.analysis.gap.homogeneity import COULOMB_MIN, decay_laws, homogeneity
    from ramdaq.analysis.gap.layers import data_effect

    x, fs, onsets = _blows({"coulomb": coulomb})
    fm = free_modal_model(x, fs, onsets)
    (w,) = decay_laws(x, fm, [0], [0], (1, 2, 3))
    assert w.z_coulomb > 5 and (w.coulomb_size >= COULOMB_MIN) == named, w
    effects = [data_effect(f.to_json()) for f in homogeneity(x, fm, (1, 2, 3))]
    assert ("friction" in effects) == named, effects


def test_an_ambient_tone_on_a_record_of_any_length():
    """The tone's slow wander steps every 64 oversampled samples: a record whose length is no
    multiple of 64 (the check seeds' four-blow SAMPSON trial, 155000, stopped the benchmark with
    shapes (167780,) against (167744,)) gets its last step whole, and its tone stays on the hull
    gages before the first blow."""
    from ramdaq.daq.commands.gap_bench import _generate_modal, scenarios

    (sc,) = [s for s in scenarios(1, "check", ("ambient_tone",), 0.25, "modal", blows=4)]
    assert sc["seed"] == 155000 and sc["rig"] == "sampson"
    gen = _generate_modal(sc)
    n_o = gen["counts"].shape[1] * mf.OVERSAMPLE
    assert n_o % 64 != 0
    pre = gen["counts"][:, : int(2.5 * gen["fs_hz"])] * gen["scale"][:, None]
    rows = [i for i, g in enumerate(gen["gages"]) if g in gen["truth"]["gages"]]
    others = [i for i in range(len(gen["gages"])) if i not in rows]
    # the tone (20 x noise rms x size 0.5 = 10 x) stands well above the noise floor on its gages
    assert np.median(pre[rows].std(axis=1)) > 3 * np.median(pre[others].std(axis=1))
