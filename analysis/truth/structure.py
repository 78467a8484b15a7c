"""The benchmark's *truth* structure: a richer rudder-stock-hull model than
:mod:`ramdaq.analysis.model.structure`.

What it adds to the nominal model (which the diagnosis fits):

* The stock is a chain of :data:`N_BEND_ELEMENTS` Timoshenko beam elements (the same element as
  :func:`ramdaq.analysis.model.structure.stock_element`, at element length) **with its own mass**: steel
  (:data:`STEEL_DENSITY_KG_M3`), area ``A = sqrt(4 pi I)`` of a solid round section, consistent
  (cubic Hermite) translational mass plus rotary inertia ``rho I``. Torsion is a chain of linear
  elements over the torsion length with polar inertia ``rho 2I`` per metre and a node at the
  bearing (the bending attachment height, where the stock turns in its hull bearing).
* The stock's internal DOFs carry a small Rayleigh stiffness-proportional damping acting on their
  deviation from the static (condensed) shape, ``C_R = beta S' K_II S`` with
  ``S q = q_I + K_II^-1 K_IB q_B``: the stock's own modes get ``zeta = STOCK_ZETA`` at the first,
  while the rudder modes (quasi-static stock) are left with the nominal damping conventions:
  ``C`` on v, ``c`` on gamma - gamma_b, ``c_alpha`` on alpha - alpha_b, hull ``2 zeta w m``.
* Optional extra DOFs that carry a hidden effect: a local hull mode (``extra_hull``), a tiller on
  a steering-gear spring at the stock top (``tiller``), a small tuned absorber on the rudder
  (``absorber``); and scaled added (or, in air, own) inertias (``inertia_factors``).

With ``stock_mass_factor = 0`` the internal DOFs are condensed out statically; a chain of these
Timoshenko elements is exact for an end-loaded beam, so the model is then the nominal one
(tests/test_gap_truth.py holds the frequencies to 1e-9). Full steel mass (1450 kg ALBACORE-like,
1670 kg SAMPSON-like, half and a quarter of the rudder's mass) shifts the nominal rigs' modes,
measured, predominant starred: ALBACORE-like in air (7.95, *24.5*, 88.2, 334 Hz) by -0.25 %,
*-0.27 %*, -0.94 %, -20.7 %; in water (6.85, *13.0*, 59.8, 216 Hz) by -0.19 %, *-0.05 %*,
-0.41 %, -10.1 %; SAMPSON-like in water (2.18, 4.36, *7.60*, 23.1, 127 Hz) by -0.04 %, -0.02 %,
*-0.04 %*, -0.13 %, -6.1 %. The stock is stubby (length/diameter 2.4-2.8) and its mass sits
where it moves little, except in the highest (rudder-on-stock rocking) mode. Its own first
modes lie at 1.1-1.3 kHz (ALBACORE-like) and 0.85-1.1 kHz (SAMPSON-like), above the
anti-alias corner. Stock gages see the Timoshenko chain's deflected shape (shear included),
which differs from the nominal model's cubic interpolation by up to ~4 % of the rudder's v.

DOFs ``q = [v, gamma, alpha, w_1, theta_1, .., phi_1, .., eta_1 .., extras]`` (m, rad; eta per the
hull modes' normalisation); units SI throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from ..model.rig import AXES, Rig
from ..model.structure import added_mass, rudder_point_dofs

STEEL_DENSITY_KG_M3 = 7850.0
N_BEND_ELEMENTS = 4
N_TORSION_ELEMENTS = 4
STOCK_ZETA = 0.03
"""Damping ratio of the stock's first fixed-interface mode (steel, bolted: a few per cent)."""


