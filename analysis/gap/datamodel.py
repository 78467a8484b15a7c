"""What the data say by themselves: a free linear modal model of a whole trial, and the typed
finding every data-only (and model-level) check reports.

The free modal model needs no stiffness and no mass: the trial's damped poles are identified
once, shared by every gage and every impact (:func:`ramdaq.analysis.modal.identify.identify_modes`
on all impacts' decays stacked as channels), and each impact's complex amplitudes at every gage
are then solved linearly with those poles held, with their standard errors from the residual
noise. The amplitudes of one impact over the gages are that impact's free complex mode shapes.

Shapes: ``n_imp`` impacts, ``n_g`` gages (DAQ channel order), ``K`` modes (ascending frequency).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from ..modal.identify import identify_modes
from ..modal.varpro import damped_basis, uniform_grid

DECAY_START_S = 0.25
"""Where the free model's decay window starts, s after each onset: past the ram's contact, the
anti-alias filter's transient and a second blow of the ram within the first 0.2 s (which the
early-window check looks for), so every impact's window holds a free decay."""
DECAY_MAX_S = 2.0
"""Longest decay window, s (the lightly damped modes are known to a small fraction of a cycle
well before; longer costs time)."""
N_IDENTIFY = 2
"""Impacts whose decays (stacked as channels) the poles are identified on: measured on a
six-blow, 16-gage trial, two take 1.5 s and all six 16 s for the same four poles to 1e-4 Hz, and
the six-fold stack's order selection also accepts weak spurious poles (0.2-1 noise rms)."""
STEADY_LOSS = 0.05
"""A pole whose envelope falls by less than this fraction over the decay window is steady (the
lightest-damped mode compared, ALBACORE's 215 Hz at delta 0.0019, falls by 56 % over 2 s;
SAMPSON's 2.2 Hz hull mode by 14 %)."""
MAX_MODES = 8
"""Most poles the order selection may accept (a rudder trial compares three to five)."""
MIN_SNR = 10.0
"""A pole is kept when, on the median impact, its amplitude at some gage is this many standard
errors: below it the order selection's rare spurious pole (its chance level is per stack, and
the stack is 32 channels) is kept out of every later test."""

P_CHANCE = 1e-3
"""Probability that a data-only check reports a finding on a trial without the fault: the chance
level of every statistic is its null distribution's upper ``P_CHANCE`` quantile,
Bonferroni-corrected for the gages, modes, frequencies or delays it searched."""
CERTAIN = "certain: no chance level applies"
"""How a finding no statistic measures (an infinite statistic: a dead gage) is said against its
chance level, where the others read "statistic 12.3x its chance level"."""
PRECEDENCE_STRENGTH = 2.0
"""A data-only sensor finding (or a double hit) overrides the model layer's "unexplained" when its
statistic is at least this many times its chance level (which is already Bonferroni-corrected at
``P_CHANCE``): well above chance, not a borderline excursion. Stated a priori, not tuned on
benchmark seeds."""


class Layer(StrEnum):
    """Where a finding places the cause."""

    SENSOR = "sensor"
    EXCITATION = "excitation"
    NONLINEARITY = "nonlinearity"
    STRUCTURE = "structure"
    MODEL_FORM = "model form"


