"""A gage's sensitivity wrong: it reads ``(1 + e)`` times what it feels, in every mode alike."""

from __future__ import annotations

import numpy as np

from .base import Effect, Placement, Term, placement, whiten_fitted


class GageSensitivity(Effect):
    name = "gage_sensitivity"
    label = "gage sensitivity error"

    def placements(self, fw, fit) -> list[Placement]:
        return [placement({"gage": g}, ("scale_error",), ("1",), 0.0, -0.8, 3.0, [[0.1]],
                          gages=(g,), window="all") for g in fw.td.gage_numbers]

    def templates(self, fw, cal, pl) -> np.ndarray:
        d = np.zeros_like(cal.fit.pred)
        r = fw.td.gage_numbers.index(pl.key["gage"])
        d[:, r] = 0.1 * cal.fit.pred[:, r]
        return whiten_fitted(fw, d)[None, :]

    def modes(self, ms, fw, term: Term):
        ms = ms.copy()
        r = fw.td.gage_numbers.index(term.placement.key["gage"])
        ms.A[r] *= 1 + term.value("scale_error")
        ms.feed[r] *= 1 + term.value("scale_error")
        return ms
