"""Sensor and front-end model: accelerometer, noise, anti-alias low-pass, ADC.

Per channel: ``a (m/s^2) + noise -> x sensitivity (V) -> anti-alias low-pass -> ADC``. The ADC
has ``bits`` bits over +-``full_scale_V``; one count is ``lsb = 2 full_scale_V / 2**bits`` volts,
so the SI scale of a channel is ``lsb / sensitivity`` m/s^2 per count. Values beyond the rails
clip at ``-2**(bits-1)`` and ``2**(bits-1) - 1`` counts, as a real converter does.

The anti-alias filter is a Butterworth low-pass of the rig's order and corner, mapped to the
sample rate by the bilinear transform with pre-warping, so its corner and order are right; what
it cannot show is aliasing of content above Nyquist, which the rigid-rudder model does not
produce (its modes lie far below the usual 2-25.6 kHz rates). Accelerometers are taken as
AC-coupled (IEPE): no gravity offset.
"""

from __future__ import annotations

import numpy as np

from .rig import Rig


def channel_scales(rig: Rig) -> np.ndarray:
    """m/s^2 per ADC count for each channel, in DAQ channel order, shape (n_channels,)."""
    lsb = 2 * rig.daq.adc_full_scale_V / 2**rig.daq.adc_bits
    return np.array([lsb / g.sensitivity_V_per_m_s2 for g in rig.gages_by_channel()])


class SensorChain:
    """Stateful front-end for a block stream: carries filter state and the noise generator.

    Parameters
    ----------
    rig : Rig
        Gives sensitivities, ADC, anti-alias filter and noise floor.
    fs_hz : float
        Sample rate, Hz (may differ from the rig's own).
    seed : int
        Seeds the noise generator, so a stream is repeatable.
    noise : bool
        Add the rig's noise floor (``False`` for noise-free truth).
    anti_alias : bool
        Apply the anti-alias low-pass.
    """

    def __init__(self, rig: Rig, fs_hz: float, *, seed: int = 0, noise: bool = True,
                 anti_alias: bool = True) -> None:
        d = rig.daq
        self.fs_hz = fs_hz
        self.sens = np.array([g.sensitivity_V_per_m_s2 for g in rig.gages_by_channel()])
        self.lsb_V = 2 * d.adc_full_scale_V / 2**d.adc_bits
        self.scale = channel_scales(rig)
        self.lo = -(2 ** (d.adc_bits - 1))
        self.hi = 2 ** (d.adc_bits - 1) - 1
        self.noise_rms = d.noise_m_s2_rms if noise else 0.0
        self.rng = np.random.default_rng(seed)
        n = len(self.sens)
        self.sos = d.anti_alias_sos(fs_hz) if anti_alias else None
        if self.sos is not None:
            # imported here, when the chain is made: only a simulator filters (a replay reads
            # its rig and never makes one), and a paced device must not stall 0.5 s at its
            # first block importing scipy.signal
            import scipy.signal

            self._sosfilt = scipy.signal.sosfilt
            self.zi = np.zeros((self.sos.shape[0], n, 2))
        self.clipped = np.zeros(n, dtype=np.int64)

    def process(self, acc: np.ndarray) -> np.ndarray:
        """Turn accelerations (m/s^2), shape (n_channels, n), into int32 counts, same shape."""
        volts = acc * self.sens[:, None]
        if self.noise_rms > 0:
            volts += (self.noise_rms * self.sens)[:, None] * self.rng.standard_normal(acc.shape)
        if self.sos is not None:
            volts, self.zi = self._sosfilt(self.sos, volts, axis=1, zi=self.zi)
        counts = np.rint(volts / self.lsb_V)
        over = (counts < self.lo) | (counts > self.hi)
        if over.any():
            self.clipped += over.sum(axis=1)
            np.clip(counts, self.lo, self.hi, out=counts)
        return counts.astype(np.int32)
