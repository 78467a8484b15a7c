"""One impact's free decay turned into Report 1836's numbers.

Per gage and mode: frequency, logarithmic decrement, damping ratio, amplitude and phase with
standard errors (the multi-channel estimator of :mod:`ramdaq.analysis.modal.identify`), beside the
report's own peak-ratio decrement (:mod:`ramdaq.analysis.modal.peaks`). Then the report's chain on the
predominant mode:
the rudder motions gamma, alpha, v (Eq 1-3b) and their decrements (Eq 4-6b), the modal decrement
averaged over the rudder gages (Eq 7), the hull motions and the decrements relative to the hull
(Eq 8-13; each motion's decrement is its own fit, reached from the gages' joint poles by
:mod:`ramdaq.analysis.report1836.motion_fits`), the damping constants C and c (Eq 16, 17) and
the effective stock lengths (Appendix B, Figures 8 and 9).

Accelerations stand in for the report's displacements: for one damped mode they differ by the
same complex factor lambda^2 at every gage, so frequencies, decrements and amplitude ratios are
the same.

Hull yaw gamma_b, which the report read off Figure 9, is taken here from hull gages 5 and 13 at
one height (the hull section's rigid yaw, ``(d13 - d5) / (x13 - x5)``) when they are level, and
is otherwise left out as the report left it out (its Eq 9, 13 footnotes).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields

import numpy as np

from .modal.before_blow import ambient_modes
from .modal.identify import identify_modes
from .modal.peaks import bandpass_rows, decrements_from_peaks
from .modal.signal import fast_length_below
from .modal.table import ModeTable
from .modal.verdicts import DecayAssessment, JointAssessment, Verdict, assess_decay_jointly
from .model.geometry import gage_geometry, stock_pair
from .model.rig import ALIGN_TOL_M, Rig
from .model.structure import added_mass
from .report1836.damping import C_translational, c_rotational
from .report1836.full_damping import GAGES as EQ14_15_GAGES
from .report1836.full_damping import full_damping, table_amplitude_covariance
from .report1836.motion_fits import fit_signals_at_poles
from .report1836.motions import (
    GageGeometry,
    alpha,
    alpha_b_from_13_14,
    d_rudder_hull,
    gamma,
    geometry_constants,
    percent_deviation_from_average,
    v_from_2_6,
    v_from_4_8,
)

CROP_MAX_FRACTION = 0.03
"""Largest share of a decay's samples :func:`analyze_decay` drops from its end to reach an
FFT-fast length (:func:`fast_length_below`: at most 2.8 % from 4096 samples on, 0.4 % on
average at a replayed decay's ~29 000; between 2048 and 4096 a few lengths, e.g. 3341-3359,
would lose more and are analysed whole): the decay's end is the noise-floor rule's estimate, so
the cropped tail is at the floor and carries next to none of the decay's information."""

CROP_FROM = 2048
"""Shortest decay (samples) :func:`analyze_decay` crops: shorter ones are cheap to transform
at any length, and each of their samples weighs more in the fit."""

MOTIONS = ("gamma", "alpha", "v_2_6", "v_4_8")
"""Rudder motions of Eq 1, 2, 3a, 3b, whose decrements are Eq 4, 5, 6a, 6b."""


def mode_energy(amplitude: np.ndarray, decay_rate_per_s: np.ndarray) -> np.ndarray:
    """Time-integrated squared amplitude of each mode, ``sum_c A_ck^2 / (2 sigma_k)``.

    ``amplitude`` (n_channels, n_modes), ``decay_rate_per_s`` (n_modes,) the envelope's rate
    ``sigma = delta * f``. The predominant mode, the one that stands out on an oscillogram, is
    the largest: large *and* lasting.
    """
    return np.nansum(amplitude**2, axis=0) / (2 * np.abs(decay_rate_per_s))


@dataclass(frozen=True)
class Decrement:
    """A decrement with its standard error, from the estimator and from the report's peaks;
    the frequency (Hz) with its standard error where the estimator gives one."""

    f_hz: float
    delta: float
    delta_se: float
    peak_delta: float
    peak_delta_se: float
    f_se_hz: float = float("nan")

    @property
    def zeta(self) -> float:
        """Damping ratio of the decrement, ``delta / sqrt(4 pi^2 + delta^2)``."""
        return float(self.delta / np.hypot(2 * np.pi, self.delta))

    @property
    def zeta_se(self) -> float:
        """Its standard error, ``d zeta / d delta * delta_se`` (``4 pi^2 / (4 pi^2 + delta^2)^1.5``)."""
        return float(4 * np.pi**2 / np.hypot(2 * np.pi, self.delta) ** 3 * self.delta_se)

    def to_json(self) -> dict:
        return {k: _num(v) for k, v in (*self.__dict__.items(), ("zeta", self.zeta),
                                        ("zeta_se", self.zeta_se))}


@dataclass(frozen=True)
class SkippedStep:
    """A step of the report's chain that did not run for this layout: ``step`` names it (with
    its equations), ``reason`` says why in one line (the gages it needs that the record lacks,
    or a rig that describes no structure)."""

    step: str
    reason: str

    def to_json(self) -> dict:
        return {"step": self.step, "reason": self.reason}


CHAIN_STEPS: dict[str, tuple[int, ...]] = {
    "rudder motions (Eq 1-6b)": (2, 4, 6, 8),
    "decrements relative to the hull (Eq 8-13)": (2, 4, 5, 6, 8, 13, 14),
    "effective stock lengths (Figures 8, 9)": (1, 3, 7, 10, 11, 12, 13, 14),
    "damping constants (Eq 16, 17)": (2, 4, 6, 8),
    "damping constants with hull motion (Eq 14, 15)": (2, 4, 5, 6, 8, 13, 14),
}
"""The steps of the report's chain after the per-gage decrements, and the gages each needs in the
record (Report 1836's numbering); every step also needs a rig that describes the structure."""


