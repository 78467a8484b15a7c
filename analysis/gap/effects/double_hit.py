"""The ram bounced: a second contact ``delay`` after the first with ``ratio`` of its peak force.
Seen mostly in the early decay (and as mode amplitudes that no single blow at the ram's point
explains)."""

from __future__ import annotations

import numpy as np

from analysis.gap.effects.base import Effect, Placement, Term, placement

DELAYS_S = (0.006, 0.012, 0.018, 0.024, 0.032, 0.040, 0.050)


class DoubleHit(Effect):
    name = "double_hit"
    label = "double hit (ram bounce)"

    def placements(self, fw, fit) -> list[Placement]:
        out = []
        for d in DELAYS_S:
            out.append(placement({"delay_s": d}, ("ratio", "delay_s"), ("1", "s"), [0.0, d], [0.0, d - 0.004],
                                 [1.5, d + 0.004], [[0.1, d]], window="early"))
        return out

    def pulses(self, term: Term) -> list[tuple[float, float]]:
        return [(term.value("delay_s"), term.value("ratio"))]


_ = np
