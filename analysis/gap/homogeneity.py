"""Homogeneity across blows of different force (issue 17, data-only layer): a linear structure
rings at the same frequencies with the same damping whatever the blow's force. Each impact's
poles are refitted on its own decay (the free modal model's shared poles as the start), and
each mode's frequency and logarithmic decrement are regressed on the blow's level (log of its
amplitude): a slope beyond chance flags friction (decrement falling as the blow grows) or an
amplitude-dependent stiffness (a crack, a rattle: frequency moving with the blow). And every
other mode's amplitude must grow as the blow (log-log slope 1): friction's linear decay, which the
free model fits with an extra slow pole of the same size after every blow, fails that.

Shapes: ``x`` (n_g, n) m/s^2 at the recorded rate; :class:`~ramdaq.analysis.gap.datamodel.FreeModal`
as made by :func:`~ramdaq.analysis.gap.datamodel.free_modal_model` on the same ``x``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import scipy.signal
import scipy.stats

from .datamodel import P_CHANCE, Finding, FreeModal, Layer

F_FLOOR = 2e-4
"""Relative frequency scatter accepted from blow to blow on top of each fit's standard error
(coloured noise and the neighbouring modes' leakage make the Jacobian's error optimistic)."""
D_FLOOR = 0.03
"""Relative decrement scatter accepted likewise (decrements are known to a few per cent at best
from a 2 s window)."""
MIN_LEVEL_SPAN = math.log(1.5)
"""Least spread of the blows' levels (log amplitude) the test needs: blows of one force say
nothing about amplitude dependence."""
MAX_GAGES = 4
AMP_FLOOR = 0.02
"""Relative amplitude scatter accepted from blow to blow on top of each amplitude's standard
error (the ram's contact time and place vary a little from blow to blow)."""
MIN_SNR = 30.0
"""A mode is tested when even the weakest blow measures it this many standard errors at its best
gage (its decrement then to a few per cent): a mode the small blows barely ring is not judged."""


def refit_poles(seg: np.ndarray, fs_hz: float, f0: np.ndarray, d0: np.ndarray,
                n_iter: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One impact's poles refitted on its decay ``seg`` (n_ch, n) from ``f0`` (Hz), ``d0``
    (decrements) by Gauss-Newton in the poles: each mode's response ``Re(c e^(s t))`` with the
    columns of its derivative ``Re(c t e^(s t))`` beside it, solved linearly, gives ``c ds``
    per channel; ``ds`` is their least-squares ratio over the channels. Returns f, d and their
    standard errors (white residual), each (K,)."""
    t = np.arange(seg.shape[1]) / fs_hz
    s = -d0 * f0 + 2j * math.pi * f0
    K = s.size
    for _ in range(n_iter):
        E = np.exp(np.outer(t, s))
        TE = t[:, None] * E
        B = np.hstack([E.real, E.imag, TE.real, TE.imag, np.ones((t.size, 1))])
        G = B.T @ B
        coef = np.linalg.solve(G, B.T @ seg.T)                         # (4K+1, n_ch)
        c = coef[:K] - 1j * coef[K:2 * K]
        g = coef[2 * K:3 * K] - 1j * coef[3 * K:4 * K]
        w = np.sum(np.abs(c) ** 2, axis=1)
        ds = np.sum(np.conj(c) * g, axis=1) / np.maximum(w, 1e-300)
        s = s + np.clip(ds.real, -0.5 * np.abs(s.real) - 1, 0.5 * np.abs(s.real) + 1) + 1j * np.clip(
            ds.imag, -0.01 * s.imag, 0.01 * s.imag)
    resid = seg.T - B @ coef
    sig2 = np.sum(resid**2, axis=0) / max(1, t.size - B.shape[1])      # (n_ch,)
    v = np.diag(np.linalg.inv(G))
    vg = 0.5 * (v[2 * K:3 * K] + v[3 * K:4 * K])                        # (K,)
    se = np.sqrt(vg * np.sum(sig2[None, :] * np.abs(c) ** 2, axis=1)) / np.maximum(w, 1e-300)
    f = s.imag / (2 * math.pi)
    return f, -s.real / f, se / (2 * math.pi), se / f


def _slope(level: np.ndarray, y: np.ndarray, se: np.ndarray) -> tuple[float, float]:
    """Weighted least-squares slope of ``y`` on ``level`` and its standard error."""
    w = 1 / se**2
    lm = np.sum(w * level) / w.sum()
    sxx = np.sum(w * (level - lm) ** 2)
    b = float(np.sum(w * (level - lm) * y) / sxx)
    return b, float(1 / math.sqrt(sxx))


def own_amplitudes(fm: FreeModal) -> np.ndarray:
    """Each impact's complex amplitudes (n_imp, n_g, K) less what the previous impact's ringing
    still contributes at its window's start (that impact's amplitudes carried forward by each
    pole: exact for a linear structure). A lightly damped mode still ringing when the next blow
    comes would otherwise not grow as the blow."""
    amp = fm.amp.copy()
    dt = np.diff(fm.t0_s)
    amp[1:] -= fm.amp[:-1] * np.exp(np.multiply.outer(dt, fm.poles))[:, None, :]
    return amp


def homogeneity(x: np.ndarray, fm: FreeModal, numbers: Sequence[int],
                skip_rows: Sequence[int] = ()) -> list[Finding]:
    """The homogeneity check: per excited mode, the slope of frequency and of decrement against
    the blow's level (per doubling of the blow), as z = slope / its standard error; a finding
    for the largest |z| beyond its chance level (two-sided normal, Bonferroni over the 2 K
    slopes at ``P_CHANCE``). Empty when the blows' levels spread too little or fewer than three
    impacts."""
    snr = np.median(fm.snr(), axis=0)                                   # (n_g, K)
    snr[list(skip_rows)] = 0
    weakest = np.min(np.max(np.delete(fm.snr(), list(skip_rows), axis=1), axis=1), axis=0)
    ks = np.flatnonzero(~fm.steady & (weakest >= MIN_SNR))
    if fm.amp.shape[0] < 3 or ks.size == 0:
        return []
    rows = list(dict.fromkeys(int(np.argmax(snr[:, k])) for k in ks))[:MAX_GAGES]
    kp = ks[int(np.argmax(snr[rows][:, ks].max(axis=0)))]               # the best-measured mode
    gp = int(np.argmax(snr[:, kp]))
    own = own_amplitudes(fm)
    level = np.log(np.abs(own[:, gp, kp]))
    if np.ptp(level) < MIN_LEVEL_SPAN:
        return []
    starts = np.rint(fm.t0_s * fm.fs_hz).astype(int)
    q = int(np.clip(fm.fs_hz // (5 * fm.f_hz.max()), 1, 8))            # 5 samples per cycle kept
    segs = [x[rows, a:a + fm.n_s] for a in starts]
    if q > 1:   # zero-phase: the poles are kept, the fit costs 1/q
        segs = [scipy.signal.decimate(s, q, ftype="fir", zero_phase=True) for s in segs]
    fits = [refit_poles(s, fm.fs_hz / q, fm.f_hz[ks], fm.delta[ks]) for s in segs]
    f, d, sf, sd = (np.array([r[i] for r in fits]) for i in range(4))   # each (n_imp, K')
    sf = np.sqrt(sf**2 + (F_FLOOR * f) ** 2)
    sd = np.sqrt(sd**2 + (D_FLOOR * np.abs(d)) ** 2)
    level_db = level / math.log(2)                                       # in doublings
    out = []
    for i, k in enumerate(ks):
        for what, y, s in (("frequency", f[:, i], sf[:, i]), ("decrement", d[:, i], sd[:, i])):
            b, se = _slope(level_db, y, s)
            out.append((abs(b) / se, what, float(fm.f_hz[k]), b / float(np.mean(y)), k))
    for k in ks:
        if k == kp:
            continue
        # linearity: every mode's amplitude grows as the blow (log-log slope 1)
        g = int(np.argmax(snr[:, k]))
        a = np.abs(own[:, g, k])
        sa = np.sqrt((fm.amp_se[:, g, k] / a) ** 2 + AMP_FLOOR**2)
        b, se = _slope(level, np.log(a), sa)
        out.append((abs(b - 1) / se, "amplitude", float(fm.f_hz[k]), b - 1, k))
    # a refit that did not converge (a mode the blow barely rings) gives no slope: not a finding
    out = [o for o in out if np.isfinite(o[0]) and np.isfinite(o[3])]
    if not out:
        return []
    z, what, f_k, rel, k = max(out)
    chance = float(scipy.stats.norm.isf(P_CHANCE / (2 * len(out))))
    if z <= chance:
        return []
    g_snr = snr[:, k]
    gages = tuple(numbers[g] for g in np.flatnonzero(g_snr >= 0.5 * g_snr.max()))
    if what == "amplitude":
        text = (f"mode {f_k:.2f} Hz: amplitude grows as the blow to the power {1 + rel:.2f}, not 1 "
                "(friction or amplitude-dependent damping)")
        unit = "exponent - 1"
    else:
        cause = ("friction or amplitude-dependent damping" if what == "decrement"
                 else "amplitude-dependent stiffness (a crack, a rattle, a stop)")
        text = f"mode {f_k:.2f} Hz: {what} changes by {100 * rel:+.1f} % per doubling of the blow ({cause})"
        unit = "per doubling of the blow"
    return [Finding("homogeneity", Layer.NONLINEARITY, gages, z, chance, rel, unit, text,
                    window="decay", mode_hz=(f_k,),
                    null="slope z of a linear structure's poles and amplitudes on the blow level: "
                         "standard normal, "
                         f"Bonferroni over {len(out)} slopes",
                    more=((f"{what}_per_doubling", rel, "1"),))]
