"""The simulator the gap diagnosis holds a trial against: the rig's model, its uncertain constants,
and the hooks through which an unmodelled effect switches on.

A prediction of a whole trial is built in four stages, each with a hook for effect terms
(:class:`~ramdaq.analysis.gap.effects.base.Effect`):

1. **rig** -- the nominal rig with the calibrated constants (:func:`apply_base`), then each
   term's change to it (an extra hull mode, a tiller...);
2. **model** -- ``M, C, K`` from :func:`ramdaq.analysis.model.structure.build_model`, then each term's change;
3. **modes** -- the exact modal form: per mode its eigenvalue and its acceleration at every gage
   per newton of ram force, including the anti-alias filter ``H_AA(lambda)`` and the decimation
   low-pass ``|H|^2``; terms may rescale, delay, split or add modes;
4. **signals** -- every impact's response per newton of peak force and its time derivative (exact
   half-sine response, superposed over all later segments, since a blow still rings when the
   next one lands), extra linear columns (a steady tone), and terms acting on signals.

The peak force of every impact and a small onset correction (via the derivative column:
``F u(t - d) ~ F u - F d u'``) are nuisance parameters solved by weighted linear least squares
for each prediction, so nothing the calibration fits is an impact's own force.

Weights are ``1 / sigma_g``, the noise rms of gage ``g`` in the decimated band.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
import scipy.linalg

from ..model.response import half_sine_response, modal_form
from ..model.rig import Rig
from ..model.structure import StructuralModel, build_model
from .trialdata import TrialData, summed_spectrum

if TYPE_CHECKING:
    from .terms import Term


@dataclass(frozen=True)
class BaseParam:
    """A calibrated constant: its value is ``nominal * exp(theta)``; ``prior_sd`` (in theta) is
    how far from nominal the rig's author would believe it, ``bound`` the hard limit on |theta|."""

    name: str
    prior_sd: float
    bound: float
    unit: str


HULL_F_BOUND = math.log(1.5)
"""A hull mode's frequency is calibrated within a factor 1.5 of the rig's (1.35 prior sd): further
off, the model's hull mode would stop being that mode and become another -- a calibration
free to carry it 3x up takes over an unmodelled hull mode's peak and loses its own."""


def base_params(rig: Rig) -> list[BaseParam]:
    """The rig's uncertain constants the calibration fits.

    Stock bending (``I``) and torsion (``J``) stiffness: +-30 % a priori (welds, bearings,
    the stock's taper); damping constants: a factor e (damping is the least known); the added
    mass factor in water +-30 %; the ram's contact time +-50 %; each hull mode's frequency
    +-30 % and damping a factor e.
    """
    p = [BaseParam("stock_EI", 0.3, 1.2, "x nominal"), BaseParam("stock_GJ", 0.3, 1.2, "x nominal"),
         BaseParam("C", 1.0, 3.0, "x nominal"), BaseParam("c", 1.0, 3.0, "x nominal"),
         BaseParam("c_alpha", 1.0, 3.0, "x nominal")]
    if rig.medium == "water":
        p.append(BaseParam("added_mass", 0.3, 1.2, "x nominal"))
    p.append(BaseParam("impact_T", 0.5, 1.5, "x nominal"))
    for k in range(len(rig.hull_modes)):
        p += [BaseParam(f"hull{k + 1}_f", 0.3, HULL_F_BOUND, "x nominal"),
              BaseParam(f"hull{k + 1}_zeta", 1.0, 3.0, "x nominal")]
    return p


def apply_base(rig: Rig, params: list[BaseParam], theta: np.ndarray) -> Rig:
    """The rig with its constants scaled by ``exp(theta)``."""
    v = {p.name: math.exp(t) for p, t in zip(params, theta, strict=True)}
    st = replace(rig.stock, I_m4=rig.stock.I_m4 * v.get("stock_EI", 1.0),
                 J_m4=rig.stock.J_m4 * v.get("stock_GJ", 1.0))
    d = rig.active_damping
    d = replace(d, C_N_s_per_m=d.C_N_s_per_m * v.get("C", 1.0),
                c_N_m_s_per_rad=d.c_N_m_s_per_rad * v.get("c", 1.0),
                c_alpha_N_m_s_per_rad=d.c_alpha_N_m_s_per_rad * v.get("c_alpha", 1.0))
    rud = replace(rig.rudder, added_mass_factor=rig.rudder.added_mass_factor * v.get("added_mass", 1.0))
    imp = replace(rig.impact, duration_s=rig.impact.duration_s * v.get("impact_T", 1.0))
    hull = tuple(replace(h, frequency_hz=h.frequency_hz * v.get(f"hull{k + 1}_f", 1.0),
                         damping_ratio=h.damping_ratio * v.get(f"hull{k + 1}_zeta", 1.0))
                 for k, h in enumerate(rig.hull_modes))
    return replace(rig, stock=st, rudder=rud, impact=imp, hull_modes=hull,
                   damping={**rig.damping, rig.medium: d})


