"""A mode that is really two close ones (asymmetry of the rudder or its bearings): a share of the
mode's response rings at a frequency ``split`` (relative) away, so the envelope beats."""

from __future__ import annotations

import numpy as np

from analysis.gap.effects.base import Effect, Placement, Term, compared_modes, placement

SPLITS = (-0.035, -0.02, -0.01, 0.01, 0.02, 0.035)


class SplitMode(Effect):
    name = "split_mode"
    label = "closely spaced / split modes"

    def placements(self, fw, fit) -> list[Placement]:
        out = []
        for _, f in compared_modes(fw, fit):
            for s in SPLITS:
                lo, hi = (-0.08, -0.002) if s < 0 else (0.002, 0.08)
                out.append(placement({"mode_hz": round(f, 3), "side": "below" if s < 0 else "above"},
                                     ("split", "share"), ("1", "1"), [s, 0.0], [lo, 0.0], [hi, 0.9],
                                     [[s, 0.1]], mode_hz=f, window="late"))
        return out

    def modes(self, ms, fw, term: Term):
        i = int(np.argmin(np.abs(ms.f_hz - term.placement.mode_hz)))
        s, share = term.value("split"), term.value("share")
        out = ms.copy()
        lam2 = ms.lam[i].real + 1j * ms.lam[i].imag * (1 + s)
        out.lam = np.append(ms.lam, lam2)
        out.A = np.hstack([ms.A, share * ms.A[:, i:i + 1]])
        out.A[:, i] *= 1 - share
        out.dof = np.hstack([ms.dof, share * ms.dof[:, i:i + 1]])
        out.dof[:, i] *= 1 - share
        out.exp_only = np.append(ms.exp_only, False)
        return out
