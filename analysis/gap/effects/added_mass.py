"""Added mass distributed otherwise than Eq 19-21 say: the rotational added inertias
(``(I_z)_vir``, ``(I_x)_vir``) off by a factor while the translational added mass is right
(the calibration's single added-mass factor scales all three together). Water only."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .base import Effect, Placement, Term, placement


class AddedMass(Effect):
    name = "added_mass"
    label = "added-mass distribution error"

    def placements(self, fw, fit) -> list[Placement]:
        if fw.td.rig.medium != "water":
            return []
        return [placement({}, ("log_rot_factor",), ("ln x",), 0.0, -1.5, 1.5, [[0.1]], window="all")]

    def model(self, model, term: Term):
        k = math.exp(term.value("log_rot_factor")) - 1.0
        M = model.M.copy()
        M[1, 1] += k * model.added["Iz_vir"]
        M[2, 2] += k * model.added["Ix_vir"]
        return replace(model, M=M)


_ = np
