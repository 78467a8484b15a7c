"""Parametric identification of damped modes on a multi-channel free decay.

:func:`identify_modes` takes a free decay ``x`` of shape (n_channels, n_samples) or (n_samples,),
t = 0 at its first sample, one unit per channel (m/s^2 in ramdaq), and returns a
:class:`~ramdaq.analysis.modal.table.ModeTable`: per mode the damped frequency (Hz), logarithmic
decrement δ and damping ratio ζ with standard errors; per channel the complex amplitude (in the
channel's unit; phase in rad; normalised mode shape) and a per-channel δ and f.

Estimator: a least-squares Matrix Pencil start (:mod:`~ramdaq.analysis.modal.subspace`) refined
by variable-projection nonlinear least squares (:mod:`~ramdaq.analysis.modal.varpro`). The
subspace estimates alone spread well beyond the Cramér–Rao bound on close modes; refined, every
start (``method`` ``"mp"``, ``"esprit"``, ``"era"``) reaches the same optimum near the bound, so
the cheapest starts it. The NLS is maximum likelihood for white Gaussian noise, so its Jacobian
covariance is also the standard error. The measurements behind this choice: ``docs/estimators.md``.

Pipeline
--------
1. Constant (dead) channels are left out. Noise per channel: median of the Hann periodogram.
2. Analysis band: highest frequency whose channel-summed whitened spectrum is significant
   (Bonferroni over bins at ``false_alarm``), against the noise's own level where it is
   coloured (a converter's roll-off; :func:`~ramdaq.analysis.modal.signal.significant_band_hz`);
   none and ``n_modes=None`` → no modes.
3. Records over ``max_samples`` (channels × samples) are FIR-decimated, keeping only outputs whose
   filter window lies inside the record (no edge transient; amplitudes are corrected by the
   filter's complex gain at each pole, standard errors by the noise-density ratio): by the
   least factor that brings them within it, or (``band_decimation``, a final's) by the whole
   factor the band allows.
4. Start: the data are decimated to ~4× the band, cropped to 2000 samples, whitened, compressed to
   at most 8 principal channels, and the Matrix Pencil is run with a generous order. Poles with
   |ζ| ≤ ``zeta_max`` inside the band become candidates, ranked by whitened energy.
5. Order selection (``n_modes=None``, :mod:`~ramdaq.analysis.modal.order`): forward selection,
   strongest candidate first, stopping after four rejections in a row. A candidate is accepted
   when the likelihood ratio Λ = Σ_c (RSS_c,without − RSS_c,with) / σ̂²_c of the refitted model
   exceeds the χ²(2·n_channels) quantile at ``false_alarm`` / (2·n_samples) — a Bonferroni
   correction for the search over frequency and damping cells, so a record yields a spurious
   mode with probability about ``false_alarm``; where the noise is denser in the band than on
   average (an anti-alias or decimation filter's roll-off: Λ divides by the whole-band
   variance) the threshold is raised by that ratio (``info["noise_colour"]``). A second round
   takes candidates from the residual (weak modes hidden by strong ones), and accepted modes
   whose Λ falls below the threshold are removed again. With ``n_modes`` given, the strongest
   n candidates are fitted as they are (when they do not fit together, the order is selected
   up to n; fewer modes than asked are said in ``info["fewer_modes"]``). Then the trend: a
   slow drift (a DC step, a swell, a sensor's recovery) left in the residual hides weak modes
   and inflates every standard error, so Legendre trend columns beyond the constant are tried one or two at a
   time with the same likelihood-ratio test (χ²(step · n_channels) at ``false_alarm``), the
   modes' poles held; if any are taken, the selection is run again with them in the
   model (``info["trend_terms"]``). Without a drift the test keeps the constant alone and the
   result is as without it. On records over ``search_max_samples`` (channels × samples), or
   whose channels hold over 8192 samples, all of this step runs on a copy decimated within the
   band (its many trial fits then touch a third or less of the samples), and the modes it
   selects are refitted on the NLS data themselves (``info["search_decimation"]``): the
   estimates are the whole record's. (Not for one channel with ``n_modes`` given: its one fit
   runs on the data themselves.)
6. Per-channel fits (``per_channel=True``): each channel alone, with the modes significant in it,
   started at the joint poles and converged to ~0.02 of their standard errors
   (``_CHANNEL_SE_TOL``), not to rounding.
7. Terms with less than one cycle in the record (drift, a slow step) are kept in the model but
   not reported (``info["nuisance_terms_hz"]``).

Threads
-------
A live trial fits in an analyzer thread while the main thread reads the device, and its numbers
must equal those of a replay to the last bit. The estimators therefore keep no state between
calls (the only caches, of window functions and of the peak method's band-pass filters, hold
read-only arrays), leave every buffer they allocate fully written before it is read, and
change nothing process-wide: results depend on
the inputs and on the process's BLAS thread count alone, not on the calling thread, on
concurrent calls, or on call order (``tests/test_modal_id.py`` checks all three).

The BLAS thread count is not set here: set it once for the process, before NumPy is imported
(``OPENBLAS_NUM_THREADS=1``, as the ``ramdaq`` command does). A limit set around each call is
process-wide under OpenBLAS and would change the count under other threads' calls; one thread
is also the faster for the thousands of small BLAS calls a fit makes. Live trial and replay
must run with the same setting to give identical digits (``docs/estimators.md``, "Threads").
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg
from scipy.special import chdtri  # χ² isf, as scipy.stats.chi2.isf (stats costs ~1.5 s to import)

from .crb import damping_ratio_from_decrement
from .order import FINAL_SE_TOL, ModeSelector, floor_noise
from .signal import (
    band_lengths,
    decimate_valid,
    decimated_index,
    estimate_noise_std,
    fir_gain,
    fir_noise_variance_factor,
    kaiser_periodogram,
    noise_colour,
    noise_std_from_periodogram,
    significant_band,
    significant_bands_alone,
)
from .subspace import (
    default_pencil_length,
    era_poles,
    esprit_poles,
    matrix_pencil_poles,
    poles_to_modes,
)
from .table import ModeTable
from .varpro import (
    Projector,
    damped_basis,
    fit_channels_varpro,
    linear_amplitudes,
    uniform_grid,
)

__all__ = ["ModeTable", "channel_periodograms", "identify_modes", "peak_above_noise"]

_STARTS = {"mp": matrix_pencil_poles, "esprit": esprit_poles, "era": era_poles}
# Per-channel fits (step 6) stop where the Gauss–Newton step promises to lower Σr² by < 3·10⁻⁴ of
# the residual variance s²: f and δ are then within ~0.02 of their standard errors of the
# converged values (Δθᵀ Cov⁻¹ Δθ = ΔΣr²/s²; measured on the ALBACORE hits, 6 and 14 s, 150
# channel fits: the remaining ΔΣr² at that stop at most 6·10⁻⁴ s², 0.025 standard errors; a
# spread 1.0003x the converged one's). From the joint poles these fits converge only linearly
# (~4x a step: the noise's curvature, which Gauss–Newton does not see); to rounding they took
# 5–11 evaluations, whose last 2–4 moved θ by 10⁻² to 10⁻⁵ SE; now 3.8 on average (the first shared).
_CHANNEL_SE_TOL = 3e-4
_SUBSPACE_MAX_SAMPLES = 2000
# The residual round's pencil (step 5) is at most 100 long, not 400: with the strong modes taken
# out, a weak one hidden by them stands alone in the residual and needs no fine resolution (the
# held-pole NLS refines whatever start it gets). The cost is the pencil's eigendecomposition,
# O(L³): 9 ms a call at L = 400 (a 16-gage record with its band at 270 Hz, 2000 samples), ~0.3 ms
# at 100. Records whose band decimates them below 300 subspace samples (all of the accuracy
# benchmark's) have L < 100 already. Its coarser starts reach noise optima that the longer
# pencil's did not offer: safe only with the threshold raised for coloured noise (_Data): with
# the white threshold it took the stern plane's stacked decays to a 382 Hz pole growing by e^50
# (Λ 151 against 148), which lost their 20 Hz mode (tests/test_free_modes_stern_plane.py).
_RESIDUAL_PENCIL = 100
# The first round's pencil is at most 200 long (it was 400): its eigendecomposition is O(L³),
# ~3.7x cheaper at 200 on a 16-gage hit whose 270 Hz band leaves 2000 subspace samples (~8 ms
# of a 14 s hit's analysis). The NLS refines whatever start it gets: on a 600 s, 20-blow
# ALBACORE replay every hit selected the same modes as at 400, its numbers equal to ~1e-10 of
# their standard errors. Records whose band leaves under 600 subspace samples (all of the
# accuracy benchmark's) had L < 200 already.
_PENCIL = 200
# A channel longer than 8192 samples is searched on a copy decimated within the band to about
# 4096 samples, whatever the number of channels (one gage's record of 6 s at 2048 Hz: by 3).
_SEARCH_MAX_LENGTH, _SEARCH_LENGTH = 8192, 4096
# A search copy of several channels still over 1.5 x search_max_samples where the band allows no
# more decimation (16 gages x 14 s at 270 Hz: 16 x 9557) is cropped to the larger of 4096 and
# search_max_samples / channels samples (the decay's tail, its weakest part, left out of the
# search; the modes found are refitted on the whole NLS data).
_SEARCH_CROP = 1.5
_MAX_PRINCIPAL_CHANNELS = 8
# The linear screen's level: noise at a fixed pole exceeds it with this probability (_Data.screen).
_SCREEN_FALSE_ALARM = 1e-3


def _candidates(
    Y: np.ndarray, t: np.ndarray, fs: float, band_hi: float, order: int, method: str,
    zeta_max: float, f_lo: float, max_length: int = _PENCIL,
) -> tuple[np.ndarray, np.ndarray]:
    """Candidate (f, δ) from the subspace start on decimated, whitened, compressed data (pencil
    length at most ``max_length``)."""
    d_sub = max(1, int(fs // (4.0 * band_hi)))
    if d_sub > 1 and Y.shape[-1] // d_sub > 3 * order + 30:
        Ys, _, _ = decimate_valid(Y, fs, d_sub, band_hi)
    else:
        Ys, d_sub = Y, 1
    fs_sub = fs / d_sub
    Ys = Ys[:, :_SUBSPACE_MAX_SAMPLES]
    n = Ys.shape[-1]
    if n < 24:
        return np.empty(0), np.empty(0)
    Ys = Ys / floor_noise(estimate_noise_std(Ys), Ys)[:, None]
    U, S, _ = linalg.svd(Ys, full_matrices=False)
    thr = 2.0 * (np.sqrt(n) + np.sqrt(Ys.shape[0])) ** 2
    r = int(np.clip(np.count_nonzero(S**2 > thr), 1, _MAX_PRINCIPAL_CHANNELS))
    Yc = U[:, :r].T @ Ys
    L = default_pencil_length(n, max_length)
    order = int(min(order, L - 2))
    if method == "era":  # block rows: as its default, for a pencil of L
        z = era_poles(Yc, order, max(-(-(order + 2) // Yc.shape[0]) + 1, L // Yc.shape[0]))
    else:
        z = _STARTS[method](Yc, order, L)
    f, d = poles_to_modes(z, fs_sub)
    zeta = damping_ratio_from_decrement(d)
    ok = (f >= f_lo) & (f <= min(band_hi, 0.45 * fs_sub)) & (np.abs(zeta) <= zeta_max)
    return f[ok], d[ok]


def _rank(
    Y: np.ndarray, t: np.ndarray, w: np.ndarray, f: np.ndarray, d: np.ndarray, fit_offset: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Candidates sorted by whitened energy, strongest first."""
    if f.size == 0:
        return f, d
    B = Projector(damped_basis(t, f, d, fit_offset, uniform_grid(t))).coef((Y * w[:, None]).T)
    amp2 = B[0 : 2 * f.size : 2] ** 2 + B[1 : 2 * f.size : 2] ** 2  # |a|² (linear_amplitudes)
    env2 = _sum_exp(t, -2.0 * d * f)
    energy = np.sum(amp2, axis=1) * env2 / 2.0
    o = np.argsort(energy)[::-1]
    return f[o], d[o]


