"""Impact trigger: finds ram blows in a block stream, to the sample, and hands over their records.

``Trigger(info, TriggerSettings(...)).process(block) -> [ImpactEvent]``; events come out once
their record is complete (``flush()`` at the end of a stream). Every setting is in
:class:`TriggerSettings` (times in seconds); the trigger turns them into samples at the stream's
rate when it is built, at any rate from 50 Hz to 51.2 kHz: a length the rate cannot resolve
(an STA of fewer than 5 samples, an AR fit of fewer than 30) is refused then, naming the
setting and the value to set, never mid-stream; ``TriggerSettings.for_rate(fs_hz)`` (what
``Trigger(info)`` uses) lengthens the defaults that need it, and is the plain defaults at the
design rates (2048 Hz, 25.6 kHz). States and what moves them::

    not ready --(lta_s / 4 of samples since the start or a long gap)--> arming
    arming --(lta_s of samples: the LTA is full)--> armed
    arming, armed --(detection: k of n gages STA/LTA > on, or ram force >= level)--> active
    active --(envelope back near the pre-event level for rearm_hold_s, or max_post_s)--> armed
    any --(short gap)--> the same state;  any --(long gap, or back in time)--> not ready

* **Detection.** With a ram load cell (a channel in ``"N"``; ``mode="force"``, or ``"auto"``
  when one exists) a level / slope trigger on ``|F|`` with hysteresis; otherwise recursive
  STA/LTA (:mod:`ramdaq.analysis.onset`) on every gage, at least ``k`` of ``n`` agreeing. A steady tone
  already present (SAMPSON's 2.18 Hz hull) is in the LTA too, so its ratio stays near 1-2 and
  does not trigger. The LTA is frozen while a blow rings, so the trigger is fully sensitive again
  as soon as it re-arms, and the frozen value is the *pre-event level*.
* **Onset.** AIC (Maeda) over the responding gages, then a joint hinge fit of the rising edge
  (:func:`ramdaq.analysis.onset.hinge_onset`) to a fraction of a sample, less the front end's delay
  (``delay_s``; by default the rig's anti-alias Butterworth, read from ``info.rig_toml``; a
  rig that does not say it usably is refused when the trigger is built, never read as 0 s).
* **Second contact.** 15-45 ms after the onset an AR prediction-error filter is fitted, forward
  and backward, to the ringing (all gages share its poles, so it reaches the noise floor); the
  innovation of a new blow then stands far out of the ringing. A new sharp onset within
  ``double_hit_s`` flags the event ``double_hit`` (its time: AIC on the innovation, which the AR
  filter has also freed of the anti-alias delay); later, while still ringing, it closes the record
  (``end_reason="next_impact"``) and opens a new event timed the same way. The innovation is
  compared with the fit's variance (corrected for the fit's few equations) or, if higher, its own
  mean over ``envelope_s`` (the filter whitens a long ringing less well as its modes decay); fewer
  than three voting gages need the ratio with three gages' chance (11.6 for one gage at 2048 Hz,
  6.7 for two), so one gage does not take its ringing for blows. A burst is a contact only if
  it also stands out of the filter refitted to the ringing around it (a hole of a few ms in up
  to 120 ms): a 30 ms filter extrapolates a mode slower than its window badly, and that error is
  no contact (the verdict waits up to ~65 ms after the burst for the samples). With a load
  cell, a second crossing of ``level`` after ``|F|`` fell below ``hysteresis * level`` is the
  second contact.
  Contacts closer than ``ar_guard_s + ar_fit_s`` (45 ms) to the first are not seen.
* **A blow the innovation misses.** From ``double_hit_s`` after an onset to the re-arm, the
  STA of x**2 (``sta_s``) over the ringing's own envelope (``envelope_s``) above 6 on ``k``
  responding gages is a new blow too: a response that starts smoothly (a damped sine from
  rest) has no innovation above the noise at 25.6 kHz, and such a blow was merged into the last
  record. A free decay keeps that ratio near a sine's peak factor, 2 (at most 3.6 over the gap
  benchmark's 222 development trials, 2.4 on the bundled recordings, deep beats 2.3-2.9),
  while a blow into a ringing at the noise floor reads ~20. Where the innovation also shows the
  blow within ``ar_guard_s``, its time is the one taken.
* **Decay and re-arm.** The envelope (recursive mean of x**2 over ``envelope_s``) of every
  responding gage must stay below ``rearm_ratio`` times its pre-event level for
  ``rearm_hold_s``. The record runs from ``pre_trigger_s`` before the onset to the decay's end,
  but at least ``post_s`` and at most ``max_post_s`` after the onset. The record is handed over
  as soon as the decay is at the noise floor (:mod:`ramdaq.daq.decay_end`: windows of the
  loudest gages against the pre-event level), if that comes before the re-arm; the ringing is
  then followed to the re-arm without a record, as after a gap. On re-arming, the LTA
  resumes from the larger of the pre-event level and the envelope, so what still rings (or a
  background that changed) cannot trigger at once.
* **No blow.** An STA/LTA event after which no octave band of the responding gages rings more
  than twice as much in the 0.2 s after the onset as before it
  (:func:`ramdaq.analysis.onset.band_energy_ratio`) added no energy: a mode that stops ringing
  by friction fires the trigger too, while a blow, even struck into the last one's ringing,
  drives every mode. It is handed over with ``not_analysable`` saying so, the ratio in the
  words, never dropped.
* **Clipping.** Counts at the ADC rails ``-2**(bits-1)`` / ``2**(bits-1) - 1`` (``adc_bits``
  from ``info.extra``; no check without it) anywhere in the record name the channel in
  ``clipped``.
* **Arming.** After the start of the stream (or a long gap) the trigger is blind for
  ``lta_s / 4`` (*not ready*): the background must be averaged over at least half a period of
  its slowest steady tone, or the tone's peaks would look like blows (the power of a sine
  averaged over half a period is its mean; 0.5 s covers tones down to 1 Hz). Until ``lta_s``
  it is *arming*: it detects against the LTA so far, and a blow it sees is reported as
  ``not_analysable`` ("trigger still arming"): its pre-event level, which ends its record,
  rests on less than the LTA window. With a load cell the force is watched while the LTA
  settles too (it needs no background): a blow then is reported the same way, not lost.
* **Offline** (a whole file: ``ramdaq import``/``analyze``, :func:`ramdaq.daq.recording.read_recording`):
  :meth:`Trigger.arm_on_record` arms the trigger on the whole record before its first block:
  the LTA starts from the record's background (the mean power of the quietest ``lta_s / 4``
  in its first ``4 lta_s``), armed from the first sample; a force channel's
  baseline (its median: a load cell's offset) is taken off and its level is the record's (20
  noise rms and a tenth of its largest blow, at most ``level_N``: a hammer's record triggers as
  a ram's does). A record that starts with the blow (no pre-trigger) has its onset where the
  force (or, without one, the responding gages' power) rises, at its first sample at the latest.
* **Gaps.** A block whose ``first_sample`` is not the previous block's ``next_sample`` is a gap:
  an open event is closed at the last sample before it (``end_reason="gap"``) and the ring
  buffer restarts (no window reads across a gap). A *short* gap, at most ``lta_s`` of missing
  samples, leaves the STA and LTA as they were: the LTA's weights fall to 1/e over ``lta_s``,
  so after such a gap the background it holds is no older than what it already averages. The
  trigger then goes on from the state it had: armed (or arming) at the first sample after the
  gap; or, if a blow was ringing, following that ringing to its decay (its record, closed at
  the gap, is handed over; the ringing after the gap is the same blow and cannot trigger) while
  its AR filter looks for a new blow once it has ``ar_order`` samples after the gap (10 ms at
  2048 Hz; until then the STA against the ringing's envelope stands in, if the blow is older
  than 2 ``envelope_s``; if it is younger, those samples are blind). A longer gap, or a stream
  that jumps back, restarts the trigger as at the start. A blow whose onset lies within the
  hinge fit's pre-event window (15 ms) after a gap may have begun inside it: it is reported,
  ``not_analysable``. :attr:`Trigger.health` counts the gaps, the missing samples, the time
  the trigger was blind (gaps, settling, an AR filter not yet able to scan) and arming.

The working state of an event is held in pieces a reader can take one at a time: the detector's
running averages (:class:`_Levels`), the envelope watch that ends the record
(:class:`_DecayWatch`), and the second-contact detector with its AR filter
(:class:`_ContactScan`, :class:`_Whitener`), which a blow that follows while the last one still
rings takes over.

Events are JSON-serialisable (:meth:`ImpactEvent.to_json`) for ``/ramdaq/impacts``
(:data:`IMPACT_JSON_SCHEMA`); the samples (``ImpactEvent.record``) travel beside the JSON.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import warnings
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from ..analysis import onset as ons
from ..analysis.model.rig import STRUCTURE_TABLES
from ..drivers.block import Block, StreamInfo
from .decay_end import FloorWatch, noise_bandwidth_fraction

__all__ = ["IMPACT_JSON_SCHEMA", "ImpactEvent", "ImpactRecord", "RecordBackground",
           "StreamHealth", "Trigger", "TriggerSettings", "record_background"]

_AIC_PRE_S, _AIC_POST_S = 0.1, 0.01          # AIC window around a detection
_EDGE_PRE_S, _EDGE_POST_S = 0.015, 0.004     # hinge fit window around the AIC pick
_EDGE_SEARCH_S = (0.0015, 0.0005)            # onset search around the AIC pick
_RING_SPARE_S = 1.0
_AIC_MARGIN = 4                              # samples the AIC keeps clear of a window's ends
_STAT_N = 5                                  # fewest samples of an average set against a threshold
_REF_STA = 20                                # innovation reference: >= 20 innovation STAs
_DESIGN_VOTES = 3                            # gages the second-contact threshold is set for
_REFIT_SPAN = 4                              # a second contact's refit: up to 4 AR fit windows
_AR_MODES_TAPS = 10                          # fewest AR taps by default: 2-3 modes (fwd-bwd fit)
_MAD_SIGMA = 1.4826                          # rms of Gaussian noise per median absolute deviation
_START_LTAS = 4                              # offline background: the record's first 4 LTAs
_FORCE_NOISE_LEVELS = 20.0                   # an offline force level: at least 20 noise rms ...
_FORCE_PEAK_FRACTION = 0.1                   # ... and a tenth of the record's largest blow
_RISE_ON = 6.0                               # a blow in the ringing: STA / envelope above this
NOT_READY, ARMING, ARMED, ACTIVE = "not ready", "arming", "armed", "active"
MODES = ("auto", "force", "sta_lta")


@dataclass(frozen=True)
class TriggerSettings:
    """Every setting of :class:`Trigger`; times in s, forces in N, the rest ratios.

    Attributes
    ----------
    mode : {"auto", "force", "sta_lta"}
        ``auto`` uses a ram force channel (unit ``"N"``) when the stream has one.
    force_channel : str, optional
        Name of the ram load cell; default the first channel in ``"N"``.
    level_N, slope_N_per_s : float
        Force trigger: ``|F| >= level_N`` (N), or ``|dF/dt| >= slope_N_per_s`` (N/s) if given.
    hysteresis : float
        ``|F|`` must fall below ``hysteresis * level_N`` before a new contact counts.
    sta_s, lta_s : float
        STA and LTA lengths, s. The trigger is ready ``lta_s`` after the start and any gap.
    on : float
        STA/LTA ratio of a voting gage that counts towards a trigger.
    off : float
        A second contact has ended when fewer than ``k`` gages' innovation ratio exceeds it.
    k_of_n : (int, int or None)
        ``k`` of the ``n`` voting gages must exceed ``on`` (``n`` None: all of ``voters``).
    voters : tuple of str, optional
        Channels that vote; default every gage (``info.gages > 0``).
    pre_trigger_s, post_s, max_post_s : float
        Record from ``pre_trigger_s`` before the onset to the decay's end, kept within
        ``post_s .. max_post_s`` after the onset, s.
    envelope_s, rearm_ratio, rearm_hold_s : float
        Decay: envelope / pre-event power < ``rearm_ratio`` on every responding gage for
        ``rearm_hold_s`` (s); the envelope is a recursive mean of x**2 over ``envelope_s`` (s).
    double_hit_s : float
        A second contact up to this long after the onset (s) is a double hit; later, a new impact.
    double_on, innovation_sta_s : float
        Second contact: innovation power (mean over ``innovation_sta_s``, s) / its level in the
        fit window above ``double_on`` on ``k`` responding gages.
    ar_order : int, optional
        Taps of the AR prediction-error filter; default ``min(32, fit samples // 3)`` (20 at
        2048 Hz, 32 at 25.6 kHz, where the anti-alias band edge needs more).
    ar_guard_s, ar_fit_s : float
        The filter is fitted from ``ar_guard_s`` to ``ar_guard_s + ar_fit_s`` after the onset, s.
    delay_s : float, optional
        Front-end delay removed from onsets, s; default the rig's anti-alias filter
        (:func:`ramdaq.analysis.onset.butterworth_delay_s`) from ``info.rig_toml``, 0 without a rig.
    keep_records : bool
        Attach the samples (:class:`ImpactRecord`) to each event.

    Settings that need no stream are checked here (``ValueError`` naming the setting); those
    that depend on the stream's channels and rate when the :class:`Trigger` is built.
    """

    mode: str = "auto"
    force_channel: str | None = None
    level_N: float = 1000.0
    slope_N_per_s: float | None = None
    hysteresis: float = 0.5
    sta_s: float = 0.01
    lta_s: float = 2.0
    on: float = 4.0
    off: float = 2.0
    k_of_n: tuple[int, int | None] = (3, None)
    voters: tuple[str, ...] | None = None
    pre_trigger_s: float = 0.5
    post_s: float = 2.0
    max_post_s: float = 30.0
    envelope_s: float = 0.25
    rearm_ratio: float = 2.0
    rearm_hold_s: float = 0.25
    double_hit_s: float = 1.0
    double_on: float = 5.0
    innovation_sta_s: float = 0.003
    ar_order: int | None = None
    ar_guard_s: float = 0.015
    ar_fit_s: float = 0.03
    delay_s: float | None = None
    keep_records: bool = True

    def __post_init__(self) -> None:
        if self.voters is not None:
            object.__setattr__(self, "voters", tuple(self.voters))
        object.__setattr__(self, "k_of_n", tuple(self.k_of_n))
        for name in ("level_N", "sta_s", "lta_s", "on", "off", "post_s", "envelope_s",
                     "rearm_ratio", "rearm_hold_s", "double_on", "innovation_sta_s",
                     "ar_guard_s", "ar_fit_s"):
            v = getattr(self, name)
            if not v > 0 or not math.isfinite(v):
                raise ValueError(f"{name} ({v}) must be a positive number")
        if not 0 < self.hysteresis < 1:
            raise ValueError(f"hysteresis ({self.hysteresis}) must lie between 0 and 1")
        if not self.off < self.on:
            raise ValueError(f"off ({self.off}) must be below on ({self.on})")
        if not (0 <= self.pre_trigger_s and self.post_s <= self.max_post_s):
            raise ValueError(f"need 0 <= pre_trigger_s ({self.pre_trigger_s}) and post_s "
                             f"({self.post_s}) <= max_post_s ({self.max_post_s})")
        if self.mode not in MODES:
            raise ValueError(f"mode {self.mode!r} is not 'auto', 'force' or 'sta_lta'")
        if self.ar_order is not None and (isinstance(self.ar_order, bool)
                                          or int(self.ar_order) != self.ar_order
                                          or self.ar_order < 1):
            raise ValueError(f"ar_order ({self.ar_order}) must be a whole number >= 1")

    @classmethod
    def for_rate(cls, fs_hz: float, n_voters: int | None = None, **overrides: Any) -> TriggerSettings:
        """The settings ``TriggerSettings(**overrides)``, with every length that was not given
        and that ``fs_hz`` cannot resolve lengthened to the fewest samples it needs
        (:func:`_samples_needed`; at 50 Hz: ``sta_s`` and ``innovation_sta_s`` 0.1 s,
        ``ar_guard_s`` 0.02 s, ``ar_fit_s`` 0.6 s). Where the defaults resolve (from 1.6 kHz
        up) this is exactly ``TriggerSettings(**overrides)``. ``Trigger(info)`` uses it, with
        ``n_voters`` the stream's gages: a ``k_of_n`` not given votes ``k = 3`` of four gages
        or more and all but one of two or three (one of one), so that one gage that does not
        respond (dead, unplugged, on a node of the blow's modes) never hides every blow."""
        if "k_of_n" not in overrides and n_voters is not None and 1 <= n_voters <= cls.k_of_n[0]:
            overrides["k_of_n"] = (max(1, n_voters - 1), None)
        s = cls(**overrides)
        longer = {name: need / fs_hz for name, (need, _) in _samples_needed(s).items()
                  if name not in overrides and round(getattr(s, name) * fs_hz) < need}
        return dataclasses.replace(s, **longer) if longer else s


def _samples_needed(s: TriggerSettings) -> dict[str, tuple[int, str]]:
    """The fewest samples each length setting of ``s`` needs at any rate, and why.

    The averages that are compared with a threshold need a few samples: the STA of white
    noise's power over one sample exceeds 4 times its mean on 3 of 4 gages about once in 2 700
    samples (chi-square, one degree of freedom: P = 0.046 per gage), a recursive mean over five
    samples about once in 10^10 (P = 1.8e-4 per gage, simulated). The AR
    fit needs three equations per tap and ten taps (two or three ringing modes, each with its
    poles' backward reflections) for the innovation to be noise where the ringing has more
    modes than one (with an AR(2) fitted to two modes,
    a second contact is found 0.1 s after every blow). These are the counts the design rate,
    2048 Hz, has (20, 6, 61 samples)."""
    needs = {"sta_s": (_STAT_N, "an STA compared with on"),
             "innovation_sta_s": (_STAT_N, "an innovation STA compared with double_on")}
    needs |= {name: (1, "a length of at least one sample")
              for name in ("envelope_s", "rearm_hold_s", "post_s", "max_post_s", "double_hit_s",
                           "ar_guard_s")}
    if s.ar_order is None:  # default order fit // 3
        needs["ar_fit_s"] = (3 * _AR_MODES_TAPS, f"the AR fit of the ringing ({_AR_MODES_TAPS} "
                                                 f"taps, five modes, for second contacts)")
    else:
        needs["ar_fit_s"] = (2 * int(s.ar_order) + 2, f"ar_order ({s.ar_order})")
    return needs


@dataclass(frozen=True)
class _Lengths:
    """The settings in samples at one stream's rate (each at least one sample, except the
    pre-trigger and the onset search after the AIC pick, which may be 0)."""

    sta: int
    lta: int
    pre: int                  # pre-trigger
    post: int                 # shortest record after the onset
    max_post: int             # longest record after the onset
    envelope: int
    hold: int                 # re-arm hold
    double: int               # double-hit window
    guard: int                # AR fit starts this far after the onset
    fit: int                  # AR fit window
    innovation: int           # innovation STA
    order: int                # AR taps
    aic_pre: int
    aic_post: int
    search: tuple[int, int]   # hinge search before / after the AIC pick
    edge_pre: int
    edge_post: int
    look: int                 # look-ahead a detection needs before its onset is refined
    spare: int                # ring spare
    settle: int               # blind after the start or a long gap (lta / 4)
    short_gap: int            # longest gap the STA and LTA survive (lta)

    @classmethod
    def at(cls, s: TriggerSettings, fs_hz: float) -> _Lengths:
        """Lengths of settings ``s`` at ``fs_hz``. ValueError, naming the setting and the value
        to set, for a length the rate cannot resolve: refused here, never mid-stream."""
        needs = _samples_needed(s)

        def n(name: str) -> int:
            seconds = getattr(s, name)
            k, (need, what) = round(seconds * fs_hz), needs[name]
            if k < need:
                raise ValueError(
                    f"{name} ({seconds} s) is {seconds * fs_hz:.3g} sample"
                    f"{'' if seconds * fs_hz == 1 else 's'} at {fs_hz:g} Hz; "
                    f"{what} needs at least {need}: set {name} to at least {need / fs_hz:.3g} s"
                    + (", or a lower ar_order" if name == "ar_fit_s" and s.ar_order else
                       f", or leave it to TriggerSettings.for_rate({fs_hz:g})"))
            return k

        def c(seconds: float, minimum: int = 1) -> int:  # the trigger's own windows
            return max(minimum, round(seconds * fs_hz))

        sta, lta = n("sta_s"), round(s.lta_s * fs_hz)
        if sta >= lta:
            raise ValueError(f"sta_s ({s.sta_s}) must be shorter than lta_s ({s.lta_s})")
        fit = n("ar_fit_s")
        order = min(32, fit // 3) if s.ar_order is None else int(s.ar_order)
        search = (c(_EDGE_SEARCH_S[0]), c(_EDGE_SEARCH_S[1], 0))
        # every AIC window spans at least the look after the detection: 2 margins + 1 sample
        aic_post = max(c(_AIC_POST_S), 2 * _AIC_MARGIN)
        # and the residual pick, which starts half of aic_pre before it, 2 margins too
        aic_pre = max(c(_AIC_PRE_S), 4 * _AIC_MARGIN)
        edge_post = max(c(_EDGE_POST_S), search[1] + 3)
        look = aic_post + edge_post + 2
        envelope, hold = n("envelope_s"), n("rearm_hold_s")
        if envelope + hold <= look:
            raise ValueError(f"envelope_s + rearm_hold_s ({s.envelope_s + s.rearm_hold_s}) must "
                             f"be longer than the onset look-ahead ({look / fs_hz} s)")
        return cls(sta=sta, lta=lta, pre=c(s.pre_trigger_s, 0), post=n("post_s"),
                   max_post=n("max_post_s"), envelope=envelope, hold=hold,
                   double=n("double_hit_s"), guard=n("ar_guard_s"), fit=fit,
                   innovation=n("innovation_sta_s"), order=order, aic_pre=aic_pre,
                   aic_post=aic_post, search=search,
                   edge_pre=max(c(_EDGE_PRE_S), search[0] + 3), edge_post=edge_post,
                   look=look, spare=c(_RING_SPARE_S), settle=max(1, lta // 4), short_gap=lta)


@dataclass(frozen=True, eq=False)
class ImpactRecord:
    """Samples of one impact, all channels: ``counts`` int32 (n_channels, n_samples), SI
    ``scale`` (n_channels,), from ``first_sample`` (device time ``t0_ns``) at ``fs_hz``."""

    first_sample: int
    t0_ns: int
    fs_hz: float
    counts: np.ndarray
    scale: np.ndarray

    @property
    def last_sample(self) -> int:
        return self.first_sample + self.counts.shape[1] - 1

    def values(self, stop: int | None = None) -> np.ndarray:
        """Samples in SI units, float64, shape (n_channels, n_samples) — the first ``stop``
        samples only when given (only those are converted)."""
        return self.counts[:, :stop] * self.scale[:, None]


NO_BLOW = "no blow"
"""How ``not_analysable`` begins for an onset that added no energy (:meth:`Trigger._no_blow`)."""


@dataclass(frozen=True)
class ImpactEvent:
    """One detected blow. Samples count from the stream's first sample; times are s since it.

    ``onset_s`` is the refined (sub-sample) onset with the front-end delay removed and
    ``onset_sample`` its nearest sample; ``trigger_sample`` is where the detector fired. The
    record spans ``first_sample .. last_sample`` (inclusive). ``peak`` is max |value| per channel
    over ``onset .. last_sample`` (SI units); ``snr_db`` is 20 log10(peak / pre-event rms) on the
    best responding channel. ``too_short``: the record was cut (gap, next impact, end of stream)
    before ``post_s`` or lacks part of its pre-trigger. ``end_reason``: ``decayed``,
    ``max_length``, ``next_impact``, ``gap`` or ``flush``. ``decay_s``: onset to the decay at the
    noise floor (or to re-arm, if that came first), or ``None`` if the envelope never came
    back. ``not_analysable``: why a blow that was seen cannot be analysed (``"trigger still
    arming ..."``, ``"onset ... after a gap ..."``, ``"no blow: ..."``), else ``None``.
    """

    onset_sample: int
    onset_s: float
    t_ns: int
    trigger_sample: int
    first_sample: int
    last_sample: int
    fs_hz: float
    mode: str
    channels: tuple[str, ...]
    gages: tuple[int, ...]
    peak: dict[str, float]
    snr_db: float
    double_hit: bool = False
    second_onset_sample: int | None = None
    second_onset_s: float | None = None
    clipped: tuple[str, ...] = ()
    too_short: bool = False
    end_reason: str = "decayed"
    decay_s: float | None = None
    not_analysable: str | None = None
    record: ImpactRecord | None = field(default=None, compare=False, repr=False)

    def to_json(self) -> dict[str, Any]:
        """Plain JSON object for ``/ramdaq/impacts`` (the record's samples are not included)."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "record"}
        return {k: list(v) if isinstance(v, tuple) else v for k, v in out.items()} | {
            "peak": dict(self.peak)}


IMPACT_JSON_SCHEMA: dict[str, Any] = {
    "title": "ramdaq.Impact", "type": "object",
    "required": ["onset_sample", "onset_s", "t_ns", "first_sample", "last_sample", "channels",
                 "peak", "double_hit", "clipped", "too_short", "end_reason"],
    "properties": {
        "onset_sample": {"type": "integer"}, "onset_s": {"type": "number"},
        "t_ns": {"type": "integer", "description": "device time of the onset, ns"},
        "trigger_sample": {"type": "integer"}, "first_sample": {"type": "integer"},
        "last_sample": {"type": "integer"}, "fs_hz": {"type": "number"},
        "mode": {"enum": ["sta_lta", "force"]},
        "channels": {"type": "array", "items": {"type": "string"}},
        "gages": {"type": "array", "items": {"type": "integer"}},
        "peak": {"type": "object", "additionalProperties": {"type": "number"}},
        "snr_db": {"type": "number"}, "double_hit": {"type": "boolean"},
        "second_onset_sample": {"type": ["integer", "null"]},
        "second_onset_s": {"type": ["number", "null"]},
        "clipped": {"type": "array", "items": {"type": "string"}},
        "too_short": {"type": "boolean"},
        "end_reason": {"enum": ["decayed", "max_length", "next_impact", "gap", "flush"]},
        "decay_s": {"type": ["number", "null"]},
        "not_analysable": {"type": ["string", "null"],
                           "description": "why a blow that was seen cannot be analysed"},
    },
}
"""JSON Schema of :meth:`ImpactEvent.to_json`, for the ``/ramdaq/impacts`` topic."""


@dataclass(frozen=True)
class StreamHealth:
    """What the trigger could not see so far: ``gaps`` in the stream and the stream time, s,
    ``missing_s`` in them; ``blind_s`` when no blow could have been seen (the missing samples
    and the settling after the start or a long gap); ``arming_s`` when a blow would be seen
    but not analysed (the rest of the LTA window)."""

    gaps: int
    missing_s: float
    blind_s: float
    arming_s: float

    def to_json(self) -> dict[str, Any]:
        return {"gaps": self.gaps, "missing_s": self.missing_s, "blind_s": self.blind_s,
                "arming_s": self.arming_s}


@dataclass
class _Tally:
    """Counts behind :class:`StreamHealth`, in samples."""

    gaps: int = 0
    missing: int = 0
    blind: int = 0
    arming: int = 0


class _Ring:
    """The last ``history`` samples (at least) of every channel, int32, by sample index."""

    def __init__(self, n_channels: int, history: int) -> None:
        self.history = history
        self.buf = np.zeros((n_channels, 2 * history), dtype=np.int32)
        self.start = self.end = 0

    def reset(self, at: int) -> None:
        self.start = self.end = at

    def write(self, first: int, counts: np.ndarray) -> None:
        n = counts.shape[1]
        if self.buf.shape[1] < self.history + n:  # a long block: grow, keeping the history
            keep = max(self.start, self.end - self.history)
            old = self.read(keep, self.end)
            self.buf = np.zeros((len(self.buf), self.history + 2 * n), dtype=np.int32)
            self.start = self.end = keep
            self._put(keep, old)
        self._put(first, counts)

    def _put(self, first: int, counts: np.ndarray) -> None:
        n, cap = counts.shape[1], self.buf.shape[1]
        i = first % cap
        k = min(n, cap - i)
        self.buf[:, i:i + k] = counts[:, :k]
        self.buf[:, :n - k] = counts[:, k:]
        self.end = first + n
        self.start = max(self.start, self.end - cap)

    def read(self, a: int, b: int, rows: Any = slice(None)) -> np.ndarray:
        if not self.start <= a <= b <= self.end:
            raise IndexError(f"samples {a}..{b} are not in the ring ({self.start}..{self.end})")
        cap = self.buf.shape[1]
        i, j = a % cap, a % cap + (b - a)
        if j <= cap:
            return self.buf[rows, i:j]
        return np.concatenate([self.buf[rows, i:], self.buf[rows, :j - cap]], axis=-1)


@dataclass
class _Levels:
    """The detector's running averages of the voting channels' power (units^2): STA and LTA at
    the last sample taken, and how many samples the LTA has taken since it started from zero."""

    sta: np.ndarray
    lta: np.ndarray
    n: int = 0

    def restart(self) -> None:
        self.sta, self.lta, self.n = np.zeros(len(self.sta)), np.zeros(len(self.lta)), 0

    def advance_lta(self, x2: np.ndarray, nlta: int) -> np.ndarray:
        """Take ``x2`` (power, (n_voters, n)) into the LTA; its value at each sample, unbiased."""
        lta, self.lta = ons.exp_average(x2, nlta, self.lta)
        m0, self.n = self.n, self.n + x2.shape[1]
        if m0 < 20 * nlta:  # undo the bias of an average started from zero
            lta = lta / -np.expm1(np.arange(m0 + 1, self.n + 1) * np.log1p(-1 / nlta))
        return lta

    def pre_power(self, nlta: int, floor: np.ndarray) -> np.ndarray:
        """The unbiased LTA now, at least ``floor``: the pre-event level of a blow detected here."""
        if self.n == 0:  # nothing averaged yet (a blow at the stream's first sample)
            return floor.copy()
        bias = -math.expm1(self.n * math.log1p(-1 / nlta))
        return np.maximum(self.lta / bias, floor)


@dataclass(frozen=True, eq=False)
class _Whitener:
    """AR prediction-error filter fitted to a ringing (``a``, shape (order + 1,)), the
    innovation's variance per responding gage it is expected to leave after its fit window
    (``var``, units^2), and the window's first sample (``start``)."""

    a: np.ndarray
    var: np.ndarray
    start: int = 0


@dataclass
class _ContactScan:
    """Where the second-contact detector stands: it scans from ``pos`` (innovation power
    ``level`` at ``pos - 1``), is still ``on`` from the last contact, last went off at
    ``off_pos``, and lets no new contact count before ``dead_until``. A blow that follows while
    the last one still rings takes the scan over, filter and all."""

    pos: int = 0
    on: bool = True
    level: np.ndarray | None = None
    off_pos: int = 0
    dead_until: int = 0
    whitener: _Whitener | None = None
    ref: np.ndarray | None = None          # the innovation's running mean, units^2
    ref_trace: np.ndarray | None = field(default=None, repr=False)  # its values in the last
    # scan, [:, i] up to its sample i


@dataclass
class _DecayWatch:
    """The envelope of the monitored channels from the onset: its value ``level`` (units^2) at
    ``pos - 1``, how many samples in a row it has been near the pre-event level (``hold``), and
    the sample where that lasted the re-arm hold (``decayed``)."""

    level: np.ndarray
    pos: int
    hold: int = 0
    decayed: int | None = None


@dataclass
class _RiseWatch:
    """The energy watch on a ringing (:meth:`Trigger._scan_rise`): the STA and the envelope
    (units^2, per responding voter) at ``pos - 1``, and the sample where a new blow showed
    (``found``), kept until the event hands over to it."""

    sta: np.ndarray
    env: np.ndarray
    pos: int
    counts_from: int  # the first sample where a rise counts
    found: int | None = None


@dataclass
class _Event:
    """An event being recorded: detected at ``detect`` over a pre-event power ``pre`` (units^2,
    per voting channel); ``voters`` the responding ones (indices into the voters, empty until
    the onset is refined); ``onset`` -1 until refined; ``second`` (sample, s) of a second contact
    (s None until refined); ``cut`` the previous event, to close at this one's onset; ``end`` the
    record's last sample, -1 while ringing; ``not_analysable`` why it cannot be analysed;
    ``recorded`` False for the ringing of a blow whose record a gap closed, followed after the
    gap to its decay (so it cannot trigger) and scanned for new blows, with no record of its
    own to hand over; ``check_until`` where its STA check (:meth:`Trigger._ring_check`) ends."""

    detect: int
    pre: np.ndarray
    cut: _Event | None = None
    voters: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    scan: _ContactScan = field(default_factory=_ContactScan)
    decay: _DecayWatch | None = None
    onset: int = -1
    onset_s: float = 0.0
    second: tuple[int, float | None] | None = None
    end: int = -1
    end_reason: str = "decayed"
    not_analysable: str | None = None
    recorded: bool = True
    check_until: int = 0
    floor: FloorWatch | None = None
    rise: _RiseWatch | None = None


@dataclass(frozen=True)
class RecordBackground:
    """What a whole record says of its background, for a trigger armed on it offline
    (:meth:`Trigger.arm_on_record`): the voting channels' background ``power`` (units^2, shape
    (n_voters,)); the force channel's baseline ``force_base_N`` (its median, N; a load cell's
    offset), its noise ``force_noise_N`` (robust rms, N) and the force ``level_N`` the trigger
    then uses (N; ``None`` without a force channel)."""

    power: np.ndarray
    force_base_N: float = 0.0
    force_noise_N: float = 0.0
    level_N: float | None = None


def record_background(x: np.ndarray, voters: np.ndarray, force: int | None,
                      settings: TriggerSettings, lta_n: int,
                      force_row: np.ndarray | None = None) -> RecordBackground:
    """The background of the whole record ``x`` (SI, (n_channels, n), NaN where a gap is):
    per voter the mean power of the quietest stretch of ``lta_n / 4`` samples in its first
    :data:`_START_LTAS` LTA windows, where the arming matters (after it the LTA follows the
    record as live; a background that changes over a record, a fading tone, stays right). The
    stretch is the settling
    window: half a period of a 1 Hz tone, so a steady tone counts as background, as the live
    LTA has it; the quietest, because a trial's blows may ring through most of it: the median
    power of a trial with a blow every 4 s is its ringing's, ten times its background). With a
    force channel (row ``force``), its median and robust rms (MAD) and a level of 20 noise rms
    and a tenth of the largest blow, at most ``settings.level_N``: a hammer's record (a few N
    to a few hundred) triggers as a ram's does. Only the record's first ``_START_LTAS`` LTAs
    of the voters are read, and the force row whole: ``force_row``, when given, is that row
    (every sample of the record, in any order) and ``x`` may then be the record's head."""
    if x.shape[-1] == 0:  # an empty record: nothing to arm on
        return RecordBackground(np.zeros(len(voters)),
                                level_N=None if force is None else settings.level_N)
    v = x[voters]
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN channel: no background
        w = max(1, min(lta_n // 4, x.shape[1]))
        m = max(1, min(x.shape[1], _START_LTAS * lta_n) // w)  # near the start: it is armed
        windows = (v[:, :m * w] ** 2).reshape(len(voters), m, w)
        power = np.nan_to_num(np.nanmin(np.nanmean(windows, axis=2), axis=1), nan=0.0)
        if force is None:
            return RecordBackground(power)
        f = x[force] if force_row is None else np.asarray(force_row, dtype=np.float64)
        base = float(np.nan_to_num(np.nanmedian(f)))
        noise = float(np.nan_to_num(_MAD_SIGMA * np.nanmedian(np.abs(f - base))))
        peak = float(np.nan_to_num(np.nanmax(np.abs(f - base))))
    level = min(settings.level_N, max(_FORCE_NOISE_LEVELS * noise, _FORCE_PEAK_FRACTION * peak))
    return RecordBackground(power, base, noise, level if level > 0 else settings.level_N)


class Trigger:
    """Stateful impact trigger over a block stream; see the module docstring.

    Parameters
    ----------
    info : StreamInfo
        The stream: channel names, units, gage numbers, ``fs_hz``, ``rig_toml``, ``extra``.
    settings : TriggerSettings, optional
        Default ``TriggerSettings.for_rate(info.fs_hz, n_voters)``: the defaults, lengthened
        where the stream's rate cannot resolve them, voting k of at most the stream's gages.

    Raises
    ------
    ValueError
        A setting the stream cannot meet (its channels, its rate), or a rig in ``info.rig_toml``
        that does not say its anti-alias filter while ``settings.delay_s`` is not given.
    """

    def __init__(self, info: StreamInfo, settings: TriggerSettings | None = None) -> None:
        s = TriggerSettings.for_rate(info.fs_hz, n_voters=sum(g > 0 for g in info.gages)) \
            if settings is None else settings
        self.info, self.settings, self.fs_hz = info, s, float(info.fs_hz)
        self._len = _Lengths.at(s, self.fs_hz)
        self._vidx, self._k = _voting_rows(info, s)
        self._all_vote = np.array_equal(self._vidx, np.arange(info.n_channels))  # no row copy
        self._block_x2 = (0, np.zeros((len(self._vidx), 0)))  # the latest block's x**2, voters
        self._fidx = _force_row(info, s)
        self.mode = "sta_lta" if self._fidx is None else "force"
        anti_alias = _anti_alias_or_none(info) if s.delay_s is not None else _rig_anti_alias(info)
        self.delay_s = float(s.delay_s) if s.delay_s is not None else (
            0.0 if anti_alias is None else ons.butterworth_delay_s(*anti_alias, self.fs_hz))
        self._delay_n = self.delay_s * self.fs_hz
        self._noise_bw = noise_bandwidth_fraction(anti_alias, self.fs_hz)
        bits = info.extra.get("adc_bits")
        self._rails = None if bits is None else (-(2 ** (int(bits) - 1)), 2 ** (int(bits) - 1) - 1)
        n = self._len
        self._ring = _Ring(info.n_channels, n.pre + n.max_post + n.spare)
        self._scale = np.ones(info.n_channels)
        self._expected: int | None = None           # first sample of the next block, if no gap
        self._seg = (0, 0)                          # (first sample, t0_ns) since the last gap
        self._after_gap = False                     # that segment began at a gap
        self._tally = _Tally()
        self._state = NOT_READY
        self._levels = _Levels(np.zeros(len(self._vidx)), np.zeros(len(self._vidx)))
        self._f_below = True                        # force fell below hysteresis since the last contact
        self._f_base, self._f_level = 0.0, s.level_N  # force baseline and level, N
        self._background: RecordBackground | None = None  # offline: armed on the whole record
        self._double_on_k: dict[int, float] = {}    # second-contact ratio for fewer voters
        self._ev: _Event | None = None
        self._prev_onset: int | None = None          # the last finished event's onset sample

    # -- public ----------------------------------------------------------------------------
    @property
    def state(self) -> str:
        """``"not ready"``, ``"arming"``, ``"armed"`` or ``"active"``."""
        if self._state == ARMED and self._levels.n < self._len.lta:
            return ARMING
        return self._state

    @property
    def health(self) -> StreamHealth:
        """Gaps, missing samples, blind and arming time so far."""
        t, fs = self._tally, self.fs_hz
        return StreamHealth(t.gaps, t.missing / fs, t.blind / fs, t.arming / fs)

    @property
    def ringing(self) -> tuple[int, int] | None:
        """``(onset_sample, end_sample)`` of the impact being recorded now, or ``None``: the
        refined onset once known (else the detection sample) and one past the latest sample.
        For an analyzer that wants a first look before the record completes."""
        ev = self._ev
        if ev is None or self._state != ACTIVE or not ev.recorded:
            return None
        return (ev.onset if ev.onset >= 0 else ev.detect), self._ring.end

    def recent(self, first: int, end: int) -> np.ndarray:
        """Samples ``first .. end-1`` of every channel from the pre-trigger ring, SI units,
        shape (n_channels, end - first). Raises IndexError if they are no longer held."""
        return self._values(first, end, slice(None))

    @property
    def head_samples(self) -> int:
        """Samples of a record's start that :meth:`arm_on_record` reads of the gages (the rest
        of the record only through its force channel)."""
        return _START_LTAS * self._len.lta

    @property
    def force_channel(self) -> int | None:
        """The row of the force channel the trigger uses, or None (acceleration alone)."""
        return self._fidx

    def arm_on_record(self, values: np.ndarray,
                      force_row: np.ndarray | None = None) -> RecordBackground:
        """Offline (a whole file: import, analyze): arm on the whole record before its first
        block, so that a blow at its first sample is found and analysable. The LTA starts from
        the record's background (:func:`record_background`) and the trigger is armed from the
        first sample (no settling, no arming); with a force channel, its baseline is taken off
        and the level is the record's (at most ``level_N``); a blow that begins before the
        record's first samples has its onset where its force (or, without one, its power)
        rises from the baseline, at the first sample at the latest. ``values``: the record in
        SI units, shape (n_channels, n_samples), NaN in gaps -- or its first
        :attr:`head_samples` when ``force_row`` gives the force channel's every sample (a
        record read block by block). What it armed on is returned."""
        values = np.asarray(values, dtype=np.float64)
        if values.ndim != 2 or values.shape[0] != self.info.n_channels:
            raise ValueError(f"record of shape {values.shape} is not ({self.info.n_channels}, n)")
        if self._expected is not None:
            raise ValueError("arm_on_record must come before the first block")
        bg = record_background(values, self._vidx, self._fidx, self.settings, self._len.lta,
                               force_row)
        self._background = bg
        if self._fidx is not None:
            self._f_base, self._f_level = bg.force_base_N, float(bg.level_N)
        return bg

    def process(self, block: Block) -> list[ImpactEvent]:
        """Feed the next block; returns the events whose records completed in it."""
        if block.n_channels != self.info.n_channels or block.fs_hz != self.fs_hz:
            raise ValueError(f"block of {block.n_channels} channels at {block.fs_hz} Hz does not "
                             f"match the stream ({self.info.n_channels} at {self.fs_hz} Hz)")
        out: list[ImpactEvent] = []
        if block.first_sample != self._expected:
            out += self._new_segment(block)
        self._expected = block.next_sample
        self._ring.write(block.first_sample, block.counts)
        self._scale = block.scale
        x2 = (block.counts * block.scale[:, None] if self._all_vote
              else block.counts[self._vidx] * block.scale[self._vidx, None])
        np.multiply(x2, x2, out=x2)  # x * x, in x's array
        self._block_x2 = (block.first_sample, x2)
        sta, self._levels.sta = ons.exp_average(x2, self._len.sta, self._levels.sta)
        self._run(block.first_sample, x2, sta, out)
        return out

    def flush(self) -> list[ImpactEvent]:
        """End of stream: close the event being recorded, if any (``end_reason="flush"``)."""
        out = self._close("flush")
        self._expected = None
        return out

    # -- state machine -----------------------------------------------------------------------
    def _new_segment(self, block: Block) -> list[ImpactEvent]:
        """``block`` does not follow the last one: the start of the stream, or a gap (the
        module docstring says what each does). The events the gap closed."""
        if self._expected is None:  # the start, or a new stream after flush()
            self._restart(block, after_gap=False)
            return []
        missing = block.first_sample - self._expected
        self._tally.gaps += 1
        self._tally.missing += max(0, missing)
        self._tally.blind += max(0, missing)
        ev, active = self._ev, self._state == ACTIVE
        out = self._close("gap")
        if not 0 < missing <= self._len.short_gap:
            self._restart(block, after_gap=True)
            return out
        self._seg, self._after_gap = (block.first_sample, block.t0_ns), True
        self._ring.reset(block.first_sample)
        if active:
            self._ev = self._ringing_after_gap(ev, block.first_sample)
        return out

    def _ringing_after_gap(self, ev: _Event, first: int) -> _Event:
        """The ringing of ``ev`` (its record closed at a gap) from sample ``first`` on: its
        envelope goes on from where it was; its contact scan from where the AR filter has the
        ``ar_order`` samples it needs (or, if the gap came before the filter was fitted, after
        the fit on the samples after the gap). Until then the STA against the ringing's level
        stands in (:meth:`_ring_check`), once the envelope has caught up with the ringing (two
        ``envelope_s`` after the onset: before, it is still below the ringing's power); before
        that, those samples are blind and counted so."""
        n = self._len
        decay = ev.decay or _DecayWatch(level=ev.pre.copy(), pos=first)
        decay.pos, decay.hold = first, 0
        scan = ev.scan
        if self._fidx is not None:
            start = first
        elif scan.whitener is None:
            start = max(ev.onset + n.guard, first) + n.fit
        else:
            start = first + n.order
        scan.pos = scan.off_pos = start
        scan.level, scan.ref, scan.dead_until = None, None, max(scan.dead_until, first)
        settled = first - ev.onset >= 2 * n.envelope
        self._tally.blind += 0 if settled else start - first
        return _Event(detect=ev.detect, pre=ev.pre, voters=ev.voters, scan=scan, decay=decay,
                      onset=ev.onset, onset_s=ev.onset_s, recorded=False,
                      check_until=start if settled else first)

    def _ring_check(self, ev: _Event, pos: int, b0: int, end: int, sta: np.ndarray) -> None:
        """While the AR scan of a ringing after a gap cannot start: a blow where ``k`` voters'
        STA exceed ``on`` times the ringing's level (its envelope, or the pre-event level if
        higher) opens a new event, as the scan would."""
        stop = min(end, ev.check_until)
        if stop <= pos:
            return
        ref = self.settings.on * np.maximum(ev.pre, ev.decay.level)
        hit = np.flatnonzero((sta[:, pos - b0:stop - b0] > ref[:, None]).sum(axis=0) >= self._k)
        if hit.size == 0:
            return
        d = pos + int(hit[0])
        ev.check_until, ev.scan.on = 0, True
        ev.scan.dead_until = max(ev.scan.dead_until, d + self._len.guard)
        self._ev = _Event(detect=d, pre=ev.pre, cut=ev, voters=ev.voters, scan=ev.scan)

    def _hand_over(self, ev: _Event, out: list[ImpactEvent]) -> None:
        """A completed event to the caller (the ringing after a gap has nothing to give)."""
        if ev.recorded:
            out.append(self._finish(ev))

    def _restart(self, block: Block, after_gap: bool) -> None:
        """Start again as at the beginning of a stream, from ``block``."""
        self._state, self._ev = NOT_READY, None
        self._levels.restart()
        self._seg, self._after_gap = (block.first_sample, block.t0_ns), after_gap
        self._ring.reset(block.first_sample)
        self._f_below = True
        if self._background is not None:  # offline: armed on the whole record from here
            self._levels.lta, self._levels.n = self._background.power.copy(), 20 * self._len.lta
            self._state = ARMED

    def _resume(self, ev: _Event) -> None:
        """The detector goes on after the ringing of ``ev``: the LTA resumes from the pre-event
        level, or from what still rings if higher, as a full average."""
        self._f_below = not ev.scan.on
        self._levels.lta = ev.pre if ev.decay is None else np.maximum(ev.pre, ev.decay.level)
        self._levels.n = max(self._levels.n, 20 * self._len.lta)

    def _run(self, b0: int, x2: np.ndarray, sta: np.ndarray, out: list[ImpactEvent]) -> None:
        end, pos, nlta = b0 + x2.shape[1], b0, self._len.lta
        while True:
            ev = self._ev
            if self._state == NOT_READY:  # blind: the LTA settles
                if pos >= end:
                    return
                stop = min(end, pos + max(0, self._len.settle - self._levels.n))
                d = self._settling_blow(pos, stop)
                self._levels.advance_lta(x2[:, pos - b0:(stop if d is None else d) - b0], nlta)
                self._tally.blind += (stop if d is None else d) - pos
                if d is not None:
                    self._ev = _Event(detect=d, pre=self._levels.pre_power(
                        nlta, self._scale[self._vidx] ** 2 / 12), not_analysable=self._arming_note())
                    self._state, pos = ACTIVE, d
                    continue
                pos = stop
                if self._levels.n >= self._len.settle:
                    self._state = ARMED
            elif self._state == ARMED:
                if ev is not None and ev.end < pos:
                    self._hand_over(ev, out)
                    self._ev = None
                    continue
                if pos >= end:
                    return
                limit = end if ev is None else min(end, ev.end + 1)
                d = self._detect(pos, limit, b0, x2, sta)
                if d is None:
                    pos = limit
                else:
                    floor = self._scale[self._vidx] ** 2 / 12
                    self._ev = _Event(detect=d, pre=self._levels.pre_power(nlta, floor), cut=ev,
                                      not_analysable=self._arming_note())
                    self._state, pos = ACTIVE, d
            else:
                if ev.check_until > pos:
                    self._ring_check(ev, pos, b0, end, sta)
                r = self._advance(end, out)
                if r is None:
                    return
                self._state, pos = ARMED, r

    def _settling_blow(self, pos: int, stop: int) -> int | None:
        """With a load cell, a blow while the LTA settles (``pos .. stop-1``): the force needs
        no background to be seen, so the blow is reported (not analysable: its pre-event level
        rests on too little), not lost. None without a force channel or a blow."""
        if self._fidx is None or stop <= pos:
            return None
        hit = np.flatnonzero(self._force_hits(pos, stop))
        return pos + int(hit[0]) if hit.size else None

    def _arming_note(self) -> str | None:
        """Why a blow detected now cannot be analysed, if the trigger is still arming."""
        if self._levels.n >= self._len.lta:
            return None
        return (f"trigger still arming ({self._levels.n / self.fs_hz:.2f} s of its "
                f"{self.settings.lta_s:g} s LTA window averaged)")

    def _values(self, a: int, b: int, rows: Any) -> np.ndarray:
        return self._ring.read(a, b, rows) * self._scale[rows, None]

    def _squares(self, a: int, b: int) -> np.ndarray:
        """``x * x`` of the voting rows at samples ``a .. b-1`` (units^2): the block's own,
        squared once in :meth:`process`, where it holds them (the same numbers: counts times
        the same scale, squared), else from the ring."""
        b0, x2 = self._block_x2
        if b0 <= a and b <= b0 + x2.shape[1]:
            return x2[:, a - b0:b - b0]
        x = self._values(a, b, self._vidx)
        return x * x

    def _detect(self, pos: int, limit: int, b0: int, x2: np.ndarray, sta: np.ndarray) -> int | None:
        """First trigger in ``pos .. limit-1`` while armed; the LTA advances up to it."""
        seg = slice(pos - b0, limit - b0)
        levels, nlta, s = self._levels, self._len.lta, self.settings
        lta_last, m0 = levels.lta, levels.n
        lta = levels.advance_lta(x2[:, seg], nlta)
        if self._fidx is None:
            hit = (sta[:, seg] > np.multiply(s.on, lta, out=lta)).sum(axis=0) >= self._k
        else:
            hit = self._force_hits(pos, limit)
        idx = np.flatnonzero(hit)
        taken = int(idx[0]) if idx.size else limit - pos
        self._tally.arming += max(0, min(taken, nlta - m0))
        if idx.size == 0:
            return None
        j = int(idx[0])
        levels.lta = lta_last if j == 0 else ons.exp_average(
            x2[:, seg.start:seg.start + j], nlta, lta_last)[1]
        levels.n = m0 + j
        return pos + j

    def _force_hits(self, pos: int, limit: int) -> np.ndarray:
        """Where the ram force (or its slope) is at the trigger level in ``pos .. limit-1``,
        counting only after it has fallen below the hysteresis level since the last contact."""
        s = self.settings
        f = self._values(max(pos - 1, self._ring.start), limit, [self._fidx])[0] - self._f_base
        slope = (np.abs(np.diff(f, prepend=f[0])) * self.fs_hz)[-(limit - pos):]
        f = np.abs(f[-(limit - pos):])
        hit = f >= self._f_level
        if s.slope_N_per_s is not None:
            hit |= slope >= s.slope_N_per_s
        if not self._f_below:
            below = np.flatnonzero(f < s.hysteresis * self._f_level)
            hit[:below[0] if below.size else hit.size] = False
            self._f_below = bool(below.size)
        return hit

    def _advance(self, end: int, out: list[ImpactEvent]) -> int | None:
        """Work through the active event up to sample ``end``; the re-arm sample, or None."""
        n = self._len
        while True:
            ev = self._ev
            if ev.onset < 0:
                if end < ev.detect + n.look:
                    return None
                self._refine(ev, out)
            self._refine_second(ev, end)
            max_end = ev.onset + n.max_post
            if (self._fidx is None and ev.scan.whitener is None
                    and end >= self._fit_start(ev) + n.fit):
                self._fit(ev)
            r = self._scan_decay(ev, min(end, max_end + 1))
            # the floor judged no further than the re-arm's sample: the record ends at whichever
            # comes first in the stream, whatever the blocks' length (judged past it on a long
            # block, the floor could end a record the re-arm had ended earlier on short ones)
            self._close_at_floor(ev, min(end, max_end + 1) if r is None else min(end, r + 1), out)
            s = self._next_contact(ev, end, r)
            if s is not None and s < 0:  # waits for samples
                return None
            if s is not None and s - ev.onset <= n.double and ev.recorded:
                ev.second = ev.second or (s, None)
            elif s is not None:  # a new blow while the last one still rings: it takes the scan
                self._ev = _Event(detect=s, pre=ev.pre, cut=ev, voters=ev.voters, scan=ev.scan)
            elif r is not None or ev.decay.pos > max_end:
                return self._rearm(ev, r, max_end)
            else:
                return None

    def _rearm(self, ev: _Event, decayed: int | None, max_end: int) -> int:
        """End the ringing of ``ev`` (decayed at ``decayed``, else at ``max_end``): set its
        record's end and resume the detector; the sample it resumes at."""
        self._resume(ev)
        if decayed is not None:
            ev.end = min(max(decayed, ev.onset + self._len.post), max_end)
            return decayed + 1
        ev.end, ev.end_reason = max_end, "max_length"
        return max_end + 1

    def _close_at_floor(self, ev: _Event, limit: int, out: list[ImpactEvent]) -> None:
        """Hand over the record of ``ev`` once its decay is at the noise floor
        (:mod:`ramdaq.daq.decay_end`); its ringing is still followed to the re-arm, as the
        ringing after a gap is, with no record of its own."""
        if not ev.recorded:
            return
        if ev.floor is None:
            ev.floor = FloorWatch.begin(ev.pre[ev.voters], ev.onset, self._len.post, self.fs_hz,
                                        self._noise_bw)
        end = ev.floor.scan(lambda a, b: self._squares(a, b)[ev.voters], limit, squared=True)
        if end is not None:
            ev.end, ev.end_reason = end, "decayed"
            self._hand_over(ev, out)
            ev.recorded = False

    def _edge(self, rows: Any, noise_var: np.ndarray | None, a: int, d: int) -> float:
        """AIC pick in ``a .. d + aic_post``, refined by the hinge fit when the ring allows."""
        n = self._len
        pick = a + ons.aic_pick(self._values(a, d + n.aic_post + 1, rows), _AIC_MARGIN)
        lo, hi = pick - n.edge_pre, pick + n.edge_post + 1
        if lo < self._ring.start or hi > self._ring.end:
            return float(pick)
        return lo + ons.hinge_onset(self._values(lo, hi, rows), n.edge_pre, pre_n=n.edge_pre,
                                    post_n=n.edge_post, search_n=n.search, noise_var=noise_var)

    def _residual_pick(self, ev: _Event, d: int) -> float:
        """AIC pick of a blow at ``d`` on the innovation of the ringing it interrupts."""
        n = self._len
        a = max(d - n.aic_pre // 2, ev.scan.off_pos, self._ring.start + n.order)
        a = max(min(a, d - n.guard), self._ring.start + n.order)  # the max: after a gap
        x = self._values(a - n.order, d + n.aic_post + 1, self._vidx[ev.voters])
        return float(a + ons.aic_pick(ons.prediction_error(x, ev.scan.whitener.a), _AIC_MARGIN))

    def _refine(self, ev: _Event, out: list[ImpactEvent]) -> None:
        """The onset of ``ev`` to a fraction of a sample; closes the event it interrupts."""
        n, d = self._len, ev.detect
        a = max(self._ring.start, d - n.aic_pre)
        if ev.voters.size == 0:
            x = self._values(d, d + n.aic_post + 1, self._vidx)
            resp = np.flatnonzero((x * x).max(axis=1) > self.settings.on * ev.pre)
            ev.voters = resp if resp.size else np.arange(len(self._vidx))
        starts = not self._after_gap and d - self._ring.start < n.edge_pre + _AIC_MARGIN
        if self._fidx is not None:
            f = self._rise_start(ev, d) if starts else \
                self._edge([self._fidx], None, max(a, ev.scan.off_pos), d)
            ev.scan.pos, ev.scan.on = d + 1, True
        elif starts:  # the record starts with the blow: too few samples before it for the AIC
            f = self._rise_start(ev, d)
        elif ev.scan.whitener is None or d < self._ring.start + n.order:  # no innovation yet
            f = self._edge(self._vidx[ev.voters], ev.pre[ev.voters], a, d)
        else:  # the AR filter whitens the anti-alias filter too: no delay to remove
            f = self._residual_pick(ev, d) + self._delay_n
        f -= self._delay_n
        ev.onset, ev.onset_s = max(round(f), self._ring.start), f / self.fs_hz
        ev.decay = _DecayWatch(level=ev.pre.copy(), pos=ev.onset)
        if self._after_gap and ev.onset - n.edge_pre < self._ring.start and not ev.not_analysable:
            ev.not_analysable = (f"onset {1e3 * (f - self._ring.start) / self.fs_hz:.0f} ms after "
                                 f"a gap, within the {1e3 * n.edge_pre / self.fs_hz:.0f} ms the "
                                 f"onset fit needs before it: the blow may have begun in the gap")
        if ev.cut is not None:
            cut = ev.cut
            cut.end = max(min(cut.end if cut.end >= 0 else ev.onset, ev.onset) - 1, cut.onset)
            cut.end_reason = "next_impact"
            self._hand_over(cut, out)
            ev.cut = None

    def _rise_start(self, ev: _Event, d: int) -> float:
        """Onset of a blow detected at ``d`` too close to the record's first sample for the AIC
        and hinge fit (offline, a record that starts with the blow): the first sample of the
        rise that reaches ``d`` -- where ``|F|`` less its baseline last was below a tenth of the
        force level, or, without a force, fewer than ``k`` responding gages' power above ``on``
        times the pre-event level -- at the record's first sample if it rose before it."""
        a = self._ring.start
        if self._fidx is not None:
            f = np.abs(self._values(a, d + 1, [self._fidx])[0] - self._f_base)
            quiet = f < 0.1 * self._f_level
        else:
            x = self._values(a, d + 1, self._vidx[ev.voters])
            k = min(self._k, len(ev.voters))
            quiet = (x * x > self.settings.on * ev.pre[ev.voters, None]).sum(axis=0) < k
        below = np.flatnonzero(quiet)
        return float(a if below.size == 0 else a + below[-1] + 1)

    def _refine_second(self, ev: _Event, end: int) -> None:
        if ev.second is None or ev.second[1] is not None or end < ev.second[0] + self._len.look:
            return
        s = ev.second[0]
        if self._fidx is not None:
            f = self._edge([self._fidx], None, max(s - self._len.aic_pre, ev.scan.off_pos), s)
            f -= self._delay_n
        else:
            f = self._residual_pick(ev, s)
        ev.second = (round(f), f / self.fs_hz)

    def _fit_start(self, ev: _Event) -> int:
        """First sample of the AR fit window: ``ar_guard_s`` after the onset, or the first
        sample after a gap that came before it."""
        return max(ev.onset + self._len.guard, self._ring.start)

    def _fit(self, ev: _Event) -> None:
        """Fit the AR filter to the ringing of ``ev``; the second-contact scan starts after it."""
        n = self._len
        f0 = self._fit_start(ev)
        scan = ev.scan
        scan.whitener = self._whitener(ev, (f0, f0 + n.fit))
        var = scan.whitener.var
        scan.pos = scan.off_pos = f0 + n.fit
        scan.on, scan.level, scan.ref = False, var.copy(), var.copy()

    def _whitener(self, ev: _Event, *spans: tuple[int, int]) -> _Whitener:
        """The AR filter fitted to the voters of ``ev`` over the sample spans ``(a, b)``
        (``a .. b-1``, all of one length) at once."""
        order = self._len.order
        rows = self._vidx[ev.voters]
        x = np.vstack([self._values(a, b, rows) for a, b in spans])
        a = ons.ar_prediction_filter(x, order, np.tile(ev.pre[ev.voters], len(spans)))
        e = ons.prediction_error(x, a)
        # The fit's residual understates the innovation it will see after the window: by
        # (m - p) / m in the window, and by (1 + p / m) after it (least squares, m equations,
        # p taps shared by the gages). One gage at 2048 Hz has m = 41 for p = 20: the ringing's
        # innovation would be 2.9 times its fitted variance, and the STA over innovation_sta_s
        # passed double_on on the ringing every second (false double hits from ~40 ms on).
        m = e.size
        var = np.mean(e * e, axis=1) * (m / (m - order)) * (1 + order / m)
        var = var.reshape(-1, len(rows)).mean(axis=0)
        return _Whitener(a, np.maximum(var, self._scale[rows] ** 2 / 12), spans[0][0])

    def _confirm(self, ev: _Event, s: int, kk: int, closing: bool) -> bool | None:
        """Whether the innovation burst at ``s`` is a contact or the filter's extrapolation
        error. The filter is refitted to the ringing on either side of the burst, leaving out
        ``innovation_sta_s`` before it to twice that after it, up to :data:`_REFIT_SPAN` fit
        windows in all, and the burst tested again with the same STA, ratio and vote. A contact
        is a new impulse, which no filter of the ringing predicts from either side, so it stands
        out of the refit; a filter fitted to a few tens of ms that merely extrapolated badly
        (30 Hz and 8 Hz at 70 dB read 17x its variance 20 ms after its window) does not: the
        refit's hole is a few ms, the ringing's slowest period ~100. A burst already out of the
        filter refitted to the ringing just before it, over the whole span, is a contact at
        once (a filter fitted to both sides at 51.2 kHz absorbs much of a blow whose response
        starts as a ramp). True: a contact; False: not one, and the refit now whitens the
        scan; None: the samples after ``s`` are not in yet."""
        n, scan = self._len, ev.scan
        span = _REFIT_SPAN * n.fit // 2
        gap = (n.innovation, 2 * n.innovation)
        m = min(s - gap[0] - max(scan.whitener.start, self._ring.start), span)
        if m <= 2 * n.order:
            return True  # too little ringing before the burst to refit: it stands as found
        if self._ring.end < s + 4 * n.innovation:
            return None if not closing else True
        if m == span and self._stands_out(ev, s, kk, self._whitener(ev, (s - gap[0] - m,
                                                                     s - gap[0]))):
            return True
        late = min(m, self._ring.end - s - gap[1])
        if late < m and not closing:
            return None
        if late <= 2 * n.order:
            return True
        w = self._whitener(ev, (s - gap[0] - late, s - gap[0]), (s + gap[1], s + gap[1] + late))
        if self._stands_out(ev, s, kk, w):
            return True
        scan.whitener = w
        scan.pos, scan.on, scan.ref_trace = s, False, None
        scan.level, scan.ref = w.var.copy(), w.var.copy()
        # the scan goes on past this sample: where the refit still leaves the burst above the
        # scan's ratio it would find the same sample, refit the same and reject it again
        scan.dead_until = max(scan.dead_until, s + 1)
        return False

    def _stands_out(self, ev: _Event, s: int, kk: int, w: _Whitener) -> bool:
        """Whether ``kk`` voters' innovation STA under ``w``, from ``innovation_sta_s`` before
        ``s`` to four after, passes the second-contact ratio over ``w.var`` at one sample."""
        n = self._len
        a, b = s - n.innovation, s + 4 * n.innovation
        e = _innovation(self._values(a - n.order, b, self._vidx[ev.voters]), w.a)
        p, _ = ons.exp_average(e * e, n.innovation, w.var)
        return bool(((p > self._double_on(kk) * w.var[:, None]).sum(axis=0) >= kk).any())

    def _scan_decay(self, ev: _Event, limit: int) -> int | None:
        """Sample where the envelope has been back near the pre-event level for the hold."""
        w = ev.decay
        if w.decayed is not None or limit <= w.pos:
            return w.decayed
        a, n = w.pos, self._len
        env, last = ons.exp_average(self._squares(a, limit), n.envelope, w.level)
        ok = (env[ev.voters] / ev.pre[ev.voters, None]).max(axis=0) < self.settings.rearm_ratio
        ok[:max(0, ev.onset + n.envelope - a)] = False
        j, w.hold = ons.first_hold(ok, n.hold, w.hold)
        if j is None:
            w.level, w.pos = last, limit
            return None
        w.level, w.pos, w.decayed = env[:, j].copy(), a + j + 1, a + j
        return a + j

    def _next_contact(self, ev: _Event, end: int, decayed: int | None) -> int | None:
        """The next contact in the ringing of ``ev`` up to ``end`` (or to its re-arm sample
        ``decayed``): the innovation's (:meth:`_scan_sharp`), or a rise of its energy
        (:meth:`_scan_rise`) where the innovation shows none within ``ar_guard_s`` of it (then
        the innovation scan skips that span: the same blow cannot trigger twice); None if
        none, -1 while it waits for samples."""
        lim = end if decayed is None else decayed
        q = self._scan_rise(ev, lim)
        if q is None:
            return self._scan_sharp(ev, lim, closing=decayed is not None)
        stop = q + self._len.guard
        if end < stop:
            return -1
        s = self._scan_sharp(ev, stop)
        if s is not None:
            return s
        if ev.scan.whitener is not None and ev.scan.pos < stop:  # a burst awaits its refit
            return -1
        ev.scan.dead_until = max(ev.scan.dead_until, stop)
        return q

    def _scan_rise(self, ev: _Event, limit: int) -> int | None:
        """First sample, from ``double_hit_s`` after the onset of ``ev`` to ``limit - 1``, where
        ``k`` responding voters' STA of x**2 (``sta_s``) exceeds :data:`_RISE_ON` times their
        envelope (``envelope_s``, to the sample before): the energy of a new blow, which a free
        decay never gains. The innovation scan misses a blow whose response starts smoothly at a
        high rate (a sine from rest at 25.6 kHz: its slope's kink is below the noise per sample),
        while its energy stands 20x out of a ringing at the floor. In a free decay the ratio
        stays near a sine's peak factor, 2 (1.5-2.4 on the bundled recordings, their beats
        included). None with a load cell (its force finds every blow) or no rise."""
        if self._fidx is None and ev.voters.size and ev.onset >= 0:
            n = self._len
            w = ev.rise
            if w is None or w.pos < self._ring.start:  # (re)started, after a gap from there:
                # the envelope settles from the pre-event level in 4 of its lengths (e^-4)
                first = max(ev.onset, self._ring.start)
                w = ev.rise = _RiseWatch(sta=ev.pre[ev.voters].copy(), env=ev.pre[ev.voters].copy(),
                                         pos=first, counts_from=max(ev.onset + n.double + 1,
                                                                    first + 4 * n.envelope))
            if w.found is not None or limit <= w.pos:
                return w.found
            a = w.pos
            x2 = self._squares(a, limit)[ev.voters]
            sta, w.sta = ons.exp_average(x2, n.sta, w.sta)
            env, last = ons.exp_average(x2, n.envelope, w.env)
            before = np.empty_like(env)  # the envelope up to the sample before
            before[:, 0], before[:, 1:] = w.env, env[:, :-1]
            kk = min(self._k, len(ev.voters))
            hit = (sta > _RISE_ON * before).sum(axis=0) >= kk
            hit[:max(0, w.counts_from - a)] = False
            idx = np.flatnonzero(hit)
            if idx.size:
                w.found, w.pos = a + int(idx[0]), a + int(idx[0]) + 1
                return w.found
            w.env, w.pos = last, limit
        return None

    def _scan_sharp(self, ev: _Event, limit: int, closing: bool = False) -> int | None:
        """Next sharp onset (second contact) in ``scan.pos .. limit-1``, with hysteresis."""
        scan, n, s = ev.scan, self._len, self.settings
        while True:  # a loop, not a recursion: a long block can hold hundreds of rejected bursts
            a, was_on, ref = scan.pos, scan.on, scan.ref  # restored if a burst waits for its refit
            if limit <= a or (self._fidx is None and scan.whitener is None):
                return None
            if self._fidx is not None:
                f = np.abs(self._values(a, limit, [self._fidx])[0] - self._f_base)
                on, off, p, last = f >= self._f_level, f < s.hysteresis * self._f_level, None, None
            else:
                x = self._values(a - n.order, limit, self._vidx[ev.voters])
                e = _innovation(x, scan.whitener.a)
                e2 = e * e
                p, last = ons.exp_average(e2, n.innovation, scan.level)
                kk = min(self._k, len(ev.voters))
                if self._no_contact(scan, p, e2, kk, max(0, scan.dead_until - a)):
                    scan.pos, scan.level = limit, last
                    return None
                ratio = self._innovation_ref(scan, e2)
                np.divide(p, ratio, out=ratio)  # p / level, in the level's array
                on = (ratio > self._double_on(kk)).sum(axis=0) >= kk
                off = (ratio > s.off).sum(axis=0) < kk
            dead = max(0, scan.dead_until - a)  # one contact cannot trigger twice
            on[:dead] = off[:dead] = False
            j, scan.on, off_i = ons.next_trigger(on, off, scan.on)
            if j is not None and p is not None:
                sure = self._confirm(ev, a + j, kk, closing)
                if sure is None:  # wait for the samples after the burst; this block again then
                    scan.on, scan.ref, scan.ref_trace = was_on, ref, None
                    return None
                if not sure:
                    continue  # rejected: scan on from past it
            if off_i >= 0:
                scan.off_pos = a + off_i
            if j is None:
                scan.pos, scan.level = limit, last
                return None
            scan.pos, scan.level = a + j + 1, None if p is None else p[:, j].copy()
            if scan.ref_trace is not None:  # the mean up to the contact's sample, inclusive
                scan.ref = scan.ref_trace[:, j].copy()
            scan.dead_until = a + j + n.guard
            return a + j

    def _no_contact(self, scan: _ContactScan, p: np.ndarray, e2: np.ndarray, kk: int,
                    dead: int) -> bool:
        """True, with the innovation's reference mean carried to the block's end, when the scan
        cannot find a contact in this block: it is off (no end of a contact to find), and after
        ``dead`` no sample has ``kk`` gages whose innovation STA ``p`` passes the ratio over the
        fit's variance alone. The ratio :meth:`_scan_sharp` tests divides by the larger of that
        variance and the reference, so it cannot pass where this does not: the reference's
        trace (a recursion over every sample) is then not needed, only its last value."""
        if scan.on:
            return False
        bound = p[:, dead:] > self._double_on(kk) * scan.whitener.var[:, None]
        if (bound.sum(axis=0) >= kk).any():
            return False
        prev, n = self._ref_start(scan)
        scan.ref = ons.exp_average_last(e2, n, prev)
        scan.ref_trace = None
        return True

    def _ref_start(self, scan: _ContactScan) -> tuple[np.ndarray, int]:
        """The innovation reference mean (:meth:`_innovation_ref`) before this block, per voter
        (the fit's innovation variance before the first block), and its averaging length in
        samples: ``envelope_s``, at least :data:`_REF_STA` innovation STAs."""
        return (scan.whitener.var if scan.ref is None else scan.ref,
                max(self._len.envelope, _REF_STA * self._len.innovation))

    def _double_on(self, kk: int) -> float:
        """The innovation ratio ``kk`` voting gages must pass for a second contact: the
        setting's ``double_on`` where at least :data:`_DESIGN_VOTES` vote; for fewer, the ratio
        whose chance on one gage, to the power ``kk``, is the design's (three gages at
        ``double_on``): the innovation STA of white noise is chi-square with ``2 n - 1``
        degrees of freedom (a recursive mean over ``n`` samples). At 2048 Hz: 11.6 for one
        gage, 6.7 for two (on one gage at 5, the ringing gave false second contacts)."""
        if kk >= _DESIGN_VOTES:
            return self.settings.double_on
        if kk not in self._double_on_k:
            from scipy import optimize, stats  # here: once a stream, for a one- or two-gage vote

            nu, on = 2 * self._len.innovation - 1, self.settings.double_on
            target = _DESIGN_VOTES * stats.chi2.logsf(on * nu, nu) / kk
            self._double_on_k[kk] = float(optimize.brentq(
                lambda t: stats.chi2.logsf(t * nu, nu) - target, on, 1e3 * on))
        return self._double_on_k[kk]

    def _innovation_ref(self, scan: _ContactScan, e2: np.ndarray) -> np.ndarray:
        """The level each innovation sample of ``e2`` (units^2, (n_voters, n)) is compared with:
        the fit's innovation variance, or, if higher, the innovation's own recursive mean up to
        the sample before, over ``envelope_s`` and at least :data:`_REF_STA` innovation STAs (a
        mean only a few STAs long would bound their ratio at a contact below ``double_on``:
        2.4 at 50 Hz). A filter fitted to the first ringing whitens the later ringing less well
        (its modes' mix changes as they decay), and on one or two gages, with no k-of-n vote to
        hold it back, that slowly rising innovation crossed ``double_on`` every few seconds of
        a long ringing (false double hits and blows); a contact's burst hardly moves the mean."""
        var = scan.whitener.var
        prev, n = self._ref_start(scan)
        ref, last = ons.exp_average(e2, n, prev)
        scan.ref, scan.ref_trace = last, ref  # ref[:, i]: the mean up to sample i
        before = np.empty_like(ref)  # [:, i]: up to sample i - 1, in one array for the caller
        before[:, 0] = prev
        before[:, 1:] = ref[:, :-1]
        return np.maximum(var[:, None], before, out=before)

    def _close(self, reason: str) -> list[ImpactEvent]:
        """Close the open event at the last sample in the ring (gap or end of stream)."""
        out: list[ImpactEvent] = []
        ev, end = self._ev, self._ring.end
        if ev is None:
            return out
        if ev.onset < 0 and end >= ev.detect + self._len.look:
            self._refine(ev, out)
        elif ev.onset < 0:
            ev.onset, ev.onset_s = ev.detect, ev.detect / self.fs_hz
            if ev.voters.size == 0:
                ev.voters = np.arange(len(self._vidx))
            if ev.cut is not None:
                ev.cut.end, ev.cut.end_reason = max(ev.detect - 1, ev.cut.onset), "next_impact"
                self._hand_over(ev.cut, out)
        if ev.onset >= 0 and ev.scan.whitener is not None and ev.scan.pos < end:
            s = self._scan_sharp(ev, end, closing=True)  # a burst that waited for its refit
            if s is not None and s - ev.onset <= self._len.double and ev.recorded:
                ev.second = ev.second or (s, None)
        self._refine_second(ev, end)
        if ev.second is not None and ev.second[1] is None:
            ev.second = (ev.second[0], ev.second[0] / self.fs_hz)
        ev.end, ev.end_reason = end - 1, reason
        self._hand_over(ev, out)
        self._ev = None
        return out

    def _no_blow(self, ev: _Event, first: int, counts: np.ndarray, prev: int | None) -> str | None:
        """Why an STA/LTA event is no blow, else ``None``: no octave band of the responding
        gages (a blow that rings a few gages only is not judged by the others' noise) rings
        more (by :data:`~ramdaq.analysis.onset.NO_BLOW_RATIO`) in the
        :data:`~ramdaq.analysis.onset.BLOW_WINDOW_S` after its onset than before it, at most
        half the time since the previous onset ``prev`` (sample; None: none)
        (:func:`~ramdaq.analysis.onset.band_energy_ratio`). A load cell's event is a blow by its
        force."""
        if self._fidx is not None:
            return None
        w = min(round(ons.BLOW_WINDOW_S * self.fs_hz), ev.onset - first, counts.shape[1] - (ev.onset - first))
        if prev is not None:
            w = min(w, (ev.onset - prev) // 2)
        if w < 8:
            return None
        rows = self._vidx[ev.voters] if ev.voters.size else self._vidx  # the responding gages
        x = counts[rows, ev.onset - first - w: ev.onset - first + w] * self._scale[rows, None]
        r = ons.band_energy_ratio(x[:, :w], x[:, w:], self.fs_hz)
        if not r <= ons.NO_BLOW_RATIO:
            return None
        return (f"{NO_BLOW}: no band of the gages rings more in the {w / self.fs_hz:.2f} s after "
                f"the onset than before (at most {r:.2f}x the RMS); a ram blow drives every mode "
                "(a mode that stops ringing by friction fires the trigger too)")

    def _finish(self, ev: _Event) -> ImpactEvent:
        """The completed event with its record cut from the ring."""
        fs, names = self.fs_hz, self.info.channels
        prev, self._prev_onset = self._prev_onset, ev.onset  # every event's, analysable or not
        first = max(ev.onset - self._len.pre, self._ring.start)
        last = max(ev.end, ev.onset)
        counts = self._ring.read(first, last + 1)
        peak = np.abs(counts[:, ev.onset - first:]).max(axis=1) * self._scale
        clipped: tuple[str, ...] = ()
        if self._rails is not None:
            rail = ((counts <= self._rails[0]) | (counts >= self._rails[1])).any(axis=1)
            clipped = tuple(names[i] for i in np.flatnonzero(rail))
        rows = self._vidx[ev.voters]
        chans = ([self._fidx] if self._fidx is not None else []) + list(rows)
        snr = np.max(peak[rows] ** 2 / ev.pre[ev.voters])
        cut = ev.end_reason in ("gap", "flush", "next_impact") and last < ev.onset + self._len.post
        seg0, t0 = self._seg
        second = ev.second or (None, None)
        decayed = None if ev.decay is None else ev.decay.decayed
        if ev.floor is not None and ev.floor.end is not None:
            decayed = ev.floor.end
        return ImpactEvent(
            onset_sample=ev.onset, onset_s=ev.onset_s,
            t_ns=t0 + round((ev.onset_s * fs - seg0) * 1e9 / fs), trigger_sample=ev.detect,
            first_sample=first, last_sample=last, fs_hz=fs, mode=self.mode,
            channels=tuple(names[i] for i in chans),
            gages=tuple(int(self.info.gages[i]) for i in chans if self.info.gages[i] > 0),
            peak={n: float(v) for n, v in zip(names, peak, strict=True)},
            snr_db=float(10 * np.log10(snr)) if snr > 0 else 0.0,
            double_hit=ev.second is not None, second_onset_sample=second[0],
            second_onset_s=second[1], clipped=clipped,
            too_short=cut or first > ev.onset - self._len.pre, end_reason=ev.end_reason,
            decay_s=None if decayed is None else (decayed - ev.onset) / fs,
            not_analysable=ev.not_analysable or self._no_blow(ev, first, counts, prev),
            record=ImpactRecord(first, t0 + round((first - seg0) * 1e9 / fs), fs, counts.copy(),
                                self._scale.copy()) if self.settings.keep_records else None)


def _innovation(x: np.ndarray, a: np.ndarray) -> np.ndarray:
    """:func:`ramdaq.analysis.onset.prediction_error` of the rows of ``x`` (n_rows, n), the
    same numbers: ``scipy.signal.lfilter(a, [1.0], x)`` runs an FIR filter as ``np.convolve(a,
    row)`` on each row and keeps the first ``n`` samples, as here, but through
    ``apply_along_axis`` and a dozen checks a call (a quarter of the second-contact scan's
    CPU). Shape (n_rows, n - order); the filter's first coefficient is 1."""
    order, n = len(a) - 1, x.shape[-1]
    e = np.empty((x.shape[0], n - order))
    for i, row in enumerate(x):
        e[i] = np.convolve(a, row)[order:n]
    return e


def _voting_rows(info: StreamInfo, s: TriggerSettings) -> tuple[np.ndarray, int]:
    """Rows of the voting channels and ``k`` of the k-of-n vote; ValueError if the stream
    cannot meet ``s.voters`` / ``s.k_of_n``."""
    names = list(info.channels)
    voters = s.voters
    if voters is None:
        voters = [c for c, g in zip(names, info.gages, strict=True) if g > 0]
    for v in voters:
        if v not in names:
            raise ValueError(f"voter {v!r} is not a channel of the stream")
    rows = np.array([names.index(v) for v in voters], dtype=int)
    k, n_of = s.k_of_n
    if n_of is not None and n_of != len(rows):
        raise ValueError(f"k_of_n n ({n_of}) is not the number of voting gages ({len(rows)})")
    if not 1 <= k <= len(rows):
        raise ValueError(f"k_of_n k ({k}) must lie in 1..{len(rows)}")
    return rows, k


def _force_row(info: StreamInfo, s: TriggerSettings) -> int | None:
    """Row of the ram load cell the trigger uses, or None (STA/LTA mode)."""
    names = list(info.channels)
    if s.force_channel is not None and (s.force_channel not in names
                                        or info.units[names.index(s.force_channel)] != "N"):
        raise ValueError(f"force_channel {s.force_channel!r} is not a channel in N")
    in_n = [i for i, u in enumerate(info.units) if u == "N"]
    fidx = names.index(s.force_channel) if s.force_channel else (in_n[0] if in_n else None)
    if s.mode == "force" and fidx is None:
        raise ValueError("mode 'force' needs a channel in N; the stream has none")
    return fidx if s.mode in ("auto", "force") else None


def _rig_anti_alias(info: StreamInfo) -> tuple[int, float] | None:
    """The anti-alias filter the stream's rig describes, ``(order, corner Hz)`` from ``[daq]``
    ``anti_alias_order`` and ``anti_alias_hz`` in ``info.rig_toml``; ``None`` for a stream that
    carries no rig, or a channels-only rig that names no filter (an imported record's).
    ValueError naming the problem for a rig that does not say it usably."""
    if not info.rig_toml.strip():
        return None
    where = f"{info.device}: the stream's rig"
    fix = "fix the rig, or give the trigger delay_s"
    try:
        doc = tomllib.loads(info.rig_toml)
        daq = doc.get("daq")
    except tomllib.TOMLDecodeError as err:
        raise ValueError(f"{where} is not valid TOML ({err}); {fix}") from err
    if not isinstance(daq, dict):
        raise ValueError(f"{where} has no [daq] table to say its anti-alias filter; {fix}")
    order, corner = daq.get("anti_alias_order"), daq.get("anti_alias_hz")
    if order is None and corner is None and not any(t in doc for t in STRUCTURE_TABLES):
        return None  # a channels-only rig (an imported record's) names no filter: none to remove
    if isinstance(order, float) and order.is_integer():
        order = int(order)
    if isinstance(order, bool) or not isinstance(order, int) or order < 1:
        raise ValueError(f"{where}: daq.anti_alias_order ({order!r}) must be a whole number "
                         f">= 1; {fix}")
    if isinstance(corner, bool) or not isinstance(corner, int | float) or not math.isfinite(corner):
        raise ValueError(f"{where}: daq.anti_alias_hz ({corner!r}) must be a number; {fix}")
    if not 0 < corner < info.fs_hz / 2:
        raise ValueError(f"{where}: daq.anti_alias_hz ({corner}) is not between 0 and the "
                         f"stream's Nyquist frequency ({info.fs_hz / 2:g} Hz); {fix}")
    return order, float(corner)


def _anti_alias_or_none(info: StreamInfo) -> tuple[int, float] | None:
    """:func:`_rig_anti_alias` where the caller gave the delay itself: a rig that does not say its
    filter usably then only costs the decay-end test its noise bandwidth (white to Nyquist)."""
    try:
        return _rig_anti_alias(info)
    except ValueError:
        return None