@dataclass(frozen=True)
class Finding:
    """One thing a check found, with its evidence.

    ``check`` names the test (``"gain"``, ``"time_skew"``, ...); ``layer`` where it places the
    cause; ``gages`` the gage numbers it concerns; ``mode_hz`` the modes (Hz) it was read on;
    ``window`` the part of each segment (``"pre"``, ``"early"``, ``"decay"``, ``"peaks"``);
    ``statistic`` its test statistic and ``chance_level`` the value the statistic exceeds by
    chance with probability ``p_chance`` when nothing is wrong (from the statistic's null
    distribution, stated in ``null``); ``size`` and ``unit`` how big (a gain ratio, a delay in s,
    a corner in Hz, ...); ``text`` one line for the report."""

    check: str
    layer: Layer
    gages: tuple[int, ...]
    statistic: float
    chance_level: float
    size: float
    unit: str
    text: str
    window: str = "decay"
    mode_hz: tuple[float, ...] = ()
    p_chance: float = P_CHANCE
    null: str = ""
    more: tuple[tuple[str, float, str], ...] = ()
    """Further sizes as (name, value, unit): a double hit's delay besides its size."""
    closed_held: float = float("nan")
    """The share of the data layer's own gap -- the residual of this check's reference (the
    rigid-body reconstruction of a gage, the phases of the free modal model, its fit of the
    peaks, the one-blow early window) beyond its noise expectation -- that the finding's
    correction closes on impacts it was not fitted on (:func:`closure_of`): the shape checks
    (gain, skew, high-pass) hold each impact out in turn, fitted on the others (a weak held-out
    blow has no entry they can read); clipping and the double hit read the blows not
    :func:`held_out` and measure on those that are. NaN when not measured: no held-out impact,
    or no gap there."""
    closed_held_ci: tuple[float, float] = (float("nan"), float("nan"))
    """Its 95 % bootstrap interval (over the held-out entries the residual is summed over)."""

    @property
    def significant(self) -> bool:
        return bool(self.statistic > self.chance_level)

    def to_json(self) -> dict:
        return {"check": self.check, "layer": str(self.layer), "gages": list(self.gages),
                "window": self.window, "mode_hz": [round(f, 3) for f in self.mode_hz],
                "statistic": _r(self.statistic), "chance_level": _r(self.chance_level),
                "p_chance": self.p_chance, "null": self.null, "size": _r(self.size, 6),
                "unit": self.unit, "more": {n: {"value": _r(v, 6), "unit": u} for n, v, u in self.more},
                "closed_held": _r(self.closed_held), "closed_held_ci": [_r(v) for v in self.closed_held_ci],
                "text": self.text}


HELD_OUT_EVERY = 3
"""Every third impact (the 3rd, 6th, ...) is held out of a data-only check's correction when its
closure is measured, and the last when none is: the model layer's split
(:func:`~ramdaq.analysis.gap.trialdata.prepare`), so both layers' closures are of the same
impacts."""
N_BOOT = 400
"""Bootstrap resamples of a closure's interval."""


def held_out(n_imp: int) -> np.ndarray:
    """(n_imp,) bool: the impacts a data-only check's correction is not fitted on and its
    closure is measured on (:data:`HELD_OUT_EVERY`); none with one impact."""
    held = np.array([(j + 1) % HELD_OUT_EVERY == 0 for j in range(n_imp)], dtype=bool)
    if not held.any() and n_imp > 1:
        held[-1] = True
    return held


def closure_of(before: np.ndarray, after: np.ndarray,
               expect: np.ndarray | None = None) -> tuple[float, tuple[float, float]]:
    """The share of a gap a correction closes, ``1 - (sum(after) - sum(expect)) / (sum(before) -
    sum(expect))`` with the remainder floored at 0, and its 95 % bootstrap interval over the
    units (:data:`N_BOOT` resamples, seeded: the same data give the same interval).

    ``before``, ``after`` (n,): each unit's residual energy (whitened: in noise variances) on
    the held-out impacts without and with the correction (a unit an entry, a blow, a stretch of
    samples); ``expect`` (n,) its expectation from the noise alone (default 0). NaN when there
    is no gap beyond that expectation."""
    b, a = np.asarray(before, float), np.asarray(after, float)
    e = np.zeros_like(b) if expect is None else np.asarray(expect, float)
    nan = (float("nan"), (float("nan"), float("nan")))
    if b.size == 0 or not np.isfinite(b).all() or not np.isfinite(a).all():
        return nan
    gap = float(np.sum(b - e))
    if gap <= 0:
        return nan
    frac = 1.0 - max(float(np.sum(a - e)), 0.0) / gap
    idx = np.random.default_rng(b.size).integers(0, b.size, size=(N_BOOT, b.size))
    gb = np.sum((b - e)[idx], axis=1)
    ga = np.maximum(np.sum((a - e)[idx], axis=1), 0.0)
    fr = 1.0 - ga / np.where(gb > 0, gb, np.nan)
    lo, hi = np.nanpercentile(fr, [2.5, 97.5]) if np.isfinite(fr).any() else (np.nan, np.nan)
    return frac, (float(lo), float(hi))


def _r(v: float, d: int = 3) -> float | None:
    return round(float(v), d) if np.isfinite(v) else None


