"""What the trial's own spectra say of the diagnosis band: lines that ring after the blows, above
the low-pass corner, which the diagnosis therefore does not compare.

The band's corner comes from the rig (:func:`~ramdaq.analysis.gap.trialdata.analysis_band`); the
data may ring above it (a mode the rig puts elsewhere, or one the band leaves out on purpose).
Nothing is cut silently: each such line is reported with where it rings and how strongly, against
its chance level. The statistic, per gage and frequency bin, is the ratio of the Welch power of the
first second after the blows (the ram's contact and ``skip_s`` left out) to the Welch power of the
pre-trigger windows, each averaged over the impacts, at full rate (before any decimation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.signal
import scipy.stats

from .. import filters

RESOLUTION_HZ = 8.0
"""Welch segment length 1 / RESOLUTION_HZ: a line's bin is 8 Hz wide (Hann), fine enough to tell
the rigs' modes apart above 50 Hz, and 8+ segments a second to average."""
STRONG = 25.0
"""Least power ratio (decay over pre-trigger) called ringing strongly: 5x the noise floor in
amplitude, the rig rule's own threshold for a mode worth comparing."""
DECAY_S = 1.0
"""Decay compared, s after the skip: a mode above 50 Hz with 1 % damping has fallen to 4 % of its
start within 1 s; a longer window would dilute it in the noise."""


@dataclass(frozen=True)
class RingingLine:
    """A line ringing after the blows above the diagnosis band.

    frequency_hz : the bin's centre, Hz (to within RESOLUTION_HZ / 2); the band rules read it.
    ratio : decay over pre-trigger power at the gage where it is largest.
    chance : the ratio noise alone exceeds with the stated false-alarm probability over all bins
        and gages (F distribution of two Welch averages).
    gages : gage numbers where the ratio passes both ``chance`` and :data:`STRONG`.
    peak_hz : the line's frequency between the bins, Hz, as printed
        (:func:`~ramdaq.analysis.filters.log_parabola_peak`).
    """

    frequency_hz: float
    ratio: float
    chance: float
    gages: tuple[int, ...]
    peak_hz: float = math.nan

    def text(self) -> str:
        f = self.peak_hz if math.isfinite(self.peak_hz) else self.frequency_hz
        return (f"{f:.0f} Hz on gage{'s' if len(self.gages) > 1 else ''} "
                f"{', '.join(map(str, self.gages))} ({self.ratio:.0f}x the pre-trigger power, "
                f"chance {self.chance:.1f}x)")

    def to_json(self) -> dict:
        return {"frequency_hz": round(self.frequency_hz, 1), "peak_hz": round(self.peak_hz, 1),
                "power_ratio": round(self.ratio, 1),
                "chance": round(self.chance, 2), "gages": list(self.gages)}


def welch_power(seg: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray, int]:
    """The frequencies (n_bins,) Hz, the Welch power (n_gages, n_bins) m^2/s^4/Hz of ``seg``
    (n_gages, n) and the number of segments averaged; gaps (NaN) read as 0 (0 segments when
    too short)."""
    nper = int(round(fs_hz / RESOLUTION_HZ))
    if seg.shape[1] < nper:
        return np.fft.rfftfreq(nper, 1 / fs_hz), np.zeros((seg.shape[0], nper // 2 + 1)), 0
    f, p = scipy.signal.welch(np.nan_to_num(seg), fs=fs_hz, nperseg=nper, axis=1)
    return f, p, 1 + (seg.shape[1] - nper) // (nper // 2)


def ringing_lines(decay: np.ndarray, n_decay: int, pre: np.ndarray, n_pre: int, f_hz: np.ndarray,
                  lo_hz: float, hi_hz: float, gage_numbers: tuple[int, ...],
                  false_alarm: float = 1e-3) -> list[RingingLine]:
    """Lines between ``lo_hz`` and ``hi_hz`` where the summed decay power ``decay`` (n_gages,
    n_bins; ``n_decay`` Welch segments in all) stands above the summed pre-trigger power ``pre``
    (``n_pre`` segments) by more than chance and by :data:`STRONG`, one per local maximum of the
    largest ratio over gages standing 2x above the dips either side, strongest first.

    Chance: with noise alone each sum is a chi-square of about one degree of freedom a Welch
    segment (Hann, half overlap: half its nominal 2, a conservative count), so the ratio of the
    means is F(n_decay, n_pre); its ``1 - false_alarm / (n_bins * n_gages)`` quantile (Bonferroni
    over the bins and gages looked at) is the level."""
    band = (f_hz > lo_hz) & (f_hz < hi_hz)
    if n_decay == 0 or n_pre == 0 or not band.any():
        return []
    ratio = (decay / n_decay) / np.maximum(pre / n_pre, np.finfo(float).tiny)
    chance = float(scipy.stats.f.isf(false_alarm / (band.sum() * ratio.shape[0]), n_decay, n_pre))
    level = max(chance, STRONG)
    top = np.where(band, ratio.max(axis=0), 1.0)
    # one line a peak standing at least 2x above the dip to the next (a damped mode's flat top
    # over a few bins is one line, not several)
    peaks, _ = scipy.signal.find_peaks(np.log(np.maximum(top, 1e-300)), height=math.log(level),
                                       prominence=math.log(2.0))
    total = decay.sum(axis=0)
    out = [RingingLine(float(f_hz[k]), float(top[k]), chance,
                       tuple(int(gage_numbers[g]) for g in np.flatnonzero(ratio[:, k] > level)),
                       filters.log_parabola_peak(f_hz, total, k))
           for k in peaks]
    return sorted(out, key=lambda r: -r.ratio)


def decay_window(onset_s: float, skip_s: float, post_s: float) -> tuple[float, float]:
    """The decay compared for ringing, s: from ``skip_s`` after the onset, :data:`DECAY_S` long
    (or to the end of the decay, ``post_s``)."""
    return onset_s + skip_s, onset_s + min(post_s, skip_s + DECAY_S)


def guard_s(fs_hz: float) -> float:
    """How long before an onset the pre-trigger window stops, s: one Welch segment, so the
    trigger's onset pick (a few samples late or early) leaves no blow in it."""
    return max(1.0 / RESOLUTION_HZ, 8 / fs_hz) if math.isfinite(fs_hz) else 0.0
