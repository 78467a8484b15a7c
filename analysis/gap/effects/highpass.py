"""AC coupling: every channel high-passed (first order, corner ``f_c``) before the converter,
as IEPE conditioners do. Each mode's amplitude and phase change by ``H(lambda) = lambda /
(lambda + w_c)`` and the filter's own pole adds a slow exponential after every blow (the
baseline undershoot)."""

from __future__ import annotations

import math

import numpy as np

from ...model.response import half_sine_response
from .base import Effect, Placement, Term, compared_modes, placement


class HighPass(Effect):
    name = "highpass"
    label = "sensor high-pass / drift"

    def placements(self, fw, fit) -> list[Placement]:
        modes = compared_modes(fw, fit)
        f1 = min(f for _, f in modes) if modes else 1.0
        return [placement({}, ("corner_hz",), ("Hz",), 0.0, 0.0, 2.0 * f1, [[0.05 * f1]],
                          gages=(), mode_hz=f1, window="all")]

    def modes(self, ms, fw, term: Term):
        fc = term.value("corner_hz")
        if fc <= 0:
            return ms
        wc = 2 * math.pi * fc
        p = -wc
        lam = ms.lam
        JT = half_sine_response(lam, ms.duration_s, np.array([ms.duration_s]))[:, 0]
        c = ms.A * (JT * np.exp(-lam * ms.duration_s))[None, :]
        c = np.where(ms.exp_only[None, :], ms.A, c)
        pole = np.real(c * (p / (p - lam))[None, :]).sum(axis=1)
        out = ms.copy()
        out.A = ms.A * (lam / (lam + wc))[None, :]
        out.lam = np.append(lam, p + 0j)
        out.A = np.hstack([out.A, pole[:, None].astype(complex)])
        out.dof = np.hstack([ms.dof, np.zeros((ms.dof.shape[0], 1), complex)])
        out.exp_only = np.append(ms.exp_only, True)
        return out
