"""The record loop: read a device, hand every block to the recorder, show the live readout.

The device is read on the calling thread and never waits on disk: the recorder has its own
thread and bounded queue, and a block it cannot take is counted and logged by it. A device that
is not paced by a real clock (the simulator run as fast as possible) has no deadline to miss, so
for it the loop waits for room in the queue instead of dropping.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from daq.readout import LiveReadout
from daq.recorder import Recorder
from drivers.base import Device
from drivers.mcap_format import SIM_IMPACTS_TOPIC


@dataclass(frozen=True)
class RecordSummary:
    path: Path
    blocks: int
    samples: int
    duration_s: float
    gaps: int
    overflows: int
    impacts: int
    interrupted: bool
    wall_s: float


def record(device: Device, path: str | Path, *, readout: bool = True, overwrite: bool = False,
           queue_blocks: int = 256, chunk_seconds: float = 0.25) -> RecordSummary:
    """Record ``device`` into ``path`` until its stream ends or Ctrl-C; the file is always
    finished (footer written), also on interruption."""
    info = device.open()
    paced = getattr(device, "pace", "realtime") != "fast"
    truth = getattr(device, "delivered_impacts", None)
    written_truth = 0
    gaps = 0
    last = None
    interrupted = False
    t_wall = time.monotonic()
    adc_bits = info.extra.get("adc_bits")
    view = LiveReadout(info, adc_bits=adc_bits) if readout else None
    with Recorder(path, info, queue_blocks=queue_blocks, chunk_seconds=chunk_seconds,
                  overwrite=overwrite) as rec:
        try:
            if view:
                view.__enter__()
            for block in device:
                if not paced:
                    while rec.stats.queued >= queue_blocks - 1:
                        time.sleep(0.001)
                rec.put(block)
                for fault in device.take_faults():
                    rec.event(fault.kind, fault.t_ns, **fault.detail)
                gap = last is not None and block.first_sample != last
                gaps += gap
                last = block.next_sample
                if truth is not None:
                    for blow in truth[written_truth:]:
                        rec.write_json(SIM_IMPACTS_TOPIC, {
                            "sample": round(blow.t_s * info.fs_hz), **blow.to_json()},
                            block.t0_ns)
                    written_truth = len(truth)
                if view:
                    view.update(block, queue=rec.stats.queued, overflows=rec.overflows, gap=gap,
                                impacts=[b.t_s for b in truth] if truth is not None else None)
        except KeyboardInterrupt:
            interrupted = True
            rec.event("interrupted", 0 if last is None else block.t0_ns, reason="Ctrl-C")
        finally:
            if view:
                view.__exit__(None, None, None)
            device.close()
    stats = rec.stats
    return RecordSummary(Path(path), stats.blocks, stats.samples, stats.samples / info.fs_hz, gaps,
                         stats.overflows, written_truth, interrupted, time.monotonic() - t_wall)
