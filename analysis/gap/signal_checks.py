"""Data-only checks of the recorded values themselves, at the recorded rate: flat tops
(clipping), lines before the blows (an ambient tone) and a second blow in the early window
(a double hit). Each returns :class:`~ramdaq.analysis.gap.datamodel.Finding` objects with the
statistic's chance level at :data:`~ramdaq.analysis.gap.datamodel.P_CHANCE`.

Shapes: ``x`` (n_g, n) m/s^2 at the recorded rate ``fs_hz``; ``onsets_s`` (n_imp,) s from its
first sample; ``numbers`` the gage number of each row.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.ndimage
import scipy.optimize
import scipy.signal
import scipy.special
import scipy.stats

from .contact import RHO_GRID, SecondBlow, contact_response, early_poles, one_blow, rss, second_blow
from .datamodel import DECAY_START_S, P_CHANCE, Finding, FreeModal, Layer, closure_of, held_out

CLIP_SPAN_S = 2.0
"""How long after each onset flat tops are looked for, s (the ringing is largest early)."""


def _longest_run(mask: np.ndarray) -> int:
    """Longest run of True in a 1-d mask."""
    if not mask.any():
        return 0
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return int(np.max(np.flatnonzero(d == -1) - np.flatnonzero(d == 1)))


def _step(v: np.ndarray) -> float:
    """The converter's step in ``v`` (the smallest nonzero difference between its values)."""
    u = np.unique(v[np.isfinite(v)])
    d = np.diff(u)
    d = d[d > 0]
    return float(d.min()) if d.size else 0.0


def flat_tops(x: np.ndarray, fs_hz: float, onsets_s: np.ndarray, numbers: Sequence[int], *,
              pre_s: float = 1.0) -> list[Finding]:
    """Gages whose blows run into flat tops: at each blow's extreme, of either sign, ``r``
    samples in a row equal to it; the statistic is the gage's excess ``S = sum (r - 1)`` over
    its ``n = 2 n_imp`` extremes (both signs of every blow).

    Under no clipping two neighbouring samples at a peak are equal when their difference, of
    standard deviation ``sqrt(2) sigma`` (``sigma`` the gage's noise before the blow, from first
    differences), falls within one converter step ``q``: at most ``p = q / (2 sqrt(pi) sigma)``
    (the difference's largest density times ``q``, whatever the signal's own step). A run of
    ``r`` holding the extreme has probability at most ``r p^(r-1)`` (``r`` places for the
    extreme in it); the extremes' noises are independent, so ``P(S >= s)`` is at most the sum of
    ``prod (k_i + 1) p^k_i`` over the splits of ``s`` into ``n`` parts:
    ``C(s + n - 1, n - 1) (1 + s / n)^n p^s``. The chance level is the least ``s`` where that
    reaches ``P_CHANCE / n_g`` (every gage searched), and at least :data:`FLAT_TOP_MIN`. Summed
    over the extremes, a rail that several blows reach counts every flat top, not only the
    longest: a clip level only the larger blows pass (the median blow overdriven 1.9x, the
    smallest not at all) tops several peaks with runs of 2-6 samples each, which the longest run
    alone reads near its single-peak chance level."""
    out = []
    n_peaks = 2 * len(onsets_s)
    for g, num in enumerate(numbers):
        runs, tops = [], []
        q = _step(x[g, : int(min(x.shape[1], (onsets_s[0] + CLIP_SPAN_S) * fs_hz))])
        sig = _pre_noise(x[g], fs_hz, onsets_s, pre_s)
        p = min(0.999, q / (2 * math.sqrt(math.pi) * sig)) if sig > 0 else 0.999
        for t in onsets_s:
            seg = x[g, int(t * fs_hz): int((t + CLIP_SPAN_S) * fs_hz)]
            seg = seg[np.isfinite(seg)]
            if seg.size == 0:
                continue
            for sgn in (1.0, -1.0):
                top = np.max(sgn * seg)
                runs.append(_longest_run(sgn * seg >= top - 0.5 * q))
                tops.append(top)
        excess = sum(max(k - 1, 0) for k in runs)
        if excess <= FLAT_TOP_MIN:
            continue                 # under the least level: the bound need not be sought
        level = flat_top_level(p, n_peaks, len(numbers))
        if excess > level:
            flat = [(t, k) for t, k in zip(tops, runs, strict=True) if k > 1]
            lvl = float(np.median([t for t, _ in flat]))
            out.append(Finding(
                check="clipping", layer=Layer.SENSOR, gages=(num,), statistic=float(excess),
                chance_level=level, size=lvl, unit="m/s^2", window="peaks",
                text=f"gage {num} is flat at {lvl:.4g} m/s^2 at its peaks: {len(flat)} of {len(runs)} "
                     f"peaks flat, runs of up to {max(runs)} equal samples ({excess} repeats; chance "
                     f"level {level:.1f})",
                null=f"equal samples at the blows' extremes, p(equal neighbours) = {p:.2g}"))
    return out


FLAT_TOP_MIN = 2.0
"""The least chance level of :func:`flat_tops`' excess, a floor as the single longest run's
least level of 3 samples was (two repeats); a gage at or under it is no finding whatever its
bound, which is then not computed (most gages: 70 ms of a trial's CPU)."""
FLAT_TOP_MAX = 100_000
"""The largest repeat count the chance level is sought up to (a coarse converter whose
neighbouring samples are mostly equal has none below it: no finding)."""


def flat_top_level(p: float, n_peaks: int, n_gages: int) -> float:
    """The chance level of :func:`flat_tops`' excess ``S`` over ``n_peaks`` extremes, each
    neighbour equal with probability at most ``p``: the least ``s`` with
    ``C(s + n - 1, n - 1) (1 + s / n)^n p^s <= P_CHANCE / n_gages``, at least :data:`FLAT_TOP_MIN`;
    infinite when none up to :data:`FLAT_TOP_MAX`."""
    n = max(n_peaks, 1)
    s = np.arange(1, FLAT_TOP_MAX + 1, dtype=float)
    log_b = (scipy.special.gammaln(s + n) - scipy.special.gammaln(s + 1) - scipy.special.gammaln(n)
             + n * np.log1p(s / n) + s * math.log(p))
    ok = np.flatnonzero(log_b <= math.log(P_CHANCE / max(n_gages, 1)))
    return max(FLAT_TOP_MIN, float(s[ok[0]])) if ok.size else math.inf


def _pre_noise(v: np.ndarray, fs_hz: float, onsets_s: np.ndarray, pre_s: float) -> float:
    """A gage's noise rms before its first blow, from first differences (a slow line or drift
    barely moves them), m/s^2."""
    b = int(onsets_s[0] * fs_hz) - int(0.01 * fs_hz)
    seg = v[max(0, b - int(pre_s * fs_hz)): b]
    seg = seg[np.isfinite(seg)]
    return float(np.std(np.diff(seg)) / math.sqrt(2)) if seg.size > 8 else 0.0


