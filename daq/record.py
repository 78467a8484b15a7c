"""The record loop: read a device, hand every block to the recorder, show the live readout.

The device is read on the calling thread and never waits on disk: the recorder has its own
thread and bounded queue, and a block it cannot take is counted and logged by it. A device that
is not paced by a real clock (the simulator run as fast as possible) has no deadline to miss, so
for it the loop waits for room in the queue instead of dropping.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from ..drivers.base import FAULT_POLL_S, Device, DeviceFault
from ..drivers.block import Block
from ..drivers.errors import DeviceError, DeviceTimeout
from ..drivers.fault_words import FaultWords
from ..drivers.mcap_format import SIM_IMPACTS_TOPIC
from .readout import LiveReadout
from .recorder import Recorder


def store_block(rec: Recorder, device: Device, block: Block, truth_written: int, *,
                wait_for_room: bool, queue_limit: int = 256) -> tuple[int, list[DeviceFault]]:
    """Hand one block to the recorder with what came with it: the device's faults as events and,
    from the simulator, the blows it delivered (``/ramdaq/sim/impacts``, ground truth).

    ``wait_for_room``: for a device with no real-time deadline (the simulator run fast), wait
    for the recorder's queue instead of letting it drop. Returns the updated count of truth
    records written and the faults, for the caller to show.
    """
    if wait_for_room:
        while rec.stats.queued >= queue_limit - 1:
            time.sleep(0.001)
    rec.put(block)
    faults = device.take_faults()
    for fault in faults:
        rec.event(fault.kind, fault.t_ns, **fault.detail)
    truth = getattr(device, "delivered_impacts", None)
    if truth is not None and len(truth) > truth_written:
        for blow in truth[truth_written:]:
            rec.write_json(SIM_IMPACTS_TOPIC, {"sample": round(blow.t_s * block.fs_hz),
                                               **blow.to_json()}, block.t0_ns)
        truth_written = len(truth)
    return truth_written, faults


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
    faults: str | None = None  # one line of what went wrong with the device, None if nothing did


def record(device: Device, path: str | Path, *, readout: bool = True, overwrite: bool = False,
           queue_blocks: int = 256, chunk_seconds: float = 0.25,
           progress: Callable[[Block], None] | None = None,
           say: Callable[[str], None] | None = None) -> RecordSummary:
    """Record ``device`` into ``path`` until its stream ends or Ctrl-C; the file is always
    finished (footer written), also on interruption. ``progress`` gets each block written.

    The device's faults are recorded as events and told in words as they come, one line an
    incident (:class:`~ramdaq.drivers.fault_words.FaultWords`, as a live trial tells them): in
    the readout when there is one, else to ``say``; while no block comes too (the device is read
    with a :data:`FAULT_POLL_S` timeout), so a lost port is said when it is lost, not at the
    next block. The summary's ``faults`` counts them. A device that gives up (``DeviceError``,
    e.g. a port that did not come back) has its last faults and a ``device_error`` event
    recorded, then the error is raised: the file is finished with what came before."""
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
    words = FaultWords(info.device, info.fs_hz)
    tell = view.hit if view else say
    with Recorder(path, info, queue_blocks=queue_blocks, chunk_seconds=chunk_seconds,
                  overwrite=overwrite) as rec:
        try:
            if view:
                view.__enter__()
            for block in _blocks(device, rec, words, tell):
                written_truth, faults = store_block(rec, device, block, written_truth,
                                                    wait_for_room=not paced, queue_limit=queue_blocks)
                words.tell(faults, tell)
                if progress:
                    progress(block)
                gap = last is not None and block.first_sample != last
                gaps += gap
                last = block.next_sample
                if view:
                    view.update(block, queue=rec.stats.queued, overflows=rec.overflows, gap=gap,
                                impacts=[b.t_s for b in truth] if truth is not None else None)
        except KeyboardInterrupt as err:  # Ctrl-C, or SIGTERM raised as KeyboardInterrupt("SIGTERM")
            interrupted = True
            rec.event("interrupted", 0 if last is None else block.t0_ns, reason=str(err) or "Ctrl-C")
        finally:
            _faults_now(device, rec, words, tell)  # what an interruption left untold
            if view:
                view.__exit__(None, None, None)
            device.close()
    stats = rec.stats
    return RecordSummary(Path(path), stats.blocks, stats.samples, stats.samples / info.fs_hz, gaps,
                         stats.overflows, written_truth, interrupted, time.monotonic() - t_wall,
                         words.tally())


def _blocks(device: Device, rec: Recorder, words: FaultWords,
            tell: Callable[[str], None] | None) -> Iterator[Block]:
    """The device's blocks to the stream's end; the faults it reports meanwhile, while no block
    comes, recorded and told at once (as :class:`~ramdaq.daq.session.TrialSession` does)."""
    while True:
        try:
            block = device.read(timeout=FAULT_POLL_S)
        except DeviceTimeout:
            _faults_now(device, rec, words, tell)
            continue
        except DeviceError as err:  # gave up: what it said before, then why, then raise
            _faults_now(device, rec, words, tell)
            rec.event("device_error", rec.t_end_ns, message=str(err))
            raise
        if block is None:
            _faults_now(device, rec, words, tell)  # reported with the last read
            return
        yield block


def _faults_now(device: Device, rec: Recorder, words: FaultWords,
                tell: Callable[[str], None] | None) -> None:
    """The faults the device reports now, recorded as events and told."""
    words.tell(device.take_faults(), tell, rec.event)
