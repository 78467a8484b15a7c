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

import numpy as np

from ...model.rig import HullMode
from .base import (
    Effect,
    Placement,
    Term,
    compared_modes,
    placement,
    residual_peaks,
)


class _ExtraMode(Effect):
    shape: tuple[float, float, float] = (0.0, 0.0, 0.0)
    where: str = "all"
    tilts: tuple[str, ...] = ()
    """Names of the free ratios of the other two stock-end motions to the main one (a local hull
    structure rarely sways without rocking): each adds a parameter, rad per m."""
    above_band: bool = False
    """Also place the mode above the compared band, where only its static compliance shows."""
    scan_f: bool = False
    """Also start refits from frequencies spread between the lowest start and the upper bound."""

    def _k_ref(self, rig) -> float:
        raise NotImplementedError

    def _placement(self, fw, fs: list[float], lo: float, hi: float) -> Placement:
        """One placement of the mode: frequencies ``fs`` to start from (the first names it),
        bounds ``lo``-``hi`` Hz."""
        gages = tuple(g.number for g in fw.td.rig.gages_by_channel() if g.body in self.bodies)
        nt = len(self.tilts)
        f = fs[0]
        probes = [[g, 2.0] + [0.0] * nt for g in fs]
        probes += [[f, 2.0] + [0.3 * (i == j) for i in range(nt)] for j in range(nt)]
        # the stiffness spans decades and acts far from linearly: start the refit from a scan
        starts = [[g, L] + [0.0] * nt for g in fs for L in (0.0, 0.5, 1.0, 1.5, 2.5, 3.5)]
        if self.scan_f:
            # a heavy tiller's own frequency may sit between the residual's peaks and the band's
            # top (a soft gear pulls the torsion mode 40 % down and rings itself far from both)
            starts += [[g, L] + [0.0] * nt for g in np.geomspace(lo, hi, 6)[1:-1] for L in (-0.3, 0.3)]
        return placement({"f_hz": round(f, 3)}, ("f_hz", "log10_k_ratio") + self.tilts,
                         ("Hz", "log10 x stock") + ("rad/m",) * nt,
                         [f, 6.0] + [0.0] * nt, [lo, -1.0] + [-1.0] * nt, [hi, 6.0] + [1.0] * nt, probes,
                         gages=gages, mode_hz=f, window=self.where, starts=starts)

    def placements(self, fw, fit) -> list[Placement]:
        avoid = [f for _, f in compared_modes(fw, fit)]
        peaks = residual_peaks(fw, fit, ("early", "late"), 3, avoid_hz=avoid)
        if not self.above_band:
            return [self._placement(fw, [f], 0.75 * f, 1.25 * f) for f in peaks]
        # a stiff gear on a light tiller rings far above the compared band, where only its
        # compliance shows (the stock's top turns): one placement spans both, started at the
        # residual's peaks and above the band
        top = fw.td.lowpass_hz
        hi = min(20.0 * top, 0.45 * fw.td.fs_full_hz)
        fs = [2.0 * top, 4.0 * top] + peaks
        return [self._placement(fw, fs, 0.75 * min(fs), hi)]

    def rig(self, rig, term: Term):
        v, g, a = self.shape
        names = term.placement.names
        g += term.value("gamma_per_v") if "gamma_per_v" in names else 0.0
        a += term.value("alpha_per_v") if "alpha_per_v" in names else 0.0
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
    above_band = True
    scan_f = True

    def _k_ref(self, rig) -> float:
        return rig.stock.G_Pa * rig.stock.J_m4 / rig.stock.torsion_length_m


class HullCoupling(_ExtraMode):
    name = "hull_coupling"
    label = "hull flexibility / coupling (extra hull mode)"
    shape = (1.0, 0.0, 0.0)
    bodies = ("hull", "stock")
    moves_hull = True
    tilts = ("gamma_per_v", "alpha_per_v")

    def _k_ref(self, rig) -> float:
        st = rig.stock
        ell = st.bending_length_m
        EI = st.E_Pa * st.I_m4
        phi = 12 * EI / (st.shear_area_m2 * st.G_Pa * ell**2)
        return 12 * EI / ((1 + phi) * ell**3)