NOISE_RATIO_FLOOR = 4.0
"""A gage is called noisy only when its noise variance is at least this many times the median
gage's (twice the rms): accelerometers of one trial differ by less, but not by nothing."""


def dead_or_noisy(x: np.ndarray, fs_hz: float, onsets_s: np.ndarray, numbers: Sequence[int], *,
                  pre_s: float = 1.0) -> list[Finding]:
    """A dead gage (its record never leaves one value, or its blows move it by less than one
    converter step) and a noisy one: its noise variance before the blows (from first
    differences) over the median gage's. Under equal noise that ratio is F-distributed with
    about ``n`` and ``n`` degrees of freedom (``n`` samples each); the chance level is its
    ``P_CHANCE / n_g`` upper quantile, and at least :data:`NOISE_RATIO_FLOOR`."""
    out = []
    var = np.array([_pre_noise(v, fs_hz, onsets_s, pre_s) for v in x]) ** 2
    n = max(2, int((pre_s - 0.01) * fs_hz) - 1)
    level = max(NOISE_RATIO_FLOOR, float(scipy.stats.f.isf(P_CHANCE / len(numbers), n, n)))
    med = float(np.median(var))
    a, b = int(onsets_s[0] * fs_hz), int((onsets_s[0] + CLIP_SPAN_S) * fs_hz)
    moves = np.array([float(np.ptp(v[np.isfinite(v)])) if np.isfinite(v).any() else 0.0
                      for v in x[:, a:b]])
    for g, num in enumerate(numbers):
        if moves[g] <= _step(x[g]) and np.median(moves) > 0:
            out.append(Finding(check="dead", layer=Layer.SENSOR, gages=(num,), statistic=math.inf,
                               chance_level=1.0, size=moves[g], unit="m/s^2", window="early",
                               text=f"gage {num} is dead: its first blow moves it by {moves[g]:.3g} m/s^2 "
                                    "(one converter step or less)",
                               null="a live gage moves by more than one step in a blow"))
        elif med > 0 and var[g] / med > level:
            out.append(Finding(check="noisy", layer=Layer.SENSOR, gages=(num,),
                               statistic=float(var[g] / med), chance_level=level,
                               size=math.sqrt(var[g]), unit="m/s^2", window="pre",
                               text=f"gage {num} is noisy: {math.sqrt(var[g]):.3g} m/s^2 rms before the "
                                    f"blows, {math.sqrt(var[g] / med):.1f}x the median gage's",
                               null=f"F({n}, {n}) variance ratio"))
    return out


# ---------------------------------------------------------------- lines before the blows

@dataclass(frozen=True)
class DeclaredLine:
    """A steady line the rig declares (its ``[[ambient]]``): ``frequency_hz`` (Hz) and the
    amplitude it gives each gage, ``amplitude_m_s2`` (n_g,) m/s^2 in the rows' order."""

    frequency_hz: float
    amplitude_m_s2: np.ndarray


DECLARED_FACTOR = 2.0
"""A line is the declared one when its amplitude on the gages the declaration moves most is
within this factor of the declared amplitude, either way. The declared amplitude wanders by
itself: the truth generator's drive by +-15 % (1 sigma) over ~5 s, so that a blow's pre window
reads within 1.45x of it at 3 sigma; and it is turned into gage amplitudes through the rig's
model, whose masses and stiffnesses are a user's guess (the benchmark's perturbed rigs: up to
25 %, each). A line twice as strong as declared (or half) is no longer the environment the user
wrote down."""
DECLARED_SHARE = 0.5
"""The gages a declaration moves most: those with at least this share of its largest gage
amplitude (SAMPSON's 2.18 Hz: the hull's athwartship gages and the rudder riding with them)."""


def declared_match(fd: Finding, declared: Sequence[DeclaredLine], res_hz: float,
                   numbers: Sequence[int]) -> Finding:
    """``fd`` (an ``ambient_tone`` finding) as a ``declared_ambient`` note when a declared line
    is within ``res_hz`` (the pre window's resolution) of its frequency, on the gages that
    declaration moves most (:data:`DECLARED_SHARE`; at least half of them among the line's), at
    an amplitude there (median ratio over them) within :data:`DECLARED_FACTOR` of the declared
    one; ``fd`` itself otherwise."""
    f0 = fd.mode_hz[0]
    amps = {g: v for g in fd.gages for n, v, _ in fd.more if n == f"amp_gage_{g}"}
    for dl in declared:
        if abs(dl.frequency_hz - f0) > res_hz:
            continue
        a = np.asarray(dl.amplitude_m_s2, dtype=float)
        strong = [numbers[i] for i in np.flatnonzero(a >= DECLARED_SHARE * a.max())] if a.max() > 0 else []
        on = [g for g in strong if g in amps]
        if not strong or 2 * len(on) < len(strong):
            continue
        ratio = float(np.median([amps[g] / a[list(numbers).index(g)] for g in on]))
        if 1 / DECLARED_FACTOR <= ratio <= DECLARED_FACTOR:
            return Finding(
                check="declared_ambient", layer=fd.layer, gages=fd.gages, statistic=fd.statistic,
                chance_level=fd.chance_level, size=fd.size, unit=fd.unit, window=fd.window,
                mode_hz=fd.mode_hz, null=fd.null, more=fd.more + (("declared_ratio", ratio, "ratio"),),
                text=f"the declared ambient line ({dl.frequency_hz:.2f} Hz), present as the rig says: "
                     f"{f0:.2f} Hz before the blows at {ratio:.2f}x the declared amplitude on gages "
                     f"{', '.join(map(str, on))} (within {DECLARED_FACTOR:g}x; not an effect)")
    return fd


PRE_GUARD_S = 0.01
"""Left out just before each onset, s (the trigger's onset is good to a sample or two)."""
LINE_F_MIN_CYCLES = 2.0
"""The lowest line looked for has this many cycles in the pre window (below, a Hann window's
own leakage of the window's mean and slope, and a 1/f noise that the running median, cut off
at 0 Hz, reads too low: a clean truth-simulator trial showed a 1.5 Hz "line" just over the
chance level)."""
LINGER = 1e-4
"""A pole still rings in a pre window when this fraction of its amplitude is left there."""
LEVEL_HALF_WIDTH_HZ = 15.0
"""Half-width of the neighbourhood the noise level is read from, Hz: wide, as the noise's broad
shape is taken out first (:func:`line_level`), so the median reads enough independent values
(:func:`level_bins`) for a chance level near Gamma's."""
LEVEL_GUARD_RES = 2.0
"""Resolutions either side of a bin left out of its level: a Hann window's main lobe."""


