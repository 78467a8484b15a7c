"""Device faults in words: one line per incident, with units, for the live terminal.

The recording keeps every :class:`~ramdaq.drivers.base.DeviceFault` as an event; this module
only decides what a person watching the trial is told, and how:

* a fault marked ``at_connect`` (bytes before the first frame boundary, the backlog of an
  adapter's start-up) is part of a normal connect: recorded, not shown;
* faults within :data:`INCIDENT_S` of stream time that are one incident -- a corrupt frame,
  the bytes skipped to find the next frame and the samples it took with it -- are one line, the
  faults of one kind in it summed (two unreadable lines, two gaps), at the time of its first
  fault (a gap's first missing sample); a part of that incident reported later (in the next
  batch) is not shown again, unless it is a second gap (each gap is reported once, so the lines
  add up to the recording's gap list);
* a fault that repeats every frame (a wrong channel count) is shown once, and then at most every
  :data:`REPEAT_S` seconds (wall clock: no samples may be coming) with the count so far;
* :meth:`FaultWords.tally` gives one line of counts for the trial's summary.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Iterable

from .base import DeviceFault

__all__ = ["FaultWords", "REPEAT_S", "number_runs"]

INCIDENT_S = 0.01
"""Faults of an incident's kinds this close in stream time are one incident, s: a CAN frame of
the wrong length and the cycle it lost are a sample apart; two serial frames (32 samples at
2048 Hz, 15.6 ms) are never this close."""
REPEAT_S = 10.0
"""Least seconds between two lines for a fault that repeats (``frame_mismatch``)."""
_INCIDENT = ("crc_error", "resync", "seq_gap", "bad_crc", "wrong_dlc", "bad_frame", "port_back")
_REPEATING = ("frame_mismatch",)
_LOSSES = ("seq_gap", "port_back")  # each is a gap of its own: never taken as said already


def number_runs(ns: Iterable[int]) -> str:
    """Channel or gage numbers as runs, in the order given: [1, 2, 3, 5] -> ``"1-3, 5"``,
    [9, ..., 16] -> ``"9-16"``; a run of two is written out (``"4, 5"``)."""
    runs: list[list[int]] = []
    for n in ns:
        if runs and n == runs[-1][-1] + 1:
            runs[-1].append(n)
        else:
            runs.append([n])
    return ", ".join(f"{r[0]}-{r[-1]}" if len(r) > 2 else ", ".join(map(str, r)) for r in runs)


def _s(n: float, unit: str) -> str:
    return f"{n:g} {unit}" + ("" if n == 1 else "s")


def _samples(d: dict, fs_hz: float) -> str:
    n = int(d.get("missing_samples", d.get("gap_samples", 0)))
    return f"{_s(n, 'sample')} ({n / fs_hz:.3f} s) missing"


def describe(f: DeviceFault, device: str, fs_hz: float) -> str:
    """One fault in words (no time stamp): what happened, with its numbers and units."""
    d, k = f.detail, f.kind
    words = {
        "crc_error": lambda: f"{_s(d.get('count', 1), 'corrupt frame')} dropped (CRC failed)",
        "resync": lambda: f"{_s(d.get('bytes_discarded', 0), 'stray byte')} skipped to the next frame",
        "seq_gap": lambda: _samples(d, fs_hz) + (f" in {d['gaps']} gaps" if d.get("gaps", 1) > 1 else "")
                           + (" at the end (the stream ended before every group delivered them)"
                              if d.get("to_end") else ""),
        "repeated_frame": lambda: f"{_s(d.get('frames', 1), 'repeated frame')} dropped",
        "stale_frame": lambda: f"a frame {d.get('where', '')} the stream that the next one does not "
                               "continue dropped",
        "stream_restart": lambda: f"the device restarted its count: about {_samples(d, fs_hz)} "
                                  "(estimated from the host clock)",
        "port_lost": lambda: f"port {d.get('url', device)} lost ({d.get('error', '?')}), reconnecting "
                             f"every {d.get('retry_every_s', 0):g} s, giving up after "
                             f"{d.get('give_up_s', 0):g} s",
        "port_back": lambda: f"port {d.get('url', device)} back after {d.get('down_s', 0):.1f} s: "
                             + _samples(d, fs_hz),
        "frame_mismatch": lambda: f"device sends {d.get('channels')} channels, the rig expects "
                                  f"{d.get('expected')}: frames refused"
                                  + (f" ({d['total']} so far)" if d.get("total", 1) > 1 else ""),
        "no_data": lambda: f"no data from {device} for {d.get('quiet_s', 0):g} s",
        "data_back": lambda: (f"first data from {device} after {d.get('silent_s', 0):.1f} s" if d.get("first")
                              else f"data from {device} again after {d.get('silent_s', 0):.1f} s"),
        "bus_lost": lambda: f"CAN bus {d.get('bus', '?')} lost ({d.get('error', '?')})",
        "bus_off": lambda: f"CAN bus {d.get('bus', '?')} off ({d.get('reason', '')})",
        "bus_recovered": lambda: f"CAN bus {d.get('bus', '?')} back after {d.get('off_s', 0):g} s off",
        "group_timeout": lambda: f"frame group {d.get('group')} (channels {d.get('channels', '?')}) silent "
                                 f"for {d.get('silent_s', 0):g} s while another delivers: declared "
                                 "missing; nothing is recorded until it speaks again (a block carries "
                                 "every channel), the other groups' samples meanwhile are lost",
        "bad_crc": lambda: f"{_s(d.get('count', 1), 'corrupt frame')} dropped (CRC failed)",
        "wrong_dlc": lambda: f"{_s(d.get('count', 1), 'frame')} of the wrong length dropped "
                             f"(id {d.get('id')}, {d.get('dlc')} bytes)",
        "bad_frame": lambda: f"{_s(d.get('count', 1), 'unreadable line')} from the adapter "
                             f"({d.get('reason', '')})",
        "unrelated_frame": lambda: f"{_s(d.get('count', 1), 'frame')} of other nodes ignored",
        "delayed_frames": lambda: f"{_s(d.get('frames', 0), 'frame')} came {d.get('late_s', 0):g} s "
                                  "late (none lost)" + (f"; or a silence of {d['whole_wraps_late']} "
                                  "whole counter wrap(s), which the counter cannot tell"
                                  if d.get("whole_wraps_late") else ""),
        "gap_unknown": lambda: f"a gap of about {d.get('estimated_samples', 0)} samples "
                               f"(+- {d.get('uncertainty_samples', 0)}) the counter cannot measure",
        "seq_wrap": lambda: f"a silence of {d.get('wraps')} whole counter wrap(s) "
                            f"({d.get('wrap_samples', 0) * d.get('wraps', 0)} samples) missing",
        "foreign_sender": lambda: "a second sender with this front-end's identifiers: its frames "
                                  "are dropped",
        "foreign_sender_gone": lambda: "the second sender is quiet again",
        "foreign_frame": lambda: f"{_s(d.get('count', 1), 'frame')} of the second sender dropped",
        "conflicting_frame": lambda: f"{_s(d.get('count', 1), 'cycle')} in which the two senders "
                                     "disagree lost",
        "duplicate_frame": lambda: f"{_s(d.get('count', 1), 'duplicate frame')} dropped",
        "late_frame": lambda: f"{_s(d.get('count', 1), 'frame')} too late for its cycle dropped",
        "seq_outlier": lambda: f"{_s(d.get('count', 1), 'frame')} with a lone SEQ jump dropped",
        "error_frame": lambda: f"{_s(d.get('count', 1), 'CAN error frame')} "
                               f"(class {d.get('error_class', '?')})",
        "error_passive": lambda: f"CAN bus {d.get('bus', '?')} error-passive",
    }
    fn = words.get(k)
    if fn is not None:
        return fn()
    extra = ", ".join(f"{key} {value}" for key, value in d.items())
    return k.replace("_", " ") + (f" ({extra})" if extra else "")


_SUMMED = {"count": ("crc_error", "bad_crc", "wrong_dlc", "bad_frame"),
           "missing_samples": ("seq_gap",), "bytes_discarded": ("resync",)}


def _merged(group: list[DeviceFault]) -> list[DeviceFault]:
    """An incident's faults with those of one kind made one: counts and missing samples summed
    (``gaps``: how many gaps), the reasons of unreadable lines joined; in first-seen order."""
    out: dict[str, DeviceFault] = {}
    for f in group:
        m = out.get(f.kind)
        if m is None:
            out[f.kind] = f
            continue
        d = dict(m.detail)
        for key, kinds in _SUMMED.items():
            if f.kind in kinds:
                one = 1 if key == "count" else 0
                d[key] = int(d.get(key, one)) + int(f.detail.get(key, one))
        if f.kind == "seq_gap":
            d["gaps"] = int(d.get("gaps", 1)) + 1
        if f.detail.get("reason") and f.detail["reason"] != d.get("reason"):
            d["reason"] = f"{d.get('reason', '')}; {f.detail['reason']}"
        out[f.kind] = DeviceFault(f.kind, m.t_ns, d)
    return list(out.values())


def _near(a_ns: int, b_ns: int) -> bool:
    return abs(a_ns - b_ns) <= INCIDENT_S * 1e9


class FaultWords:
    """Turns batches of faults into the lines to show (module notes); keeps the counts."""

    def __init__(self, device: str, fs_hz: float) -> None:
        self.device = device
        self.fs_hz = fs_hz
        self.counts: Counter = Counter()  # kind -> faults (or frames, where the fault counts them)
        self.silent_s = 0.0
        self._incident_t: int | None = None  # stream time of the last incident shown, ns
        self._incident_gap = False  # ... and whether its line said a gap
        self._repeat_t: dict[tuple, float] = {}  # (kind, what) -> monotonic s last shown

    def tell(self, faults: list[DeviceFault], say: Callable[[str], None] | None,
             record: Callable[..., None] | None = None) -> None:
        """Record each fault through ``record`` (a recorder's ``event(kind, t_ns, **detail)``;
        None where the faults are recorded already or nothing is recorded), then say their
        :meth:`lines` through ``say`` (None: counted, not said)."""
        if record is not None:
            for fault in faults:
                record(fault.kind, fault.t_ns, **fault.detail)
        for line in self.lines(faults):
            if say is not None:
                say(line)

    def lines(self, faults: Iterable[DeviceFault]) -> list[str]:
        """The lines to show for one batch of faults (oldest first)."""
        out: list[str] = []
        group: list[DeviceFault] = []
        for f in sorted(faults, key=lambda f: f.t_ns):  # a device may report out of stream order
            if f.detail.get("at_connect"):
                continue
            self._count(f)
            if f.kind in _INCIDENT:
                if group and not _near(group[0].t_ns, f.t_ns):
                    out.append(self._incident(group))
                    group = []
                if (group or self._incident_t is None or not _near(f.t_ns, self._incident_t)
                        or (f.kind in _LOSSES and self._incident_gap)):  # a gap of its own
                    group.append(f)
                continue
            if group:
                out.append(self._incident(group))
                group = []
            if f.kind in _REPEATING:
                what = (f.kind, f.detail.get("channels"))
                last, now = self._repeat_t.get(what), time.monotonic()
                if last is not None and now - last < REPEAT_S:
                    continue
                self._repeat_t[what] = now
            out.append(self._line(f.t_ns, describe(f, self.device, self.fs_hz)))
        if group:
            out.append(self._incident(group))
        return out

    def _incident(self, group: list[DeviceFault]) -> str:
        """One incident's line, at its first fault's time (a gap's: its first missing sample),
        the causes before the samples they cost."""
        self._incident_t = group[0].t_ns
        self._incident_gap = any(f.kind in _LOSSES for f in group)
        parts = sorted(_merged(group), key=lambda f: f.kind in _LOSSES)
        return self._line(group[0].t_ns, "; ".join(describe(f, self.device, self.fs_hz) for f in parts))

    def _line(self, t_ns: int, words: str) -> str:
        if words.startswith(("no data from", "data from", "first data from")):  # names the device
            return f"{words} (stream time {t_ns / 1e9:.3f} s)"
        return f"{self.device} at {t_ns / 1e9:.3f} s: {words}"

    def _count(self, f: DeviceFault) -> None:
        d = f.detail
        if f.kind == "frame_mismatch":
            self.counts[f.kind] = max(self.counts[f.kind], int(d.get("total", 1)))
        elif f.kind in ("crc_error", "bad_crc", "wrong_dlc", "bad_frame"):
            self.counts[f.kind] += int(d.get("count", 1))
        else:
            self.counts[f.kind] += 1
        if f.kind == "data_back":
            self.silent_s += float(d.get("silent_s", 0))

    def tally(self) -> str | None:
        """One line of what went wrong with the device over the trial; ``None`` if nothing did
        (faults of a normal connect are not counted as going wrong)."""
        c = self.counts
        parts = [(c["frame_mismatch"], "frame(s) refused for a wrong channel count"),
                 (c["crc_error"] + c["bad_crc"], "corrupt frame(s)"),
                 (c["wrong_dlc"], "frame(s) of the wrong length"),
                 (c["bad_frame"], "unreadable line(s) from the adapter"),
                 (c["seq_gap"], "gap(s) in the frame sequence"),
                 (c["group_timeout"], "frame group(s) declared missing"),
                 (c["no_data"], "silence(s) of the device"),
                 (c["port_lost"] + c["bus_lost"], "lost port(s) or bus(es)"),
                 (c["port_back"], "reconnect(s)")]
        said = [f"{n} {what}" for n, what in parts if n]
        return f"device faults: {', '.join(said)}" if said else None