def skipped_steps(rig: Rig, gage_numbers: tuple[int, ...]) -> tuple[SkippedStep, ...]:
    """The steps of :data:`CHAIN_STEPS` that cannot run on a record of ``gage_numbers`` with
    ``rig``, each with its reason."""
    if not rig.structural:
        return tuple(SkippedStep(step, f"rig {rig.name!r} describes only its channels (no rudder, "
                                       f"stock or hull)") for step in CHAIN_STEPS)
    have, in_rig = set(gage_numbers), {g.number for g in rig.gages}
    out = []
    for step, need in CHAIN_STEPS.items():
        lacking = [n for n in need if n not in have]
        if lacking:
            whose = "the record" if set(lacking) <= in_rig else f"rig {rig.name!r}"
            out.append(SkippedStep(step, f"needs gage(s) {', '.join(map(str, lacking))}, which "
                                         f"{whose} does not have"))
    return tuple(out)


@dataclass(frozen=True)
class GageVerdict:
    """Whether one gage's free decay can give a decrement (:func:`assess_decay`): ``code`` is
    ``Verdict.OK`` or what is wrong, ``reason`` one line with the numbers behind it, ``f_hz``
    and ``delta`` the dominant mode the verdict judged (Hz, 1; NaN where none was estimated)."""

    code: Verdict
    reason: str
    f_hz: float = float("nan")
    delta: float = float("nan")

    @classmethod
    def of(cls, a: DecayAssessment) -> GageVerdict:
        return cls(a.verdict, a.reason, a.f_hz, a.delta)

    @property
    def ok(self) -> bool:
        """The decay is usable: the mode fit takes this gage."""
        return self.code is Verdict.OK

    def to_json(self) -> dict:
        return {"verdict": str(self.code), "reason": self.reason}


@dataclass(frozen=True)
class FullDamping:
    """Eq 14 and 15: C (N s/m) and c (N m s/rad) with the hull motions and the phases between
    motions kept, the stock stiffness k_s (N/m) and bending length ell (m) they used, and their
    standard errors from the gages' noise (NaN when not known)."""

    C_eq14_N_s_per_m: float
    c_eq15_N_m_s_per_rad: float
    k_s_N_per_m: float
    ell_m: float
    C_eq14_se_N_s_per_m: float = float("nan")
    c_eq15_se_N_m_s_per_rad: float = float("nan")


@dataclass(frozen=True)
class DampingConstants:
    """The predominant mode's damping constants: C (N s/m) and c (N m s/rad) by Eq 16 and 17,
    NaN where a motion they need is missing; the masses they used (the rig's, plus the added
    mass in water: kg, kg m^2); the modal decrement (Eq 7, the mean over the rudder gages); and
    ``full``, Eq 14 and 15, None where a gage they need is unusable."""

    m_y_kg: float
    I_z_kg_m2: float
    I_xz_kg_m2: float
    delta_modal: float
    C_N_s_per_m: float
    c_N_m_s_per_rad: float
    full: FullDamping | None = None

    def values(self) -> dict[str, float]:
        """Every constant by its name in report.json, ``full``'s after the others when there."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "full"}
        if self.full is not None:
            out |= {f.name: getattr(self.full, f.name) for f in fields(self.full)}
        return out

    def __getitem__(self, key: str) -> float:
        """A constant by its report.json name, e.g. ``damping["delta_modal"]`` (how the trial
        summary and the live readout in ``ramdaq.daq`` read it)."""
        return self.values()[key]

    def to_json(self) -> dict[str, float | None]:
        return {k: _num(v) for k, v in self.values().items()}


@dataclass(frozen=True)
class ImpactAnalysis:
    """Everything one impact gives. Frequencies Hz, damping constants N s/m and N m s/rad,
    lengths m. Per-gage dicts are keyed by gage number."""

    onset_s: float
    decay_start_s: float
    duration_s: float
    modes: ModeTable
    predominant: int
    gage_numbers: tuple[int, ...]
    verdicts: dict[int, GageVerdict]
    gages: dict[int, Decrement]
    motions: dict[str, Decrement]
    relative: dict[str, Decrement]
    alpha1_over_gamma1: float
    damping: DampingConstants
    stock_lengths: dict[str, float] = field(default_factory=dict)
    stock_curves: dict[str, list[float]] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    hull_motions: dict[str, Decrement] = field(default_factory=dict)
    """The hull section's (a stern plane's fixed portion's) own motions at the stock and their
    decrements: ``alpha_b`` (Eq 8), ``gamma_b`` (from gages 5 and 13 when level), ``v_b``."""
    skipped: tuple[SkippedStep, ...] = ()
    chosen: int | None = None
    """Index in ``modes`` of the mode the user chose (``mode_hz``, :func:`chosen_mode`) for the
    report's chain; None when none was asked (the chain then runs on ``predominant``, the most
    energetic mode on the rudder, which this field never replaces)."""
    mode_hz: float | None = None
    """The frequency asked for (Hz) that chose ``chosen``; None when none was asked."""
    record_samples: int | None = None
    """Samples of the decay handed to :func:`analyze_decay` (``duration_s`` at the sample rate);
    None when not known."""
    analysed_samples: int | None = None
    """Leading samples of the decay every fit used: ``record_samples``, or fewer when its tail was
    cropped to an FFT-fast length (:data:`CROP_MAX_FRACTION`; a note says how much and how far
    the predominant mode was there above the noise); None when not known."""

    @property
    def chain_mode(self) -> int:
        """Index in ``modes`` of the mode the report's chain ran on: ``chosen`` when the user
        chose one, else ``predominant``. The per-gage and motion decrements are its."""
        return self.predominant if self.chosen is None else self.chosen

    def mode_tag(self, k: int) -> str:
        """What mode ``k`` of ``modes`` is, for a label: ``" (predominant)"``, ``" (asked:
        mode_hz 59.8)"``, both, or ``""``."""
        return mode_tag(k, self.predominant, self.chosen, self.mode_hz)

    @property
    def f_hz(self) -> float:
        """Frequency of the mode the chain ran on (:attr:`chain_mode`), Hz."""
        return float(self.modes.frequency_hz[self.chain_mode])

    @property
    def active_gages(self) -> tuple[int, ...]:
        """The gages whose decay the mode fit used (verdict ok), in ``gage_numbers`` order: the
        rows of ``modes.complex_amplitude``, ``modes.amplitude`` and ``modes.mode_shape``."""
        return tuple(n for n in self.gage_numbers if self.verdicts[n].ok)

    def hull_table(self) -> dict:
        """Table 2f's fixed-portion column done automatically: the decrements of the hull
        section's (fixed portion's) motions gamma_b, alpha_b, v_b, their average and each one's
        percent deviation from it; the finite ones only (``None`` rows for the others)."""
        names = ("gamma_b", "alpha_b", "v_b")
        vals = {n: self.hull_motions[n].delta for n in names if n in self.hull_motions}
        good = {n: v for n, v in vals.items() if np.isfinite(v)}
        rows = {n: {"delta": None, "deviation_pct": None} for n in names}
        if not good:
            return {"rows": rows, "average": None, "mean_abs_deviation_pct": None}
        mean, dev, mean_abs = percent_deviation_from_average(list(good.values()))
        for n, d in zip(good, dev, strict=True):
            rows[n] = {"delta": good[n], "deviation_pct": d}
        return {"rows": rows, "average": mean, "mean_abs_deviation_pct": mean_abs}

    def table2b(self) -> dict:
        """Table 2b done automatically: delta_gamma, delta_alpha, delta_v, delta_modal, their
        average and each one's percent deviation from it. A decrement that is not a finite
        number (a motion the chain could not measure) is left out of the average: its row holds
        ``None`` and ``left_out`` names it with the reason; with none left, the average is
        ``None`` too."""
        names = ("gamma", "alpha", "v_2_6", "modal")
        vals = [self.motions[n].delta if n in self.motions else float("nan") for n in names[:3]]
        vals.append(self.damping.delta_modal)
        good = [k for k, v in enumerate(vals) if np.isfinite(v)]
        rows = {n: {"delta": None, "deviation_pct": None} for n in names}
        out = {"rows": rows, "average": None, "mean_abs_deviation_pct": None}
        if len(good) < len(names):
            out["left_out"] = {names[k]: ("not measured" if names[k] not in self.motions and k < 3
                                          else f"not a finite number ({vals[k]})")
                               for k in range(len(names)) if k not in good}
        if good:
            mean, dev, mean_abs = percent_deviation_from_average([vals[k] for k in good])
            for k, d in zip(good, dev, strict=True):
                rows[names[k]] = {"delta": vals[k], "deviation_pct": d}
            out |= {"average": mean, "mean_abs_deviation_pct": mean_abs}
        return out


