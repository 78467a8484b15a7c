"""Effects that add a degree of freedom at the stock's top: the stock's end is held by a spring
``k`` to the hull through a mass ``m = k / (2 pi f)^2`` instead of rigidly -- a steering gear /
tiller that twists (``gamma_b``), or a local hull structure that sways (``v_b``). Each adds a
mode the nominal model lacks and pulls the rudder's own modes; which DOF it moves tells them
apart. ``log10_k_ratio`` is ``k`` against the stock's own stiffness in that direction (torsion
``G J / l_T``, bending ``12 k_s``): +6 is as good as rigid (the effect off: at a ram blow's
signal-to-noise of 10^5 a gear 1000x stiffer than the stock still shows), 0 as soft as the stock."""

from __future__ import annotations

import math
from dataclasses import replace

from analysis.gap.effects.base import Effect, Placement, Term, compared_modes, placement, residual_peaks
from analysis.rig import HullMode


class _ExtraMode(Effect):
    shape: tuple[float, float, float] = (0.0, 0.0, 0.0)
    where: str = "all"

    def _k_ref(self, rig) -> float:
        raise NotImplementedError

    def placements(self, fw, fit) -> list[Placement]:
        avoid = [f for _, f in compared_modes(fw, fit)]
        gages = tuple(g.number for g in fw.td.rig.gages_by_channel() if g.body in self.bodies)
        out = []
        for f in residual_peaks(fw, fit, ("early", "late"), 3, avoid_hz=avoid):
            out.append(placement({"f_hz": round(f, 3)}, ("f_hz", "log10_k_ratio"), ("Hz", "log10 x stock"),
                                 [f, 6.0], [0.75 * f, -1.0], [1.25 * f, 6.0], [[f, 2.0]],
                                 gages=gages, mode_hz=f, window=self.where))
        return out

    def rig(self, rig, term: Term):
        v, g, a = self.shape
        k = self._k_ref(rig) * 10 ** term.value("log10_k_ratio")
        f = term.value("f_hz")
        extra = HullMode(self.name, f, 0.02, k / (2 * math.pi * f) ** 2, v, g, a,
                         moves_hull=self.moves_hull)
        return replace(rig, hull_modes=rig.hull_modes + (extra,))


class Tiller(_ExtraMode):
    name = "tiller"
    label = "steering-gear / tiller flexibility (extra mode)"
    shape = (0.0, 1.0, 0.0)
    bodies = ("rudder", "stock")
    moves_hull = False

    def _k_ref(self, rig) -> float:
        return rig.stock.G_Pa * rig.stock.J_m4 / rig.stock.torsion_length_m


class HullCoupling(_ExtraMode):
    name = "hull_coupling"
    label = "hull flexibility / coupling (extra hull mode)"
    shape = (1.0, 0.0, 0.0)
    bodies = ("hull", "stock")
    moves_hull = True

    def _k_ref(self, rig) -> float:
        st = rig.stock
        ell = st.bending_length_m
        EI = st.E_Pa * st.I_m4
        phi = 12 * EI / (st.shear_area_m2 * st.G_Pa * ell**2)
        return 12 * EI / ((1 + phi) * ell**3)

