"""A trial cut into the pieces the gap diagnosis compares: one segment per impact, decimated.

Every impact ``j`` gets a segment from ``pre_s`` before its onset to the end of its decay (the
same length for all, so the segments stack into one array). Three windows of a segment are
compared separately: ``pre`` (before the onset: what the hull does on its own), ``early`` (the
first third of the decay after the ram has let go) and ``late`` (the rest).

The data are low-passed with a zero-phase Butterworth (``sosfiltfilt``, so no phase error) and
decimated to a rate about 2.5x the low-pass corner, which sits between the highest mode worth
comparing and the next one (:func:`analysis_band`, from the rig, its cut widened by the rig's own
+-25 % uncertainty so a field rig's error does not move it to another mode). The forward model
corrects each kept mode's amplitude by the low-pass's ``|H|^2`` at its frequency. What the
trial's noise is comes from the pre windows. What the data show ringing above the corner is
reported (``TrialData.ringing_above``), not compared -- unless asked for the data's band
(``prepare(..., data_band=True)``): the corner is then widened to take in the lines the trial
rings with on several gages (:func:`data_corner`), which ``ramdaq gap`` asks for where the modes
there show a structural effect (``modal_level.structure_above``).

Shapes: ``x`` is (n_segments, n_gages, n_samples) in m/s^2, gages in DAQ channel order.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
import scipy.signal

from ..model.response import ambient_gage_amplitudes, impact_amplitudes, modal_form, predominant_mode
from ..model.rig import Rig
from ..model.structure import build_model
from ..onset import BLOW_WINDOW_S, band_energy_ratio
from .ringing import RESOLUTION_HZ, RingingLine, decay_window, guard_s, ringing_lines, welch_power
from .signal_checks import DeclaredLine

DEC_ORDER = 8
"""Order of the decimation low-pass (applied forward and back: 16 in magnitude)."""
SMEAR_CYCLES = 8.0
"""How far (in periods of the low-pass corner) the zero-phase low-pass spreads the ram's
impulsive content either side of the onset: measured, noise-free, the residual of the exact
model is above 1 % of the noise 15 samples (6.8 periods) after a blow; windows keep clear."""


@dataclass(frozen=True)
class Windows:
    """Sample slices of a segment: ``pre`` before the onset, ``early``/``late`` of the decay.
    ``skip`` samples after the onset are left out (the ram's contact and the low-pass's smear)."""

    pre: slice
    early: slice
    late: slice

    def items(self) -> list[tuple[str, slice]]:
        return [("pre", self.pre), ("early", self.early), ("late", self.late)]


@dataclass
class TrialData:
    """A trial ready for the gap diagnosis.

    Attributes
    ----------
    rig : Rig
        The nominal rig (its ``[[ambient]]`` entries removed: a steady tone is an effect to find).
    x : ndarray (n_seg, n_gages, n_s)
        Decimated accelerations, m/s^2; NaN where the stream had a gap.
    fs_hz : float
        Decimated sample rate, Hz.
    fs_full_hz : float
        The recording's own rate, Hz.
    seg_t0_s : ndarray (n_seg,)
        Time of each segment's first sample, s from the stream's start.
    onsets_s : ndarray (n_seg,)
        Impact onsets, s from the stream's start (segment j holds impact j).
    windows : Windows
    lowpass_hz : float
        Corner of the decimation low-pass, Hz.
    fitted : ndarray (n_seg,) bool
        Impacts the calibration may use; the others are held out.
    clip : ndarray (n_seg, n_gages) int
        Samples at the ADC rails (full rate) in each segment, when the rails are known, else 0.
    flat : ndarray (n_seg, n_gages) int
        Runs of >= 3 equal extreme samples at full rate (a clipped channel without known rails).
    peak_full : ndarray (n_seg, n_gages)
        Largest |x| at full rate in each segment, m/s^2.
    """

    rig: Rig
    x: np.ndarray
    fs_hz: float
    fs_full_hz: float
    seg_t0_s: np.ndarray
    onsets_s: np.ndarray
    windows: Windows
    lowpass_hz: float
    fitted: np.ndarray
    clip: np.ndarray
    flat: np.ndarray
    peak_full: np.ndarray
    gage_numbers: tuple[int, ...] = field(default=())
    dropped_onsets_s: list[float] = field(default_factory=list)
    """Trigger events too soon after the previous impact to compare (s)."""
    ringing_above: list[RingingLine] = field(default_factory=list)
    """Lines the data show ringing after the blows above ``lowpass_hz`` (full rate, against the
    pre-trigger windows): not compared, said so (:mod:`~ramdaq.analysis.gap.ringing`)."""
    rig_lowpass_hz: float = float("nan")
    """The band's top the rig alone gives, Hz: its corner (:func:`analysis_band`), or half the
    rate where that corner leaves nothing to decimate (as ``lowpass_hz``); ``lowpass_hz`` is
    above it only where the data's band was asked for and they ring above it (:func:`data_corner`)."""
    decay_cut: str | None = None
    """Why every decay is compared over less than the length asked (``post_max_s``): the closest
    blows, or the record's end after the last; None when it is not cut."""

    @property
    def n_seg(self) -> int:
        return self.x.shape[0]

    @property
    def n_gages(self) -> int:
        return self.x.shape[1]

    @property
    def n_s(self) -> int:
        return self.x.shape[2]

    @property
    def t_rel(self) -> np.ndarray:
        """Time of each sample relative to the segment's own onset, s, (n_seg, n_s)."""
        k = np.arange(self.n_s) / self.fs_hz
        return self.seg_t0_s[:, None] + k[None, :] - self.onsets_s[:, None]

    @property
    def valid(self) -> np.ndarray:
        """Samples that carry data, (n_seg, n_gages, n_s) bool."""
        return np.isfinite(self.x)

    def lowpass_gain(self, f_hz: np.ndarray) -> np.ndarray:
        """Power gain ``|H(f)|^2`` of the zero-phase decimation low-pass at ``f_hz``."""
        if self.fs_hz >= self.fs_full_hz:
            return np.ones_like(np.asarray(f_hz, dtype=float))
        h = sos_response(_lowpass(self.lowpass_hz, self.fs_full_hz), np.abs(f_hz), self.fs_full_hz)
        return np.abs(h) ** 2