def _num(v: float) -> float | None:
    return None if v is None or not np.isfinite(v) else float(v)


def _nearest(table: ModeTable, f_hz: float) -> int | None:
    if len(table) == 0:
        return None
    i = int(np.argmin(np.abs(table.frequency_hz - f_hz)))
    return i if abs(table.frequency_hz[i] / f_hz - 1) < 0.1 else None


def _peak_decrements(x: np.ndarray, fs_hz: float, f_hz: float,
                     noise_std: np.ndarray | None = None,
                     bandpassed: np.ndarray | None = None) -> list[tuple[float, float]]:
    """The report's peak-ratio decrement and its standard error of each row of ``x`` (signals,
    samples; all at once: :func:`~ramdaq.analysis.modal.peaks.decrements_from_peaks`; each row's
    ``noise_std`` where known; ``bandpassed``: the rows band-passed already, where known,
    :func:`_bandpassed_rows`); NaN where the mode is too weak in a signal to show three peaks
    above the noise."""
    nan = (np.nan, np.nan)
    try:
        got = decrements_from_peaks(x, fs_hz, f_hz, noise_std=noise_std, bandpassed=bandpassed)
    except ValueError:  # refused for all rows alike (too few samples a period, or in all)
        return [nan] * len(x)
    return [nan if isinstance(p, ValueError) else (p.delta, p.std_error) for p in got]


CHAIN_READS = (2, 4, 5, 6, 8, 13, 14)
"""The gages the report's chain combines into motions whether or not they are usable (the
rudder motions, Eq 1-3b, and the hull's, Eq 8-13, are formed before the unusable are dropped)."""


def _bandpassed_rows(x: np.ndarray, fs_hz: float, f_hz: float,
                     rows: list[int]) -> np.ndarray | None:
    """The rows ``rows`` of ``x`` band-passed around ``f_hz`` as the peak decrements filter them
    (:func:`~ramdaq.analysis.modal.peaks.bandpass_rows`: each row on its own, the same bits as
    all rows at once), once for the gages and the motions made of them, in an array shaped as
    ``x`` whose other rows are NaN (no step reads them); None where the band does not fit (the
    peak decrements then say why)."""
    try:
        got = bandpass_rows(x[rows], fs_hz, f_hz)
    except ValueError:
        return None
    out = np.full(x.shape, np.nan)
    out[rows] = got
    return out