@dataclass(frozen=True)
class FreeModal:
    """The free linear modal model of a trial.

    Attributes
    ----------
    f_hz, delta : ndarray (K,)
        Damped frequency (Hz) and logarithmic decrement of each shared pole.
    f_se_hz, delta_se : ndarray (K,)
        Their standard errors.
    amp : ndarray (n_imp, n_g, K) complex
        Each impact's complex amplitude at each gage at its window's start ``t0_s``, m/s^2.
    amp_se : ndarray (n_imp, n_g, K)
        Standard error of the real (and of the imaginary) part of ``amp``, m/s^2.
    noise : ndarray (n_imp, n_g)
        Residual rms of each impact's decay at each gage, m/s^2.
    t0_s : ndarray (n_imp,)
        Each window's start, s from the stream's first sample.
    n_s : int
        Samples of each window (at ``fs_hz``).
    fs_hz : float
        The rate the amplitudes were solved at, Hz.
    steady : ndarray (K,) bool
        Poles that lose less than :data:`STEADY_LOSS` of their amplitude over the window and
        whose phase is not the same from blow to blow: a line that does not decay (an ambient
        tone) rather than a mode the blows excite. The shape checks leave them out.
    """

    f_hz: np.ndarray
    delta: np.ndarray
    f_se_hz: np.ndarray
    delta_se: np.ndarray
    amp: np.ndarray
    amp_se: np.ndarray
    noise: np.ndarray
    t0_s: np.ndarray
    n_s: int
    fs_hz: float
    steady: np.ndarray
    info: dict = field(default_factory=dict)

    @property
    def n_modes(self) -> int:
        return int(self.f_hz.size)

    @property
    def poles(self) -> np.ndarray:
        """s_k = -delta f + i 2 pi f, 1/s, (K,)."""
        return -self.delta * self.f_hz + 2j * math.pi * self.f_hz

    def snr(self) -> np.ndarray:
        """|amp| / its standard error, (n_imp, n_g, K)."""
        return np.abs(self.amp) / np.maximum(self.amp_se, 1e-300)

    def response(self, j: int, t_s: np.ndarray) -> np.ndarray:
        """Impact ``j``'s modal response at times ``t_s`` (s from the stream's start), (n_g, n)."""
        e = np.exp(np.multiply.outer(self.poles, np.asarray(t_s) - self.t0_s[j]))
        return np.real(self.amp[j] @ e)


def decay_window(onsets_s: np.ndarray, n_total: int, fs_hz: float,
                 pre_s: float) -> tuple[np.ndarray, int]:
    """First sample of each impact's decay window and the common window length (samples): from
    :data:`DECAY_START_S` after the onset to :data:`DECAY_MAX_S`, ``pre_s`` before the next
    onset or the stream's end, whichever is first."""
    on = np.asarray(onsets_s, dtype=float)
    ends = np.append(on[1:] - pre_s, n_total / fs_hz)
    length = float(min(DECAY_MAX_S, np.min(ends - on) - DECAY_START_S))
    if length < 0.5:
        raise ValueError(f"impacts {np.min(np.diff(on)) if on.size > 1 else 0:.2f} s apart leave "
                         f"less than 0.5 s of free decay for the data-only checks")
    starts = np.rint((on + DECAY_START_S) * fs_hz).astype(int)
    return starts, int(length * fs_hz)