def pre_windows(x: np.ndarray, fs_hz: float, onsets_s: np.ndarray, fm: FreeModal,
                pre_s: float) -> np.ndarray:
    """Each impact's pre window with the previous blows' ringing taken out: every pole of the
    free modal model that keeps more than :data:`LINGER` of its amplitude from the previous
    onset to the window is fitted with free amplitudes and removed, and so is the mean (an
    extrapolation over seconds leaves a lightly damped mode's ringing at a few % of itself).
    (n_imp, n_g, n_pre) m/s^2. A steady pole (a tone) stays; a steady tone at a lingering
    mode's frequency is removed with the mode."""
    n_pre = int((pre_s - PRE_GUARD_S) * fs_hz)
    tt = np.arange(n_pre) / fs_hz
    out = []
    for j, t in enumerate(onsets_s):
        a = max(0, int(round((t - pre_s) * fs_hz)))
        seg = x[:, a:a + n_pre]
        if seg.shape[1] < n_pre:
            seg = np.pad(seg, ((0, 0), (0, n_pre - seg.shape[1])))
        seg = np.nan_to_num(seg)
        since = a / fs_hz - onsets_s[j - 1] if j else math.inf
        keep = (np.exp(fm.poles.real * since) > LINGER) & ~fm.steady
        e = np.exp(np.multiply.outer(tt, fm.poles[keep]))
        A = np.column_stack([e.real, e.imag, np.ones(n_pre)])
        c, *_ = np.linalg.lstsq(A, seg.T, rcond=None)
        out.append(seg - (A @ c).T)
    return np.stack(out)


def pre_trigger_lines(x: np.ndarray, fs_hz: float, onsets_s: np.ndarray, numbers: Sequence[int],
                      fm: FreeModal, *, pre_s: float = 1.0,
                      declared: Sequence[DeclaredLine] = ()) -> list[Finding]:
    """Spectral lines before the blows: per gage, the Hann periodograms of every pre window
    (previous blows' decay taken out) summed over the impacts and divided by the local noise
    level (:func:`line_level`). With no line that ratio is Gamma(n_imp, 1) over a level read
    from ``m`` independent bins: ``n_imp F(2 n_imp, 2 n_imp m)``; its chance level is that
    distribution's ``P_CHANCE / (n_g n_bins)`` upper quantile (``n_bins`` independent
    frequencies searched). Gages whose lines fall within one resolution ``1/T`` are one finding;
    how steady it is: the spread of its amplitude over the blows.

    A line before the blows is there before the first blow too, where nothing rings: a line the
    first pre window (when the record holds it whole) does not show on half of its gages
    (:func:`_in_first`) is the blows' ringing (a lightly damped mode the free model misses:
    SAMPSON's 2.18 Hz hull mode loses a third of its amplitude from one blow to the next, and
    issue 17's clean SAMPSON trials read it as a tone in 12 of 20). Without a whole first
    window a line within ``1/T`` of a mode is dropped. A
    pre window the record's start cuts is left out.

    A line the rig declares (``declared``, its ``[[ambient]]``: :func:`declared_match`) is
    reported as check ``"declared_ambient"``: present as the rig says, a note, not an effect."""
    whole = np.asarray(onsets_s) >= pre_s          # a window cut by the record's start holds the blow
    if not whole.any():
        return []
    pw = pre_windows(x, fs_hz, onsets_s, fm, pre_s)[whole]
    n_imp, n_g, n = pw.shape
    nfft = 4 * n
    f = np.fft.rfftfreq(nfft, 1 / fs_hz)
    P = np.abs(np.fft.rfft(pw * np.hanning(n), n=nfft, axis=-1)) ** 2
    S = P.sum(axis=0)
    band = (f >= LINE_F_MIN_CYCLES * fs_hz / n) & (f <= 0.4 * fs_hz)
    level = line_level(S, f, band, n_imp, fs_hz)
    T = S / np.maximum(level, 1e-300)
    n_bins = int(band.sum() * n / nfft)
    m = level_bins(n / fs_hz)
    chance = n_imp * float(scipy.stats.f.isf(P_CHANCE / (n_g * max(1, n_bins)), 2 * n_imp, 2 * n_imp * m))
    T[:, ~band] = 0.0
    peaks = [(int(np.argmax(T[g])), g) for g in range(n_g) if T[g].max() > chance]
    groups = _group(peaks, f, fs_hz / n)
    if whole[0]:
        first = P[0] / np.maximum(level, 1e-300)
        groups = [grp for grp in groups if _in_first(first, T, grp, m, n_imp)]
    else:
        modes = fm.f_hz[~fm.steady]
        groups = [grp for grp in groups if np.min(np.abs(modes - f[grp[0][0]]), initial=np.inf) > fs_hz / n]
    found = [_line_finding(pw, fs_hz, f, T, grp, numbers, chance) for grp in groups]
    return [declared_match(fd, declared, fs_hz / n, numbers) for fd in found]


def level_bins(window_s: float) -> float:
    """Independent values the running median of :func:`line_level` reads a level from: the
    resolutions in its window outside the guard band, over a Hann window's noise bandwidth (1.5
    resolutions: neighbouring bins are correlated), times a median's efficiency against a mean
    (2/pi): 11.0 for a 1 s window. Measured on the truth generator's coloured noise (16 gages,
    four 1-s pre windows, 100 trials: 1600 gage maxima over the band), the maximum passed
    ``n F(2n, 2nm)``'s quantile for a per-gage probability of 10, 3 and 1 % in 10.4, 3.2 and
    0.8 % of the gages at m = 10 and 12.9, 4.9 and 1.4 % at m = 12; Gamma(n, 1)'s (a level
    known exactly) in 42, 20 and 10 %."""
    return max(1.0, 2 * (LEVEL_HALF_WIDTH_HZ * window_s - LEVEL_GUARD_RES) / 1.5 * 2 / math.pi)


FIRST_Q = 0.01
"""Probability that a gage's first pre window passes its own level with no line there."""


def _in_first(first: np.ndarray, T: np.ndarray, grp: list[tuple[int, int]], m: float, n_imp: int) -> bool:
    """Whether the first pre window shows the line of ``grp``: at the group's common peak, at
    least half of its gages' first-window periodograms over their level (Exp(1) with no line,
    over a level read from ``m`` bins: F(2, 2 n_imp m)) pass that distribution's
    :data:`FIRST_Q` upper quantile. Half the gages, not their sum: one gage whose level is read
    wrong (a SAMPSON double-hit trial: 54x on one gage, 0-3x on four) does not make the blows'
    ringing a tone; with no line, half of ``r`` gages pass together with probability
    ``C(r, r/2) FIRST_Q^(r/2)`` or less."""
    rows = sorted({g for _, g in grp})
    k = int(np.argmax(T[rows].sum(axis=0)))
    level = float(scipy.stats.f.isf(FIRST_Q, 2, 2 * n_imp * m))
    return 2 * int(np.sum(first[rows, k] > level)) >= len(rows)


