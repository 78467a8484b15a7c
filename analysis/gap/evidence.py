"""What is beyond chance: the trial's noise, repeated simulations of the calibrated model, the gap
map, and each candidate effect's signature strength.

* :func:`noise_model` -- each gage's noise spectrum from the residual of the pre windows, with
  narrow lines replaced by a running median over frequency (a steady tone is a finding, not
  noise) and smoothed by a running mean.
* :func:`replicate_residuals` -- the calibrated prediction plus fresh noise of that spectrum, the
  impacts' forces re-solved: what the residual looks like when the calibrated model *is* true.
* :func:`cell_energies` / :class:`GapMap` -- residual energy per gage x band x window (pre,
  early, late), standardised by the replicates: ``z = (E - mean_rep) / sd_rep``.
* :func:`signature_scores` -- for an effect's placements, the residual's projection on the
  effect's signature (its probe prediction less the calibrated one), with the calibration's own
  directions (constants, forces, onsets) projected out: a score test. Its null spread comes from
  the same replicates, so coloured noise does not inflate it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.ndimage
import scipy.signal
import scipy.special
import scipy.stats

from .calibrate import Calibration
from .effects.base import Effect, Placement, Term, whiten_fitted
from .forward import Design, Forward, ModeSet

WINDOWS = ("pre", "early", "late")
DECAY_TOL_PER_FORM_TOL = 5.0
"""A model whose mode shapes are right to 2 % has decay rates right to ~10 %."""
GAP_CELL_Z = 3.0
"""A map cell counts into the gap when its z exceeds this (one-sided 0.13 %)."""


@dataclass
class NoiseModel:
    """One-sided noise PSD per gage on the rfft grid of a segment: ``psd`` (n_gages, n_f)
    (m/s^2)^2/Hz, ``sigma`` (n_gages,) its rms, m/s^2."""

    psd: np.ndarray
    sigma: np.ndarray
    fs_hz: float
    n_s: int

    def draw(self, rng: np.random.Generator, n_seg: int) -> np.ndarray:
        """Noise of this spectrum, (n_seg, n_gages, n_s), m/s^2."""
        w = rng.standard_normal((n_seg, self.psd.shape[0], self.n_s))
        X = np.fft.rfft(w, axis=-1) * np.sqrt(self.psd * self.fs_hz / 2)[None]
        return np.fft.irfft(X, n=self.n_s, axis=-1)


def noise_model(fw: Forward, resid: np.ndarray) -> NoiseModel:
    """Noise spectrum of each gage from ``resid`` (n_seg, n_g, n_s) in the pre windows.

    A front-end's noise floor is smooth: white above a corner, rising as ``1/f^a`` below it.
    So each gage's Welch spectrum (narrow lines replaced by a running median: a steady tone is
    a finding, not noise) is fitted by ``w (1 + (f_k / f)^a)``; the few bins of a short
    window's low end would otherwise set the low band's floor by chance.
    """
    td = fw.td
    pre = np.nan_to_num(resid[:, :, td.windows.pre])
    n_pre = pre.shape[-1]
    nper = int(min(n_pre, max(64, 2 ** int(math.log2(max(n_pre, 64))))))
    f, P = scipy.signal.welch(pre, fs=td.fs_hz, nperseg=nper, axis=-1, detrend=False)
    n_avg = pre.shape[0] * max(1, 2 * n_pre // nper - 1)
    P = P.mean(axis=0)
    S = scipy.ndimage.median_filter(P, size=(1, 9), mode="nearest")
    line = scipy.ndimage.binary_dilation(P > 4 * S, structure=np.ones((1, 5)))  # Hann spreads a line
    fg = np.fft.rfftfreq(td.n_s, 1 / td.fs_hz)
    band = (f > 0) & (f < td.lowpass_hz)
    if band.sum() < 3:  # the floor's three constants need three bins at the least
        raise ValueError(f"the band compared ({td.lowpass_hz:.3g} Hz, decimated to "
                         f"{td.fs_hz:.3g} Hz) leaves {int(band.sum())} bin(s) of the pre-trigger "
                         f"window's spectrum ({n_pre} samples): too little to model the noise")
    psd = np.empty((P.shape[0], len(fg)))
    for g in range(P.shape[0]):
        keep = band & ~line[g]
        if keep.sum() < 4:
            keep = band
        psd[g] = _floor_fit(f[keep], P[g, keep], fg, 2 * n_avg)
    sigma = np.sqrt(np.trapezoid(psd, fg, axis=1))
    return NoiseModel(psd, sigma, td.fs_hz, td.n_s)


def _floor_fit(f: np.ndarray, P: np.ndarray, f_out: np.ndarray, dof: float) -> np.ndarray:
    """``w (1 + (f_k/f)^a)`` fitted to a spectrum in log power, evaluated at ``f_out``
    (the DC bin takes the lowest bin's value). The level is set by the median ratio of the
    spectrum to the fit, corrected for the median of a chi-square of ``dof`` degrees of freedom
    (Wilson-Hilferty) -- a median, so a line the masking missed does not lift the floor."""
    import scipy.optimize

    y = np.log(np.maximum(P, 1e-300))
    w0 = np.median(P)

    def model(p, ff):
        lw, lk, a = p
        return lw + np.log1p(np.exp(a * (lk - np.log(ff))))

    res = scipy.optimize.least_squares(lambda p: model(p, f) - y, [math.log(w0), math.log(f[0]), 1.0],
                                       bounds=([-np.inf, math.log(f[0] / 100), 0.3],
                                               [np.inf, math.log(f[-1]), 2.5]), loss="soft_l1")
    ff = np.maximum(f_out, f_out[1] if len(f_out) > 1 else 1.0)
    out = np.exp(model(res.x, ff))
    med = (1 - 2 / (9 * dof)) ** 3
    return out * np.median(P / np.exp(model(res.x, f))) / med


def replicate_residuals(fw: Forward, cal: Calibration, noise: NoiseModel, n_rep: int,
                        seed: int = 0, form_tol: float = 0.0) -> np.ndarray:
    """Residuals of ``n_rep`` simulated trials of the calibrated model, (n_rep, n_seg, n_g, n_s).

    Each replicate is the calibrated prediction with fresh noise of the trial's spectrum and,
    for a model-form tolerance ``form_tol``, every gage's amplitude of every mode perturbed by
    a random complex factor ``1 + form_tol (a + j b) / sqrt(2)`` (a, b standard normal), its decay
    rate by ``DECAY_TOL_PER_FORM_TOL * form_tol``: what a model "right to within form_tol" leaves
    when it is right."""
    rng = np.random.default_rng(seed)
    U, u_blocks, design = _replicate_design(fw, cal)     # the same columns for every replicate
    out = np.empty((n_rep,) + fw.td.x.shape)
    needs_force = any(t.effect.needs_force for t in cal.terms)
    for r in range(n_rep):
        x = cal.fit.pred + noise.draw(rng, fw.td.n_seg)
        if form_tol > 0:
            ms = cal.fit.modes.copy()
            xi = rng.standard_normal(ms.A.shape) + 1j * rng.standard_normal(ms.A.shape)
            ms.A = ms.A * (1 + form_tol * xi / math.sqrt(2))
            # and each mode's decay rate by DECAY_TOL_PER_FORM_TOL x as much: the damping
            # constants are shared by all modes, so their per-mode rates are the loosest part
            rel = DECAY_TOL_PER_FORM_TOL * form_tol * rng.standard_normal(ms.lam.shape)
            ms.lam = ms.lam + ms.lam.real * rel
            x = x + _form_change(fw, cal, ms, U, u_blocks, needs_force)
        _, pred = design.solve(x)
        out[r] = np.where(fw.mask, x - pred, np.nan)
    return out


def _replicate_design(fw: Forward, cal: Calibration) -> tuple[np.ndarray | None, dict | None, Design]:
    """The calibration's linear columns as the replicates re-solve them: (None, its unit blocks
    (:meth:`Forward.unit_blocks`, the derivatives let go), their design) when no term changes
    the unit responses -- the numbers :meth:`Forward.fit` solves with --; else (the dense unit
    responses (n_imp, n_seg, n_g, n_s), None, their design)."""
    if any(t.effect.changes_units() for t in cal.terms):
        U, dU, extra = cal.columns(fw)
        return U, None, fw.linear_design(U, dU, extra)
    blocks = fw.unit_blocks(cal.fit.modes, cal.terms)
    design = fw.block_design(blocks, fw.columns(cal.terms))
    for b in blocks.values():
        b[1] = None     # the derivatives are in the design; the differences read the responses
    return None, blocks, design


def _form_change(fw: Forward, cal: Calibration, ms: ModeSet, U: np.ndarray | None,
                 u_blocks: dict | None, needs_force: bool) -> np.ndarray:
    """What perturbing the calibrated modes to ``ms`` changes in the prediction at the
    calibrated forces, (n_seg, n_g, n_s) m/s^2: ``force . (U_r - U)`` over the impacts.

    With ``u_blocks`` (the calibration's unit blocks, :meth:`Forward.unit_blocks`) the
    difference is made segment by segment from the perturbed modes' blocks, each segment's
    (n_imp, n_g * n_s) rows with zeros where neither writes -- the same numbers, impact by
    impact, as the dense form, whose difference touched every page of an (n_imp, n_seg, n_g,
    n_s) array (72 MB at 20 impacts) per replicate; else the dense unit responses."""
    force = cal.fit.force
    if u_blocks is None:
        # the derivative is not wanted: dropped at once; the difference made in place
        Ur = fw.unit_responses(ms, cal.terms, force=force if needs_force else None)[0]
        Ur -= U
        return np.tensordot(force, Ur, axes=1)
    td = fw.td
    r_blocks = fw.unit_blocks(ms, cal.terms)
    out = np.empty(td.x.shape)
    D = np.zeros((td.n_seg, td.n_gages * td.n_s))
    for s in range(td.n_seg):
        D[:] = 0.0
        for j in range(s + 1):
            if (b := r_blocks.get((j, s))) is not None:
                D[j] = b[0].ravel()
            if (b := u_blocks.get((j, s))) is not None:
                D[j] -= b[0].ravel()
        out[s] = (force @ D).reshape(td.n_gages, td.n_s)
    return out


@dataclass
class Bands:
    """Frequency bands of the map: ``low`` below the first compared mode, then one band around
    each mode. ``edges_hz`` (n_bands + 1,), ``labels``, ``center_hz`` (n_bands,)."""

    edges_hz: np.ndarray
    labels: list[str]
    center_hz: np.ndarray


def bands_for(f_modes: np.ndarray, top_hz: float) -> Bands:
    f = np.sort(np.asarray([x for x in f_modes if 0 < x < top_hz]))
    edges = [0.0, f[0] / 1.5] + [math.sqrt(a * b) for a, b in zip(f[:-1], f[1:], strict=True)] + [top_hz]
    labels = ["low"] + [f"{x:.1f} Hz" for x in f]
    center = np.concatenate([[f[0] / 3], f])
    return Bands(np.array(edges), labels, center)


def cell_energies(fw: Forward, resid: np.ndarray, bands: Bands) -> np.ndarray:
    """Whitened residual energy per segment x gage x band x window,
    (..., n_seg, n_g, n_bands, 3); ``resid`` may carry leading replicate axes (read one
    replicate at a time: the spectra of all at once were 3x the replicates' own memory)."""
    if resid.ndim > 3:
        return np.stack([cell_energies(fw, r, bands) for r in resid])
    td = fw.td
    out = []
    for name in WINDOWS:
        sl = getattr(td.windows, name)
        r = np.nan_to_num(resid[..., sl]) * fw.W[..., sl]
        n = r.shape[-1]
        P = np.abs(np.fft.rfft(r, axis=-1)) ** 2 / n
        P[..., 1: (n + 1) // 2] *= 2
        f = np.fft.rfftfreq(n, 1 / td.fs_hz)
        idx = np.clip(np.searchsorted(bands.edges_hz, f, side="right") - 1, 0, len(bands.labels) - 1)
        E = np.stack([P[..., idx == b].sum(axis=-1) for b in range(len(bands.labels))], axis=-1)
        out.append(E)
    return np.stack(out, axis=-1)


def _band_bins(fw: Forward, bands: Bands) -> np.ndarray:
    """Expected whitened energy of unit white noise per band x window for one segment: the
    spectral bins each band holds (one-sided, so interior bins count twice), (n_bands, 3)."""
    out = np.zeros((len(bands.labels), len(WINDOWS)))
    for w, name in enumerate(WINDOWS):
        sl = getattr(fw.td.windows, name)
        n = len(range(*sl.indices(fw.td.n_s)))
        f = np.fft.rfftfreq(n, 1 / fw.td.fs_hz)
        wt = np.full(len(f), 2.0)
        wt[0] = 1.0
        if n % 2 == 0:
            wt[-1] = 1.0
        idx = np.clip(np.searchsorted(bands.edges_hz, f, side="right") - 1, 0, len(bands.labels) - 1)
        out[:, w] = np.bincount(idx, weights=wt, minlength=len(bands.labels))
    return out


def cell_inflation(fw: Forward, rep_cells: np.ndarray, bands: Bands, segments: np.ndarray) -> np.ndarray:
    """Per gage x band x window, how much more energy the replicates of the calibrated model
    carry than white noise would (>= 1): coloured noise and the model-form tolerance, where
    they are. (n_gages, n_bands, 3)."""
    seg = np.flatnonzero(np.asarray(segments)) if np.asarray(segments).dtype == bool else segments
    mean = rep_cells[:, seg].sum(axis=1).mean(axis=0)
    white = len(seg) * _band_bins(fw, bands)[None, :, :]
    # a band narrower than a short window's bin spacing holds no bin there: nothing to inflate
    return np.maximum(1.0, np.divide(mean, white, out=np.ones_like(mean), where=white > 0))


def window_inflation(fw: Forward, rep_cells: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Per gage x window, the replicates' energy against white noise's (>= 1), all bands
    together, (n_gages, 3): how much the model's form tolerance and coloured noise add to each
    gage's noise there -- a big-signal gage's form error dwarfs its noise."""
    seg = np.flatnonzero(np.asarray(segments)) if np.asarray(segments).dtype == bool else segments
    mean = rep_cells[:, seg].sum(axis=(1, 3)).mean(axis=0)
    n = np.array([len(range(*getattr(fw.td.windows, w).indices(fw.td.n_s))) for w in WINDOWS])
    return np.maximum(1.0, mean / (len(seg) * n[None, :]))


def form_weights(fw: Forward, inflation: np.ndarray) -> np.ndarray:
    """``fw.W`` with each gage x window deflated by ``sqrt(inflation)`` (n_gages, 3), so a fit
    weighs every gage by what it can tell beyond the model's known form error."""
    W = fw.W.copy()
    for w, name in enumerate(WINDOWS):
        W[:, :, getattr(fw.td.windows, name)] /= np.sqrt(inflation[:, w])[None, :, None]
    return W


def cell_chi2(fw: Forward, resid: np.ndarray, bands: Bands, segments: np.ndarray,
              inflation: np.ndarray) -> float:
    """A residual's whitened energy over ``segments``, each map cell deflated by its
    ``inflation`` (:func:`cell_inflation`): a chi-square that charges the model for what it
    misses beyond its known form error, cell by cell."""
    return float(np.sum(cell_energies(fw, resid, bands)[segments].sum(axis=0) / inflation))


@dataclass
class GapMap:
    """Standardised discrepancy ``z`` (n_gages, n_bands, 3 windows) of a set of segments, with
    the observed and expected energies (whitened units) it came from."""

    z: np.ndarray
    observed: np.ndarray
    expected: np.ndarray
    spread: np.ndarray
    bands: Bands
    gage_numbers: tuple[int, ...]

    def gap_cells(self, z_min: float = GAP_CELL_Z) -> np.ndarray:
        """Cells where the gap is beyond chance (z > ``z_min``), bool (n_gages, n_bands, 3)."""
        return self.z > z_min

    def excess(self, cells: np.ndarray | None = None) -> float:
        """The gap: energy beyond the noise expectation (whitened units: noise variances) summed
        over ``cells`` (default: this map's own :meth:`gap_cells`)."""
        return float(np.sum(self.excess_by_gage(cells)))

    def excess_by_gage(self, cells: np.ndarray | None = None) -> np.ndarray:
        cells = self.gap_cells() if cells is None else cells
        return np.where(cells, np.maximum(self.observed - self.expected, 0), 0).sum(axis=(1, 2))

    def to_json(self) -> dict:
        return {"gages": list(self.gage_numbers), "bands": self.bands.labels,
                "band_edges_hz": [round(float(e), 3) for e in self.bands.edges_hz],
                "windows": list(WINDOWS), "z": np.round(self.z, 2).tolist()}


def gap_map(fw: Forward, resid: np.ndarray, rep_cells: np.ndarray, bands: Bands,
            segments: np.ndarray) -> GapMap:
    """The map of ``segments`` (bool or index) given the replicates' cells."""
    obs = cell_energies(fw, resid, bands)[segments].sum(axis=0)
    rep = rep_cells[:, segments].sum(axis=1)
    mean, sd = rep.mean(axis=0), rep.std(axis=0, ddof=1)
    sd = np.maximum(sd, 1e-9 + 0.05 * mean)
    return GapMap(energy_z(obs, mean, sd), obs, mean, sd, bands, fw.td.gage_numbers)


def energy_z(obs: np.ndarray, mean: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """Normal score of an energy against a scaled chi-square of the replicates' mean and spread
    (``k = 2 mean^2 / sd^2`` degrees of freedom): a cell of few bins is skewed, and a plain
    ``(E - mean) / sd`` would call its upper tail a gap."""
    k = np.maximum(2 * mean**2 / sd**2, 0.5)
    a = mean / k
    # a cell with no spectral bin (a band narrower than a short window's bin spacing) expects
    # and holds nothing: it says nothing either way, z = 0
    p = scipy.stats.chi2.sf(np.divide(obs, a, out=np.zeros_like(obs), where=a > 0), k)
    return np.where(a > 0, scipy.stats.norm.isf(np.clip(p, 1e-300, 1.0)), 0.0)


@dataclass
class Signature:
    """How strongly the residual carries an effect's signature: the best placement, its
    statistic ``chi2`` (deflated for coloured noise), dof ``k``, the equivalent normal score
    ``z`` after charging for the number of placements tried, and the start parameters the
    projection suggests."""

    effect: Effect
    placement: Placement | None
    chi2: float
    k: int
    z: float
    x0: np.ndarray
    n_placements: int


def chi2_logsf(x: float, k: int) -> float:
    """``ln P(chi2_k > x)`` without underflow: scipy's where it is finite, else the
    Wilson-Hilferty normal approximation, whose log tail is finite for any x."""
    v = float(scipy.stats.chi2.logsf(x, k))
    if np.isfinite(v):
        return v
    c = 2.0 / (9.0 * k)
    z = ((x / k) ** (1.0 / 3.0) - (1.0 - c)) / math.sqrt(c)
    return float(scipy.stats.norm.logsf(z))


WHITE_COPY_BYTES = 32 << 20
"""Replicates at most this large (a 6-impact trial's; 86 MB at 20 impacts) are kept whitened
once scored: a second copy of them costs no more than the search's own peak, and re-whitening
them was a fifth of the signature scores' time."""


class ScoreBasis:
    """The calibration's own directions in the fitted segments' whitened sample space, to be
    projected out of every signature; and the replicates' residuals in the same space.

    The directions are the design ``B`` (N, k): every impact's unit response and its derivative
    (alive only in the segments its blow still rings in), the terms' own columns, and the
    calibration's Jacobian (dense, but held by the calibration anyway). ``B`` is kept block by
    block -- per fitted segment only the columns alive there -- and the projection is
    ``D - B G^-1 B^T D`` with ``G = B^T B`` (k, k) accumulated segment by segment, applied twice
    (the second pass removes what the first left through rounding: the same projection as an
    orthonormal basis's to ~1e-12). No dense (N, k) basis, which grew with the impacts squared.
    The replicates are whitened segment by segment when scored; when they are small
    (:data:`WHITE_COPY_BYTES`) the whitened segments are kept after the first score, the same
    numbers, instead of being made again for each of the ~50 signatures.
    """

    def __init__(self, fw: Forward, cal: Calibration, reps: np.ndarray) -> None:
        self.fw = fw
        self.fitted = np.flatnonzero(fw.td.fitted)
        self.W = fw.W[self.fitted]                 # the weights now (a later reweighting aside)
        self.L = fw.td.n_gages * fw.td.n_s         # rows per fitted segment
        if cal.jac is None:
            raise ValueError("score basis: the calibration's Jacobian was let go (drop_jacobian)")
        self.jac = cal.jac                         # (N, p): the calibration's own, not copied
        self.blocks, self.n_lin = _design_blocks(fw, cal, self.fitted)
        self._ginv = _gram_inverse(self._gram())
        self.r = self._white(cal.fit.resid[self.fitted])
        self.reps = reps                           # (n_rep, n_seg, n_g, n_s), not whitened
        self._reps_w: list[np.ndarray] | None = None   # the whitened segments, when kept

    def _white(self, resid: np.ndarray) -> np.ndarray:
        return np.nan_to_num(resid * self.W).ravel()

    def _rows(self, i: int) -> slice:
        return slice(i * self.L, (i + 1) * self.L)

    def _gram(self) -> np.ndarray:
        """``B^T B`` (k, k), segment by segment."""
        n, p = self.n_lin, self.jac.shape[1]
        G = np.zeros((n + p, n + p))
        for i, (idx, X) in enumerate(self.blocks):
            G[np.ix_(idx, idx)] += X @ X.T
            C = X @ self.jac[self._rows(i)]
            G[idx, n:] += C
            G[n:, idx] += C.T
        G[n:, n:] = self.jac.T @ self.jac
        return G

    def _project_once(self, D: np.ndarray) -> np.ndarray:
        n = self.n_lin
        C = np.zeros((n + self.jac.shape[1], D.shape[0]))     # B^T D^T
        for i, (idx, X) in enumerate(self.blocks):
            C[idx] += X @ D[:, self._rows(i)].T
        C[n:] = self.jac.T @ D.T
        Y = self._ginv(C)
        out = D - (self.jac @ Y[n:]).T
        for i, (idx, X) in enumerate(self.blocks):
            out[:, self._rows(i)] -= Y[idx].T @ X
        return out

    def _white_reps(self, i: int) -> np.ndarray:
        """The replicates of fitted segment ``i`` whitened, (n_rep, n_g * n_s)."""
        if self._reps_w is not None:
            return self._reps_w[i]
        return np.nan_to_num(self.reps[:, self.fitted[i]] * self.W[i]).reshape(len(self.reps), -1)

    def reps_dot(self, Dp: np.ndarray) -> np.ndarray:
        """The whitened replicates' products with templates ``Dp`` (k, N), (n_rep, k)."""
        if self._reps_w is None and self.reps.nbytes <= WHITE_COPY_BYTES:
            self._reps_w = [self._white_reps(i) for i in range(len(self.fitted))]
        out = np.zeros((len(self.reps), Dp.shape[0]))
        for i in range(len(self.fitted)):
            out += self._white_reps(i) @ Dp[:, self._rows(i)].T
        return out

    def null_inflation(self, d: np.ndarray) -> float:
        """How much more the replicates' residuals carry along the direction ``d`` (N,) than
        white noise of unit variance would (>= 1): the factor a chi-square gain along ``d`` is
        deflated by, for coloured noise and the model-form tolerance."""
        dp = self.project(d[None, :])
        nrm = float(dp[0] @ dp[0])
        if not np.isfinite(nrm) or nrm <= 0:
            return 1.0
        return max(1.0, float(np.mean(self.reps_dot(dp)[:, 0] ** 2)) / nrm)

    def project(self, D: np.ndarray) -> np.ndarray:
        """Templates (k, N) with the calibration's directions removed."""
        D = np.asarray(D, dtype=float)
        return self._project_once(self._project_once(D))

    def score(self, D: np.ndarray) -> tuple[float, float, np.ndarray]:
        """(chi2 of the residual on span(D), its replicates' mean, coefficients)."""
        Dp = self.project(D)
        G = Dp @ Dp.T
        if not np.all(np.isfinite(G)) or np.trace(G) <= 0:
            return 0.0, 1.0, np.zeros(D.shape[0])
        Gi = np.linalg.pinv(G, rcond=1e-10)
        b = Dp @ self.r
        chi2 = float(b @ Gi @ b)
        br = self.reps_dot(Dp)
        chi2_rep = np.einsum("ri,ij,rj->r", br, Gi, br)
        return chi2, float(np.mean(chi2_rep)), Gi @ b


def _design_blocks(fw: Forward, cal: Calibration, fitted: np.ndarray
                   ) -> tuple[list[tuple[np.ndarray, np.ndarray]], int]:
    """The calibration's linear columns (:meth:`Forward.design`'s order) in the fitted segments'
    whitened sample space, block by block: per fitted segment the indices of the columns alive
    there and their rows (a, n_g * n_s); and the number of linear columns. A column alive in no
    fitted segment (a held-out blow rung out before the next) is no direction at all."""
    units = cal.blocks(fw)      # the blocks a pulse writes, each let go as it is taken
    if units is None:
        U, dU, extra = cal.columns(fw)
        columns = lambda s: fw.alive_columns(U, dU, extra, s)             # noqa: E731
    else:
        extra = fw.columns(cal.terms)
        columns = lambda s: fw.segment_columns(units, extra, s, consume=True)   # noqa: E731
    blocks = []
    for s in fitted:
        idx, X = columns(s)
        X *= (fw.mask[s] * fw.W[s]).ravel()[None, :]
        blocks.append((np.asarray(idx, dtype=int), X))
    n_lin = 2 * fw.td.n_seg + (0 if extra is None else extra.shape[0])
    return blocks, n_lin


def _gram_inverse(G: np.ndarray):
    """``C -> G^-1 C`` for a Gram matrix (k, k): Cholesky of its unit-diagonal scaling over the
    columns that are not zero, a pseudo-inverse if that fails (dependent columns)."""
    d = np.diag(G).copy()
    on = d > 0
    s = np.sqrt(d[on])
    Gs = G[np.ix_(on, on)] / s[:, None] / s[None, :]
    try:
        cf = scipy.linalg.cho_factor(Gs, check_finite=False)
        inv = lambda C: scipy.linalg.cho_solve(cf, C, check_finite=False)   # noqa: E731
    except np.linalg.LinAlgError:
        P = np.linalg.pinv(Gs, rcond=1e-13, hermitian=True)
        inv = lambda C: P @ C   # noqa: E731

    def solve(C: np.ndarray) -> np.ndarray:
        Y = np.zeros_like(C)
        Y[on] = inv(C[on] / s[:, None]) / s[:, None]
        return Y
    return solve


def template(fw: Forward, cal: Calibration, term: Term) -> np.ndarray:
    """The signature of one probe: prediction with the term less the calibrated one, whitened,
    over the fitted segments, flattened."""
    return whiten_fitted(fw, fw.fit(cal.theta, list(cal.terms) + [term]).pred - cal.fit.pred)


def signature_scores(fw: Forward, cal: Calibration, basis: ScoreBasis, effect: Effect) -> Signature:
    """The effect's best placement and its score (see module docstring)."""
    direct = effect.direct_score(fw, cal)
    if direct is not None:
        return Signature(effect, direct[1], 0.0, 0, direct[0], direct[1].x0 if direct[1] else np.zeros(0), 1)
    places = effect.placements(fw, cal.fit)
    best = Signature(effect, None, 0.0, 1, -np.inf, np.zeros(0), len(places))
    best_p = 0.0
    for pl in places:
        try:
            D = effect.templates(fw, cal, pl)
            if D is None:
                D = np.stack([template(fw, cal, Term(effect, pl, probe)) for probe in pl.probes])
        except (ValueError, np.linalg.LinAlgError):   # a probe the model cannot take (overdamped)
            continue
        chi2, chi2_rep, coef = basis.score(D)
        k = D.shape[0]
        kappa = max(chi2_rep / k, 1.0)   # coloured noise carries more along some signatures
        p = chi2_logsf(chi2 / kappa, k)
        if p < best_p or best.placement is None:
            # the placement's x0 is the effect switched off; the probes are steps from it
            x0 = pl.x0 + (coef @ (pl.probes - pl.x0[None, :]) if len(coef) == len(pl.probes) else 0)
            x0 = np.clip(x0, pl.lo, pl.hi)
            best = Signature(effect, pl, chi2 / kappa, k, 0.0, x0, len(places))
            best_p = p
    if best.placement is None:
        return best
    log_p_any = min(0.0, best_p + math.log(max(1, len(places))))      # Bonferroni over placements
    best.z = float(-scipy.special.ndtri_exp(log_p_any)) if log_p_any < 0 else -np.inf
    return best