def strip_ambient(rig: Rig) -> Rig:
    """The rig without its ``[[ambient]]`` tone: the nominal model the diagnosis starts from."""
    from dataclasses import replace
    return replace(rig, ambient=())


def declared_lines(rig: Rig) -> list[DeclaredLine]:
    """The steady lines ``rig`` declares (its ``[[ambient]]``), each with the amplitude the rig's
    model gives every gage, m/s^2, in DAQ channel order: what the data-only layer reports as the
    user's environment, present as declared, rather than as an ambient-tone effect. Empty for a
    rig without a declaration or without a structure (a channels-only rig)."""
    if not rig.ambient or rig.rudder is None:
        return []
    model = build_model(rig)
    rows = [model.gage_numbers.index(g.number) for g in rig.gages_by_channel()]
    return [DeclaredLine(a.frequency_hz, np.abs(ambient_gage_amplitudes(model, a.hull_mode, a.frequency_hz,
                                                                     a.v_b_amplitude_m))[rows])
            for a in rig.ambient]


def sos_response(sos: np.ndarray, f_hz: np.ndarray, fs_hz: float) -> np.ndarray:
    """Complex response ``H(f)`` of the second-order sections ``sos`` (n_sections, 6) at
    ``f_hz`` (any shape, flattened to 1-d), Hz, for a sample rate ``fs_hz``.

    The same operations in the same order as ``scipy.signal.sosfreqz(sos, worN=f_hz, fs=fs_hz)``
    (``e^{-i w}``, each section's numerator and denominator by Horner, sections multiplied in
    turn), so the very same numbers, without its per-call checks: every modal prediction asks
    for the gain, and with them it took 200 us a call against 31 us (measured).
    """
    w = 2 * math.pi * np.atleast_1d(np.asarray(f_hz, dtype=float)) / float(fs_hz)
    z = np.exp(-1j * w)
    h = 1.0
    for b0, b1, b2, a0, a1, a2 in sos:
        # in place, as scipy does it: numpy rounds an in-place complex product differently
        h *= (b0 + (b1 + b2 * z) * z) / (a0 + (a1 + a2 * z) * z)
    return h


