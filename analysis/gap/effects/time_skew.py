"""One channel sampled late (or early) against the others: a multiplexed converter, a
different filter. Every mode's phase at that gage lags by ``omega * tau``."""

from __future__ import annotations

import numpy as np

from .base import Effect, Placement, Term, placement, whiten_fitted


class TimeSkew(Effect):
    name = "time_skew"
    label = "channel time skew"

    def placements(self, fw, fit) -> list[Placement]:
        return [placement({"gage": g}, ("delay_s",), ("s",), 0.0, -0.02, 0.02, [[1e-4]],
                          gages=(g,), window="all") for g in fw.td.gage_numbers]

    def templates(self, fw, cal, pl) -> np.ndarray:
        d = np.zeros_like(cal.fit.pred)
        r = fw.td.gage_numbers.index(pl.key["gage"])
        d[:, r] = -1e-4 * cal.pred_rate(fw)[:, r]
        return whiten_fitted(fw, d)[None, :]

    def modes(self, ms, fw, term: Term):
        ms = ms.copy()
        r = fw.td.gage_numbers.index(term.placement.key["gage"])
        ms.A[r] *= np.exp(-ms.lam * term.value("delay_s"))
        return ms