def identify_modes(
    x: ArrayLike,
    fs_hz: float,
    *,
    n_modes: int | None = None,
    f_range_hz: tuple[float, float] | None = None,
    method: str = "mp",
    zeta_max: float = 0.3,
    false_alarm: float = 1e-4,
    per_channel: bool = True,
    fit_offset: bool = True,
    max_modes: int = 12,
    max_samples: int = 400_000,
    max_trend_terms: int = 16,
    start: tuple[ArrayLike, ArrayLike] | None = None,
    search_max_samples: int = 60_000,
    periodograms: dict[int, np.ndarray] | None = None,
    noise_std: np.ndarray | None = None,
    band_decimation: bool = False,
) -> ModeTable:
    """Identify damped modes shared by all channels of a free decay.

    Parameters
    ----------
    x : array_like, shape (n_channels, n_samples) or (n_samples,)
        Free decay starting at the start of the decay (t = 0 at x[..., 0]); one unit per channel.
    fs_hz : float
        Sample rate (Hz).
    n_modes : int, optional
        Number of modes to fit; None selects the order by the likelihood-ratio test. When the n
        strongest candidates do not fit together, the order is selected up to n; a table with
        fewer modes than asked says so in ``info["fewer_modes"]``.
    f_range_hz : (float, float), optional
        Report only modes in [lo, hi] Hz. Modes outside are still modelled when present; for
        records that must be decimated the band is limited to 1.25·hi.
    method : {"mp", "esprit", "era"}
        Subspace start (see module docstring; all reach the same NLS optimum).
    zeta_max : float
        Largest |ζ| accepted as a mode.
    false_alarm : float
        Probability of a spurious mode in pure noise (order selection).
    per_channel : bool
        Also fit each channel on its own (``channel_delta`` etc.).
    fit_offset : bool
        Fit a constant offset per channel and, where the likelihood-ratio test asks for it, a
        slow drift: Legendre trend columns up to ``max_trend_terms`` (``info["trend_terms"]``;
        module docstring, step 5).
    max_modes : int
        Largest number of modes the selection may accept.
    max_samples : int
        Channels × samples above which the record is decimated (memory, time).
    search_max_samples : int
        Channels × samples above which (or above 8192 samples a channel) the order is searched
        on a copy decimated within the band (where the band allows a factor of 2 or more;
        ``info["search_decimation"]``), the modes it finds refitted on the record itself: the
        estimates and their standard errors are those of the whole record, the search's trial
        fits touch a fraction of it.
    start : (f_hz, delta), optional
        Candidate poles to start from instead of the subspace estimate (step 4), e.g. the modes
        another fit found on channels of the same decay (a combination of them has the same
        poles): ranked and selected as the subspace's would be; candidates from the residual
        (step 5's second round) still come from the subspace.
    periodograms : dict, optional
        The channels' Kaiser periodograms of step 2 where the caller has them already
        (:func:`channel_periodograms` of ``x``): not computed again.
    noise_std : numpy.ndarray, shape (n_channels,), optional
        With ``periodograms``: ``noise_std_from_periodogram`` of their whole-record one, where
        the caller has it (the verdicts' screen): not computed again (equal to the bit).
    band_decimation : bool
        A record over ``max_samples`` decimated by the whole factor its band allows, not just
        as far as brings it within ``max_samples`` (a final's 16 gages x 14 s at 2048 Hz with
        a 270 Hz band: by 3, not 2, so every fit on the NLS data touches a third fewer
        samples; the FIR keeps the band and its noise, the estimates' accuracy is unchanged:
        :func:`_nls_data`); the order search then runs on the NLS data themselves, cropped as
        its own decimated copy would be; and the selected modes' final fits stop within ~0.001
        of their standard errors of the optimum instead of converging to rounding
        (:data:`~ramdaq.analysis.modal.order.FINAL_SE_TOL`); and every fit's basis is built by
        a BLAS product (:func:`~ramdaq.analysis.modal.varpro.damped_basis`'s ``by_matmul``: ~2x
        faster, equal to rounding, not to the bit). ``analyze_decay`` (a final) sets it.

    Returns
    -------
    ModeTable
        Modes sorted by frequency; empty when nothing is significant.
    """
    X = _checked(x, fs_hz, n_modes=n_modes, f_range_hz=f_range_hz, method=method)
    n_ch, n = X.shape
    active = np.ptp(X, axis=1) > 0
    Xa = X[active]
    info: dict = {"active_channels": np.flatnonzero(active)}
    if Xa.shape[0] == 0:
        return _empty(n_ch, fs_hz, n, method, info | {"reason": "all channels constant"})
    pg = (channel_periodograms(Xa) if periodograms is None  # the band test's; P0: the noise
          else {m: P[active] for m, P in periodograms.items()})  # estimate's when not decimated
    P0 = pg[n]
    sig0 = (noise_std_from_periodogram(P0) if noise_std is None or periodograms is None
            else np.asarray(noise_std, dtype=float)[active])  # the band test's, and the
    # search's when not decimated
    band = _band(Xa, fs_hz, false_alarm, P0, pg, sig0)
    if band is None and n_modes is None:
        return _empty(n_ch, fs_hz, n, method, info | {"reason": "no spectral peak above noise"})
    band_hi = 0.45 * fs_hz if band is None else min(1.25 * band + 3 * fs_hz / n, 0.45 * fs_hz)

    Y, t, d_nls, taps, band_hi = _nls_data(Xa, fs_hz, band_hi, f_range_hz, max_samples,
                                           band_decimation)
    fs_nls = fs_hz / d_nls
    duration = t[-1] - t[0] + 1.0 / fs_nls
    f_lo = 1.0 / duration
    full = _Data(Y, t, fs_nls, false_alarm, band_hz=(f_lo, band_hi),
                 noise_std=sig0 if Y is Xa else None,
                 periodogram=P0 if Y is Xa else None)
    # The order is searched on a copy decimated within the band when the record is long (the
    # search's many trial fits then touch a fraction of the samples); the modes found are then
    # refitted on the data themselves, so the estimates are those of the full record.
    # (one channel with its order given: one fit, converged at once on the data themselves)
    data = (full if n_modes is not None and Xa.shape[0] == 1
            else _search_data(full, Xa, fs_hz, d_nls, band_hi, search_max_samples,
                              crop_full=band_decimation))
    order = 2 * (max_modes if n_modes is None else n_modes) + 4
    final_se_tol = FINAL_SE_TOL if band_decimation else 0.0
    start_fd = None if start is None else tuple(np.atleast_1d(np.asarray(v, dtype=float))
                                                for v in start)

    def select(trend: bool | int, D: _Data) -> tuple[ModeSelector, int]:
        """The modes selected in ``D`` with ``trend`` columns in the model; and the candidates'
        count."""
        def ranked_candidates(Z: np.ndarray, w: np.ndarray, max_length: int = _PENCIL
                              ) -> tuple[np.ndarray, np.ndarray]:
            """Candidate (f, δ) in ``Z`` (the data or a residual), strongest first by ``w``."""
            f_c, d_c = _candidates(Z, D.t, D.fs, band_hi, order, method, zeta_max, f_lo,
                                   max_length)
            return _rank(Z, D.t, w, f_c, d_c, trend)

        fc, dc = (ranked_candidates(D.Y, D.w0) if start_fd is None
                  else _rank(D.Y, D.t, D.w0, *start_fd, trend))
        sel = ModeSelector(D.Y, D.t, trend, D.threshold, zeta_max, (0.5 * f_lo, 0.49 * D.fs), D.w0,
                           final_se_tol, by_matmul=band_decimation, screen=D.screen)
        # One channel: its weight scales the cost, not the optimum, so the reweighted refit
        # would restart at the point reached; the fit of the n modes is converged at once.
        final = n_modes is not None and D.Y.shape[0] == 1 and D is full
        if n_modes is not None:
            sel.fit = sel.refit(fc[:n_modes], dc[:n_modes], trial=not final) if fc.size else None
            if sel.fit is None and fc.size:  # the n strongest do not fit together: select up to n
                final = False
                info["n_modes_fit"] = (f"the {min(n_modes, fc.size)} strongest candidates did not "
                                       f"fit together; the order was selected (at most {n_modes})")
                _select_order(sel, fc, dc, ranked_candidates, n_modes)
        else:
            _select_order(sel, fc, dc, ranked_candidates, max_modes)
        if final and sel.fit is not None:
            sel.w = 1.0 / floor_noise(sel.fit.noise_std, sel.Y)  # as _reweighted, without a refit
        elif sel.fit is not None and D is full:  # refit with weights from its own residual (on
            _reweighted(sel)  # a decimated copy _refined does it on the data themselves)
        return sel, int(fc.size)

    def search(D: _Data) -> tuple[ModeSelector, int]:
        sel, n_cand = select(fit_offset, D)
        if fit_offset:  # a drift: more trend columns where the likelihood-ratio test asks for them
            trend = _trend_order(sel, false_alarm, max_trend_terms)
            if trend > 1:
                sel, n_cand = select(trend, D)
            info["trend_terms"] = trend
        return sel, n_cand

    sel, n_cand = search(data)
    if data is not full:
        info["search_decimation"] = data.decimation
        if sel.fit is not None:
            refined = _refined(sel, full, zeta_max, f_lo)
            sel, n_cand = (refined, n_cand) if refined is not None else search(full)
    threshold = full.threshold
    info |= {"decimation": d_nls, "band_hz": band_hi, "n_candidates": n_cand,
             "lr_threshold": threshold, "noise_colour": full.colour}
    if sel.fit is None:
        table = _empty(n_ch, fs_hz, n, method, info | {"reason": "no significant mode"})
    else:
        table = _table(sel, X, active, fs_hz, d_nls, taps, f_range_hz, per_channel, method, info)
    if n_modes is not None and len(table) < n_modes:
        table.info["fewer_modes"] = (f"n_modes={n_modes} asked, {len(table)} found "
                                     f"({n_cand} candidate(s) in the band)")
    return table