@dataclass(frozen=True)
class TruthModel:
    """``M q'' + C q' + K q = sum_j f_j u_j(t)`` of the truth structure.

    ``M, C, K``: (n, n). ``gage_dofs``: (n_gages, n) displacement along each gage's sensing axis
    per unit DOF, rows in DAQ channel order. ``rows``: named (n,) maps used by the effects
    (``hull_v``, ``hull_gamma``, ``hull_alpha`` at the stock's hull attachment, ``bearing_twist``
    the stock's twist at its bearing, ``top_twist``). ``stock_mass_kg`` the stock's bending mass.
    """

    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    dofs: tuple[str, ...]
    gage_dofs: np.ndarray
    rows: dict[str, np.ndarray]
    rig: Rig
    stock_mass_kg: float
    rayleigh_beta_s: float
    _point: object = field(repr=False, default=None)

    @property
    def n_dof(self) -> int:
        return self.M.shape[0]

    def force_vector(self, location_m: tuple[float, float, float], direction: str = "y") -> np.ndarray:
        """Generalised force per newton at a rudder point along ``direction``, shape (n,)."""
        return self.point_row("rudder", location_m, direction)

    def point_row(self, body: str, point_m: tuple[float, float, float], axis: str | np.ndarray) -> np.ndarray:
        """Displacement of a point on ``body`` along ``axis`` (name or unit 3-vector) per unit DOF, (n,)."""
        d = np.asarray(AXES[axis] if isinstance(axis, str) else axis, dtype=float)
        return d @ self._point(body, point_m)  # type: ignore[misc]


def stock_section(rig: Rig) -> tuple[float, float]:
    """Area (m^2) and mass per metre (kg/m) of a solid round stock of the rig's ``I_m4``."""
    area = math.sqrt(4 * math.pi * rig.stock.I_m4)
    return area, STEEL_DENSITY_KG_M3 * area


def _bend_element(rig: Rig, le: float, rho_a: float, rho_i: float) -> tuple[np.ndarray, np.ndarray]:
    """Timoshenko stiffness and consistent mass (translation + rotary) on [w1, th1, w2, th2]."""
    s = rig.stock
    EI = s.E_Pa * s.I_m4
    phi = 12 * EI / (s.shear_area_m2 * s.G_Pa * le**2)
    ks = EI / ((1 + phi) * le**3)
    K = ks * np.array([[12, 6 * le, -12, 6 * le], [6 * le, (4 + phi) * le**2, -6 * le, (2 - phi) * le**2],
                       [-12, -6 * le, 12, -6 * le], [6 * le, (2 - phi) * le**2, -6 * le, (4 + phi) * le**2]])
    Mt = rho_a * le / 420 * np.array([[156, 22 * le, 54, -13 * le],
                                      [22 * le, 4 * le**2, 13 * le, -3 * le**2],
                                      [54, 13 * le, 156, -22 * le],
                                      [-13 * le, -3 * le**2, -22 * le, 4 * le**2]])
    Mr = rho_i / (30 * le) * np.array([[36, 3 * le, -36, 3 * le], [3 * le, 4 * le**2, -3 * le, -(le**2)],
                                       [-36, -3 * le, 36, -3 * le], [3 * le, -(le**2), -3 * le, 4 * le**2]])
    return K, Mt + Mr


