"""Order selection for :func:`ramdaq.analysis.modal.identify.identify_modes`: a likelihood-ratio test.

A mode is kept when refitting the model with it lowers the whitened residual by more than a
χ² threshold (see the ``identify_modes`` docstring for the threshold and its false-alarm rate).

Trial fits (speed; the decisions are those of full refits)
----------------------------------------------------------
Most candidates a search tries are noise and are rejected, and a full refit of all K + 1 modes
from a noise candidate's start takes 10–60 Levenberg–Marquardt steps, each touching every
sample for all modes. A candidate is therefore first fitted with the accepted poles *held*
(amplitudes free; the held modes are projected out once, so a step costs O(n_samples) for one
mode): Λ_p of that fit is a lower bound for Λ of the full refit started from it (the refit only
descends). First, though, the linear screen: Λ_lin with the new pole held at its start
(:meth:`ModeSelector._screen_lr`, from the current fit's residual); below ``screen`` the
candidate is rejected, above the threshold it goes straight to the full refit from its start
(a strong mode: the held-pole fit, which could only raise Λ_p further above the threshold,
would only have moved its start; ord22: same decisions on 420 records, final estimates within
1.4·10⁻⁴ of their standard errors, a hit's final fits' own tolerance being 10⁻³). Then

- Λ_p above the threshold: the full refit, started there (~2–3 steps), decides (it can only
  raise Λ);
- else the decrease of the residual that freeing the accepted poles promises (one Gauss–Newton
  step from that point, in Λ units, ``gain``) is computed; the candidate is rejected when
  Λ_p + 4·gain + 1 stays below the threshold, otherwise the full refit decides.

The margin (4·gain + 1) covers the largest full-refit gain measured against the Gauss–Newton
estimate, and every decision measured equalled that of a full refit (``docs/estimators.md``,
"Order selection").

Most noise candidates are rejected before their held-pole fit converges: it is looked at after
two Levenberg–Marquardt iterations (~4 evaluations; converged, a noise candidate took ~12, up
to 72 creeping along a valley) and rejected there when Λ_p ≤ threshold and Λ_p + 4·gain + 1 ≤
0.6 × threshold (not where the Gauss–Newton gain comes out negative: close modes, an
indefinite model). Any other candidate's fit continues from where it was looked at
(:class:`~ramdaq.analysis.modal.varpro.HeldFit`: the path of one fit without the look, to the
bit) and is judged as above. Over 216 rejected candidates (the ALBACORE hits, 16 gages
and one, 6 and 14 s; the accuracy benchmark's single- and two-mode records) the converged
Λ_p + 4·gain + 1 rose by at most 0.23 × threshold after those two iterations, and none of the
candidates the early look rejects exceeded 0.72 × threshold converged: every decision equalled
that of the converged test, with 0.4 × threshold to spare; half the held-fit evaluations go.
(A look after one iteration rejected as safely over 568 such candidates, but not on a gap
benchmark trial's free modal model, modal double hit 556005, where the converged test accepts
a candidate it rejected.)

Trial fits (the held-pole fits and the trial refits of all poles) are converged to 10⁻³ of the
residual variance, which moves Λ by ~10⁻³: they stop at an accepted point from which the
undamped Gauss–Newton step promises less than that (``se_tol``), or where a step gained less
and promises less (``chi2_tol``). (Until ord22 the second alone: a trial refit from its held
start took 3 evaluations, the last only confirming; it now takes 2, a held fit 4.2 a record
instead of 7.2, one gage's 6 s hit. Same decisions on 420 records of hit_cost's and the
accuracy benchmark's; the final estimates, refitted from the search's poles, moved by at most
6·10⁻⁵ of their standard errors, the final fit's own stop: Σr² to 10⁻¹¹.)
The final fit to rounding, or, with ``final_se_tol`` (a hit's final analysis,
``identify_modes``' ``band_decimation``: :data:`FINAL_SE_TOL`), until the Gauss–Newton step
promises to lower Σr² by less than 10⁻⁶ of the residual variance: every f and δ within ~0.001
of its standard error of the optimum (Δθᵀ Cov⁻¹ Δθ = ΔΣr²/s²). The ALBACORE hits' final fits
then take 2.5-2.7 evaluations, not 3.4-3.7; their numbers moved by at most 0.001 standard
errors (a 600 s, 20-blow replay). (Not by default: the gap diagnosis calibrates a rig to the
modes, and that calibration's optimum moved far on such a change, hull damping x1.7 -> x0.7
on sampson-water.)
"""

