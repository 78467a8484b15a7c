"""How the shipped rigs' tuned numbers were found. Prints them; does not rewrite the files.

ALBACORE-like: the stock diameter d (solid round section: I = pi d^4/64, J = 2I, kappa A = 0.9 A)
and the rudder's I_x (not given in the report) are solved so that the predominant mode after the
rig's default blow is 24.5 Hz in air and 13.0 Hz in water (Report 1836, Table 2a).
SAMPSON-like: the two hull modes' dry frequencies and the stock diameter are solved so that, in
water, the coupled modes lie at 2.18, 4.36 and 7.6 Hz (Table 2g).
Stern plane (ALBACORE-like, in air only): the stock diameter, the plane's I_y (about the stock's
direction) and the fixed plane's dry frequency are solved so that the modes lie at 20, 77 and
120 Hz (Table 2e); then the damping C (with c_alpha = C x 0.1 m^2) so that the 20 Hz mode's
decrement is Table 2f's 0.0933.

    python recordings/tune_rigs.py
"""

from __future__ import annotations

import dataclasses as dc
import math
from pathlib import Path

import numpy as np
from scipy.optimize import brentq, least_squares

from ramdaq.analysis.model.rig import Rig, load_rig
from ramdaq.analysis.model.rig_modes import modes_in

HERE = Path(__file__).resolve().parent / "rigs"


def with_stock_diameter(rig: Rig, d: float) -> Rig:
    inertia, area = math.pi * d**4 / 64, math.pi * d**2 / 4
    return dc.replace(rig, stock=dc.replace(rig.stock, I_m4=inertia, J_m4=2 * inertia,
                                            shear_area_m2=0.9 * area))


def tune_albacore() -> None:
    rig = load_rig(HERE / "albacore.toml")

    def build(p):
        return dc.replace(with_stock_diameter(rig, p[0]),
                          rudder=dc.replace(rig.rudder, Ix_kg_m2=p[1]))

    def residual(p):
        r = build(p)
        return [modes_in(r, "air").predominant_hz / 24.5 - 1,
                modes_in(r, "water").predominant_hz / 13.0 - 1]

    fit = least_squares(residual, [0.45, 3000.0], x_scale=[0.05, 500.0], diff_step=1e-4)
    print(f"albacore: stock d = {fit.x[0]:.4f} m, I_x = {fit.x[1]:.0f} kg m^2, "
          f"residuals {fit.fun}")


def tune_sampson() -> None:
    rig = load_rig(HERE / "sampson.toml")

    def build(p):
        modes = (dc.replace(rig.hull_modes[0], frequency_hz=p[0]),
                 dc.replace(rig.hull_modes[1], frequency_hz=p[1]))
        return dc.replace(with_stock_diameter(rig, p[2]), hull_modes=modes)

    def residual(p):
        f = modes_in(build(p), "water").table.frequency_hz
        return [f[0] / 2.18 - 1, f[1] / 4.36 - 1, f[2] / 7.6 - 1]

    fit = least_squares(residual, [2.9, 5.8, 0.4], x_scale=[0.1, 0.1, 0.02], diff_step=1e-4,
                        bounds=([1, 2, 0.2], [10, 20, 1.0]))
    print(f"sampson: hull dry {fit.x[0]:.3f} Hz and {fit.x[1]:.3f} Hz, stock d = {fit.x[2]:.4f} m,"
          f" residuals {fit.fun}")


def tune_stern_plane() -> None:
    rig = load_rig(HERE / "stern_plane.toml")

    def build(p):
        modes = (dc.replace(rig.hull_modes[0], frequency_hz=p[2]),)
        return dc.replace(with_stock_diameter(rig, p[0]), hull_modes=modes,
                          rudder=dc.replace(rig.rudder, Iz_kg_m2=p[1]))  # the model's I_z is I_y

    def residual(p):
        f = modes_in(build(p), "air").table.frequency_hz
        return [f[0] / 20 - 1, f[1] / 77 - 1, f[2] / 120 - 1]

    fit = least_squares(residual, [0.22, 145.0, 138.0], x_scale=[0.01, 20.0, 5.0], diff_step=1e-4,
                        bounds=([0.05, 20, 50], [0.5, 2000, 300]))
    tuned = build(fit.x)
    delta = 0.0933
    zeta = delta / np.hypot(2 * np.pi, delta)

    def zeta_20(C):
        d = dc.replace(tuned.damping["air"], C_N_s_per_m=C, c_alpha_N_m_s_per_rad=0.1 * C)
        return modes_in(dc.replace(tuned, damping={"air": d}), "air").table.damping_ratio[0] - zeta

    C = brentq(zeta_20, 1000.0, 10000.0)
    print(f"stern plane: stock d = {fit.x[0]:.4f} m, I_y = {fit.x[1]:.2f} kg m^2, fixed plane dry "
          f"{fit.x[2]:.3f} Hz, C = {C:.0f} N s/m, residuals {fit.fun}")


if __name__ == "__main__":
    tune_albacore()
    tune_sampson()
    tune_stern_plane()