@dataclass
class _Data:
    """What the order search runs on: data (n_channels, n_samples), times (s), rate (Hz), the
    starting weights 1/σ and the likelihood-ratio threshold for its size; ``decimation``
    relative to the record (that of the NLS data when they are the record itself).

    The threshold is χ²(2 n_channels) at ``false_alarm`` / (2 n_samples) in units of the
    in-band noise variance; Λ divides by each channel's whole-band residual variance, so the
    threshold is raised by the noise's in-band density over its mean (``colour``,
    :func:`~ramdaq.analysis.modal.signal.noise_colour` over ``band_hz``, (lo, hi) Hz; 1 for
    white noise). Without it a converter's anti-alias roll-off (1.28 on the stern plane's
    simulated record) let the search accept noise: a pole at 382 Hz growing by e^50 over the
    window, at Λ 151 against 148, whose basis column then hid the 20 Hz mode from the gap's
    free modal model."""

    Y: np.ndarray
    t: np.ndarray
    fs: float
    false_alarm: float
    decimation: int = 1
    band_hz: tuple[float, float] = (0.0, np.inf)
    noise_std: np.ndarray | None = None  # of Y's rows when known (= estimate_noise_std(Y))
    periodogram: np.ndarray | None = None  # of Y's rows when known (= kaiser_periodogram(Y))

    def __post_init__(self) -> None:
        P = kaiser_periodogram(self.Y) if self.periodogram is None else self.periodogram
        sig = noise_std_from_periodogram(P) if self.noise_std is None else self.noise_std
        self.w0 = 1.0 / floor_noise(sig, self.Y)
        self.colour = noise_colour(P, self.fs, self.band_hz)
        self.threshold = self.colour * float(chdtri(2 * self.Y.shape[0],
                                                    self.false_alarm / (2.0 * self.Y.shape[-1])))
        # The linear screen (order.ModeSelector.try_add): a candidate whose Λ with its pole held
        # at the start is below this is rejected without a fit. Λ of noise at a fixed pole is
        # χ²(2 n_channels); the old screen, 0.25 x threshold (~25-33 on 16 channels), lay below
        # that distribution's own mean (32), so nearly every noise candidate went on to a held
        # fit (~20 of a 16-gage hit's ~60 ms). The screen is now that χ²'s 10⁻³ upper quantile
        # (62.5 on 16 channels, 13.8 on one; x the colour, as the threshold), or 0.25 x
        # threshold where that is higher. Measured (ord22): no accepted candidate's screen Λ was
        # within 2.3x of it (one channel: 0.92 x threshold, two modes 1 % apart; 16 channels:
        # >= 268 x); every decision and every estimate of hit_cost's and decrement_accuracy's
        # records the same to the bit (only rejections moved from the held fit to the screen).
        self.screen = max(0.25 * self.threshold,
                          self.colour * float(chdtri(2 * self.Y.shape[0], _SCREEN_FALSE_ALARM)))


