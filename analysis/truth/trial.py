"""Truth trials for the sim-to-real gap benchmark: impact trials made by a richer simulation than
the diagnosis uses, carrying one hidden effect (or none).

What differs from the nominal simulator (:mod:`ramdaq.analysis.model.response` +
:mod:`ramdaq.analysis.model.sensor`):

* **Structure** (:mod:`ramdaq.analysis.truth.structure`): the stock is a 4-element Timoshenko chain with
  its own steel mass and a discretised torsion line, so it has its own (damped) modes and shifts
  the rudder modes by 0.02-0.9 % (the highest rudder mode by 6-21 %); stock gages follow the
  chain's deflected shape.
* **Integrator** (:mod:`ramdaq.analysis.truth.integrate`): an exactly discretised state-space recursion
  with a piecewise-linear (Legendre-projected) force hold at ``OVERSAMPLE`` x the sample rate, not
  closed-form modal superposition; nonlinear friction by an implicit (mid-step rate) recursion at
  twice the sample rate, fed back as an input.
* **Front-end**: the anti-alias Butterworth of the rig's order and corner runs at the oversampled
  rate (so it is closer to the analog filter: below 100 Hz its group delay is 0.50 ms against
  sensor.py's 0.23 ms at 2048 Hz -- 0.27 ms more, the same on every channel), then decimation to
  fs, ADC quantisation and clipping at the rails.
* **Noise**: per channel white (80 % of the variance) + 1/f between 0.05 and 50 Hz (15 %) + a
  common-mode part shared by all channels (5 %), total rms ``rig.daq.noise_m_s2_rms`` over 0..fs/2
  before the anti-alias filter (the same in-band level as sensor.py's white noise); a smooth
  spectrum, no lines. It is band-limited to fs/2, so it is made at fs directly through the chain's
  filters' frequency response (exactly what the oversampled chain would do to it).
* **Effects** (:mod:`ramdaq.analysis.truth.effects`): each injected physically; ``reference_size``.

Random streams are split by purpose: for one seed the blows and the noise are the same whatever
the effect, so ``generate_trial(rig, e, s, seed)`` and ``generate_trial(rig, "none", 0, seed)``
differ only by the effect.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import scipy.fft
import scipy.signal

from ..model.response import modal_form, model_modes, predominant_mode
from ..model.rig import ImpactSpec, Rig
from ..model.structure import build_model
from .effects import PLANNERS, REFERENCE, Context, Plan
from .integrate import (
    ModalRecursion,
    friction_input,
    half_sine_moments,
    half_sine_samples,
    modal_recursion,
    smooth_moments,
)
from .structure import build_truth_model

EFFECTS: tuple[str, ...] = ("none", "hull_coupling", "ambient_tone", "friction", "tiller", "added_mass",
                            "split_mode", "gage_sensitivity", "gage_alignment", "clipping", "time_skew",
                            "highpass", "double_hit")
WINDOWS = ("pre", "early", "late", "all")
OVERSAMPLE = 4
NOISE_SHARES = {"white": 0.80, "pink": 0.15, "common": 0.05}
PINK_BAND_HZ = (0.05, 50.0)


@dataclass(frozen=True)
class TruthEffect:
    """The hidden effect of a trial. ``size`` dimensionless (:func:`reference_size`); ``params`` the
    physical parameters used, SI, JSON-able; ``gages`` report gage numbers where it shows most (()
    = all or none); ``mode_hz`` the nominal-model mode or band it affects (Hz) or None; ``window``
    where it shows: "pre" (pre-trigger), "early", "late" decay, or "all"."""

    name: str
    size: float
    params: dict
    gages: tuple[int, ...]
    mode_hz: float | None
    window: str


@dataclass(frozen=True)
class TruthTrial:
    """A generated trial. ``rig`` the nominal rig the diagnosis is given (ambient removed);
    ``counts`` int32 (n_channels, n) in the rig's DAQ channel order; ``scale`` (n_channels,)
    m/s^2 per count; ``fs_hz``; ``onsets_s`` true blow starts (s from the first sample) and
    ``peaks_N`` their peak forces, (n_impacts,); ``effect``; ``seed``."""

    rig: Rig
    counts: np.ndarray
    scale: np.ndarray
    fs_hz: float
    onsets_s: np.ndarray
    peaks_N: np.ndarray
    effect: TruthEffect
    seed: int

    @property
    def acc(self) -> np.ndarray:
        """Recorded accelerations, m/s^2, (n_channels, n)."""
        return self.counts * self.scale[:, None]


def reference_size(effect: str) -> str:
    """One line: what size 1.0 of ``effect`` means physically."""
    if effect not in REFERENCE:
        raise ValueError(f"unknown effect {effect!r}; one of {', '.join(EFFECTS)}")
    return REFERENCE[effect]


def nominal_rig(rig: Rig) -> Rig:
    """The rig as the diagnosis gets it: ambient entries removed, also from its TOML text."""
    out, skip = [], False
    for line in rig.text.splitlines(keepends=True):
        if line.lstrip().startswith("["):
            skip = line.strip().startswith("[[ambient]]")
        if not skip:
            out.append(line)
    return replace(rig, ambient=(), text="".join(out))


def default_interval_s(rig: Rig) -> float:
    """Time for the nominal predominant mode to decay to 5 %, clamped to 3..6 s."""
    form = modal_form(build_model(rig))
    imp = rig.impact
    lam = form.eigenvalues[predominant_mode(form, imp.peak_force_N, imp.duration_s, imp.location_m,
                                            imp.direction)]
    return float(np.clip(math.log(20) / abs(lam.real), 3.0, 6.0))


def generate_trial(rig: Rig, effect: str = "none", size: float = 1.0, seed: int = 0, *,
                   n_impacts: int = 6, interval_s: float | None = None, pre_s: float = 3.0,
                   noise: bool = True, stock_mass_factor: float = 1.0) -> TruthTrial:
    """One truth trial of ``rig`` (in its medium) with ``effect`` of ``size`` (>= 0).

    ``n_impacts`` blows of the rig's ram (peaks +-20 %, seeded) start ``pre_s`` s in and every
    ``interval_s`` s (default :func:`default_interval_s`), each a seeded fraction of a sample late;
    the record ends one interval after the last. ``noise=False`` and ``stock_mass_factor`` exist for
    validation. Raises ValueError for an unknown effect or a negative size.
    """
    if effect not in EFFECTS:
        raise ValueError(f"unknown effect {effect!r}; one of {', '.join(EFFECTS)}")
    if not (math.isfinite(size) and size >= 0):
        raise ValueError(f"effect size must be finite and >= 0, got {size}")
    if n_impacts < (1 if effect in ("clipping", "double_hit") else 0):
        raise ValueError(f"effect {effect} needs at least one blow (n_impacts = {n_impacts})")
    nom = nominal_rig(rig)
    fs = nom.daq.sample_rate_hz
    dt = 1 / (OVERSAMPLE * fs)
    interval = default_interval_s(nom) if interval_s is None else float(interval_s)
    rng_blows = np.random.default_rng([seed, 1])
    imp = nom.impact
    peaks = imp.peak_force_N * rng_blows.uniform(0.8, 1.2, n_impacts)
    onsets = pre_s + interval * np.arange(n_impacts) + rng_blows.uniform(0, 1, n_impacts) / fs
    n = math.ceil((pre_s + n_impacts * interval) * fs)
    n_o = n * OVERSAMPLE

    form = modal_form(build_model(nom))
    modes = model_modes(form)
    base = build_truth_model(nom, stock_mass_factor=stock_mass_factor)
    base_rec = modal_recursion(base, dt)
    ctx = Context(rig=nom, ambient_hz=rig.ambient[0].frequency_hz if rig.ambient else None, fs_hz=fs, dt=dt,
                  nominal_hz=modes.frequency_hz, nominal_zeta=modes.damping_ratio,
                  pred=predominant_mode(form, imp.peak_force_N, imp.duration_s, imp.location_m,
                                        imp.direction),
                  base=base, base_rec=base_rec, onsets_s=onsets, peaks_N=peaks, interval_s=interval,
                  stock_mass_factor=stock_mass_factor)
    plan = PLANNERS[effect](ctx, size, np.random.default_rng([seed, 3, EFFECTS.index(effect)]))
    model = plan.model or (build_truth_model(nom, stock_mass_factor=stock_mass_factor, **plan.model_kw)
                           if plan.model_kw else base)
    rec = base_rec if model is base else modal_recursion(model, dt)

    acc = _structure(rec, plan, onsets, peaks, imp, n_o, seed)
    for ch, g in plan.gain.items():
        acc[ch] *= g
    sens = np.array([g.sensitivity_V_per_m_s2 for g in nom.gages_by_channel()])
    fo = OVERSAMPLE * fs
    d = nom.daq
    sos_aa = scipy.signal.butter(d.anti_alias_order, d.anti_alias_hz, fs=fo, output="sos")
    filters = [sos_aa]
    if plan.highpass:
        hp = plan.highpass
        filters.insert(0, scipy.signal.butter(hp["order"], hp["corner_hz"], "highpass", fs=fo, output="sos"))
    volts = acc * sens[:, None]
    for sos in filters:
        volts = scipy.signal.sosfilt(sos, volts, axis=1)
    volts = volts[:, ::OVERSAMPLE]
    if noise and d.noise_m_s2_rms > 0:
        volts += sens[:, None] * coloured_noise(np.random.default_rng([seed, 2]), len(sens), n, fs,
                                                d.noise_m_s2_rms, filters, fo)
    full_scale = np.full(len(sens), d.adc_full_scale_V)
    if plan.clip:
        _plan_clipping(plan, nom, volts, onsets, fs, full_scale)
    lsb = 2 * full_scale / 2**d.adc_bits
    counts = np.clip(np.rint(volts / lsb[:, None]), -(2 ** (d.adc_bits - 1)), 2 ** (d.adc_bits - 1) - 1)
    truth = TruthEffect(name=effect, size=float(size), params=_jsonable(dict(plan.params, size=size)),
                        gages=tuple(sorted(plan.gages)), mode_hz=plan.mode_hz, window=plan.window)
    return TruthTrial(rig=nom, counts=counts.astype(np.int32), scale=lsb / sens, fs_hz=fs,
                      onsets_s=onsets, peaks_N=peaks, effect=truth, seed=seed)


def _structure(rec: ModalRecursion, plan: Plan, onsets: np.ndarray, peaks: np.ndarray, imp: ImpactSpec,
               n_o: int,
               seed: int) -> np.ndarray:
    """Noise-free gage accelerations (m/s^2) at the oversampled rate, (n_gages, n_o)."""
    model, dt = rec.model, rec.dt
    f_imp = model.force_vector(imp.location_m, imp.direction)
    on, pk = onsets, peaks
    if plan.second_blows is not None:
        on, pk = np.concatenate([on, plan.second_blows[0]]), np.concatenate([pk, plan.second_blows[1]])
    t = np.arange(n_o) * dt
    rows = model.gage_dofs.copy()
    for ch, (body, pos, axis) in plan.moved.items():
        rows[ch] = model.point_row(body, pos, axis)
    Z = rec.run(f_imp, *half_sine_moments(on, pk, imp.duration_s, dt, n_o))
    direct = [(f_imp, half_sine_samples(on, pk, imp.duration_s, t))]
    if plan.ambient:
        e, drive, z0 = _ambient(rec, plan.ambient, n_o * dt, np.random.default_rng([seed, 4]))
        Za = rec.run(e, *smooth_moments(drive, dt, n_o), z0=z0)
        # the hull mode filters the wandering drive (its bandwidth is ~0.01 Hz): scale the response
        # so its mean amplitude (sqrt 2 x rms) on the reference hull gage is the planned one
        ref = plan.ambient["reference_channel"]
        got = math.sqrt(2) * np.std(outputs(rec, Za[:, ::8], rows[ref:ref + 1], [(e, drive(t[::8]))]))
        k = plan.ambient["amplitude_m_s2"] / got if got > 0 else 0.0
        Z += k * Za
        direct.append((e, k * drive(t)))
    if plan.friction:
        row = np.eye(model.n_dof)[1] - model.rows["hull_gamma"]
        u = friction_input(rec, Z, row, plan.friction["torque_N_m"], plan.friction["rate_eps_rad_s"],
                           OVERSAMPLE // 2)
        Z += rec.run(row, u, np.zeros(n_o))
        direct.append((row, u))
    acc = outputs(rec, Z, rows, direct)
    if plan.skew:
        ch, tau = plan.skew["channel"], plan.skew["delay_s"]
        Zs = rec.run(f_imp, *half_sine_moments(on + tau, pk, imp.duration_s, dt, n_o))
        acc[ch] = outputs(rec, Zs, rows[ch:ch + 1], [(f_imp, half_sine_samples(on + tau, pk, imp.duration_s,
                                                                               t))])[0]
    return acc


def outputs(rec: ModalRecursion, Z: np.ndarray, rows: np.ndarray, direct: list) -> np.ndarray:
    """Accelerations of ``rows`` (k, n) from modal states Z (m, N) plus the direct terms
    ``[(force vector, amplitude series (N,)), ...]``, (k, N); in time chunks to bound memory."""
    C = rec.output_matrix(rows, "acc")
    m = Z.shape[0]
    Cr, Ci = C[:, :m], C[:, m:]
    out = np.empty((rows.shape[0], Z.shape[1]))
    for s in range(0, Z.shape[1], 1 << 13):
        sl = slice(s, s + (1 << 13))
        on = np.flatnonzero(np.any(Z[:, sl] != 0, axis=1))  # fast modes are zero between blows
        out[:, sl] = Cr[:, on] @ Z[on, sl].real + Ci[:, on] @ Z[on, sl].imag
    for force, u in direct:
        out += rec.feedthrough(rows, force)[:, None] * u[None, :]
    return out


def _ambient(rec: ModalRecursion, amb: dict, duration_s: float,
             rng: np.random.Generator) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray], np.ndarray]:
    """Modal force on hull mode 1: ``F (1 + a(t)) cos(w t + p(t))``, with a, p slow Gaussian
    wanders (second-order low-pass of white noise, time constant ``wander_time_s``), and the
    modal state of its steady response at t = 0 (so the tone is there from the first sample)."""
    model = rec.model
    e = np.zeros(model.n_dof)
    e[model.dofs.index(f"eta{amb['hull_mode']}")] = 1.0
    tau, step = amb["wander_time_s"], 0.25
    grid = np.arange(-step, duration_s + 2 * step, step)
    a = math.exp(-step / tau)
    warm = int(8 * tau / step)
    white = rng.standard_normal((2, warm + len(grid)))
    for _ in range(2):
        white = scipy.signal.lfilter([1 - a], [1, -a], white, axis=1)
    # stationary std of the two cascaded first-order low-passes of unit white noise
    slow = white[:, warm:] / math.sqrt((1 - a) ** 4 * (1 + a * a) / (1 - a * a) ** 3)
    amp = 1 + amb["amp_wander"] * slow[0]
    ph = amb["phase_wander_rad"] * slow[1] + rng.uniform(0, 2 * math.pi)
    w, F = 2 * math.pi * amb["frequency_hz"], amb["force_N"]

    def drive(t: np.ndarray) -> np.ndarray:
        return F * np.interp(t, grid, amp) * np.cos(w * t + np.interp(t, grid, ph))

    X = np.linalg.solve(model.K - w**2 * model.M + 1j * w * model.C, e)
    phasor = F * np.interp(0.0, grid, amp) * np.exp(1j * np.interp(0.0, grid, ph))
    x0 = np.real(np.concatenate([X, 1j * w * X]) * phasor)
    return e, drive, rec.W @ x0


def coloured_noise(rng: np.random.Generator, n_ch: int, n: int, fs: float, sigma: float,
                   filters: list[np.ndarray], fo: float) -> np.ndarray:
    """Front-end noise (m/s^2) at the sample rate after the chain's filters, (n_ch, n).

    Before the filters each channel's noise has variance ``sigma^2`` over 0..fs/2: white, 1/f
    (between ``PINK_BAND_HZ``) and a common-mode part (``NOISE_SHARES``); made in the frequency
    domain (smooth spectrum, random phases) and shaped by the filters' response (``filters``: sos
    at rate ``fo``), which is what they do to noise band-limited below fs/2.
    """
    nf = scipy.fft.next_fast_len(n, real=True)
    f = np.fft.rfftfreq(nf, 1 / fs)
    lo, hi = PINK_BAND_HZ
    shapes = {"white": np.ones_like(f), "pink": 1 / ((lo + f) * (1 + (f / hi) ** 2))}
    for s in shapes.values():
        s[0] = 0.0
        s /= s.sum()
    own = NOISE_SHARES["white"] * shapes["white"] + NOISE_SHARES["pink"] * shapes["pink"]
    common = NOISE_SHARES["common"] / (1 - NOISE_SHARES["common"]) * own
    H = np.ones(len(f), dtype=complex)
    for sos in filters:
        H *= scipy.signal.sosfreqz(sos, worN=f, fs=fo)[1]
    amp = sigma * nf / 2 * H
    spec = rng.standard_normal((n_ch + 1, len(f))) + 1j * rng.standard_normal((n_ch + 1, len(f)))
    spec[:n_ch] *= amp * np.sqrt(own)
    spec[n_ch] *= amp * np.sqrt(common)
    x = scipy.fft.irfft(spec, n=nf, axis=1)[:, :n]
    return x[:n_ch] + x[n_ch]


def _plan_clipping(plan: Plan, rig: Rig, volts: np.ndarray, onsets: np.ndarray, fs: float,
                   full_scale: np.ndarray) -> None:
    """Lower the ADC range of the chosen rudder channels so the median blow peaks at
    ``overdrive`` x the rail; records the channels and ranges in ``plan``."""
    chans = [g.channel for g in rig.gages_by_channel() if g.body == "rudder"]
    win = [volts[chans, int(t * fs):int((t + 0.5) * fs)] for t in onsets]
    peak = np.median(np.stack([np.abs(w).max(axis=1) for w in win]), axis=0)
    cands = [c for c, p in zip(chans, peak, strict=True) if p >= 0.3 * peak.max()]
    pick = np.random.default_rng(plan.clip["pick"]).choice(
        cands, size=min(plan.clip["count"], len(cands)), replace=False)
    for c in pick:
        full_scale[c] = peak[chans.index(c)] / plan.clip["overdrive"]
    by_ch = {g.channel: g.number for g in rig.gages}
    plan.gages = tuple(by_ch[int(c)] for c in pick)
    plan.params.update(gages=list(plan.gages), full_scale_V=[float(full_scale[c]) for c in pick])


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple | np.ndarray):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.integer | bool):
        return x if isinstance(x, bool) else int(x)
    if isinstance(x, np.floating | float):
        return float(x)
    return x
