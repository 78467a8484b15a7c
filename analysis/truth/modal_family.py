"""The ``modal`` generator family: impact trials that share nothing with the diagnosis's model.

Issue 17's second family. Free modal superposition with its own, random but physical mode shapes:
no stiffness, no mass matrix, no rig model -- numpy and scipy only, plus the gages' numbers,
bodies, positions and axes and the DAQ's constants read from a rig file's TOML *as data*
(:func:`gages_from_toml`). It imports nothing from ``analysis.model``, ``analysis.gap`` or the
truth simulator (``tests/test_modal_family.py`` checks that).

A trial (:func:`generate`):

* **Modes**: the rudder's, near frequencies the caller hands in (the rig's nominal modes, as
  plain numbers; each x U(0.93, 1.07)), plus two or three hull modes at 4-15 Hz. Shapes are
  smooth in position: on the rudder a low-order polynomial of (x, z) weighted to bending (z) or
  torsion (x) by mode, the stock following at 30-70 % of the rudder's field, the hull carrying
  2-10 %; hull modes a linear field over the hull gages and a common rigid ride of the rudder.
  Damping ratios log-uniform 0.5-5 %.
* **Blows**: half-sine of a contact time drawn once per trial (3-8 ms), peaks spread
  log-evenly over 0.5-2x the nominal force (homogeneity across forces is a check).
* **Chain**: responses at ``OVERSAMPLE`` x the rate (exact zero-order-hold per mode), the rig's
  anti-alias Butterworth, decimation, coloured noise (white, 1/f, common-mode), 16-bit ADC
  with its full scale set so the largest blow peaks at ~40 % of the range.
* **Effects**, built here and nowhere else: the library's kinds (:data:`LIBRARY`) and effects the
  diagnosis's library does not hold (:data:`OUTSIDE`), whose right answer is "unexplained".
  Friction, a split, a crack and a stop (rattle) act on the predominant rudder mode, the one
  that rings fastest after a blow (participation per modal mass times the half-sine's spectrum
  there, :func:`ringing_per_impulse`), at amplitudes set from its median blow; their gages are
  where that mode shows (half its largest shape or more), which is where the trial departs from
  its clean twin.

Units SI; shapes (n_gages, n) in the rig file's channel order.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.signal

OVERSAMPLE = 4
ADC_BITS = 16
HEADROOM = 0.4
"""The largest blow's peak as a fraction of the ADC's full scale (a trial engineer's range)."""
LIBRARY = ("none", "gage_sensitivity", "time_skew", "clipping", "highpass",
           "ambient_tone", "double_hit", "friction", "hull_coupling", "split_mode")
"""Effects of kinds the diagnosis's library names (each built independently here)."""
OUTSIDE = ("crack", "rattle", "mains_pickup", "sensor_resonance", "gain_drift")
"""Effects the library does not hold: the right verdict is "unexplained", with where and how big."""
EFFECTS = LIBRARY + OUTSIDE


@dataclass(frozen=True)
class GageSpec:
    """A gage as data: its ``number``, ``body`` ("rudder", "stock", "hull"), ``position_m`` (3,),
    sensing ``axis`` ("y"/"z", sign allowed), DAQ ``channel`` and ``sensitivity`` V per m/s^2."""

    number: int
    body: str
    position_m: tuple[float, float, float]
    axis: str
    channel: int
    sensitivity: float


@dataclass(frozen=True)
class RigData:
    """What the generator reads of a rig file: gages in channel order, the DAQ's rate, anti-alias
    corner and order, noise rms (m/s^2), the ram's location (m) and nominal peak force (N)."""

    gages: tuple[GageSpec, ...]
    fs_hz: float
    anti_alias_hz: float
    anti_alias_order: int
    noise_rms: float
    ram_m: tuple[float, float, float]
    force_N: float


def gages_from_toml(text: str) -> RigData:
    """The gages, DAQ and ram of a rig file's TOML text, read as plain data."""
    doc = tomllib.loads(text)
    try:
        gs = [GageSpec(int(g["number"]), str(g["body"]), tuple(float(v) for v in g["position_m"]),
                       str(g["axis"]), int(g["channel"]), float(g["sensitivity_V_per_m_s2"]))
              for g in doc["gages"]]
        d, imp = doc["daq"], doc["impact"]
        return RigData(tuple(sorted(gs, key=lambda g: g.channel)), float(d["sample_rate_hz"]),
                       float(d["anti_alias_hz"]), int(d["anti_alias_order"]), float(d["noise_m_s2_rms"]),
                       tuple(float(v) for v in imp["location_m"]), float(imp["peak_force_N"]))
    except KeyError as exc:
        raise ValueError(f"rig TOML: the modal family needs key {exc} (gages, daq, impact)") from None


@dataclass(frozen=True)
class FamilyEffect:
    """The hidden effect: ``name``, ``size`` (1.0 plain on an oscillogram), ``params`` (SI,
    JSON-able), ``gages`` where it shows, ``mode_hz`` the mode or line (Hz) or None, ``window``
    ("pre", "early", "late", "all"); ``expect`` the verdict a right diagnosis gives (the
    library's effect name, "none", or "unexplained")."""

    name: str
    size: float
    params: dict
    gages: tuple[int, ...]
    mode_hz: float | None
    window: str
    expect: str


@dataclass(frozen=True)
class ModalTrial:
    """``counts`` int32 (n_ch, n); ``scale`` (n_ch,) m/s^2 per count; ``fs_hz``; ``gage_numbers``
    per row; ``onsets_s``, ``peaks_N`` (n_imp,); ``modes`` (f_hz, zeta) of the generator;
    ``adc_bits``; ``effect``; ``seed``."""

    counts: np.ndarray
    scale: np.ndarray
    fs_hz: float
    gage_numbers: tuple[int, ...]
    onsets_s: np.ndarray
    peaks_N: np.ndarray
    modes: tuple[tuple[float, float], ...]
    adc_bits: int
    effect: FamilyEffect
    seed: int

    @property
    def acc(self) -> np.ndarray:
        """Recorded accelerations, m/s^2, (n_ch, n)."""
        return self.counts * self.scale[:, None]


@dataclass
class Modes:
    """The structure as the generator sees it: per mode its frequency (Hz), damping ratio,
    shape at each gage (n_g,), at the ram and at the tiller (stock top), and a ``kind``."""

    f_hz: np.ndarray
    zeta: np.ndarray
    shape: np.ndarray          # (K, n_g)
    at_ram: np.ndarray         # (K,)
    at_tiller: np.ndarray      # (K,)
    kind: list[str] = field(default_factory=list)


def _field(rng: np.random.Generator, kind: str) -> np.ndarray:
    """Coefficients of a smooth field c0 + c1 xi + c2 zeta + c3 xi zeta + c4 zeta^2 + c5 xi^2:
    bending-like modes grow with height (zeta), torsion-like with chord (xi)."""
    w = {"bending": [0.3, 0.3, 1.0, 0.2, 0.6, 0.1], "torsion": [0.2, 1.0, 0.3, 0.5, 0.1, 0.3],
         "mixed": [0.3, 0.8, 0.8, 0.4, 0.3, 0.3]}[kind]
    return rng.standard_normal(6) * np.array(w)


def _eval(c: np.ndarray, p: np.ndarray, span: np.ndarray) -> np.ndarray:
    xi, ze = p[..., 0] / span[0], p[..., 2] / span[2]
    return c[0] + c[1] * xi + c[2] * ze + c[3] * xi * ze + c[4] * ze**2 + c[5] * xi**2


def draw_modes(rig: RigData, rudder_hz: Sequence[float], rng: np.random.Generator) -> Modes:
    """Random but physical modes (:class:`Modes`) for the rig's gages and ram."""
    pos = np.array([g.position_m for g in rig.gages])
    body = np.array([g.body for g in rig.gages])
    vert = np.array(["z" in g.axis for g in rig.gages])
    rud = body != "hull"
    span = np.maximum(np.abs(pos[rud]).max(axis=0), 0.3)
    ram = np.array(rig.ram_m)
    top = pos[body == "stock"].max(axis=0) if (body == "stock").any() else np.array([0.0, 0.0, span[2]])
    hull = body == "hull"
    hull_span = np.maximum(np.abs(pos[hull]).max(axis=0), 1.0) if hull.any() else span
    f, z, sh, ar, at, kinds = [], [], [], [], [], []
    for k, f0 in enumerate(rudder_hz):
        kind = ("bending", "torsion", "mixed")[k % 3]
        c = _field(rng, kind)
        s = _eval(c, pos, span)
        s[body == "stock"] *= rng.uniform(0.3, 0.7)
        # the hull feels the rudder's modes at 2-10 %, smoothly over its own extent
        lin = rng.uniform(-0.3, 0.3, 2)
        s[hull] = rng.uniform(0.02, 0.1) * (1 + lin[0] * pos[hull, 0] / hull_span[0]
                                            + lin[1] * pos[hull, 2] / hull_span[2])
        s[vert] *= 0.2
        norm = np.abs(s[rud & ~vert]).max() if (rud & ~vert).any() else 1.0
        f.append(f0 * rng.uniform(0.93, 1.07))
        z.append(math.exp(rng.uniform(math.log(0.005), math.log(0.05))))
        sh.append(s / norm)
        ar.append(_eval(c, ram, span) / norm)
        at.append(0.5 * _eval(c, top, span) / norm)
        kinds.append(kind)
    for fh in np.sort(rng.uniform(4.0, 15.0, int(rng.integers(2, 4)))):
        lin = rng.standard_normal(3)
        own = 1.0 + lin[0] * pos[:, 0] / hull_span[0] + lin[1] * pos[:, 2] / hull_span[2]
        s = np.where(body == "hull", own, rng.uniform(0.2, 0.6))
        s[vert] = lin[2] * rng.uniform(0.3, 1.0)
        f.append(float(fh))
        z.append(math.exp(rng.uniform(math.log(0.005), math.log(0.05))))
        sh.append(s / np.abs(s).max())
        ar.append(rng.uniform(0.2, 0.5))
        at.append(rng.uniform(0.2, 0.5))
        kinds.append("hull")
    return Modes(np.array(f), np.array(z), np.array(sh), np.array(ar), np.array(at), kinds)


def mode_filter(f_hz: float, zeta: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) of the exact zero-order-hold discretisation of one mode's acceleration per unit
    modal force (per kg): s^2 / (s^2 + 2 zeta w s + w^2)."""
    w = 2 * math.pi * f_hz
    b, a, _ = scipy.signal.cont2discrete(([1.0, 0.0, 0.0], [1.0, 2 * zeta * w, w * w]), dt, method="zoh")
    return np.ravel(b), np.ravel(a)


def half_sine(onsets: np.ndarray, peaks: np.ndarray, contact_s: float, t: np.ndarray) -> np.ndarray:
    """The ram's force (N) at times ``t``: a half-sine of ``contact_s`` from each onset."""
    out = np.zeros_like(t)
    dt = t[1] - t[0]
    for t0, p in zip(onsets, peaks, strict=True):
        i = int(math.ceil(t0 / dt))
        tt = t[i:i + int(contact_s / dt) + 2] - t0
        out[i:i + tt.size] += p * np.where(tt < contact_s, np.sin(math.pi * tt / contact_s), 0.0)
    return out


def ringing_per_impulse(f_hz: float, contact_s: float) -> float:
    """A half-sine blow's ringing at ``f_hz`` as a fraction of an impulse's of the same area:
    |F(w)| / F(0) = |cos(w T / 2) / (1 - (w T / pi)^2)| for contact time T (s); 1 for a short
    blow, pi / 4 at w T = pi, near 0 for a mode well above 1 / T."""
    x = 2 * f_hz * contact_s          # w T / pi
    return math.pi / 4 if abs(1 - x * x) < 1e-9 else abs(math.cos(math.pi * x / 2) / (1 - x * x))


def nonlinear_mode(f_hz: float, zeta: float, force: np.ndarray, dt: float, *,
                   coulomb: float = 0.0, crack_at: float = math.inf, crack_drop: float = 0.0,
                   stop_at: float = math.inf, stop_k: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """One mode (unit modal mass) integrated step by step (semi-implicit Euler at ``dt``), with
    an amplitude-dependent law: Coulomb friction ``coulomb`` (m/s^2 equivalent), a crack that
    opens beyond ``crack_at`` (m, one side) and lowers the stiffness by ``crack_drop``, a hard
    stop beyond ``|q| > stop_at`` of stiffness ``stop_k`` x w^2. Returns the acceleration and
    the stop's contact force per unit modal mass, each (n,)."""
    w2, c = (2 * math.pi * f_hz) ** 2, 2 * zeta * 2 * math.pi * f_hz
    n = force.size
    acc, contact = np.zeros(n), np.zeros(n)
    q = v = 0.0
    for i in range(n):
        k = w2 * (1 - crack_drop) if q > crack_at else w2
        r = 0.0
        if abs(q) > stop_at:
            r = -stop_k * w2 * (abs(q) - stop_at) * (1 if q > 0 else -1)
        fr = -coulomb * (1 if v > 0 else -1 if v < 0 else 0)
        a = force[i] - c * v - k * q + r + fr
        if coulomb and abs(v) < abs(a) * dt and abs(force[i] - k * q + r) <= coulomb:
            a, v = 0.0, 0.0          # stuck: static friction holds
        v += a * dt
        q += v * dt
        acc[i], contact[i] = a, r
    return acc, contact


RUDDER_MASS_KG = 3000.0
"""Modal mass of each rudder mode (x U(0.5, 1.5)) for a unit shape at the gage that moves most."""
HULL_MASS_KG = 3.0e4
"""Modal mass of each hull mode (x U(0.5, 2))."""


@dataclass
class Plan:
    """What an effect changes, stage by stage (filled by :func:`_plan`)."""

    params: dict = field(default_factory=dict)
    gages: tuple[int, ...] = ()
    mode_hz: float | None = None
    window: str = "all"
    nonlinear: dict = field(default_factory=dict)      # keyword arguments of nonlinear_mode
    second: tuple[np.ndarray, np.ndarray] | None = None
    gain: dict[int, float] = field(default_factory=dict)
    drift: dict[int, float] = field(default_factory=dict)
    skew: dict[int, float] = field(default_factory=dict)
    resonance: dict[int, tuple[float, float]] = field(default_factory=dict)
    highpass: dict[int, float] = field(default_factory=dict)
    tone: dict | None = None
    mains: dict | None = None
    clip: dict[int, float] = field(default_factory=dict)


def _pick(rig: RigData, rng: np.random.Generator, body: tuple[str, ...] = ("rudder",),
          n: int = 1) -> list[int]:
    """``n`` channel rows of athwartship gages on ``body``, drawn."""
    rows = [i for i, g in enumerate(rig.gages) if g.body in body and "z" not in g.axis]
    return sorted(int(r) for r in rng.choice(rows, size=min(n, len(rows)), replace=False))


def _showing(modes: Modes, k: int, rig: RigData, frac: float = 0.5) -> tuple[int, ...]:
    s = np.abs(modes.shape[k])
    return tuple(rig.gages[i].number for i in np.flatnonzero(s >= frac * s.max()))


def _plan(effect: str, size: float, rig: RigData, modes: Modes, masses: np.ndarray, pred: int,
          q0: float, interval: float, onsets: np.ndarray, peaks: np.ndarray,
          rng: np.random.Generator) -> Plan:
    """The effect's plan; may change ``modes``/``masses`` in place (an extra or split mode)."""
    p, num = Plan(), [g.number for g in rig.gages]
    f = float(modes.f_hz[pred])
    if effect == "gage_sensitivity":
        (r,) = _pick(rig, rng)
        p.gain, p.gages, p.params = {r: 1 + 0.2 * size}, (num[r],), {"gain": 1 + 0.2 * size}
    elif effect == "time_skew":
        (r,) = _pick(rig, rng)
        p.skew, p.gages, p.params = {r: 2e-3 * size}, (num[r],), {"delay_s": 2e-3 * size}
    elif effect == "clipping":
        rows = _pick(rig, rng, n=int(rng.integers(1, 3)))
        p.clip = {r: 1 + size for r in rows}
        p.gages, p.window, p.params = tuple(num[r] for r in rows), "early", {"overdrive": 1 + size}
    elif effect == "highpass":
        rows = sorted(int(r) for r in rng.choice(len(num), size=int(rng.integers(4, 7)), replace=False))
        p.highpass = {r: 1.5 * size for r in rows}
        p.gages, p.mode_hz = tuple(num[r] for r in rows), float(modes.f_hz.min())
        p.params = {"corner_hz": 1.5 * size}
    elif effect == "ambient_tone":
        k = int(np.flatnonzero(np.array(modes.kind) == "hull")[0])
        p.tone = {"mode": k, "f_hz": float(modes.f_hz[k]), "amp": 20 * rig.noise_rms * size}
        hull = [i for i, g in enumerate(rig.gages) if g.body == "hull" and "z" not in g.axis]
        s = np.abs(modes.shape[k, hull])
        p.gages = tuple(num[hull[i]] for i in np.flatnonzero(s >= 0.5 * s.max()))
        p.mode_hz, p.window, p.params = float(modes.f_hz[k]), "pre", dict(p.tone)
    elif effect == "double_hit":
        delay = rng.uniform(0.010, 0.060)
        p.second = (onsets + delay, 0.3 * size * peaks)
        p.window, p.params = "early", {"delay_s": delay, "ratio": 0.3 * size}
    elif effect == "friction":
        # Coulomb loss 4 mu / w^2 of displacement amplitude per cycle: the median blow's
        # ringing stops about 1/size half-intervals after the blow
        mu = size * q0 * (2 * math.pi * f) ** 2 / (4 * f * interval / 2)
        p.nonlinear = {"coulomb": mu}
        p.gages, p.mode_hz, p.window, p.params = _showing(modes, pred, rig), f, "late", {"coulomb": mu}
    elif effect == "hull_coupling":
        fx = f * (rng.uniform(0.7, 0.9) if rng.random() < 0.5 else rng.uniform(1.1, 1.4))
        s = np.array([1.0 if g.body == "hull" and "z" not in g.axis else 0.3 if g.body == "stock" else 0.05
                      for g in rig.gages]) * rng.uniform(0.7, 1.0, len(num))
        _add_mode(modes, masses, fx, 0.02, s, 0.3 * size, "hull_coupling", RUDDER_MASS_KG)
        k = modes.f_hz.size - 1
        p.gages, p.mode_hz, p.params = _showing(modes, k, rig), fx, {"f_hz": fx, "at_ram": 0.3 * size}
    elif effect == "split_mode":
        dz = 3 * modes.zeta[pred] * min(size, 2.0)
        _add_mode(modes, masses, f * (1 + dz / 2), modes.zeta[pred], modes.shape[pred].copy(),
                  modes.at_ram[pred], "split", masses[pred])
        modes.f_hz[pred] = f * (1 - dz / 2)
        p.gages, p.mode_hz, p.window, p.params = _showing(modes, pred, rig), f, "late", {"split": dz}
    elif effect == "crack":
        p.nonlinear = {"crack_at": 0.5 * q0, "crack_drop": min(0.3 * size, 0.8)}
        p.gages, p.mode_hz, p.window, p.params = _showing(modes, pred, rig), f, "early", dict(p.nonlinear)
    elif effect == "rattle":
        # a stop in the mode's own equation, as the crack: it shows where the mode does
        p.nonlinear = {"stop_at": 0.5 * q0, "stop_k": 2.0 * size}
        p.gages, p.mode_hz, p.window, p.params = _showing(modes, pred, rig), f, "early", dict(p.nonlinear)
    elif effect == "mains_pickup":
        first = int(rng.integers(0, len(num) - 2))
        rows = list(range(first, first + int(rng.integers(2, 4))))
        base = float(rng.choice([50.0, 60.0]))
        p.mains = {"rows": rows, "f_hz": base, "amp": 30 * rig.noise_rms * size, "onsets": list(onsets)}
        p.gages, p.mode_hz, p.window = tuple(num[r] for r in rows), base, "late"
        p.params = {"f_hz": base, "amp_m_s2": p.mains["amp"], "harmonics": [1, 3, 5]}
    elif effect == "sensor_resonance":
        (r,) = _pick(rig, rng)
        fr = float(np.max(modes.f_hz[:3])) * rng.uniform(0.6, 0.9)
        p.resonance = {r: (fr, 0.05 / max(size, 0.05))}
        p.gages, p.mode_hz, p.window = (num[r],), fr, "early"
        p.params = {"f_hz": fr, "zeta": 0.05 / max(size, 0.05)}
    elif effect == "gain_drift":
        (r,) = _pick(rig, rng)
        p.drift, p.gages, p.params = {r: 0.3 * size}, (num[r],), {"drift": 0.3 * size}
    elif effect != "none":
        raise ValueError(f"unknown effect {effect!r} of the modal family; one of {', '.join(EFFECTS)}")
    return p


def _add_mode(modes: Modes, masses: list, f: float, zeta: float, shape: np.ndarray, at_ram: float,
              kind: str, mass: float) -> None:
    modes.f_hz = np.append(modes.f_hz, f)
    modes.zeta = np.append(modes.zeta, zeta)
    modes.shape = np.vstack([modes.shape, shape[None]])
    modes.at_ram = np.append(modes.at_ram, at_ram)
    modes.at_tiller = np.append(modes.at_tiller, 0.5 * at_ram)
    modes.kind.append(kind)
    masses.append(mass)


def generate(rig_toml: str, rudder_hz: Sequence[float], effect: str = "none", size: float = 1.0,
             seed: int = 0, *, n_impacts: int = 6, pre_s: float = 3.0, noise: bool = True) -> ModalTrial:
    """One trial of the modal family for the gages of ``rig_toml`` (its text), rudder modes near
    ``rudder_hz`` (Hz, plain numbers), with ``effect`` (:data:`EFFECTS`) of ``size`` >= 0.
    Streams split by purpose: for one seed, the structure, blows and noise do not depend on the
    effect."""
    if effect not in EFFECTS:
        raise ValueError(f"unknown effect {effect!r} of the modal family; one of {', '.join(EFFECTS)}")
    if not (math.isfinite(size) and size >= 0):
        raise ValueError(f"effect size must be finite and >= 0, got {size}")
    if n_impacts < 2:
        raise ValueError(f"the modal family needs two or more blows, got {n_impacts}")
    rig = gages_from_toml(rig_toml)
    fs = rig.fs_hz
    dt = 1 / (OVERSAMPLE * fs)
    rs = np.random.default_rng([seed, 71])
    modes = draw_modes(rig, rudder_hz, rs)
    masses = [RUDDER_MASS_KG * rs.uniform(0.5, 1.5) if k != "hull" else HULL_MASS_KG * rs.uniform(0.5, 2.0)
              for k in modes.kind]
    rb = np.random.default_rng([seed, 72])
    contact = rb.uniform(0.003, 0.008)
    spread = rb.permutation(np.geomspace(0.5, 2.0, n_impacts))
    peaks = rig.force_N * spread * rb.uniform(0.97, 1.03, n_impacts)
    rudder = [k for k in range(len(masses)) if modes.kind[k] != "hull"]
    sigma = 2 * math.pi * modes.f_hz[rudder] * modes.zeta[rudder]
    interval = float(np.clip(math.log(20) / sigma.min(), 3.0, 6.0))
    onsets = pre_s + interval * np.arange(n_impacts) + rb.uniform(0, 1, n_impacts) / fs
    n = math.ceil((pre_s + n_impacts * interval) * fs)
    # the predominant mode rings fastest after a blow: modal velocity amplitude per impulse
    rings = [abs(a) / m * ringing_per_impulse(f, contact)
             for a, m, f in zip(modes.at_ram, masses, modes.f_hz, strict=True)]
    pred = max(rudder, key=lambda k: rings[k])
    w = 2 * math.pi * modes.f_hz[pred]
    # the median blow's displacement amplitude of the predominant mode: impulse x ringing / (m w)
    q0 = float(np.median(peaks)) * 2 * contact / math.pi * rings[pred] / w
    plan = _plan(effect, size, rig, modes, masses, pred, q0, interval, onsets, peaks,
                 np.random.default_rng([seed, 73, EFFECTS.index(effect)]))
    acc = _response(modes, np.array(masses), pred, plan, onsets, peaks, contact, n * OVERSAMPLE, dt)
    volts = _chain(acc, rig, plan, n, dt, np.random.default_rng([seed, 74]), noise)
    counts, scale = _adc(volts, rig, plan, onsets)
    truth = FamilyEffect(effect, float(size), _plain(dict(plan.params, size=size)), tuple(sorted(plan.gages)),
                         plan.mode_hz, plan.window, "unexplained" if effect in OUTSIDE else effect)
    return ModalTrial(counts, scale, fs, tuple(g.number for g in rig.gages), onsets, peaks,
                      tuple((float(f), float(z)) for f, z in zip(modes.f_hz, modes.zeta, strict=True)),
                      ADC_BITS, truth, seed)


def _response(modes: Modes, masses: np.ndarray, pred: int, plan: Plan, onsets: np.ndarray,
              peaks: np.ndarray, contact: float, n_o: int, dt: float) -> np.ndarray:
    """Gage accelerations (m/s^2) at the oversampled rate, (n_g, n_o)."""
    t = np.arange(n_o) * dt
    force = half_sine(onsets, peaks, contact, t)
    if plan.second is not None:
        force += half_sine(*plan.second, contact, t)
    q = np.zeros((modes.f_hz.size, n_o))
    tiller = np.zeros(n_o)
    if plan.nonlinear:
        u = force * modes.at_ram[pred] / masses[pred]
        q[pred], r = nonlinear_mode(modes.f_hz[pred], modes.zeta[pred], u, dt, **plan.nonlinear)
        # the stop's force (N, the mode's modal force), felt by every other mode through its
        # shape at the tiller
        tiller = r * masses[pred]
    for k in range(modes.f_hz.size):
        if k == pred and plan.nonlinear:
            continue
        b, a = mode_filter(modes.f_hz[k], modes.zeta[k], dt)
        q[k] = scipy.signal.lfilter(b, a, (force * modes.at_ram[k] + tiller * modes.at_tiller[k]) / masses[k])
    acc = modes.shape.T @ q
    if plan.tone:
        k, fr = plan.tone["mode"], plan.tone["f_hz"]
        rng = np.random.default_rng(int(1e6 * fr) % 2**31)
        # one slow step every 64 samples, the last one whole (n_o need not be a multiple of 64)
        slow = scipy.signal.lfilter([0.002], [1, -0.998], rng.standard_normal((2, -(-n_o // 64))), axis=1)
        slow = np.repeat(slow / max(slow.std(), 1e-12), 64, axis=1)[:, :n_o]
        amp = plan.tone["amp"] * (1 + 0.15 * slow[0])
        acc += np.outer(modes.shape[k] / np.abs(modes.shape[k]).max(),
                        amp * np.cos(2 * math.pi * fr * t + 0.5 * slow[1] + rng.uniform(0, 2 * math.pi)))
    for r, tau in plan.skew.items():
        spec = np.fft.rfft(acc[r])
        acc[r] = np.fft.irfft(spec * np.exp(-2j * math.pi * np.fft.rfftfreq(n_o, dt) * tau), n=n_o)
    for r, (fr, zr) in plan.resonance.items():
        wr = 2 * math.pi * fr
        tf = ([2 * zr * wr, wr * wr], [1.0, 2 * zr * wr, wr * wr])
        b, a, _ = scipy.signal.cont2discrete(tf, dt, "bilinear")
        acc[r] = scipy.signal.lfilter(np.ravel(b), np.ravel(a), acc[r])
    for r, g in plan.gain.items():
        acc[r] *= g
    for r, d in plan.drift.items():
        acc[r] *= 1 + d * t / t[-1]
    return acc


def _chain(acc: np.ndarray, rig: RigData, plan: Plan, n: int, dt: float, rng: np.random.Generator,
           noise: bool) -> np.ndarray:
    """Sensor volts at the recorded rate, (n_g, n): high-pass (AC coupling) where planned, the
    anti-alias Butterworth, decimation, cable pick-up, coloured noise."""
    fo = 1 / dt
    for r, fc in plan.highpass.items():
        acc[r] = scipy.signal.sosfilt(scipy.signal.butter(1, fc, "highpass", fs=fo, output="sos"), acc[r])
    sos = scipy.signal.butter(rig.anti_alias_order, rig.anti_alias_hz, fs=fo, output="sos")
    x = scipy.signal.sosfilt(sos, acc, axis=1)[:, ::OVERSAMPLE][:, :n]
    fs = rig.fs_hz
    t = np.arange(n) / fs
    if plan.mains:
        m = plan.mains
        on = np.zeros(n, bool)
        for t0 in m.get("onsets", []):
            on |= (t > t0 + 0.05) & (t < t0 + 2.5)
        line = sum(np.cos(2 * math.pi * h * m["f_hz"] * t + h) / h for h in (1, 3, 5))
        for r in m["rows"]:
            x[r] += m["amp"] * line * on
    if noise:
        x += _noise(rng, x.shape[0], n, fs, rig.noise_rms)
    sens = np.array([g.sensitivity for g in rig.gages])
    return x * sens[:, None]


def _noise(rng: np.random.Generator, n_ch: int, n: int, fs: float, sigma: float) -> np.ndarray:
    """Coloured noise (m/s^2), (n_ch, n): per channel 80 % white and 15 % 1/f (0.1-40 Hz) of the
    variance, 5 % common to all channels; rms ``sigma``."""
    f = np.fft.rfftfreq(n, 1 / fs)
    pink = 1 / np.sqrt(np.maximum(f, 0.1) * (1 + (f / 40.0) ** 2))
    pink[0] = 0.0
    spec = (rng.standard_normal((n_ch + 1, f.size)) + 1j * rng.standard_normal((n_ch + 1, f.size))) * pink
    col = np.fft.irfft(spec, n=n, axis=1)
    col /= col.std(axis=1, keepdims=True)
    white = rng.standard_normal((n_ch, n))
    return sigma * (math.sqrt(0.80) * white + math.sqrt(0.15) * col[:n_ch] + math.sqrt(0.05) * col[n_ch])


def _adc(volts: np.ndarray, rig: RigData, plan: Plan, onsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """16-bit counts and m/s^2 per count: each channel's full scale puts the largest blow's peak
    at :data:`HEADROOM` of the range (a clipped channel's at ``overdrive`` x the rail for the
    median blow)."""
    peak = np.abs(volts).max(axis=1)
    fsv = np.maximum(peak / HEADROOM, 1e-6)
    fs = rig.fs_hz
    for r, over in plan.clip.items():
        blows = [np.abs(volts[r, int(t * fs):int((t + 0.5) * fs)]).max() for t in onsets]
        fsv[r] = float(np.median(blows)) / over
    lsb = 2 * fsv / 2**ADC_BITS
    counts = np.clip(np.rint(volts / lsb[:, None]), -(2 ** (ADC_BITS - 1)), 2 ** (ADC_BITS - 1) - 1)
    sens = np.array([g.sensitivity for g in rig.gages])
    return counts.astype(np.int32), lsb / sens


def _plain(x):
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, list | tuple | np.ndarray):
        return [_plain(v) for v in x]
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.floating):
        return float(x)
    return x
