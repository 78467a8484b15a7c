"""The report's equations applied to the model's own motions: the conventions agree.

For every mode of the model, the gage displacements are exact rigid-body kinematics of the
rudder (and hull), so Eq 1-3b must give back the mode's own v, gamma, alpha to float rounding,
and Eq 8 the hull's alpha_b."""

import numpy as np
import pytest

from ramdaq.analysis.model.geometry import gage_geometry
from ramdaq.analysis.model.response import modal_form
from ramdaq.analysis.model.structure import build_model
from ramdaq.analysis.report1836.motions import (
    alpha,
    alpha_b_from_13_14,
    alpha_b_from_15_16,
    gamma,
    geometry_constants,
    v_from_2_6,
    v_from_4_8,
)


@pytest.mark.parametrize("part", [np.real, np.imag], ids=["real", "imag"])
@pytest.mark.parametrize("rig_name", ["albacore", "sampson"])
def test_eq_1_to_3_recover_model_motions(request, rig_name, part):
    rig = request.getfixturevalue(rig_name)
    K = geometry_constants(gage_geometry(rig))
    model = build_model(rig)
    form = modal_form(model)
    rows = {n: i for i, n in enumerate(model.gage_numbers)}
    # one quadrature of the complex mode shapes: a real displacement pattern at every gage
    d = {n: part(form.gage_disp[rows[n]]) for n in rows}
    q = part(form.right[: model.n_dof])  # the same modes in DOFs (v, gamma, alpha, eta...)
    scale = np.abs(q[:3]).max()
    tol = 1e-9 * scale  # float rounding of a few products
    assert np.allclose(gamma(d[4], d[8], K["K1"]), q[1], atol=tol)
    assert np.allclose(alpha(d[6], d[2], K["K2"]), q[2], atol=tol)
    assert np.allclose(v_from_2_6(d[2], d[6], K["K3"], K["K4"]), q[0], atol=tol)
    assert np.allclose(v_from_4_8(d[4], d[8], K["K5"], K["K6"]), q[0], atol=tol)
    geom = gage_geometry(rig)
    alpha_b = sum(m.alpha_b * q[3 + k] for k, m in enumerate(rig.hull_modes))
    assert np.allclose(alpha_b_from_13_14(d[13], d[14], geom.L_P), alpha_b, atol=tol)
    assert np.allclose(alpha_b_from_15_16(d[15], d[16], geom.Y_P), alpha_b, atol=tol)


def test_albacore_distances(albacore):
    g = gage_geometry(albacore)
    assert (g.x1, g.x2, g.z1, g.z2) == (0.6, 0.6, 1.0, 1.0)
    assert g.L_P == pytest.approx(1.5) and g.Y_P == pytest.approx(2.0)
    assert g.x7 == pytest.approx(0.23) and g.x10 == pytest.approx(0.23)
