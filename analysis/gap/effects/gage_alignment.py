"""A rudder gage that reads another point or direction than the rig says: an effective offset
``(dx, dz)`` of its position changes how much of the rudder's rotations it sees
(``a_y = v'' + x gamma'' - z alpha''``), differently in every mode -- unlike a sensitivity error."""

from __future__ import annotations

from .base import Effect, Placement, Term, placement


class GageAlignment(Effect):
    name = "gage_alignment"
    label = "gage misaligned / mislocated (cross-axis)"

    def placements(self, fw, fit) -> list[Placement]:
        rig = fw.td.rig
        out = []
        for g in rig.gages_by_channel():
            if g.body != "rudder" or g.axis.lstrip("+-") != "y":
                continue
            out.append(placement({"gage": g.number}, ("dx_m", "dz_m"), ("m", "m"), [0, 0], [-0.6, -0.6],
                                 [0.6, 0.6], [[0.05, 0.0], [0.0, 0.05]], gages=(g.number,), window="all"))
        return out

    def modes(self, ms, fw, term: Term):
        ms = ms.copy()
        g = fw.td.rig.gage(term.placement.key["gage"])
        r = fw.td.gage_numbers.index(g.number)
        sign = -1.0 if g.axis.startswith("-") else 1.0
        dx, dz = term.value("dx_m"), term.value("dz_m")
        # dof rows 1 (gamma) and 2 (alpha): acceleration per newton, conjugate weight included
        ms.A[r] = ms.A[r] + sign * (dx * ms.dof[1] - dz * ms.dof[2])
        return ms