# Long (130 lines) on purpose: one assembly read top to bottom -- the DOF layout, the bending and
# torsion node maps, the element matrices, the rudder's masses, damping, tiller and absorber, the
# massless stock's condensation. Every step reads the DOF indices (i_hull, i_tiller, i_abs,
# internal) and the node maps (Tb, Tt, tz); split, each piece would take most of them as arguments.
def build_truth_model(rig: Rig, *, stock_mass_factor: float = 1.0, extra_hull: dict | None = None,
                      tiller: dict | None = None, absorber: dict | None = None,
                      inertia_factors: tuple[float, float] = (1.0, 1.0)) -> TruthModel:
    """Assemble the truth structure of ``rig`` in its medium.

    Parameters
    ----------
    stock_mass_factor : float
        Multiplies the stock's steel mass; 0 condenses the stock's internal DOFs out (massless).
    extra_hull : dict, optional
        A hull mode the rig lacks: ``frequency_hz``, ``damping_ratio``, ``modal_mass_kg``, ``v_b``
        (m), ``gamma_b``, ``alpha_b`` (rad) per unit modal coordinate at the stock's hull attachment.
    tiller : dict, optional
        ``inertia_kg_m2`` on the stock top, ``stiffness_N_m_per_rad`` of the steering gear to the
        hull, ``damping_ratio`` of that spring-inertia pair.
    absorber : dict, optional
        ``mass_kg`` on a spring ``stiffness_N_per_m`` with dashpot ``damping_N_s_per_m`` to the
        rudder point ``point_m`` along its ``axis``.
    inertia_factors : (float, float)
        ``(translational, rotational)``: in water they scale the added mass m_vir and the added
        inertias Iz_vir, Ix_vir; in air the rudder's own mass and its (Iz, Ix, Ixz).
    """
    r, st, d = rig.rudder, rig.stock, rig.active_damping
    h, b, ell, ellT = r.stock_x_m, r.attach_z_m, st.bending_length_m, st.torsion_length_m
    ne = N_BEND_ELEMENTS
    n_low = N_TORSION_ELEMENTS - 1 if ellT > 1.02 * ell else N_TORSION_ELEMENTS
    tz = np.concatenate([b + np.linspace(0.0, min(ell, ellT), n_low + 1),
                         [b + ellT] if n_low < N_TORSION_ELEMENTS else []])  # torsion nodes, up
    nt = len(tz) - 1
    hulls = [(m.frequency_hz, m.damping_ratio, m.modal_mass_kg
              * (1 + (m.added_mass_ratio_water if rig.medium == "water" else 0.0)), m.modal_mass_kg,
              m.v_b, m.gamma_b, m.alpha_b) for m in rig.hull_modes]
    if extra_hull is not None:
        e = extra_hull
        hulls.append((e["frequency_hz"], e["damping_ratio"], e["modal_mass_kg"], e["modal_mass_kg"],
                      e["v_b"], e["gamma_b"], e["alpha_b"]))
    dofs = ["v", "gamma", "alpha"]
    dofs += [f"{k}{j}" for j in range(1, ne) for k in ("w", "theta")]
    dofs += [f"phi{j}" for j in range(1, nt)]
    i_hull = len(dofs)
    dofs += [f"eta{k + 1}" for k in range(len(rig.hull_modes))] + (["eta_x"] if extra_hull else [])
    i_tiller = len(dofs) if tiller else -1
    dofs += ["tiller"] if tiller else []
    i_abs = len(dofs) if absorber else -1
    dofs += ["absorber"] if absorber else []
    n = len(dofs)
    internal = np.arange(3, i_hull)

    hv, hg, ha = np.zeros(n), np.zeros(n), np.zeros(n)
    for k, (_, _, _, _, vb, gb, ab) in enumerate(hulls):
        hv[i_hull + k], hg[i_hull + k], ha[i_hull + k] = vb, gb, ab
    # hull gages see the hull modes that move the hull around the stock (all of a rig file's)
    seen = np.ones(n)
    for k, m in enumerate(rig.hull_modes):
        seen[i_hull + k] = float(getattr(m, "moves_hull", True))
    # bending nodes, from the hull attachment (s = 0) down to the rudder (s = ell)
    Tb = np.zeros((2 * (ne + 1), n))
    Tb[0], Tb[1] = hv, ha
    for j in range(1, ne):
        Tb[2 * j, 3 + 2 * (j - 1)] = Tb[2 * j + 1, 4 + 2 * (j - 1)] = 1.0
    Tb[2 * ne, :3] = (1.0, h, -b)
    Tb[2 * ne + 1, 2] = 1.0
    # torsion nodes, from the rudder (z = b) up to the top (z = b + ellT)
    Tt = np.zeros((nt + 1, n))
    Tt[0, 1] = 1.0
    for j in range(1, nt):
        Tt[j, 3 + 2 * (ne - 1) + j - 1] = 1.0
    if tiller:
        Tt[nt, i_tiller] = 1.0
    else:
        Tt[nt] = hg

    area, rho_a = stock_section(rig)
    rho_a *= stock_mass_factor
    rho_i = STEEL_DENSITY_KG_M3 * st.I_m4 * stock_mass_factor
    le = ell / ne
    Kb, Mb = _bend_element(rig, le, rho_a, rho_i)
    Kn, Mn = np.zeros((2 * ne + 2,) * 2), np.zeros((2 * ne + 2,) * 2)
    for j in range(ne):
        sl = slice(2 * j, 2 * j + 4)
        Kn[sl, sl] += Kb
        Mn[sl, sl] += Mb
    K = Tb.T @ Kn @ Tb
    M = Tb.T @ Mn @ Tb
    GJ, rho_p = st.G_Pa * st.J_m4, 2 * rho_i
    for j in range(nt):
        lt = tz[j + 1] - tz[j]
        R = Tt[j:j + 2]
        K += GJ / lt * R.T @ np.array([[1.0, -1.0], [-1.0, 1.0]]) @ R
        M += rho_p * lt / 6 * R.T @ np.array([[2.0, 1.0], [1.0, 2.0]]) @ R

    add = added_mass(rig)
    f_tr, f_rot = inertia_factors
    if rig.medium == "water":
        M[0, 0] += r.mass_kg + f_tr * add["m_vir"]
        M[1, 1] += r.Iz_kg_m2 + f_rot * add["Iz_vir"]
        M[2, 2] += r.Ix_kg_m2 + f_rot * add["Ix_vir"]
        M[1, 2] -= r.Ixz_kg_m2
        M[2, 1] -= r.Ixz_kg_m2
    else:
        M[0, 0] += f_tr * r.mass_kg
        M[1, 1] += f_rot * r.Iz_kg_m2
        M[2, 2] += f_rot * r.Ix_kg_m2
        M[1, 2] -= f_rot * r.Ixz_kg_m2
        M[2, 1] -= f_rot * r.Ixz_kg_m2
    e_v, e_g, e_a = np.eye(n)[:3]
    Rd = np.vstack([e_v, e_g - hg, e_a - ha])
    C = Rd.T @ np.diag([d.C_N_s_per_m, d.c_N_m_s_per_rad, d.c_alpha_N_m_s_per_rad]) @ Rd
    for k, (f_hz, zeta, m_k, m_dry, *_) in enumerate(hulls):
        i, wk = i_hull + k, 2 * math.pi * f_hz
        M[i, i] += m_k
        K[i, i] += m_dry * wk**2
        C[i, i] += 2 * zeta * wk * m_dry
    if tiller:
        Jt, kt = tiller["inertia_kg_m2"], tiller["stiffness_N_m_per_rad"]
        rel = np.eye(n)[i_tiller] - hg
        M[i_tiller, i_tiller] += Jt
        K += kt * np.outer(rel, rel)
        C += 2 * tiller["damping_ratio"] * math.sqrt(kt * Jt) * np.outer(rel, rel)
    bearing = Tt[n_low]

    def point(body: str, p: tuple[float, float, float]) -> np.ndarray:
        return _point_dofs(body, p, n, h, b, ell, Tb, Tt, tz, hv * seen, hg * seen, ha * seen)

    if absorber:
        u = np.asarray(AXES[absorber["axis"]]) @ rudder_point_dofs(absorber["point_m"], n)
        rel = np.eye(n)[i_abs] - u
        M[i_abs, i_abs] += absorber["mass_kg"]
        K += absorber["stiffness_N_per_m"] * np.outer(rel, rel)
        C += absorber["damping_N_s_per_m"] * np.outer(rel, rel)

    beta_r = 0.0
    KII = K[np.ix_(internal, internal)]
    S = np.zeros((len(internal), n))
    S[:, internal] = np.eye(len(internal))
    ext = np.setdiff1d(np.arange(n), internal)
    S[:, ext] = np.linalg.solve(KII, K[np.ix_(internal, ext)])
    gages = rig.gages_by_channel()
    G = np.vstack([g.direction @ point(g.body, g.position_m) for g in gages])
    rows = {"hull_v": hv, "hull_gamma": hg, "hull_alpha": ha, "bearing_twist": bearing, "top_twist": Tt[nt]}
    if stock_mass_factor > 0:
        w1 = math.sqrt(scipy.linalg.eigh(KII, M[np.ix_(internal, internal)], eigvals_only=True)[0])
        beta_r = 2 * STOCK_ZETA / w1
        C += beta_r * S.T @ KII @ S
        Tg = np.eye(n)
    else:  # massless stock: static condensation of its internal DOFs (exact for these elements)
        Tg = np.eye(n)[:, ext]
        Tg[internal] = -S[:, ext]
        M, C, K = Tg.T @ M @ Tg, Tg.T @ C @ Tg, Tg.T @ K @ Tg
        G = G @ Tg
        rows = {k: v @ Tg for k, v in rows.items()}
        dofs = [dofs[i] for i in ext]
    return TruthModel(M=0.5 * (M + M.T), C=0.5 * (C + C.T), K=0.5 * (K + K.T), dofs=tuple(dofs),
                      gage_dofs=G, rows=rows, rig=rig, stock_mass_kg=rho_a * ell,
                      rayleigh_beta_s=beta_r, _point=lambda body, p: point(body, p) @ Tg)


