"""The hidden effects of the truth generator: each turns a dimensionless size into the physical
parameters it injects into the truth structure or front-end, and says where it shows.

Every planner takes the trial's :class:`Context` (nominal and truth-baseline modes, gages, blows),
the size (>= 0) and its own random generator, and returns a :class:`Plan`: keyword arguments for
:func:`ramdaq.analysis.truth.structure.build_truth_model`, drives (ambient tone, friction, second blows)
and front-end changes (gain, moved gage, clipping, skew, high-pass), plus the metadata of
:class:`ramdaq.analysis.truth.trial.TruthEffect`. Sizes are scaled so that a visible amplitude grows about
linearly with size: 1.0 is plain on an oscillogram, 0.1 barely. ``REFERENCE`` says what 1.0 is.

Where each shows (``TruthEffect.gages`` / ``mode_hz`` / ``window``):

* hull_coupling: the gages where its new mode is at least half as visible as on its best one (the
  hull's athwartship gages on both rigs) / nominal mode nearest the new one (log scale, as bands
  are cut) / all.
* ambient_tone: the hull's athwartship gages (it is hull vibration; rudder and stock gages carry it
  about as strongly, the vertical hull gages not at all: see ``steady_amplitude_per_gage_m_s2``)
  / the tone frequency / pre.
* friction: rudder gages / nominal mode nearest the friction-sensitive mode it was sized on (with
  the default intervals the lightly damped ALBACORE-like 88 Hz mode in air, 60 Hz in water, the
  SAMPSON-like 127 Hz) / late.
* tiller: rudder gages / nominal mode nearest the new (tiller) mode / all.
* added_mass: rudder gages / the nominal mode whose frequency moves most / all.
* split_mode: rudder gages / the predominant mode / late (the first beat node).
* gage_sensitivity, gage_alignment, time_skew: that rudder gage / None / all.
* clipping: the clipped gages / None / early. highpass: () / lowest nominal mode / all.
  double_hit: () / None / early. none: () / None / all.

In air, added_mass scales the rudder's own rotational inertias (or its mass) by 15 %: what an
unmodelled air-side mass (fittings, water trapped in the rudder) would do; air adds next to none.
A gage's tilt is not modelled: the rigs' rudder gages sit on the mid-plane (y = 0), where a
rigid rudder has no x or z motion, so a tilt would only scale them by its cosine.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..model.rig import Rig
from .integrate import (
    ModalRecursion,
    blow_amplitudes,
    decay_weighted,
    gage_mode_amplitudes,
    modal_recursion,
)
from .structure import TruthModel, build_truth_model

REFERENCE: dict[str, str] = {
    "none": "no effect; size is ignored",
    "hull_coupling": "a local hull mode at 0.7-0.9 or 1.1-1.4x the predominant frequency (modal mass "
                     "= rudder's, zeta 2 %) coupled at the stock so that, on the gage where it shows "
                     "most, its amplitude is 1.5x the other modes' plus 10 noise rms; amplitude ~ size",
    "ambient_tone": "narrowband hull vibration near a hull mode (SAMPSON 2.18 Hz), amplitude at the "
                    "hull gages 20x the channel noise rms; its drive wanders +-15 % in amplitude and "
                    "~1 rad in phase over ~5 s",
    "friction": "Coulomb torque on the rudder's rotation in its bearing that stops the most "
                "friction-sensitive visible mode's ringing half a blow interval T after the blow (its "
                "first-cycle loss is 1/(e^(sigma T/2) - 1) of the viscous one)",
    "tiller": "steering gear as stiff as the stock in torsion and a tiller of 0.3x the rudder's "
              "Iz at the stock top: torsional line half as stiff and an extra mode",
    "added_mass": "rotational (or translational, seeded) added inertia 30 % off Eq 19-21 in water; "
                  "in air the rudder's own rotational inertia (or mass) 15 % off",
    "split_mode": "a tuned absorber on the rudder splits the predominant mode into two modes "
                  "3 zeta (2-4 %) apart, so the decay envelope beats to a node at ~1/3 amplitude",
    "gage_sensitivity": "one rudder gage reads 20 % high",
    "gage_alignment": "one rudder gage sits 0.3 m from where the rig says, along x or z",
    "clipping": "one or two rudder channels' ADC range so low that the median blow peaks at 2x "
                "the rail",
    "time_skew": "one rudder channel sampled 2 ms late (a multiplexed converter)",
    "highpass": "AC coupling: first-order high-pass at 1 Hz on every channel, before the ADC",
    "double_hit": "a second half-sine blow 10-40 ms after each blow, of 0.3x its peak",
}


HULL_VISIBILITY = 1.5
"""hull_coupling at size 1: the extra mode's amplitude is 1.5x the rest plus 10 noise rms."""


