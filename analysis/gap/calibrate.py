"""Calibration: the nominal model's uncertain constants fitted to the trial's fitted impacts, so
that what is left is the model's form, not a mistuned constant.

Maximum a posteriori: the whitened residual of the fitted impacts (pre and decay windows) plus
the constants' Gaussian priors (:func:`~ramdaq.analysis.gap.forward.base_params`), minimised by
this module's own bounded Levenberg-Marquardt (:func:`levenberg_marquardt`: Broyden updates of
the Jacobian, steps capped in length), which says how it stopped (:class:`Stop`). Only the
spectrum prefit (:func:`prefit_frequencies`) uses ``scipy.optimize.least_squares``. Each
prediction re-solves every impact's force and onset shift (linear), so the calibration never
sees them as parameters. The held-out impacts enter only through their own forces.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from enum import StrEnum
from typing import IO

import numpy as np

from .. import filters
from .forward import Fit, Forward
from .terms import Term


class Stop(StrEnum):
    """How a :func:`levenberg_marquardt` run ended. Only ``CONVERGED`` is convergence."""

    CONVERGED = "converged"
    """The cost fell by less than ``tol`` (relative) on a freshly differenced Jacobian."""
    GAVE_UP = "gave up"
    """Six failed steps in a row, or the damping beyond 1e8: no proposed step lowered the
    cost. The point is where the solver stopped, not a minimum shown to be one."""
    ITERATION_LIMIT = "iteration limit"
    """``max_iter`` steps taken without converging."""
    AT_BOUNDS = "stopped at the bounds"
    """The bounds cut the step to nothing."""
    SCREENED = "brief refit ended"
    """A brief refit (``refresh=False``) ended on a step that gained less than its tolerance on
    a Broyden Jacobian: where it got ranks a start; it is not shown to be a minimum."""
    NOTHING_TO_FIT = "nothing to fit"
    """No free parameter (the terms' parameters alone were to be fitted, and they have none)."""


@dataclass
class Calibration:
    """Result of a (re)fit: base constants ``theta`` (log multipliers), the terms with their
    fitted parameters, the fit, ``chi2`` (sum of squared whitened residuals of the fitted
    impacts, priors excluded), ``prior`` (the prior's part of the cost, x2), ``jac`` the data
    rows of the Jacobian of the whitened residual in the base constants then the terms'
    parameters (None once let go: :meth:`drop_jacobian`), ``n_params``, ``nfev`` the
    predictions it took, ``stop`` how the solver ended (giving up is not convergence)."""

    theta: np.ndarray
    terms: list[Term]
    fit: Fit
    chi2: float
    prior: float
    jac: np.ndarray | None
    n_params: int
    nfev: int
    stop: Stop
    cache: dict = field(default_factory=dict)
    parked: IO[bytes] | None = field(default=None, repr=False)
    """The unnamed temporary file the Jacobian is parked in (:meth:`park_jacobian`), or None."""

    @property
    def cost(self) -> float:
        """What the fit minimised: ``chi2 + prior``."""
        return self.chi2 + self.prior

    def drop_jacobian(self) -> None:
        """Let the Jacobian go (it is N x p, 40 MB for 20 impacts, and a judged candidate of
        a search needs it no more); a score basis asked of this calibration then refuses."""
        self.jac = None
        if self.parked is not None:
            self.parked.close()
            self.parked = None

    def park_jacobian(self) -> None:
        """Move the Jacobian out of memory into an unnamed temporary file (gone when closed),
        while it is not read: N x p, 24 MB for 20 impacts of 9 constants, 76 MB with a double
        hit's 20 delays, and a search holds the calibration's, the best refit's and the one
        being made at once. :meth:`jacobian` reads it back, :meth:`unpark_jacobian` holds it
        again -- the same numbers to the last bit (``np.save``/``np.load``). Where no temporary
        file can be written (no space, no writable temporary folder) it stays in memory: the
        diagnosis is the same, only its peak memory is not lowered."""
        if self.jac is None:
            return
        try:
            f = tempfile.TemporaryFile()
            np.save(f, self.jac, allow_pickle=False)
        except OSError:
            return
        self.parked, self.jac = f, None

    def jacobian(self) -> np.ndarray | None:
        """The Jacobian, read back from its file when parked (a copy for the caller, not
        kept); None once let go."""
        if self.jac is not None or self.parked is None:
            return self.jac
        self.parked.seek(0)
        return np.load(self.parked, allow_pickle=False)

    def unpark_jacobian(self) -> None:
        """Hold the parked Jacobian in memory again (:attr:`jac`), its file closed."""
        if self.parked is not None:
            jac = self.jacobian()
            self.drop_jacobian()
            self.jac = jac

    def drop_fit_arrays(self) -> None:
        """Let the prediction and residual go (``fit.pred``, ``fit.resid`` None; (n_seg, n_g,
        n_s) each, 3.6 MB each at 20 impacts): a search's candidate no longer read until it is
        named. :meth:`restore_fit` makes them again, the same to the last bit."""
        if self.fit.pred is not None:
            self.fit = replace(self.fit, pred=None, resid=None)

    def restore_fit(self, fw: Forward) -> None:
        """The prediction and residual let go by :meth:`drop_fit_arrays` made again (one
        prediction of ``fw``, the forward model this calibration was fitted with)."""
        if self.fit.pred is None:
            self.fit = fw.fit(self.theta, self.terms)

    def columns(self, fw: Forward) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """The linear columns of this calibration's prediction -- every impact's unit response,
        its time derivative, the terms' own columns (see :meth:`Forward.fit`). Computed anew at
        each call, not kept: they are (n_seg, n_seg, n_g, n_s) each, 150 MB for 20 impacts, and
        every candidate of a search holds its calibration (one prediction's work to remake)."""
        needs_force = any(t.effect.needs_force for t in self.terms)
        U, dU = fw.unit_responses(self.fit.modes, self.terms,
                                  force=self.fit.force if needs_force else None)
        return U, dU, fw.columns(self.terms)

    def blocks(self, fw: Forward) -> dict[tuple[int, int], list[np.ndarray]] | None:
        """The unit responses and derivatives of :meth:`columns` as the blocks they are not zero
        in (:meth:`Forward.term_blocks`), or None when a term has no block form."""
        needs_force = any(t.effect.needs_force for t in self.terms)
        return fw.term_blocks(self.fit.modes, self.terms, force=self.fit.force if needs_force else None)

    def pred_rate(self, fw: Forward) -> np.ndarray:
        """Time derivative of the prediction, (n_seg, n_g, n_s), m/s^3 (cached): ``force . dU``
        over the impacts, segment by segment from :meth:`blocks` (each segment's (n_imp, n_g *
        n_s) rows, zeros where no block is: the numbers of the dense product, whose unit
        responses were made whole), the dense form when a term has no blocks."""
        if "pred_rate" not in self.cache:
            blocks = self.blocks(fw)
            if blocks is None:
                self.cache["pred_rate"] = np.tensordot(self.fit.force, self.columns(fw)[1], axes=1)
                return self.cache["pred_rate"]
            td = fw.td
            out = np.empty(td.x.shape)
            D = np.zeros((td.n_seg, td.n_gages * td.n_s))
            for s in range(td.n_seg):
                D[:] = 0.0
                for j in range(s + 1):
                    if (b := blocks.pop((j, s), None)) is not None:
                        D[j] = b[1].ravel()
                out[s] = (self.fit.force @ D).reshape(td.n_gages, td.n_s)
            self.cache["pred_rate"] = out
        return self.cache["pred_rate"]


def _pack(fw: Forward, terms: list[Term]):
    sd = np.array([p.prior_sd for p in fw.params])
    bd = np.array([p.bound for p in fw.params])
    lo = [-bd] + [t.placement.lo for t in terms]
    hi = [bd] + [t.placement.hi for t in terms]
    return sd, np.concatenate(lo), np.concatenate(hi)


def calibrate(fw: Forward, terms: list[Term] = (), *, theta0: np.ndarray | None = None,
              max_iter: int = 60, free_base: bool = True, jac0: np.ndarray | None = None,
              fit0: Fit | None = None, refresh: bool = True) -> Calibration:
    """Fit the base constants (and the terms' parameters) to the fitted impacts.

    ``terms`` carry their start values in ``Term.x``; ``free_base=False`` keeps ``theta0``
    fixed and fits the terms alone (quicker, for screening). ``jac0``, the data rows of an
    earlier calibration's Jacobian in the base constants, saves recomputing them: only the
    terms' columns are differenced. ``fit0``, the prediction at the start (``theta0``, the
    terms' ``x``) when it was made already (a fit of the terms alone ends there), is not made
    again: the same numbers (unused when the start had to be moved inside the bounds).
    ``refresh=False``: a brief refit that ranks starts (:func:`levenberg_marquardt`'s).
    """
    terms = list(terms)
    n_b = len(fw.params)
    theta0 = prefit_frequencies(fw) if theta0 is None else np.asarray(theta0, float)
    sd, lo, hi = _pack(fw, terms)
    sizes = [len(t.x) for t in terms]
    fitted = np.flatnonzero(fw.td.fitted)

    def unpack(p: np.ndarray) -> tuple[np.ndarray, list[Term]]:
        th = p[:n_b] if free_base else theta0
        out, i = [], n_b if free_base else 0
        for t, k in zip(terms, sizes, strict=True):
            out.append(t.with_x(p[i:i + k]))
            i += k
        return th, out

    last: dict[bytes, Fit] = {}     # the latest prediction: the solver mostly ends on it
    known: dict[bytes, Fit] = {}    # the start's prediction, when given (fit0)

    def residual(p: np.ndarray) -> np.ndarray:
        th, ts = unpack(p)
        fit = known.pop(p.tobytes(), None) or fw.fit(th, ts)
        last.clear()
        last[p.tobytes()] = fit
        r = fw.whitened(fit, fitted)
        return np.concatenate([r, th / sd]) if free_base else r

    x_start = np.concatenate(([theta0] if free_base else []) + [t.x for t in terms])
    lo_, hi_ = (lo, hi) if free_base else (lo[n_b:], hi[n_b:])
    inside = np.clip(x_start, lo_ + 1e-9 * (hi_ - lo_), hi_ - 1e-9 * (hi_ - lo_))
    if fit0 is not None and fit0.resid is not None and np.array_equal(inside, x_start):
        known[x_start.tobytes()] = fit0
    x_start = inside
    if len(x_start) == 0:
        fit = fw.fit(theta0, terms)
        r = fw.whitened(fit, fitted)
        return Calibration(theta0, terms, fit, chi2=float(r @ r), prior=0.0, jac=np.zeros((len(r), 0)),
                           n_params=0, nfev=1, stop=Stop.NOTHING_TO_FIT)
    x_scale = np.concatenate(([sd] if free_base else []) + [(t.placement.hi - t.placement.lo) / 10
                                                             for t in terms])
    J0 = None
    if jac0 is not None and free_base:
        J0 = np.zeros((len(jac0) + n_b, len(x_start)))
        J0[: len(jac0), :n_b] = jac0[:, :n_b]
        J0[len(jac0):, :n_b] = np.diag(1 / sd)
    del jac0        # copied: a caller's temporary (a reweighted Jacobian, N x p) goes now
    res = levenberg_marquardt(residual, x_start, lo_, hi_, x_scale, max_iter=max_iter, J0=J0,
                              refresh=refresh)
    th, ts = unpack(res.x)
    fit = last.pop(res.x.tobytes(), None) or fw.fit(th, ts)
    r = fw.whitened(fit, fitted)
    n_data = len(r)
    jac = res.jac[:n_data] if free_base else np.zeros((n_data, 0))
    prior = float(np.sum((th / sd) ** 2)) if free_base else 0.0
    return Calibration(th, ts, fit, chi2=float(r @ r), prior=prior, jac=np.asarray(jac),
                       n_params=len(res.x), nfev=res.nfev, stop=res.stop)


def spectrum_peaks(fw: Forward, f_guess: np.ndarray, *, rel: float = 0.35,
                   prominence: float = 20.0) -> np.ndarray:
    """Where the data's decays actually ring near each of ``f_guess`` (Hz, ascending): the peak
    of the summed, whitened, Hann-windowed and zero-padded spectrum of the fitted impacts'
    decay windows within +-``rel`` and no nearer a neighbouring guess than the geometric mean
    of the two (a stiffness error of a factor two moves a mode 30 %; the neighbour's peak is
    the neighbour's), interpolated (parabola on log power); NaN where no peak stands
    ``prominence`` times above the median of that range."""
    f, P = fw.decay_spectrum()
    out = np.full(len(f_guess), np.nan)
    g = np.asarray(f_guess, float)
    for k, fg in enumerate(g):
        lo = max([fg * (1 - rel)] + [np.sqrt(fg * x) for x in g if x < fg])
        hi = min([fg * (1 + rel)] + [np.sqrt(fg * x) for x in g if x > fg])
        sel = np.flatnonzero((f > lo) & (f < hi))
        if len(sel) < 5:
            continue
        i = sel[np.argmax(P[sel])]
        if i in (sel[0], sel[-1]) or P[i] < prominence * np.median(P[sel]):
            continue
        out[k] = filters.log_parabola_peak(f, P, i)
    return out


def prefit_frequencies(fw: Forward, theta0: np.ndarray | None = None, terms: list[Term] = (), *,
                       max_nfev: int = 200) -> np.ndarray:
    """Base constants moved so the model's modes ring where the data's do.

    A time-domain fit cannot find a frequency off by more than about one cycle over the decay
    (4 % of a 24 Hz mode over 4 s is four cycles): it would settle in a wrong valley. So the
    stiffness-like constants (stock bending and torsion, hull frequencies, added mass) are
    first fitted to the spectrum peaks of the data (log frequency, with the same priors); the
    time-domain calibration starts from there.

    With ``terms`` (an effect that changes the structure, e.g. adds a mode) the peaks are still
    those near the base model's modes, each matched to the nearest mode of the model with the
    terms on.
    """
    theta0 = np.zeros(len(fw.params)) if theta0 is None else np.asarray(theta0, float)
    ms = fw.modes(theta0)
    f0 = ms.f_hz
    comp = np.flatnonzero((f0 > 0) & (f0 < fw.td.lowpass_hz))
    f_obs = spectrum_peaks(fw, f0[comp])
    ok = np.isfinite(f_obs)
    if not ok.any():
        return theta0
    free = [i for i, p in enumerate(fw.params) if p.name in ("stock_EI", "stock_GJ", "added_mass")
            or (p.name.startswith("hull") and p.name.endswith("_f"))]
    sd = np.array([fw.params[i].prior_sd for i in free])
    bd = np.array([fw.params[i].bound for i in free])

    def resid(v: np.ndarray) -> np.ndarray:
        th = theta0.copy()
        th[free] = v
        try:
            f = fw.frequencies(th, terms)
        except (ValueError, np.linalg.LinAlgError):
            return np.full(ok.sum() + len(v), 1e3)
        f = f[f > 0]
        if terms:
            fm = np.full(len(comp), np.nan)
            fm[ok] = f[np.argmin(np.abs(np.log(f[None, :] / f_obs[ok][:, None])), axis=1)]
        else:   # each mode keeps its place in frequency order
            fm = f[comp] if len(f) > comp.max() else np.full(len(comp), np.nan)
        r = np.log(fm[ok] / f_obs[ok]) / 1e-3     # frequencies read to ~0.1 %
        return np.concatenate([np.nan_to_num(r, nan=1e3), v / sd])

    import scipy.optimize
    res = scipy.optimize.least_squares(resid, theta0[free], bounds=(-bd, bd), method="trf",
                                       x_scale=sd, max_nfev=max_nfev)
    th = theta0.copy()
    th[free] = res.x
    return th


@dataclass
class LMResult:
    """Where :func:`levenberg_marquardt` ended: ``x``, the Jacobian ``jac`` there (Broyden-updated
    unless just differenced), ``nfev`` evaluations of ``fun`` and how it stopped."""

    x: np.ndarray
    jac: np.ndarray
    nfev: int
    stop: Stop


def levenberg_marquardt(fun: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, lo: np.ndarray,
                        hi: np.ndarray, scale: np.ndarray, *, max_iter: int = 60,
                        J0: np.ndarray | None = None, rel_step: float = 1e-3, tol: float = 1e-6,
                        max_step: float = 3.0, refresh: bool = True) -> LMResult:
    """Bounded Levenberg-Marquardt on ``sum(fun(x)^2)`` with Broyden updates of the Jacobian.

    The Jacobian is differenced once (forward, step ``rel_step * scale``; columns given in
    ``J0`` are taken as they are -- non-zero columns only; ``J0`` itself is filled and updated in
    place, not copied), then corrected by Broyden's rank-one
    update after every step, and differenced afresh when steps fail or stall. No step is longer
    than ``max_step`` in units of ``scale`` (for the base constants their prior's sd, for an
    effect's parameters a tenth of their range). Each iteration
    thus costs one prediction instead of one per parameter; convergence (relative decrease
    below ``tol``) is only accepted on a freshly differenced Jacobian, so a fit and its refit
    with an effect end equally converged and their chi-square difference is the effect's.
    Six failed steps in a row (or the damping beyond 1e8) end it too, recorded as giving up
    (``LMResult.stop``), not as convergence.

    ``refresh=False`` never differences the Jacobian afresh after the first: a brief refit
    that only ranks starts by where it got in ``max_iter`` steps. Its convergence is never
    claimed: a step that gains less than ``tol`` on a Broyden Jacobian ends it (``SCREENED``).
    A fresh Jacobian costs one prediction per parameter -- in a six-step refit of eleven
    parameters more than the steps themselves.
    """
    def difference(J: np.ndarray | None, x: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, int]:
        return _difference(fun, J, x, r, lo, hi, rel_step * scale)

    x = np.asarray(x0, float).copy()
    r = fun(x)
    J, n = difference(J0, x, r)
    nfev = 1 + n
    fresh = J0 is None
    cost = float(r @ r)
    mu = 1e-3
    fails = 0
    for _ in range(max_iter):
        x_new = _trial_point(J, r, x, scale, mu, lo, hi, max_step)
        step = x_new - x
        if not np.any(step):
            return LMResult(x, J, nfev, Stop.AT_BOUNDS)
        try:
            r_new = fun(x_new)
        except (ValueError, np.linalg.LinAlgError):   # e.g. a mode turned overdamped
            r_new = None
        nfev += 1
        c_new = float(r_new @ r_new) if r_new is not None else math.inf
        if r_new is not None:
            _broyden(J, r_new - r - J @ step, step)
        if c_new < cost:
            small = (cost - c_new) < tol * cost
            x, r, cost = x_new, r_new, c_new
            mu = max(mu / 3, 1e-7)
            fails = 0
            if small:
                if fresh:
                    return LMResult(x, J, nfev, Stop.CONVERGED)   # on a true Jacobian
                if not refresh:
                    return LMResult(x, J, nfev, Stop.SCREENED)
                J = None      # the stale Jacobian is let go before the fresh one is made
                (J, n), fresh = difference(None, x, r), True
                nfev += n
                continue
            fresh = False
        else:
            mu *= 4
            fails += 1
            if fails >= 2 and not fresh and refresh:
                J = None
                (J, n), fresh, fails = difference(None, x, r), True, 0
                nfev += n
            elif fails >= 6 or mu > 1e8:
                return LMResult(x, J, nfev, Stop.GAVE_UP)
    return LMResult(x, J, nfev, Stop.ITERATION_LIMIT)


def _broyden(J: np.ndarray, v: np.ndarray, step: np.ndarray) -> None:
    """Broyden's rank-one update of the Jacobian ``J`` (n_data, n_params) in place, ``J[:, j] +=
    v step_j / |step|^2`` for each column the ``step`` moved (``v`` (n_data,) the residual's
    change the Jacobian did not predict): :data:`NORMAL_ROWS` rows at a time over all columns
    when the step moved every one (each element the same product, quotient and sum as column
    by column, in one pass over ``J`` instead of one strided pass per column), else column by
    column. Neither ``J`` nor the outer product is copied whole."""
    ss = float(step @ step)
    cols = np.flatnonzero(step)
    if len(cols) < J.shape[1]:
        for j in cols:
            J[:, j] += v * step[j] / ss
        return
    for a in range(0, J.shape[0], NORMAL_ROWS):
        t = v[a:a + NORMAL_ROWS, None] * step[None, :]
        t /= ss
        J[a:a + NORMAL_ROWS] += t


def _difference(fun: Callable[[np.ndarray], np.ndarray], J: np.ndarray | None, x: np.ndarray,
                r: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                h: np.ndarray) -> tuple[np.ndarray, int]:
    """The Jacobian of ``fun`` at ``x`` (where it is ``r``) by forward differences of step ``h``
    (backward where the forward one leaves the bounds ``lo``, ``hi`` or fails), keeping the
    non-zero columns of ``J`` (filled in place: ``J`` is overwritten, not copied); and the
    number of columns differenced."""
    out = np.zeros((len(r), len(x))) if J is None else J
    n = 0
    for i in range(len(x)):
        if J is not None and np.any(J[:, i] != 0):
            continue
        xi = x.copy()
        for sign in (1, -1):
            xi[i] = x[i] + sign * h[i]
            if not lo[i] <= xi[i] <= hi[i]:
                continue
            try:
                out[:, i] = (fun(xi) - r) / (xi[i] - x[i])
                break
            except (ValueError, np.linalg.LinAlgError):
                continue
        n += 1
    return out, n


def _trial_point(J: np.ndarray, r: np.ndarray, x: np.ndarray, scale: np.ndarray, mu: float,
                 lo: np.ndarray, hi: np.ndarray, max_step: float) -> np.ndarray:
    """The damped Gauss-Newton step from ``x`` (damping ``mu`` on the scaled normal equations'
    diagonal), at most ``max_step`` scales long, clipped to the bounds."""
    A, g = _normal_equations(J, r, scale)
    d = np.sqrt(np.maximum(np.diag(A), 1e-30))
    step = -np.linalg.solve(A + mu * np.diag(d**2) + 1e-12 * np.eye(len(x)), g) * scale
    # a trust region: no step longer than ``max_step`` scales (a Gauss-Newton step across a
    # beat's phase or a mode's crossing lands where the linearisation means nothing, and
    # from there back off only slowly)
    n_step = float(np.linalg.norm(step / scale))
    if n_step > max_step:
        step *= max_step / n_step
    return np.clip(x + step, lo, hi)


NORMAL_ROWS = 1 << 15
"""Rows of the Jacobian scaled at a time for the normal equations (8 MB at 32 columns)."""


def _normal_equations(J: np.ndarray, r: np.ndarray, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``Js' Js`` and ``Js' r`` of the column-scaled Jacobian ``Js = J * scale``, summed over
    blocks of :data:`NORMAL_ROWS` rows: the scaled copy is never whole (it was N x p, as large as
    the Jacobian, 25-80 MB for 20 impacts). Summed in blocks, the sums round differently from
    one product over all rows (last bits)."""
    p = J.shape[1]
    A, g = np.zeros((p, p)), np.zeros(p)
    for a in range(0, J.shape[0], NORMAL_ROWS):
        Js = J[a:a + NORMAL_ROWS] * scale[None, :]
        A += Js.T @ Js
        g += Js.T @ r[a:a + NORMAL_ROWS]
    return A, g


@dataclass(frozen=True)
class ModeRef:
    """A mode identified on the trial (:class:`~ramdaq.analysis.gap.modal_level.TrialModes`):
    damped frequency ``f_hz`` and damping ratio ``zeta`` with their standard errors."""

    f_hz: float
    f_se_hz: float
    zeta: float
    zeta_se: float


F_FLOOR = 0.01
"""The least relative frequency error a mode's misfit is measured in (the rig calibrated to the
modes leaves 1-2 % as its form: a crude rig cannot do better, and a time fit is not blamed for
what the model level left)."""
ZETA_FLOOR = 0.2
"""The least relative damping-ratio error a mode's misfit is measured in (damping ratios
identified from 3-6 blows scatter by 10-20 %)."""
WORSE_PER_MODE = 9.0
"""How much a time fit's mode misfit (a sum of squared standardised errors) may exceed the
modal-level constants' before it is said to have moved the modes away: three standard errors
per identified mode."""


def mode_misfit(fw: Forward, theta: np.ndarray, refs: tuple[ModeRef, ...]) -> float:
    """Sum over the identified modes ``refs`` of the squared standardised errors of the model's
    nearest mode (in log frequency) at base constants ``theta``: frequency and damping ratio,
    each over its standard error floored at :data:`F_FLOOR` / :data:`ZETA_FLOOR` relative.
    Infinite when the model cannot be built there."""
    try:
        lam = fw.modes(theta).lam
    except (ValueError, np.linalg.LinAlgError):
        return math.inf
    lam = lam[lam.imag > 0]
    if not len(lam) or not refs:
        return math.inf if refs else 0.0
    f, zeta = lam.imag / (2 * math.pi), -lam.real / np.abs(lam)
    total = 0.0
    for m in refs:
        i = int(np.argmin(np.abs(np.log(f / m.f_hz))))
        zf = (f[i] - m.f_hz) / max(m.f_se_hz, F_FLOOR * m.f_hz)
        zz = (zeta[i] - m.zeta) / max(m.zeta_se, ZETA_FLOOR * m.zeta)
        total += zf * zf + zz * zz
    return float(total)


def departs_from_modes(fw: Forward, theta_time: np.ndarray, theta_modal: np.ndarray,
                       refs: tuple[ModeRef, ...]) -> str | None:
    """Why the time-history calibration's constants ``theta_time`` are not kept over the
    modal-level ones ``theta_modal``: the identified modes ``refs`` (:func:`mode_misfit`) fit
    worse by more than :data:`WORSE_PER_MODE` per mode. One line, or None (keep the time fit)."""
    if not refs:
        return None
    m_time = mode_misfit(fw, theta_time, refs)
    m_modal = mode_misfit(fw, theta_modal, refs)
    if not m_time > m_modal + WORSE_PER_MODE * len(refs):
        return None
    bound = [p.name for p, t in zip(fw.params, theta_time, strict=True) if abs(t) >= 0.999 * p.bound]
    at = f"; at their bounds: {', '.join(bound)}" if bound else ""
    return (f"the time-history calibration moved the model's modes away from the identified ones "
            f"(misfit {m_time:.0f} against {m_modal:.0f} at the modal-level constants{at}): the "
            "modal-level constants are kept")