def _motion_fits(signals: dict[str, np.ndarray], fs_hz: float, table: ModeTable, k: int,
                 notes: list[str], bandpassed: dict[str, np.ndarray] | None = None
                 ) -> dict[str, tuple[Decrement, complex]]:
    """Each signal's decrement of the predominant mode ``k`` of ``table`` (its own fit, reached
    from the joint poles: :mod:`~ramdaq.analysis.report1836.motion_fits`), beside the report's
    peak-ratio one, and the mode's complex amplitude in it (the combination of the gages'). A
    signal in which the mode does not stand out of the noise gets NaN and a note.
    ``bandpassed``: each signal made of the band-passed gages (the same combination: equal to
    rounding to the band-passed signal), so that the peak method filters no signal again."""
    if not signals:
        return {}
    S = np.array(list(signals.values()))
    fits = fit_signals_at_poles(S, fs_hz, table.frequency_hz, table.delta, modes=(k,),
                                trend_terms=int(table.info.get("trend_terms", 1)))
    f = float(table.frequency_hz[k])
    Sb = None if bandpassed is None else np.array([bandpassed[name] for name in signals])
    peaks = _peak_decrements(S, fs_hz, f, bandpassed=Sb)
    out = {}
    for name, fit, peak in zip(signals, fits, peaks, strict=True):
        if not np.isfinite(fit.delta[k]):
            why = ("its fit failed" if fit.method.endswith("failed")
                   else "the mode is not above the noise in it")
            notes.append(f"{name}: no decrement of the {f:.3g} Hz mode, {why}")
            out[name] = (Decrement(f, np.nan, np.nan, np.nan, np.nan), complex(fit.amplitude[k]))
            continue
        out[name] = (Decrement(float(fit.f_hz[k]), float(fit.delta[k]), float(fit.delta_se[k]),
                               *peak, f_se_hz=float(fit.f_se_hz[k])),
                     complex(fit.amplitude[k]))
    return out


def _usable_fit(x: np.ndarray, fs_hz: float, judged: JointAssessment, good: list[int]) -> ModeTable:
    """The modes of the usable channels ``good`` (rows of ``x``): the verdicts' joint fit when
    it took exactly those; when it also took channels that hold noise only, the usable ones
    refitted with its modes as start and its order (no new search: noise moved the modes by no
    more than noise); else the usable ones searched afresh, so that no unusable channel (a
    growing or steady oscillation) shapes the modes."""
    tab = judged.table
    if tab is not None and tuple(good) == judged.rows:
        return tab
    if tab is not None and len(tab) and set(judged.rows) - set(good) <= set(judged.quiet_rows):
        return identify_modes(x[good], fs_hz, per_channel=True, n_modes=len(tab),
                              start=(tab.frequency_hz, tab.delta), band_decimation=True)
    return identify_modes(x[good], fs_hz, per_channel=True, band_decimation=True)


def analyze_decay(x: np.ndarray, fs_hz: float, rig: Rig, gage_numbers: tuple[int, ...], *,
                  onset_s: float = 0.0, decay_start_s: float = 0.0,
                  adc_full_scale: float | None = None, pre: np.ndarray | None = None,
                  pre_fs_hz: float | None = None, mode_hz: float | None = None) -> ImpactAnalysis:
    """Analyse one free decay.

    Parameters
    ----------
    x : ndarray, (n_channels, n_samples)
        Accelerations (m/s^2) from the start of the free decay (after the forced part).
    fs_hz : float
        Sample rate, Hz.
    rig : Rig
        Gage positions, masses and medium.
    gage_numbers : tuple of int
        Report gage number of each row of ``x``.
    onset_s, decay_start_s : float
        Impact onset and start of ``x``, seconds in the stream (for the record).
    adc_full_scale : float, optional
        Converter full scale in m/s^2 (the smallest over channels), to judge clipping.
    pre : ndarray, (n_channels, n_pre), optional
        The same channels before the blow (m/s^2, at ``pre_fs_hz``, default ``fs_hz``): a mode
        already ringing there (:func:`~ramdaq.analysis.modal.before_blow.ambient_modes`) is
        not taken as the predominant mode, and a note says so.
    mode_hz : float, optional
        The mode the report's chain is run on, chosen by the user (:func:`chosen_mode`)
        instead of the most energetic one; :class:`NoSuchMode` (a ValueError) when no
        identified mode is near it (:func:`chosen_mode`).
    """
    notes: list[str] = []
    n_record = x.shape[1]
    x = x[:, :fast_crop_length(n_record)]
    judged = assess_decay_jointly(x, fs_hz, adc_full_scale=adc_full_scale, band_decimation=True)
    verdicts = {gage_numbers[a.channel]: GageVerdict.of(a) for a in judged.verdicts}
    good = [i for i, n in enumerate(gage_numbers) if verdicts[n].ok]
    if not good:
        raise ValueError("no channel holds a usable free decay: "
                         + "; ".join(f"g{n:02d} {v.code}" for n, v in verdicts.items()))
    table = _usable_fit(x, fs_hz, judged, good)
    if len(table) == 0:
        raise ValueError(f"no mode found above the noise ({table.info.get('reason', '')})")
    ambient = ambient_modes(None if pre is None else pre[good], pre_fs_hz or fs_hz,
                            table.frequency_hz, table.complex_amplitude)
    k = predominant_mode(table, [j for j, i in enumerate(good)
                                 if rig.gage(gage_numbers[i]).body == "rudder"],
                         exclude=[a for a, _ in ambient])
    pred = k
    if mode_hz is not None:
        k = chosen_mode(table, mode_hz, x.shape[1] / fs_hz, k, notes)
    notes += [f"{table.frequency_hz[a]:.2f} Hz rang before the blow at {r:.0%} of its amplitude "
              "at the decay's start: an ambient line, not the blow's free decay (not taken as "
              "the predominant mode; its decrement is no damping measure)" for a, r in ambient]
    f = float(table.frequency_hz[k])
    xb = _bandpassed_rows(x, fs_hz, f, sorted(set(good) | {  # the gages' and (combined) the
        i for i, n in enumerate(gage_numbers) if n in CHAIN_READS}))  # motions' band-pass
    peaks = _peak_decrements(x[good], fs_hz, f, judged.noise_std[good],  # the verdicts' noise
                             None if xb is None else xb[good])
    gages = {gage_numbers[i]: Decrement(float(table.channel_frequency_hz[j, k]),
                                        float(table.channel_delta[j, k]),
                                        float(table.channel_delta_se[j, k]),
                                        *peaks[j],
                                        f_se_hz=float(table.channel_frequency_se_hz[j, k]))
             for j, i in enumerate(good)}
    amp = {gage_numbers[i]: table.complex_amplitude[j, k] for j, i in enumerate(good)}
    if x.shape[1] < n_record:
        notes.append(crop_note(x.shape[1], n_record, fs_hz, table, pred,
                               judged.noise_std[good]))
    skipped = skipped_steps(rig, tuple(gage_numbers))
    chain = _chain(x, fs_hz, rig, gage_numbers, verdicts, table, k, gages, amp,
                   {s.step for s in skipped}, notes, xb)
    return ImpactAnalysis(
        onset_s=onset_s, decay_start_s=decay_start_s, duration_s=n_record / fs_hz,
        modes=table, predominant=pred, gage_numbers=tuple(gage_numbers), verdicts=verdicts,
        gages=gages, **chain, notes=tuple(notes), skipped=skipped,
        chosen=None if mode_hz is None else k, mode_hz=mode_hz, record_samples=n_record,
        analysed_samples=x.shape[1])


