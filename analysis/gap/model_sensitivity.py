"""Derivatives of a rig model's modes with respect to the rig's fitted constants, without
rebuilding the model: the first-order sensitivities of a non-symmetric eigenproblem.

The rig calibration (:mod:`~ramdaq.analysis.gap.rigfit`) differences its modal residual with
respect to a dozen constants at every step of its least squares; by finite differences that is a
dozen model builds and eigen-analyses a step (nine in ten of the model level's residual
evaluations). Here the same derivatives come from one eigen-analysis:

- :func:`matrix_derivatives`: ``dM, dC, dK`` with respect to each constant's log multiplier
  (``p dM/dp``), in closed form from how :func:`~ramdaq.analysis.model.structure.build_model`
  assembles them (every constant enters linearly, bilinearly with another, or -- the stock's
  bending inertia -- through the Timoshenko shear factor); ``tests/test_model_sensitivity.py``
  holds them against central differences of ``build_model``.
- :func:`mode_derivatives`: with ``A = [[0, I], [-M^-1 K, -M^-1 C]]`` diagonalised as
  ``A = V diag(lambda) W`` (``W = V^-1``, all ``2 n`` eigenvectors: the kept ones and their
  conjugates), ``d lambda_i = W_i dA V_i`` and ``d V_i = sum_{j != i} V_j (W_j dA V_i) /
  (lambda_i - lambda_j)`` (the part along ``V_i`` itself is a change of scale, which the
  calibration's shape comparison does not see, and is left out).
"""

from __future__ import annotations

import math
import re

import numpy as np

from ..model.response import ModalForm
from ..model.rig import Rig
from ..model.structure import added_mass, dashpot_strokes, stock_element, stock_ends

_HULL = re.compile(r"^hull\.modes\[(\d+)\]\.(\w+)$")
_DAMPING = {"C_N_s_per_m": 0, "c_N_m_s_per_rad": 1, "c_alpha_N_m_s_per_rad": 2}


def _dKe_stock_I(rig: Rig) -> np.ndarray:
    """``I dKe/dI`` of the stock's bending element (4, 4): with ``Phi`` and ``EI`` both
    proportional to I, ``k_s = EI / ((1 + Phi) l^3)`` gives ``I dk_s/dI = k_s / (1 + Phi)``,
    and the Phi-terms of the element add ``k_s Phi A1``."""
    s = rig.stock
    ell = s.bending_length_m
    EI = s.E_Pa * s.I_m4
    phi = 12 * EI / (s.shear_area_m2 * s.G_Pa * ell**2)
    ks = EI / ((1 + phi) * ell**3)
    A1 = ell**2 * np.array([[0, 0, 0, 0], [0, 1, 0, -1], [0, 0, 0, 0], [0, -1, 0, 1]], float)
    return stock_element(rig) / (1 + phi) + ks * phi * A1