def _search_data(full: _Data, Xa: np.ndarray, fs_hz: float, d_nls: int, band_hi: float,
                 max_samples: int, crop_full: bool = False) -> _Data:
    """The data the order search runs on: ``full`` (the NLS data, ``Xa`` decimated by ``d_nls``)
    decimated within ``band_hi`` when it holds over ``max_samples`` (channels x samples) or its
    channels over ``_SEARCH_MAX_LENGTH`` samples (then to about ``_SEARCH_LENGTH``), and the
    band allows a total factor of 2 or more above ``d_nls``; else ``full`` itself. Where the
    NLS data are decimated already, the search's copy is decimated from the record ``Xa``
    (rate ``fs_hz``) by the whole factor the band allows, over the same span (a factor of the
    NLS data's would have to be a multiple of ``d_nls``: 2 of 3 allowed, 14 s decays).
    ``crop_full``: where the NLS data are decimated as far as the band allows already
    (``band_decimation``), a several-channel copy over 1.5 x ``max_samples`` is the NLS data
    cropped as a decimated copy would be (:func:`_search_crop`), not the NLS data whole."""
    if full.Y.size <= max_samples and full.Y.shape[1] <= _SEARCH_MAX_LENGTH:
        return full

    def need(Y: np.ndarray) -> int:  # the factor that brings Y within both limits
        n = Y.shape[1]
        return int(np.ceil(max(Y.size / max_samples,
                               n / _SEARCH_LENGTH if n > _SEARCH_MAX_LENGTH else 1.0)))

    d_max = int(fs_hz // (2.5 * band_hi))
    if d_nls == 1:
        d = min(need(full.Y), d_max)
        if d < 2:
            return full
        Ys, idx, _ = decimate_valid(full.Y, full.fs, d, band_hi)
        t = full.t[idx]
    else:
        d = min(need(Xa), d_max)
        if d <= d_nls:
            return _cropped_search(full, d_nls, max_samples) if crop_full else full
        # Outputs within the NLS data's span (they may be cropped). A several-channel copy still
        # over 1.5 x max_samples where the band allows no more decimation (16 gages x 14 s at a
        # 270 Hz band) is cropped to _search_crop samples, its tail (weakest) left out of the
        # search: it is decimated only as far as it is kept (the same outputs to the bit).
        n_out = int(np.count_nonzero(decimated_index(Xa.shape[1], fs_hz, d, band_hi)
                                     <= round(full.t[-1] * fs_hz)))
        if n_out < 256:
            return full
        rows = Xa.shape[0]
        keep = (_search_crop(rows, max_samples)
                if rows > 1 and rows * n_out > _SEARCH_CROP * max_samples else None)
        Ys, idx, _ = decimate_valid(Xa, fs_hz, d, band_hi, max_outputs=keep)
        inside = idx <= round(full.t[-1] * fs_hz)
        return _Data(Ys[:, inside], idx[inside] / fs_hz, fs_hz / d, full.false_alarm, d,
                     full.band_hz)
    if Ys.shape[-1] < 256:
        return full
    if Ys.shape[0] > 1 and Ys.size > _SEARCH_CROP * max_samples:  # as above
        keep = _search_crop(Ys.shape[0], max_samples)
        Ys, t = Ys[:, :keep], t[:keep]
    return _Data(Ys, t, fs_hz / d, full.false_alarm, d, full.band_hz)


def _cropped_search(full: _Data, d_nls: int, max_samples: int) -> _Data:
    """``full`` (the NLS data, decimated by ``d_nls``) as the search's data: cropped to
    :func:`_search_crop` samples where it holds several channels and over ``_SEARCH_CROP`` x
    ``max_samples`` (as a decimated copy is), else itself."""
    if full.Y.shape[0] == 1 or full.Y.size <= _SEARCH_CROP * max_samples:
        return full
    keep = _search_crop(full.Y.shape[0], max_samples)
    return _Data(full.Y[:, :keep], full.t[:keep], full.fs, full.false_alarm, d_nls, full.band_hz)


def _search_crop(n_channels: int, max_samples: int) -> int:
    """How many samples a search copy of ``n_channels`` cropped by ``_SEARCH_CROP`` keeps."""
    return max(_SEARCH_LENGTH, max_samples // n_channels)


def _reweighted(sel: ModeSelector) -> None:
    """``sel``'s fit refitted with weights from its own residual (converged to rounding, or to
    ``sel.final_se_tol``)."""
    sel.w = 1.0 / floor_noise(sel.fit.noise_std, sel.Y)
    sel.fit = sel.refit(sel.fit.f_hz, sel.fit.delta) or sel.fit


def _refined(found: ModeSelector, full: _Data, zeta_max: float, f_lo: float) -> ModeSelector | None:
    """The modes ``found`` by a search on decimated data refitted on ``full`` (same trend
    columns; a trial fit with ``full``'s starting weights, then reweighted and converged as the
    search's own last step); None when they do not fit there."""
    sel = ModeSelector(full.Y, full.t, found.fit_offset, full.threshold, zeta_max,
                       (0.5 * f_lo, 0.49 * full.fs), full.w0, found.final_se_tol, found.by_matmul,
                       full.screen)
    f, d = found.fit.f_hz, found.fit.delta
    if full.Y.shape[0] == 1:  # its weight scales the cost, not the optimum: no reweighting
        sel.fit = sel.refit(f, d)
        if sel.fit is not None:
            sel.w = 1.0 / floor_noise(sel.fit.noise_std, sel.Y)  # as _reweighted, no refit
        return sel if sel.fit is not None else None
    # The weights from the residual at the poles found (linear least squares), not from a trial
    # fit's: the search converged them on the decimated copy, and the few σ² a refit would take
    # off each channel's Σr² move its weight by ~1e-4 relative, the optimum by far less.
    C, N = full.Y.shape
    _, _, rss = linear_amplitudes(full.t, full.Y, f, d, fit_offset=found.fit_offset)
    dof = max(N - 4 * f.size - int(found.fit_offset) - 2 * f.size / C, 1)
    sel.w = 1.0 / floor_noise(np.sqrt(rss / dof), sel.Y)
    sel.fit = sel.refit(f, d)
    return sel if sel.fit is not None else None


def _band(Xa: np.ndarray, fs_hz: float, false_alarm: float,
          P0: np.ndarray | None = None, parts: dict[int, np.ndarray] | None = None,
          sig: np.ndarray | None = None) -> float | None:
    """Step 2 of the module docstring: the highest significant spectral peak of the channels
    ``Xa`` together (Hz), None if none; ``P0``: their Kaiser periodogram if already computed
    (``parts``: those of their first m samples, by m; ``sig``: the noise std from ``P0``)."""
    P0 = kaiser_periodogram(Xa) if P0 is None else P0  # for the noise estimate and the band test
    sig0 = floor_noise(noise_std_from_periodogram(P0) if sig is None else sig, Xa)
    return significant_band(Xa, fs_hz, sig0, false_alarm, P0, parts)


def channel_periodograms(x: np.ndarray) -> dict[int, np.ndarray]:
    """The Kaiser periodograms the band test (step 2) reads, of every row of ``x`` (n_channels,
    n_samples) at once (row by row the same operations as one at a time, equal to the bit, except
    at lengths :func:`~ramdaq.analysis.modal.signal.rfft_rows` packs two rows a transform:
    there equal to rounding, ~3e-15 of the pair's larger norm): of the first m samples, by m
    (:func:`~ramdaq.analysis.modal.signal.band_lengths`; m = n_samples: the whole record's)."""
    return {m: kaiser_periodogram(x[:, :m]) for m in band_lengths(x.shape[1])}


def peak_above_noise(x: ArrayLike, fs_hz: float, *, false_alarm: float = 1e-4,
                     periodograms: dict[int, np.ndarray] | None = None,
                     noise_std: np.ndarray | None = None) -> np.ndarray:
    """Whether each channel alone (rows of ``x``, (n_channels, n_samples)) shows a spectral peak
    above its noise: where not, :func:`identify_modes` on that channel alone (automatic order,
    same ``false_alarm``) finds no mode ("no spectral peak above noise"), by the same test.
    ``periodograms``: :func:`channel_periodograms` of ``x`` where the caller has them;
    ``noise_std``: ``noise_std_from_periodogram`` of their whole-record one, likewise."""
    X = np.atleast_2d(np.asarray(x, dtype=float))
    pg = channel_periodograms(X) if periodograms is None else periodograms
    n = X.shape[1]
    sig = noise_std_from_periodogram(pg[n]) if noise_std is None else noise_std
    return np.isfinite(significant_bands_alone(fs_hz, floor_noise(sig, X), false_alarm, pg, n))


def _checked(x: ArrayLike, fs_hz: float, *, n_modes: int | None,
             f_range_hz: tuple[float, float] | None, method: str) -> np.ndarray:
    """``x`` as (n_channels, n_samples) floats, the arguments of :func:`identify_modes` checked."""
    X = np.atleast_2d(np.asarray(x, dtype=float))
    if X.ndim != 2:
        raise ValueError(f"x must have shape (n_channels, n_samples), got {X.shape}")
    if not np.all(np.isfinite(X)):
        raise ValueError("x contains non-finite samples")
    if method not in _STARTS:
        raise ValueError(f"method ({method!r}) must be one of {sorted(_STARTS)}")
    if fs_hz <= 0:
        raise ValueError(f"fs_hz ({fs_hz}) must be positive")
    if X.shape[1] < 32:
        raise ValueError(f"n_samples ({X.shape[1]}) must be at least 32")
    if n_modes is not None and n_modes < 1:
        raise ValueError(f"n_modes ({n_modes}) must be positive or None")
    if f_range_hz is not None and not 0 <= f_range_hz[0] < f_range_hz[1]:
        raise ValueError(f"f_range_hz ({f_range_hz}) must be (lo, hi) with 0 <= lo < hi")
    return X


def _nls_data(Xa: np.ndarray, fs_hz: float, band_hi: float,
              f_range_hz: tuple[float, float] | None, max_samples: int,
              band_decimation: bool = False
              ) -> tuple[np.ndarray, np.ndarray, int, np.ndarray, float]:
    """The data the NLS fits, (Y, t s, decimation, FIR taps, band_hi Hz): ``Xa`` as it is unless
    it holds over ``max_samples`` (channels x samples), then decimated within the band (limited
    to 1.25 times ``f_range_hz``'s top) and cropped: by as little as brings it within
    ``max_samples``, or with ``band_decimation`` by the whole factor the band allows (the
    minimum-phase FIR from the first sample, :func:`decimate_valid`: in-band content and noise
    kept, amplitudes corrected by its gain at each pole, standard errors by its noise factor;
    30 simulated ALBACORE 14 s water hits, 16 gages, d = 3 against 2: every mode's bias and
    spread within 0.02 SE of before, the decimation noise's colour 1.10 -> 1.02)."""
    d_nls, taps = 1, np.ones(1)
    Y, t = Xa, np.arange(Xa.shape[1]) / fs_hz
    if Xa.size > max_samples:
        if f_range_hz is not None:
            band_hi = min(band_hi, 1.25 * f_range_hz[1])
        d_band = int(fs_hz // (2.5 * band_hi))
        d_nls = max(1, d_band if band_decimation else min(int(np.ceil(Xa.size / max_samples)),
                                                          d_band))
        if d_nls > 1:
            Y, idx, taps = decimate_valid(Xa, fs_hz, d_nls, band_hi, from_first=True)
            t = idx / fs_hz
        n_keep = max(max_samples // Xa.shape[0], 64)
        Y, t = Y[:, :n_keep], t[:n_keep]
    return Y, t, d_nls, taps, band_hi


def _select_order(sel: ModeSelector, fc: np.ndarray, dc: np.ndarray,
                  ranked_candidates: Callable[..., tuple[np.ndarray, np.ndarray]],
                  max_modes: int) -> None:
    """Forward selection on ``sel`` (see the module docstring, step 5): the candidates (fc, dc),
    strongest first, until four in a row are rejected; then up to four candidates from the
    residual (``ranked_candidates(residual, weights, max_length)``, a shorter pencil: see
    ``_RESIDUAL_PENCIL``); then the pruning of modes no longer
    significant. Leaves the selected fit in ``sel.fit`` (None if none)."""
    misses = 0
    for f_c, d_c in zip(fc, dc, strict=True):  # strongest first
        if misses >= 4 or (sel.fit is not None and sel.fit.f_hz.size >= max_modes):
            break
        misses = 0 if sel.try_add(f_c, d_c) else misses + 1
    if sel.fit is not None and sel.fit.f_hz.size < max_modes:  # residual round
        if int(sel.fit_offset) > 1:  # the modes and the whole trend, refitted linearly
            proj = Projector(damped_basis(sel.t, sel.fit.f_hz, sel.fit.delta, sel.fit_offset,
                                          uniform_grid(sel.t)))
            model = (proj.Phi @ proj.coef(sel.Y.T)).T
        else:
            B = sel.fit.amplitude
            model = _synth(sel.t, sel.fit.f_hz, sel.fit.delta, B) + sel.fit.offset[:, None]
        fr, dr = ranked_candidates(sel.Y - model, sel.w, _RESIDUAL_PENCIL)
        for f_c, d_c in zip(fr[:4], dr[:4], strict=True):
            if sel.fit.f_hz.size >= max_modes:
                break
            sel.try_add(f_c, d_c)
    sel.prune()


def _trend_order(sel: ModeSelector, false_alarm: float, max_terms: int) -> int:
    """How many trend columns (Legendre P₀ … ) the model of ``sel``'s modes needs: from the
    current one, one or two more are tried (a drift may be odd or even about the record's
    middle), the modes' poles held (linear least squares: cheap, and Λ with the poles held is
    at most Λ with them refitted, so the test errs towards fewer columns), and the fewest taken
    whose likelihood ratio Λ = Σ_c ΔRSS_c / σ̂²_c exceeds the χ²(step · n_channels) quantile at
    ``false_alarm``; until neither does. The nested fits come from one (:func:`_nested_rss`)."""
    f = sel.fit.f_hz if sel.fit is not None else np.empty(0)
    d = sel.fit.delta if sel.fit is not None else np.empty(0)
    p = int(sel.fit_offset)
    n_ch, n = sel.Y.shape
    while p < max_terms:
        top = min(p + 2, max_terms)
        rss = _nested_rss(sel.t, sel.Y, f, d, p, top)  # rss[j]: with p + j trend columns
        for step in (1, 2):
            if p + step > max_terms:
                return p
            var = rss[step] / max(n - 2 * f.size - p - step, 1)
            lam = float(np.sum((rss[0] - rss[step]) / np.maximum(var, 1e-300)))
            if lam > chdtri(step * n_ch, false_alarm):
                p += step
                break
        else:
            return p
    return p


def _nested_rss(t: np.ndarray, Y: np.ndarray, f: np.ndarray, d: np.ndarray, p: int,
                top: int) -> list[np.ndarray]:
    """RSS per channel of the least-squares fits of the modes (f, δ) with p, p + 1, …, ``top``
    trend columns (a list, entry j for p + j): one fit with ``top`` columns, whose Cholesky
    factor gives the others, RSS_k = RSS_top + Σ_(k ≤ i < top) V_i² (V = L⁻¹ Φᵀy, row i the
    gain of column i over the columns before it: sums of squares, no cancellation); each
    fitted on its own where Φ needs the QR path."""
    proj = Projector(damped_basis(t, f, d, top, uniform_grid(t)))
    if proj.cho is None:
        return [linear_amplitudes(t, Y, f, d, fit_offset=k)[2] for k in range(p, top + 1)]
    PtY = proj.Phi.T @ Y.T
    rss_top = np.sum((Y.T - proj.Phi @ proj.coef_from(PtY)) ** 2, axis=0)
    V2 = proj.whitened(PtY) ** 2  # (2K + top, n_channels)
    k0 = 2 * f.size
    return [rss_top + np.sum(V2[k0 + k : k0 + top], axis=0) for k in range(p, top + 1)]


def _sum_exp(t: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """Σₙ exp(rate_k tₙ) for each k: a geometric series on a uniform grid, else summed."""
    grid = uniform_grid(t)
    if grid is None:
        return np.sum(np.exp(rate[:, None] * t[None, :]), axis=1)
    t0, dt = grid
    x = rate * dt
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        ratio = np.where(x != 0, np.expm1(t.size * x) / np.where(x != 0, np.expm1(x), 1.0),
                         float(t.size))
        return np.exp(rate * t0) * ratio


def _synth(t, f, d, amp):
    """Model Σ_k Re(a_ck exp(s_k t)) per channel (rows of ``amp``), via :func:`damped_basis`."""
    coef = np.empty((amp.shape[0], 2 * f.size))
    coef[:, 0::2], coef[:, 1::2] = amp.real, -amp.imag  # Re(a e^{st}) = Re a·e·cos − Im a·e·sin
    return coef @ damped_basis(t, f, d, False, uniform_grid(t)).T


def _empty(n_ch, fs_hz, n, method, info) -> ModeTable:
    e, ec = np.empty(0), np.empty((n_ch, 0))
    return ModeTable(e, e, e, e, e, e, ec.astype(complex), ec, ec, ec, ec, e,
                     np.full(n_ch, np.nan), np.full(n_ch, np.nan), fs_hz, n,
                     f"{method}+varpro", info)


def _channel_fits(sel: ModeSelector, channels: np.ndarray):
    """Each channel's own fit (step 6) of the modes significant in it (energy of its joint
    amplitude over its noise above χ²₂ at 10⁻³), started at the joint poles: yields (channel,
    mode indices, VarProFit) where the fit succeeded. Channels with the same modes share the
    first evaluation (:func:`~ramdaq.analysis.modal.varpro.fit_channels_varpro`)."""
    fit = sel.fit
    f, d = fit.f_hz, fit.delta
    env2 = _sum_exp(sel.t, -2.0 * d * f) / 2.0
    snr = np.abs(fit.amplitude) ** 2 * env2 / np.maximum(fit.noise_std[:, None] ** 2, 1e-300)
    groups: dict[tuple[int, ...], list[int]] = {}
    for j in range(len(channels)):
        ks = tuple(np.flatnonzero(snr[j] > chdtri(2, 1e-3)))
        if ks:
            groups.setdefault(ks, []).append(j)
    for ks, rows in groups.items():
        k = np.array(ks)
        fits = fit_channels_varpro(sel.t, sel.Y[rows], f[k], d[k], fit_offset=sel.fit_offset,
                                   f_bounds_hz=sel.f_lim, delta_bounds=(-3.0, 3.0),
                                   se_tol=_CHANNEL_SE_TOL, by_matmul=sel.by_matmul)
        for j, fc in zip(rows, fits, strict=True):
            if fc is not None:
                yield int(channels[j]), k, fc


def _table(sel, X, active, fs_hz, d_nls, taps, f_range, per_channel, method, info) -> ModeTable:
    fit = sel.fit
    n_ch, n = X.shape
    se = np.sqrt(np.abs(np.diag(fit.covariance))).reshape(-1, 2)
    f, d = fit.f_hz, fit.delta
    vfac = np.sqrt(fir_noise_variance_factor(taps, d_nls, f, fs_hz))
    f_se, d_se = se[:, 0] * vfac, se[:, 1] * vfac
    amp = fit.amplitude
    if d_nls > 1:
        amp = amp / fir_gain(taps, np.exp((-d * f + 2j * np.pi * f) / fs_hz))[None, :]
    signif = sel.significance()
    K = f.size
    ch_f, ch_fse, ch_d, ch_dse = (np.full((n_ch, K), np.nan) for _ in range(4))
    if per_channel:
        for c, ks, fc in _channel_fits(sel, np.flatnonzero(active)):
            cse = np.sqrt(np.abs(np.diag(fc.covariance))).reshape(-1, 2) * vfac[ks, None]
            ch_f[c, ks], ch_d[c, ks] = fc.f_hz, fc.delta
            ch_fse[c, ks], ch_dse[c, ks] = cse[:, 0], cse[:, 1]
    full_amp = np.full((n_ch, K), np.nan + 0j)
    full_amp[active] = amp
    offset = np.full(n_ch, np.nan)
    offset[active] = fit.offset
    noise = np.full(n_ch, np.nan)
    noise[active] = fit.noise_std / np.sqrt(np.sum(taps * taps))  # back to the input rate
    # Terms with under one cycle in the record (drift, a DC step) stay in the model, unreported.
    keep = f >= 2.0 * sel.f_lim[0]
    info = info | {"nuisance_terms_hz": f[~keep]}
    if f_range is not None:
        inside = (f >= f_range[0]) & (f <= f_range[1])
        info = info | {"modes_outside_f_range": f[keep & ~inside]}
        keep &= inside
    o = np.flatnonzero(keep)[np.argsort(f[keep])]
    zeta = damping_ratio_from_decrement(d[o])
    dzeta = 4 * np.pi**2 / (4 * np.pi**2 + d[o] ** 2) ** 1.5
    return ModeTable(
        frequency_hz=f[o], delta=d[o], zeta=np.asarray(zeta), frequency_se_hz=f_se[o],
        delta_se=d_se[o], zeta_se=d_se[o] * dzeta, complex_amplitude=full_amp[:, o],
        channel_frequency_hz=ch_f[:, o], channel_frequency_se_hz=ch_fse[:, o],
        channel_delta=ch_d[:, o], channel_delta_se=ch_dse[:, o], significance=signif[o],
        offset=offset, noise_std=noise, fs_hz=float(fs_hz), n_samples=int(n),
        method=f"{method}+varpro", info=info,
    )
