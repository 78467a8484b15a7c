r"""Eq 14 and 15 on one mode's measured complex amplitudes, with standard errors.

From amplitudes to Eq 14/15's inputs
------------------------------------
One damped mode moves every motion X as ``X(t) = Re(x e^{λt})`` (x complex, λ = μ + jω). Eq 14
and 15 (:mod:`ramdaq.analysis.report1836.damping`) want ``v = v1 e^{μt} sin ωt`` and every other
motion as ``X = e^{μt}(X1 sin ωt + X2 cos ωt)``: the time origin moved so that v has no cosine
part. Multiplying every x by ``-j |x_v| / x_v`` does that, and then ``X1 = -Im x``, ``X2 = Re x``
(:meth:`ModeMotions.quadrature`). C and c are homogeneous of degree 0 in the amplitudes, so any
complex factor common to all motions (accelerations instead of displacements, the fit's t = 0,
the anti-alias filter's phase) drops out. The motions come from the gages as in Table 1: v from
gages 2 and 6 (Eq 3a), γ from 4 and 8 (Eq 1), α from 2 and 6 (Eq 2), α_b from 13 and 14 (Eq 8),
γ_b from 5 and 13 (the hull section's yaw), and ``v_b = d13 + (z13 - z_attach) α_b`` at the
stock's hull attachment, ``z_attach = b + ℓ`` (:func:`motions_from_gages`).

Why the measured constants swing
--------------------------------
Eq 14 is ``C = -2 m_y μ + (12 k_s / (v1 ω)) Q`` with the bracket
``Q = v_b2 - h γ2 + b α2 + (ℓ/2)(α2 + α_b2)``. For the ALBACORE-like rig in water (13.0 Hz)
the model's exact mode has, relative to v1: v_b2 = +1.19e-3, -h γ2 = -1.66e-4 (h < 0),
b α2 = -6.49e-4, (ℓ/2) α2 = -2.30e-4, (ℓ/2) α_b2 = +1.96e-5 -- terms worth up to 4.4e4 N s/m
of C each, that cancel to Q/v1 = 1.6e-4: 5.9e3 of the rig's 3.73e4 N s/m (the rest is
``-2 m_y μ``, Eq 16). ``12 k_s/ω`` is 3.7e7 N s/m per unit of Q/v1, so a phase error of
1e-4 rad in α (its cosine part moves by 1e-4 α1 = 4.6e-5 v1, times b + ℓ/2) moves C by
3.6e3 N s/m. Eq 15 divides the same bracket, times h, by γ1 ω with γ1 = 0.12 v1, and adds
the torsion ``(GJ/ℓ_T) γ2 / (γ1 ω)``: c moves |h| v1/γ1 = 3.3 times as far as C (N m s/rad
against N s/m), against a constant ten times smaller.

With the rig's 0.005 m/s² channel noise and its blow (0.65 m/s² at gage 6), 6 s of decay
(``python benchmarks/eq14_15_inputs.py``, 400 draws at the exact pole), the inputs scatter,
relative to v1, by: γ2 7.0e-4 (1.7 times its value; γ's phase 5.8e-3 rad), α2 4.7e-4 (1.1
times; 1.0e-3 rad), v_b2 8.3e-4 (0.7 times), α_b2 5.6e-4 (16 times: gages 13 and 14 are 1.5 m
apart on a hull that hardly tilts), γ_b2 3.4e-4 (5 times); v1, γ1 and α1 to 1e-3 and better.
As phases: v (the time reference) 4e-4 rad, α 8e-4, γ 6e-3, v_b 1.7e-2, α_b 0.45. By gage,
the noise of hull gage 13 (0.02 m/s² of this mode against 0.65 at gage 6: v_b2, the largest
term) and rudder gage 2 (0.24 m/s²: α2) give most of the scatter, then gages 14 and 6.
Eq 14 then scatters by 5.6e4 N s/m (26 % of draws negative) and Eq 15 by 1.8e5 N m s/rad
(50 % negative) about the right means: there is no bias, only noise. The recorded
``c_eq15 = -3.6e5, -4.7e4, -2.5e4`` of ``recordings/albacore-water.mcap`` (s.e. 1.7e5 to
1.8e5) are -2.0, -0.3 and -0.2 standard errors from the rig's 3750, its ``C_eq14 = 1.43e5,
6.4e4, 4.6e4`` (s.e. 5.4e4 to 5.6e4) +1.9, +0.5, +0.2 from 3.73e4. In air (24.5 Hz, the blow
rings 7 times larger) Eq 14 is 1.07e4 +- 0.4e4 (significant, right), Eq 15 still +- 1.3e4
against 503. Eq 16/17 are not
affected: they use only the decrement and α1/γ1.

Standard errors
---------------
Every channel's complex amplitude of the mode is a linear least-squares coefficient at the
fitted poles (the mode table's amplitudes are exactly that): with white noise of standard
deviation σ_c its covariance is ``σ_c² [(Φᵀ Φ)⁻¹]`` for the mode's cosine and sine columns of
the damped basis Φ (all the table's modes and its trend, the record's length and rate), the
other columns projected out -- :func:`amplitude_covariance`, :func:`table_amplitude_covariance`.
σ_c is the fit's residual, times :func:`filtered_noise_factor` (1.13 for the shipped rigs): the
noise passed the anti-alias filter, so the residual's variance understates the noise density
below the corner, where the modes are. Channels' noises are independent. C and c are
propagated to first order (central differences on the real and imaginary part of each gage
amplitude they use). Held fixed, and so left out of the error: the poles (their errors are a
complex factor common to all channels to first order, which drops out: on 12 simulated hits
Eq 14/15 at the fitted and at the exact poles agree within 0.3 % of their s.e.; δ's own s.e.,
5e-5, moves C by 15 N s/m) and the stock constants (ℓ from Figure 8, k_s, GJ from the rig):
on 24 simulated hits in water ℓ's 9 mm scatter moved C by 830 N s/m and c by 2.7e3 N m s/rad
rms, under 2 % of their standard errors.

Checked on the ALBACORE-like rig in water: at the exact pole with white noise (400 draws) the
scatter of C and c is 1.04 and 1.03 times the propagated s.e.; on 200 simulated hits (the
simulator's own noise, filter and ADC; amplitudes at the exact poles, which the chain's equal)
C scatters by 5.41e4 about a mean of 3.54e4 ± 0.38e4 (rig 3.73e4) and c by 1.73e5 about
1.2e4 ± 1.2e4 (rig 3750): 0.99 and 0.97 times the s.e. with the filter's factor (1.12 and 1.10
without it). An estimate within :data:`SIGNIFICANT_SE` standard errors of zero is *not
significant*: :meth:`FullDampingEstimate.notes` says so rather than printing a confident
negative number.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from functools import lru_cache

import numpy as np

from .. import filters
from ..modal.table import ModeTable
from ..modal.varpro import Projector, damped_basis, uniform_grid
from ..model.geometry import gage_geometry
from ..model.rig import Daq, Rig
from .damping import C_translational_full, c_rotational_full, stock_stiffness_k_s
from .motions import geometry_constants

__all__ = [
    "GAGES",
    "ModeMotions",
    "StockConstants",
    "FullDampingEstimate",
    "motions_from_gages",
    "stock_constants",
    "eq14_15",
    "amplitude_covariance",
    "filtered_noise_factor",
    "table_amplitude_covariance",
    "full_damping",
]

GAGES = (2, 4, 5, 6, 8, 13, 14)
"""The gages whose amplitudes Eq 14 and 15 read."""

SIGNIFICANT_SE = 2.0
"""An estimate further than this many standard errors from zero is significant (about 95 %
two-sided for a Gaussian error)."""


@dataclass(frozen=True)
class ModeMotions:
    """One mode's complex amplitudes of the rudder's v (m), γ, α (rad) at its centre of mass and
    of the hull's v_b (m), α_b, γ_b (rad) at the stock's hull attachment, up to a complex factor
    common to all: ``X(t) = Re(x e^{λt})``."""

    v: complex
    gamma: complex
    alpha: complex
    v_b: complex
    alpha_b: complex
    gamma_b: complex

    def quadrature(self) -> tuple[dict[str, float], dict[str, float]]:
        """(sine, cosine) amplitudes of each motion with time turned so that ``v = v1 sin ωt``
        (v1 = |v| > 0, v's cosine amplitude 0): ``X = e^{μt}(X1 sin ωt + X2 cos ωt)``."""
        if self.v == 0:
            raise ValueError("v's amplitude is zero: no time origin puts v = v1 sin(wt)")
        turn = -1j * abs(self.v) / self.v
        turned = {f.name: complex(getattr(self, f.name)) * turn for f in fields(self)}
        return ({k: float(-x.imag) for k, x in turned.items()},
                {k: float(x.real) for k, x in turned.items()})


@dataclass(frozen=True)
class StockConstants:
    """The stock as Eq 62a/b see it: k_s (N/m), the attachment's h and b (m), the bending length
    ℓ (m) and ``GJ_e`` (N m²) such that ``GJ_e/ℓ`` is the torsional stiffness (N m/rad)."""

    k_s: float
    h: float
    b: float
    ell: float
    GJ_e: float


def stock_constants(rig: Rig, ell: float) -> StockConstants:
    """The rig's stock with bending length ``ell`` (m): k_s from EI, κAG and ``ell``; the rig's
    torsion ``GJ/ℓ_T`` written as Eq 62b's ``GJ_e/ℓ`` (``GJ_e = GJ ℓ/ℓ_T``)."""
    st, r = rig.stock, rig.rudder
    k_s = float(stock_stiffness_k_s(st.E_Pa * st.I_m4, st.shear_area_m2 * st.G_Pa, ell))
    return StockConstants(k_s, r.stock_x_m, r.attach_z_m, ell,
                          st.G_Pa * st.J_m4 * ell / st.torsion_length_m)


def motions_from_gages(amp: Mapping[int, complex], rig: Rig, ell: float) -> ModeMotions:
    """The motions of one mode from its complex amplitudes at gages :data:`GAGES` (any one unit
    for all: displacement, or acceleration, which differs by the common factor λ²), with the
    stock's hull attachment ``ell`` (m) above the rudder attachment."""
    return _GageFrame.of(rig, ell).motions(amp)


@dataclass(frozen=True)
class _GageFrame:
    """What :func:`motions_from_gages` reads from the rig (its geometry constants K1-K4, L_P,
    the lever from gage 13 to the stock's attachment, gage 13 to 5 along x, m), once for the
    many evaluations of a standard error's differences."""

    K: Mapping[str, float]
    L_P: float
    lever_13: float
    dx_13_5: float

    @classmethod
    def of(cls, rig: Rig, ell: float) -> _GageFrame:
        geom = gage_geometry(rig)
        p5, p13 = rig.gage(5).position_m, rig.gage(13).position_m
        return cls(geometry_constants(geom), geom.L_P, p13[2] - rig.rudder.attach_z_m - ell,
                   p13[0] - p5[0])

    def motions(self, amp: Mapping[int, complex]) -> ModeMotions:
        missing = [n for n in GAGES if n not in amp]
        if missing:
            raise ValueError(f"Eq 14/15 need gages {GAGES}; missing {missing}")
        K = self.K
        alpha_b = (amp[13] - amp[14]) / self.L_P
        return ModeMotions(
            v=K["K3"] * (amp[2] + K["K4"] * amp[6]),
            gamma=K["K1"] * (amp[4] - amp[8]),
            alpha=K["K2"] * (amp[6] - amp[2]),
            v_b=amp[13] + self.lever_13 * alpha_b,
            alpha_b=alpha_b,
            gamma_b=(amp[13] - amp[5]) / self.dx_13_5,
        )


def eq14_15(m: ModeMotions, f_hz: float, delta: float, m_y: float, I_z: float, I_xz: float,
            stock: StockConstants) -> tuple[float, float]:
    """(C N s/m, c N m s/rad) by Eq 14 and 15 from a mode's motions, its damped frequency
    (Hz) and decrement, the masses m_y (kg), I_z, I_xz (kg m²) and the stock."""
    sin, cos = m.quadrature()
    s = stock
    C = C_translational_full(m_y, f_hz, delta, sin["v"], s.k_s, s.h, s.b, s.ell,
                             v_b2=cos["v_b"], gamma2=cos["gamma"], alpha2=cos["alpha"],
                             alpha_b2=cos["alpha_b"])
    c = c_rotational_full(I_z, I_xz, f_hz, delta, sin["gamma"], sin["alpha"], s.k_s, s.h, s.b,
                          s.ell, s.GJ_e, gamma2=cos["gamma"], alpha2=cos["alpha"],
                          v_b2=cos["v_b"], alpha_b2=cos["alpha_b"], gamma_b1=sin["gamma_b"],
                          gamma_b2=cos["gamma_b"])
    return float(C), float(c)


def amplitude_covariance(n_samples: int, fs_hz: float, f_hz: np.ndarray, delta: np.ndarray,
                         k: int, noise_std: np.ndarray, trend_terms: int = 1) -> np.ndarray:
    """Covariance of mode ``k``'s complex amplitude ``a`` (``y = Re(a e^{λt})``, t = 0 at the
    first sample) at each channel, as ``[Re a, Im a]`` pairs, shape (n_channels, 2, 2) in
    (signal unit)²: the linear least squares at the poles ``f_hz``, ``delta`` (all the modes
    fitted, shape (n_modes,)) with ``trend_terms`` Legendre trend columns, over ``n_samples``
    at ``fs_hz``, and white noise of ``noise_std`` (n_channels,) per channel (NaN: NaN)."""
    t = np.arange(n_samples) / fs_hz
    Phi = damped_basis(t, np.asarray(f_hz, dtype=float), np.asarray(delta, dtype=float),
                       trend_terms, uniform_grid(t))
    flip = np.diag([1.0, -1.0])  # the basis is (e cos, e sin): a = b_cos - j b_sin
    unit = flip @ np.linalg.inv(_schur_complement(Phi, k)) @ flip
    return np.asarray(noise_std, dtype=float)[:, None, None] ** 2 * unit[None, :, :]


def _schur_complement(Phi: np.ndarray, k: int) -> np.ndarray:
    """(2, 2): mode ``k``'s two columns of ``Phi`` (n, P) with every other column projected
    out, R^T R for R = P_perp cols. From the Gram Phi^T Phi (one pass over the samples) while
    its other columns' Cholesky and the complement keep their digits (as varpro's Projector:
    cond below ~1e5, diagonal not cancelled below 1e-8); else from a QR of the others."""
    cols = [2 * k, 2 * k + 1]
    rest = np.delete(np.arange(Phi.shape[1]), cols)
    if rest.size == 0:
        return Phi[:, cols].T @ Phi[:, cols]
    G = Phi.T @ Phi
    G_cc = G[np.ix_(cols, cols)]
    proj = Projector(None, gram=G[np.ix_(rest, rest)])
    if proj.cho is not None:
        V = proj.whitened(G[np.ix_(rest, cols)])
        S = G_cc - V.T @ V
        if (S.diagonal() > 1e-8 * G_cc.diagonal()).all():
            return S
    Q, _ = np.linalg.qr(Phi[:, rest])
    resid = Phi[:, cols] - Q @ (Q.T @ Phi[:, cols])
    return resid.T @ resid


def filtered_noise_factor(daq: Daq, fs_hz: float, f_hz: float) -> float:
    """How far a residual's standard deviation understates the noise at ``f_hz`` when the noise
    passed the anti-alias low-pass of ``daq`` (Butterworth, order and corner, at ``fs_hz``) before
    it was sampled: ``|H(f)| / sqrt(mean |H|² over 0 .. fs/2)`` (1.13 for the shipped rigs'
    800 Hz, 4th order at 2048 Hz). White noise fills the band evenly; filtered, the residual's
    variance holds less than the band's share below the corner, where the modes are."""
    got = _anti_alias_response(daq, float(fs_hz))
    if got is None:
        return 1.0
    sos, rms = got
    _, Hf = filters.sosfreqz(sos, [f_hz], fs_hz)
    return float(abs(Hf[0]) / rms)


@lru_cache(maxsize=16)
def _anti_alias_response(daq: Daq, fs_hz: float) -> tuple[np.ndarray, np.floating] | None:
    """The anti-alias low-pass of ``daq`` at ``fs_hz`` (sos, read-only) and the rms of its
    response over 4096 bins from 0 to fs/2; None where it has none. Cached (read-only values,
    as the module's callers in an analyzer thread need): every hit's final asks for the same
    filter, whose design and response cost ~1.3 ms a hit (the same bits as computed afresh)."""
    sos = daq.anti_alias_sos(fs_hz)
    if sos is None:
        return None
    _, H = filters.sosfreqz(sos, 4096, fs_hz)
    sos.setflags(write=False)
    return sos, np.sqrt(np.mean(np.abs(H) ** 2))


def table_amplitude_covariance(table: ModeTable, k: int, daq: Daq | None = None) -> np.ndarray:
    """:func:`amplitude_covariance` of mode ``k`` of ``table`` at each of its channels: its
    poles, record, trend and per-channel residual noise (the input rate's), scaled by
    :func:`filtered_noise_factor` when the acquisition ``daq`` is given and the table is at its
    sample rate (a resampled record's noise is no longer the filter's)."""
    cov = amplitude_covariance(table.n_samples, table.fs_hz, table.frequency_hz, table.delta,
                               k, table.noise_std, int(table.info.get("trend_terms", 1)))
    if daq is not None and table.fs_hz == daq.sample_rate_hz:
        cov = cov * filtered_noise_factor(daq, table.fs_hz, float(table.frequency_hz[k])) ** 2
    return cov


@dataclass(frozen=True)
class FullDampingEstimate:
    """Eq 14's C (N s/m) and Eq 15's c (N m s/rad) with their standard errors (NaN when no
    amplitude covariance was given), and the stock constants they used."""

    C: float
    C_se: float
    c: float
    c_se: float
    stock: StockConstants

    def significant(self, name: str) -> bool:
        """``name`` ("C" or "c") is further than :data:`SIGNIFICANT_SE` standard errors from
        zero; True when its standard error is unknown (nothing says otherwise)."""
        value, se = (self.C, self.C_se) if name == "C" else (self.c, self.c_se)
        return not np.isfinite(se) or abs(value) > SIGNIFICANT_SE * se

    def notes(self) -> list[str]:
        """One line per constant that is not positive (``not a damping constant``) or not
        significant, with its standard error; none for a significant positive one."""
        out = []
        for name, eq, simple, unit in (("C", 14, 16, "N s/m"), ("c", 15, 17, "N m s/rad")):
            value, se = (self.C, self.C_se) if name == "C" else (self.c, self.c_se)
            said = []
            if not value > 0:  # a dashpot of zero or negative constant is no damping
                said.append("not a damping constant")
            if not self.significant(name):
                said.append(f"not significant (within {SIGNIFICANT_SE:g} s.e. of 0: the "
                            f"motions' small parts out of phase with v that it rests on are "
                            f"lost in the gages' noise)")
            if said:
                pm = f" +- {se:.2g}" if np.isfinite(se) else ""
                out.append(f"Eq {eq}: {name} = {value:.4g}{pm} {unit} (1 s.e.), "
                           f"{', and '.join(said)}; Eq {simple} is the report's reading without "
                           f"the parts out of phase with v")
        return out


def full_damping(amp: Mapping[int, complex], f_hz: float, delta: float, rig: Rig, m_y: float,
                 I_z: float, ell: float,
                 amp_cov: Mapping[int, np.ndarray] | None = None) -> FullDampingEstimate:
    """Eq 14 and 15 on mode amplitudes ``amp`` at gages :data:`GAGES` (complex, one unit), with
    the mode's f (Hz) and decrement, m_y (kg), I_z (kg m², with any added inertia), the rig's
    I_xz and stock, and bending length ``ell`` (m). ``amp_cov``: each gage's (2, 2) covariance
    of ``[Re a, Im a]`` (:func:`amplitude_covariance`), for the standard errors."""
    stock = stock_constants(rig, ell)
    frame = _GageFrame.of(rig, ell)  # the rig's geometry once, not at each of the 29 evaluations

    def constants(a: Mapping[int, complex]) -> np.ndarray:
        return np.array(eq14_15(frame.motions(a), f_hz, delta, m_y, I_z,
                                rig.rudder.Ixz_kg_m2, stock))

    C, c = constants(amp)
    se = np.full(2, np.nan)
    if amp_cov is not None:
        var = np.zeros(2)
        for n in GAGES:
            step = 1e-6 * abs(amp[n]) or 1e-300
            grad = np.empty((2, 2))  # rows (d/d Re a, d/d Im a), columns (C, c)
            for i, unit in enumerate((1.0, 1j)):
                up = constants({**amp, n: amp[n] + unit * step})
                down = constants({**amp, n: amp[n] - unit * step})
                grad[i] = (up - down) / (2 * step)
            var += np.einsum("ia,ij,ja->a", grad, np.asarray(amp_cov[n]), grad)
        se = np.sqrt(var)
    return FullDampingEstimate(float(C), float(se[0]), float(c), float(se[1]), stock)
