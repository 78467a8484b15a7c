"""Simulated 16-channel device: the physics model of the rudder-stock-hull system behind a DAQ.

``SimDevice`` streams blocks exactly as hardware would (int32 counts, per-channel scale, sequence
numbers, device time), computed by :class:`ramdaq.analysis.model.response.ModalSimulator` (exact response to
half-sine ram blows) and :class:`ramdaq.analysis.model.sensor.SensorChain` (noise, anti-alias, ADC). It is
deterministic under its seed: the same rig, seed, block size and impacts give the same counts,
whether paced in real time or run as fast as possible.

Impacts come from a schedule (``impacts=[1.0, 4.0]`` seconds, or :class:`Impact` s) or on command
(``device.impact()`` hits at the start of the next block). Every impact the device delivers is
kept in ``delivered_impacts`` as ground truth, with its exact start time. A rig with
``[[forces]]`` channels gets them after the gages: the ram's force in N, the blows' half-sines
(ideal: no noise, no anti-alias filter), 24-bit with four times the rig's blow as full scale.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..analysis.model.response import ModalSimulator, modal_form
from ..analysis.model.rig import AXES, Rig, load_rig
from ..analysis.model.sensor import SensorChain
from ..analysis.model.structure import build_model
from .base import TIMED_OUT, Device
from .block import Block, StreamInfo, sample_time_ns
from .rig_channels import force_scale_N


@dataclass(frozen=True)
class Impact:
    """A ram blow: starts at ``t_s`` seconds after the stream's first sample (may fall between
    samples); half-sine of ``peak_force_N`` N over ``duration_s`` s at ``location_m`` (m from the
    rudder's centre of mass) along ``direction``."""

    t_s: float
    peak_force_N: float
    duration_s: float
    location_m: tuple[float, float, float]
    direction: str = "y"

    def to_json(self) -> dict:
        return {"t_s": self.t_s, "peak_force_N": self.peak_force_N,
                "duration_s": self.duration_s, "location_m": list(self.location_m),
                "direction": self.direction}


class SimDevice(Device):
    """The simulated device (back-end name ``"sim"``).

    Parameters
    ----------
    rig : Rig or path
        The rig to simulate.
    medium : str, optional
        Override the rig's medium ("air" or "water").
    seed : int
        Noise seed.
    duration_s : float or None
        Stream length in seconds; ``None`` streams until closed.
    impacts : sequence of float or Impact
        Scheduled blows; a number is a start time in seconds with the rig's default ram.
    pace : {"fast", "realtime"}
        Deliver blocks as fast as they are computed, or at the sample clock's pace.
    block_s : float
        Block length in seconds (rounded to whole samples).
    fs_hz : float, optional
        Override the rig's sample rate.
    noise : bool
        Add the rig's noise floor.

    The stream's ``rig_toml`` is the rig file's text: a rig changed in memory
    (``dataclasses.replace``) is simulated as changed but described by its file's text.
    """

    kind = "sim"

    def __init__(self, rig: Rig | str | Path, *, medium: str | None = None, seed: int = 0,
                 duration_s: float | None = None, impacts: Sequence[float | Impact] = (),
                 pace: str = "fast", block_s: float = 0.05, fs_hz: float | None = None,
                 noise: bool = True, anti_alias: bool = True) -> None:
        super().__init__()
        rig = rig if isinstance(rig, Rig) else load_rig(rig)
        self.rig = rig.with_medium(medium) if medium else rig
        self.rig.require_structure("the simulator")
        if pace not in ("fast", "realtime"):
            raise ValueError(f"pace must be 'fast' or 'realtime', got {pace!r}")
        self.fs_hz = float(fs_hz or self.rig.daq.sample_rate_hz)
        if self.rig.daq.anti_alias_hz >= self.fs_hz / 2:
            raise ValueError(f"fs_hz {self.fs_hz} puts Nyquist below the rig's anti-alias corner "
                             f"{self.rig.daq.anti_alias_hz} Hz")
        self.block_n = max(1, round(block_s * self.fs_hz))
        self.total_n = None if duration_s is None else round(duration_s * self.fs_hz)
        self.seed, self.pace, self.noise, self.anti_alias = seed, pace, noise, anti_alias
        self._pending = sorted((self._as_impact(i) for i in impacts), key=lambda i: i.t_s)
        self.delivered_impacts: list[Impact] = []
        self._seq = 0

    def _as_impact(self, item: float | Impact) -> Impact:
        if isinstance(item, Impact):
            if item.direction not in AXES:
                raise ValueError(f"impact direction {item.direction!r} is not an axis")
            return item
        spec = self.rig.impact
        return Impact(float(item), spec.peak_force_N, spec.duration_s, spec.location_m,
                      spec.direction)

    def impact(self, peak_force_N: float | None = None, duration_s: float | None = None,
               location_m: tuple[float, float, float] | None = None) -> Impact:
        """Hit the rudder now: the blow starts with the next block. Returns the scheduled blow."""
        spec = self.rig.impact
        sample = self._sim.sample if self._info is not None else 0
        blow = Impact(sample / self.fs_hz, peak_force_N or spec.peak_force_N,
                      duration_s or spec.duration_s, location_m or spec.location_m,
                      spec.direction)
        self._pending.append(blow)
        self._pending.sort(key=lambda i: i.t_s)
        return blow

    def _open(self) -> StreamInfo:
        model = build_model(self.rig)
        self.form = modal_form(model)
        self._sim = ModalSimulator(self.form, self.fs_hz)
        for amb in self.rig.ambient:
            self._sim.add_ambient(amb.hull_mode, amb.frequency_hz, amb.v_b_amplitude_m)
        self._sensor = SensorChain(self.rig, self.fs_hz, seed=self.seed, noise=self.noise,
                                   anti_alias=self.anti_alias)
        self._t_start = time.monotonic()
        gages = self.rig.gages_by_channel()
        forces = tuple(sorted(self.rig.forces, key=lambda f: f.channel))
        # a force channel: the blows' half-sines, with 4x headroom over the rig's blow
        self._force_scale = np.full(len(forces), force_scale_N(self.rig) if forces else 0.0)
        return StreamInfo(
            device="sim", fs_hz=self.fs_hz,
            channels=tuple(f"g{g.number:02d}" for g in gages) + tuple(f.name for f in forces),
            units=("m/s^2",) * len(gages) + ("N",) * len(forces),
            gages=tuple(g.number for g in gages) + (0,) * len(forces),
            rig_toml=self.rig.text,
            extra={"seed": self.seed, "medium": self.rig.medium, "block_samples": self.block_n,
                   "adc_bits": self.rig.daq.adc_bits, "noise": self.noise,
                   "rig_name": self.rig.name},
        )

    def _read(self, timeout: float | None) -> Block | None:
        start = self._sim.sample
        n = self.block_n
        if self.total_n is not None:
            n = min(n, self.total_n - start)
            if n <= 0:
                return None
        end_t = (start + n) / self.fs_hz
        while self._pending and self._pending[0].t_s < end_t:
            blow = self._pending.pop(0)
            if blow.t_s * self.fs_hz < start:  # commanded while a block was in flight
                blow = Impact(start / self.fs_hz, blow.peak_force_N, blow.duration_s,
                              blow.location_m, blow.direction)
            self._sim.add_impact(blow.t_s, blow.peak_force_N, blow.duration_s, blow.location_m,
                                 blow.direction)
            self.delivered_impacts.append(blow)
        if self.pace == "realtime":
            wait = self._t_start + end_t - time.monotonic()
            if timeout is not None and wait > timeout:
                time.sleep(max(timeout, 0.0))
                return TIMED_OUT
            if wait > 0:
                time.sleep(wait)
        counts = self._sensor.process(self._sim.advance(n))
        scale = self._sensor.scale
        if self._force_scale.size:
            f = np.rint(self._force(start, n) / self._force_scale[0]).astype(np.int32)
            counts = np.vstack([counts, np.tile(f, (self._force_scale.size, 1))])
            scale = np.concatenate([scale, self._force_scale])
        block = Block(seq=self._seq, first_sample=start,
                      t0_ns=sample_time_ns(start, self.fs_hz), fs_hz=self.fs_hz,
                      counts=counts, scale=scale)
        self._seq += 1
        return block

    def _force(self, start: int, n: int) -> np.ndarray:
        """The ram's force over samples ``start .. start+n-1``, N: the half-sines of the blows
        delivered (the force channel of a rig with ``[[forces]]``), shape (n,)."""
        t = (start + np.arange(n)) / self.fs_hz
        f = np.zeros(n)
        for b in self.delivered_impacts:
            on = (t >= b.t_s) & (t < b.t_s + b.duration_s)
            f[on] += b.peak_force_N * np.sin(np.pi * (t[on] - b.t_s) / b.duration_s)
        return f

    @property
    def sample0_monotonic_s(self) -> float | None:
        """``time.monotonic()`` s at which sample 0 was due (the device's start; with
        ``pace="realtime"`` sample k is delivered no earlier than this plus k / fs_hz); None
        before it opens."""
        return getattr(self, "_t_start", None)

    @property
    def clipped_samples(self) -> dict[str, int]:
        """Samples clipped at the ADC rails so far, by channel name (only those that clipped)."""
        return {name: int(c) for name, c in zip(self.info.channels, self._sensor.clipped,
                                                strict=False) if c}  # gages, then forces