@dataclass
class Context:
    """What a planner may look at. Frequencies Hz; gage tuples are report gage numbers."""

    rig: Rig
    ambient_hz: float | None
    fs_hz: float
    dt: float
    nominal_hz: np.ndarray
    nominal_zeta: np.ndarray
    pred: int
    base: TruthModel
    base_rec: ModalRecursion
    onsets_s: np.ndarray
    peaks_N: np.ndarray
    interval_s: float
    stock_mass_factor: float = 1.0

    def build(self, **kw) -> TruthModel:
        """The truth structure with an effect's additions (``build_truth_model`` keywords)."""
        return build_truth_model(self.rig, stock_mass_factor=self.stock_mass_factor, **kw)

    def gages_on(self, body: str) -> tuple[int, ...]:
        return tuple(g.number for g in self.rig.gages if g.body == body)

    def channel(self, gage: int) -> int:
        return self.rig.gage(gage).channel

    @property
    def pred_hz(self) -> float:
        return float(self.nominal_hz[self.pred])

    def nearest_nominal(self, f_hz: float) -> float:
        return float(self.nominal_hz[np.argmin(np.abs(np.log(self.nominal_hz / f_hz)))])


@dataclass
class Plan:
    """One effect's injection and where it shows (see the module docstring)."""

    params: dict = field(default_factory=dict)
    gages: tuple[int, ...] = ()
    mode_hz: float | None = None
    window: str = "all"
    model_kw: dict = field(default_factory=dict)
    ambient: dict | None = None
    friction: dict | None = None
    second_blows: tuple[np.ndarray, np.ndarray] | None = None
    gain: dict[int, float] = field(default_factory=dict)
    moved: dict[int, tuple[str, tuple[float, float, float], str]] = field(default_factory=dict)
    clip: dict | None = None
    skew: dict | None = None
    highpass: dict | None = None
    model: TruthModel | None = None


def _impact(ctx: Context, rec: ModalRecursion) -> np.ndarray:
    imp = ctx.rig.impact
    return blow_amplitudes(rec, imp.peak_force_N, imp.duration_s, imp.location_m, imp.direction)


def truth_predominant(ctx: Context, rec: ModalRecursion) -> int:
    """Index of the truth model's predominant mode (the measure of response.predominant_mode)."""
    rows = [i for i, g in enumerate(ctx.rig.gages_by_channel()) if g.body == "rudder"]
    return int(np.argmax(decay_weighted(rec, gage_mode_amplitudes(rec, _impact(ctx, rec)))[rows].sum(0)))


def _new_mode(ctx: Context, rec: ModalRecursion, dof: str) -> int:
    """The mode whose kinetic energy lies most in ``dof``."""
    i = rec.model.dofs.index(dof)
    n = rec.model.n_dof
    Vq = rec.V[:n]
    energy = np.abs(Vq) * np.abs(rec.model.M @ Vq)
    share = energy[i] / energy.sum(axis=0)
    return int(np.argmax(np.where(np.abs(rec.lam.imag) > 0, share, 0)))


def visibility(ctx: Context, rec: ModalRecursion, mode: int) -> np.ndarray:
    """Per gage (channel order), ``mode``'s acceleration amplitude after a blow over the sum of
    the other modes' plus 10 noise rms: how plainly it stands out on that gage's oscillogram."""
    acc = gage_mode_amplitudes(rec, _impact(ctx, rec)) * np.abs(rec.lam) ** 2
    others = acc.sum(axis=1) - acc[:, mode]
    return acc[:, mode] / (others + 10 * ctx.rig.daq.noise_m_s2_rms)


def _showing_gages(ctx: Context, rec: ModalRecursion, mode: int) -> tuple[int, ...]:
    """Gages where ``mode`` is at least half as visible as on its best gage."""
    vis = visibility(ctx, rec, mode)
    if not vis.max() > 0:
        return ()
    chans = ctx.rig.gages_by_channel()
    return tuple(sorted(chans[i].number for i in np.flatnonzero(vis >= 0.5 * vis.max())))