RIG_SPREAD = 0.25
"""How far a rig file's masses, inertias and stiffnesses may be off the structure's, as a
fraction (issue 17: a field rig is off by up to +-25 %; the benchmark's perturbed rigs)."""


def default_max_hz(predominant_hz: float, spread: float = RIG_SPREAD) -> float:
    """Highest mode the diagnosis compares unless told (Hz): 5x the rig's predominant rudder mode
    ``predominant_hz`` (the report's decrements are of the predominant modes; far higher modes
    cost samples and say little of the rudder on its stock), widened by how far a frequency
    ratio can be off when the rig's stiffnesses and masses are each off by up to ``spread``.

    A mode's frequency goes as sqrt(stiffness / mass), so with each within ``1 +- spread`` one
    frequency is off by up to sqrt((1 + s) / (1 - s)) and the ratio of two (a mode to the
    predominant one) by up to (1 + s) / (1 - s): 1.67 at +-25 %. A mode the structure has
    below 5x its predominant one may sit at up to 8.3x it in the rig; a cut at 5x the rig's
    ratio dropped such a mode in 11 of 170 dev scenarios (ALBACORE in water: 59.8 Hz at 4.6x
    13.0 Hz; the corner fell from 113.6 Hz to 26-29 Hz, the mode filtered out before any test
    saw it). The nominal rigs' next modes sit at 13.7-16.7x their predominant ones, so their
    bands do not move.
    """
    if not 0 <= spread < 1:
        raise ValueError(f"rig spread {spread}: a fraction from 0 to below 1")
    return 5.0 * predominant_hz * (1 + spread) / (1 - spread)


DATA_BAND_GAGES = 2
"""Least gages a line ringing above the rig's band must ring on to widen the band: a mode of the
structure moves its body's gages together, while a line on one gage alone is that channel's own
(a mount's resonance, a clipped gage's harmonics) and is reported, not compared."""
CORNER_OVER_LINE = 1.4
"""The widened band's low-pass corner over the highest line it takes in (the line's bin's upper
edge): the zero-phase order-8 Butterworth passes a line at 1/1.4 of its corner with an amplitude
gain |H|^2 = 1 / (1 + 1.4^-16) = 0.995, and the upper half of a split up to 25 % above the line
read (``modal_level.MAX_SPLIT_REL``) at 0.86; the forward model corrects each mode by the gain."""


def data_corner(corner_hz: float, lines: list[RingingLine], limit_hz: float, fs_hz: float) -> float:
    """The low-pass corner (Hz) of the band the data ask for: ``corner_hz`` (the rig's,
    :func:`analysis_band`) widened to :data:`CORNER_OVER_LINE` times the highest line ``lines``
    (:func:`~ramdaq.analysis.gap.ringing.ringing_lines`, above ``corner_hz``) rings on
    :data:`DATA_BAND_GAGES` gages or more, below ``limit_hz`` (0.8x the anti-alias corner); at most
    0.45x the rate ``fs_hz``. Unchanged when no line rings so: a mode the rig's band leaves out
    that the trial rings with after every blow is compared, so an effect on it (a split, a
    coupled hull mode, a shift) is seen by the layers, not only listed."""
    ring = [r.frequency_hz + RESOLUTION_HZ / 2 for r in lines
            if len(r.gages) >= DATA_BAND_GAGES and corner_hz < r.frequency_hz < limit_hz]
    if not ring:
        return corner_hz
    return float(min(max(corner_hz, CORNER_OVER_LINE * max(ring)), 0.45 * fs_hz))


