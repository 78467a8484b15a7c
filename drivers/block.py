"""The unit that flows from every device: a :class:`Block` of raw ADC counts, and the
:class:`StreamInfo` that describes the stream it belongs to.

A block carries integer counts, never volts or engineering units: the conversion to SI is a
per-channel ``scale`` (SI units per count), so a recording is lossless and the physical value of
sample ``i`` of channel ``c`` is ``counts[c, i] * scale[c]``.

Gaps are explicit. ``seq`` increases by exactly one per block a device produces and
``first_sample`` is the index, counted from the start of the stream, of the block's first sample.
A consumer that sees ``seq`` jump, or ``first_sample`` differ from the previous block's
``first_sample + n_samples``, has found a gap: samples that were never delivered. Nobody fills it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, eq=False)
class Block:
    """A contiguous run of samples from all channels of one device.

    Attributes
    ----------
    seq : int
        Block sequence number, +1 per block the device produced (a jump is a gap).
    first_sample : int
        Index of the first sample since the stream started (sample clock, not wall time).
    t0_ns : int
        Device time of the first sample, integer nanoseconds.
    fs_hz : float
        Sample rate, Hz.
    counts : numpy.ndarray
        Raw ADC counts, ``int32``, shape ``(n_channels, n_samples)``.
    scale : numpy.ndarray
        SI units per count for each channel, ``float64``, shape ``(n_channels,)``
        (m/s^2 per count for accelerometers, N per count for a ram load cell).
    """

    seq: int
    first_sample: int
    t0_ns: int
    fs_hz: float
    counts: np.ndarray
    scale: np.ndarray

    def __post_init__(self) -> None:
        if self.counts.ndim != 2:
            raise ValueError(f"Block.counts must be 2-D (channels, samples), got {self.counts.ndim}-D")
        if self.counts.dtype != np.int32:
            raise ValueError(f"Block.counts must be int32, got {self.counts.dtype}")
        if self.scale.shape != (self.counts.shape[0],):
            raise ValueError(
                f"Block.scale has shape {self.scale.shape}, expected ({self.counts.shape[0]},)"
            )
        if self.fs_hz <= 0:
            raise ValueError(f"Block.fs_hz must be positive, got {self.fs_hz}")

    @property
    def n_channels(self) -> int:
        return int(self.counts.shape[0])

    @property
    def n_samples(self) -> int:
        return int(self.counts.shape[1])

    @property
    def next_sample(self) -> int:
        """Index of the sample that should start the next block if no gap occurs."""
        return self.first_sample + self.n_samples

    def values(self) -> np.ndarray:
        """Samples in SI units, ``float64``, shape ``(n_channels, n_samples)``."""
        return self.counts * self.scale[:, None]

    def times_s(self) -> np.ndarray:
        """Sample times in seconds since the stream's first sample, shape ``(n_samples,)``."""
        return (self.first_sample + np.arange(self.n_samples)) / self.fs_hz

    def same_as(self, other: Block) -> bool:
        """True when both blocks carry exactly the same header fields and samples."""
        return (
            self.seq == other.seq
            and self.first_sample == other.first_sample
            and self.t0_ns == other.t0_ns
            and self.fs_hz == other.fs_hz
            and np.array_equal(self.counts, other.counts)
            and np.array_equal(self.scale, other.scale)
        )


@dataclass(frozen=True)
class StreamInfo:
    """What a device streams: channel names, units and sample rate.

    Attributes
    ----------
    device : str
        Back-end name and address, e.g. ``"sim"`` or ``"can://virtual/0"``.
    fs_hz : float
        Sample rate, Hz.
    channels : tuple of str
        Channel names in row order of every block's ``counts``, e.g. ``"g01"`` ... ``"g16"``.
    units : tuple of str
        SI unit of each channel after scaling (``"m/s^2"``, ``"N"``).
    gages : tuple of int
        Report gage number (1-16) of each channel, 0 for a channel that is not a gage
        (such as a ram load cell).
    rig_toml : str
        The rig file's text, so a stream (and its recording) describes itself. Empty if unknown.
    extra : dict
        Back-end specific facts worth keeping (seed, ADC bits, block size, ...), JSON-serialisable.
    """

    device: str
    fs_hz: float
    channels: tuple[str, ...]
    units: tuple[str, ...]
    gages: tuple[int, ...]
    rig_toml: str = ""
    extra: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.channels)
        if len(self.units) != n or len(self.gages) != n:
            raise ValueError(
                f"StreamInfo: {n} channels but {len(self.units)} units and {len(self.gages)} gages"
            )

    @property
    def n_channels(self) -> int:
        return len(self.channels)


def sample_time_ns(sample: int, fs_hz: float) -> int:
    """Time of sample index ``sample`` on a clock of ``fs_hz``, integer ns, rounded half up."""
    return int(np.floor(sample * 1e9 / fs_hz + 0.5))