def fast_crop_length(n: int) -> int:
    """How many leading samples of an ``n``-sample decay :func:`analyze_decay` analyses: the
    longest FFT-fast length <= n (:func:`~ramdaq.analysis.modal.signal.fast_length_below`) when
    that drops at most :data:`CROP_MAX_FRACTION` of the samples and n >= :data:`CROP_FROM`,
    else n. A decay's end is arbitrary (where it reached the noise floor) and at such lengths
    every periodogram, decimation and filter of the fits ran Bluestein's algorithm."""
    m = fast_length_below(n) if n >= CROP_FROM else n
    return m if n - m <= CROP_MAX_FRACTION * n else n


def crop_note(n_used: int, n_record: int, fs_hz: float, table: ModeTable, k: int,
              noise_std: np.ndarray) -> str:
    """The note that the last ``n_record - n_used`` samples were cropped, with the predominant
    mode ``k``'s fitted amplitude at the crop on its strongest gage over that gage's noise
    standard deviation (``noise_std`` per row of ``table``'s amplitudes)."""
    t = n_used / fs_hz
    env = np.abs(table.complex_amplitude[:, k]) * np.exp(-table.delta[k] * table.frequency_hz[k] * t)
    j = int(np.argmax(np.abs(table.complex_amplitude[:, k])))
    drop = n_record - n_used
    return (f"analysed {n_used:,} of {n_record:,} samples: the last {drop:,} "
            f"({drop / fs_hz:.3f} s; the predominant mode there at {env[j] / noise_std[j]:.2g}x "
            "the noise on its strongest gage) cropped to an FFT-fast length").replace(",", " ")


def _chain(x: np.ndarray, fs_hz: float, rig: Rig, gage_numbers: tuple[int, ...],
           verdicts: dict[int, GageVerdict], table: ModeTable, k: int,
           gages: dict[int, Decrement], amp: dict[int, complex], skip: set[str],
           notes: list[str], xb: np.ndarray | None = None) -> dict:
    """The report's chain on the predominant mode ``k`` of ``table``: each step of
    :data:`CHAIN_STEPS` not in ``skip``. Returns the :class:`ImpactAnalysis` fields it fills.
    ``xb``: the rows of ``x`` band-passed for the peak decrements (:func:`_bandpassed_rows`),
    of which the motions' band-passed signals are made."""
    f = float(table.frequency_hz[k])
    rows = {n: i for i, n in enumerate(gage_numbers)}
    steps = list(CHAIN_STEPS)
    made = _motion_signals([lambda n: x[rows[n]]] + ([] if xb is None else [lambda n: xb[rows[n]]]),
                           rig, verdicts, skip, notes)
    rudder, relative, hull = made[0]
    # the same signals of the band-passed gages, for the peak method
    bandpassed = None if xb is None else {name: v for part in made[1] for name, v in part.items()}
    fits = _motion_fits(rudder | relative | hull, fs_hz, table, k, notes, bandpassed)
    motions = {name: fits[name][0] for name in rudder}
    amps = {name: fits[name][1] for name in rudder}
    ratio = float(np.real(amps.get("alpha", np.nan) / amps.get("gamma", np.nan)))
    lengths, curves = _stock_lengths(amp, rig, notes) if steps[2] not in skip else ({}, {})
    full = steps[4] not in skip
    amp_cov = dict(zip(amp, table_amplitude_covariance(table, k, rig.daq), strict=True)) if full else None
    damping = _damping(rig, f, float(table.delta[k]), gages, motions, ratio, amp, curves, notes,
                       full=full, amp_cov=amp_cov)
    return {"motions": motions, "relative": {name: fits[name][0] for name in relative},
            "alpha1_over_gamma1": ratio, "damping": damping, "stock_lengths": lengths,
            "stock_curves": curves, "hull_motions": {name: fits[name][0] for name in hull}}


_Signals = dict[str, np.ndarray]


def _motion_signals(ds: Sequence[Callable[[int], np.ndarray]], rig: Rig,
                    verdicts: dict[int, GageVerdict], skip: set[str], notes: list[str]
                    ) -> list[tuple[_Signals, _Signals, _Signals]]:
    """For each accessor ``d`` of ``ds`` (``d(n)``: gage n's decay; e.g. the gages' and the
    band-passed gages'), the rudder motions (Eq 1-3b, those of usable gages), the motions
    relative to the hull (Eq 8-13) and the hull's own, each a linear combination of the gages,
    for the steps of :data:`CHAIN_STEPS` not in ``skip``; the rig's geometry read once, the
    notes said for the first accessor alone."""
    steps = list(CHAIN_STEPS)
    geom = gage_geometry(rig) if steps[0] not in skip else None
    out = []
    for i, d in enumerate(ds):
        said = notes if i == 0 else []
        rudder: _Signals = {}
        relative: _Signals = {}
        if geom is not None:
            signals = _rudder_motions(d, geom)
            rudder = _usable_motions(signals, verdicts, said)
            if steps[1] not in skip:
                relative = _relative_signals(d, rig, geom, signals, said)
        hull = _hull_motions(d, rig, verdicts) if rig.structural else {}
        out.append((rudder, relative, hull))
    return out


