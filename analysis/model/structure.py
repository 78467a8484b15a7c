"""Linear model of the rudder-stock-hull system (Report 1836, Appendix D, Reference 1 Eq 62).

Degrees of freedom ``q = [v, gamma, alpha, eta_1 .. eta_m]``: the rudder's translation v (m) along
y and rotations gamma about z and alpha about x (rad) at its centre of mass, and one modal
coordinate per hull mode (m-normalised by each mode's ``v_b, gamma_b, alpha_b`` at the stock).

Stiffness: the stock is a Timoshenko beam element between the hull attachment (node 1, slope
alpha_b, deflection v_b) and the rudder attachment (node 2, at x = h, z = b above the centre of mass),
measured along s pointing down the stock, so the slope ``dw/ds`` equals alpha at both ends.
With ``Phi = 12 EI / (kappa A G l^2)`` and ``k_s = EI / ((1 + Phi) l^3)`` (the report's k_s), the
element stiffness on ``[w1, theta1, w2, theta2]`` is::

    k_s * [[ 12,      6l,          -12,      6l         ],
           [ 6l,  (4+Phi) l^2,     -6l,  (2-Phi) l^2    ],
           [-12,     -6l,           12,     -6l         ],
           [ 6l,  (2-Phi) l^2,     -6l,  (4+Phi) l^2    ]]

and the ends follow the rigid bodies: ``w1 = v_b, theta1 = alpha_b, w2 = v + h*gamma - b*alpha,
theta2 = alpha``. Torsion adds ``(G J / l_T)(gamma - gamma_b)^2 / 2``. The stiffness matrix is the
congruence ``K = T' K_e T`` plus the hull modes' own ``m_k w_k^2`` -- symmetric and positive
(semi-)definite by construction. Its v row is Eq 62a exactly,
``12 k_s [v - v_b + h gamma - b alpha - (l/2)(alpha + alpha_b)]``, and its gamma row Eq 62b's
stiffness terms, ``12 k_s h (v - v_b) - 6 k_s h (l + 2b) alpha + [GJ/l + 12 k_s h^2] gamma -
6 k_s h l alpha_b - (GJ/l) gamma_b`` (the report writes them on the right-hand side, negated).
The alpha row that the report leaves out (its Eq 62c) is the same energy's derivative:
``-b * F2 + M2`` with ``F2`` the shear and ``M2`` the end moment of the element at the rudder.

Mass: ``diag(m, [[I_z, -I_xz], [-I_xz, I_x]])`` for the rudder (Eq 62b's ``I_z gamma'' - I_xz
alpha''``), plus, in water, Eq 19-21's added mass and inertias (times the rig's
``added_mass_factor``); the hull modes' modal masses, in water times (1 + added_mass_ratio).
The stock's own mass is neglected, as in the report.

Damping (viscous): ``C`` on v (absolute, Eq 62a), ``c`` on ``gamma - gamma_b`` (Eq 62b) and
``c_alpha`` on ``alpha - alpha_b``; hull modes ``2 zeta_k w_k m_k``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..report1836.virtual_mass import Ix_vir, Iz_vir_elliptic, m_vir_flat_plate
from .rig import AXES, Rig

RUDDER_DOFS = ("v", "gamma", "alpha")


@dataclass(frozen=True)
class StructuralModel:
    """Second-order model ``M q'' + C q' + K q = Q f(t)``.

    Attributes
    ----------
    M, C, K : numpy.ndarray
        Mass (kg, kg m^2), damping and stiffness matrices, shape ``(n_dof, n_dof)``.
    dofs : tuple of str
        Names of the degrees of freedom.
    gage_dofs : numpy.ndarray
        Displacement of each gage along its sensing axis per unit DOF, shape
        ``(n_gages, n_dof)``, rows in DAQ channel order.
    gage_numbers : tuple of int
        Report gage number of each row of ``gage_dofs``.
    medium : str
        "air" or "water".
    added : dict
        Added mass and inertias used (kg, kg m^2): ``m_vir``, ``Iz_vir``, ``Ix_vir``; zeros in air.
    """

    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    dofs: tuple[str, ...]
    gage_dofs: np.ndarray
    gage_numbers: tuple[int, ...]
    medium: str
    added: dict[str, float]
    rig: Rig

    @property
    def n_dof(self) -> int:
        return self.M.shape[0]

    def force_vector(self, location_m: tuple[float, float, float], direction: str = "y") -> np.ndarray:
        """Generalised force per newton applied at ``location_m`` on the rudder, shape (n_dof,)."""
        return np.asarray(AXES[direction]) @ rudder_point_dofs(location_m, self.n_dof)


def rudder_point_dofs(point_m: tuple[float, float, float], n_dof: int) -> np.ndarray:
    """Displacement (x, y, z) of a rudder point per unit DOF, shape ``(3, n_dof)``.

    ``u = (-gamma*y, v + gamma*x - alpha*z, alpha*y)`` about the centre of mass.
    """
    x, y, z = point_m
    U = np.zeros((3, n_dof))
    U[0, 1] = -y
    U[1, :3] = (1.0, x, -z)
    U[2, 2] = y
    return U


def added_mass(rig: Rig) -> dict[str, float]:
    """Eq 19-21 added mass (kg) and inertias (kg m^2) of the rudder in water, zero in air.

    Eq 19: ``m_vir = (pi/4) rho chord^2 span``; Eq 20: ``(I_z)_vir = (pi/8) rho
    ((chord/2)^2 - (thickness/2)^2)^2 span`` (r^2 m_vir ~ 0); Eq 21 (reconstructed):
    ``(I_x)_vir = m_vir span^2 / 16`` (s^2 m_vir ~ 0). All times ``rudder.added_mass_factor``.
    """
    if rig.medium == "air":
        return {"m_vir": 0.0, "Iz_vir": 0.0, "Ix_vir": 0.0}
    r, f = rig.rudder, rig.rudder.added_mass_factor
    m_vir, iz_vir, ix_vir = _added_mass_as_printed(rig.water_density_kg_m3, r.chord_m, r.span_m,
                                                   r.thickness_m)
    return {"m_vir": f * m_vir, "Iz_vir": f * iz_vir, "Ix_vir": f * ix_vir}


@functools.lru_cache(maxsize=64)
def _added_mass_as_printed(rho: float, chord: float, span: float, thickness: float) -> tuple:
    """Eq 19-21 as printed (kg, kg m^2, kg m^2), once per geometry: a calibration builds the
    model thousands of times with only the factor changing."""
    m_vir = m_vir_flat_plate(rho, chord, span)
    return m_vir, Iz_vir_elliptic(rho, chord, thickness, span), Ix_vir(m_vir, span)


def stock_element(rig: Rig) -> np.ndarray:
    """Timoshenko element stiffness on ``[w1, theta1, w2, theta2]`` (N/m, N, N m/rad), (4, 4)."""
    s = rig.stock
    ell = s.bending_length_m
    EI = s.E_Pa * s.I_m4
    phi = 12 * EI / (s.shear_area_m2 * s.G_Pa * ell**2)
    ks = EI / ((1 + phi) * ell**3)
    return ks * np.array([
        [12, 6 * ell, -12, 6 * ell],
        [6 * ell, (4 + phi) * ell**2, -6 * ell, (2 - phi) * ell**2],
        [-12, -6 * ell, 12, -6 * ell],
        [6 * ell, (2 - phi) * ell**2, -6 * ell, (4 + phi) * ell**2],
    ])


def stock_ends(rig: Rig) -> np.ndarray:
    """The stock's ends in terms of the model's coordinates q (rudder v, gamma, alpha, then one
    per hull mode): rows w1, theta1, w2, theta2, gamma, gamma_b per unit of each, (6, n_dof)."""
    r = rig.rudder
    T = np.zeros((6, 3 + len(rig.hull_modes)))
    T[2, :3] = (1.0, r.stock_x_m, -r.attach_z_m)
    T[3, 2] = 1.0
    T[4, 1] = 1.0
    for k, mode in enumerate(rig.hull_modes):
        T[0, 3 + k] = mode.v_b
        T[1, 3 + k] = mode.alpha_b
        T[5, 3 + k] = mode.gamma_b
    return T


def dashpot_strokes(T: np.ndarray) -> np.ndarray:
    """What the rig's three dashpots (C, c, c_alpha) see per unit of each coordinate, from the
    stock's ends ``T`` (:func:`stock_ends`): v (absolute), gamma - gamma_b, alpha - alpha_b,
    (3, n_dof)."""
    R = np.zeros((3, T.shape[1]))
    R[0, 0] = 1.0
    R[1] = T[4] - T[5]
    R[2] = T[3] - T[1]
    return R


def build_model(rig: Rig) -> StructuralModel:
    """Assemble M, C, K and the gage output map for ``rig`` in its medium."""
    r, st, modes = rig.rudder, rig.stock, rig.hull_modes
    n = 3 + len(modes)
    water = rig.medium == "water"
    add = added_mass(rig)

    M = np.zeros((n, n))
    M[0, 0] = r.mass_kg + add["m_vir"]
    M[1, 1] = r.Iz_kg_m2 + add["Iz_vir"]
    M[2, 2] = r.Ix_kg_m2 + add["Ix_vir"]
    M[1, 2] = M[2, 1] = -r.Ixz_kg_m2

    T = stock_ends(rig)
    Ke = np.zeros((6, 6))
    Ke[:4, :4] = stock_element(rig)
    kt = st.G_Pa * st.J_m4 / st.torsion_length_m
    Ke[4:, 4:] = kt * np.array([[1.0, -1.0], [-1.0, 1.0]])
    K = T.T @ Ke @ T

    d = rig.active_damping
    R = dashpot_strokes(T)
    C = R.T @ np.diag([d.C_N_s_per_m, d.c_N_m_s_per_rad, d.c_alpha_N_m_s_per_rad]) @ R

    for k, mode in enumerate(modes):
        i = 3 + k
        mk = mode.modal_mass_kg * (1 + (mode.added_mass_ratio_water if water else 0.0))
        # The hull's own frequency is given dry; in water its stiffness is the same.
        wk = 2 * math.pi * mode.frequency_hz
        M[i, i] = mk
        K[i, i] += mode.modal_mass_kg * wk**2
        C[i, i] += 2 * mode.damping_ratio * wk * mode.modal_mass_kg

    gages = rig.gages_by_channel()
    return StructuralModel(
        M=M, C=C, K=0.5 * (K + K.T), dofs=RUDDER_DOFS + tuple(f"eta{k + 1}" for k in range(len(modes))),
        gage_dofs=gage_map(rig, n), gage_numbers=tuple(g.number for g in gages), medium=rig.medium,
        added=add, rig=rig,
    )


_GAGE_MAPS: dict[tuple, np.ndarray] = {}


def gage_map(rig: Rig, n_dof: int) -> np.ndarray:
    """Each gage's displacement along its sensing axis per unit DOF, (n_gages, n_dof), rows in
    DAQ channel order; read-only.

    Kept per geometry -- the gages, the stock's attachment and lengths, the hull modes' shapes at
    the stock: all that :func:`point_dofs` reads -- since a calibration rebuilds the model
    thousands of times changing only stiffness, damping and mass."""
    r, st = rig.rudder, rig.stock
    key = (rig.gages, r.stock_x_m, r.attach_z_m, st.bending_length_m, st.torsion_length_m,
           tuple((m.v_b, m.gamma_b, m.alpha_b, m.moves_hull) for m in rig.hull_modes), n_dof)
    G = _GAGE_MAPS.get(key)
    if G is None:
        G = np.vstack([g.direction @ point_dofs(rig, g.body, g.position_m, n_dof)
                       for g in rig.gages_by_channel()])
        G.flags.writeable = False
        if len(_GAGE_MAPS) >= 256:        # an extra mode's fitted shape makes new keys
            _GAGE_MAPS.clear()
        _GAGE_MAPS[key] = G
    return G


def point_dofs(rig: Rig, body: str, point_m: tuple[float, float, float], n_dof: int) -> np.ndarray:
    """Displacement (x, y, z) of a point on ``body`` per unit DOF, shape ``(3, n_dof)``.

    Rudder: rigid body about the centre of mass. Hull: the section at the stock moves rigidly
    with ``(v_b, gamma_b, alpha_b)`` about the hull attachment ``(h, 0, b + l)``. Stock: its axis
    deflects by the beam element's cubic (Hermite) shape between the rudder and hull attachments,
    and twists linearly from gamma at the rudder to gamma_b over the torsion length.

    What it reads of ``rig`` is :func:`gage_map`'s key: anything it comes to read must join it.
    """
    r, st = rig.rudder, rig.stock
    h, b, ell = r.stock_x_m, r.attach_z_m, st.bending_length_m
    x, y, z = point_m
    U = np.zeros((3, n_dof))
    if body == "rudder":
        return rudder_point_dofs(point_m, n_dof)
    hull_v = np.zeros(n_dof)
    hull_g = np.zeros(n_dof)
    hull_a = np.zeros(n_dof)
    for k, mode in enumerate(rig.hull_modes):
        if body != "hull" or mode.moves_hull:
            hull_v[3 + k], hull_g[3 + k], hull_a[3 + k] = mode.v_b, mode.gamma_b, mode.alpha_b
    if body == "hull":
        zh = b + ell
        U[0] = -y * hull_g
        U[1] = hull_v + (x - h) * hull_g - (z - zh) * hull_a
        U[2] = y * hull_a
        return U
    # stock: s runs down from the hull attachment (s = 0) to the rudder attachment (s = l)
    s = np.clip((b + ell - z) / ell, 0.0, 1.0)
    H1, H2 = 1 - 3 * s**2 + 2 * s**3, ell * (s - 2 * s**2 + s**3)
    H3, H4 = 3 * s**2 - 2 * s**3, ell * (-(s**2) + s**3)
    w2 = np.zeros(n_dof)
    w2[:3] = (1.0, h, -b)
    th2 = np.zeros(n_dof)
    th2[2] = 1.0
    w = H1 * hull_v + H2 * hull_a + H3 * w2 + H4 * th2
    # slope dw/ds = alpha along the stock; a point off the axis in y sees it as u_z = y*alpha
    dH1, dH2 = (-6 * s + 6 * s**2) / ell, 1 - 4 * s + 3 * s**2
    dH3, dH4 = (6 * s - 6 * s**2) / ell, -2 * s + 3 * s**2
    slope = dH1 * hull_v + dH2 * hull_a + dH3 * w2 + dH4 * th2
    t = np.clip((z - b) / st.torsion_length_m, 0.0, 1.0)
    twist = np.zeros(n_dof)
    twist[1] = 1 - t
    twist += t * hull_g
    U[0] = -y * twist
    U[1] = w + (x - h) * twist
    U[2] = y * slope
    return U
