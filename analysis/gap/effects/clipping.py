"""A converter at its rail: the first cycles after a blow are cut flat. Read straight off the
full-rate samples (counts at the known rails, or runs of equal extreme values when the rails
are unknown, as in an imported file); the term takes the clipped stretches out of the
comparison instead of pretending to predict them."""

from __future__ import annotations

import math

import numpy as np

from .base import Effect, Placement, Term, placement


class Clipping(Effect):
    name = "clipping"
    label = "clipping (converter at its rail)"

    def _clipped(self, fw) -> dict[int, float]:
        td = fw.td
        hits = np.where(td.clip.sum(axis=0) > 0, td.clip.sum(axis=0), 0)
        flat = td.flat.copy()
        runs = (flat >= 2).sum(axis=0)                       # segments with two or more flat runs
        out = {}
        for r, g in enumerate(td.gage_numbers):
            segs = (td.clip[:, r] > 0) | (flat[:, r] >= 2)
            if hits[r] > 0 or runs[r] >= 2:
                out[g] = float(np.median(td.peak_full[segs, r]))
        return out

    def direct_score(self, fw, cal):
        found = self._clipped(fw)
        if not found:
            return -math.inf, None
        td = fw.td
        rows = [td.gage_numbers.index(g) for g in found]
        n = int(td.clip[:, rows].sum() + td.flat[:, rows].sum())
        pl = placement({"gages": sorted(found), "level_m_s2": [round(v, 4) for v in found.values()]},
                       (), (), [], [], [], np.zeros((1, 0)), gages=tuple(sorted(found)), window="early")
        return 8.0 + math.log(max(n, 1)), pl

    def placements(self, fw, fit) -> list[Placement]:
        return []

    def output(self, pred, fw, term: Term):
        td = fw.td
        keep = np.ones(pred.shape, bool)
        reach = int(math.ceil(8.0 / td.lowpass_hz * td.fs_hz)) + 1
        for g, level in zip(term.placement.key["gages"], term.placement.key["level_m_s2"], strict=True):
            r = td.gage_numbers.index(g)
            over = np.abs(pred[:, r]) > 0.9 * level
            c = np.cumsum(np.pad(over, ((0, 0), (reach + 1, reach))), axis=1)
            keep[:, r] = (c[:, 2 * reach + 1:] - c[:, : -2 * reach - 1]) == 0
        return pred, keep
