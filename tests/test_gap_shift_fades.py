"""The early-late frequency shift names an amplitude-dependent stiffness only where it does not
fade as the blow grows (:func:`~ramdaq.analysis.gap.homogeneity.fades_with_blow`): a crack or a
stop acts more the larger the amplitude, Coulomb friction's phase lag less."""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.stats

from ramdaq.analysis.gap.datamodel import P_CHANCE, free_modal_model
from ramdaq.analysis.gap.homogeneity import early_late_shifts, early_shift, fades_with_blow
from tests.blow_helpers import FS_HZ, ONSETS_S, rung_mode, unit_amplitude

F_HZ, ZETA = 60.0, 0.01
"""The struck mode, as tests/test_gap_early_shift.py's."""


def _crack_shift():
    """The early-late shift of a crack opening at half the unit blow and 15 % softer (the modal
    family's size 0.5), six blows of 0.5-2x through the modal family's integrator, three gages,
    white noise at 1e-4 of the largest peak."""
    q = rung_mode(F_HZ, ZETA, {"crack_at": 0.5 * unit_amplitude(F_HZ), "crack_drop": 0.15})
    x = np.outer([1.0, 0.6, -0.4], q)
    x += 1e-4 * np.abs(x).max() * np.random.default_rng(0).standard_normal(x.shape)
    fm = free_modal_model(x, FS_HZ, ONSETS_S)
    (t,) = early_late_shifts(x, fm, [int(np.argmin(abs(fm.f_hz - F_HZ)))], [0, 1])
    return x, fm, t


def test_a_cracks_shift_grows_with_the_blow_and_is_kept():
    x, fm, t = _crack_shift()
    # softer early, more so in the bigger blows: the slope per doubling has the shift's sign,
    # beyond the one-sided 1e-3 normal quantile (3.09)
    assert t.size < 0 and t.slope < 0 and t.slope_z < -scipy.stats.norm.isf(P_CHANCE), t
    assert not fades_with_blow(t)
    f = early_shift(x, fm, (1, 2, 3))
    assert f is not None and f.statistic > f.chance_level


def test_a_shift_that_fades_as_the_blow_grows_is_no_stiffness():
    _, _, t = _crack_shift()
    level = scipy.stats.norm.isf(P_CHANCE)
    # the crack's shift turned round: the same size, its slope against it beyond chance (as
    # friction on an 86 Hz mode read, +1.5 % early, -0.56 % per doubling at z -3.7) -- fades
    fading = dataclasses.replace(t, slope=-t.slope, slope_z=-(level + 0.5) * np.sign(t.slope_z))
    assert fades_with_blow(fading)
    # within chance it does not: a slope the blows' scatter makes is no law
    assert not fades_with_blow(dataclasses.replace(fading, slope_z=0.9 * level * np.sign(fading.slope_z)))