@functools.lru_cache(maxsize=16)
def _lowpass(corner_hz: float, fs_hz: float) -> np.ndarray:
    """The decimation low-pass's second-order sections, designed once per corner and rate
    (every modal prediction asks for its gains); callers must not write to them."""
    return scipy.signal.butter(DEC_ORDER, corner_hz, fs=fs_hz, output="sos")


def analysis_band(rig: Rig, fs_hz: float, *, max_hz: float | None = None) -> tuple[float, list[float]]:
    """Low-pass corner (Hz) and the nominal model's modes (Hz) worth comparing.

    A mode is worth comparing when a nominal blow gives it an acceleration at some gage of at
    least 5x the noise floor and it lies below 0.8x the anti-alias corner and below ``max_hz``
    (default :func:`default_max_hz`: 5x the predominant mode of the rudder gages, widened by the
    rig's own uncertainty). The corner sits at
    the geometric mean of the highest such mode and the next mode (or the anti-alias corner).
    """
    form = modal_form(build_model(rig))
    f = form.eigenvalues.imag / (2 * math.pi)
    imp = rig.impact
    amp = impact_amplitudes(form, imp.peak_force_N, imp.duration_s, imp.location_m, imp.direction)
    acc = amp * np.abs(form.eigenvalues)[None, :] ** 2
    limit = 0.8 * min(rig.daq.anti_alias_hz, fs_hz / 2)
    if max_hz is None:
        k = predominant_mode(form, imp.peak_force_N, imp.duration_s, imp.location_m, imp.direction)
        max_hz = default_max_hz(float(f[k]))
    limit = min(limit, max_hz)
    keep = [i for i in range(len(f)) if f[i] < limit and acc[:, i].max() >= 5 * rig.daq.noise_m_s2_rms]
    if not keep:
        keep = [int(np.argmax(acc.max(axis=0)))]
    top = max(f[i] for i in keep)
    above = [fi for fi in f if fi > top * 1.05]
    nxt = min(above + [rig.daq.anti_alias_hz, fs_hz / 2])
    corner = min(math.sqrt(top * nxt), 0.45 * fs_hz)
    return corner, [float(f[i]) for i in keep]


@dataclass(frozen=True)
class ScaledCounts:
    """A trial kept as its converter's counts, read a window at a time: ``counts`` (n_gages, n)
    integers (int16 when they fit: a quarter of float64's memory), ``scale`` (n_gages,) SI per
    count, ``missing`` (k, 2) column ranges ``[a, b)`` the stream never delivered (NaN when read).
    The values are exactly ``counts * scale`` (as :meth:`ramdaq.drivers.block.Block.values`)."""

    counts: np.ndarray
    scale: np.ndarray
    missing: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))

    @property
    def shape(self) -> tuple[int, int]:
        return self.counts.shape

    def window(self, a: int, b: int) -> np.ndarray:
        """Columns ``a:b`` in SI units (m/s^2), float64 (n_gages, b - a), NaN where missing."""
        x = self.counts[:, a:b] * self.scale[:, None]
        m = self.missing
        for m0, m1 in m[(m[:, 0] < b) & (m[:, 1] > a)] if len(m) else ():
            x[:, max(m0, a) - a: min(m1, b) - a] = np.nan
        return x

    def full(self) -> np.ndarray:
        """The whole trial in SI units, float64 (n_gages, n), NaN where missing."""
        return self.window(0, self.shape[1])


class _ArrayWindows:
    """An in-memory trial (n_gages, n) read as :class:`ScaledCounts` is (views, not copies)."""

    def __init__(self, x: np.ndarray) -> None:
        self.x = np.asarray(x, dtype=float)
        self.shape = self.x.shape

    def window(self, a: int, b: int) -> np.ndarray:
        return self.x[:, a:b]


