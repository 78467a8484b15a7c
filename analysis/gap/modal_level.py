"""The model level of the gap diagnosis: a trial's identified modes held against its rig's modes.

:func:`trial_modes` identifies the modes of each impact's free decay on its own (poles shared by
all gages, :func:`~ramdaq.analysis.modal.identify.identify_modes`) and keeps those found again in
most impacts: a mode of the structure rings after every blow, while the spurious poles an order
selection admits now and then (noise fitted at a false-alarm level) do not come back at the same
frequency. What is kept is averaged over the impacts, and its uncertainty is the impacts'
spread -- the noise floor comes from the data, never from the rig file.

:func:`compare` pairs those modes with the rig model's (:func:`model_modes_at_gages`) by mode
shape and frequency and tabulates per pair the frequencies, damping ratios and the modal
assurance criterion (MAC) over all gages and per gage body (:class:`ModePair`).

Mode shapes are complex accelerations at the gages (m/s^2 per unit, any scale), in the trial's
gage (DAQ channel) order; they are compared by the complex MAC
``|phi_a^H phi_b|^2 / (|phi_a|^2 |phi_b|^2)``, which no common complex factor changes (the
filters in the signal chain act alike on every gage).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.stats

from ..modal.identify import identify_modes
from ..model.response import ModalForm, modal_form
from ..model.rig import BODIES, HullMode, Rig
from ..model.structure import build_model, gage_map
from .trialdata import TrialData

SAME_MODE_REL = 0.01
"""Two impacts' poles within 1 % in frequency are one mode: a structure's mode moves far less
than that between blows (the spread across impacts of a mode is ~1e-5 relative at a ram blow's
signal-to-noise), while the spurious poles of order selection land anywhere in the band."""
MAX_PAIR_RATIO = 2.0
"""A model mode and an identified one are paired only within a factor 2 in frequency: a rig
whose stiffness or mass is off by a factor of 2 (a crude rig) moves its modes by sqrt(2)."""
SPLIT_MAC = 0.95
"""Two identified modes are one mode split in two when their shapes agree to this MAC (16
gages: a shape agreeing to 0.95 is the same motion, while two modes of a linear structure are
orthogonal in its mass and differ at the gages; the hull modes of a clean modal-family trial
1-2 % apart came to 0.83-0.84). Checked on development seeds only (modal 51000-60003)."""
SPLIT_ZETA_RATIO = 1.5
"""The halves of a split mode decay alike: damping ratios within this factor (the impacts'
spread of an identified damping ratio is a few per cent; two unrelated modes' differ by any
factor; a tone's decay window poles are near zero or negative)."""
SPLIT_RESOLVED = 1.0
"""Two halves at least their damping ratio apart (relative): the beat's period 1 / (f r) is then
within 2 pi decay time constants 1 / (2 pi f zeta), and a decay that rings ~9 time constants to
the noise (a ram blow's 1e4 signal-to-noise) shows it; closer, one identified mode is two poles
fitted to one (the modal family's hull pair 0.9 % apart at 1.2 % damping)."""
MAX_SPLIT_REL = 0.25
"""The widest split, relative, read at the model level: a tuned absorber of mass ratio mu splits
its mode into two at about f (1 -+ sqrt(mu) / 2) (Den Hartog), 22 % apart at mu = 5 %; further
apart, two modes of one shape are modes of their own. Wider than the effect search's
``split_mode.MAX_SPLIT`` (10 %, the split its time-domain refit fits): the identified modes show
a wider split directly, by their shapes (:data:`SPLIT_MAC`) and damping (:func:`_a_split`);
the effect's closure of such a split is then partial. (Was 10 % as the effect's bound; modal
check seed 159001's halves 11.7 % apart, MAC 1.000, damping 1.84 % both, were left out.)"""
QUIET_BODY = 1e-3
"""A body whose gages carry less than this share of a model mode's shape norm is not predicted
to move in that mode: its MAC there is not defined (NaN)."""


@dataclass(frozen=True)
class TrialModes:
    """Modes identified on a trial's impacts, sorted by frequency.

    ``f_hz``, ``f_se_hz`` (K,) damped frequency and its standard error, Hz; ``zeta``,
    ``zeta_se`` (K,) damping ratio and standard error; ``shapes`` (n_gages, K) complex
    acceleration shape, unit norm, its largest entry real and positive; ``shape_se``
    (n_gages, K) standard error of each entry (absolute, in units of the unit-norm shape);
    ``n_seen`` (K,) impacts in which the mode was found, of ``n_impacts`` identified;
    ``noise_std`` (n_gages,) the decay windows' noise rms, m/s^2 (median over impacts), as the
    identification measured it; ``gage_numbers`` the report's number of each shape row.
    Standard errors are the spread over the impacts divided by sqrt(n_seen), never smaller than
    the single fits' own standard errors divided by sqrt(n_seen).
    """

    f_hz: np.ndarray
    f_se_hz: np.ndarray
    zeta: np.ndarray
    zeta_se: np.ndarray
    shapes: np.ndarray
    shape_se: np.ndarray
    n_seen: np.ndarray
    n_impacts: int
    noise_std: np.ndarray
    gage_numbers: tuple[int, ...]
    skipped: tuple[str, ...] = ()
    """Impacts whose identification failed, and why (they are left out)."""

    @property
    def n_modes(self) -> int:
        return len(self.f_hz)


@dataclass(frozen=True)
class ModelModesAtGages:
    """A rig model's modes as the gages see them: ``f_hz``, ``zeta`` (m,), ``shapes``
    (n_gages, m) complex acceleration per unit modal state, gage (DAQ channel) order."""

    f_hz: np.ndarray
    zeta: np.ndarray
    shapes: np.ndarray


@dataclass(frozen=True)
class ModePair:
    """One identified mode against the model mode paired with it.

    ``f_id_hz`` +- ``f_id_se_hz`` and ``zeta_id`` +- ``zeta_id_se`` identified; ``f_model_hz``,
    ``zeta_model`` the model's; ``mac`` over all gages; ``mac_rudder``, ``mac_stock``,
    ``mac_hull`` over each body's gages (NaN where the model does not move that body in this
    mode, or the body has fewer than two gages); ``i_id``, ``i_model`` the modes' indices in
    :class:`TrialModes` and :class:`ModelModesAtGages`.
    """

    i_id: int
    i_model: int
    f_id_hz: float
    f_id_se_hz: float
    f_model_hz: float
    zeta_id: float
    zeta_id_se: float
    zeta_model: float
    mac: float
    mac_rudder: float
    mac_stock: float
    mac_hull: float

    @property
    def df_rel(self) -> float:
        """(f_model - f_id) / f_id."""
        return self.f_model_hz / self.f_id_hz - 1

    def mac_of(self, body: str) -> float:
        return {"rudder": self.mac_rudder, "stock": self.mac_stock, "hull": self.mac_hull}[body]


@dataclass(frozen=True)
class ModalComparison:
    """The pairs, and the modes left unpaired on either side (indices)."""

    pairs: tuple[ModePair, ...]
    unpaired_id: tuple[int, ...]
    unpaired_model: tuple[int, ...]
    trial: TrialModes
    model: ModelModesAtGages


# -- identification ----------------------------------------------------------------------------
def _decay(td: TrialData, j: int) -> np.ndarray | None:
    """Impact ``j``'s decay window (n_gages, n) up to the first sample any gage lacks, or None
    when less than a second is left."""
    y = td.x[j, :, td.windows.early.start:]
    bad = np.flatnonzero(~np.all(np.isfinite(y), axis=0))
    n = bad[0] if len(bad) else y.shape[1]
    return y[:, :n] if n >= td.fs_hz else None


def _unit_shape(a: np.ndarray) -> np.ndarray:
    """``a`` scaled to unit norm, its largest entry real and positive."""
    k = int(np.argmax(np.abs(a)))
    return a * np.conj(a[k]) / (np.abs(a[k]) * np.linalg.norm(a))


def trial_modes(td: TrialData, *, f_lo_hz: float = 0.5, min_share: float = 0.5) -> TrialModes:
    """The modes of a trial's impacts: identified on each decay, kept when found in at least
    ``min_share`` of the impacts (and in two, if two were identified), between ``f_lo_hz`` and
    the trial's low-pass corner. Raises ValueError when no impact leaves a decay to identify."""
    found = []          # per impact: (f, f_se, zeta, zeta_se, shapes (n_g, k))
    noise = []
    skipped: list[str] = []
    for j in range(td.n_seg):
        y = _decay(td, j)
        if y is None:
            continue
        try:
            mt = identify_modes(y, td.fs_hz, f_range_hz=(f_lo_hz, 0.9 * td.lowpass_hz),
                                per_channel=False)
        except (ValueError, ArithmeticError, np.linalg.LinAlgError, scipy.linalg.LinAlgError) as err:
            skipped.append(f"impact {j + 1}: {type(err).__name__}: {err}")
            continue
        noise.append(mt.noise_std)
        found.append((mt.frequency_hz, mt.frequency_se_hz, mt.zeta, mt.zeta_se,
                      np.nan_to_num(mt.complex_amplitude)))
    if not found:
        raise ValueError("no impact leaves a decay of a second or more to identify modes on"
                         + (f" ({'; '.join(skipped)})" if skipped else ""))
    need = max(math.ceil(min_share * len(found)), min(2, len(found)))
    merged = sorted((_merge(found, members) for members in _clusters(found, need)),
                    key=lambda m: m[0])
    n_g = td.n_gages
    col = lambda i: np.array([m[i] for m in merged])   # noqa: E731
    return TrialModes(
        f_hz=col(0) if merged else np.empty(0), f_se_hz=col(1) if merged else np.empty(0),
        zeta=col(2) if merged else np.empty(0), zeta_se=col(3) if merged else np.empty(0),
        shapes=col(4).T if merged else np.empty((n_g, 0), complex),
        shape_se=col(5).T if merged else np.empty((n_g, 0)),
        n_seen=col(6).astype(int) if merged else np.empty(0, int), n_impacts=len(found),
        noise_std=_median_or_nan(np.array(noise)), gage_numbers=td.gage_numbers,
        skipped=tuple(skipped))


def _median_or_nan(v: np.ndarray) -> np.ndarray:
    """The median over impacts (axis 0) of each gage's value, NaN where no impact has one (a dead
    gage's noise) -- without numpy's All-NaN warning on the terminal."""
    out = np.full(v.shape[1:], np.nan)
    some = ~np.all(np.isnan(v), axis=0)
    out[some] = np.nanmedian(v[:, some], axis=0)
    return out


def _mean_se(v: np.ndarray, se: np.ndarray) -> tuple[float, float]:
    """Mean of one quantity over impacts and its standard error: the impacts' spread over
    sqrt(n), never below the single fits' own errors over sqrt(n)."""
    n = len(v)
    spread = float(np.std(v, ddof=1)) if n > 1 else 0.0
    return float(np.mean(v)), max(spread, float(np.sqrt(np.mean(se**2)))) / math.sqrt(n)


def _merge(found: list[tuple], members: list[tuple[int, int]]) -> tuple:
    """One mode from its (impact, index) members: (f, f_se, zeta, zeta_se, unit shape,
    shape standard error per gage, n_seen)."""
    get = lambda i: np.array([found[j][i][k] for j, k in members])   # noqa: E731
    f, f_se = _mean_se(get(0), get(1))
    z, z_se = _mean_se(get(2), get(3))
    phis = np.array([_unit_shape(found[j][4][:, k]) for j, k in members])
    phis = np.array([p * np.exp(-1j * np.angle(np.vdot(phis[0], p))) for p in phis])
    phi = _unit_shape(np.mean(phis, axis=0))
    n = len(members)
    phi_se = np.abs(phis - phi).std(axis=0, ddof=1) / math.sqrt(n) if n > 1 else np.zeros(len(phi))
    return f, f_se, z, z_se, phi, phi_se, n


def _clusters(found: list[tuple], need: int) -> list[list[tuple[int, int]]]:
    """Groups of (impact, mode index) within :data:`SAME_MODE_REL` of each other, at most one
    per impact (the nearest to the group's first member), found in ``need`` impacts or more;
    groups are formed in order of frequency."""
    poles = sorted(((float(f), j, k) for j, fd in enumerate(found) for k, f in enumerate(fd[0])))
    used: set[tuple[int, int]] = set()
    rows = []
    for f0, _, _ in poles:
        members: dict[int, tuple[float, int]] = {}
        for f, j, k in poles:
            if (j, k) in used or abs(f / f0 - 1) > SAME_MODE_REL:
                continue
            if j not in members or abs(f - f0) < abs(members[j][0] - f0):
                members[j] = (f, k)
        if len(members) >= need:
            group = [(j, k) for j, (_, k) in sorted(members.items())]
            used.update(group)
            rows.append(group)
    return rows


@dataclass(frozen=True)
class Split:
    """Two identified modes ``f_lo_hz`` < ``f_hi_hz`` of one shape (``mac`` between them, at
    least :data:`SPLIT_MAC`) where the rig model, calibrated to the trial's modes, has one mode
    for them (at most one of them paired): a mode split in two (an absorber, an asymmetry),
    what no calibration of the rig's constants makes. ``gages``: where the pair's shape is at
    least half its largest entry, largest first; ``zeta_lo``, ``zeta_hi`` their damping ratios."""

    f_lo_hz: float
    f_hi_hz: float
    mac: float
    gages: tuple[int, ...]
    zeta_lo: float = float("nan")
    zeta_hi: float = float("nan")

    @property
    def f_hz(self) -> float:
        return 0.5 * (self.f_lo_hz + self.f_hi_hz)

    def to_json(self) -> dict:
        return {"f_lo_hz": self.f_lo_hz, "f_hi_hz": self.f_hi_hz, "mac": self.mac, "gages": list(self.gages),
                "zeta": [self.zeta_lo, self.zeta_hi]}


def _alike(tm: TrialModes) -> list[tuple[int, int, float]]:
    """(i, j, MAC) of the identified modes i < j within :data:`MAX_SPLIT_REL` in frequency
    whose shapes agree to :data:`SPLIT_MAC`."""
    out = []
    for i in range(tm.n_modes):
        for j in range(i + 1, tm.n_modes):
            if tm.f_hz[j] <= (1 + MAX_SPLIT_REL) * tm.f_hz[i]:
                m = mac(tm.shapes[:, i], tm.shapes[:, j])
                if m >= SPLIT_MAC:
                    out.append((i, j, m))
    return out


def _a_split(tm: TrialModes, i: int, j: int) -> bool:
    """Whether modes i < j ring as the two halves of one mode: both decaying, with the same
    damping (within :data:`SPLIT_ZETA_RATIO`; the halves share the mode's), and resolved as a
    beat: their distance at least their damping ratio (:data:`SPLIT_RESOLVED`)."""
    zi, zj = float(tm.zeta[i]), float(tm.zeta[j])
    if zi <= 0 or zj <= 0 or max(zi, zj) > SPLIT_ZETA_RATIO * min(zi, zj):
        return False
    return tm.f_hz[j] / tm.f_hz[i] - 1 >= SPLIT_RESOLVED * 0.5 * (zi + zj)


def splits(tm: TrialModes, cmp: ModalComparison, rig: Rig) -> list[Split]:
    """The identified modes ``tm`` that are one mode split in two (:class:`Split`) against the
    pairing ``cmp`` of the calibrated model of ``rig``: two modes within :data:`MAX_SPLIT_REL` in
    frequency, shapes agreeing to :data:`SPLIT_MAC`, one of them paired with a model mode and
    the other not; alone (a chain of three or more modes of one shape is a frequency that moves
    -- an amplitude-dependent stiffness, friction, a wandering tone -- not a split), decaying as
    halves of one mode do (:func:`_a_split`), and not the hull's: a pair with
    :data:`HULL_MODE_SHARE` of its shape energy on the hull gages (:func:`hull_share`) is two hull
    modes -- a few gages on a hull read two of its low modes as near one field, and the rig's one
    lumped hull mode pairs one of them -- not a mode split by something on the rudder (issue 17:
    a clean modal-family trial, holdout seed 950004, rang hull modes at 10.0 and 12.3 Hz of MAC
    0.98 and hull share 0.93, read as a split; the modal family's split rudder modes, 0.05).
    The ratio of the rudder's to the hull's largest amplitude does not tell them: benchmark seed
    559001's split 13.8 Hz rudder mode, mixed with a hull mode near it, rode the hull at 4.3x)."""
    paired = {p.i_id for p in cmp.pairs}
    alike = _alike(tm)
    count = np.bincount([k for i, j, _ in alike for k in (i, j)], minlength=tm.n_modes)
    out = []
    for i, j, m in alike:
        if len(paired & {i, j}) != 1 or count[i] > 1 or count[j] > 1 or not _a_split(tm, i, j):
            continue
        ai, aj = np.abs(tm.shapes[:, i]), np.abs(tm.shapes[:, j])
        if hull_share(ai**2 + aj**2, rig) >= HULL_MODE_SHARE:
            continue
        a = ai + aj
        big = [int(k) for k in np.argsort(-a) if a[k] >= 0.5 * a.max()]
        out.append(Split(float(tm.f_hz[i]), float(tm.f_hz[j]), m, tuple(tm.gage_numbers[k] for k in big),
                         float(tm.zeta[i]), float(tm.zeta[j])))
    return out


def hull_share(e: np.ndarray, rig: Rig) -> float:
    """The share of a shape's energy ``e`` ((n_gages,) ``|phi|^2`` in channel order) on the hull's
    gages: the hull's mode from :data:`HULL_MODE_SHARE` up."""
    hull = np.array([g.body == "hull" for g in rig.gages_by_channel()])
    return float(e[hull].sum() / max(e.sum(), 1e-30))


def ride_over_hull(a: np.ndarray, rig: Rig) -> float:
    """A shape's largest rudder-and-stock amplitude over its largest hull amplitude, athwartship
    gages (``a`` (n_gages,) amplitudes in channel order); inf when no hull gage reads it."""
    gs = rig.gages_by_channel()
    ath = np.array(["z" not in g.axis for g in gs])
    hull = np.array([g.body == "hull" for g in gs]) & ath
    ride = ~hull & ath
    if not hull.any() or not ride.any():
        return math.inf
    return float(a[ride].max() / max(a[hull].max(), 1e-30))


# -- the model's side ----------------------------------------------------------------------------
def model_modes_at_gages(rig: Rig) -> ModelModesAtGages:
    """The rig model's modes (in the rig's medium) with their gage acceleration shapes."""
    return modes_at_gages(modal_form(build_model(rig)))


def modes_at_gages(form: ModalForm) -> ModelModesAtGages:
    """A model's modal form's modes as the gages see them (:func:`model_modes_at_gages` of a
    form already made)."""
    lam = form.eigenvalues
    return ModelModesAtGages(lam.imag / (2 * math.pi), -lam.real / np.abs(lam), form.gage_acc)


def modes_of_set(lam: np.ndarray, shapes: np.ndarray) -> ModelModesAtGages:
    """Modes given as eigenvalues ``lam`` (m,) 1/s and gage shapes ``shapes`` (n_gages, m)
    complex, any scale per mode (the effect search's :class:`~ramdaq.analysis.gap.forward.ModeSet`:
    ``lam``, ``A``), as :class:`ModelModesAtGages`; modes without a positive frequency (a
    filter's real pole) are left out."""
    keep = np.asarray(lam).imag > 0
    lam = np.asarray(lam)[keep]
    return ModelModesAtGages(lam.imag / (2 * math.pi), -lam.real / np.abs(lam), np.asarray(shapes)[:, keep])


def mac(a: np.ndarray, b: np.ndarray) -> float:
    """Complex modal assurance criterion of two shapes, 0..1 (NaN if either is zero)."""
    na, nb = np.vdot(a, a).real, np.vdot(b, b).real
    if na <= 0 or nb <= 0:
        return float("nan")
    return float(abs(np.vdot(a, b)) ** 2 / (na * nb))


def body_mac(rig: Rig, a: np.ndarray, model_shape: np.ndarray, body: str) -> float:
    """MAC over the gages on ``body`` (NaN when fewer than two, or the model does not move
    the body in this mode: below :data:`QUIET_BODY` of the shape's norm)."""
    rows = np.array([g.body == body for g in rig.gages_by_channel()])
    if rows.sum() < 2:
        return float("nan")
    m = model_shape[rows]
    if np.linalg.norm(m) < QUIET_BODY * np.linalg.norm(model_shape):
        return float("nan")
    return mac(a[rows], m)


def compare(tm: TrialModes, rig: Rig, *, top_hz: float | None = None,
            model: ModelModesAtGages | None = None) -> ModalComparison:
    """Pair the identified modes ``tm`` with ``rig``'s model modes below ``top_hz`` (default:
    twice the highest identified mode): the assignment that minimises the summed
    ``(1 - MAC) + |ln(f_model / f_id)| / ln 2`` over pairs within :data:`MAX_PAIR_RATIO` in
    frequency whose cost stays below 1.2 (a pair sharing no shape and a factor 1.5 apart is no
    pair). ``model``: the modes to pair with, when not ``rig``'s own model's (a model with an
    effect's update on it, :func:`modes_of_set`); ``rig`` then gives only the gages' bodies."""
    mm = model_modes_at_gages(rig) if model is None else model
    top = top_hz if top_hz is not None else 2 * float(np.max(tm.f_hz, initial=0.0))
    cand = np.flatnonzero((mm.f_hz > 0) & (mm.f_hz < top))
    K = tm.n_modes
    cost = np.full((K, len(cand)), 1e6)
    for i in range(K):
        for c, m in enumerate(cand):
            ratio = abs(math.log(mm.f_hz[m] / tm.f_hz[i]))
            if ratio <= math.log(MAX_PAIR_RATIO):
                cost[i, c] = (1 - mac(tm.shapes[:, i], mm.shapes[:, m])) + ratio / math.log(2)
    pairs = []
    if K and len(cand):
        rows, cols = scipy.optimize.linear_sum_assignment(cost)
        for i, c in zip(rows, cols, strict=True):
            if cost[i, c] < 1.2:
                pairs.append(_pair(tm, mm, rig, int(i), int(cand[c])))
    got_id = {p.i_id for p in pairs}
    got_m = {p.i_model for p in pairs}
    return ModalComparison(
        pairs=tuple(sorted(pairs, key=lambda p: p.f_id_hz)),
        unpaired_id=tuple(i for i in range(K) if i not in got_id),
        unpaired_model=tuple(int(m) for m in cand if m not in got_m), trial=tm, model=mm)


def _pair(tm: TrialModes, mm: ModelModesAtGages, rig: Rig, i: int, m: int) -> ModePair:
    a, b = tm.shapes[:, i], mm.shapes[:, m]
    by = {body: body_mac(rig, a, b, body) for body in BODIES}
    return ModePair(i_id=i, i_model=m, f_id_hz=float(tm.f_hz[i]), f_id_se_hz=float(tm.f_se_hz[i]),
                    f_model_hz=float(mm.f_hz[m]), zeta_id=float(tm.zeta[i]),
                    zeta_id_se=float(tm.zeta_se[i]), zeta_model=float(mm.zeta[m]),
                    mac=mac(a, b), mac_rudder=by["rudder"], mac_stock=by["stock"], mac_hull=by["hull"])


# -- a hull mode the rudder does not ride rigidly: coupling --------------------------------------
HULL_MODE_SHARE = 0.5
"""A mode is the hull's when at least half its shape's energy (sum of |phi|^2) is on hull gages."""
COUPLED_NONRIGID = 0.05
"""The least share of the rudder's and stock's shape energy off a rigid-body motion that reads
as their own deformation taking part in a hull mode: gage positions off by up to 5 cm on a
rudder of 2-3 m span move a rigid motion's fit by ~2 % of amplitude (~0.1 % of energy), and the
clean modal-family trials' hull modes, which carry the rudder rigidly, came to 0.000-0.015 (dev
seeds 51000-51003). A coupled mode's rudder deformation is a share of order one."""
COUPLED_P = 1e-3
"""Chance level of the rigid-ride test: the chi-square quantile at 1 - P (Bonferroni over the
trial's modes) of the residual's degrees of freedom."""


@dataclass(frozen=True)
class Coupled:
    """An identified mode at ``f_hz`` (damping ``zeta``) that moves the hull (``hull_share`` of
    its shape energy on hull gages) while the rudder and stock do not ride it as one rigid body
    (``nonrigid``: the share of their shape energy off the best rigid-body motion; ``statistic``
    that residual over its noise expectation, against ``chance`` its chi-square quantile) and the
    calibrated rig has no mode of that shape: the rudder's own flexibility takes part in a hull
    mode -- hull coupling -- which no constant of a rig whose hull modes carry the rudder as a
    passenger makes. ``gages``: where its shape is at least half its largest entry, largest first."""

    f_hz: float
    zeta: float
    hull_share: float
    nonrigid: float
    statistic: float
    chance: float
    gages: tuple[int, ...]
    kind: str = "flexible"
    """"flexible": the rudder deforms in the hull mode (:func:`flexible_coupled`); "line": a hull
    mode the calibrated rig lacks that the rudder rides rigidly (:func:`extra_lines`), whose
    ``statistic`` is its frequency's steadiness over a chance pole's (:func:`steadiness`);
    "driven": such a line that the rudder rides as the calibrated rig's stock carries it from
    the hull's section (:func:`stock_driven`), a second hull structure at the stock."""

    def to_json(self) -> dict:
        return {"f_hz": self.f_hz, "zeta": self.zeta, "hull_share": self.hull_share,
                "nonrigid": self.nonrigid, "statistic": self.statistic, "chance_level": self.chance,
                "gages": list(self.gages), "kind": self.kind}


def rigid_ride(shape: np.ndarray, se: np.ndarray, pos: np.ndarray,
               n_tests: int = 1) -> tuple[float, float, float]:
    """How far a shape's entries at athwartship gages of one assembly (``pos`` (n, 3) m) are from
    a rigid-body motion (a translation and the two rotations that move them athwartship: basis
    1, x, z): (share of the shape energy off it, residual over its noise expectation from the
    entries' standard errors ``se``, the chi-square chance level of that ratio at
    :data:`COUPLED_P` over ``n_tests``, the modes tested, Bonferroni). NaNs when fewer than five
    gages leave the test no freedom."""
    n = len(shape)
    if n < 5:
        return float("nan"), float("nan"), float("nan")
    A = np.c_[np.ones(n), pos[:, 0], pos[:, 2]]
    coef, *_ = np.linalg.lstsq(A, shape, rcond=None)
    r = shape - A @ coef
    energy = float(np.vdot(shape, shape).real)
    off = float(np.vdot(r, r).real)
    dof = 2 * (n - 3)        # complex entries: two per gage, less the three complex coefficients
    noise = max(float(np.sum(se**2)) * (n - 3) / n, 1e-30)
    chance = float(scipy.stats.chi2.ppf(1 - COUPLED_P / max(n_tests, 1), dof) / dof)
    return off / max(energy, 1e-30), off / noise / dof, chance


def coupled_modes(tm: TrialModes, rig: Rig, cmp: ModalComparison) -> list[Coupled | StockTurn]:
    """The hull modes the model level reports: those the rudder deforms in, hull coupling
    (:func:`flexible_coupled`, ``kind`` "flexible"), and the hull modes the calibrated rig lacks
    (:func:`extra_lines`, ``kind`` "line"), which name nothing alone but say where a hull mode
    rings (:func:`~ramdaq.analysis.gap.layers.unrung_hull`), or "driven" where the rig's stock
    carries the rudder in them as it rides (a hull structure at the stock the rig lacks); and the
    stock's top turning with the rudder (:func:`stock_turns`, ``kind`` "tiller"), a steering gear
    the rig holds rigid, which the model level reports beside them (not a hull mode)."""
    return [*flexible_coupled(tm, rig, cmp), *extra_lines(tm, rig, cmp), *stock_turns(tm, rig)]


def flexible_coupled(tm: TrialModes, rig: Rig, cmp: ModalComparison) -> list[Coupled]:
    """The identified modes that are hull coupling (:class:`Coupled`) against the pairing ``cmp``
    of the calibrated rig: decaying, found in three quarters of the impacts or more, the hull's
    (:data:`HULL_MODE_SHARE`), unpaired or paired below chance (MAC under 1 / n_gages, what two
    unrelated shapes give), and the rudder's and stock's athwartship gages off a rigid ride by at
    least :data:`COUPLED_NONRIGID` of their energy and beyond the test's chance level."""
    gs = rig.gages_by_channel()
    ride = np.array([g.body != "hull" and "z" not in g.axis for g in gs])
    pos = np.array([g.position_m for g in gs], float)
    good = {p.i_id for p in cmp.pairs if p.mac >= 1 / max(tm.shapes.shape[0], 1)}
    out = []
    for i in range(tm.n_modes):
        if i in good or tm.zeta[i] <= 0 or tm.n_seen[i] < 0.75 * tm.n_impacts:
            continue
        s = tm.shapes[:, i]
        hull = hull_share(np.abs(s) ** 2, rig)
        if hull < HULL_MODE_SHARE:
            continue
        share, stat, chance = rigid_ride(s[ride], tm.shape_se[ride, i], pos[ride], tm.n_modes)
        if not (share >= COUPLED_NONRIGID and stat > chance):
            continue
        a = np.abs(s)
        big = [int(k) for k in np.argsort(-a) if a[k] >= 0.5 * a.max()]
        out.append(Coupled(float(tm.f_hz[i]), float(tm.zeta[i]), hull, share, stat, chance,
                           tuple(tm.gage_numbers[k] for k in big)))
    return out


LINE_DECAY_Z = 3.1
"""A line decays when its damping ratio stands this many standard errors (the impacts' spread)
above zero: one-sided chance 1e-3 (:data:`COUPLED_P`). A steady tone (ambient, mains) read in a
decay window has a damping ratio of zero within its error; a structure's mode decays."""
LINE_RIDE = 5.0
"""The most a hull line's largest rudder/stock amplitude may be over its largest hull amplitude
(athwartship gages): the rig model's own hull modes ride the rudder at 1.2-1.7x their hull
amplitude and the rudder's own modes at 30-3000x; above 5x a mode is the rudder's (as the
benchmark's ``RUDDER_OVER_HULL`` reads a rig's modes), unless the rig's stock carries the rudder
in it from the hull section's motion (a "driven" line, :func:`extra_lines`)."""


def steadiness(tm: TrialModes, i: int) -> float:
    """How much steadier mode ``i``'s frequency is over the impacts than a pole the identification
    admits by chance: a spurious pole lands anywhere within :data:`SAME_MODE_REL` of the cluster's
    frequency (uniform: standard deviation ``SAME_MODE_REL f / sqrt(3)``, its mean's standard error
    that over ``sqrt(n_seen)``), a structure's mode within its own estimation error; the ratio of
    the two standard errors (chance level 1)."""
    chance_se = SAME_MODE_REL * float(tm.f_hz[i]) / math.sqrt(3 * max(int(tm.n_seen[i]), 1))
    return chance_se / max(float(tm.f_se_hz[i]), 1e-12 * float(tm.f_hz[i]))


def extra_lines(tm: TrialModes, rig: Rig, cmp: ModalComparison) -> list[Coupled]:
    """The identified modes that are a hull mode the calibrated rig lacks (:class:`Coupled`,
    ``kind`` "line"): unpaired with any of the rig's modes (or paired below chance, MAC under
    1 / n_gages), rung by three quarters of the impacts or more, decaying beyond its error
    (:data:`LINE_DECAY_Z`), not half of a split (a mode of its shape within
    :data:`MAX_SPLIT_REL`, to :data:`SPLIT_MAC`), moving the hull (the rudder at most
    :data:`LINE_RIDE` times the hull), the rudder and stock riding it rigidly (off a rigid ride
    by less than :data:`COUPLED_NONRIGID`: else :func:`flexible_coupled` reads it), and its
    frequency steadier than a chance pole's (:func:`steadiness` above 1). A +-25 % change of the
    rig's masses, inertias and stiffnesses moves the modes the rig has and adds none: a further
    mode that moves the hull is a hull structure the rig lacks. Alone it is no coupling (a clean
    modal-family trial rings two or three hull modes where the rig has one: modal development
    seed 51000's 10.2 Hz line rides the rudder at 0.27x its hull amplitude); it is the mode an
    effect search's hull_coupling must ring at (:func:`~ramdaq.analysis.gap.layers.unrung_hull`).
    A line the rudder rides as the calibrated rig's stock would carry it from the hull section's
    motion (:func:`stock_driven` within :data:`DRIVEN_MISFIT`) is ``kind`` "driven": a hull mode
    at the stock the rig lacks, which no change of its constants adds -- hull coupling (the truth
    family's local hull mode carries the rudder rigidly, so the flexible test cannot see it).
    :data:`LINE_RIDE` does not bound a driven line: the rudder's answer to the section's motion
    is the rig's own forced response, which grows toward a rudder mode beyond the quasi-static
    1.2-1.7x (issue 17: the truth family's hull couplings of sizes 0.05-0.96, benchmark seed
    501002 and holdout seeds 901000, 901004, 901005, each rang a mode every blow rang that no
    mode of the calibrated rig pairs, riding the rudder at 5.3-5.7x the hull, within 0.001-0.02
    of the stock's forced response: set aside as the rudder's, they were answered "none").
    ``gages``: the hull gages where its shape is at least half its largest hull entry."""
    gs = rig.gages_by_channel()
    body = np.array([g.body for g in gs])
    ath = np.array(["z" not in g.axis for g in gs])
    ride = (body != "hull") & ath
    hull_ath = (body == "hull") & ath
    if not hull_ath.any() or not ride.any():
        return []
    pos = np.array([g.position_m for g in gs], float)
    good = {p.i_id for p in cmp.pairs if p.mac >= 1 / max(tm.shapes.shape[0], 1)}
    halves = {k for i, j, _ in _alike(tm) for k in (i, j)}   # half of a split
    out = []
    for i in range(tm.n_modes):
        if (i in good or i in halves or tm.n_seen[i] < 0.75 * tm.n_impacts or tm.zeta[i] <= 0
                or tm.zeta[i] < LINE_DECAY_Z * tm.zeta_se[i]):
            continue
        s = tm.shapes[:, i]
        a = np.abs(s)
        share, _, _ = rigid_ride(s[ride], tm.shape_se[ride, i], pos[ride], tm.n_modes)
        stat = steadiness(tm, i)
        if not (share < COUPLED_NONRIGID and stat > 1.0):
            continue
        driven = stock_driven(s, float(tm.f_hz[i]), rig) <= DRIVEN_MISFIT
        if not (driven or ride_over_hull(a, rig) <= LINE_RIDE):
            continue
        hull = hull_share(a**2, rig)
        top = a[hull_ath].max()
        big = [int(k) for k in np.argsort(-a) if hull_ath[k] and a[k] >= 0.5 * top]
        kind = "driven" if driven else "line"
        out.append(Coupled(float(tm.f_hz[i]), float(tm.zeta[i]), hull, share, stat, 1.0,
                           tuple(tm.gage_numbers[k] for k in big), kind))
    return out


DRIVEN_MISFIT = 0.25
"""The largest share of a line's rudder-and-stock shape energy the calibrated rig's forced
response may miss for the line to be a hull mode driven through the stock (:func:`stock_driven`):
the response's amplitude off by up to half (a relative error eps leaves eps^2 of the energy) --
the rig's constants are off by +-25 % before calibration, and a constant the modes do not pin
may end at its calibration bound (x0.5-x2), where the rudder's response near one of its own
modes scales with the distance to it. A hull mode the rudder rides in a proportion of its own
leaves the order of its whole energy or more: clean modal-family trials' hull lines ride the
rudder at 0.1-0.4x the hull's amplitude where the stock would carry it at about 1x (development
and check seeds 51000-51005, 150000-150005: 14 lines, misfits 1.1-4800 where the hull gages move
as one section, the rest not), the truth family's local hull modes at 0.0001-0.17 (development
and check hull-coupling seeds 2000-2005, 101000-101005)."""
PROBE_MASS = 1e3
"""The probe hull mode's modal mass over the rudder's (:func:`stock_driven`): heavy enough that
the rudder's reaction neither moves its frequency nor its section's motion, so the mode's shape
is the section's motion with the rudder's forced response to it."""


def section_motion(s: np.ndarray, rig: Rig) -> tuple[np.ndarray, float]:
    """The hull section's motion at the stock (``v_b`` m, ``gamma_b`` and ``alpha_b`` rad; complex,
    (3,)) that best reads a mode shape ``s`` (n_gages,) at the hull gages through the rig's own
    kinematics (:func:`~ramdaq.analysis.model.structure.gage_map`: the section at the stock moves
    rigidly), and the share of the hull gages' shape energy it leaves (1 when four hull gages or
    more are not there to test the three motions)."""
    gs = rig.gages_by_channel()
    hull = np.array([g.body == "hull" for g in gs])
    if hull.sum() < 4:
        return np.zeros(3, complex), 1.0
    n0 = 3 + len(rig.hull_modes)
    unit = tuple(HullMode(f"unit{j}", 1.0, 0.0, 1.0, *np.eye(3)[j]) for j in range(3))
    A = gage_map(replace(rig, hull_modes=rig.hull_modes + unit), n0 + 3)[hull][:, n0:]
    c, *_ = np.linalg.lstsq(A.astype(complex), s[hull], rcond=None)
    r = s[hull] - A @ c
    return c, float(np.vdot(r, r).real / max(np.vdot(s[hull], s[hull]).real, 1e-30))


def stock_driven(s: np.ndarray, f_hz: float, rig: Rig) -> float:
    """How far a hull line's shape ``s`` (n_gages,) at ``f_hz`` is from a hull mode driven through
    the stock of the calibrated ``rig``: the hull section moving as the line's hull gages read it
    (:func:`section_motion`), the rig's rudder and stock answering that motion at ``f_hz`` (a probe
    hull mode of that shape, :data:`PROBE_MASS`, added to the rig), and the share of the line's
    rudder-and-stock shape energy the response misses once scaled to the hull gages (the hull
    gages set the scale; the rudder's amplitude and shape are the prediction). ``inf`` when the
    hull gages do not move as the rig's section can (more than :data:`COUPLED_NONRIGID` of their
    energy off it, or fewer than four of them). A +-25 % change of the rig's constants adds no
    hull mode; a second hull structure at the stock (hull coupling) rings one the rudder answers
    exactly so."""
    c, off = section_motion(s, rig)
    if off > COUPLED_NONRIGID or not np.any(c):
        return math.inf
    c = (c * np.exp(-1j * np.angle(c[np.argmax(np.abs(c))]))).real
    probe = HullMode("probe", f_hz, 0.02, PROBE_MASS * rig.rudder.mass_kg, *(c / np.abs(c).max()))
    mm = model_modes_at_gages(replace(rig, hull_modes=rig.hull_modes + (probe,)))
    p = mm.shapes[:, int(np.argmin(np.abs(mm.f_hz - f_hz)))]
    hull = np.array([g.body == "hull" for g in rig.gages_by_channel()])
    a = np.vdot(p[hull], s[hull]) / max(np.vdot(p[hull], p[hull]).real, 1e-30)
    r = s[~hull] - a * p[~hull]
    return float(np.vdot(r, r).real / max(np.vdot(s[~hull], s[~hull]).real, 1e-30))


# -- the stock's top turning with the rudder: a steering gear the rig holds rigid ----------------
TURN_FORM = 0.05
"""The model-form tolerance of the stock's twist (share of the rudder's rotation): the rig's stock
twists linearly from the rudder's rotation at its attachment to the hull section's at its top
(:func:`~ramdaq.analysis.model.structure.point_dofs`), a kinematic law no mass, inertia or
stiffness changes; a stock with its own torsional inertia bends that line by about
``(2 pi f l_T / c)^2 / 6`` (c = sqrt(G / rho) ~ 3200 m/s in steel: ~1 % at 88 Hz on a 1.3 m
stock). Measured: the truth family's clean trials (development seeds 1000-1011, 24 turning
modes) turn the stock's top by at most 0.025 of the rudder's rotation and leave the linear twist
by at most 0.051; a tiller of size s turns it by s / (1 + s) at low frequency (0.048 at s 0.05,
0.33 at 0.46, 0.69 at 2) with the line kept to 0.012."""


@dataclass(frozen=True)
class StockTurn:
    """The stock's top turning with the rudder in its modes: a steering gear / tiller of finite
    stiffness, which the rig holds rigid (:func:`stock_turns`). ``f_hz`` and ``zeta`` the mode
    that turns the rudder most; ``modes_hz`` the modes read, by frequency, and ``turn`` each one's
    top rotation over the rudder's (the gear's law: real, positive and growing with frequency
    below the tiller's own mode, negative above it); ``statistic`` the smallest turn in the run
    below the tiller's mode over its tolerance (:data:`TURN_FORM` plus three standard errors),
    ``chance`` 1; ``gages`` where the strongest mode's rudder and stock shape is at least half
    its largest entry, largest first."""

    f_hz: float
    zeta: float
    modes_hz: tuple[float, ...]
    turn: tuple[float, ...]
    statistic: float
    chance: float
    gages: tuple[int, ...]
    kind: str = "tiller"

    def to_json(self) -> dict:
        return {"f_hz": self.f_hz, "zeta": self.zeta, "modes_hz": list(self.modes_hz),
                "turn": list(self.turn), "statistic": self.statistic, "chance_level": self.chance,
                "gages": list(self.gages), "kind": self.kind}


def twist_maps(rig: Rig) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Linear maps of a mode shape (n_gages,) to what its stock's twist reads, rows in the rig's
    gage (DAQ channel) order: ``top`` (n,), the stock top's rotation less the hull section's
    (rad per unit shape), from a linear twist between the rudder's rotation at the attachment
    and the top's, least squares through the stock's gage pairs; ``rudder`` (n,), the rudder's
    rotation about its vertical axis (its athwartship gages' rigid-body fit, basis 1, x, -z)
    less the hull section's (:func:`section_motion`'s, with four hull gages or more; a hull mode
    turns the rudder with the hull, which the stock's top turns with too);
    ``misfit`` (H, n), the twist at each of the H pair heights less that line. A pair is two
    athwartship stock gages at one height and different x (their difference over the distance
    is the twist there). None when the rig has fewer than three athwartship rudder gages or
    pairs at fewer than two heights (the line then has no freedom left to test)."""
    gs = rig.gages_by_channel()
    if rig.rudder is None or rig.stock is None:
        return None
    pos = np.array([g.position_m for g in gs], float)
    body = np.array([g.body for g in gs])
    ath = np.array(["z" not in g.axis for g in gs])
    rud = np.flatnonzero((body == "rudder") & ath)
    stock = np.flatnonzero((body == "stock") & ath)
    heights = sorted({float(pos[i, 2]) for i in stock})
    pairs = [(ii[0], ii[-1]) for z in heights
             if len(ii := [i for i in stock if pos[i, 2] == z]) >= 2 and pos[ii[0], 0] != pos[ii[-1], 0]]
    if len(rud) < 3 or len(pairs) < 2:
        return None
    n = len(gs)
    gamma = np.zeros(n)
    gamma[rud] = np.linalg.pinv(np.c_[np.ones(len(rud)), pos[rud, 0], -pos[rud, 2]])[1]
    tw = np.zeros((len(pairs), n))
    for k, (i, j) in enumerate(pairs):
        tw[k, i], tw[k, j] = 1 / (pos[i, 0] - pos[j, 0]), -1 / (pos[i, 0] - pos[j, 0])
    t = np.array([(pos[i, 2] - rig.rudder.attach_z_m) / rig.stock.torsion_length_m for i, _ in pairs])
    free = tw - np.outer(1 - t, gamma)                  # what the top's turn must explain
    top = t @ free / float(t @ t)
    misfit = free - np.outer(t, top)
    unit = tuple(HullMode(f"unit{j}", 1.0, 0.0, 1.0, *np.eye(3)[j]) for j in range(3))
    hull = body == "hull"
    if hull.sum() >= 4:                                 # the hull section's own rotation, as it moves
        n0 = 3 + len(rig.hull_modes)
        A = gage_map(replace(rig, hull_modes=rig.hull_modes + unit), n0 + 3)[hull][:, n0:]
        hull_turn = np.linalg.pinv(A)[1]
        top, gamma = top.copy(), gamma.copy()
        top[hull] -= hull_turn
        gamma[hull] -= hull_turn
    return top, gamma, misfit


def stock_turns(tm: TrialModes, rig: Rig) -> list[StockTurn]:
    """The stock's top turning with the rudder (:class:`StockTurn`; one or none): a steering gear
    or tiller of finite stiffness ``k_g`` with the tiller's inertia ``J_t`` at the stock's top,
    where the rig holds the top to the hull. A stock of torsional stiffness ``k_s`` then turns
    its top by ``q = k_s / (k_s + k_g - J_t w^2)`` of the rudder's rotation (both relative to
    the hull's section) in a mode of circular
    frequency ``w``: real, positive and growing with frequency below the tiller's own mode,
    negative above it, and the stock's twist between the rudder and the top stays linear. Any
    mass, inertia or stiffness of the rig leaves ``q`` at zero -- the twist's kinematics are
    geometry (:func:`twist_maps`) -- so a ``q`` beyond :data:`TURN_FORM` is what no calibration of
    the constants makes.

    Read on the identified modes that turn the rudder (decaying, found in three quarters of the
    impacts, the rudder's by most of their energy, ``q`` known to within :data:`TURN_FORM`): at
    least two, each with its stock twisting linearly (the line's misfit within
    :data:`TURN_FORM` of the rudder's rotation), and by frequency a run of two or more whose
    ``q`` is in phase (imaginary part within the tolerance and three standard errors), above the
    tolerance and not falling by more than it, before any that turns against the rudder. A
    structure whose stock does not twist as the rig's kinematics say (the modal family's stock
    gages read each mode's own field: the line missed by 0.09-1.1 on development seeds
    51000-51005, in every trial on one mode at least) raises none."""
    maps = twist_maps(rig)
    if maps is None:
        return []
    top, gamma, misfit = maps
    body = np.array([g.body for g in rig.gages_by_channel()])
    rows = []
    for i in range(tm.n_modes):
        s, se = tm.shapes[:, i], tm.shape_se[:, i]
        e = np.abs(s) ** 2
        g = complex(gamma @ s)
        if (tm.zeta[i] <= 0 or tm.n_seen[i] < 0.75 * tm.n_impacts or abs(g) == 0
                or hull_share(e, rig) >= HULL_MODE_SHARE):
            continue
        q = complex(top @ s) / g
        q_se = float(np.sqrt(np.sum(np.abs(top - q * gamma) ** 2 * se**2)) / abs(g))
        if q_se <= TURN_FORM:
            rows.append((i, q, q_se, float(np.linalg.norm(misfit @ s)) / abs(g), abs(g)))
    if len(rows) < 2 or any(r[3] > TURN_FORM for r in rows):
        return []
    run = []
    for r in rows:
        if r[1].real < 0:
            break
        tol = TURN_FORM + 3 * r[2]
        if abs(r[1].imag) > tol or r[1].real < tol or (run and r[1].real < run[-1][1].real - tol):
            return []
        run.append(r)
    if len(run) < 2:
        return []
    i = max(run, key=lambda r: r[4])[0]
    a = np.where(body == "hull", 0.0, np.abs(tm.shapes[:, i]))
    big = [int(k) for k in np.argsort(-a) if a[k] >= 0.5 * a.max()]
    return [StockTurn(float(tm.f_hz[i]), float(tm.zeta[i]), tuple(float(tm.f_hz[r[0]]) for r in rows),
                      tuple(float(r[1].real) for r in rows),
                      min(r[1].real / (TURN_FORM + 3 * r[2]) for r in run), 1.0,
                      tuple(tm.gage_numbers[k] for k in big))]


# -- modes above the rig's band ------------------------------------------------------------------
def structure_above(td: TrialData, f_from_hz: float) -> list[Split | Coupled]:
    """The splits (:func:`splits`) and flexibly coupled hull modes (:func:`flexible_coupled`) among ``td``'s
    modes above ``f_from_hz`` (Hz; the rig's own band, which does not compare them), against
    ``td``'s rig model as it stands: what makes the data's band (``prepare(..., data_band=True)``)
    worth its cost. Only the modes above ``f_from_hz`` are identified, so the rig's modes there are
    paired by shape and frequency within :data:`MAX_PAIR_RATIO` (a rig off by +-25 % moves a mode
    by up to 1.3x, well within); a mode of the rig paired with one identified mode of its shape is
    no finding, whatever its frequency. Empty when no mode there recurs over the impacts."""
    try:
        tm = trial_modes(td, f_lo_hz=f_from_hz)
    except (ValueError, np.linalg.LinAlgError):
        return []
    if tm.n_modes == 0:
        return []
    cmp = compare(tm, td.rig)
    return [*splits(tm, cmp, td.rig), *flexible_coupled(tm, td.rig, cmp)]