def mode_tag(k: int, predominant: int, chosen: int | None, mode_hz: float | None) -> str:
    """The label of mode ``k`` given the ``predominant`` one's index and the one ``chosen`` by
    ``mode_hz`` (None: none asked): ``" (predominant)"``, ``" (asked: mode_hz 59.8)"``, both
    (``" (predominant; asked: mode_hz 13)"``) or ``""``. report.json readers call it with its
    ``predominant_mode``, ``chosen_mode`` and ``mode_hz_asked``."""
    tags = (["predominant"] if k == predominant else []) \
        + ([f"asked: mode_hz {mode_hz:g}"] if chosen is not None and k == chosen else [])
    return f" ({'; '.join(tags)})" if tags else ""


class NoSuchMode(ValueError):
    """No identified mode near the frequency the user chose (``mode_hz``): the decay itself may
    be fine."""


MODE_HZ_TOL = 0.05
"""How far (a fraction of it) a mode chosen by ``mode_hz`` may be from the frequency asked for."""


def chosen_mode(table: ModeTable, mode_hz: float, duration_s: float, k: int, notes: list[str]) -> int:
    """Index in ``table`` of the mode nearest ``mode_hz`` (the user's choice of the mode the
    chain is run on), when within :data:`MODE_HZ_TOL` of it or the resolution ``1 / duration_s``
    of the decay, whichever is wider (a frequency typed from memory or another trial is a few %
    off; the resolution alone took 13.15 for 13.00 Hz on a 5 s decay and refused it on an 8 s
    one); a note when it is not the predominant mode ``k``. Raises :class:`NoSuchMode` naming the
    modes identified when no mode is that close."""
    tol = max(1.0 / duration_s, MODE_HZ_TOL * mode_hz)
    i = int(np.argmin(np.abs(table.frequency_hz - mode_hz)))
    if not abs(table.frequency_hz[i] - mode_hz) <= tol:
        raise NoSuchMode(f"mode_hz {mode_hz:g}: no identified mode within {tol:.3g} Hz "
                         f"({100 * MODE_HZ_TOL:.0f} % or the {duration_s:.2f} s decay's resolution); "
                         "modes identified: "
                         + ", ".join(f"{f:.3f}" for f in table.frequency_hz) + " Hz")
    if i != k:
        notes.append(f"the chain runs on the {table.frequency_hz[i]:.3f} Hz mode chosen by mode_hz "
                     f"{mode_hz:g} (the most energetic on the rudder is {table.frequency_hz[k]:.3f} Hz)")
    return i


def predominant_mode(table: ModeTable, rudder_rows: list[int], exclude: Sequence[int] = ()) -> int:
    """Index in ``table`` of the predominant mode: the largest :func:`mode_energy` of the
    displacement amplitudes (accelerations in, a / w^2 judged, as on the report's records) over
    the table's rows ``rudder_rows`` (the rudder gages; all rows where there are none), among
    the modes not in ``exclude`` (ambient lines; all modes when every one is excluded)."""
    disp = table.amplitude / (2 * np.pi * table.frequency_hz) ** 2
    energy = mode_energy(disp[rudder_rows or slice(None)], table.delta * table.frequency_hz)
    if len(set(exclude)) < len(energy):
        energy[list(exclude)] = -np.inf
    return int(np.argmax(energy))


MOTION_GAGES = {"gamma": (4, 8), "alpha": (2, 6), "v_2_6": (2, 6), "v_4_8": (4, 8)}
"""The gages each rudder motion of :data:`MOTIONS` is computed from."""


def _rudder_motions(d: Callable[[int], np.ndarray], geom: GageGeometry) -> dict[str, np.ndarray]:
    """The rudder motions of Eq 1, 2, 3a, 3b from the gages' decays (``d(n)``, gage n's) and
    the rig's distances ``geom`` (:func:`~ramdaq.analysis.model.geometry.gage_geometry`)."""
    K = geometry_constants(geom)
    return {
        "gamma": gamma(d(4), d(8), K["K1"]),
        "alpha": alpha(d(6), d(2), K["K2"]),
        "v_2_6": v_from_2_6(d(2), d(6), K["K3"], K["K4"]),
        "v_4_8": v_from_4_8(d(4), d(8), K["K5"], K["K6"]),
    }


def _usable_motions(signals: dict[str, np.ndarray], verdicts: dict[int, GageVerdict],
                    notes: list[str]) -> dict[str, np.ndarray]:
    """The rudder motions whose gages are all usable (Eq 4-6b are taken of those; a note names
    the others' unusable gages)."""
    out = {}
    for name, sig in signals.items():
        bad = [n for n in MOTION_GAGES[name] if not verdicts[n].ok]
        if bad:
            notes.append(f"{name}: not computed, gage(s) {bad} unusable")
            continue
        out[name] = sig
    return out


def _relative_signals(d: Callable[[int], np.ndarray], rig: Rig, geom: GageGeometry,
                      signals: dict[str, np.ndarray], notes: list[str]) -> dict[str, np.ndarray]:
    """Eq 8-13: the hull motions from gages 13, 14 (and 5 for the yaw, when level with 13) and
    the rudder motions relative to the hull, whose decrements Eq 10-13 are."""
    alpha_b = alpha_b_from_13_14(d(13), d(14), geom.L_P)
    p5, p13 = rig.gage(5).position_m, rig.gage(13).position_m
    gamma_b = 0.0
    if abs(p5[2] - p13[2]) <= ALIGN_TOL_M and abs(p13[0] - p5[0]) > ALIGN_TOL_M:
        gamma_b = (d(13) - d(5)) / (p13[0] - p5[0])
    else:
        notes.append("gamma_b left out: hull gages 5 and 13 are not level")
    d_rh = d_rudder_hull(d(13), d(14), geom.L_H, geom.L_P, geom.h, gamma_b)
    return {"gamma_R": signals["gamma"] - gamma_b, "alpha_R": signals["alpha"] - alpha_b,
            "v_R_2_6": signals["v_2_6"] - d_rh, "v_R_4_8": signals["v_4_8"] - d_rh}