@dataclass
class ModeSet:
    """Modes as the gages see them.

    ``lam`` (m,) eigenvalues 1/s; ``A`` (n_gages, m) complex gage acceleration (m/s^2) per
    newton of peak force per unit of the half-sine response ``J`` (conjugate weight 2 and the
    filters included), so a blow of peak ``F`` gives ``F Re(A J(t))``; ``dof`` (n_dof, m) the
    same for the model's degrees of freedom; ``feed`` (n_gages,) the direct feed-through
    (m/s^2 per N) while the ram pushes; ``exp_only`` (m,) marks terms that start as a plain
    exponential at the onset (a filter's own pole) rather than through ``J``.
    """

    lam: np.ndarray
    A: np.ndarray
    dof: np.ndarray
    feed: np.ndarray
    exp_only: np.ndarray
    model: StructuralModel
    duration_s: float

    @property
    def f_hz(self) -> np.ndarray:
        return self.lam.imag / (2 * math.pi)

    def copy(self) -> ModeSet:
        return replace(self, lam=self.lam.copy(), A=self.A.copy(), dof=self.dof.copy(),
                       feed=self.feed.copy(), exp_only=self.exp_only.copy())


RUNG_OUT = 1e-13
"""A blow's free decay is left out of a later segment (zeros there) when every gage's
acceleration and its rate at that segment's start are bounded by this fraction of the same
bound just after the blow (each mode's term bounded by its modulus; the decay only shrinks it):
at a ram blow's signal-to-noise of 1e4-1e6 that is below 1e-7 of the noise -- the rounding of the
least squares, not data. Blows 30 s apart then cost one segment or two each, not every later one
(time and memory linear in the impacts, not quadratic)."""


def _rung_out(ms: ModeSet, c: np.ndarray, JT: np.ndarray) -> bool:
    """Whether a free decay of modal factors ``c`` (m,) is below :data:`RUNG_OUT` of the blow
    whose factors just after contact are ``JT`` (m,), for the response and its rate."""
    return _RungOut(ms, JT)(c)


class _RungOut:
    """:func:`_rung_out` for one mode set and blow (``JT``), asked of many decays ``c``: what
    does not depend on ``c`` (the moduli, the blow's bound) made once."""

    def __init__(self, ms: ModeSet, JT: np.ndarray) -> None:
        self.A = np.abs(ms.A)
        self.lam = np.abs(ms.lam)
        self.ref = [(self.A @ np.abs(JT)).max(), (self.A @ (np.abs(JT) * self.lam)).max()]

    def __call__(self, c: np.ndarray) -> bool:
        ac = np.abs(c)
        now = [(self.A @ ac).max(), (self.A @ (ac * self.lam)).max()]
        return all(v <= RUNG_OUT * r for v, r in zip(now, self.ref, strict=True))


def _add(blocks: dict, key: tuple[int, int], u: np.ndarray, du: np.ndarray) -> None:
    """Add a response and its derivative to the block ``key`` (taken as it is when first
    written, made contiguous: the same numbers as adding them to zeros). The arrays given must
    not be used elsewhere (they may be added to in place)."""
    if key in blocks:
        blocks[key][0] += u
        blocks[key][1] += du
    else:
        blocks[key] = [np.ascontiguousarray(u, dtype=float), np.ascontiguousarray(du, dtype=float)]