TREND_ORDER = 5
"""Order of the polynomial in log frequency that takes the noise spectrum's broad shape (a 1/f
part, the anti-alias roll-off) out before the running median reads its local level."""
TREND_BINS = 40
"""Log-spaced bins over the band whose median log powers that polynomial is fitted to."""
TREND_CLIP = math.log(4.0)
"""A bin whose median power is more than this (natural log) above the fitted shape holds a line
and is left out of the next fit (a noise bin's median scatters by about +-0.5)."""


def line_level(S: np.ndarray, f: np.ndarray, band: np.ndarray, n_sum: int, fs_hz: float,
               res_hz: float | None = None) -> np.ndarray:
    """The noise level under a summed periodogram ``S`` (n_g, n_f) of ``n_sum`` windows: the
    mean power of one window at each frequency of ``band`` (n_f,) bool (1 elsewhere), so that
    with no line ``S / level`` is Gamma(n_sum, 1).

    The broad shape is taken out first (least squares of ``log S`` on a polynomial of order
    :data:`TREND_ORDER` in ``log f`` over the band, bins a line fills left out); the running
    median of what is left over +-:data:`LEVEL_HALF_WIDTH_HZ`, reflected at the band's ends,
    without the :data:`LEVEL_GUARD_RES` resolutions ``res_hz`` (default four padded bins, as
    :func:`pre_trigger_lines` pads) either side of the bin itself (a line's own Hann main lobe:
    a strong line at the band's edge, reflected, filled nearly half the window and read its own
    level; SAMPSON's 2.18 Hz), is divided by the median of Gamma(n_sum, 1).

    A running median of the raw spectrum read a 1/f noise's level too low at the band's low
    end (its window reached down to where the spectrum is 2-3x higher, and past 0 Hz onto
    padding) and, taken as an exponential's mean (over ``ln 2``), a sum of four windows' 1.3x
    too high: on coloured noise alone the lines' test passed its 1 % level in 9 % of the bins
    at 2-2.6 Hz and 0.1 % above 5 Hz (issue 17: a 1.77 Hz "line" at 1.1-1.2x its chance level
    on clean ALBACORE trials)."""
    level = np.ones_like(S)
    if band.sum() < 2 * TREND_ORDER + 2:
        return level
    lf = np.log(f[band])
    ls = np.log(np.maximum(S[:, band], 1e-300))
    res = 4 * float(f[1] - f[0]) if res_hz is None else res_hz
    # the shape read from the medians of log-spaced bins, each bin one point: the few bins of
    # the lowest octaves, where a 1/f part bends most, weigh as much as the many above
    fb = f[band]
    edges = [float(fb[0])]
    step = (fb[-1] / fb[0]) ** (1 / TREND_BINS)
    while edges[-1] <= fb[-1]:
        edges.append(edges[-1] * step)
    which = np.searchsorted(np.log(edges), lf, side="right") - 1
    pts = [(float(lf[which == b].mean()), np.median(ls[:, which == b], axis=1))
           for b in range(len(edges)) if np.any(which == b)]
    u0, du = lf.mean(), max(float(np.ptp(lf)), 1e-12)
    order = min(TREND_ORDER, len(pts) - 1)
    V = np.vander([(p[0] - u0) / du for p in pts], order + 1)        # (n_pts, order + 1)
    Y = np.stack([p[1] for p in pts])                                  # (n_pts, n_g)
    keep = np.ones(Y.shape, bool)
    # a bin a line fills (the lowest hold a few frequencies each) is left out for good: found
    # first against a quadratic, which cannot bend into a line at the band's edge, then against
    # the full order; the last fit is on the bins left
    for o in (min(2, order), min(2, order), order, order):
        Vo = V[:, order - o:]
        c = np.stack([np.linalg.lstsq(Vo[keep[:, g]], Y[keep[:, g], g], rcond=None)[0]
                      for g in range(Y.shape[1])], axis=1)
        if o < order:
            c = np.concatenate([np.zeros((order - o, c.shape[1])), c])
        nxt = keep & (Y - V @ c <= TREND_CLIP)
        keep = np.where((np.sum(nxt, axis=0) > order + 2)[None, :], nxt, keep)
    c = np.stack([np.linalg.lstsq(V[keep[:, g]], Y[keep[:, g], g], rcond=None)[0]
                  for g in range(Y.shape[1])], axis=1)
    trend = np.exp(np.vander((lf - u0) / du, order + 1) @ c).T      # (n_g, n_band)
    df = float(f[1] - f[0])
    guard = int(round(LEVEL_GUARD_RES * res / df))
    half = max(guard + 3, int(round(LEVEL_HALF_WIDTH_HZ / df)))
    W = S[:, band] / trend
    if W.shape[1] <= half:
        return level
    win = np.lib.stride_tricks.sliding_window_view(np.pad(W, ((0, 0), (half, half)), mode="reflect"),
                                                   2 * half + 1, axis=1)
    beside = np.r_[0:half - guard + 1, half + guard:2 * half + 1]     # the guard band left out
    # a gage at a time: the windows' copy is (n_band, n_beside) floats, 2.7 MB a gage on a
    # 10-minute trial's pre windows, where all gages at once held 3 x 43 MB at the gap's peak
    med = np.stack([np.median(win[g][:, beside], axis=-1) for g in range(W.shape[0])])
    level[:, band] = med * trend / float(scipy.stats.gamma.median(n_sum))
    return level


def _group(peaks: list[tuple[int, int]], f: np.ndarray, res_hz: float) -> list[list[tuple[int, int]]]:
    """Peaks (bin, gage) grouped by frequency: within ``res_hz`` of a group's first member."""
    groups: list[list[tuple[int, int]]] = []
    for k, g in sorted(peaks):
        for grp in groups:
            if abs(f[grp[0][0]] - f[k]) <= res_hz:
                grp.append((k, g))
                break
        else:
            groups.append([(k, g)])
    return groups