from __future__ import annotations

import numpy as np
from scipy import linalg
from scipy.linalg import lapack

from .crb import damping_ratio_from_decrement
from .varpro import (
    HELD_MAX_ITER,
    GaussNewtonGain,
    HeldPoleFitter,
    Projector,
    VarProFit,
    damped_basis,
    drop_one_rss_increase,
    fit_modes_varpro,
    linear_amplitudes,
    trend_basis,
    uniform_grid,
)

__all__ = ["FINAL_SE_TOL", "ModeSelector", "floor_noise"]

_TRIAL_CHI2_TOL = 1e-3  # trial fits: converged to 10⁻³ of the residual variance (Λ to ~10⁻³)
_GAIN_MARGIN = 4.0  # reject on held poles when Λ_p + 4·(Gauss–Newton gain) + 1 < threshold
_EARLY_ITER = 2  # held-pole fits: judged first after 2 Levenberg–Marquardt iterations …
_EARLY_REJECT = 0.6  # … and rejected there when Λ_p + 4·gain + 1 ≤ 0.6 × threshold
FINAL_SE_TOL = 1e-6  # a hit's final fits: stopped within ~0.001 standard errors of the optimum


def floor_noise(sig: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Noise std floored at 10⁻⁹ of each channel's rms (noise-free synthetic data). The rms
    by one fused pass (no squared copy of the data: its rounding differs from the mean of
    squares by ~1e-16, and only the floor, 10⁻⁹ of it, reads it)."""
    yy = np.einsum("...i,...i->...", y, y)
    rms = np.sqrt(yy / max(y.shape[-1], 1))
    return np.maximum(sig, 1e-9 * rms + 1e-300)


class _Strong(Exception):
    """A candidate whose linear screen alone exceeds the threshold (try_add)."""


class ModeSelector:
    """Forward/backward selection of modes by a likelihood-ratio test on refitted models.

    Parameters
    ----------
    Y : numpy.ndarray, shape (n_channels, n_samples)
        Data. ``t`` (n_samples,) are its times (s).
    fit_offset : bool or int
        Constant per channel in the model (True), or p trend columns (a drift of degree p - 1).
    threshold : float
        Λ a mode must exceed.
    zeta_max : float
        Largest |ζ| of an accepted fit.
    f_lim : (float, float)
        Frequency bounds (Hz) of the fit.
    w0 : numpy.ndarray, shape (n_channels,)
        Starting channel weights 1/σ_c.
    final_se_tol : float
        ``se_tol`` of the fits that are not trial fits (0: converged to rounding; module
        docstring).
    by_matmul : bool
        Every fit's basis by :func:`~ramdaq.analysis.modal.varpro.damped_basis`'s ``by_matmul``
        (a hit's finals).
    screen : float, optional
        Λ of the linear screen (the new pole held at its start) below which a candidate is
        rejected without a fit; default 0.25 × ``threshold``
        (:func:`~ramdaq.analysis.modal.identify.identify_modes` sets it from the noise's own
        χ² distribution: ``_Data.screen``).
    """

    def __init__(
        self, Y: np.ndarray, t: np.ndarray, fit_offset: bool, threshold: float, zeta_max: float,
        f_lim: tuple[float, float], w0: np.ndarray, final_se_tol: float = 0.0,
        by_matmul: bool = False, screen: float | None = None,
    ) -> None:
        self.Y, self.t, self.fit_offset, self.by_matmul = Y, t, fit_offset, by_matmul
        self.screen = 0.25 * threshold if screen is None else screen
        self.final_se_tol = final_se_tol
        self.threshold, self.zeta_max, self.f_lim = threshold, zeta_max, f_lim
        self.w = w0
        self.fit: VarProFit | None = None
        self._held: tuple[VarProFit, np.ndarray, HeldPoleFitter] | None = None
        self._gain_cache: tuple[np.ndarray, GaussNewtonGain] | None = None
        self._screen_cache: tuple | None = None
        self._grid = uniform_grid(t)
        if int(fit_offset) > 1:  # the trend alone: least squares on its columns
            T = trend_basis(t, int(fit_offset))
            resid = Y - linalg.lstsq(T.T, Y.T)[0].T @ T
        else:
            resid = Y - (Y.mean(axis=1, keepdims=True) if fit_offset else 0.0)
        self.rss = np.sum(resid**2, axis=1)

    def refit(self, f: np.ndarray, d: np.ndarray, trial: bool = False,
              keep: dict | None = None) -> VarProFit | None:
        """NLS fit from (f, δ) with the current weights; None if it fails or leaves |ζ| ≤ ζmax.

        ``trial``: a fit that only decides the likelihood-ratio test (or starts a later fit) is
        converged to 10⁻³ of the residual variance (``chi2_tol`` and ``se_tol``: module
        docstring); any other to rounding, or
        with ``final_se_tol`` to ~0.001 of its standard errors (module docstring).
        """
        try:
            fit = fit_modes_varpro(self.t, self.Y, f, d, weights=self.w, fit_offset=self.fit_offset,
                                   f_bounds_hz=self.f_lim, delta_bounds=(-3.0, 3.0),
                                   chi2_tol=_TRIAL_CHI2_TOL if trial else 0.0,
                                   se_tol=_TRIAL_CHI2_TOL if trial else self.final_se_tol,
                                   by_matmul=self.by_matmul, keep=keep)
        except (ValueError, linalg.LinAlgError):
            return None
        zeta = damping_ratio_from_decrement(fit.delta)
        if not np.all(np.abs(zeta) <= self.zeta_max) or not np.all(np.isfinite(fit.covariance)):
            return None
        return fit

    def _lr(self, rss_without, fit: VarProFit) -> float:
        var = fit.noise_std**2
        return float(np.sum((rss_without - fit.rss) / np.maximum(var, 1e-300)))

    def _held_fitter(self) -> HeldPoleFitter:
        """Fitter with the current fit's poles held, for the current weights (cached)."""
        if self._held is None or self._held[0] is not self.fit or self._held[1] is not self.w:
            fitter = HeldPoleFitter(self.t, self.Y, self.fit.f_hz, self.fit.delta,
                                     weights=self.w, fit_offset=self.fit_offset, grams=True,
                                     by_matmul=self.by_matmul)
            self._held = (self.fit, self.w, fitter)
        return self._held[2]

    def _gain(self) -> GaussNewtonGain:
        """Gauss–Newton gain on the data weighted by the current weights (cached)."""
        if self._gain_cache is None or self._gain_cache[0] is not self.w:
            self._gain_cache = (self.w, GaussNewtonGain(self.t, self.Y, weights=self.w,
                                                         fit_offset=self.fit_offset,
                                                         by_matmul=self.by_matmul))
        return self._gain_cache[1]

    def try_add(self, fc: float, dc: float) -> bool:
        """Refit with one more mode started at (fc, δc); keep it if Λ exceeds the threshold."""
        # (arrays joined by np.concatenate: the same values as the index trick r_, ~10 µs
        # less a call, ~10 calls a try)
        fc1, dc1 = np.array([fc], dtype=float), np.array([dc], dtype=float)
        f0 = fc1 if self.fit is None else np.concatenate((self.fit.f_hz, fc1))
        d0 = dc1 if self.fit is None else np.concatenate((self.fit.delta, dc1))
        if self.fit is not None:
            try:
                # Linear screen (poles fixed at their starts): a candidate far below the
                # threshold is not worth a nonlinear refit. Not for the first, whose weights are
                # not yet residual-based. From the fit's own residual (_screen_lr), else as
                # the held-pole fitter's first evaluation.
                lam_lin = self._screen_lr(fc1, dc1)
                if lam_lin is None:
                    rss_lin_w = self._held_fitter().weighted_rss(fc1, dc1)
                    lam_lin = np.sum(self.rss * self.w**2 - rss_lin_w)
                if lam_lin < self.screen:
                    return False
                if lam_lin > self.threshold:
                    raise _Strong  # straight to the refit of all poles from the start
                held = self._held_fitter()
                # The new mode alone, accepted poles held (see the module docstring): looked
                # at after _EARLY_ITER iterations, then (unless rejected there) continued to
                # convergence: the path of one fit without the look, to the bit (HeldFit).
                run = held.start(fc1, dc1, f_bounds_hz=self.f_lim, delta_bounds=(-3.0, 3.0),
                                 chi2_tol=_TRIAL_CHI2_TOL, se_tol=_TRIAL_CHI2_TOL)
                try:
                    looked = lam_lin <= self.threshold  # (above it, the held fit, which only
                    # descends from there, is above it too: no early rejection possible)
                    if looked and self._rejected(*run.advance(_EARLY_ITER)[:4], _EARLY_REJECT):
                        return False
                    fp, dp, rss_p, noise_p, _ = run.advance(HELD_MAX_ITER
                                                            - _EARLY_ITER * looked)
                finally:
                    run.close()
                if self._rejected(fp, dp, rss_p, noise_p, 1.0):
                    return False
            except _Strong:
                fp, dp = fc1, dc1
            except (ValueError, linalg.LinAlgError):
                return False
            f0, d0 = np.concatenate((self.fit.f_hz, fp)), np.concatenate((self.fit.delta, dp))
        last: dict = {}
        fit = self.refit(f0, d0, trial=True, keep=last)
        if fit is None or self._lr(self.rss, fit) <= self.threshold:
            return False
        w_fit = self.w
        self.fit, self.rss = fit, fit.rss
        self.w = 1.0 / floor_noise(fit.noise_std, self.Y)
        proj = last["proj"]
        if proj.cho is not None:  # the screen's terms at the new fit (_screen_lr), reweighted
            self._screen_cache = (fit, self.w, proj.Phi, proj,
                                  last["resid_w"] * (self.w / w_fit)[None, :])
        return True

    def _screen_lr(self, fc: np.ndarray, dc: np.ndarray) -> float | None:
        """Λ of the linear screen for the new pole (fc, δc) held at its start: the weighted
        residual r of the current fit (orthogonal to its columns Φ) projected onto the new
        columns Φ_n with Φ's part removed, Σ_c w_c² (Φ_nᵀr_c)ᵀ S⁻¹ (Φ_nᵀr_c), S = Φ_nᵀ P⊥ Φ_n
        (2 x 2, the Schur complement from Φ's Cholesky, cached a fit). The same Λ as the held-pole
        fitter's first evaluation gives (Σ w²r² − its Σr², to rounding) without that fitter (a
        QR of Φ and the data projected, per fit: a candidate whose screen passes above the
        threshold goes straight to the refit, below the screen nowhere). None where Φ needs the
        QR path or S keeps under 10⁻⁶ of Φ_nᵀΦ_n (the new pole on an accepted one's): the
        fitter decides. (Φ, its projector and r: those of the accepted fit's last evaluation,
        where :meth:`try_add` kept them.)"""
        c = self._screen_cache
        if c is None or c[0] is not self.fit or c[1] is not self.w:
            Phi = damped_basis(self.t, self.fit.f_hz, self.fit.delta, self.fit_offset, self._grid,
                               by_matmul=self.by_matmul)
            proj = Projector(Phi)
            R = None
            if proj.cho is not None:
                Yw = self.Y.T * self.w[None, :]  # (n_samples, n_channels)
                R = Yw - Phi @ proj.coef(Yw)
            c = self._screen_cache = (self.fit, self.w, Phi, proj, R)
        _, _, Phi, proj, R = c
        if R is None:
            return None
        Pn = damped_basis(self.t, fc, dc, False, self._grid, by_matmul=self.by_matmul)
        V = proj.whitened(Phi.T @ Pn)  # VᵀV = Φ_nᵀ Φ (ΦᵀΦ)⁻¹ Φᵀ Φ_n
        G = Pn.T @ Pn
        S = G - V.T @ V
        if not (S.diagonal() > 1e-6 * G.diagonal()).all():
            return None
        L, info = lapack.dpotrf(S, lower=1)
        if info != 0:
            return None
        b = Pn.T @ R  # (2, n_channels)
        return float(np.sum(b * lapack.dpotrs(L, b, lower=1)[0]))

    def _rejected(self, fp: np.ndarray, dp: np.ndarray, rss_p: np.ndarray, noise_p: np.ndarray,
                  fraction: float) -> bool:
        """Whether a held-pole fit of the new mode (fp, δp; per-channel Σr² and noise std)
        rejects it: Λ_p at most the threshold and Λ_p + 4·gain + 1 at most ``fraction`` × the
        threshold. An early look (``fraction`` < 1) rejects nothing whose Gauss–Newton gain
        came out negative: an indefinite model (close modes, JᵀJ rounded) says nothing yet."""
        lam_p = float(np.sum((self.rss - rss_p) / np.maximum(noise_p**2, 1e-300)))
        if lam_p > self.threshold or (fraction < 1.0 and lam_p + 1.0 > fraction * self.threshold):
            return False  # (an early look rejects only with a gain ≥ 0: Λ_p + 1 decides it here)
        try:
            gain_w = self._gain()(np.concatenate((self.fit.f_hz, fp)),
                                   np.concatenate((self.fit.delta, dp)))
        except (ValueError, linalg.LinAlgError):
            gain_w = np.inf
        # weighted Σr² → Λ units (Λ divides by each channel's own residual variance)
        gain = gain_w * float(np.max(1.0 / np.maximum(self.w**2 * noise_p**2, 1e-300)))
        if fraction < 1.0 and not gain >= 0.0:
            return False
        return lam_p + _GAIN_MARGIN * gain + 1.0 <= fraction * self.threshold

    def significance(self) -> np.ndarray:
        """Λ of each mode of the current fit (amplitudes re-solved without it, poles fixed)."""
        fit = self.fit
        rise = drop_one_rss_increase(self.t, self.Y, fit.f_hz, fit.delta,
                                      fit_offset=self.fit_offset)
        if rise is not None:  # all drop-one refits from one factorisation
            return np.sum(rise / np.maximum(fit.noise_std**2, 1e-300), axis=1)
        out = np.empty(fit.f_hz.size)
        for k in range(fit.f_hz.size):
            keep = np.arange(fit.f_hz.size) != k
            _, _, rss_wo = linear_amplitudes(self.t, self.Y, fit.f_hz[keep], fit.delta[keep],
                                             fit_offset=self.fit_offset)
            out[k] = self._lr(rss_wo, fit)
        return out

    def prune(self) -> None:
        """Drop the least significant mode and refit while any Λ is below the threshold."""
        while self.fit is not None and self.fit.f_hz.size:
            lr = self.significance()
            k = int(np.argmin(lr))
            if lr[k] > self.threshold:
                return
            keep = np.arange(lr.size) != k
            if not np.any(keep):
                self.fit = None
                return
            self.fit = self.refit(self.fit.f_hz[keep], self.fit.delta[keep], trial=True)