@dataclass
class Fit:
    """A prediction and how it matches the data.

    ``pred`` and ``resid`` (n_seg, n_gages, n_s) m/s^2 (resid NaN where there is no data; both
    None once let go, :meth:`~ramdaq.analysis.gap.calibrate.Calibration.drop_fit_arrays`);
    ``force`` (n_seg,) peak forces N; ``shift_s`` (n_seg,) onset corrections s;
    ``lin`` the extra linear coefficients; ``modes`` the :class:`ModeSet` used.
    """

    pred: np.ndarray | None
    resid: np.ndarray | None
    force: np.ndarray
    shift_s: np.ndarray
    lin: np.ndarray
    modes: ModeSet

    @property
    def rig(self) -> Rig:
        """The rig the prediction was made for (calibrated constants, the terms' changes)."""
        return self.modes.model.rig


class Forward:
    """Predictions of one trial for given constants and effect terms.

    Parameters
    ----------
    td : TrialData
    sigma : ndarray (n_gages,)
        Noise rms of each gage in the decimated band, m/s^2 (the weights).
    """

    def __init__(self, td: TrialData, sigma: np.ndarray) -> None:
        self.td = td
        self.sigma = np.asarray(sigma, dtype=float)
        self.params = base_params(td.rig)
        self.weight = 1.0 / self.sigma
        self.cache: dict = {}
        """What effects compute once per trial (a tone's gage patterns), keyed by the effect."""
        valid = td.valid
        self.mask = valid.copy()
        self.mask[:, :, : td.windows.early.start] = False
        self.mask[:, :, td.windows.pre] = valid[:, :, td.windows.pre]
        self.x0 = np.where(valid, td.x, 0.0)
        self.set_weights(np.broadcast_to(self.weight[None, :, None], td.x.shape))
        self._aa = td.rig.daq.anti_alias_sos(td.fs_full_hz)
        self._k_s = np.arange(td.n_s) / td.fs_hz
        """A segment's sample times from its sample 0, s (n_s,)."""

    def set_weights(self, W: np.ndarray) -> None:
        """Per-sample weights ``1 / sigma_eff`` (n_seg, n_gages, n_s), 1/(m/s^2)."""
        self.W = np.array(W, dtype=float)
        self._w2 = (self.mask * self.W**2).ravel()
        self._spectrum: tuple[np.ndarray, np.ndarray] | None = None

    def decay_spectrum(self) -> tuple[np.ndarray, np.ndarray]:
        """The summed, whitened, Hann-windowed and zero-padded spectrum (frequencies Hz, power)
        of the fitted impacts' decay windows (early window's start to the segment's end), by
        :func:`~ramdaq.analysis.gap.trialdata.summed_spectrum`: made once for these weights
        (the spectrum prefit reads it for every candidate)."""
        if self._spectrum is None:
            td = self.td
            a, b = td.windows.early.start, td.n_s
            r = np.nan_to_num(td.x[td.fitted][:, :, a:b] * self.W[td.fitted][:, :, a:b])
            self._spectrum = summed_spectrum(r, td.fs_hz)
        return self._spectrum

    # -- stages ---------------------------------------------------------------------------
    def rig_for(self, theta: np.ndarray, terms: list[Term] = ()) -> Rig:
        rig = apply_base(self.td.rig, self.params, theta)
        for t in terms:
            rig = t.effect.rig(rig, t)
        return rig

    def modes(self, theta: np.ndarray, terms: list[Term] = ()) -> ModeSet:
        rig = self.rig_for(theta, terms)
        model = build_model(rig)
        for t in terms:
            model = t.effect.model(model, t)
        form = modal_form(model)
        imp = rig.impact
        force = model.force_vector(imp.location_m, imp.direction)
        beta = form.input_vector(force)
        lam = form.eigenvalues
        gain = self._filter_gain(lam)
        scale = form.weights * beta * gain
        n = model.n_dof
        dof = form.right[n:] * lam * scale[None, :]
        A = form.gage_acc * scale[None, :]
        feed = form.feedthrough(force)
        ms = ModeSet(lam, A, dof, feed, np.zeros(len(lam), bool), model, imp.duration_s)
        keep = ms.f_hz < self.td.fs_full_hz / 2
        ms = replace(ms, lam=lam[keep], A=A[:, keep], dof=dof[:, keep], exp_only=ms.exp_only[keep])
        for t in terms:
            ms = t.effect.modes(ms, self, t)
        return ms

    def frequencies(self, theta: np.ndarray, terms: list[Term] = ()) -> np.ndarray:
        """The damped frequencies (Hz) of :meth:`modes` ``(theta, terms).f_hz``, ascending in
        ``|lambda|``: where no term changes the mode set (its ``modes`` hook), only the
        eigen-analysis :func:`~ramdaq.analysis.model.response.modal_form` makes (the same call,
        the same numbers and the same errors), without the gages' and the ram's parts; else
        :meth:`modes` itself. The spectrum prefit asks for nothing else, thousands of times."""
        if any(_own_modes_hook(t.effect) for t in terms):
            return self.modes(theta, terms).f_hz
        rig = self.rig_for(theta, terms)
        model = build_model(rig)
        for t in terms:
            model = t.effect.model(model, t)
        lam, V = scipy.linalg.eig(_state_matrix(model))
        np.linalg.inv(V)        # as modal_form: a singular V fails here as it does there
        keep = np.flatnonzero(lam.imag >= 0)
        lam = lam[keep[np.argsort(np.abs(lam[keep]))]]
        if np.any(np.abs(lam.imag) < 1e-9 * np.abs(lam)):
            raise ValueError("model has an overdamped (real) mode; ram-impact trials expect "
                             "underdamped modes: check the rig's damping")
        f = lam.imag / (2 * math.pi)
        return f[f < self.td.fs_full_hz / 2]

    def _filter_gain(self, lam: np.ndarray) -> np.ndarray:
        g = self.td.lowpass_gain(lam.imag / (2 * math.pi)).astype(complex)
        if self._aa is not None:
            z = np.exp(lam / self.td.fs_full_hz)
            h = np.ones_like(z)
            for b0, b1, b2, a0, a1, a2 in self._aa:
                zi = 1 / z
                h *= (b0 + b1 * zi + b2 * zi**2) / (a0 + a1 * zi + a2 * zi**2)
            g = g * h
        return g

    def unit_responses(self, ms: ModeSet, terms: list[Term] = (),
                       force: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Response of every impact per newton of peak force and its time derivative,
        each (n_imp, n_seg, n_gages, n_s); impact ``j`` is zero before its onset."""
        td = self.td
        U = np.zeros((td.n_seg, td.n_seg, td.n_gages, td.n_s))
        dU = np.zeros(U.shape)   # calloc: pages no pulse writes stay unmapped (zeros_like fills all)
        for (j, s_), (u, du) in self.unit_blocks(ms, terms).items():
            U[j, s_] = u
            dU[j, s_] = du
        for t in terms:
            U, dU = t.effect.units(U, dU, ms, self, force, t)
        return U, dU

    def unit_blocks(self, ms: ModeSet, terms: list[Term] = ()) -> dict[tuple[int, int], list[np.ndarray]]:
        """The blocks of :meth:`unit_responses` a pulse writes, before the terms' ``units`` hooks:
        ``{(impact, segment): [u, du]}``, each (n_gages, n_s); every other block is zero (a blow
        before its segment, or rung out). Summed in the same order as the dense form."""
        td = self.td
        pulses = [(0.0, 1.0)]
        for t in terms:
            pulses += t.effect.pulses(t)
        basis = self.pulse_basis(ms)
        E, JT = basis
        T = ms.duration_s
        out: dict[tuple[int, int], list[np.ndarray]] = {}
        free = []      # (impact, segment, modal factors) of pulses over before the segment began
        rung_out = _RungOut(ms, JT)
        for j in range(td.n_seg):
            for s_ in range(j, td.n_seg):
                for delay, ratio in pulses:
                    d_j = delay[j] if np.ndim(delay) else delay      # one per impact, or shared
                    tau0 = td.seg_t0_s[s_] - td.onsets_s[j] - d_j   # time of sample 0 after contact
                    if tau0 + (td.n_s - 1) / td.fs_hz <= 0:
                        continue
                    if tau0 >= T:
                        lag = np.where(ms.exp_only, tau0, tau0 - T)
                        c = ratio * JT * np.exp(ms.lam * lag)
                        if s_ > j and rung_out(c):
                            continue       # a blow rung out before a later segment: exact zeros
                        free.append((j, s_, c))
                        continue
                    u, du = self.pulse_response(ms, tau0, basis)
                    _add(out, (j, s_), u if ratio == 1.0 else ratio * u,
                         du if ratio == 1.0 else ratio * du)
        if free:
            # a free decay is A diag(c) e^{lambda k dt}: all of them in one product
            C = np.stack([c for _, _, c in free])                         # (P, m)
            AC = ms.A[None, :, :] * C[:, None, :]                          # (P, g, m)
            AC = np.concatenate([AC, AC * ms.lam]).reshape(-1, len(ms.lam))
            # only the real part is wanted: Re(a) Re(E) - Im(a) Im(E), one real product
            X = np.hstack([AC.real, -AC.imag]) @ np.vstack([E.real, E.imag])
            X = X.reshape(2, len(free), td.n_gages, td.n_s)
            for p_, (j, s_, _) in enumerate(free):
                _add(out, (j, s_), X[0, p_], X[1, p_])
        return out

    def pulse_basis(self, ms: ModeSet) -> tuple[np.ndarray, np.ndarray]:
        """What every pulse of a mode set shares: ``e^{lambda k dt}`` on a segment's grid
        (m, n_s) and each mode's state at the end of a contact ``J(T)`` (m,)."""
        k = np.arange(self.td.n_s) / self.td.fs_hz
        E = np.exp(ms.lam[:, None] * k[None, :])
        JT = half_sine_response(ms.lam, ms.duration_s, np.array([ms.duration_s]))[:, 0]
        return E, np.where(ms.exp_only, 1.0, JT)

    def pulse_response(self, ms: ModeSet, tau0: float,
                       basis: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """One half-sine contact of unit peak force at every gage on a segment's grid whose
        sample 0 is ``tau0`` s after the contact began, and its time derivative, (n_gages, n_s).

        After the ram lets go a mode is ``J(T) e^{lambda (t - T)}``: on the uniform grid that is
        one complex factor per mode times ``e^{lambda k dt}``; only the few samples inside a
        contact use the closed form of :func:`half_sine_response`."""
        E, JT = basis if basis is not None else self.pulse_basis(ms)
        lam, T = ms.lam, ms.duration_s
        lag = np.where(ms.exp_only, tau0, tau0 - T)
        # valid for t >= T (and t >= 0 where exp_only); a sample before then is overwritten
        # below, so a mode whose factor for sample 0 would overflow (a strongly damped one long
        # before its contact) starts from its first valid sample: e^{lambda (lag + k0 dt)} E[k - k0]
        n_s, fs = self.td.n_s, self.td.fs_hz
        k0 = np.ceil(np.maximum(-lag, 0.0) * fs).astype(int)
        Z = (JT * np.exp(lam * (lag + k0 / fs)))[:, None] * E
        t = tau0 + self._k_s
        # t rises: the samples before the contact (t <= 0) and those during it (0 < t < T) are
        # the first n0 and the next n1 - n0
        n0, n1 = int(np.count_nonzero(t <= 0)), int(np.count_nonzero(t < T))
        if k0.any():
            for v in np.unique(k0[(k0 > 0) & (k0 < n_s)]):   # one shift per kind of mode
                rows = k0 == v
                Z[rows, v:] = Z[rows, :n_s - v]
            # samples before k0 are set below -- to 0 before the contact, to J(t) during it
            # (exp_only: kept) -- but for a rounding edge, where t and lag disagree by an ulp:
            # only those are computed from the closed form (what is set below is the first
            # ``first`` samples)
            first = np.where(ms.exp_only, n0, n1)
            for m in np.flatnonzero(first < np.minimum(k0, n_s)):
                kk = np.arange(first[m], min(k0[m], n_s))
                with np.errstate(over="ignore", invalid="ignore"):
                    Z[m, kk] = JT[m] * np.exp(lam[m] * (lag[m] + kk / fs))
        Z[:, :n0] = 0.0
        if n1 > n0:
            Jd = half_sine_response(lam, T, t[n0:n1])
            Z[:, n0:n1] = np.where(ms.exp_only[:, None], Z[:, n0:n1], Jd)
        # Re(A Z) and Re(A lam Z) as one real product: [Re A, -Im A] [Re Z, Re lam Z; Im Z, Im lam Z]
        # (the complex products' imaginary halves were made and thrown away)
        LZ = lam[:, None] * Z
        m = len(lam)
        S = np.empty((2 * m, 2 * n_s))
        S[:m, :n_s], S[m:, :n_s] = Z.real, Z.imag
        S[:m, n_s:], S[m:, n_s:] = LZ.real, LZ.imag
        ud = np.hstack([ms.A.real, -ms.A.imag]) @ S
        u, du = ud[:, :n_s], ud[:, n_s:]
        if n1 > n0:
            f = np.sin(math.pi / T * t[n0:n1])
            u[:, n0:n1] += ms.feed[:, None] * f[None, :]
            du[:, n0:n1] += np.real(ms.A[:, ~ms.exp_only] @ np.broadcast_to(
                f, (int((~ms.exp_only).sum()), f.size)))
        return u, du

    def mode_unit(self, ms: ModeSet, i: int, j: int) -> np.ndarray:
        """Mode ``i``'s part of impact ``j``'s unit response after the contact,
        (n_seg, n_gages, n_s); zero before ``onset + T``."""
        td = self.td
        lam, T = ms.lam[i], ms.duration_s
        t = td.seg_t0_s[:, None] + np.arange(td.n_s)[None, :] / td.fs_hz - td.onsets_s[j]
        JT = 1.0 if ms.exp_only[i] else half_sine_response(np.array([lam]), T, np.array([T]))[0, 0]
        lag = t if ms.exp_only[i] else t - T
        z = np.where(lag >= 0, JT * np.exp(lam * np.maximum(lag, 0)), 0.0)
        return np.real(ms.A[:, i][None, :, None] * z[:, None, :])

    def columns(self, terms: list[Term]) -> np.ndarray | None:
        """The terms' own linear columns, (k, n_seg, n_gages, n_s), or None."""
        cols = [c for t in terms if (c := t.effect.columns(self, t)) is not None]
        return np.concatenate(cols) if cols else None

    # -- the prediction -------------------------------------------------------------------
    def fit(self, theta: np.ndarray, terms: list[Term] = (), *, x: np.ndarray | None = None,
            modes: ModeSet | None = None) -> Fit:
        """Predict the trial and solve every impact's force (and onset shift) and the terms'
        linear coefficients by weighted least squares against ``x`` (default: the data)."""
        ms = modes if modes is not None else self.modes(theta, terms)
        needs_force = any(t.effect.needs_force for t in terms)
        extra = self.columns(list(terms))
        data = self.x0 if x is None else np.where(self.td.valid, x, 0.0)
        if any(t.effect.changes_units() for t in terms):
            design = self.unit_design(ms, terms, extra)
            coef, pred = design.solve(data)
            if needs_force:     # the first design let go before the second is made
                del design
                design = self.unit_design(ms, terms, extra, force=coef[: self.td.n_seg])
                coef, pred = design.solve(data)
            del design
        else:     # no term changes the unit responses: only the blocks a pulse writes are made
            coef, pred = self.block_design(self.unit_blocks(ms, terms), extra, consume=True,
                                           data=data).solve(data)
        mask = self.mask
        for t in terms:
            pred, m = t.effect.output(pred, self, t)
            if m is not None:
                mask = mask & m
        n = self.td.n_seg
        force = coef[:n]
        shift = -coef[n: 2 * n] / np.where(force != 0, force, 1.0)
        src = self.td.x if x is None else x
        resid = np.where(mask, src - pred, np.nan)
        return Fit(pred, resid, force, shift, coef[2 * n:], ms)

    def unit_design(self, ms: ModeSet, terms: list[Term], extra: np.ndarray | None,
                    force: np.ndarray | None = None) -> Design:
        """The linear design of the impacts' unit responses as the terms change them (their
        ``units`` hooks, at the impacts' ``force`` where given): from the blocks a pulse writes
        when every such term can change those (``units_on_blocks``; the blocks let go segment
        by segment as the design takes their rows), else from the dense unit responses -- the
        same numbers. A friction term's dense form was (n_imp, n_seg, n_g, n_s) touched whole,
        75 MB at 20 impacts, beside the design made of it."""
        blocks = self.term_blocks(ms, terms, force)
        if blocks is not None:
            return self.block_design(blocks, extra, consume=True)
        U, dU = self.unit_responses(ms, terms, force=force)
        return self.linear_design(U, dU, extra)

    def term_blocks(self, ms: ModeSet, terms: list[Term] = (),
                    force: np.ndarray | None = None) -> dict[tuple[int, int], list[np.ndarray]] | None:
        """:meth:`unit_blocks` with the terms' changes of the unit responses made on them
        (``units_on_blocks``, at the impacts' ``force`` where given): the blocks of
        :meth:`unit_responses` (segment >= impact; every other block zero); None when a term
        has no block form."""
        blocks = self.unit_blocks(ms, terms)
        if all(t.effect.units_on_blocks(blocks, ms, self, force, t) for t in terms
               if t.effect.changes_units()):
            return blocks
        return None

    def segment_columns(self, blocks: dict[tuple[int, int], list[np.ndarray]], extra: np.ndarray | None,
                        s: int, *, consume: bool = False) -> tuple[list[int], np.ndarray]:
        """:meth:`alive_columns` of segment ``s`` from blocks (:meth:`term_blocks`); with
        ``consume`` the segment's blocks are taken out of ``blocks``."""
        take = blocks.pop if consume else blocks.get
        return _segment_columns(self.td.n_seg, self.td.n_gages * self.td.n_s, s,
                                lambda j: take((j, s), None), extra)

    def design(self, U: np.ndarray, dU: np.ndarray, extra: np.ndarray | None) -> np.ndarray:
        """The linear columns (forces, onset shifts, terms' own), (n_cols, n_seg, n_g, n_s)."""
        cols = [U[j] for j in range(U.shape[0])] + [dU[j] for j in range(U.shape[0])]
        if extra is not None:
            cols += list(extra)
        return np.stack(cols)

    def linear_design(self, U, dU, extra) -> Design:
        """The linear columns ``U``, ``dU``, ``extra`` block by block (:class:`Design`): built
        once, solved against as many data as wanted (the replicates re-solve the same design)."""
        n = U.shape[0]
        e = 0 if extra is None else extra.shape[0]
        blocks = [self.alive_columns(U, dU, extra, s) for s in range(self.td.n_seg)]
        return Design(blocks, 2 * n + e, self._w2.reshape(self.td.n_seg, -1))

    def block_design(self, blocks: dict[tuple[int, int], list[np.ndarray]],
                     extra: np.ndarray | None, *, consume: bool = False,
                     data: np.ndarray | None = None) -> Design:
        """:meth:`linear_design` from the blocks of :meth:`unit_blocks` (the same columns, rows
        and numbers as from the dense unit responses they fill); with ``consume`` each block is
        taken out of ``blocks`` as its segment's rows are made (no second copy of them all);
        ``data`` the data it will be solved against first (see :class:`Design`)."""
        n = self.td.n_seg
        take = blocks.pop if consume else blocks.get
        segs = [_segment_columns(n, self.td.n_gages * self.td.n_s, s,
                                 lambda j, s=s: take((j, s), None), extra) for s in range(n)]
        return Design(segs, 2 * n + (0 if extra is None else extra.shape[0]),
                      self._w2.reshape(n, -1), data=data)

    def alive_columns(self, U, dU, extra, s: int) -> tuple[list[int], np.ndarray]:
        """The linear columns alive in segment ``s`` -- impacts 0 .. s, their derivatives, the
        terms' columns not zero there -- as their indices and rows (k, n_gages * n_s)."""
        return _segment_columns(U.shape[0], U.shape[2] * U.shape[3], s,
                                lambda j: (U[j, s], dU[j, s]), extra)

    def whitened(self, fit: Fit, segments: np.ndarray | None = None) -> np.ndarray:
        """Residual divided by each gage's sigma, flattened, over ``segments`` (default all);
        samples not compared are 0, so the length never changes."""
        if segments is None:
            r = fit.resid * self.W
        else:        # the segments first: the same products, fewer of them
            r = fit.resid[segments] * self.W[segments]
        return np.nan_to_num(r.ravel(), nan=0.0, copy=False)


def _own_modes_hook(effect: object) -> bool:
    """Whether an effect's class changes the mode set: a ``modes`` hook of its own over the
    base's (which returns the mode set as it is) -- the classes defining ``modes`` in its
    method order are more than the base alone (the core imports no effect)."""
    defs = [c for c in type(effect).__mro__ if "modes" in vars(c)]
    return len(defs) > 1


def _state_matrix(model: StructuralModel) -> np.ndarray:
    """:func:`~ramdaq.analysis.model.response.state_matrix` made by the same operations into
    one array (no ``np.block``: its bookkeeping was a tenth of the spectrum prefit's call)."""
    n = model.n_dof
    Minv = np.linalg.inv(model.M)
    A = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    A[n:, :n] = -Minv @ model.K
    A[n:, n:] = -Minv @ model.C
    return A


def _nonzero(block: tuple[np.ndarray, np.ndarray]) -> bool:
    """Whether a unit response or its derivative (each (n_gages, n_s)) is not all zero: the
    first sample of every gage asked first (a decay is largest there), the whole only if those
    are all zero -- the same answer, mostly without reading the block."""
    u, du = block
    return bool(u[:, 0].any() or du[:, 0].any() or u.any() or du.any())


def _segment_columns(n: int, L: int, s: int,
                     unit: Callable[[int], tuple[np.ndarray, np.ndarray] | None],
                     extra: np.ndarray | None) -> tuple[list[int], np.ndarray]:
    """The linear columns alive in segment ``s`` of ``n`` impacts: impact ``j``'s unit response
    and its derivative there (``unit(j)``: the pair, each (n_gages, n_s); None where no pulse
    wrote them, all zero), alive for j = s and for an earlier impact not rung out before it
    (not all zero); the terms' columns ``extra`` not zero there. Their indices (impacts, their
    derivatives after the ``n`` impacts, the terms' after those) and rows (k, ``L``)."""
    e = 0 if extra is None else extra.shape[0]
    units = {j: unit(j) for j in range(min(s + 1, n))}
    live = [j for j, b in units.items() if j == s or (b is not None and _nonzero(b))]
    a = len(live)
    live_e = [] if extra is None else [i for i in range(e) if extra[i, s].any()]
    idx = live + [n + j for j in live] + [2 * n + i for i in live_e]
    X = np.empty((len(idx), L))     # every row written below (no pass of zeros first)
    for k, j in enumerate(live):
        if units[j] is not None:
            X[k] = units[j][0].ravel()
            X[a + k] = units[j][1].ravel()
        else:
            X[k] = X[a + k] = 0.0
    if live_e:
        X[2 * a:] = extra[live_e, s].reshape(len(live_e), -1)
    return idx, X


class Design:
    """The linear columns of a prediction (every impact's unit response, its derivative, the
    terms' own columns) held segment by segment: impact ``j`` is zero before segment ``j`` and a
    term's column may live in one segment only, so each segment holds just the columns alive
    there -- ``blocks[s] = (indices, rows (k, n_gages * n_s))`` -- and the weighted normal
    equations are summed segment by segment (made once: the replicates solve many data against
    one design). ``w2`` (n_seg, n_gages * n_s) the squared weights, zero where not compared;
    the rows times them are made segment by segment where they are used, never all kept (they
    were as large as the rows: 75 MB for a friction term's dense responses over 20 impacts).
    With ``data`` (n_seg, n_gages, n_s) given, its right-hand side is summed in the same pass as
    the normal equations, the weighted rows made once for both (a prediction solves its design
    once): :meth:`solve` of that same array then uses it, the same numbers."""

    def __init__(self, blocks: list[tuple[list[int], np.ndarray]], n_cols: int, w2: np.ndarray,
                 data: np.ndarray | None = None) -> None:
        self.blocks = blocks
        self.n_cols = n_cols
        self.w2 = w2
        G = np.zeros((n_cols, n_cols))
        b = None if data is None else np.zeros(n_cols)
        buf = np.empty((max((len(idx) for idx, _ in blocks), default=0), w2.shape[1]))
        for s, (idx, X) in enumerate(blocks):
            XW = np.multiply(X, w2[s], out=buf[: len(idx)])  # (one buffer for every segment's)
            G[np.ix_(idx, idx)] += XW @ X.T
            if b is not None:
                b[idx] += XW @ data[s].ravel()
        self._first = None if b is None else (data, b)
        self.scale = np.sqrt(np.maximum(np.diag(G), 1e-300))
        self.Gs = G / self.scale[:, None] / self.scale[None, :]

    def solve(self, data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The coefficients fitted to ``data`` (n_seg, n_gages, n_s; zeros where there is none)
        by weighted least squares, and the prediction they make (same shape)."""
        if self._first is not None and self._first[0] is data:
            b, self._first = self._first[1], None
        else:
            b = np.zeros(self.n_cols)
            for s, (idx, X) in enumerate(self.blocks):
                b[idx] += (X * self.w2[s]) @ data[s].ravel()
        coef = np.linalg.lstsq(self.Gs, b / self.scale, rcond=1e-10)[0] / self.scale
        pred = np.empty_like(data)
        for s, (idx, X) in enumerate(self.blocks):
            pred[s] = (coef[idx] @ X).reshape(data.shape[1:])
        return coef, pred
