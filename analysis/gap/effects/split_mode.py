"""A mode that is really two close ones (a tuned absorber, asymmetry of the rudder or its
bearings): the mode's response rings at two frequencies ``split`` (relative) apart, ``share`` of
it in the upper one, so the envelope beats. ``centre`` says where the calibrated mode sits
between them: the halves ring at ``f (1 - split centre)`` and ``f (1 + split (1 - centre))``.
``centre = share`` keeps their amplitude-weighted mean frequency where the data's single peak put
it (a narrow split, which the calibration reads as one mode); ``centre`` 0 or 1 keeps the lower
or the upper half at the calibrated frequency (a wide split, where the calibration locks on one
of the two peaks and reads the other as a faster decay). ``share = 0`` with ``centre = 0`` is
the effect off."""

from __future__ import annotations

import numpy as np

from .base import Effect, Placement, Term, compared_modes, placement

MAX_SPLIT = 0.1
"""The widest split fitted, relative: beyond it the two are modes of their own (an extra mode)."""
SPLITS = (0.004, 0.007, 0.012, 0.02, 0.03, 0.045, 0.065)
"""Separations the refit starts from with the halves about the calibrated mode: a beat's period
is 1 / (f split), and a time-domain fit finds it only from within about half a beat over the
decay."""
WIDE_SPLITS = (0.03, 0.045, 0.06, 0.075, 0.09)
"""Separations the refit starts from with one half at the calibrated mode, the other above or
below it."""
PROBES = ((0.02, 0.3, 0.3), (0.007, 0.3, 0.3), (0.045, 0.3, 0.3),
          (0.06, 0.5, 0.0), (0.06, 0.5, 1.0))
"""(split, share, centre) of the signature's probes: narrow splits about the mode, and a wide
one above and below it."""


class SplitMode(Effect):
    name = "split_mode"
    label = "closely spaced / split modes"

    @classmethod
    def retunes(cls) -> bool:
        # the halves keep the calibrated mode's weighted mean frequency, or one of them keeps
        # it: re-tuning the constants to the spectrum with the term on would pull them off the
        # calibration that was right
        return False

    def placements(self, fw, fit) -> list[Placement]:
        lam = fit.modes.lam
        starts = [[s, 0.5, 0.5] for s in SPLITS] + [[s, 0.5, c] for s in WIDE_SPLITS for c in (0.0, 1.0)]
        # x0 is the effect off: no share above, the mode itself where the calibration put it
        # (centre 0). Two modes are told apart only when further apart than the half-power
        # bandwidth 2 zeta: a mode damped beyond what the widest split resolves is no place
        # for one
        return [placement({"mode_hz": round(f, 3)}, ("split", "share", "centre"), ("1", "1", "1"),
                          [0.02, 0.0, 0.0], [0.002, 0.0, 0.0], [MAX_SPLIT, 0.9, 1.0], PROBES,
                          mode_hz=f, window="late", starts=starts)
                for i, f in compared_modes(fw, fit) if 2 * -lam[i].real / abs(lam[i]) < MAX_SPLIT]

    def modes(self, ms, fw, term: Term):
        i = int(np.argmin(np.abs(ms.f_hz - term.placement.mode_hz)))
        s, share, c = term.value("split"), term.value("share"), term.value("centre")
        out = ms.copy()
        lam = ms.lam[i]
        out.lam = ms.lam.copy()
        out.lam[i] = lam.real + 1j * lam.imag * (1 - s * c)
        out.lam = np.append(out.lam, lam.real + 1j * lam.imag * (1 + s * (1 - c)))
        out.A = np.hstack([ms.A, share * ms.A[:, i:i + 1]])
        out.A[:, i] *= 1 - share
        out.dof = np.hstack([ms.dof, share * ms.dof[:, i:i + 1]])
        out.dof[:, i] *= 1 - share
        out.exp_only = np.append(ms.exp_only, False)
        return out