def mode_shifts(ctx: Context, rec: ModalRecursion, skip: int | None = None) -> np.ndarray:
    """Relative frequency change of each of the first ``len(nominal_hz)`` truth-baseline modes:
    to the nearest mode of ``rec`` (``skip`` excluded, e.g. a new mode)."""
    fb = ctx.base_rec.lam.imag[:len(ctx.nominal_hz)]
    f = rec.lam.imag.copy()
    if skip is not None:
        f[skip] = np.inf
    return np.array([f[np.argmin(np.abs(np.log(np.abs(f) / x)))] / x - 1 for x in fb])


def _structural(ctx: Context, plan: Plan, dof: str) -> None:
    """Build the effect's model once; name its new mode, the gages it shows on and its neighbour."""
    model = ctx.build(**plan.model_kw)
    rec = modal_recursion(model, ctx.dt)
    k = _new_mode(ctx, rec, dof)
    f = float(rec.lam[k].imag / (2 * math.pi))
    plan.params.update(new_mode_hz=f, new_mode_damping_ratio=float(-rec.lam[k].real / abs(rec.lam[k])),
                       nominal_modes_hz=[float(x) for x in ctx.nominal_hz],
                       mode_shift=[float(x) for x in mode_shifts(ctx, rec, skip=k)])
    plan.mode_hz = ctx.nearest_nominal(f)
    plan.model = model
    if not plan.gages:
        plan.gages = _showing_gages(ctx, rec, k)


def hull_coupling(ctx: Context, size: float, rng: np.random.Generator) -> Plan:
    for _ in range(50):
        ratio = float(rng.choice([rng.uniform(0.7, 0.9), rng.uniform(1.1, 1.4)]))
        f = ratio * ctx.pred_hz
        if np.all(np.abs(ctx.nominal_hz / f - 1) > 0.08):
            break
    m_x = float(ctx.base.M[0, 0])  # rudder + added mass
    g, a = rng.choice([-1, 1]) * rng.uniform(0.05, 0.2), rng.choice([-1, 1]) * rng.uniform(0.05, 0.2)

    def hull(p: float) -> dict:
        return dict(frequency_hz=f, damping_ratio=0.02, modal_mass_kg=m_x, v_b=p, gamma_b=p * g,
                    alpha_b=p * a)

    # the extra mode's visibility grows as p^2: measure it at a weak reference coupling, then
    # scale p so that at size 1 it reaches HULL_VISIBILITY on the gage where it shows most
    ref = modal_recursion(ctx.build(extra_hull=hull(0.05)), ctx.dt)
    p = min(0.5, 0.05 * math.sqrt(HULL_VISIBILITY / visibility(ctx, ref, _new_mode(ctx, ref, "eta_x")).max()))
    plan = Plan(params=dict(hull(p * math.sqrt(size)), frequency_ratio=ratio, participation_at_size_1=p),
                model_kw=dict(extra_hull=hull(p * math.sqrt(size))), window="all")
    _structural(ctx, plan, "eta_x")
    return plan


def ambient_tone(ctx: Context, size: float, rng: np.random.Generator) -> Plan:
    if ctx.ambient_hz is not None:
        f = ctx.ambient_hz
    else:  # near the coupled mode that hull mode 1 dominates
        k = _new_mode(ctx, ctx.base_rec, "eta1")
        f = float(ctx.base_rec.lam[k].imag / (2 * math.pi)) * (1 + rng.uniform(-0.01, 0.01))
    hull_y = [i for i, g in enumerate(ctx.rig.gages_by_channel())
              if g.body == "hull" and g.axis.endswith("y")]
    m = ctx.base
    w = 2 * math.pi * f
    e = np.zeros(m.n_dof)
    e[m.dofs.index("eta1")] = 1.0
    X = np.linalg.solve(m.K - w**2 * m.M + 1j * w * m.C, e)
    per_N = np.abs(w**2 * (m.gage_dofs @ X))
    ref = hull_y[int(np.argmax(per_N[hull_y]))]
    target = 20 * ctx.rig.daq.noise_m_s2_rms * size
    plan = Plan(gages=tuple(ctx.rig.gages_by_channel()[i].number for i in hull_y), mode_hz=float(f),
                window="pre")
    plan.ambient = dict(frequency_hz=f, force_N=target / per_N[ref], amp_wander=0.15, phase_wander_rad=1.0,
                        wander_time_s=5.0, hull_mode=1, reference_channel=ref, amplitude_m_s2=target)
    plan.params = dict(plan.ambient, reference_gage=ctx.rig.gages_by_channel()[ref].number,
                       steady_amplitude_per_gage_m_s2={str(g.number): float(a * target / per_N[ref])
                                                       for g, a in zip(ctx.rig.gages_by_channel(), per_N,
                                                                       strict=True)})
    return plan


