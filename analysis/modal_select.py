"""Order selection for :func:`analysis.modal_id.identify_modes`: a likelihood-ratio test.

A mode is kept when refitting the model with it lowers the whitened residual by more than a
χ² threshold (see the ``identify_modes`` docstring for the threshold and its false-alarm rate).
"""

from __future__ import annotations

import numpy as np
from scipy import linalg

from analysis.damping import damping_ratio_from_decrement
from analysis.modal_varpro import VarProFit, fit_modes_varpro, linear_amplitudes

__all__ = ["ModeSelector", "floor_noise"]


def floor_noise(sig: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Noise std floored at 10⁻⁹ of each channel's rms (noise-free synthetic data)."""
    rms = np.sqrt(np.mean(y * y, axis=-1))
    return np.maximum(sig, 1e-9 * rms + 1e-300)


class ModeSelector:
    """Forward/backward selection of modes by a likelihood-ratio test on refitted models.

    Parameters
    ----------
    Y : numpy.ndarray, shape (n_channels, n_samples)
        Data. ``t`` (n_samples,) are its times (s).
    fit_offset : bool
        Constant per channel in the model.
    threshold : float
        Λ a mode must exceed.
    zeta_max : float
        Largest |ζ| of an accepted fit.
    f_lim : (float, float)
        Frequency bounds (Hz) of the fit.
    w0 : numpy.ndarray, shape (n_channels,)
        Starting channel weights 1/σ_c.
    """

    def __init__(
        self, Y: np.ndarray, t: np.ndarray, fit_offset: bool, threshold: float, zeta_max: float,
        f_lim: tuple[float, float], w0: np.ndarray,
    ) -> None:
        self.Y, self.t, self.fit_offset = Y, t, fit_offset
        self.threshold, self.zeta_max, self.f_lim = threshold, zeta_max, f_lim
        self.w = w0
        self.fit: VarProFit | None = None
        resid = Y - (Y.mean(axis=1, keepdims=True) if fit_offset else 0.0)
        self.rss = np.sum(resid**2, axis=1)

    def refit(self, f: np.ndarray, d: np.ndarray) -> VarProFit | None:
        """NLS fit from (f, δ) with the current weights; None if it fails or leaves |ζ| ≤ ζmax."""
        try:
            fit = fit_modes_varpro(self.t, self.Y, f, d, weights=self.w, fit_offset=self.fit_offset,
                                   f_bounds_hz=self.f_lim, delta_bounds=(-3.0, 3.0))
        except (ValueError, linalg.LinAlgError):
            return None
        zeta = damping_ratio_from_decrement(fit.delta)
        if not np.all(np.abs(zeta) <= self.zeta_max) or not np.all(np.isfinite(fit.covariance)):
            return None
        return fit

    def _lr(self, rss_without, fit: VarProFit) -> float:
        var = fit.noise_std**2
        return float(np.sum((rss_without - fit.rss) / np.maximum(var, 1e-300)))

    def try_add(self, fc: float, dc: float) -> bool:
        """Refit with one more mode started at (fc, δc); keep it if Λ exceeds the threshold."""
        f0 = np.r_[self.fit.f_hz if self.fit else [], fc]
        d0 = np.r_[self.fit.delta if self.fit else [], dc]
        # Linear screen (poles fixed at their starts): a candidate far below the threshold is
        # not worth a nonlinear refit. Not for the first, whose weights are not yet residual-based.
        if self.fit is not None:
            _, _, rss_lin = linear_amplitudes(self.t, self.Y, f0, d0, fit_offset=self.fit_offset)
            if np.sum((self.rss - rss_lin) * self.w**2) < 0.25 * self.threshold:
                return False
        fit = self.refit(f0, d0)
        if fit is None or self._lr(self.rss, fit) <= self.threshold:
            return False
        self.fit, self.rss = fit, fit.rss
        self.w = 1.0 / floor_noise(fit.noise_std, self.Y)
        return True

    def significance(self) -> np.ndarray:
        """Λ of each mode of the current fit (amplitudes re-solved without it, poles fixed)."""
        fit = self.fit
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
            self.fit = self.refit(self.fit.f_hz[keep], self.fit.delta[keep])