def _point_dofs(body: str, p: tuple[float, float, float], n: int, h: float, b: float, ell: float,
                Tb: np.ndarray, Tt: np.ndarray, tz: np.ndarray, hv: np.ndarray, hg: np.ndarray,
                ha: np.ndarray) -> np.ndarray:
    """Displacement (x, y, z) of a point on ``body`` per unit DOF, (3, n): rudder rigid about its
    centre of mass; hull section rigid about the stock's hull attachment ``(h, 0, b + ell)``;
    stock by Hermite interpolation of the bending element holding the point and linear
    interpolation of the twist."""
    x, y, z = p
    if body == "rudder":
        return rudder_point_dofs(p, n)
    U = np.zeros((3, n))
    if body == "hull":
        U[0] = -y * hg
        U[1] = hv + (x - h) * hg - (z - (b + ell)) * ha
        U[2] = y * ha
        return U
    ne = Tb.shape[0] // 2 - 1
    le = ell / ne
    sg = float(np.clip(b + ell - z, 0.0, ell))  # s down from the hull attachment
    j = min(int(sg // le), ne - 1)
    s = (sg - j * le) / le
    nodal = Tb[2 * j:2 * j + 4]
    H = np.array([1 - 3 * s**2 + 2 * s**3, le * (s - 2 * s**2 + s**3), 3 * s**2 - 2 * s**3,
                  le * (-(s**2) + s**3)])
    dH = np.array([(-6 * s + 6 * s**2) / le, 1 - 4 * s + 3 * s**2, (6 * s - 6 * s**2) / le,
                   -2 * s + 3 * s**2])
    w, slope = H @ nodal, dH @ nodal
    zc = float(np.clip(z, tz[0], tz[-1]))
    k = min(int(np.searchsorted(tz, zc, side="right")) - 1, len(tz) - 2)
    t = (zc - tz[k]) / (tz[k + 1] - tz[k])
    twist = (1 - t) * Tt[k] + t * Tt[k + 1]
    U[0] = -y * twist
    U[1] = w + (x - h) * twist
    U[2] = y * slope
    return U