def _windows(x: ScaledCounts | np.ndarray) -> ScaledCounts | _ArrayWindows:
    """A trial, counts or an array (n_gages, n) in m/s^2, read a window at a time."""
    return x if isinstance(x, ScaledCounts) else _ArrayWindows(x)


def energy_added(data: ScaledCounts | np.ndarray, fs_hz: float, onsets_s: np.ndarray) -> np.ndarray:
    """Per onset, :func:`~ramdaq.analysis.onset.band_energy_ratio` of the gages over the
    :data:`~ramdaq.analysis.onset.BLOW_WINDOW_S` after it against as long a window before it (at
    most half the time since the onset before); NaN where there is no window of 8 samples
    before, or nothing in it. At most :data:`~ramdaq.analysis.onset.NO_BLOW_RATIO`: no blow (a
    mode that stops ringing by friction fires the trigger too)."""
    src = _windows(data)
    n = src.shape[1]
    out = np.full(len(onsets_s), np.nan)
    for k, t in enumerate(onsets_s):
        i = int(round(t * fs_hz))
        w = int(BLOW_WINDOW_S * fs_hz)
        if k:
            w = min(w, int((t - onsets_s[k - 1]) * fs_hz / 2))
        if w < 8 or i - w < 0 or i + w > n:
            continue
        x = src.window(i - w, i + w)
        out[k] = band_energy_ratio(x[:, :w], x[:, w:], fs_hz)
    return out


@functools.lru_cache(maxsize=16)
def filter_reach(corner_hz: float, fs_hz: float, rel: float = 1e-14) -> int:
    """Samples after which the decimation low-pass's impulse response (one pass) has fallen below
    ``rel`` of its peak for good, plus the zero-phase filter's edge padding: filtering a window
    this much wider than the samples kept on each side gives them as filtering the whole trial
    would, to ``rel`` of the signal (the edges' transients die out within it)."""
    sos = _lowpass(corner_hz, fs_hz)
    n = int(64 * fs_hz / corner_hz) + 64
    imp = np.zeros(n)
    imp[0] = 1.0
    h = np.abs(scipy.signal.sosfilt(sos, imp))
    above = np.flatnonzero(h > rel * h.max())
    pad = 3 * (2 * len(sos) + 1)
    return int(above[-1]) + 1 + pad


