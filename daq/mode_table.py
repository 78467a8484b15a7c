"""The mode table: one row per hit x gage x mode of an analysed trial, SI — what
:func:`ramdaq.analyze` returns and ``ramdaq batch analyze`` writes as Parquet."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .analyzer import HitResult

__all__ = ["ModeEstimate", "mode_rows", "zeta_with_se"]


@dataclass(frozen=True)
class ModeEstimate:
    """One mode on one gage of one hit.

    ``f_hz``, ``f_se_hz`` damped frequency and its standard error (Hz); ``delta``,
    ``delta_se`` the logarithmic decrement (1); ``zeta``, ``zeta_se`` the damping ratio (1):
    the gage's own fit (the report's per-gage decrement, Eq 7). ``mode_f_hz`` ...
    ``mode_zeta_se``: the same of the fit shared by all gages (one value per mode, repeated on
    each gage's row; what ``ramdaq batch analyze``'s table holds). ``amplitude`` the mode's
    amplitude on the gage at the decay's start (m/s^2), ``phase_rad`` its phase against the
    gage where the mode is largest (the mode shape's). ``predominant``: the mode is the most
    energetic on the rudder (report.json ``predominant_mode``); ``chosen``: the mode ``mode_hz``
    asked for (report.json ``chosen_mode``; False on every row when none was asked), on which
    the report's chain then ran instead of the predominant one. ``verdict`` is the gage's
    (``ok`` or what is wrong with its decay) and ``reason`` the hit's when it was rejected, else
    the gage's -- judged on one mode, the gage's dominant one; the other modes' rows say so
    ("the gage's verdict, judged at 11 Hz: ..."). ``mode`` is the index into report.json's
    ``analysis.modes`` (from 0, as the CLI's ``mode 0``); where no mode was fitted -- a rejected
    or unrequested hit (one row, gage 0), a gage with no usable decay -- it is None, ``fitted``
    is False and ``reason`` says why, the numbers NaN: the convention of ``ramdaq batch
    analyze``'s table (null + ``fitted``).
    """

    hit: int
    onset_s: float
    accepted: bool
    gage: int
    mode: int | None
    fitted: bool
    predominant: bool
    chosen: bool
    f_hz: float
    f_se_hz: float
    delta: float
    delta_se: float
    zeta: float
    zeta_se: float
    mode_f_hz: float
    mode_f_se_hz: float
    mode_delta: float
    mode_delta_se: float
    mode_zeta: float
    mode_zeta_se: float
    amplitude: float
    phase_rad: float
    verdict: str
    reason: str


def zeta_with_se(delta: float, delta_se: float) -> tuple[float, float]:
    """Damping ratio of a log decrement, zeta = delta / sqrt(4 pi^2 + delta^2), and its standard
    error by the derivative d zeta / d delta = 4 pi^2 / (4 pi^2 + delta^2)^1.5."""
    k = 4 * math.pi**2
    return delta / math.sqrt(k + delta**2), delta_se * k / (k + delta**2) ** 1.5


def mode_rows(h: HitResult) -> Iterator[ModeEstimate]:
    nan = float("nan")
    a = h.analysis
    if not h.accepted or a is None:
        yield ModeEstimate(h.index, h.event.onset_s, False, 0, None, False, False, False, *[nan] * 14,
                           "", h.reason)
        return
    m = a.modes
    row = {n: j for j, n in enumerate(a.active_gages)}
    for n in a.gage_numbers:
        v = a.verdicts[n]
        if n not in row:
            yield ModeEstimate(h.index, a.onset_s, True, n, None, False, False, False, *[nan] * 14,
                               str(v.code), v.reason)
            continue
        j = row[n]
        judged = _judged_mode(v.f_hz, m.frequency_hz)
        for k in range(len(m.frequency_hz)):
            d, dse = float(m.channel_delta[j, k]), float(m.channel_delta_se[j, k])
            z, zse = zeta_with_se(d, dse)
            shared = (m.frequency_hz[k], m.frequency_se_hz[k], m.delta[k], m.delta_se[k], m.zeta[k],
                      m.zeta_se[k])
            yield ModeEstimate(h.index, a.onset_s, True, n, k, True, k == a.predominant, k == a.chosen,
                               float(m.channel_frequency_hz[j, k]),
                               float(m.channel_frequency_se_hz[j, k]), d, dse, z, zse,
                               *(float(x) for x in shared), float(abs(m.complex_amplitude[j, k])),
                               float(np.angle(m.mode_shape[j, k])), str(v.code),
                               v.reason if judged in (None, k) else
                               f"the gage's verdict, judged at {v.f_hz:.4g} Hz: {v.reason}")


def _judged_mode(f_hz: float, modes_hz: np.ndarray) -> int | None:
    """Index of the mode (of ``modes_hz``, Hz) nearest the frequency a gage's verdict judged;
    None where the verdict estimated none (NaN): its reason then stands on every row."""
    if not np.isfinite(f_hz) or len(modes_hz) == 0:
        return None
    return int(np.argmin(np.abs(np.asarray(modes_hz) - f_hz)))
