"""Logs for Foxglove: a recording read with the plain mcap reader and the schemas it registers
only -- each gage's SI values per block, UTC log times, real JSON schemas, the shipped .proto."""

from __future__ import annotations

import json
import re
import time
from importlib.resources import files
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from ramdaq.daq.analyzer import hit_to_json, judge_event
from ramdaq.daq.recorder import CLOCK_METADATA, Recorder
from ramdaq.daq.topics import GAGES_TOPIC, RESULTS_TOPIC, TRACE_TOPIC, GageSummary
from ramdaq.daq.trigger import Trigger
from ramdaq.drivers.block import Block, StreamInfo
from ramdaq.drivers.mcap_format import BLOCK_TOPIC, IMPACTS_TOPIC, BlockProto
from ramdaq.drivers.mcap_replay import McapReplayDevice
from ramdaq.drivers.sim import SimDevice

RECORDINGS = Path(__file__).parent.parent / "recordings"


@pytest.fixture(scope="module")
def trial(tmp_path_factory) -> tuple[Path, list[Block], int, int]:
    """A simulated 6 s trial recorded with its detections and results, as a live trial writes
    them; the wall clock before and after, ns."""
    path = tmp_path_factory.mktemp("topics") / "trial.mcap"
    t_before = time.time_ns()
    blocks = []
    with SimDevice("albacore", seed=3, duration_s=6.0, impacts=[2.0]) as sim, \
            Recorder(path, sim.info) as rec:
        trigger = Trigger(sim.info)
        rig = sim.rig
        events = []
        for b in sim:
            blocks.append(b)
            rec.put(b)
            for ev in trigger.process(b):
                rec.write_json(IMPACTS_TOPIC, ev.to_json(), ev.t_ns)
                events.append(ev)
        for ev in trigger.flush():
            rec.write_json(IMPACTS_TOPIC, ev.to_json(), ev.t_ns)
            events.append(ev)
        assert len(events) == 1
        for k, ev in enumerate(events):
            doc = hit_to_json(judge_event(k, ev, sim.info, rig))
            rec.write_json(RESULTS_TOPIC, {key: doc[key] for key in ("index", "accepted", "reason",
                                                                    "analysis")}, ev.t_ns)
    return path, blocks, t_before, time.time_ns()


def _read(path: Path) -> tuple[dict, list]:
    with open(path, "rb") as f:
        reader = make_reader(f)
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        msgs = []
        for schema, channel, message in reader.iter_messages():
            decoded = None
            if channel.message_encoding == "protobuf":  # by the registered descriptor alone
                decoded = DecoderFactory().decoder_for("protobuf", schema)(message.data)
            msgs.append((schema, channel, message, decoded))
    return meta, msgs


def test_every_json_message_fits_its_registered_schema(trial) -> None:
    _, msgs = _read(trial[0])
    seen = set()
    for schema, channel, message, _ in msgs:
        if channel.message_encoding == "json":
            assert schema.encoding == "jsonschema"
            doc = json.loads(schema.data)
            jsonschema.validate(json.loads(message.data), doc)
            seen.add((channel.topic, doc["title"]))
    assert {(IMPACTS_TOPIC, "ramdaq.Impact"), (RESULTS_TOPIC, "ramdaq.Result"),
            (GAGES_TOPIC, "ramdaq.GageBlock"), (TRACE_TOPIC, "ramdaq.GageTrace")} <= seen
    impact_schema = next(json.loads(s.data) for s, c, *_ in msgs if c.topic == IMPACTS_TOPIC)
    assert "onset_s" in impact_schema["required"]  # the trigger's schema, not a placeholder


