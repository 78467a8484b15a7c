"""The result of :func:`ramdaq.analysis.modal.identify.identify_modes`: a table of damped modes."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ModeTable"]


@dataclass(frozen=True)
class ModeTable:
    """Damped modes identified on a multi-channel free decay, sorted by frequency.

    A channel's signal is modelled as y_c(t) = o_c + Σ_k Re(a_ck · exp((−δ_k f_k + j2π f_k) t))
    with t = 0 at the first sample given. Per-channel arrays have NaN for channels that were
    not fitted (dead channels; per-channel values where the mode is not significant there).

    Attributes
    ----------
    frequency_hz, delta, zeta : numpy.ndarray, shape (n_modes,)
        Damped frequency (Hz), logarithmic decrement, damping ratio, shared by all channels.
    frequency_se_hz, delta_se, zeta_se : numpy.ndarray, shape (n_modes,)
        Standard errors (white-noise Jacobian covariance of the shared fit).
    complex_amplitude : numpy.ndarray, shape (n_channels, n_modes), complex
        a_ck at t = 0 (signal units).
    channel_frequency_hz, channel_frequency_se_hz, channel_delta, channel_delta_se :
        numpy.ndarray, shape (n_channels, n_modes)
        Each channel fitted on its own (the report's per-gage decrement, Eq 7).
    significance : numpy.ndarray, shape (n_modes,)
        Likelihood-ratio statistic of each mode (drop in whitened residual when it is added).
    offset : numpy.ndarray, shape (n_channels,)
        Fitted constant o_c (signal units).
    noise_std : numpy.ndarray, shape (n_channels,)
        Residual std of each channel (signal units).
    fs_hz : float
        Sample rate of the input (Hz).
    n_samples : int
        Input length (samples).
    method : str
        Estimator chain, e.g. ``"mp+varpro"``.
    info : dict
        Diagnostics: decimation factors, order selection, thresholds, modes outside f_range.
    """

    frequency_hz: np.ndarray
    delta: np.ndarray
    zeta: np.ndarray
    frequency_se_hz: np.ndarray
    delta_se: np.ndarray
    zeta_se: np.ndarray
    complex_amplitude: np.ndarray
    channel_frequency_hz: np.ndarray
    channel_frequency_se_hz: np.ndarray
    channel_delta: np.ndarray
    channel_delta_se: np.ndarray
    significance: np.ndarray
    offset: np.ndarray
    noise_std: np.ndarray
    fs_hz: float
    n_samples: int
    method: str
    info: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.frequency_hz.size)

    @property
    def n_channels(self) -> int:
        """Number of channels of the input."""
        return int(self.complex_amplitude.shape[0])

    @property
    def amplitude(self) -> np.ndarray:
        """Initial amplitude |a_ck| (signal units), shape (n_channels, n_modes)."""
        return np.abs(self.complex_amplitude)

    @property
    def phase_rad(self) -> np.ndarray:
        """Phase of a_ck at t = 0 (rad), shape (n_channels, n_modes)."""
        return np.angle(self.complex_amplitude)

    @property
    def mode_shape(self) -> np.ndarray:
        """Complex mode shapes, shape (n_channels, n_modes).

        Each column is divided by its largest-magnitude entry, which becomes 1 + 0j; the other
        entries are relative amplitude and phase. Requires all channels in the same unit.
        """
        a = self.complex_amplitude
        if a.size == 0:
            return a.copy()
        mag = np.where(np.isfinite(a), np.abs(a), -1.0)
        ref = a[np.argmax(mag, axis=0), np.arange(a.shape[1])]
        return a / np.where(ref != 0, ref, 1.0)

    def rows(self) -> list[dict]:
        """One dict per mode (frequency, decrement, damping ratio, errors), for tables."""
        return [
            {
                "mode": k + 1,
                "frequency_hz": float(self.frequency_hz[k]),
                "frequency_se_hz": float(self.frequency_se_hz[k]),
                "delta": float(self.delta[k]),
                "delta_se": float(self.delta_se[k]),
                "zeta": float(self.zeta[k]),
                "zeta_se": float(self.zeta_se[k]),
                "significance": float(self.significance[k]),
            }
            for k in range(len(self))
        ]