def free_modal_model(x: np.ndarray, fs_hz: float, onsets_s: np.ndarray, *, pre_s: float = 1.0,
                     max_hz: float | None = None, false_alarm: float = 1e-4,
                     exclude_rows: tuple[int, ...] = ()) -> FreeModal:
    """The free modal model of a trial.

    Parameters
    ----------
    x : ndarray (n_g, n)
        The whole trial, m/s^2, at its recorded rate ``fs_hz`` (Hz); NaN in gaps.
    onsets_s : ndarray (n_imp,)
        Impact onsets, s from the first sample.
    pre_s : float
        Kept clear before each next onset, s.
    max_hz : float, optional
        Report no pole above this frequency.
    false_alarm : float
        Probability of a spurious pole (:func:`identify_modes`' order selection).
    exclude_rows : tuple of int
        Rows the poles are not identified on (a clipped gage's harmonics are no modes); their
        amplitudes are still solved.
    """
    starts, n_s = decay_window(onsets_s, x.shape[1], fs_hz, pre_s)
    seg = np.stack([x[:, a:a + n_s] for a in starts])            # (n_imp, n_g, n_s)
    if seg.shape[-1] < n_s or not np.all(np.isfinite(seg)):
        raise ValueError("a decay window of the data-only checks runs past the stream's end or "
                         "over a gap in it")
    n_imp, n_g, _ = seg.shape
    rng = (0.0, max_hz) if max_hz else None
    rows = [g for g in range(n_g) if g not in set(exclude_rows)]
    tab = identify_modes(seg[:N_IDENTIFY, rows].reshape(-1, n_s), fs_hz, f_range_hz=rng,
                         per_channel=False, false_alarm=false_alarm, max_modes=MAX_MODES)
    keep = np.isfinite(tab.frequency_hz) & (tab.frequency_hz > 0)
    if max_hz:
        keep &= tab.frequency_hz <= max_hz
    f, d = tab.frequency_hz[keep], tab.delta[keep]
    amp, se, noise = _amplitudes(seg, fs_hz, f, d)
    snr = np.abs(amp) / np.maximum(se, 1e-300)          # a dead gage: 0 / 0 -> 0
    strong = np.median(np.max(snr, axis=1), axis=0) >= MIN_SNR
    if not strong.all():
        keep = np.flatnonzero(keep)[strong]
        f, d = tab.frequency_hz[keep], tab.delta[keep]
        amp, se, noise = _amplitudes(seg, fs_hz, f, d)
    return FreeModal(f_hz=f, delta=d, f_se_hz=tab.frequency_se_hz[keep], delta_se=tab.delta_se[keep],
                     amp=amp, amp_se=se, noise=noise, t0_s=starts / fs_hz, n_s=n_s, fs_hz=fs_hz,
                     steady=_steady(amp, f, d, n_s / fs_hz), info={"identify": tab.info})


def _steady(amp: np.ndarray, f: np.ndarray, d: np.ndarray, window_s: float) -> np.ndarray:
    """(K,) bool: poles that barely decay over the window (envelope loss under
    :data:`STEADY_LOSS`) and whose phase at the onset is not the same blow after blow (a mode a
    blow excites starts in the same phase every time; a tone's phase is wherever it happens to
    be): the Rayleigh test at the gage where the pole is strongest, ``exp(-n R^2) > 0.01``."""
    slow = np.exp(-d * f * window_s) > 1 - STEADY_LOSS
    g = np.argmax(np.sum(np.abs(amp), axis=0), axis=0)                 # (K,)
    a = amp[:, g, np.arange(f.size)]                                    # (n_imp, K)
    R = np.abs(np.mean(a / np.maximum(np.abs(a), 1e-300), axis=0))
    return slow & (np.exp(-amp.shape[0] * R**2) > 0.01)


def _amplitudes(seg: np.ndarray, fs_hz: float, f: np.ndarray,
                d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Complex amplitudes (n_imp, n_g, K) with the poles held, their standard errors (white
    residual: sigma^2 (Phi^T Phi)^-1, the mean of the real and imaginary parts' variances) and
    each decay's residual rms (n_imp, n_g)."""
    n_imp, n_g, n_s = seg.shape
    t = np.arange(n_s) / fs_hz
    Phi = damped_basis(t, f, d, True, uniform_grid(t))             # (n_s, 2K+1)
    K = f.size
    coef, *_ = np.linalg.lstsq(Phi, seg.reshape(-1, n_s).T, rcond=None)
    resid = seg.reshape(-1, n_s).T - Phi @ coef
    dof = max(1, n_s - Phi.shape[1])
    noise = np.sqrt(np.sum(resid**2, axis=0) / dof)
    cov = np.linalg.pinv(Phi.T @ Phi)
    v = np.diag(cov)
    var1 = 0.5 * (v[0:2 * K:2] + v[1:2 * K:2])                     # (K,)
    amp = (coef[0:2 * K:2] - 1j * coef[1:2 * K:2]).T.reshape(n_imp, n_g, K)
    noise = noise.reshape(n_imp, n_g)
    se = noise[..., None] * np.sqrt(var1)[None, None, :]
    return amp, se, noise
