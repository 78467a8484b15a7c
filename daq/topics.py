"""The JSON topics a ramdaq recording carries beside its blocks, with their JSON Schemas -- the
documents registered in the file (schema encoding ``jsonschema``), so that Foxglove and any
MCAP reader decode and plot them without ramdaq (``docs/topics.md``).

``/ramdaq/gages``
    One message per block: the block's ``seq``, ``first_sample``, stream time ``t_s`` (s since
    the stream's first sample) and device time ``device_time_ns``, and for each channel, by its
    name (``g01`` ... ``g16``, a ram load cell's), ``{"min", "max", "mean"}`` of its samples in
    the block, in SI units (the schema says which: m/s^2, N). A Plot panel on
    ``/ramdaq/gages.g04.max`` and ``.min`` draws gage 4's envelope, no alias.
``/ramdaq/gages/trace``
    Every channel decimated to ``TRACE_RATE_HZ`` or less (an integer factor ``q``), in SI: one
    message per kept sample, ``{"t_s", "device_time_ns", "<channel>": value, ...}``. Before
    keeping every ``q``-th sample, an 8th-order Butterworth low-pass at 0.4 of the kept rate,
    its state carried from block to block (restarted at a gap), attenuates what would alias by
    56 dB or more (its response at 0.6 of the kept rate, the lowest frequency that folds into
    the band below 0.4). The filter delays the trace by a few kept samples; it is a picture,
    not the data.
``/ramdaq/impacts``
    The trigger's detections (:data:`ramdaq.daq.trigger.IMPACT_JSON_SCHEMA`).
``/ramdaq/results``
    Each hit's final result (:data:`RESULTS_JSON_SCHEMA`).

``/ramdaq/events`` and ``/ramdaq/sim/impacts`` keep their schemas from
:data:`ramdaq.drivers.mcap_format.JSON_SCHEMAS`.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

# at import, not in GageSummary: a recorder is made once its device is open and streaming, and
# a first import of scipy.signal there (~0.5 s) stalls a paced device's reader (a replay, which
# makes no recorder, does not import this module)
import scipy.signal

from ..drivers import mcap_format as fmt
from ..drivers.block import Block, StreamInfo
from .trigger import IMPACT_JSON_SCHEMA

__all__ = ["GAGES_TOPIC", "TRACE_TOPIC", "RESULTS_TOPIC", "TRACE_RATE_HZ", "RESULTS_JSON_SCHEMA",
           "GageSummary", "gages_schema", "trace_schema", "json_schema", "schema_for"]

GAGES_TOPIC = "/ramdaq/gages"
TRACE_TOPIC = "/ramdaq/gages/trace"
RESULTS_TOPIC = "/ramdaq/results"
TRACE_RATE_HZ = 200.0
"""Highest rate of ``/ramdaq/gages/trace``, Hz: 20 s of a trial is 4 000 small messages."""

_NUM = {"type": "number"}
_NUM_OR_NULL = {"type": ["number", "null"]}
_DECREMENT = {"type": "object", "description": "a decrement, estimator's and the report's peaks'",
              "properties": {k: _NUM_OR_NULL for k in
                             ("f_hz", "delta", "delta_se", "peak_delta", "peak_delta_se")}}
RESULTS_JSON_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "ramdaq.Result",
    "description": "The final result of one hit of a live trial, SI units; the analysis is that "
                   "of ramdaq analyze's report.json (null when the hit was rejected).",
    "type": "object",
    "required": ["index", "accepted", "reason", "analysis"],
    "properties": {
        "index": {"type": "integer", "description": "hit number in the trial, from 0"},
        "accepted": {"type": "boolean"},
        "reason": {"type": "string", "description": "why the hit was rejected; empty if accepted"},
        "analysis": {
            "type": ["object", "null"],
            "properties": {
                "onset_s": {**_NUM, "description": "s since the stream's first sample"},
                "decay_start_s": _NUM, "decay_duration_s": _NUM,
                "record_samples": {"type": ["integer", "null"], "description": "samples of the "
                                   "decay record, from decay_start_s"},
                "analysed_samples": {"type": ["integer", "null"], "description": "leading samples "
                                     "of the record every fit used (fewer where the tail at the "
                                     "noise floor was cropped to an FFT-fast length; a note says)"},
                "predominant_mode": {"type": "integer", "description": "index in modes of the "
                                     "most energetic mode on the rudder"},
                "chosen_mode": {"type": ["integer", "null"], "description": "index in modes of "
                                "the mode mode_hz chose for the chain (null: none asked)"},
                "mode_hz_asked": {**_NUM_OR_NULL, "description": "the mode_hz asked for, Hz"},
                "f_hz": {**_NUM, "description": "frequency of the mode the chain ran on (the "
                         "chosen one, else the predominant one), Hz"},
                "modes": {"type": "array", "items": {
                    "type": "object",
                    "properties": {k: _NUM_OR_NULL for k in
                                   ("f_hz", "f_se_hz", "delta", "delta_se", "zeta", "zeta_se")}
                    | {"shape": {"type": "object", "description": "gNN: [|amplitude|, phase rad]"}}}},
                "verdicts": {"type": "object", "additionalProperties": {
                    "type": "object", "properties": {"verdict": {"type": "string"},
                                                     "reason": {"type": "string"}}}},
                "gages": {"type": "object", "additionalProperties": _DECREMENT,
                          "description": "per gage (g01 ...) decrement"},
                "motions": {"type": "object", "additionalProperties": _DECREMENT},
                "relative_to_hull": {"type": "object", "additionalProperties": _DECREMENT},
                "alpha1_over_gamma1": _NUM_OR_NULL,
                "damping": {"type": "object", "additionalProperties": _NUM_OR_NULL,
                            "description": "C (N s/m), c (N m s/rad), masses (kg, kg m^2), "
                                           "delta_modal"},
                "stock_lengths_m": {"type": "object", "additionalProperties": _NUM_OR_NULL},
                "table2b": {"type": "object"},
                "notes": {"type": "array", "items": {"type": "string"}},
            },
        },
    },
}
"""JSON Schema of ``/ramdaq/results`` (``hit_to_json`` less ``onset_*``, as the session writes)."""


def gages_schema(info: StreamInfo) -> dict[str, Any]:
    """JSON Schema of ``/ramdaq/gages`` for this stream: one property per channel, its unit said."""
    chan = {c: {"$ref": "#/$defs/stats", "description": f"{c}, {u}"}
            for c, u in zip(info.channels, info.units, strict=True)}
    stats = {"type": "object", "required": ["min", "max", "mean"],
             "properties": {k: {"type": "number"} for k in ("min", "max", "mean")}}
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": "ramdaq.GageBlock",
            "description": "each channel's min, max and mean over one block, SI units",
            "type": "object", "required": ["seq", "first_sample", "t_s", "device_time_ns", *chan],
            "$defs": {"stats": stats},
            "properties": {"seq": {"type": "integer"}, "first_sample": {"type": "integer"},
                           "t_s": {"type": "number", "description": "stream time of the block's "
                                                                    "first sample, s"},
                           "device_time_ns": {"type": "integer"}} | chan}


def trace_schema(info: StreamInfo) -> dict[str, Any]:
    """JSON Schema of ``/ramdaq/gages/trace`` for this stream."""
    chan = {c: {"type": "number", "description": u}
            for c, u in zip(info.channels, info.units, strict=True)}
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", "title": "ramdaq.GageTrace",
            "description": "every channel low-passed and decimated, SI units",
            "type": "object", "required": ["t_s", "device_time_ns", *chan],
            "properties": {"t_s": {"type": "number", "description": "stream time, s"},
                           "device_time_ns": {"type": "integer"}} | chan}


def json_schema(topic: str, info: StreamInfo) -> dict[str, Any]:
    """The JSON Schema registered for ``topic`` in a recording of ``info``."""
    known = {GAGES_TOPIC: lambda: gages_schema(info), TRACE_TOPIC: lambda: trace_schema(info),
             fmt.IMPACTS_TOPIC: lambda: IMPACT_JSON_SCHEMA, RESULTS_TOPIC: lambda: RESULTS_JSON_SCHEMA}
    if topic in known:
        return known[topic]()
    return fmt.JSON_SCHEMAS.get(topic, {"title": topic, "type": "object"})


def schema_for(topic: str, info: StreamInfo) -> tuple[str, bytes]:
    """``(schema name, schema data)`` to register for a JSON topic."""
    schema = json_schema(topic, info)
    return schema["title"], json.dumps(schema, separators=(",", ":")).encode()


class GageSummary:
    """The derived topics of a stream, block by block: ``/ramdaq/gages`` and the decimated
    ``/ramdaq/gages/trace`` (module docstring). Keeps the low-pass's state between blocks."""

    def __init__(self, info: StreamInfo) -> None:
        self.channels = info.channels
        self.q = max(1, math.ceil(info.fs_hz / TRACE_RATE_HZ))
        self.rate_hz = info.fs_hz / self.q
        self._sos = None  # the trace's anti-alias low-pass (none when not decimated)
        if self.q > 1:
            self._sos = scipy.signal.butter(8, 0.8 / self.q, output="sos")
        self._zi: np.ndarray | None = None
        self._next = None  # the sample expected next; another one is a gap: the filter restarts

    def block(self, b: Block) -> dict[str, Any]:
        """The ``/ramdaq/gages`` message of block ``b``."""
        x = b.values()
        out: dict[str, Any] = {"seq": b.seq, "first_sample": b.first_sample,
                               "t_s": b.first_sample / b.fs_hz, "device_time_ns": b.t0_ns}
        if b.n_samples:
            lo, hi, mean = x.min(axis=1), x.max(axis=1), x.mean(axis=1)
            for i, c in enumerate(self.channels):
                out[c] = {"min": float(lo[i]), "max": float(hi[i]), "mean": float(mean[i])}
        return out

    def trace(self, b: Block) -> list[tuple[int, dict[str, Any]]]:
        """``(device time ns, message)`` of each ``/ramdaq/gages/trace`` sample in block ``b``."""
        x = b.values()
        if self._sos is not None and b.n_samples:
            if self._zi is None or b.first_sample != self._next:
                self._zi = scipy.signal.sosfilt_zi(self._sos)[:, None, :] * x[None, :, :1]
            x, self._zi = scipy.signal.sosfilt(self._sos, x, axis=-1, zi=self._zi)
        self._next = b.next_sample
        keep = np.arange((-b.first_sample) % self.q, b.n_samples, self.q)
        msgs = []
        for j in keep.tolist():
            n = b.first_sample + j
            t_ns = b.t0_ns + round(j / b.fs_hz * 1e9)
            msg = {"t_s": n / b.fs_hz, "device_time_ns": t_ns}
            msg |= {c: float(v) for c, v in zip(self.channels, x[:, j], strict=True)}
            msgs.append((t_ns, msg))
        return msgs