def matrix_derivatives(rig: Rig, names: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(dM, dC, dK)``, each (len(names), n_dof, n_dof): the derivatives of ``build_model(rig)``'s
    matrices with respect to the log multiplier of each rig-file constant in ``names`` (those of
    :func:`~ramdaq.analysis.gap.rigfit.fit_params`). Raises ValueError naming a constant it has
    no derivative for (the rudder's mass: the fit's scale, never fitted)."""
    n = 3 + len(rig.hull_modes)
    p = len(names)
    dM, dC, dK = np.zeros((p, n, n)), np.zeros((p, n, n)), np.zeros((p, n, n))
    T = stock_ends(rig)
    R = dashpot_strokes(T)
    water = rig.medium == "water"
    r, d = rig.rudder, rig.active_damping
    for k, name in enumerate(names):
        if (m := _HULL.match(name)) is not None:
            _hull_derivative(rig, int(m[1]), m[2], water, dM[k], dC[k], dK[k])
            continue
        part = name.split(".")
        if name == "rudder.Iz_kg_m2":
            dM[k, 1, 1] = r.Iz_kg_m2
        elif name == "rudder.Ix_kg_m2":
            dM[k, 2, 2] = r.Ix_kg_m2
        elif name == "rudder.Ixz_kg_m2":
            dM[k, 1, 2] = dM[k, 2, 1] = -r.Ixz_kg_m2
        elif name == "rudder.added_mass_factor":
            add = added_mass(rig)
            dM[k][np.diag_indices(3)] = (add["m_vir"], add["Iz_vir"], add["Ix_vir"])
        elif name == "stock.I_m4":
            dKe = np.zeros((6, 6))
            dKe[:4, :4] = _dKe_stock_I(rig)
            dK[k] = T.T @ dKe @ T
        elif name == "stock.J_m4":
            kt = rig.stock.G_Pa * rig.stock.J_m4 / rig.stock.torsion_length_m
            t = T[4] - T[5]
            dK[k] = kt * np.outer(t, t)
        elif part[0] == "damping" and part[1] == rig.medium and part[2] in _DAMPING:
            i = _DAMPING[part[2]]
            dC[k] = getattr(d, part[2]) * np.outer(R[i], R[i])
        elif part[0] != "damping":
            raise ValueError(f"{name}: no model derivative for this constant")
    dK = 0.5 * (dK + dK.transpose(0, 2, 1))
    return dM, dC, dK


def _hull_derivative(rig: Rig, k: int, key: str, water: bool, dM: np.ndarray, dC: np.ndarray,
                     dK: np.ndarray) -> None:
    """Hull mode ``k``'s ``key``: its diagonal terms ``M = m (1 + ratio)``, ``K = m w^2``,
    ``C = 2 zeta w m`` differentiated in the key's log multiplier (in place)."""
    mode = rig.hull_modes[k]
    i = 3 + k
    mk, wk, z = mode.modal_mass_kg, 2 * math.pi * mode.frequency_hz, mode.damping_ratio
    if key == "frequency_hz":
        dK[i, i], dC[i, i] = 2 * mk * wk**2, 2 * z * wk * mk
    elif key == "modal_mass_kg":
        dM[i, i] = mk * (1 + (mode.added_mass_ratio_water if water else 0.0))
        dK[i, i], dC[i, i] = mk * wk**2, 2 * z * wk * mk
    elif key == "damping_ratio":
        dC[i, i] = 2 * z * wk * mk
    else:
        raise ValueError(f"hull.modes[{k}].{key}: no model derivative for this constant")


def mode_derivatives(form: ModalForm, dM: np.ndarray, dC: np.ndarray,
                     dK: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(dlam, dacc)``: the derivatives of ``form``'s eigenvalues (p, n_modes) and of its gage
    acceleration shapes (p, n_gages, n_modes), for the matrix derivatives ``dM, dC, dK``
    (p, n_dof, n_dof) of :func:`matrix_derivatives`. Every mode must be underdamped (a
    :func:`~ramdaq.analysis.model.response.modal_form` is); a shape's derivative leaves out
    its change of scale. Raises ValueError when two eigenvalues coincide (no derivative)."""
    model = form.model
    n = model.n_dof
    Minv = np.linalg.inv(model.M)
    A21, A22 = -Minv @ model.K, -Minv @ model.C
    p = dM.shape[0]
    dA = np.zeros((p, 2 * n, 2 * n))
    dA[:, n:, :n] = -Minv @ (dK + dM @ A21)
    dA[:, n:, n:] = -Minv @ (dC + dM @ A22)
    lam = form.eigenvalues
    m = len(lam)
    lam_all = np.concatenate([lam, lam.conj()])
    V = np.hstack([form.right, form.right.conj()])
    W = np.vstack([form.left, form.left.conj()])
    P = W @ dA @ V[:, :m]                       # (p, 2m, m): W_j dA V_i
    dlam = np.diagonal(P[:, :m, :], axis1=1, axis2=2)
    gap = lam[None, :] - lam_all[:, None]       # (2m, m): lambda_i - lambda_j
    gap[np.arange(m), np.arange(m)] = np.inf    # the V_i part: a change of scale, left out
    if np.any(np.abs(gap) <= 1e-12 * np.abs(lam).max(initial=1.0)):
        raise ValueError("two of the model's eigenvalues coincide: no mode derivative")
    dV = V[n:] @ (P / gap)                      # (p, n, m): velocity rows of dV
    dacc = model.gage_dofs @ (dV * lam + form.right[n:] * dlam[:, None, :])
    return dlam, dacc
