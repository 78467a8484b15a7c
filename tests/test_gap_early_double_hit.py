"""A second blow before the double-hit scan's early window (issue 17: the modal family's double
hit 13.0 ms after the blow at 45 %, modal development seed 57004, was not found: the scan reads
from :data:`~ramdaq.analysis.gap.signal_checks.EARLY_FROM_S`, 16 ms, where a second blow already
rung is the first blow's modes with other amplitudes). Read with the contact held from the onset
(:func:`~ramdaq.analysis.gap.signal_checks.early_double_hits`)."""

from __future__ import annotations

import pytest

from ramdaq.analysis.gap.datamodel import free_modal_model
from ramdaq.analysis.gap.signal_checks import EARLY_FROM_S, RHO_MIN, double_hits
from ramdaq.analysis.gap.verdict import UNEXPLAINED_CLOSURE
from tests.blow_helpers import FS_HZ, ONSETS_S, struck

DELAY_S, RHO = 0.013, 0.45
"""The second blow: 13 ms after the first (inside the scan's 16 ms start) at 45 % of it."""


def test_a_second_blow_before_the_scans_window_is_found():
    assert DELAY_S < EARLY_FROM_S
    x = struck(DELAY_S, RHO)
    fm = free_modal_model(x, FS_HZ, ONSETS_S)
    (dh,) = double_hits(x, FS_HZ, ONSETS_S, (1, 2, 3), fm)
    more = {n: v for n, v, _ in dh.more}
    assert dh.statistic > dh.chance_level
    # the delay to the sample grid (1 ms at 1024 Hz; the trigger's onset, not the contact's
    # start, is the reference: a sample either way), the size to 10 % (noise at 1e-4 moves it
    # far less; the half sine's samples at 1024 Hz are coarse)
    assert more["delay_s"] == pytest.approx(DELAY_S, abs=1.5 / FS_HZ)
    assert dh.size == pytest.approx(RHO, rel=0.1)
    # it repeats: the second blow read on the other blows closes at least half the held-out
    # blows' misfit, as the layers ask before naming it
    assert dh.closed_held >= UNEXPLAINED_CLOSURE


def test_one_blow_and_a_small_rebound_raise_no_double_hit():
    # one half sine per blow: its own shape is no second blow
    x = struck(0.0, 0.0)
    fm = free_modal_model(x, FS_HZ, ONSETS_S)
    assert double_hits(x, FS_HZ, ONSETS_S, (1, 2, 3), fm) == []
    # a rebound under RHO_MIN at the same delay is not named either
    x = struck(DELAY_S, 0.5 * RHO_MIN)
    fm = free_modal_model(x, FS_HZ, ONSETS_S)
    assert double_hits(x, FS_HZ, ONSETS_S, (1, 2, 3), fm) == []
