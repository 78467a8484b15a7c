"""The gap in physical terms: per gage x mode x window, how the trial's decay differs from the
calibrated model's -- frequency, decrement, amplitude (a per-gage scale), envelope shape, mode
shape (MAC), rigid-body consistency of the rudder's and the hull's gages -- and, before each blow,
the spectral lines the model does not have. Each is standardised against the same replicate
simulations of the calibrated model as the energy map (:mod:`ramdaq.analysis.gap.evidence`), so its
``z`` says what is beyond the trial's noise and the model's form tolerance.

How a decay is read: in each decay window every segment of every gage is fitted, by linear
least squares, with the calibrated model's own modes carrying a slowly varying complex amplitude,

    x(tau) = Re sum_m (c_m + d_m u + e_m u^2) exp(lambda_m tau),   u = tau / T (0..1 over the window)

(modes above the compared band and a constant with c only). Since ``exp((lambda + dl) tau) ~
exp(lambda tau) (1 + dl tau + ...)``, ``d/c = dl T`` is the shift of the mode's eigenvalue the
data asks for (its imaginary part a frequency error, its real part a decay-rate error);
``|c|`` is the amplitude at the window's start; and the log-envelope's curvature over the window,
``2 Re(e/c - (d/c)^2 / 2)``, is zero for any pure exponential and not for a beat or an
amplitude-dependent damping. The vectors ``c`` over the gages give each mode's shape. The
replicates are read the same way: ``pred + resid_rep`` is what the trial would look like if the
calibrated model (within its form tolerance) were true.

Shapes: ``n_g`` gages (the trial's rows), ``n_m`` compared modes (in the band, ascending), two
decay windows (``early``, ``late``), ``n_b`` map bands (pre-trigger lines).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .calibrate import Calibration
from .effects.base import compared_modes
from .evidence import Bands
from .forward import Forward
from .trialdata import TrialData

DECAY_WINDOWS = ("early", "late")
FEATURES = {
    "frequency": "frequency error (fraction of the model's)",
    "decrement": "decrement error (fraction of the model's)",
    "scale": "amplitude ratio, trial / model",
    "envelope": "log-envelope curvature over the window (dimensionless, 0 for an exponential)",
    "rigid": "share of the motion off the body's rigid-body motion (fraction)",
}
"""Per gage x mode x window features: name -> what it is, in what unit."""
MIN_SNR = 3.0
"""A gage is judged on a mode only where the model's amplitude there is this many times the
spread of the replicates' amplitude about it (the estimate's own noise and form tolerance):
below it every ratio is noise."""
Z_FLOOR = 1e-9


@dataclass
class FeatureMap:
    """Discrepancies of a trial from a calibrated model, with their replicate z-scores.

    ``value`` and ``z``: name -> (n_g, n_m, 2) for :data:`FEATURES` (NaN where not judged:
    too weak, or a gage on no rigid body); ``value`` is the trial's, in the unit
    :data:`FEATURES` gives; ``expected`` the replicates' median of the same. ``mac`` and ``mac_z``
    (n_m, 2): each mode's shape against the model's (1 = same; ``mac_z`` > 0 when lower than the
    replicates'). ``line_amp`` (n_g, n_b) the largest spectral line in each band before the blows
    (m/s^2 amplitude), ``line_hz`` its frequency, ``line_z`` its score against the replicates."""

    gage_numbers: tuple[int, ...]
    mode_hz: np.ndarray
    value: dict[str, np.ndarray]
    expected: dict[str, np.ndarray]
    z: dict[str, np.ndarray]
    mac: np.ndarray
    mac_z: np.ndarray
    bands: Bands
    line_amp: np.ndarray
    line_hz: np.ndarray
    line_z: np.ndarray
    z_family: float
    """The map's own chance level (:func:`family_level`): a trial that is just another replicate
    reaches it anywhere on its map at most 1 time in 20. A cell beyond it stands out of the
    whole map, not just of its own spread."""
    model_hz: np.ndarray
    """Every mode of the model (Hz), compared or not: a pre-trigger line at one of them may be
    an earlier blow's ringing the model decays differently, not a tone."""
    pre_s: float
    """Length of the pre-trigger window, s: lines closer than 1/pre_s cannot be told apart."""

    @property
    def list_level(self) -> float:
        """The z beyond which a cell is listed: :attr:`z_family`, and never below 3."""
        return max(3.0, self.z_family) if np.isfinite(self.z_family) else 3.0

    def strongest(self, n: int = 6, z_min: float | None = None) -> list[dict]:
        """The ``n`` largest discrepancies beyond ``z_min`` (default :attr:`list_level`), most
        significant first: each a dict with ``feature``, ``gage`` (None for a mode's shape),
        ``mode_hz`` or ``band``, ``window``, ``value``, ``expected``, ``z`` and a one-line
        ``text``."""
        z_min = self.list_level if z_min is None else z_min
        rows = []
        for name, z in self.z.items():
            for g, m, w in zip(*np.nonzero(np.abs(np.nan_to_num(z)) > z_min), strict=True):
                rows.append({"feature": name, "gage": self.gage_numbers[g], "mode_hz": float(self.mode_hz[m]),
                             "window": DECAY_WINDOWS[w], "value": float(self.value[name][g, m, w]),
                             "expected": float(self.expected[name][g, m, w]), "z": float(z[g, m, w])})
        for m, w in zip(*np.nonzero(np.nan_to_num(self.mac_z) > z_min), strict=True):
            rows.append({"feature": "mac", "gage": None, "mode_hz": float(self.mode_hz[m]),
                         "window": DECAY_WINDOWS[w], "value": float(self.mac[m, w]), "expected": 1.0,
                         "z": float(self.mac_z[m, w])})
        for g, b in zip(*np.nonzero(np.nan_to_num(self.line_z) > z_min), strict=True):
            f = float(self.line_hz[g, b])
            near = self.model_hz[np.abs(self.model_hz - f) < 1 / self.pre_s]
            rows.append({"feature": "line", "gage": self.gage_numbers[g], "band": self.bands.labels[b],
                         "mode_hz": f, "window": "pre", "value": float(self.line_amp[g, b]),
                         "expected": float("nan"), "z": float(self.line_z[g, b]),
                         "at_model_mode_hz": float(near[0]) if near.size else None})
        rows.sort(key=lambda r: -abs(r["z"]))
        for r in rows[:n]:
            r["text"] = describe(r)
        return rows[:n]

    def worst_by_feature(self) -> dict[str, float]:
        """The largest z of each feature over the whole map, |z| for two-sided ones (NaN where
        nothing was judged)."""
        out = {k: _nanmax(np.abs(v)) for k, v in self.z.items()}
        # one-sided: a shape closer to the model's, a line weaker than the noise's, is no gap
        out["mac"] = _nanmax(self.mac_z)
        out["line"] = _nanmax(self.line_z)
        return out

    def to_json(self) -> dict:
        def r(a: np.ndarray, d: int = 4) -> list:
            return np.where(np.isfinite(a), np.round(a, d), np.nan).tolist()

        return {"gages": list(self.gage_numbers), "modes_hz": r(self.mode_hz, 3),
                "windows": list(DECAY_WINDOWS),
                "features": {k: {"what": FEATURES[k], "value": r(self.value[k]),
                                 "expected": r(self.expected[k]), "z": r(self.z[k], 2)}
                             for k in self.value},
                "mac": {"value": r(self.mac), "z": r(self.mac_z, 2)},
                "pre_trigger_lines": {"bands": self.bands.labels, "amplitude_m_s2": r(self.line_amp, 6),
                                      "f_hz": r(self.line_hz, 3), "z": r(self.line_z, 2),
                                      "pre_window_s": round(self.pre_s, 4)},
                "z_family": round(self.z_family, 2) if np.isfinite(self.z_family) else None,
                "strongest": self.strongest()}


def _nanmax(a: np.ndarray) -> float:
    a = a[np.isfinite(a)]
    return float(a.max()) if a.size else float("nan")


def describe(row: dict) -> str:
    """One line a trial engineer reads: what, where, how much, how sure."""
    where = f"{row['mode_hz']:.2f} Hz mode, {row['window']} decay"
    v, f = row["value"], row["feature"]
    if f == "line":
        at = row.get("at_model_mode_hz")
        what = (f"at the model's {at:.2f} Hz mode: a tone, or ringing it decays otherwise" if at is not None
                else "no model mode there")
        return (f"gage {row['gage']}: {row['mode_hz']:.2f} Hz line before the blows, "
                f"{1e3 * v:.2f} mm/s^2 ({what}; z {row['z']:.1f})")
    if f == "mac":
        return f"{where}: mode shape MAC {v:.3f} against the model (z {row['z']:.1f})"
    if f == "scale":
        return f"gage {row['gage']}, {where}: amplitude x{v:.3f} of the model's (z {row['z']:.1f})"
    if f == "envelope":
        return (f"gage {row['gage']}, {where}: envelope {'bends up' if v > 0 else 'bends down'} "
                f"(curvature {v:+.3f}, model {row['expected']:+.3f}; z {row['z']:.1f})")
    if f == "rigid":
        return (f"gage {row['gage']}, {where}: {100 * v:.1f} % off its body's rigid-body motion "
                f"(model {100 * row['expected']:.1f} %; z {row['z']:.1f})")
    return f"gage {row['gage']}, {where}: {f} error {100 * v:+.1f} % (z {row['z']:.1f})"


def decay_amplitudes(x: np.ndarray, fs_hz: float, lam: np.ndarray,
                     lam_other: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Slowly varying modal amplitudes of decays ``x`` (..., n) sampled at ``fs_hz`` from the
    window's start: least squares on the modes ``lam`` (m,) with ``c + d u + e u^2``
    (``u`` 0..1 over the window), ``lam_other`` and a constant with a fixed amplitude.

    Returns ``c, d, e`` (..., m) complex, in the units of ``x``; NaN for a series with a gap."""
    n = x.shape[-1]
    tau = np.arange(n) / fs_hz
    u = tau / max(tau[-1], 1 / fs_hz)
    cols = []
    for lm in lam:
        e = np.exp(lm * tau)
        for k in range(3):
            cols += [(e * u**k).real, -(e * u**k).imag]
    for lm in () if lam_other is None else lam_other:
        e = np.exp(lm * tau)
        cols += [e.real] + ([-e.imag] if abs(lm.imag) > 0 else [])
    cols.append(np.ones(n))
    X = np.stack(cols, axis=1)
    scale = np.linalg.norm(X, axis=0)
    P = np.linalg.pinv(X / scale, rcond=1e-10) / scale[:, None]        # (n_cols, n)
    flat = x.reshape(-1, n)
    ok = np.all(np.isfinite(flat), axis=1)
    if ok.all():        # no series with a gap: no copy of them (the same product)
        coef = flat @ P.T
    else:
        coef = np.full((flat.shape[0], P.shape[0]), np.nan)
        coef[ok] = flat[ok] @ P.T
    m = len(lam)
    z = coef[:, : 6 * m].reshape(-1, m, 3, 2)
    amp = z[..., 0] + 1j * z[..., 1]
    shape = x.shape[:-1] + (m,)
    return amp[..., 0].reshape(shape), amp[..., 1].reshape(shape), amp[..., 2].reshape(shape)


def decay_features(c: np.ndarray, d: np.ndarray, e: np.ndarray, lam: np.ndarray,
                   T_s: float) -> dict[str, np.ndarray]:
    """Frequency (Hz) and decrement of each mode as the amplitudes ``c, d, e`` (..., n_seg, n_g,
    m) of a window of ``T_s`` s read them, the log-envelope's curvature, and the rms amplitude:
    name -> (..., n_g, m). The segments are pooled as a ratio estimate weighted by ``|c|^2``
    (``d/c ~ sum conj(c) d / sum |c|^2``): a segment where a gage barely sees the mode adds
    little, where a plain mean of its ratios would be led by it."""
    ok = np.isfinite(c) & np.isfinite(d) & np.isfinite(e)
    c0, d0, e0 = (np.where(ok, v, 0) for v in (c, d, e))
    w = np.sum(np.abs(c0) ** 2, axis=-3)
    n = ok.sum(axis=-3)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.sum(np.conj(c0) * d0, axis=-3) / w
        q = np.sum(np.conj(c0) * e0, axis=-3) / w
        lam_d = lam + r / T_s
        curv = 2 * (q - r**2 / 2).real
        f = lam_d.imag / (2 * math.pi)
        delta = -2 * math.pi * lam_d.real / lam_d.imag
        amp = np.sqrt(w / n)
    bad = n == 0
    return {k: np.where(bad, np.nan, v) for k, v in
            {"f_hz": f, "delta": delta, "curv": curv, "amp": amp}.items()}


def rigid_projector(rig_gages: list, rows: np.ndarray) -> np.ndarray | None:
    """``I - Q Q^H`` for the gages ``rows`` of one rigid body: what of a vector of their motions
    no rigid-body motion makes (columns ``n`` and ``r x n`` per gage: translation and rotation
    about the rudder's centre of mass seen along each sensing axis). None when the gages are not
    redundant (no more of them than rigid-body motions they can see)."""
    G = np.array([np.concatenate([g.direction, np.cross(np.array(g.position_m), g.direction)])
                  for g in (rig_gages[i] for i in rows)])
    u, s, _ = np.linalg.svd(G, full_matrices=False)
    rank = int(np.sum(s > 1e-9 * s[0])) if s.size and s[0] > 0 else 0
    if len(rows) <= rank:
        return None
    Q = u[:, :rank]
    return np.eye(len(rows)) - Q @ Q.T


def rigid_share(c: np.ndarray, bodies: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Per gage, the share of a mode's motion off its body's rigid-body motion, pooled over the
    segments: ``sqrt(sum |P c|_g^2 / sum mean_body |c|^2)``, (..., n_seg, n_g, m) -> (..., n_g,
    m); NaN for gages on no redundant body. ``bodies`` are (rows, projector) pairs from
    :func:`rigid_projector`."""
    out = np.full(c.shape[:-3] + c.shape[-2:], np.nan)
    for rows, P in bodies:
        cb = c[..., rows, :]
        res = np.einsum("ij,...jm->...im", P, cb)
        ok = np.all(np.isfinite(cb), axis=-2, keepdims=True)
        num = np.sum(np.where(ok, np.abs(res) ** 2, 0), axis=-3)
        den = np.sum(np.where(ok, np.mean(np.abs(cb) ** 2, axis=-2, keepdims=True), 0), axis=-3)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[..., rows, :] = np.sqrt(num / den)
    return out


def mac(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Modal assurance criterion of complex shapes over the gage axis -2: (..., n_g, m) -> (..., m)."""
    num = np.abs(np.sum(np.conj(a) * b, axis=-2)) ** 2
    den = np.sum(np.abs(a) ** 2, axis=-2) * np.sum(np.abs(b) ** 2, axis=-2)
    with np.errstate(divide="ignore", invalid="ignore"):
        return num / den


def line_spectrum(x: np.ndarray, fs_hz: float, edges_hz: np.ndarray,
                  oversample: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """The strongest spectral line of ``x`` (..., n_seg, n_g, n) in each band, m/s^2 amplitude
    and Hz, (..., n_g, n_b) each.

    At every frequency of a grid ``oversample`` times finer than ``1/T``, a sine, a constant and
    a slope are fitted by least squares (a pre-trigger window holds only a few cycles of a low
    tone, which a windowed periodogram smears over the next band); the sine's power is averaged
    over the segments. Lines are taken strongest first, each fitted sine subtracted before the
    next is sought (matching pursuit), so a strong tone's sidelobes are not read as lines of
    their own; one line per band. Below one cycle in the window nothing is read (a slope takes
    it)."""
    lead, (n_seg, n_g, n) = x.shape[:-3], x.shape[-3:]
    T = n / fs_hz
    t = np.arange(n) / fs_hz - T / 2
    grid = np.arange(1.0 / T, min(edges_hz[-1], fs_hz / 2), 1.0 / (oversample * T))
    n_b = len(edges_hz) - 1
    r = np.nan_to_num(x).reshape((-1, n_seg, n_g, n))
    A = np.full((r.shape[0], n_g, n_b), np.nan)
    F = np.full_like(A, np.nan)
    if grid.size == 0:
        return A.reshape(lead + (n_g, n_b)), F.reshape(lead + (n_g, n_b))
    X = np.stack([np.cos(2 * math.pi * grid[:, None] * t), np.sin(2 * math.pi * grid[:, None] * t),
                  np.ones((len(grid), n)), np.broadcast_to(t, (len(grid), n))], axis=-1)   # (n_f, n, 4)
    Pinv = np.linalg.pinv(X)                                                           # (n_f, 4, n)
    band = np.clip(np.searchsorted(edges_hz, grid, side="right") - 1, 0, n_b - 1)
    free = np.ones((r.shape[0], n_g, n_b), bool)
    ii, gg = np.meshgrid(np.arange(r.shape[0]), np.arange(n_g), indexing="ij")
    # the scan only ranks frequencies: single precision (1e-7) is ample and 2.5x as fast; each
    # line's own fit and its subtraction below stay in double
    S = Pinv[:, :2].reshape(-1, n).T.astype(np.float32)                                # (n, 2 n_f)
    for _ in range(n_b):
        ab = (r.reshape(-1, n).astype(np.float32) @ S).reshape(r.shape[:3] + (len(grid), 2))
        power = np.einsum("lsgfk,lsgfk->lgf", ab, ab).astype(np.float64) / n_seg    # (L, n_g, n_f)
        power = np.where(free[..., band], power, -np.inf)
        k = np.argmax(power, axis=-1)                                                  # (L, n_g)
        b = band[k]
        take = np.isfinite(np.take_along_axis(power, k[..., None], -1)[..., 0])
        # the peak between grid points: a parabola through the power at k-1, k, k+1
        pw = [np.take_along_axis(power, np.clip(k + j, 0, len(grid) - 1)[..., None], -1)[..., 0]
              for j in (-1, 0, 1)]
        with np.errstate(invalid="ignore", divide="ignore"):
            den = pw[0] - 2 * pw[1] + pw[2]
            off = np.where(np.isfinite(den) & (den < 0), 0.5 * (pw[0] - pw[2]) / den, 0.0)
        f = grid[k] + np.clip(off, -0.5, 0.5) * (grid[1] - grid[0] if len(grid) > 1 else 0.0)
        Xf = np.stack([np.cos(2 * math.pi * f[..., None] * t), np.sin(2 * math.pi * f[..., None] * t),
                       np.ones(f.shape + (n,)), np.broadcast_to(t, f.shape + (n,))], axis=-1)
        coef = np.einsum("lgkn,lsgn->lsgk", np.linalg.pinv(Xf), r)                     # (L, n_seg, n_g, 4)
        p_f = np.mean(np.sum(coef[..., :2] ** 2, axis=-1), axis=1)
        A[ii[take], gg[take], b[take]] = np.sqrt(p_f[take])
        F[ii[take], gg[take], b[take]] = f[take]
        free[ii, gg, b] = False
        # the line's sine (with its constant and slope) out of every segment, then the next
        r = r - np.einsum("lgnk,lsgk->lsgn", Xf, coef)
    return A.reshape(lead + (n_g, n_b)), F.reshape(lead + (n_g, n_b))


def _nanmean(a: np.ndarray, axis: int | tuple[int, ...]) -> np.ndarray:
    """Mean of the finite values along ``axis``; NaN where there are none (no warning)."""
    ok = np.isfinite(a)
    n = ok.sum(axis=axis)
    s = np.where(ok, a, 0).sum(axis=axis)
    return np.where(n > 0, s / np.maximum(n, 1), np.nan)


def robust_z(value: np.ndarray, reps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(value - median) / (1.4826 MAD)`` against replicate values (n_rep, ...); and the median.
    A ratio of a weakly seen mode has heavy tails, which a standard deviation would let set the
    scale."""
    import warnings

    with warnings.catch_warnings(), np.errstate(divide="ignore", invalid="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)          # all-NaN cells: NaN, as meant
        med = np.nanmedian(reps, axis=0)
        mad = 1.4826 * np.nanmedian(np.abs(reps - med), axis=0)
        z = (value - med) / np.maximum(mad, Z_FLOOR + 1e-6 * np.abs(med))
    return z, med


def family_level(nulls: list[tuple[np.ndarray, bool]], alpha: float = 0.05) -> float:
    """The map's chance level: each replicate scored against the others, its largest z anywhere
    on its map; the level is the conformal rank of those maxima, the ``ceil((n + 1)(1 - alpha))``
    -th smallest of ``n``, so that a trial which is just another replicate exceeds it with
    probability at most ``alpha`` (with 24 replicates and 5 %: their largest, 1 time in 25).
    ``nulls`` are (replicate values (n_rep, ...), two-sided) per feature, in the form
    :func:`robust_z` scores them. Infinite when there are too few replicates to say."""
    n_rep = nulls[0][0].shape[0]
    worst = np.full(n_rep, -np.inf)
    for j in range(n_rep):
        for reps, two_sided in nulls:
            z, _ = robust_z(reps[j], np.delete(reps, j, axis=0))
            z = np.abs(z) if two_sided else z
            if np.any(np.isfinite(z)):
                worst[j] = max(worst[j], float(np.nanmax(z)))
    rank = math.ceil((n_rep + 1) * (1 - alpha))
    return float(np.sort(worst)[rank - 1]) if rank <= n_rep else math.inf


def feature_map(fw: Forward, cal: Calibration, resid_reps: np.ndarray, bands: Bands) -> FeatureMap:
    """The trial's discrepancies from the calibrated ``cal`` (its residual ``cal.fit.resid``),
    standardised by the replicates' residuals ``resid_reps`` (n_rep, n_seg, n_g, n_s) of the
    same model (see the module docstring). All impacts count."""
    td = fw.td
    pred, resid = cal.fit.pred, cal.fit.resid
    ms = cal.fit.modes
    idx = [i for i, _ in sorted(compared_modes(fw, cal.fit), key=lambda t: t[1])]
    others = [i for i in range(len(ms.lam)) if i not in idx]
    lam, lam_o = ms.lam[idx], ms.lam[others]
    bodies = _rigid_bodies(td)
    shape = (td.n_gages, len(idx), len(DECAY_WINDOWS))
    value = {k: np.full(shape, np.nan) for k in FEATURES}
    expected = {k: np.full(shape, np.nan) for k in FEATURES}
    z = {k: np.full(shape, np.nan) for k in FEATURES}
    mac_v = np.full((len(idx), len(DECAY_WINDOWS)), np.nan)
    mac_z = np.full_like(mac_v, np.nan)
    nulls: list[tuple[np.ndarray, bool]] = []
    for w, name in enumerate(DECAY_WINDOWS):
        win = getattr(td.windows, name)
        per, m_all = _window_features(_signals(pred, resid, resid_reps, fw.mask, win), td.fs_hz, lam,
                                      lam_o, bodies)
        for k, v in per.items():
            # a ratio is judged in log: its spread is relative
            judged = np.log(v) if k == "scale" else v
            zz, med = robust_z(judged[0], judged[2:])
            nulls.append((judged[2:], True))
            value[k][..., w] = v[0]
            expected[k][..., w] = np.exp(med) if k == "scale" else med
            z[k][..., w] = zz
        mac_v[:, w] = m_all[0]
        zz, _ = robust_z(-m_all[0], -m_all[2:])
        mac_z[:, w] = zz
        nulls.append((-m_all[2:], False))
    pre = td.windows.pre
    n_pre = len(range(*pre.indices(td.n_s)))
    if n_pre >= 8:
        line_amp, line_hz, line_z, null = _pre_lines(resid, resid_reps, pre, td.fs_hz, bands)
        nulls.append(null)
    else:
        line_amp = line_hz = line_z = np.full((td.n_gages, len(bands.labels)), np.nan)
    f_all = ms.lam.imag[~ms.exp_only] / (2 * math.pi)
    return FeatureMap(td.gage_numbers, lam.imag / (2 * math.pi), value, expected, z, mac_v, mac_z,
                      bands, line_amp, line_hz, line_z, family_level(nulls), np.sort(f_all[f_all > 0]),
                      n_pre / td.fs_hz)


def _signals(pred: np.ndarray, resid: np.ndarray, resid_reps: np.ndarray, mask: np.ndarray,
             win: slice) -> np.ndarray:
    """The trial, the model itself and each replicate in the window ``win`` of the segments,
    (2 + n_rep, n_seg, n_g, n_win) m/s^2, NaN off ``mask``: made window by window and in place
    (the whole of them was 93 MB at 20 impacts, and a copy of each window besides)."""
    p, m = pred[..., win], mask[..., win]
    out = np.empty((2 + len(resid_reps),) + p.shape)
    np.add(p, resid[..., win], out=out[0])
    out[1] = p
    np.add(p[None], resid_reps[..., win], out=out[2:])
    np.copyto(out, np.nan, where=~m[None])
    return out


def _rigid_bodies(td: TrialData) -> list[tuple[np.ndarray, np.ndarray]]:
    """(rows, rigid-body projector) of the rudder's and the hull's gages, where their layout
    determines a rigid motion (:func:`rigid_projector`)."""
    by_num = {g.number: g for g in td.rig.gages_by_channel()}
    rig_gages = [by_num[n] for n in td.gage_numbers]
    bodies = []
    for body in ("rudder", "hull"):
        rows = np.array([i for i, g in enumerate(rig_gages) if g.body == body])
        if rows.size and (P := rigid_projector(rig_gages, rows)) is not None:
            bodies.append((rows, P))
    return bodies


def _window_features(xs: np.ndarray, fs_hz: float, lam: np.ndarray, lam_o: np.ndarray,
                     bodies: list[tuple[np.ndarray, np.ndarray]]
                     ) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """One decay window of the trial, the model and each replicate (``xs`` (2 + n_rep, n_seg,
    n_g, n) m/s^2): each of :data:`FEATURES` per signal x gage x compared mode (poles ``lam``,
    the other modes ``lam_o``), NaN where the model's mode does not stand ``MIN_SNR`` times above
    the replicates' spread; and each mode's shape over all gages against the model's
    (amplitude-weighted, as MAC is), (2 + n_rep, m)."""
    T = (xs.shape[-1] - 1) / fs_hz
    # each window's amplitudes are read from its own start
    c, d, e = decay_amplitudes(xs, fs_hz, lam, lam_o)
    feats = decay_features(c, d, e, lam, T)                          # (2 + n_rep, n_g, m)
    spread = np.sqrt(_nanmean(np.abs(c[2:] - c[1][None]) ** 2, axis=(0, 1)))   # (n_g, m)
    seen = feats["amp"][1] > MIN_SNR * spread
    f0, d0 = lam.imag / (2 * math.pi), -2 * math.pi * lam.real / lam.imag
    with np.errstate(divide="ignore", invalid="ignore"):
        per = {"frequency": feats["f_hz"] / f0 - 1, "decrement": feats["delta"] / d0 - 1,
               "scale": feats["amp"] / feats["amp"][1], "envelope": feats["curv"],
               "rigid": rigid_share(c, bodies)}
    # unseen cells stay NaN from here on
    per = {k: np.where(seen, v, np.nan) for k, v in per.items()}
    return per, _nanmean(mac(c[1][None], c), axis=1)


def _pre_lines(resid: np.ndarray, resid_reps: np.ndarray, pre: slice, fs_hz: float,
               bands: Bands) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, bool]]:
    """The lines before the blows (:func:`line_spectrum` of the pre windows) of the trial's
    residual against its replicates' (``resid_reps``): per gage x band the trial's line
    amplitude (m/s^2), frequency (Hz) and z; and the replicates' log amplitudes as a null of
    :func:`family_level` (one-sided)."""
    # the pre windows cut before they are joined: the whole residuals joined were 93 MB at 20 impacts
    A, F = line_spectrum(np.concatenate([resid[None, ..., pre], resid_reps[..., pre]]), fs_hz, bands.edges_hz)
    with np.errstate(divide="ignore"):
        logA = np.log(A)                                     # an amplitude's spread is relative
    line_z, _ = robust_z(logA[0], logA[1:])
    return A[0], F[0], line_z, (logA[1:], False)