def friction(ctx: Context, size: float, rng: np.random.Generator) -> Plan:
    rec, model = ctx.base_rec, ctx.base
    n = model.n_dof
    z = _impact(ctx, rec)
    rows = [i for i, g in enumerate(ctx.rig.gages_by_channel()) if g.body == "rudder"]
    acc = (gage_mode_amplitudes(rec, z)[rows] * np.abs(rec.lam) ** 2).max(axis=0)
    f_hz = rec.lam.imag / (2 * math.pi)
    row = np.eye(n)[1] - model.rows["hull_gamma"]
    best = None
    for k in np.flatnonzero((acc >= 0.1 * acc.max()) & (f_hz > 0) & (f_hz < ctx.rig.daq.anti_alias_hz)):
        u = 2 * rec.lam[k] * rec.V[:n, k] * z[k]  # velocity amplitudes of the first cycle
        omega = abs(rec.lam[k].imag)
        loss = math.pi / omega * float(np.real(np.conj(u) @ model.C @ u))  # viscous, J per cycle
        theta = 2 * abs(row @ rec.V[:n, k] * z[k])
        share = 1 / math.expm1(abs(rec.lam[k].real) * ctx.interval_s / 2)
        torque = share * loss / (4 * theta)
        if best is None or torque < best[0]:
            best = (torque, k, theta, omega, loss, share)
    torque, k, theta, omega, loss, share = best
    plan = Plan(gages=ctx.gages_on("rudder"), mode_hz=ctx.nearest_nominal(f_hz[k]), window="late")
    plan.friction = dict(torque_N_m=size * torque, rate_eps_rad_s=0.02 * omega * theta)
    plan.params = dict(plan.friction, sized_on_mode_hz=float(f_hz[k]), first_cycle_rotation_rad=theta,
                       first_cycle_viscous_loss_J=loss, first_cycle_loss_share=share,
                       where="rudder rotation gamma relative to the hull (stock turning in its bearing)")
    return plan


def tiller(ctx: Context, size: float, rng: np.random.Generator) -> Plan:
    st = ctx.rig.stock
    plan = Plan(gages=ctx.gages_on("rudder"), window="all")
    if size <= 0:
        plan.mode_hz = ctx.pred_hz
        return plan
    k_stock = st.G_Pa * st.J_m4 / st.torsion_length_m
    til = dict(inertia_kg_m2=0.3 * size * float(ctx.base.M[1, 1]), stiffness_N_m_per_rad=k_stock / size,
               damping_ratio=0.03)
    plan.params = dict(til, stock_torsion_N_m_per_rad=k_stock)
    plan.model_kw = dict(tiller=til)
    _structural(ctx, plan, "tiller")
    return plan


def added_mass(ctx: Context, size: float, rng: np.random.Generator) -> Plan:
    which = str(rng.choice(["rotational", "translational"]))
    up = bool(rng.integers(2))
    per = 0.3 if ctx.rig.medium == "water" else 0.15
    fac = (1 + per * size) if up else 1 / (1 + per * size)
    factors = (1.0, fac) if which == "rotational" else (fac, 1.0)
    plan = Plan(gages=ctx.gages_on("rudder"), window="all", model_kw=dict(inertia_factors=factors))
    model = ctx.build(**plan.model_kw)
    rec = modal_recursion(model, ctx.dt)
    shift = mode_shifts(ctx, rec)
    plan.mode_hz = float(ctx.nominal_hz[int(np.argmax(np.abs(shift)))])
    plan.model = model
    quantity = ("added " if ctx.rig.medium == "water" else "own ") + which
    plan.params = dict(scaled=quantity + (" inertias" if which == "rotational" else " mass"), factor=fac,
                       nominal_modes_hz=[float(x) for x in ctx.nominal_hz],
                       mode_shift=[float(s) for s in shift])
    return plan


