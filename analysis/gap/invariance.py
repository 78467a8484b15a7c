"""Time invariance of a trial's measurement (issue 17, data-only layer): generic tests of what a
linear, time-invariant structure measured by fixed gages must show, against the free modal model
(:class:`~ramdaq.analysis.gap.datamodel.FreeModal`: poles shared by every gage and impact, free
shapes, each impact's amplitudes solved). Neither test names a library effect; a failure no
library check explains is "unexplained", with where and how big.

- :func:`gain_invariance` -- each gage's gain, impact by impact: with fixed gages every mode's
  amplitudes over the impacts and gages are one shape times one amplitude per impact (rank one).
  A gage whose entries move together over every mode, impact by impact, beyond their standard
  errors has a gain that changes between impacts (a constant gain is the library's
  ``gage_sensitivity``, absorbed in the free shape).
- :func:`line_persistence` -- a pole that does not decay within the decay windows must still be
  there in the next blow's pre window (a mode rings on by its own decay; an ambient line is there
  throughout). A line present after the blows and gone before the next is neither.

Shapes: ``x`` (n_g, n) m/s^2 at the recorded rate; ``numbers`` the gage number of each row.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import scipy.stats

from .datamodel import DECAY_START_S, P_CHANCE, Finding, FreeModal, Layer
from .signal_checks import EARLY_FROM_S, early_lines

MIN_ENTRY_SNR = 20.0
"""A shape entry enters the gain test when its amplitude is this many standard errors (as the
rigid-body checks' :data:`~ramdaq.analysis.gap.sensors.MIN_ENTRY_SNR`)."""
GAIN_FLOOR = 0.01
"""Relative scatter of an entry accepted on top of its standard error: the free model's shared
poles are estimated (a pole 1e-4 off moves an amplitude by a few 0.1 %), the noise is coloured
(the white-residual standard error is optimistic by up to ~2x at low frequency). Stated a priori,
twice the rigid-body checks' :data:`~ramdaq.analysis.gap.sensors.GAIN_FLOOR`."""
MAX_SHARE = 0.5
"""When more than this share of the gages fails the gain test, the rank-one model itself fails
(the structure is not linear: the homogeneity check's matter), not one gage's gain: no finding."""
ALS_STEPS = 8
"""Alternating least-squares steps of each mode's rank-one fit (from the SVD's start)."""

STEADY_LOSS = 0.05
"""A pole that loses less than this share of its amplitude over the decay window does not decay
(:data:`~ramdaq.analysis.gap.datamodel.STEADY_LOSS`)."""
PERSIST_FLOOR = 0.1
"""Relative error of a steady pole's amplitude carried from one decay window to the next blow's
pre window (its decrement is known to a few % of the window's loss; a line's level may wander
by a few %). Stated a priori."""
PRE_GUARD_S = 0.01
"""Left out just before each onset, s."""
MIN_CYCLES = 2.0
"""A pole is read in a pre window only with this many cycles in it."""


# ------------------------------------------------------------------ gain, impact by impact


def rank_one(a: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted rank-one fit ``a ~ c phi^T`` of one mode's amplitudes ``a`` (n_imp, n_g) complex
    with weights ``w`` (n_imp, n_g) (1/variance, 0 for an entry left out): ``c`` (n_imp,),
    ``phi`` (n_g,), by alternating least squares from the leading singular vectors."""
    u, s, vh = np.linalg.svd(np.where(w > 0, a, 0), full_matrices=False)
    c, phi = u[:, 0] * s[0], vh[0]
    for _ in range(ALS_STEPS):
        c = np.sum(w * np.conj(phi) * a, axis=1) / np.maximum(np.sum(w * np.abs(phi) ** 2, axis=1), 1e-300)
        phi = np.sum(w * np.conj(c)[:, None] * a, axis=0) / np.maximum(
            np.sum(w * np.abs(c)[:, None] ** 2, axis=0), 1e-300)
    return c, phi


def impact_gains(fm: FreeModal, rows: Sequence[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each gage's relative gain change impact by impact, common to every mode it measures:
    ``rho`` (n_imp, n_g) the weighted mean over the modes of ``Re(a / (c phi)) - 1`` (first
    order in the log-gain), ``var`` its variance (inf where no mode measures it), and ``misfit``
    (n_g,) the chi-square of the modes' departures from that common gain (dof: entries less
    impacts). Only ``rows`` and the modes that decay (not ``fm.steady``) enter."""
    n_imp, n_g, K = fm.amp.shape
    num, den = np.zeros((n_imp, n_g)), np.zeros((n_imp, n_g))
    parts = []
    for k in np.flatnonzero(~fm.steady):
        a, se = fm.amp[:, :, k], fm.amp_se[:, :, k]
        w = np.zeros((n_imp, n_g))
        w[:, list(rows)] = 1.0 / np.maximum(se[:, list(rows)], 1e-300) ** 2
        c, phi = rank_one(a, w)
        pred = np.outer(c, phi)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):   # a row left out: 0 / 0
            r = np.real(a / np.where(np.abs(pred) > 0, pred, np.nan)) - 1.0
            s2 = (se / np.maximum(np.abs(pred), 1e-300)) ** 2 + GAIN_FLOOR**2
        ok = (w > 0) & (np.abs(pred) >= MIN_ENTRY_SNR * se) & np.isfinite(r)
        r, s2 = np.where(ok, r, 0.0), np.where(ok, s2, np.inf)
        num += r / s2
        den += 1.0 / s2
        parts.append((r, s2, ok))
    var = np.where(den > 0, 1.0 / np.maximum(den, 1e-300), np.inf)
    rho = num * np.where(den > 0, var, 0.0)
    misfit = np.zeros(n_g)
    for r, s2, ok in parts:
        misfit += np.sum(np.where(ok, (r - rho) ** 2 / s2, 0.0), axis=0)
    return rho, var, misfit


def gain_invariance(fm: FreeModal, numbers: Sequence[int], skip_rows: Sequence[int] = ()) -> list[Finding]:
    """Gages whose gain changes between impacts, the same over every mode: per gage the
    chi-square of its common gain changes (:func:`impact_gains`) about their weighted mean, over
    the impacts it was measured on (dof: those less one). Null: a fixed gage on a linear
    structure, chi-square with that dof; chance level its ``P_CHANCE / n_g`` upper quantile
    (Bonferroni over the gages). A gage passes only when the common gain explains its
    departures better than the modes' scatter about it (the gain chi-square above the misfit's
    own), and the check reports nothing when more than :data:`MAX_SHARE` of the gages pass
    (the rank-one model fails as a whole). One finding with every gage that passes."""
    n_imp, n_g, _ = fm.amp.shape
    rows = [i for i in range(n_g) if i not in set(skip_rows)]
    if n_imp < 3 or (~fm.steady).sum() == 0 or len(rows) < 3:
        return []
    rho, var, misfit = impact_gains(fm, rows)
    hits = []
    for g in rows:
        ok = np.isfinite(var[:, g])
        dof = int(ok.sum()) - 1
        if dof < 2:
            continue
        w = 1.0 / var[ok, g]
        m = float(np.sum(w * rho[ok, g]) / np.sum(w))
        chi2 = float(np.sum(w * (rho[ok, g] - m) ** 2))
        level = float(scipy.stats.chi2.isf(P_CHANCE / n_g, dof))
        excess = chi2 - dof
        if chi2 > level and excess > misfit[g] - max(1, n_imp * ((~fm.steady).sum() - 1)):
            hits.append((chi2 / level, chi2, level, g, rho[ok, g] - m, dof))
    if not hits or len(hits) > MAX_SHARE * len(rows):
        return []
    best = max(hits)
    _, chi2, level, g, dev, dof = best
    gages = tuple(numbers[h[3]] for h in sorted(hits, reverse=True))
    span = float(np.ptp(dev))
    trend = float(np.corrcoef(np.arange(dev.size), dev)[0, 1]) if dev.size > 2 and np.ptp(dev) > 0 else 0.0
    text = (f"gage {numbers[g]}'s gain changes between impacts by {100 * span:.1f} % (the same over every "
            f"mode it measures; {'drifting with time' if abs(trend) >= 0.8 else 'not steadily'}, "
            f"correlation with the impact's order {trend:+.2f}): a fixed gain would be one shape; "
            "no library effect changes a gage's gain during a trial")
    more = tuple(("gain_change_gage", float(numbers[h[3]]), "number") for h in hits)
    return [Finding("gain_invariance", Layer.SENSOR, gages, chi2, level, span, "relative gain change", text,
                    window="decay", mode_hz=tuple(float(f) for f in fm.f_hz[~fm.steady]),
                    null=(f"chi-square, {dof} dof: a fixed gage's common gain over the impacts about its "
                          f"mean (relative floor {GAIN_FLOOR}); Bonferroni over {n_g} gages"),
                    more=more + (("time_correlation", trend, "1"),))]


# ------------------------------------------------------------------ lines after the blows


def _line_amplitude(seg: np.ndarray, fs_hz: float, f_hz: float,
                    others: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude (n_g,) of a sinusoid at ``f_hz`` in ``seg`` (n_g, n) fitted with a constant, a
    slope and the free model's other poles ``others`` (1/s, complex: the blows' ringing still
    there), and its standard error (white residual)."""
    n = seg.shape[1]
    t = np.arange(n) / fs_hz
    e = np.exp(np.multiply.outer(t, others))
    A = np.column_stack([np.cos(2 * math.pi * f_hz * t), np.sin(2 * math.pi * f_hz * t),
                         np.ones(n), t - t.mean(), e.real, e.imag])
    c, *_ = np.linalg.lstsq(A, seg.T, rcond=None)
    res = seg.T - A @ c
    s = np.sqrt(np.sum(res**2, axis=0) / max(1, n - A.shape[1]))
    se = s * math.sqrt(2.0 / n)
    return np.hypot(c[0], c[1]), se


def line_persistence(x: np.ndarray, fm: FreeModal, onsets_s: np.ndarray, numbers: Sequence[int],
                     pre_s: float = 1.0, skip_rows: Sequence[int] = ()) -> list[Finding]:
    """Poles that do not decay within the decay windows (loss under :data:`STEADY_LOSS`) yet are
    gone before the next blow: per such pole and gage (its median amplitude at least
    :data:`MIN_ENTRY_SNR` standard errors), each decay window's amplitude carried by the pole's
    own decay to the next blow's pre window against the amplitude measured there (a sinusoid at
    the pole's frequency, :func:`_line_amplitude`); ``z = sum(carried - measured) /
    sqrt(sum(var))``, the variance the two standard errors and :data:`PERSIST_FLOOR` of the
    carried amplitude. Null: a mode or a steady line, z standard normal; chance level its
    one-sided ``P_CHANCE`` quantile, Bonferroni over the poles and gages tested. One finding,
    the gages and poles beyond chance."""
    n_imp, n_g, _ = fm.amp.shape
    nxt = np.asarray(onsets_s)[1:]
    a0 = np.maximum(0, np.rint((nxt - pre_s) * fm.fs_hz).astype(int))
    n_pre = int((pre_s - PRE_GUARD_S) * fm.fs_hz)
    T = fm.n_s / fm.fs_hz
    ks = [k for k in range(fm.f_hz.size) if math.exp(-fm.delta[k] * fm.f_hz[k] * T) > 1 - STEADY_LOSS
          and fm.f_hz[k] * n_pre / fm.fs_hz >= MIN_CYCLES]
    if n_imp < 2 or not ks or np.any(a0 + n_pre > x.shape[1]) or np.any(a0 / fm.fs_hz < fm.t0_s[:-1] + T):
        return []
    snr = np.median(fm.snr(), axis=0)                                   # (n_g, K)
    rows = [g for g in range(n_g) if g not in set(skip_rows)]
    tests, share = [], {}
    for k in ks:
        z, share[k] = _persistence(x, fm, k, a0, n_pre, nxt - pre_s / 2)
        tests += [(float(z[g]), k, g) for g in rows if snr[g, k] >= MIN_ENTRY_SNR]
    if not tests:
        return []
    level = float(scipy.stats.norm.isf(P_CHANCE / len(tests)))
    hits = [t for t in tests if t[0] > level]
    if not hits:
        return []
    z, k, g = max(hits)
    poles = sorted({h[1] for h in hits})
    gages = tuple(dict.fromkeys(numbers[h[2]] for h in sorted(hits, reverse=True)))
    size = float(np.mean(np.abs(fm.amp[:, g, k])))
    text = (f"a line at {', '.join(f'{fm.f_hz[p]:.2f}' for p in poles)} Hz on gages "
            f"{', '.join(map(str, gages))}: steady through each decay ({size:.3g} m/s^2 at gage "
            f"{numbers[g]}) but down to {100 * share[k][g]:.0f} % of it before the next blow -- "
            "switched on by the blows: not a mode (it would ring on) and not an ambient line (it "
            "would be there throughout)")
    return [Finding("line_persistence", Layer.EXCITATION, gages, z, level, size, "m/s^2", text,
                    window="decay", mode_hz=tuple(float(fm.f_hz[p]) for p in poles),
                    null=("z of a steady pole's amplitude carried to the next pre window less the one "
                          f"measured there: standard normal, one-sided, Bonferroni over {len(tests)} "
                          "poles x gages"))]


def _persistence(x: np.ndarray, fm: FreeModal, k: int, a0: np.ndarray, n_pre: int,
                 t_pre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pole ``k``'s z per gage (n_g,) of :func:`line_persistence` and the share (n_g,) of its
    carried amplitude measured in the pre windows (starting at samples ``a0``, centred at
    ``t_pre`` s)."""
    # a pole fitted growing (noise) is carried as a steady one: no growth is extrapolated
    loss = max(float(fm.delta[k]), 0.0) * fm.f_hz[k] * (t_pre - fm.t0_s[:-1])
    carry = np.abs(fm.amp[:-1, :, k]) * np.exp(-loss)[:, None]
    others = np.delete(fm.poles, k)
    meas, se = (np.array(v) for v in zip(*(_line_amplitude(np.nan_to_num(x[:, a:a + n_pre]), fm.fs_hz,
                                                           fm.f_hz[k], others) for a in a0), strict=True))
    var = fm.amp_se[:-1, :, k] ** 2 + se**2 + (PERSIST_FLOOR * carry) ** 2
    with np.errstate(invalid="ignore", divide="ignore"):   # a dead gage: 0/0, NaN, no finding
        z = np.sum(carry - meas, axis=0) / np.sqrt(np.sum(var, axis=0))
    return z, np.sum(meas, axis=0) / np.maximum(np.sum(carry, axis=0), 1e-300)


# ------------------------------------------------------------------ spatial coherence, early window

ONE_GAGE_RATIO = 10.0
"""A line of the early window lives on one gage alone when its power there (over that gage's
noise) is at least this many times its power at every other gage and no other gage shows it
beyond chance: no structure moves one gage alone -- a mode of the rudder or the hull shows at
every gage of its body that is not at its node, and a body carries six. Stated a priori (10 dB)."""
ONE_GAGE_MIN_HZ = 5.0
"""Early lines below this are not read: a gage's own high-pass recovery after the blow (the
library's ``highpass``) lives below a few Hz."""


def one_gage_lines(x: np.ndarray, fm: FreeModal, onsets_s: np.ndarray, numbers: Sequence[int],
                   skip_rows: Sequence[int] = ()) -> list[Finding]:
    """Lines of the early windows the free modal model lacks
    (:func:`~ramdaq.analysis.gap.signal_checks.early_lines`: each gage's Hann periodogram over
    its noise variance, summed over the blows) that live on one gage alone: beyond the chance
    level there (``Gamma(n_imp, 1) / n_imp``, Bonferroni over the gages and independent bins at
    ``P_CHANCE``) and at no other gage, and :data:`ONE_GAGE_RATIO` times the next gage's. The
    statistic is the line's ratio at its gage against that chance level. One finding, the
    strongest such line (its gage; the other lines' gages listed after it)."""
    f, W, a0 = early_lines(x, fm.fs_hz, onsets_s, fm, skip_rows=skip_rows)
    if f.size == 0:
        return []
    # early_lines' own chance level: the early window's independent bins below 0.45 fs
    n_bins = max(1, int(0.45 * (DECAY_START_S - EARLY_FROM_S) * fm.fs_hz))
    chance = float(scipy.stats.gamma.isf(P_CHANCE / (n_bins * W.shape[0]), a0.size)) / a0.size
    hits = _alone(W, f, chance, np.ones(f.size, bool))
    if not hits:
        return []
    _, fk, g, best, second = hits[0]
    text = (f"a line at {fk:.1f} Hz in the early window on gage {numbers[g]} alone ({best:.3g} times its "
            f"noise, the next gage {second:.2g}): {ALONE}")
    return [_alone_finding(hits, numbers, chance, text, "early",
                           "early-window line power over the noise, summed over the blows: Gamma(n_imp, 1) / "
                           f"n_imp, Bonferroni over {W.shape[0]} gages x {n_bins} bins")]


def _alone(W: np.ndarray, f_hz: np.ndarray, chance: float, read: np.ndarray) -> list[tuple]:
    """The columns of ``W`` (n_rows, n_lines: each line's power per row over its chance unit)
    that live on one row alone, strongest first, each as (its power over ``chance``, its
    frequency Hz, its row, its power there, the next row's): a line of ``read`` at or above
    :data:`ONE_GAGE_MIN_HZ`, beyond ``chance`` on its row, at or below it on every other, and
    :data:`ONE_GAGE_RATIO` times the next row's."""
    hits = []
    for i, fk in enumerate(f_hz):
        o = np.argsort(-W[:, i])
        best, second = W[o[0], i], W[o[1], i]
        alone = second <= chance and best >= ONE_GAGE_RATIO * max(second, 1.0)
        if read[i] and fk >= ONE_GAGE_MIN_HZ and best > chance and alone:
            hits.append((best / chance, float(fk), int(o[0]), float(best), float(second)))
    return sorted(hits, reverse=True)


ALONE = ("no structure moves one gage alone -- the gage's own mount or signal chain rings; no library "
         "effect does")
"""Why a line or pole on one gage alone is no mode and no library effect (the findings' text)."""


def _alone_finding(hits: list[tuple], numbers: Sequence[int], chance: float, text: str, window: str,
                   null: str) -> Finding:
    """The ``one_gage_line`` finding of :func:`_alone`'s ``hits`` (rows as ``numbers``' gages):
    the strongest one's statistic, every hit's gage and frequency."""
    _, _, _, best, second = hits[0]
    gages = tuple(dict.fromkeys(numbers[h[2]] for h in hits))
    return Finding("one_gage_line", Layer.SENSOR, gages, best, chance, best / max(second, 1.0),
                   "power ratio", text, window=window, mode_hz=tuple(h[1] for h in hits), null=null)


def one_gage_poles(fm: FreeModal, numbers: Sequence[int], skip_rows: Sequence[int] = ()) -> list[Finding]:
    """Poles of the free modal model whose shape lives on one gage alone: the pole a gage's own
    resonance (its mount, its sensor) adds, which the model identifies as it does a mode, so that
    :func:`one_gage_lines` (lines the model lacks) never sees it (issue 17: a 75.8 Hz pole at
    7.4e5 times its standard error on gage 3 and at most 13 on every other). Per pole and gage
    the power of its amplitude over its standard error, ``|a|^2 / (2 se^2)``, averaged over the
    blows: ``Gamma(n_imp, 1) / n_imp`` under noise alone; chance level its ``P_CHANCE / (n_g K)``
    upper quantile. A pole counts where its gage stands beyond chance, every other gage at or
    below it, and the gage :data:`ONE_GAGE_RATIO` times the next (as a line does); not a
    steady line (an ambient tone) nor one below :data:`ONE_GAGE_MIN_HZ`; three gages or more
    read. One finding, the strongest such pole (its gage; the others' gages after it), check
    ``one_gage_line``: the same claim as a line's."""
    keep = [i for i in range(fm.amp.shape[1]) if i not in set(skip_rows)]
    if fm.n_modes == 0 or len(keep) < 3:
        return []
    n_imp = fm.amp.shape[0]
    W = np.mean(np.abs(fm.amp[:, keep]) ** 2 / np.maximum(2 * fm.amp_se[:, keep] ** 2, 1e-300), axis=0)
    chance = float(scipy.stats.gamma.isf(P_CHANCE / (len(keep) * fm.n_modes), n_imp)) / n_imp
    hits = _alone(W, fm.f_hz, chance, ~fm.steady)
    if not hits:
        return []
    _, fk, g, best, second = hits[0]
    text = (f"a pole at {fk:.1f} Hz on gage {numbers[keep[g]]} alone ({best:.3g} times its standard error "
            f"squared, the next gage {second:.2g}): {ALONE}")
    return [_alone_finding([(*h[:2], keep[h[2]], *h[3:]) for h in hits], numbers, chance, text, "decay",
                           "a pole's amplitude power over its standard error, averaged over the blows: Gamma("
                           f"n_imp, 1) / n_imp, Bonferroni over {len(keep)} gages x {fm.n_modes} poles")]