def test_per_gage_si_fields_and_utc_times(trial) -> None:
    path, blocks, t_before, t_after = trial
    meta, msgs = _read(path)
    by_topic: dict[str, list] = {}
    for schema, channel, message, decoded in msgs:
        by_topic.setdefault(channel.topic, []).append((schema, message, decoded))
    gages = by_topic[GAGES_TOPIC]
    raw = by_topic[BLOCK_TOPIC]
    assert len(gages) == len(raw) == len(blocks)
    schema = json.loads(gages[0][0].data)
    assert schema["properties"]["g04"]["description"] == "g04, m/s^2"
    for (_, gm, _), (_, bm, proto), b in zip(gages, raw, blocks, strict=True):
        g = json.loads(gm.data)
        # the block decoded by the registered protobuf schema alone, in SI
        x = np.asarray(proto.counts).reshape(proto.n_channels, proto.n_samples) * \
            np.asarray(proto.scale)[:, None]
        assert [g[c]["max"] for c in ("g01", "g04", "g16")] == [x[0].max(), x[3].max(), x[15].max()]
        assert g["g04"]["min"] == x[3].min() and g["g04"]["mean"] == pytest.approx(x[3].mean(),
                                                                                    rel=1e-12)
        # publish_time: device time; log_time: UTC, in step with device time
        assert bm.publish_time == gm.publish_time == b.t0_ns == g["device_time_ns"]
        assert gm.log_time == bm.log_time
    clock = meta[CLOCK_METADATA]
    utc0, dev0 = int(clock["utc_ns"]), int(clock["device_ns"])
    assert t_before - 10**9 <= utc0 <= t_after  # the first block's UTC (less its 50 ms length)
    for _, m, _ in raw:
        assert m.log_time == utc0 + m.publish_time - dev0
    assert 2020 < time.gmtime(raw[0][1].log_time / 1e9).tm_year  # not 1970


def test_trace_is_anti_aliased() -> None:
    """A 215 Hz tone at 2048 Hz is above the trace's Nyquist (93 Hz): it must not come back as an
    alias; a 20 Hz tone passes whole."""
    fs, n = 2048.0, 2048 * 4
    info = StreamInfo("test", fs, ("hi", "lo"), ("m/s^2", "m/s^2"), (1, 2))
    t = np.arange(n) / fs
    x = np.vstack([np.sin(2 * np.pi * 215 * t), np.sin(2 * np.pi * 20 * t)])
    scale = np.array([1e-6, 1e-6])
    counts = np.round(x / scale[:, None]).astype(np.int32)
    summary = GageSummary(info)
    trace = []
    for k, a in enumerate(range(0, n, 102)):
        blk = Block(k, a, round(a / fs * 1e9), fs, counts[:, a:a + 102], scale)
        trace += [m for _, m in summary.trace(blk)]
    assert summary.rate_hz == fs / 11
    settled = [m for m in trace if m["t_s"] > 1.0]  # after the filter's start
    hi = np.array([m["hi"] for m in settled])
    lo = np.array([m["lo"] for m in settled])
    # 56 dB (the 8th-order low-pass at 0.4 x 186 Hz, evaluated at 0.6 x 186 Hz, the nearest
    # frequency that folds into its pass band; 215 Hz is further out): |alias| < 10^(-56/20)
    assert np.max(np.abs(hi)) < 10 ** (-56 / 20)
    assert np.max(np.abs(lo)) == pytest.approx(1.0, abs=0.02)  # 20 Hz: flat pass band, sampled peak


def test_old_recordings_read_the_same() -> None:
    """Recordings made when log_time was device time: device times still come back as such."""
    with McapReplayDevice(RECORDINGS / "albacore-water.mcap") as dev:
        sim = dev.json_messages("/ramdaq/sim/impacts")
        assert [m.t_ns for m in sim] == [1992187500, 7968750000, 13995117188]  # as read before


def test_block_proto_is_shipped_and_matches_the_schema() -> None:
    text = (files("ramdaq.drivers") / "block.proto").read_text()
    fields = re.findall(r"^\s*(repeated )?(\w+)\s+(\w+)\s*=\s*(\d+);", text, re.M)
    f = BlockProto.DESCRIPTOR.fields_by_name
    names = {"uint64": f["seq"].TYPE_UINT64, "int64": f["seq"].TYPE_INT64,
             "double": f["seq"].TYPE_DOUBLE, "uint32": f["seq"].TYPE_UINT32,
             "sint32": f["seq"].TYPE_SINT32}
    assert [(name, int(num), names[typ], bool(rep)) for rep, typ, name, num in fields] == [
        (d.name, d.number, d.type, d.is_repeated) for d in BlockProto.DESCRIPTOR.fields]
