"""The data's band: where a trial rings clearly above the rig's band on several gages, the band
can be widened to take the line in (``prepare(..., data_band=True)``), and the modes there are
read for a structural effect the rig's band would leave out (``modal_level.structure_above``):
a mode split in two is found; the rig's own mode ringing there is not a finding."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ramdaq.analysis.gap.diagnose import _trial_notes
from ramdaq.analysis.gap.modal_level import Split, model_modes_at_gages, structure_above
from ramdaq.analysis.gap.ringing import RESOLUTION_HZ
from ramdaq.analysis.gap.trialdata import CORNER_OVER_LINE, prepare
from ramdaq.analysis.model.rig import load_rig

FS = 2048.0


def _rig():
    return load_rig("albacore").with_medium("water")


def _trial(rig, seed, high=(), rows=None):
    """Six blows 5 s apart: every gage rings a 13 Hz mode at 50x the rig's noise floor, and each
    ``(f_hz, zeta, amp)`` of ``high`` rings with the rig model's highest mode's gage shape (its
    largest entry ``amp`` times the noise), on ``rows`` only if given; white noise of the floor.
    (n_gages, n) m/s^2 and the onsets, s."""
    rng = np.random.default_rng(seed)
    n_g = len(rig.gages_by_channel())
    mm = model_modes_at_gages(rig)
    k = int(np.argmax(mm.f_hz))
    shape = mm.shapes[:, k] / np.abs(mm.shapes[:, k]).max()
    if rows is not None:
        shape = np.where(np.isin(np.arange(n_g), rows), 1.0, 0.0)
    onsets = 1.5 + 5.0 * np.arange(6)
    t = np.arange(int(FS * 31.5)) / FS
    sd = rig.daq.noise_m_s2_rms
    x = sd * rng.standard_normal((n_g, len(t)))
    for t0 in onsets:
        on = t >= t0
        tau = np.where(on, t - t0, 0.0)
        x += on * 50 * sd * np.exp(-2 * math.pi * 13 * 0.02 * tau) * np.sin(2 * math.pi * 13 * tau)
        for f, zeta, amp in high:
            w = 2 * math.pi * f
            x += on * amp * sd * np.real(shape[:, None] * np.exp((-zeta * w + 1j * w) * tau)[None, :])
    return x, onsets, float(mm.f_hz[k])


def test_the_band_widens_to_a_line_ringing_on_several_gages_only_when_asked():
    """The rig's 215 Hz mode ringing at 30x the noise (above the rig's 113.6 Hz corner): with
    ``data_band`` the corner moves to CORNER_OVER_LINE times the line's bin's upper edge and the
    line is compared, no longer listed; without it the corner is the rig's and the line is listed."""
    rig = _rig()
    x, onsets, f_top = _trial(rig, 1, high=[(215.5, 0.003, 30.0)])
    plain = prepare(x, FS, onsets, rig)
    wide = prepare(x, FS, onsets, rig, data_band=True)
    assert plain.lowpass_hz == pytest.approx(113.6, abs=0.05)
    assert plain.ringing_above and abs(plain.ringing_above[0].frequency_hz - 215.5) <= RESOLUTION_HZ / 2
    line = plain.ringing_above[0].frequency_hz
    # printed between the bins (the new user read "208 Hz" for this 215.5 Hz mode): a damped line
    # at 30x the noise comes within a tenth of an 8 Hz bin by the Gaussian interpolation
    assert abs(plain.ringing_above[0].peak_hz - 215.5) <= 0.1 * RESOLUTION_HZ
    assert plain.ringing_above[0].text().startswith(f"{plain.ringing_above[0].peak_hz:.0f} Hz")
    assert wide.lowpass_hz == pytest.approx(CORNER_OVER_LINE * (line + RESOLUTION_HZ / 2))
    assert wide.rig_lowpass_hz == pytest.approx(plain.lowpass_hz)
    assert wide.ringing_above == []
    assert wide.fs_hz == FS / max(1, int(FS // (2.5 * wide.lowpass_hz)))   # the band's own decimation


def test_a_line_on_one_gage_or_noise_alone_leaves_the_rigs_band():
    """A line on one gage only (a channel's own: a mount's resonance) is listed, not compared; with
    noise and the in-band mode only, nothing rings above and the band is the rig's."""
    rig = _rig()
    x, onsets, _ = _trial(rig, 2, high=[(215.0, 0.01, 30.0)], rows=[4])
    td = prepare(x, FS, onsets, rig, data_band=True)
    assert td.lowpass_hz == pytest.approx(113.6, abs=0.05)
    assert [r.gages for r in td.ringing_above] == [(rig.gages_by_channel()[4].number,)]
    x, onsets, _ = _trial(rig, 3)
    assert prepare(x, FS, onsets, rig, data_band=True).lowpass_hz == pytest.approx(113.6, abs=0.05)


def test_a_split_of_the_mode_above_the_band_is_found_and_the_rigs_own_mode_is_not():
    """The rig's 215.5 Hz mode split into two halves 6 % apart with its shape and one damping
    (0.3 %, what the modal family gives its high modes): found as a Split about 215 Hz; the mode
    whole, as the rig has it, gives no finding (no split, no coupled hull mode)."""
    rig = _rig()
    x, onsets, f_top = _trial(rig, 4, high=[(0.97 * 215.5, 0.003, 30.0), (1.03 * 215.5, 0.003, 30.0)])
    td = prepare(x, FS, onsets, rig, data_band=True)
    found = structure_above(td, 0.9 * td.rig_lowpass_hz)
    assert len(found) == 1 and isinstance(found[0], Split), found
    s = found[0]
    assert s.f_lo_hz == pytest.approx(0.97 * 215.5, rel=0.005)     # identified to 0.5 % (a 1 s decay)
    assert s.f_hi_hz == pytest.approx(1.03 * 215.5, rel=0.005)
    x, onsets, _ = _trial(rig, 5, high=[(215.5, 0.003, 30.0)])
    td = prepare(x, FS, onsets, rig, data_band=True)
    assert td.lowpass_hz > 215.5
    assert structure_above(td, 0.9 * td.rig_lowpass_hz) == []


def test_a_rig_band_with_nothing_to_decimate_is_not_said_widened():
    """A rig whose band reaches past 0.4x the rate (here its modes compared up to 900 Hz at
    2048 Hz) is compared at the full rate, up to half of it: that is still the rig's band, and
    the report must not say the data widened it."""
    rig = _rig()
    x, onsets, _ = _trial(rig, 3)
    td = prepare(x, FS, onsets, rig, max_hz=900.0)
    assert td.fs_hz == FS and td.lowpass_hz == FS / 2
    assert td.rig_lowpass_hz == td.lowpass_hz
    assert not [n for n in _trial_notes(td) if n.startswith("compared up to")]