def _hull_motions(d: Callable[[int], np.ndarray], rig: Rig,
                  verdicts: dict[int, GageVerdict]) -> dict[str, np.ndarray]:
    """The hull section's rigid motions at the stock from its gages (those usable): alpha_b
    (Eq 8, 13 and 14), gamma_b (5 and 13, when level) and v_b at the stock's hull attachment,
    ``d13 + (z13 - z_attach) alpha_b``. For a stern plane, the fixed portion's alpha, beta, w."""
    ok = {n for n, v in verdicts.items() if v.ok}
    out: dict[str, np.ndarray] = {}
    p5, p13, p14 = (rig.gage(n).position_m if n in ok else (np.nan,) * 3 for n in (5, 13, 14))
    if {13, 14} <= ok and abs(p13[0] - p14[0]) <= ALIGN_TOL_M:
        out["alpha_b"] = alpha_b_from_13_14(d(13), d(14), p14[2] - p13[2])
        out["v_b"] = d(13) + (p13[2] - rig.hull_attach_z_m) * out["alpha_b"]
    if {5, 13} <= ok and abs(p5[2] - p13[2]) <= ALIGN_TOL_M and abs(p13[0] - p5[0]) > ALIGN_TOL_M:
        out["gamma_b"] = (d(13) - d(5)) / (p13[0] - p5[0])
    return out


def _damping(rig: Rig, f: float, delta: float, gages: dict[int, Decrement],
             motions: dict[str, Decrement], ratio: float, amp: dict[int, complex],
             curves: dict[str, list[float]], notes: list[str], full: bool = True,
             amp_cov: dict[int, np.ndarray] | None = None) -> DampingConstants:
    """Eq 16 and 17 with the rig's masses (plus the added mass in water), the modal decrement
    (Eq 7) over the rudder gages, and, with ``full``, Eq 14 and 15 (:func:`_full_damping`).
    ``f``, ``delta``: the predominant mode's; ``ratio``: alpha1 / gamma1. A channels-only rig
    has no masses (NaN) and its modal decrement is the mean over every gage (it names no
    bodies)."""
    if not rig.structural:
        notes.append("delta_modal: the mean over every gage (the rig names no rudder gages)")
        return DampingConstants(m_y_kg=np.nan, I_z_kg_m2=np.nan, I_xz_kg_m2=np.nan,
                                delta_modal=float(np.mean([g.delta for g in gages.values()])),
                                C_N_s_per_m=np.nan, c_N_m_s_per_rad=np.nan)
    add = added_mass(rig)
    r = rig.rudder
    m_y = r.mass_kg + add["m_vir"]
    I_z = r.Iz_kg_m2 + add["Iz_vir"]
    d_v, d_gamma = _motion_delta(motions, "v_2_6", notes), _motion_delta(motions, "gamma", notes)
    return DampingConstants(
        m_y_kg=m_y, I_z_kg_m2=I_z, I_xz_kg_m2=r.Ixz_kg_m2,
        delta_modal=_rudder_mean([gages[n].delta for n in gages if rig.gage(n).body == "rudder"],
                                 notes),
        C_N_s_per_m=float(C_translational(m_y, f, d_v)) if np.isfinite(d_v) else np.nan,
        c_N_m_s_per_rad=float(c_rotational(I_z, r.Ixz_kg_m2, ratio, f, d_gamma))
        if np.isfinite(d_gamma) and np.isfinite(ratio) else np.nan,
        full=_full_damping(amp, f, delta, rig, m_y, I_z, curves, notes, amp_cov) if full else None)


def _motion_delta(motions: dict[str, Decrement], name: str, notes: list[str]) -> float:
    """The decrement of the rudder motion ``name`` that Eq 16 / 17 take, NaN when the motion was
    not computed (its gages unusable: already noted) or its decay gave no decrement (a motion
    the blow did not excite above the noise, e.g. no rotation when every rudder gage moves
    alike), with a note naming which damping constant that leaves undetermined."""
    if name not in motions:
        return float("nan")
    d = float(motions[name].delta)
    if not np.isfinite(d):
        eq = "Eq 17, c" if name == "gamma" else "Eq 16, C"
        notes.append(f"{eq}: not computed, the {name} motion's decay gave no decrement "
                     "(not excited above the noise)")
    return d


def _rudder_mean(deltas: list[float], notes: list[str]) -> float:
    """Eq 7: the mean decrement over the rudder gages; NaN, with a note, when none is usable."""
    finite = [v for v in deltas if np.isfinite(v)]
    if not finite:
        notes.append("delta_modal (Eq 7): no usable rudder gage")
        return float("nan")
    return float(np.mean(finite))


