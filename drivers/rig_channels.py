"""The channels a rig streams, in DAQ channel order: its gages (m/s^2) and its force channels
(N, a ram's load cell or an instrumented hammer), with the SI value of one ADC count of each.

Every device that streams a rig's channels -- the simulator, CAN, serial -- describes them with
:func:`rig_channels`, so that a rig with ``[[forces]]`` streams its force the same way on all
of them and the trigger's force mode finds it (a channel in ``"N"``, gage number 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..analysis.model.rig import Rig
from ..analysis.model.sensor import channel_scales

__all__ = ["FORCE_HEADROOM", "RigChannels", "force_scale_N", "rig_channels"]

FORCE_HEADROOM = 4.0
"""A force channel's full scale over the rig's blow (``[impact] peak_force_N``)."""


@dataclass(frozen=True)
class RigChannels:
    """Names, units (``"m/s^2"`` or ``"N"``), gage numbers (0 for a force) and SI units per
    count (shape (n_channels,)) of a rig's channels in DAQ channel order."""

    names: tuple[str, ...]
    units: tuple[str, ...]
    gages: tuple[int, ...]
    scales: np.ndarray


def force_scale_N(rig: Rig) -> float:
    """N per count of a force channel: the ADC's range (``daq.adc_bits``) spans
    :data:`FORCE_HEADROOM` times the rig's blow. ValueError for a rig without ``[impact]``."""
    if rig.impact is None:
        raise ValueError(f"rig {rig.name!r}: a force channel's scale needs [impact] peak_force_N "
                         f"(its full scale is {FORCE_HEADROOM:g} times the blow)")
    return FORCE_HEADROOM * rig.impact.peak_force_N / (2 ** (rig.daq.adc_bits - 1) - 1)


def rig_channels(rig: Rig) -> RigChannels:
    """The channels ``rig`` streams (gages ``gNN``, then forces by name, in channel order)."""
    gages = rig.gages_by_channel()
    rows = [(g.channel, f"g{g.number:02d}", "m/s^2", g.number, float(s))
            for g, s in zip(gages, channel_scales(rig), strict=True)]
    if rig.forces:
        scale = force_scale_N(rig)
        rows += [(f.channel, f.name, "N", 0, scale) for f in rig.forces]
    rows.sort(key=lambda r: r[0])
    return RigChannels(tuple(r[1] for r in rows), tuple(r[2] for r in rows),
                       tuple(r[3] for r in rows), np.array([r[4] for r in rows]))