def split_mode(ctx: Context, size: float, rng: np.random.Generator) -> Plan:
    rec, model = ctx.base_rec, ctx.base
    k = truth_predominant(ctx, rec)
    n = model.n_dof
    w = abs(rec.lam[k])
    zeta = float(-rec.lam[k].real / w)
    sep = size * min(max(0.02, 3 * zeta), 0.04)  # first beat node where the decay is at ~1/3
    phi = rec.V[:n, k] / np.abs(rec.V[:n, k]).max()
    phi = np.real(phi * np.exp(-1j * np.angle(phi[np.argmax(np.abs(phi))])))
    rud = [g for g in ctx.rig.gages if g.body == "rudder" and g.axis.endswith("y")]
    disp = [abs(model.point_row("rudder", g.position_m, "y") @ phi) for g in rud]
    point = rud[int(np.argmax(disp))].position_m
    modal_mass = float(phi @ model.M @ phi) / max(disp) ** 2
    m_a = sep**2 * modal_mass
    plan = Plan(gages=ctx.gages_on("rudder"), mode_hz=ctx.pred_hz, window="late")
    if size <= 0:
        return plan
    absorber = dict(mass_kg=m_a, stiffness_N_per_m=m_a * w**2, damping_N_s_per_m=2 * zeta * w * m_a,
                    point_m=point, axis="y")
    plan.model_kw = dict(absorber=absorber)
    split = ctx.build(absorber=absorber)
    r2 = modal_recursion(split, ctx.dt)
    near = np.argsort(np.abs(r2.lam.imag - w))[:2]
    fz = np.sort(r2.lam[near].imag / (2 * math.pi))
    plan.model = split
    plan.params = dict(absorber, point_m=list(point), target_separation=sep, split_hz=[float(x) for x in fz],
                       mode_modal_mass_kg=modal_mass)
    return plan


def gage_sensitivity(ctx: Context, size: float, rng: np.random.Generator) -> Plan:
    gage = int(rng.choice(ctx.gages_on("rudder")))
    fac = 1 + 0.2 * size
    return Plan(gages=(gage,), window="all", gain={ctx.channel(gage): fac},
                params=dict(gage=gage, sensitivity_factor=fac))


def gage_alignment(ctx: Context, size: float, rng: np.random.Generator) -> Plan:
    gage = int(rng.choice(ctx.gages_on("rudder")))
    g = ctx.rig.gage(gage)
    along = int(rng.choice([0, 2]))
    off = np.zeros(3)
    off[along] = rng.choice([-1.0, 1.0]) * 0.3 * size
    pos = tuple(float(c) for c in np.add(g.position_m, off))
    return Plan(gages=(gage,), window="all", moved={g.channel: ("rudder", pos, g.axis)},
                params=dict(gage=gage, offset_m=[float(c) for c in off], true_position_m=list(pos),
                            axis=g.axis))


def clipping(ctx: Context, size: float, rng: np.random.Generator) -> Plan:
    return Plan(window="early", clip=dict(count=int(rng.integers(1, 3)), overdrive=1 + size,
                                          pick=int(rng.integers(1 << 30))),
                params=dict(peak_over_rail=1 + size))


def time_skew(ctx: Context, size: float, rng: np.random.Generator) -> Plan:
    gage = int(rng.choice(ctx.gages_on("rudder")))
    delay = 2e-3 * size
    return Plan(gages=(gage,), window="all", skew=dict(channel=ctx.channel(gage), delay_s=delay),
                params=dict(gage=gage, delay_s=delay))


def highpass(ctx: Context, size: float, rng: np.random.Generator) -> Plan:
    corner = 1.0 * size
    return Plan(mode_hz=float(ctx.nominal_hz.min()), window="all",
                highpass=dict(corner_hz=corner, order=1) if corner > 0 else None,
                params=dict(corner_hz=corner, order=1, channels="all"))


def double_hit(ctx: Context, size: float, rng: np.random.Generator) -> Plan:
    delays = rng.uniform(0.010, 0.040, len(ctx.onsets_s))
    peaks = 0.3 * size * ctx.peaks_N
    return Plan(window="early", second_blows=(ctx.onsets_s + delays, peaks),
                params=dict(delays_s=[float(d) for d in delays], second_peaks_N=[float(p) for p in peaks]))


def none(ctx: Context, size: float, rng: np.random.Generator) -> Plan:
    return Plan()


PLANNERS: dict[str, Callable[[Context, float, np.random.Generator], Plan]] = {
    "none": none, "hull_coupling": hull_coupling, "ambient_tone": ambient_tone, "friction": friction,
    "tiller": tiller, "added_mass": added_mass, "split_mode": split_mode,
    "gage_sensitivity": gage_sensitivity, "gage_alignment": gage_alignment, "clipping": clipping,
    "time_skew": time_skew, "highpass": highpass, "double_hit": double_hit,
}