def _line_finding(pw: np.ndarray, fs_hz: float, f: np.ndarray, T: np.ndarray,
                  grp: list[tuple[int, int]], numbers: Sequence[int], chance: float) -> Finding:
    rows = sorted(g for _, g in grp)
    k = int(np.argmax(T[rows].sum(axis=0)))
    t = np.arange(pw.shape[-1]) / fs_hz
    # the peak refined on a grid 20x finer than the padded spectrum's, over every blow and gage,
    # two padded bins either way (half a resolution: the ratio's peak leans where the level falls)
    fine = f[k] + np.linspace(-2, 2, 81) * (f[1] - f[0])
    xw = pw[:, rows, :] * np.hanning(t.size)
    power = [np.sum(np.abs(xw @ np.exp(-2j * math.pi * fq * t)) ** 2) for fq in fine]
    f0 = float(fine[int(np.argmax(power))])
    B = np.column_stack([np.cos(2 * math.pi * f0 * t), np.sin(2 * math.pi * f0 * t)])
    c, *_ = np.linalg.lstsq(B, pw[:, rows, :].reshape(-1, t.size).T, rcond=None)
    amp = np.hypot(c[0], c[1]).reshape(pw.shape[0], len(rows))       # (n_imp, rows)
    with np.errstate(invalid="ignore", divide="ignore"):     # per gage over the blows
        spread = float(np.nanmedian(np.std(amp, axis=0) / np.mean(amp, axis=0)))
    gnums = tuple(numbers[g] for g in rows)
    stat = float(max(T[g, kk] for kk, g in grp))
    return Finding(
        check="ambient_tone", layer=Layer.EXCITATION, gages=gnums, statistic=stat,
        chance_level=chance, size=float(np.median(amp)), unit="m/s^2", window="pre",
        mode_hz=(f0,),
        text=f"a {f0:.2f} Hz line before the blows on gages {', '.join(map(str, gnums))}: "
             f"{np.median(amp):.3g} m/s^2 (spread over the blows {100 * spread:.0f} %)",
        null="summed Hann periodogram over its local level: Gamma(n_impacts, 1)",
        more=(("f_hz", f0, "Hz"), ("spread", spread, "fraction"),
              *((f"amp_gage_{g}", float(v), "m/s^2") for g, v in zip(gnums, np.median(amp, axis=0),
                                                                     strict=True))))


# ---------------------------------------------------------------- the early window

EARLY_FROM_S = 0.016
"""The early window starts this long after the onset, s: past a ram's contact, which the data
layer does not know (the modal family's run 3-8 ms against the rig's nominal 5 ms), and past
the ringing it leaves in modes above those the free modal model identified and in the
anti-alias filter. Inside that, the one-blow model's force shape is free: a "second blow" just
after a 12 ms start was the clean modal trials' own contact (issue 17: a double hit at 13 ms on a
clean trial; on the development seeds 2 of 6 clean modal trials were read so)."""
EARLY_TO_S = 0.2
"""The early window ends here, s after the onset: a second blow later than this is a new
impact for the trigger."""
SEEN_FOR_S = 0.05
"""A second blow is looked for up to this long before the early window's end: seen for less, its
response is not told from the first blow's decay misfit (a clean truth-simulator trial read its
last 20 ms as a second blow as large as the first)."""
MIN_BLOWS = 2
"""A second blow is reported when at least this many blows show it (all of them when fewer): a
rebound of the ram belongs to the set-up and repeats; a misfit of one blow's early response is
no double hit (as the map's gap must reproduce on held-out impacts)."""
DELAY_AGREE_S = 0.01
"""The contact-held measurement of a second blow (:func:`_measured`) is taken when its delay is
within this of the scan's: the scan reads the delay from where the modes' amplitudes step, which
a second contact's length blurs by a few ms, but the two see the same blow."""

RHO_MIN = 0.1
"""Least size of a second blow reported, relative to the first: a smaller "second blow" is what
a contact the model does not hold leaves in the early window (a 3-8 ms half-sine against the
nominal 5 ms, a flexible body's early response; issue 17's modal family read them as 1-6 %
second blows in every trial). Stated a priori: the double hits of both generators are 0.3x the
blow at size 1, and a ram's rebound worth naming is a tenth of its blow or more."""


EARLY_LINES = 3
"""Most lines of the early window outside the free modal model's poles that are looked at."""
LINE_GUARD = 0.24
"""An early line is looked at only this far (relative, and at least :data:`LINE_GUARD_HZ`) from
every free-model pole: nearer, it is that pole's own leakage (a Hann window's main lobe over the
early window is a few Hz wide), and it would beat with it in the homogeneity check's band
(twice :data:`~ramdaq.analysis.gap.homogeneity.LAW_BAND`)."""
LINE_GUARD_HZ = 2.0