def _stock_lengths(amp: dict[int, complex], rig: Rig,
                   notes: list[str]) -> tuple[dict[str, float], dict[str, list[float]]]:
    """Effective stock lengths (Figures 8, 9) from the predominant mode's complex amplitudes
    ``amp`` (by gage, the usable ones), and the curves they were read from: heights z' (m above
    the rudder top), (d_v,alpha) and gamma of the stock points, and the hull points 13, 14 -- in
    the mode's amplitude units, signed by the phase of gage 4."""
    from .report1836.stock_length import effective_length_bending, effective_length_torsion

    needed = (1, 3, 7, 11, 10, 12, 13, 14)
    if any(n not in amp for n in needed):
        notes.append("stock lengths: not computed, a stock, rudder-top or hull gage is unusable")
        return {}, {}
    ref = amp.get(4, amp[needed[0]])
    rot = np.conj(ref) / abs(ref)  # project on the phase of gage 4: real, signed values
    a = {n: float(np.real(v * rot)) for n, v in amp.items()}
    b = rig.rudder.attach_z_m
    h = rig.rudder.stock_x_m
    z_stock, d_stock, g_stock = [], [], []
    for pair in (stock_pair(rig, 1, 3), stock_pair(rig, 7, 11), stock_pair(rig, 10, 12)):
        xa = rig.gage(pair.aft).position_m[0] - h
        xf = h - rig.gage(pair.forward).position_m[0]
        da, df = a[pair.aft], a[pair.forward]
        z_stock.append(pair.z_m - b)
        d_stock.append((xf * da + xa * df) / (xa + xf))  # on the stock line (B-7, B-8, B-11)
        g_stock.append((da - df) / (xa + xf))  # B-3, B-6, B-12
    z13, z14 = rig.gage(13).position_m[2] - b, rig.gage(14).position_m[2] - b
    curves = {"z_stock_m": z_stock, "d_v_alpha": d_stock, "gamma": g_stock,
              "z_hull_m": [z13, z14], "d_hull": [a[13], a[14]]}
    out: dict[str, float] = {}
    try:
        bend = effective_length_bending(z_stock, d_stock, [z13, z14], [a[13], a[14]], b)
        out["bending_m"] = bend.length
        curves["z_attach_bending_m"] = [bend.z_attach]
    except ValueError as err:
        notes.append(f"stock bending length: {err}")
    p13 = rig.gage(13).position_m
    p5 = rig.gage(5).position_m if 5 in a else None       # a field rig may have no gage 5
    if p5 is not None and abs(p5[2] - p13[2]) <= ALIGN_TOL_M and abs(p13[0] - p5[0]) > ALIGN_TOL_M:
        gamma_b = (a[13] - a[5]) / (p13[0] - p5[0])  # the hull section's yaw, as for Eq 10
        try:
            tors = effective_length_torsion(z_stock, g_stock, b, gamma_b=gamma_b)
            out["torsion_m"] = tors.length
            curves["z_attach_torsion_m"] = [tors.z_attach]
        except ValueError as err:
            notes.append(f"stock torsion length: {err}")
    else:
        notes.append("stock torsion length: needs gamma_b from level hull gages 5 and 13")
    return out, curves


def _full_damping(a: dict[int, complex], f: float, delta: float, rig: Rig, m_y: float,
                  I_z: float, curves: dict, notes: list[str],
                  amp_cov: dict[int, np.ndarray] | None = None) -> FullDamping | None:
    """Eq 14 and 15: C and c with the hull motions and the phases between motions kept, and
    their standard errors from the amplitudes' covariance ``amp_cov`` (by gage); None (and a
    note) where a gage they need is unusable. A note says when one is not significant or not
    positive (:mod:`~ramdaq.analysis.report1836.full_damping`).

    The predominant mode's complex amplitudes ``a`` (by gage) give every motion's sine (in phase
    with v) and cosine parts. ``f`` (Hz), ``delta``: the mode's. The stock constants come from
    the rig (EI, kappa A G, G J) and the effective bending length read off Figure 8 (the rig's
    own when it could not be read).
    """
    if any(n not in a for n in EQ14_15_GAGES):
        notes.append("Eq 14/15: not computed, a rudder or hull gage is unusable")
        return None
    ell = curves.get("z_attach_bending_m", [rig.stock.bending_length_m])[0]
    est = full_damping(a, f, delta, rig, m_y, I_z, ell, amp_cov)
    notes.extend(est.notes())
    return FullDamping(C_eq14_N_s_per_m=est.C, c_eq15_N_m_s_per_rad=est.c,
                       k_s_N_per_m=est.stock.k_s, ell_m=ell, C_eq14_se_N_s_per_m=est.C_se,
                       c_eq15_se_N_m_s_per_rad=est.c_se)


@dataclass(frozen=True)
class FirstLook:
    """A preliminary reading while the rudder still rings: the predominant mode's frequency and
    decrement per gage, from the decay so far (``duration_s`` of it)."""

    duration_s: float
    f_hz: float
    delta: float
    gages: dict[int, tuple[float, float, float]]  # gage -> (f_hz, delta, delta_se)
    n_modes: int = 0  # modes in the fit (the order the look found, or was given)


def first_look(x: np.ndarray, fs_hz: float, rig: Rig, gage_numbers: tuple[int, ...], *,
               max_samples: int = 40_000, pre: np.ndarray | None = None,
               n_modes: int | None = None) -> FirstLook | None:
    """Quick per-gage frequency and decrement on the decay so far, (n_gages, n) m/s^2.

    The same estimator as the final analysis, on a decimated copy (``max_samples``) and
    without verdicts or the report's chain: a first look, refined as the decay goes on. ``pre``
    (n_gages, n_pre) m/s^2 at ``fs_hz``, the same gages before the blow: a mode already ringing
    there is not taken as the predominant one (as in :func:`analyze_decay`). ``n_modes``: the
    order to fit, where it is known (an earlier look at a like decay found it), instead of the
    likelihood-ratio search for it -- the same fit, about half the CPU of a look on 16 gages.
    Returns None when no mode stands above the noise yet.
    """
    table = identify_modes(x, fs_hz, per_channel=True, max_samples=max_samples, n_modes=n_modes)
    if len(table) == 0:
        return None
    ambient = ambient_modes(pre, fs_hz, table.frequency_hz, table.complex_amplitude)
    k = predominant_mode(table, [i for i, n in enumerate(gage_numbers)
                                 if rig.gage(n).body == "rudder"], exclude=[a for a, _ in ambient])
    gages = {n: (float(table.channel_frequency_hz[i, k]), float(table.channel_delta[i, k]),
                 float(table.channel_delta_se[i, k])) for i, n in enumerate(gage_numbers)}
    return FirstLook(x.shape[1] / fs_hz, float(table.frequency_hz[k]), float(table.delta[k]),
                     gages, len(table))