def prepare(x_full: np.ndarray | ScaledCounts, fs_hz: float, onsets_s: np.ndarray, rig: Rig, *,
            pre_s: float = 1.0, post_max_s: float = 4.0, held_out_every: int = 3,
            rails: tuple[float, float] | None = None, max_hz: float | None = None,
            data_band: bool = False, min_corner_hz: float | None = None) -> TrialData:
    """Cut, filter and decimate a trial, reading only the windows compared.

    Parameters
    ----------
    x_full : ndarray (n_gages, n) or ScaledCounts
        The trial at its recorded rate, m/s^2, DAQ channel order; NaN in gaps. Of
        :class:`ScaledCounts` (what ``ramdaq gap`` reads) only each segment's samples and the
        low-pass's reach either side (:func:`filter_reach`) are read and filtered: memory and
        time go with the impacts, not the recording's length. An array is filtered whole.
    fs_hz : float
        Its sample rate, Hz.
    onsets_s : ndarray (n_impacts,)
        Impact onsets (s from the first sample), e.g. from the trigger.
    rig : Rig
        Nominal rig.
    pre_s, post_max_s : float
        Pre-trigger window and longest decay compared, s. The decay stops ``pre_s`` before the
        next impact, so no segment overlaps the next one's pre window.
    held_out_every : int
        Every ``held_out_every``-th impact (the 3rd, 6th, ...) is held out of the calibration.
    rails : (low, high) in m/s^2 per gage row, or None
        ADC rails when known (``x`` equal to them is clipped).
    max_hz : float, optional
        Compare no mode above this frequency.
    data_band : bool
        Widen the rig's band to the lines the data ring with above it (:func:`data_corner`);
        else the rig's band, and those lines are listed only.
    min_corner_hz : float, optional
        The low-pass corner at the least (Hz): the band the trial's modes were identified and
        the rig calibrated on, which the calibrated rig's own band does not narrow.
    """
    rig = strip_ambient(rig)
    src = _windows(x_full)
    onsets = np.sort(np.asarray(onsets_s, dtype=float))
    if len(onsets) == 0:
        raise ValueError("no impacts to compare: the gap diagnosis needs at least one ram blow")
    n_g, n = src.shape
    corner, _ = analysis_band(rig, fs_hz, max_hz=max_hz)
    if min_corner_hz is not None:
        corner = max(corner, min_corner_hz)
    rig_corner = corner
    # an event too close after the previous one to leave a decay (a re-trigger on a tone, a
    # bounce the trigger split off) is not compared; its ringing stays in the data
    min_gap = pre_s + rig.impact.duration_s + SMEAR_CYCLES / corner + 0.25
    keep = [0]
    for j in range(1, len(onsets)):
        if onsets[j] - onsets[keep[-1]] >= min_gap:
            keep.append(j)
    dropped = [float(t) for j, t in enumerate(onsets) if j not in keep]
    onsets = onsets[keep]
    skip_s = rig.impact.duration_s + SMEAR_CYCLES / corner
    gaps_next = np.diff(np.append(onsets, n / fs_hz + pre_s))
    post_s = float(min(post_max_s, np.min(gaps_next) - pre_s))
    cut = _decay_cut(post_s, post_max_s, gaps_next - pre_s)
    if post_s < skip_s + 0.25:
        raise ValueError(f"impacts {np.min(gaps_next):.2f} s apart leave too short a decay to "
                         f"compare (need {pre_s + skip_s + 0.25:.2f} s)")
    gage_numbers = tuple(g.number for g in rig.gages_by_channel())
    limit = 0.8 * min(rig.daq.anti_alias_hz, fs_hz / 2)
    rig_q = max(1, int(fs_hz // (2.5 * corner)))
    above = _ringing_above(src, fs_hz, onsets, pre_s, skip_s, post_s, corner if rig_q > 1 else fs_hz / 2,
                           limit, gage_numbers)
    if data_band:
        corner = data_corner(corner, above, limit, fs_hz)
        skip_s = rig.impact.duration_s + SMEAR_CYCLES / corner
    q = max(1, int(fs_hz // (2.5 * corner)))
    fs_d = fs_hz / q
    above = [r for r in above if r.frequency_hz > (corner if q > 1 else fs_hz / 2)]
    n_pre = int(round(pre_s * fs_d))
    n_s = n_pre + int(round(post_s * fs_d))
    starts = np.rint((onsets - pre_s) * fs_hz).astype(int)
    starts = np.maximum(starts, 0) // q * q  # on the decimation grid
    if isinstance(src, ScaledCounts):
        x = np.stack([_segment(src, int(a), q, n_s, corner, fs_hz) for a in starts])
    else:    # a trial the caller holds whole already: filtered whole, as ever (to the last bit)
        x = _cut_whole(src.x, starts, q, n_s, corner, fs_hz)
    seg_t0 = starts / fs_hz
    k_on = np.rint((onsets - seg_t0) * fs_d).astype(int)
    n_skip = int(math.ceil(skip_s * fs_d))
    k0 = int(np.max(k_on)) + n_skip
    k_early = k0 + (n_s - k0) // 3
    n_smear = int(math.ceil(SMEAR_CYCLES / corner * fs_d)) if q > 1 else 2  # the filter reaches back
    windows = Windows(pre=slice(0, int(np.min(k_on)) - n_smear), early=slice(k0, k_early),
                      late=slice(k_early, n_s))
    fitted = np.array([(j + 1) % held_out_every != 0 for j in range(len(onsets))])
    if fitted.all() and len(onsets) > 1:
        fitted[-1] = False
    clip, flat, peak = _full_rate_stats(src, fs_hz, onsets, pre_s, post_s, rails)
    return TrialData(rig=rig, x=x, fs_hz=fs_d, fs_full_hz=fs_hz, seg_t0_s=seg_t0, onsets_s=onsets,
                     windows=windows, lowpass_hz=corner if q > 1 else fs_hz / 2, fitted=fitted,
                     clip=clip, flat=flat, peak_full=peak,
                     gage_numbers=gage_numbers, dropped_onsets_s=dropped, ringing_above=above,
                     rig_lowpass_hz=rig_corner if rig_q > 1 else fs_hz / 2, decay_cut=cut)


def _decay_cut(post_s: float, post_max_s: float, room_s: np.ndarray) -> str | None:
    """Why every impact's decay is compared over ``post_s`` rather than the ``post_max_s`` asked
    (s), from each impact's room ``room_s`` (s to the next impact's pre-trigger window, the last
    one's to the record's end); None when it is not cut."""
    if post_s >= post_max_s:
        return None
    k = int(np.argmin(room_s))
    why = ("the record ends" if k == len(room_s) - 1 else
           f"impact {k + 2}'s pre-trigger window begins") + f" {room_s[k]:.2f} s after impact {k + 1}"
    return (f"decays compared over {post_s:.2f} s (at most {post_max_s:g} s): {why}, and every "
            "impact is compared over the same length")


def _segment(src: ScaledCounts | _ArrayWindows, a: int, q: int, n_s: int, corner: float,
             fs_hz: float) -> np.ndarray:
    """One segment, (n_gages, n_s): every ``q``-th sample from column ``a`` of the trial
    low-passed at ``corner`` (zero-phase, when ``q > 1``), NaN past the stream's end and where
    a gap or the filter's reach around it leaves no data. The low-pass runs over the segment
    and :func:`filter_reach` either side only."""
    n = src.shape[1]
    b = a + q * (n_s - 1) + 1                       # one past the last sample kept
    m = filter_reach(corner, fs_hz) if q > 1 else 0
    lo, hi = max(0, a - m), min(n, b + m)
    xf = _lowpassed(src.window(lo, hi), q, corner, fs_hz)
    idx = a - lo + q * np.arange(n_s)
    out = xf[:, np.minimum(idx, hi - lo - 1)]
    out[:, idx >= n - lo] = np.nan                  # past the stream's end
    return out


def _lowpassed(w: np.ndarray, q: int, corner: float, fs_hz: float) -> np.ndarray:
    """``w`` (n_gages, n) low-passed at ``corner`` along its samples (zero-phase; when ``q > 1``
    only, as decimating by ``q`` needs), gaps as 0 while filtering: a gap's samples and the
    filter's reach around them are NaN in the result, which carry no data."""
    gaps = ~np.isfinite(w)
    xf = np.where(gaps, 0.0, w)
    if q > 1:
        xf = scipy.signal.sosfiltfilt(_lowpass(corner, fs_hz), xf, axis=1)
        if gaps.any():
            xf[_dilate(gaps, int(math.ceil(3 * fs_hz / corner)))] = np.nan
    return xf


def _cut_whole(x_full: np.ndarray, starts: np.ndarray, q: int, n_s: int, corner: float,
               fs_hz: float) -> np.ndarray:
    """The segments (n_seg, n_gages, n_s) of a trial held whole (n_gages, n), low-passed whole
    (:func:`_segment` does the same a window at a time, to 1e-14 of the signal)."""
    n = x_full.shape[1]
    xf = _lowpassed(x_full, q, corner, fs_hz)
    idx = starts[:, None] + q * np.arange(n_s)[None, :]
    x = xf[:, np.clip(idx, 0, n - 1)].transpose(1, 0, 2).copy()
    x[np.broadcast_to((idx >= n)[:, None, :], x.shape)] = np.nan   # past the stream's end
    return x


def _dilate(mask: np.ndarray, reach: int) -> np.ndarray:
    """``mask`` widened by ``reach`` samples either way along axis 1."""
    c = np.cumsum(np.pad(mask, ((0, 0), (reach + 1, reach))), axis=1)
    return (c[:, 2 * reach + 1:] - c[:, : -2 * reach - 1]) > 0


def _full_rate_stats(src: ScaledCounts | _ArrayWindows, fs_hz: float, onsets: np.ndarray,
                     pre_s: float, post_s: float, rails) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n_seg, n_g = len(onsets), src.shape[0]
    clip = np.zeros((n_seg, n_g), dtype=int)
    flat = np.zeros((n_seg, n_g), dtype=int)
    peak = np.zeros((n_seg, n_g))
    for j, t in enumerate(onsets):
        a = max(0, int((t - pre_s) * fs_hz))
        b = min(src.shape[1], int((t + post_s) * fs_hz))
        seg = src.window(a, b)
        ok = np.isfinite(seg)
        s = np.where(ok, seg, 0.0)
        peak[j] = np.abs(s).max(axis=1) if s.shape[1] else 0.0
        if rails is not None:
            lo, hi = rails
            clip[j] = ((s <= np.asarray(lo)[:, None]) | (s >= np.asarray(hi)[:, None])).sum(axis=1)
        # runs of three equal samples at the segment's extreme value: a converter at its rail
        top = peak[j][:, None]
        at = np.isclose(np.abs(s), top, rtol=0, atol=1e-12 + 1e-9 * top) & (top > 0)
        run = at[:, 2:] & at[:, 1:-1] & at[:, :-2] & (s[:, 2:] == s[:, :-2])
        flat[j] = run.sum(axis=1)
    return clip, flat, peak


def _ringing_above(src: ScaledCounts | _ArrayWindows, fs_hz: float, onsets: np.ndarray, pre_s: float,
                   skip_s: float, post_s: float, lo_hz: float, hi_hz: float,
                   gage_numbers: tuple[int, ...]) -> list[RingingLine]:
    """Lines ringing after the blows between ``lo_hz`` (the band's corner) and ``hi_hz``, from
    each impact's pre-trigger window and first decay second at full rate, Welch powers summed
    over the impacts (:func:`~ramdaq.analysis.gap.ringing.ringing_lines`): two short windows an
    impact, read apart, so memory stays that of one window."""
    if lo_hz >= hi_hz:
        return []
    sums, counts, f = [0.0, 0.0], [0, 0], None
    n = src.shape[1]
    for t in onsets:
        for i, (a, b) in enumerate(((t - pre_s, t - guard_s(fs_hz)), decay_window(t, skip_s, post_s))):
            ia, ib = max(0, int(a * fs_hz)), min(n, int(b * fs_hz))
            if ib > ia:
                f, p, k = welch_power(src.window(ia, ib), fs_hz)
                sums[i] = sums[i] + p * k
                counts[i] += k
    if f is None:
        return []
    return ringing_lines(sums[1], counts[1], sums[0], counts[0], f, lo_hz, hi_hz, gage_numbers)


def summed_spectrum(x: np.ndarray, fs_hz: float, nfft: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Hann-windowed power spectrum of ``x`` (..., n), zero-padded to ``nfft`` (default 8x the
    next power of two), summed over the leading axes: (frequencies Hz, power)."""
    n = x.shape[-1]
    nfft = nfft or 8 * int(2 ** math.ceil(math.log2(n)))
    P = np.abs(np.fft.rfft(x * np.hanning(n), n=nfft, axis=-1)) ** 2
    return np.fft.rfftfreq(nfft, 1 / fs_hz), P.reshape(-1, P.shape[-1]).sum(axis=0)