def early_lines(x: np.ndarray, fs_hz: float, onsets_s: np.ndarray, fm: FreeModal,
                noise: np.ndarray | None = None,
                skip_rows: Sequence[int] = ()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lines of the early windows (:data:`EARLY_FROM_S` after each onset to the free model's
    decay window, :data:`~ramdaq.analysis.gap.datamodel.DECAY_START_S`) that the free modal
    model does not hold: modes that no longer ring in its decay window (a heavily damped mode, a
    mode friction stops). The :data:`EARLY_LINES` largest peaks of the early windows' Hann
    periodogram, with the free model's poles fitted and taken out, summed over the blows, each
    gage's over its noise variance (``noise`` (n_g,) rms, m/s^2, of ``x``'s rows; default the
    free model's residual, when ``x`` has its rows) and the number of blows, at least
    :data:`LINE_GUARD` from every free-model pole and below 0.45 ``fs_hz``, largest first, that
    pass the chance level of that ratio (Gamma(n_imp, 1) / n_imp, Bonferroni over gages and
    independent bins at ``P_CHANCE``). Returns (f_hz (L,), the ratio (n_g, L), the early
    windows' first samples (n_imp,))."""
    m = int((DECAY_START_S - EARLY_FROM_S) * fs_hz)
    a0 = np.rint((np.asarray(onsets_s) + EARLY_FROM_S) * fs_hz).astype(int)
    none = (np.empty(0), np.empty((x.shape[0], 0)), a0)
    if m < 16 or a0.min() < 0 or a0.max() + m > x.shape[1]:
        return none
    seg = np.nan_to_num(np.stack([x[:, a:a + m] for a in a0]))          # (n_imp, n_g, m)
    # the free model's modes taken out (free amplitudes per blow and gage): their side lobes
    # over so short a window would otherwise be the largest "lines" past the guard
    e = np.exp(np.multiply.outer(np.arange(m) / fs_hz, fm.poles))
    A = np.column_stack([e.real, e.imag, np.ones(m)])
    for j in range(len(a0)):
        c, *_ = np.linalg.lstsq(A, seg[j].T, rcond=None)
        seg[j] -= (A @ c).T
    win = np.hanning(m)
    nfft = 4 * m
    f = np.fft.rfftfreq(nfft, 1 / fs_hz)
    P = np.sum(np.abs(np.fft.rfft(seg * win, n=nfft, axis=-1)) ** 2, axis=0)
    rms = np.median(fm.noise, axis=0) if noise is None else np.asarray(noise)
    sig2 = np.maximum(rms**2, 1e-300)
    W = P / (sig2[:, None] * len(a0) * float(win @ win))
    W[list(skip_rows)] = 0
    S = W.max(axis=0)
    ok = (f > 0) & (f < 0.45 * fs_hz)
    for fk in fm.f_hz:
        ok &= np.abs(f - fk) >= max(LINE_GUARD * fk, LINE_GUARD_HZ)
    n_bins = max(1, int(ok.sum() * m / nfft))
    chance = float(scipy.stats.gamma.isf(P_CHANCE / (n_bins * x.shape[0]), len(a0))) / len(a0)
    peaks, _ = scipy.signal.find_peaks(np.where(ok, S, 0))
    picked: list[int] = []
    for i in peaks[np.argsort(-S[peaks])]:
        if len(picked) >= EARLY_LINES or S[i] <= chance:
            break
        if all(abs(f[i] - f[j]) >= LINE_GUARD * f[j] for j in picked):
            picked.append(int(i))
    return f[picked], W[:, picked], a0


def double_hits(x: np.ndarray, fs_hz: float, onsets_s: np.ndarray, numbers: Sequence[int],
                fm: FreeModal) -> list[Finding]:
    """A second blow of the ram in each impact's early window, at full rate: the free modal
    model's poles with each gage's amplitudes free, once as one blow and once with a second
    blow ``rho`` times the first ``d`` later (the same modal participation, shifted), every
    ``d`` on the sample grid and ``rho`` in :data:`RHO_GRID` tried. Statistic: the drop in the
    whitened residual sum of squares (each gage by its noise before the blows) over the one-blow
    residual's variance per degree of freedom (at least 1: an F-test, so a free modal model that
    misses part of the early response does not read its misfit as a second blow); under one blow
    it is about chi-square with 2 degrees of freedom, and its chance level is that distribution's
    ``P_CHANCE / (n_delays n_imp)`` upper quantile. Blows whose second blow is under
    :data:`RHO_MIN` of the first are not counted, and none is reported unless :data:`MIN_BLOWS`
    show one."""
    if fm.n_modes == 0:
        return []
    sig = np.array([_pre_noise(v, fs_hz, onsets_s, 1.0) for v in x])
    sig = np.maximum(sig, 1e-12)
    poles = fm.poles[~fm.steady]                   # a second blow does not start a tone again
    # with the early window's own poles (modes damped out before the free model's decay window,
    # which the scan would otherwise fit with a second blow: contact.early_poles)
    every = [np.concatenate([poles, early_poles(x, fs_hz, t, poles, sig)]) for t in onsets_s]
    best = [_double_hit_scan(x, fs_hz, t, p, sig) for t, p in zip(onsets_s, every, strict=True)]
    n_d = best[0][3]
    chance = float(scipy.stats.chi2.isf(P_CHANCE / (n_d * len(onsets_s)), 2))
    hits = [(j, b) for j, b in enumerate(best) if b[0] > chance and b[2] >= RHO_MIN]
    if len(hits) < min(MIN_BLOWS, len(onsets_s)):
        return early_double_hits(x, fs_hz, onsets_s, numbers, fm, poles, sig,
                                 [p[poles.size:] for p in every])
    stat = max(b[0] for _, b in hits)
    (d, rho, contact), found = _measured(x, fs_hz, onsets_s, poles, sig, hits)
    blows = ", ".join(str(j + 1) for j, _ in hits)
    held = f"; contact {1e3 * contact:.1f} ms" if math.isfinite(contact) else ""
    if math.isfinite(contact):
        # the second contact measured on every blow that shows it: held out as it was measured,
        # a half-sine of that length (the scan's second blow is an impulse, which a contact
        # still under way in the early window is not: issue 17, modal benchmark seed 556003, a
        # second blow 17.5 ms after the first, 1.5 ms into the window, closed 37 % held out as an
        # impulse, 97 % as the contact it is)
        closed, ci = contact_closure(x, fs_hz, onsets_s, poles, sig, found, chance)
    else:
        closed, ci = double_hit_closure(x, fs_hz, onsets_s, every, sig, best, chance)
    return [Finding(
        check="double_hit", layer=Layer.EXCITATION, gages=tuple(numbers), statistic=stat,
        closed_held=closed, closed_held_ci=ci,
        chance_level=chance, size=rho, unit="ratio", window="early",
        mode_hz=tuple(float(v) for v in fm.f_hz),
        text=f"a second blow {1e3 * d:.1f} ms after the first at {100 * rho:.0f} % of it "
             f"(blows {blows} of {len(onsets_s)}{held})",
        null="whitened residual drop, chi-square 2 dof, Bonferroni over delays and blows",
        more=(("delay_s", d, "s"), ("blows", float(len(hits)), "count"), ("contact_s", contact, "s")))]


def early_double_hits(x: np.ndarray, fs_hz: float, onsets_s: np.ndarray, numbers: Sequence[int],
                      fm: FreeModal, poles: np.ndarray, sig: np.ndarray,
                      extra: Sequence[np.ndarray] | None = None) -> list[Finding]:
    """A second blow before the scan's early window starts (:data:`EARLY_FROM_S`): there its
    response from the window's start on is the first blow's modes with other amplitudes, which
    the scan's free amplitudes absorb whole (issue 17: a second blow 13.0 ms after the first at
    45 % was not found). Read with the contact held (:func:`~ramdaq.analysis.gap.contact.second_blow`
    from the onset, delays up to the scan's first): the first blow's amplitudes are pinned by
    its half-sine contact, so a second contact that starts after it ends shows as the step in
    every mode's amplitude it makes. Statistic: the residual drop over the two-blow residual's
    variance per degree of freedom (at least 1, an F-test as the scan's), chi-square with 2
    degrees of freedom under one blow; chance level its ``P_CHANCE / (n_delays n_imp)`` upper
    quantile. A contact that is no exact half-sine leaves a misfit the statistic reads past its
    level (clean modal trials: 22-56x, at the least size tried, 1.4 %, or at 5-13 % right where
    the delays tried begin, the contact's end plus its separation), so, as for the scan, a blow
    counts only with a second blow of :data:`RHO_MIN` or more, and not flush against the first
    contact (starting as it ends plus :data:`~ramdaq.analysis.gap.contact.SEPARATION_S`: there a
    first contact that is no exact half-sine leaves its misfit; a true second blow that close is
    not told from it), and a finding needs :data:`MIN_BLOWS` of them.
    ``poles`` the free model's decaying poles (1/s); ``sig`` (n_g,) each gage's noise, m/s^2;
    ``extra`` each blow's early-window poles when already read
    (:func:`~ramdaq.analysis.gap.contact.early_poles`)."""
    until = EARLY_FROM_S + 2 / fs_hz                  # the scan's first delay
    extra = list(extra) if extra is not None else [None] * len(onsets_s)
    found = [second_blow(x, fs_hz, t, poles, sig, until_s=until, min_rho=RHO_MIN, extra=e)
             for t, e in zip(onsets_s, extra, strict=True)]
    n_d = max([m.n_delays for m in found if m is not None], default=1)
    chance = float(scipy.stats.chi2.isf(P_CHANCE / (n_d * len(onsets_s)), 2))
    hits = [(j, m) for j, m in enumerate(found)
            if m is not None and m.statistic > chance and m.rho >= RHO_MIN and not m.at_first]
    if len(hits) < min(MIN_BLOWS, len(onsets_s)):
        return []
    d, rho, contact = (float(np.median([getattr(m, k) for _, m in hits]))
                       for k in ("delay_s", "rho", "contact_s"))
    closed, ci = contact_closure(x, fs_hz, onsets_s, poles, sig, found, chance)
    blows = ", ".join(str(j + 1) for j, _ in hits)
    return [Finding(
        check="double_hit", layer=Layer.EXCITATION, gages=tuple(numbers),
        statistic=max(m.statistic for _, m in hits), closed_held=closed, closed_held_ci=ci,
        chance_level=chance, size=rho, unit="ratio", window="early",
        mode_hz=tuple(float(v) for v in fm.f_hz),
        text=f"a second blow {1e3 * d:.1f} ms after the first at {100 * rho:.0f} % of it "
             f"(blows {blows} of {len(onsets_s)}; contact {1e3 * contact:.1f} ms, read with the "
             "contact held)",
        null="whitened residual drop with the contact held, chi-square 2 dof, Bonferroni over delays "
             "and blows",
        more=(("delay_s", d, "s"), ("blows", float(len(hits)), "count"), ("contact_s", contact, "s")))]


def contact_closure(x: np.ndarray, fs_hz: float, onsets_s: np.ndarray, poles: np.ndarray,
                    sig: np.ndarray, found: Sequence[SecondBlow | None],
                    chance: float) -> tuple[float, tuple[float, float]]:
    """How much of the held-out blows' misfit by one contact
    (:func:`~ramdaq.analysis.gap.contact.one_blow`) a second contact read on the other blows
    closes (:func:`closure_of`): its delay, size and contact length the medians of ``found``'s
    (one per blow, :func:`~ramdaq.analysis.gap.contact.second_blow`) on the blows not held out
    beyond ``chance`` of :data:`RHO_MIN` or more not flush against the first, the first contact's
    start the held-out blow's own. Units: the gages of the held-out blows; the noise expectation
    one per sample less the gage's share of the fitted amplitudes."""
    held = held_out(len(onsets_s))
    seen = [m for j, m in enumerate(found) if not held[j] and m is not None
            and m.statistic > chance and m.rho >= RHO_MIN and not m.at_first]
    if not held.any() or not seen:
        return math.nan, (math.nan, math.nan)
    d, rho, c = (float(np.median([getattr(m, k) for m in seen])) for k in ("delay_s", "rho", "contact_s"))
    before, after, expect = [], [], []
    for j in np.flatnonzero(held):
        ob = one_blow(x, fs_hz, onsets_s[j], poles, sig)
        if ob is None:
            continue
        two = contact_response(ob.tau, ob.poles, c) + rho * contact_response(ob.tau - d, ob.poles, c)
        before += list(_rss_by_gage(contact_response(ob.tau, ob.poles, ob.contact_s), ob.y))
        after += list(_rss_by_gage(two, ob.y))
        expect += [ob.y.shape[0] - (2 * ob.poles.size + 1)] * ob.y.shape[1]
    return closure_of(np.array(before), np.array(after), np.array(expect, dtype=float))


def _measured(x: np.ndarray, fs_hz: float, onsets_s: np.ndarray, poles: np.ndarray, sig: np.ndarray,
              hits: list) -> tuple[tuple[float, float, float], list[SecondBlow | None]]:
    """The second blow's delay (s), size (ratio) and the contact length (s), median over the blows
    that showed it: measured with the contact held from the onset
    (:func:`~ramdaq.analysis.gap.contact.second_blow`), whose delay and size are read from the
    whole early window; where that finds no second blow of :data:`RHO_MIN` or more within
    :data:`DELAY_AGREE_S` of the scan's delay, the scan's own (delay, refined size; contact
    NaN). Also each blow's contact-held measurement where it agreed (None elsewhere), one per
    onset."""
    out, found = [], [None] * len(onsets_s)
    for j, b in hits:
        m = second_blow(x, fs_hz, onsets_s[j], poles, sig)
        if m is not None and m.rho >= RHO_MIN and abs(m.delay_s - b[1]) <= DELAY_AGREE_S:
            out.append((m.delay_s, m.rho, m.contact_s))
            found[j] = m
        else:
            out.append((b[1], _refined_size(x, fs_hz, onsets_s[j], poles, sig, b[1], b[2]), math.nan))
    d, rho, contact = (float(np.median([o[i] for o in out])) for i in range(3))
    return (d, rho, contact), found


def _double_hit_scan(x: np.ndarray, fs_hz: float, onset_s: float, poles: np.ndarray,
                     sig: np.ndarray) -> tuple[float, float, float, int]:
    """(best residual drop, its delay s, its size, delays tried) for one impact."""
    a = int(round((onset_s + EARLY_FROM_S) * fs_hz))
    b = int(round((onset_s + EARLY_TO_S) * fs_hz))
    y = (x[:, a:b] / sig[:, None]).T                                 # (N, n_g)
    if y.shape[0] < 16 or not np.all(np.isfinite(y)):
        return 0.0, float("nan"), float("nan"), 1
    tau = (a + np.arange(y.shape[0])) / fs_hz - onset_s
    e1 = np.exp(np.multiply.outer(tau, poles))                        # (N, K)
    rss0 = rss(e1, y)
    delays = np.arange(2, max(3, y.shape[0] - int(SEEN_FOR_S * fs_hz)))
    # every other delay first, then the neighbours of the best (the drop is smooth over a sample)
    coarse = [_drop_at(e1, y, tau, i, poles, rss0) for i in delays[::2]]
    i0 = int(delays[::2][int(np.argmax([c[0] for c in coarse]))])
    fine = [_drop_at(e1, y, tau, i, poles, rss0) for i in (i0 - 1, i0 + 1) if i in delays]
    drop, d, rho = max(coarse + fine, key=lambda c: c[0])
    # the drop is chi-square(2) in units of the residual's variance per sample: the noise's
    # (whitened to 1) when the one-blow model holds, larger where the free modal model misses
    # the structure's early response (modes it did not identify, a flexible body's model form
    # -- issue 17's modal family): read it in that variance, never below the noise's (F-test)
    dof = y.size - y.shape[1] * (2 * len(poles) + 1) - 2
    s2 = max(1.0, float(rss0 - drop) / max(dof, 1))
    return drop / s2, d, rho, len(delays)


def _drop_at(e1: np.ndarray, y: np.ndarray, tau: np.ndarray, i: int, poles: np.ndarray,
             rss0: float) -> tuple[float, float, float]:
    """(residual drop, delay s, size) of the best second blow at sample ``i`` of the window."""
    d = float(tau[i] - tau[0] + EARLY_FROM_S)
    e2 = np.zeros_like(e1)
    e2[i:] = np.exp(np.multiply.outer(tau[i:] - d, poles))
    by_rho = rss(e1[None] + RHO_GRID[:, None, None] * e2[None], y)     # (n_rho,)
    m = int(np.argmin(by_rho))
    return float(rss0 - by_rho[m]), d, float(RHO_GRID[m])


def _refined_size(x: np.ndarray, fs_hz: float, onset_s: float, poles: np.ndarray, sig: np.ndarray,
                  d: float, rho: float) -> float:
    """The second blow's size at delay ``d`` refined from the grid's ``rho`` by a bounded scalar
    minimisation of the residual between the grid's neighbours."""
    a = int(round((onset_s + EARLY_FROM_S) * fs_hz))
    b = int(round((onset_s + EARLY_TO_S) * fs_hz))
    y = (x[:, a:b] / sig[:, None]).T
    tau = (a + np.arange(y.shape[0])) / fs_hz - onset_s
    e1 = np.exp(np.multiply.outer(tau, poles))
    e2 = np.where((tau >= d - 0.5 / fs_hz)[:, None], np.exp(np.multiply.outer(tau - d, poles)), 0)
    step = RHO_GRID[1] / RHO_GRID[0]
    res = scipy.optimize.minimize_scalar(lambda r: float(rss(e1 + r * e2, y)),
                                         bounds=(rho / step, rho * step), method="bounded",
                                         options={"xatol": 1e-3 * rho})
    return float(res.x)


# ---------------------------------------------------------------- closures on held-out blows

CLIP_BLOCK_S = 0.1
"""The units of a clipping closure's bootstrap: stretches of this length of the held-out blows."""



def clip_closure(v: np.ndarray, fs_hz: float, onsets_s: np.ndarray,
                 fm: FreeModal) -> tuple[float, tuple[float, float]]:
    """How much of a clipped gage's misfit by the free modal model at its peaks a clipping at the
    rails read on the other blows closes (:func:`closure_of`), each blow held out in turn. Per
    blow, from ``EARLY_FROM_S`` after the onset to the free model's decay window's end, the
    free model's poles (each with free amplitudes, and a mean) are fitted to the record ``v``
    (m/s^2) as it is, and, with the correction, to the samples off the rails only, their
    prediction cut at the rails (the highest and lowest values of the other blows, less one
    converter step). Units: the :data:`CLIP_BLOCK_S` stretches that reach the rails (the
    finding's window, the peaks: a blow too weak to clip, or the stretches after its peaks,
    hold the model's own misfit of the early window, which no clipping explains); the noise
    expectation the gage's noise before the blows. NaN when no blow reaches the others' rails."""
    if len(onsets_s) < 2 or fm.n_modes == 0:
        return math.nan, (math.nan, math.nan)
    a0 = np.rint((np.asarray(onsets_s) + EARLY_FROM_S) * fs_hz).astype(int)
    n = int((DECAY_START_S - EARLY_FROM_S) * fs_hz) + fm.n_s
    if a0.min() < 0 or a0.max() + n > v.size:
        return math.nan, (math.nan, math.nan)
    seg = np.stack([v[a:a + n] for a in a0])
    q = _step(seg)
    e = np.exp(np.multiply.outer(np.arange(n) / fs_hz, fm.poles[~fm.steady]))
    A = np.column_stack([e.real, e.imag, np.ones(n)])
    sig2 = max(_pre_noise(v, fs_hz, onsets_s, 1.0) ** 2, 1e-300)
    blk = max(1, int(CLIP_BLOCK_S * fs_hz))
    m = n // blk * blk
    before, after = [], []
    for j, y in enumerate(seg):
        rest = np.delete(seg, j, axis=0)
        hi, lo = float(np.max(rest)) - q, float(np.min(rest)) + q
        free = (y < hi) & (y > lo)
        railed = (~free[:m]).reshape(-1, blk).any(axis=1)
        if not railed.any():
            continue
        c0, *_ = np.linalg.lstsq(A, y, rcond=None)
        c1, *_ = np.linalg.lstsq(A[free], y[free], rcond=None)
        r0, r1 = (y - A @ c0) ** 2, (y - np.clip(A @ c1, lo, hi)) ** 2
        before += list(r0[:m].reshape(-1, blk).sum(axis=1)[railed] / sig2)
        after += list(r1[:m].reshape(-1, blk).sum(axis=1)[railed] / sig2)
    return closure_of(np.array(before), np.array(after), np.full(len(before), float(blk)))


def double_hit_closure(x: np.ndarray, fs_hz: float, onsets_s: np.ndarray, poles: list[np.ndarray],
                       sig: np.ndarray, best: list, chance: float) -> tuple[float, tuple[float, float]]:
    """How much of the held-out blows' early-window misfit by one blow (the free model's and the
    early poles ``poles[j]`` of blow ``j``, whitened by each gage's noise ``sig``) a second blow
    read on the other blows closes (:func:`closure_of`): its delay and size the median of the
    scans (``best``, :func:`_double_hit_scan` per blow) of the blows not held out that show one
    beyond ``chance`` of :data:`RHO_MIN` or more. Units: the gages of the held-out blows; the
    noise expectation one per sample less the gage's share of the fitted amplitudes."""
    held = held_out(len(onsets_s))
    seen = [b for j, b in enumerate(best) if not held[j] and b[0] > chance and b[2] >= RHO_MIN]
    if not held.any() or not seen:
        return math.nan, (math.nan, math.nan)
    d, rho = float(np.median([b[1] for b in seen])), float(np.median([b[2] for b in seen]))
    before, after, expect = [], [], []
    for j in np.flatnonzero(held):
        a = int(round((onsets_s[j] + EARLY_FROM_S) * fs_hz))
        b = int(round((onsets_s[j] + EARLY_TO_S) * fs_hz))
        y = (x[:, a:b] / sig[:, None]).T
        if y.shape[0] < 16 or not np.all(np.isfinite(y)):
            continue
        tau = (a + np.arange(y.shape[0])) / fs_hz - onsets_s[j]
        e1 = np.exp(np.multiply.outer(tau, poles[j]))
        e2 = np.where((tau >= d - 0.5 / fs_hz)[:, None], np.exp(np.multiply.outer(tau - d, poles[j])), 0)
        before += list(_rss_by_gage(e1, y))
        after += list(_rss_by_gage(e1 + rho * e2, y))
        expect += [y.shape[0] - (2 * poles[j].size + 1)] * y.shape[1]
    return closure_of(np.array(before), np.array(after), np.array(expect, dtype=float))


def _rss_by_gage(e: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Each column's residual sum of squares of ``y`` (N, n_g) on the real basis of the complex
    columns ``e`` (N, K) and a constant (as :func:`~ramdaq.analysis.gap.contact.rss`), (n_g,)."""
    A = np.column_stack([e.real, e.imag, np.ones(e.shape[0])])
    Q, _ = np.linalg.qr(A)
    return np.sum(y**2, axis=0) - np.sum((Q.T @ y) ** 2, axis=0)
