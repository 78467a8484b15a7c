"""The rig model's modal sensitivities (analysis/gap/model_sensitivity.py) against central
differences of the model itself: the matrices' derivatives in each fitted constant, the modes'
derivatives, and the rig calibration's residual Jacobian built from them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ramdaq.analysis.gap.model_sensitivity import matrix_derivatives, mode_derivatives
from ramdaq.analysis.gap.rigfit import _data_jacobian, _data_residual, _Pairs, apply, fit_params
from ramdaq.analysis.model.response import modal_form
from ramdaq.analysis.model.rig import load_rig
from ramdaq.analysis.model.structure import build_model

H = 1e-5
"""Central-difference step in a log multiplier: truncation ~H^2 = 1e-10 relative, rounding
~1e-16 / H = 1e-11 relative of the model's matrices; of its eigenvectors (conditioned ~1e3
here) ~1e-7."""

RIGS = [("sampson", "water"), ("albacore", "air"), ("albacore", "water"), ("stern_plane", "air")]


def _rigs():
    rng = np.random.default_rng(3)
    for name, medium in RIGS:
        rig = load_rig(name).with_medium(medium)
        params = fit_params(rig)
        # away from the start, where a bilinear term (a hull mode's mass x frequency^2) shows
        yield name, medium, rig, params, rng.normal(0, 0.2, len(params))


@pytest.mark.parametrize("name,medium,rig,params,theta", list(_rigs()), ids=[f"{n}-{m}" for n, m in RIGS])
def test_matrix_derivatives_are_the_models_own(name, medium, rig, params, theta):
    """Every fitted constant's dM, dC, dK (in its log multiplier) equals central differences
    of build_model to 1e-8 of the matrix's scale (the step's truncation and rounding: 1e-10)."""
    at = apply(rig, params, theta)
    dM, dC, dK = matrix_derivatives(at, [p.name for p in params])
    for k, p in enumerate(params):
        e = np.zeros(len(params))
        e[k] = H
        hi, lo = build_model(apply(rig, params, theta + e)), build_model(apply(rig, params, theta - e))
        for got, a, b in ((dM[k], hi.M, lo.M), (dC[k], hi.C, lo.C), (dK[k], hi.K, lo.K)):
            ref = (a - b) / (2 * H)
            assert np.allclose(got, ref, rtol=0, atol=1e-8 * np.abs(a).max()), (name, p.name)


@pytest.mark.parametrize("name,medium,rig,params,theta", list(_rigs()), ids=[f"{n}-{m}" for n, m in RIGS])
def test_mode_derivatives_and_the_residual_jacobian(name, medium, rig, params, theta):
    """The eigenvalues' derivatives agree with central differences to 1e-6 of |lambda| and the
    rig fit's residual Jacobian (frequency, damping and scale-matched shape rows) column by
    column to 1e-5 of the column's size (eigenvector rounding in the differences, ~1e-7)."""
    at = apply(rig, params, theta)
    form = modal_form(build_model(at))
    dlam, _ = mode_derivatives(form, *matrix_derivatives(at, [p.name for p in params]))
    m = form.n_modes
    # identified modes: the model's own, each shape perturbed so the scale-match is not trivial
    rng = np.random.default_rng(1)
    shapes = form.gage_acc * (1 + 0.1 * rng.normal(size=form.gage_acc.shape))
    shapes /= np.linalg.norm(shapes, axis=0)
    f = form.eigenvalues.imag / (2 * math.pi) * 1.01
    zeta = -form.eigenvalues.real / np.abs(form.eigenvalues) * 0.9

    class TM:                     # the few fields of TrialModes the residual reads
        pass
    tm = TM()
    tm.f_hz, tm.zeta, tm.shapes = f, zeta, shapes
    idx = np.arange(m)
    pr = _Pairs(idx, idx, np.full(m, 1e-3), np.where(idx % 2 == 0, 0.05, np.nan),
                np.full(shapes.shape, 0.01))
    jac = _data_jacobian(tm, rig, params, pr, theta)
    for k, p in enumerate(params):
        e = np.zeros(len(params))
        e[k] = H
        lam_hi = modal_form(build_model(apply(rig, params, theta + e))).eigenvalues
        lam_lo = modal_form(build_model(apply(rig, params, theta - e))).eigenvalues
        ref = (lam_hi - lam_lo) / (2 * H)
        assert np.allclose(dlam[k], ref, rtol=0, atol=1e-6 * np.abs(form.eigenvalues).max()), p.name
        col = (_data_residual(tm, rig, params, pr, theta + e)
               - _data_residual(tm, rig, params, pr, theta - e)) / (2 * H)
        assert np.allclose(jac[:, k], col, rtol=0, atol=1e-5 * max(np.abs(col).max(), 1.0)), p.name
