"""The on-disk format of a ramdaq recording: an MCAP file, shared by the recorder and replay.

Layout
------
Header       profile ``""``, library ``"ramdaq/<version> mcap-python/<version>"``.
Metadata     ``ramdaq.stream`` (string -> string), written first; see *Stream metadata*.
Attachment   ``rig.toml`` (media type ``application/toml``): ``StreamInfo.rig_toml``, when not
             empty.
Chunks       zstd-compressed (by default), each closed after ``chunk_seconds`` (0.25 s) of
             samples, one block if a block is longer, or ``chunk_seconds`` of wall time, and
             handed to the OS at once: a killed recorder loses at most the open chunk.
             Each chunk carries the CRC-32 of its uncompressed records. The live view's
             topics (``/ramdaq/gages``, ``/ramdaq/gages/trace``: three quarters of the
             bytes) have chunks of their own, each written after the chunk of blocks of the
             same time, so that a replay steps over them by the chunk index (summary)
             without decompressing them; recordings made before mix them with the blocks.
DataEnd      the CRC-32 of the whole data section (header, metadata, attachment, chunks and
             their indexes; 0 means none); the footer, the CRC-32 of the summary. Readers
             check every one (:mod:`ramdaq.drivers.mcap_replay`, *Integrity*).

Topics
------
``/ramdaq/block``
    Message encoding ``protobuf``, schema ``ramdaq.Block`` (schema encoding ``protobuf``: a
    serialized ``google.protobuf.FileDescriptorSet``, so Foxglove and ``mcap-protobuf-support``
    decode it without ramdaq). One message per :class:`~ramdaq.drivers.block.Block`::

        syntax = "proto3";
        package ramdaq;
        message Block {
          uint64 seq            = 1;  // +1 per block the device produced; a jump is a gap
          uint64 first_sample   = 2;  // index of the block's first sample since stream start
          int64  device_time_ns = 3;  // device time of the first sample, ns
          double sample_rate_hz = 4;  // Hz
          uint32 n_channels     = 5;
          uint32 n_samples      = 6;  // per channel
          repeated double scale  = 7; // SI units per count, one per channel (m/s^2, N)
          repeated sint32 counts = 8; // raw ADC counts, channel-major: counts[c*n_samples + i]
        }

    The value of sample ``i`` of channel ``c`` in SI units is ``counts[c*n_samples+i] *
    scale[c]``. Both repeated fields are packed; ``counts`` is ``sint32`` (zigzag varint): 3 bytes
    per sample for ``|count| < 2**20``, 4 bytes up to ``2**27``.
    Record ``publish_time`` = ``device_time_ns`` (clamped at 0, since MCAP times are unsigned);
    ``log_time`` = UTC (see *Times*); record ``sequence`` = ``seq mod 2**32``. The schema's
    ``.proto`` is shipped as ``ramdaq/drivers/block.proto`` (``drivers/block.proto``).
    Messages are in the order the device produced them; nobody fills a gap.

    Why one flat ``counts`` field and not a nested ``repeated Channel {double scale; repeated
    sint32 counts}``: measured on 1 s of 16 ch x 25.6 kHz, both encode in ~8 ms with the numpy
    encoder below (the flat one is encoded in cache-sized pieces too), both are the same size
    before and after zstd, but decoding through the protobuf runtime takes 2.4 ms flat versus
    4.8 ms nested (one parse and one array copy instead of sixteen).

``/ramdaq/events``
    JSON (schema encoding ``jsonschema``, schema ``ramdaq.Event``), one message per event:
    ``{"kind": str, "t_ns": int, "detail": {...}}``; ``publish_time`` = ``t_ns`` = device time in ns.
    Kinds: ``gap`` (the device skipped blocks or samples: ``after_seq``, ``seq``,
    ``missing_blocks``, ``expected_sample``, ``first_sample``, ``missing_samples``),
    ``overflow`` (the recorder's queue was full and it dropped blocks: ``first_seq``,
    ``last_seq``, ``blocks``, ``first_sample``, ``samples``, ``queue_blocks``),
    ``device_error`` and ``note`` (free text in ``detail["message"]``).

``/ramdaq/sim/impacts``
    JSON truth of each simulated impact, written by whoever drives a simulator:
    ``{"sample": int, "t_s": float, "peak_force_N": float, "duration_s": float,
    "location_m": [x, y, z]}``; ``publish_time`` = device time of the impact.

``/ramdaq/impacts``
    The trigger's detections, written by a live trial (``ramdaq trial``): one JSON message per
    detected blow, ``ImpactEvent.to_json()`` of :mod:`ramdaq.daq.trigger` (onset, flags, end
    reason; the samples are not included); ``publish_time`` = device time of the onset. Schema:
    the trigger's ``IMPACT_JSON_SCHEMA`` (registered by the recorder; recordings made before
    registered a placeholder, ``{"title": "ramdaq.Impact", "type": "object"}``).

``/ramdaq/results``
    The final result of each hit, written by a live trial: ``{"index", "accepted", "reason",
    "analysis"}``, the analysis in SI as in ``ramdaq analyze``'s report.json (null when the hit
    was rejected); ``publish_time`` = device time of the hit's onset. Schema
    ``ramdaq.Result`` (:data:`ramdaq.daq.topics.RESULTS_JSON_SCHEMA`).

``/ramdaq/gages``, ``/ramdaq/gages/trace``
    Each channel in SI per block (min, max, mean as named fields) and decimated, derived by the
    recorder for Foxglove's Plot panel (:mod:`ramdaq.daq.topics`; ``docs/topics.md``).

Times
-----
``publish_time`` is the stream's device time; ``log_time`` is UTC in ns since 1970, anchored
at the recording's start: the recorder takes the wall clock when the first block arrives, less
that block's length, as the UTC of its first sample (metadata ``ramdaq.clock``: ``utc_ns``,
``device_ns``), and ``log_time = utc_ns + (device time - device_ns)``. Two recordings line up
in Foxglove by their ``log_time``. Recordings made before this held device time in both fields;
readers take device time from ``publish_time``, so both read the same.

Stream metadata
---------------
Record ``ramdaq.stream``, every value a string: ``format`` (``"1"``), ``device``, ``fs_hz``
(``repr`` of the float, exact), ``channels``, ``units``, ``gages`` (JSON lists), ``extra``
(JSON object; tuples come back as lists), ``ramdaq_version``, ``created_utc`` (ISO 8601).
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Mapping
from datetime import UTC, datetime
from typing import Any, NamedTuple

import numpy as np
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from google.protobuf.message import DecodeError

from .block import Block, StreamInfo
from .errors import FrameError

__all__ = [
    "BLOCK_SCHEMA_NAME", "BLOCK_TOPIC", "EVENTS_TOPIC", "IMPACTS_TOPIC", "SIM_IMPACTS_TOPIC",
    "STREAM_METADATA", "RIG_ATTACHMENT", "RIG_MEDIA_TYPE", "FORMAT_VERSION", "JSON_SCHEMAS",
    "MCAP_MAGIC", "BlockHeader", "BlockProto", "RecordingError", "TruncatedRecording",
    "NotARamdaqRecording", "CorruptRecording", "block_schema_data", "encode_block", "decode_block",
    "decode_header", "encode_json", "decode_json", "json_schema_for", "make_event", "ramdaq_version",
    "stream_info_to_metadata", "stream_info_from_metadata",
]

BLOCK_TOPIC = "/ramdaq/block"
EVENTS_TOPIC = "/ramdaq/events"
SIM_IMPACTS_TOPIC = "/ramdaq/sim/impacts"
IMPACTS_TOPIC = "/ramdaq/impacts"
BLOCK_SCHEMA_NAME = "ramdaq.Block"
STREAM_METADATA = "ramdaq.stream"
RIG_ATTACHMENT = "rig.toml"
RIG_MEDIA_TYPE = "application/toml"
FORMAT_VERSION = "1"
MCAP_MAGIC = b"\x89MCAP0\r\n"


# -- errors ------------------------------------------------------------------------------------
class RecordingError(Exception):
    """A ramdaq MCAP recording cannot be written or read as one (see ``daq/errors.py``)."""


class TruncatedRecording(RecordingError):
    """The file ends without an MCAP footer: the writer was killed; ``ramdaq recover`` it."""


class NotARamdaqRecording(RecordingError):
    """Not an MCAP file, or an MCAP file without ramdaq's stream metadata and block topic."""


class CorruptRecording(RecordingError):
    """A record of the file fails its CRC check or does not parse (a flipped bit, a bad disk):
    its samples cannot be trusted; ``ramdaq recover`` copies every intact record to a new file."""


# -- the ramdaq.Block protobuf schema, built at run time ---------------------------------------
_F = descriptor_pb2.FieldDescriptorProto
_BLOCK_FIELDS = (  # (name, number, type, repeated)
    ("seq", 1, _F.TYPE_UINT64, False),
    ("first_sample", 2, _F.TYPE_UINT64, False),
    ("device_time_ns", 3, _F.TYPE_INT64, False),
    ("sample_rate_hz", 4, _F.TYPE_DOUBLE, False),
    ("n_channels", 5, _F.TYPE_UINT32, False),
    ("n_samples", 6, _F.TYPE_UINT32, False),
    ("scale", 7, _F.TYPE_DOUBLE, True),
    ("counts", 8, _F.TYPE_SINT32, True),
)


def _block_file_descriptor() -> descriptor_pb2.FileDescriptorProto:
    fd = descriptor_pb2.FileDescriptorProto(
        name="ramdaq/block.proto", package="ramdaq", syntax="proto3"
    )
    msg = fd.message_type.add(name="Block")
    for name, number, ftype, repeated in _BLOCK_FIELDS:
        label = _F.LABEL_REPEATED if repeated else _F.LABEL_OPTIONAL
        field = msg.field.add(name=name, number=number, type=ftype, label=label, json_name=name)
        if repeated:
            field.options.packed = True
    return fd


_FILE_DESCRIPTOR = _block_file_descriptor()
_POOL = descriptor_pool.DescriptorPool()
_POOL.Add(_FILE_DESCRIPTOR)
BlockProto = message_factory.GetMessageClass(_POOL.FindMessageTypeByName(BLOCK_SCHEMA_NAME))
"""The ``ramdaq.Block`` protobuf message class (a private descriptor pool, no protoc)."""


def block_schema_data() -> bytes:
    """The MCAP schema data of ``ramdaq.Block``: a serialized ``FileDescriptorSet``."""
    return descriptor_pb2.FileDescriptorSet(file=[_FILE_DESCRIPTOR]).SerializeToString()


# -- fast encoder ------------------------------------------------------------------------------
_ENCODE_PIECE = 1 << 16  # samples per numpy pass: temporaries stay in cache (~1.3x faster)


def _varint(value: int) -> bytes:
    out = bytearray()
    while value > 0x7F:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _packed_sint32(x: np.ndarray) -> np.ndarray:
    """Zigzag varints of int32 ``x`` (1-D), as protobuf packs a ``repeated sint32``, uint8."""
    z = ((x << 1) ^ (x >> 31)).view(np.uint32)  # zigzag: 0,-1,1,-2 -> 0,1,2,3
    ge = [z >= np.uint32(1 << (7 * k)) for k in (1, 2, 3, 4)]  # needs more than k+1 bytes
    nbytes = ge[0].astype(np.int32)
    for g in ge[1:]:
        nbytes += g
    nbytes += 1
    ends = np.cumsum(nbytes)
    total = int(ends[-1])
    starts = ends - nbytes
    out = np.empty(total + 4, np.uint8)
    top = max((k + 1 for k in range(4) if ge[k].any()), default=0)
    # Byte k of every value goes to starts + k. Writing k from high to low, a value's unused
    # high bytes land on positions that the following values then overwrite with real bytes.
    for k in range(top, -1, -1):
        plane = (z >> np.uint32(7 * k)).astype(np.uint8) & np.uint8(0x7F)
        if k < 4:
            plane |= ge[k].view(np.uint8) << np.uint8(7)  # continuation bit
        out[starts + k] = plane
    return out[:total]


def encode_block(block: Block) -> bytes:
    """Serialize a block as a ``ramdaq.Block`` protobuf message.

    The bytes are identical to ``BlockProto(...).SerializeToString()`` (proto3: zero scalars
    omitted, fields in number order, repeated fields packed) but about 3x faster, because the
    zigzag varints of ``counts`` are computed with numpy.

    Parameters
    ----------
    block : Block
        ``counts`` int32, shape ``(n_channels, n_samples)``; ``seq``, ``first_sample`` >= 0;
        ``t0_ns`` within int64.

    Returns
    -------
    bytes
        The message, about ``3 * n_channels * n_samples`` bytes for 24-bit counts.
    """
    if block.seq < 0 or block.first_sample < 0 or not -(2**63) <= block.t0_ns < 2**63:
        raise ValueError(
            f"block seq {block.seq}: seq and first_sample must be >= 0 and t0_ns fit in int64, "
            f"got first_sample {block.first_sample}, t0_ns {block.t0_ns}"
        )
    n_ch, n_s = block.counts.shape
    head = bytearray()
    for tag, value in ((0x08, block.seq), (0x10, block.first_sample)):
        if value:
            head += bytes((tag,)) + _varint(value)
    if block.t0_ns:
        head += b"\x18" + _varint(block.t0_ns & 0xFFFF_FFFF_FFFF_FFFF)  # int64: two's complement
    fs = struct.pack("<d", block.fs_hz)
    if fs != bytes(8):
        head += b"\x21" + fs
    for tag, value in ((0x28, n_ch), (0x30, n_s)):
        if value:
            head += bytes((tag,)) + _varint(value)
    if n_ch:
        head += b"\x3a" + _varint(8 * n_ch) + np.ascontiguousarray(block.scale, "<f8").tobytes()
    if n_ch * n_s == 0:
        return bytes(head)
    flat = np.ascontiguousarray(block.counts).reshape(-1)
    pieces = [_packed_sint32(flat[i : i + _ENCODE_PIECE]) for i in range(0, flat.size, _ENCODE_PIECE)]
    size = sum(p.size for p in pieces)
    return b"".join([head, b"\x42", _varint(size), *pieces])


# -- decoders ----------------------------------------------------------------------------------
def decode_block(data: bytes) -> Block:
    """Parse a ``ramdaq.Block`` message (from any protobuf writer) back into a :class:`Block`.

    Raises
    ------
    FrameError
        The bytes are not a consistent ``ramdaq.Block``.
    """
    msg = BlockProto()
    try:
        msg.ParseFromString(data)
    except DecodeError as err:
        raise FrameError(f"{BLOCK_TOPIC}: message is not a ramdaq.Block ({err})") from err
    n_ch, n_s = msg.n_channels, msg.n_samples
    counts = np.asarray(msg.counts, dtype=np.int32)  # upb has __array__: a memcpy, not a loop
    scale = np.array(msg.scale[:], dtype=np.float64)  # via a list: half the time of asarray
    if counts.size != n_ch * n_s or scale.size != n_ch:
        raise FrameError(
            f"{BLOCK_TOPIC}: block seq {msg.seq} has {counts.size} counts and {scale.size} "
            f"scales for {n_ch} channels x {n_s} samples"
        )
    try:
        return Block(
            seq=msg.seq, first_sample=msg.first_sample, t0_ns=msg.device_time_ns,
            fs_hz=msg.sample_rate_hz, counts=counts.reshape(n_ch, n_s), scale=scale,
        )
    except ValueError as err:
        raise FrameError(f"{BLOCK_TOPIC}: block seq {msg.seq}: {err}") from err


class BlockHeader(NamedTuple):
    """The scalar fields of a ``ramdaq.Block`` message, read without touching its samples."""

    seq: int
    first_sample: int
    t0_ns: int
    fs_hz: float
    n_channels: int
    n_samples: int

    @property
    def next_sample(self) -> int:
        return self.first_sample + self.n_samples


def _read_varint(data: bytes, pos: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if pos >= len(data) or shift > 63:
            raise FrameError(f"{BLOCK_TOPIC}: truncated or overlong varint at byte {pos}")
        b = data[pos]
        pos += 1
        value |= (b & 0x7F) << shift
        shift += 7
        if b < 0x80:
            return value, pos


def decode_header(data: bytes) -> BlockHeader:
    """Read the scalar fields of a ``ramdaq.Block`` message in microseconds (skips samples)."""
    fields = {1: 0, 2: 0, 3: 0, 4: 0.0, 5: 0, 6: 0}
    pos, end = 0, len(data)
    while pos < end:
        key, pos = _read_varint(data, pos)
        number, wire = key >> 3, key & 7
        if wire == 0:
            fields[number], pos = _read_varint(data, pos)
        elif wire == 1:
            if number == 4:
                fields[4] = struct.unpack_from("<d", data, pos)[0]
            pos += 8
        elif wire == 2:
            length, pos = _read_varint(data, pos)
            pos += length
        elif wire == 5:
            pos += 4
        else:
            raise FrameError(f"{BLOCK_TOPIC}: wire type {wire} at byte {pos} in a ramdaq.Block")
    if pos != end:
        raise FrameError(f"{BLOCK_TOPIC}: ramdaq.Block message ends inside a field")
    t0 = fields[3] & 0xFFFF_FFFF_FFFF_FFFF
    t0 = t0 - (1 << 64) if t0 >= 1 << 63 else t0
    return BlockHeader(fields[1], fields[2], t0, fields[4], fields[5], fields[6])


# -- JSON topics -------------------------------------------------------------------------------
_EVENT_SCHEMA = {
    "title": "ramdaq.Event",
    "type": "object",
    "properties": {
        "kind": {"type": "string", "description": "gap, overflow, device_error, note, ..."},
        "t_ns": {"type": "integer", "description": "device time, ns"},
        "detail": {"type": "object"},
    },
    "required": ["kind", "t_ns", "detail"],
}
_SIM_IMPACT_SCHEMA = {
    "title": "ramdaq.SimImpact",
    "type": "object",
    "properties": {
        "sample": {"type": "integer", "description": "sample index of the impact"},
        "t_s": {"type": "number", "description": "s since the stream's first sample"},
        "peak_force_N": {"type": "number"},
        "duration_s": {"type": "number"},
        "location_m": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3},
    },
    "required": ["sample", "t_s", "peak_force_N", "duration_s", "location_m"],
}
_IMPACT_SCHEMA = {"title": "ramdaq.Impact", "type": "object"}  # reserved: fixed with the trigger
JSON_SCHEMAS: dict[str, dict] = {
    EVENTS_TOPIC: _EVENT_SCHEMA,
    SIM_IMPACTS_TOPIC: _SIM_IMPACT_SCHEMA,
    IMPACTS_TOPIC: _IMPACT_SCHEMA,
}
"""JSON Schema of each known JSON topic; any other topic gets ``{"type": "object"}``."""


def json_schema_for(topic: str) -> tuple[str, bytes]:
    """``(schema name, schema data)`` to register for a JSON topic."""
    schema = JSON_SCHEMAS.get(topic, {"title": topic, "type": "object"})
    return schema["title"], json.dumps(schema, separators=(",", ":")).encode()


def encode_json(obj: Any) -> bytes:
    """Strict JSON (no NaN or Infinity, which Foxglove's ``JSON.parse`` rejects), UTF-8."""
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()


def decode_json(data: bytes) -> Any:
    return json.loads(data)


def make_event(kind: str, t_ns: int, detail: Mapping[str, Any]) -> dict:
    """An ``/ramdaq/events`` message: ``{"kind", "t_ns", "detail"}``."""
    return {"kind": str(kind), "t_ns": int(t_ns), "detail": dict(detail)}


# -- stream metadata ---------------------------------------------------------------------------
def ramdaq_version() -> str:
    """The installed ramdaq version (``ramdaq.__version__``)."""
    from ramdaq import __version__

    return __version__


def stream_info_to_metadata(info: StreamInfo, *, created_utc: str | None = None) -> dict[str, str]:
    """The ``ramdaq.stream`` metadata record of a stream (``rig_toml`` goes in an attachment)."""
    if created_utc is None:
        created_utc = datetime.now(UTC).isoformat(timespec="seconds").replace("+00:00", "Z")
    return {
        "format": FORMAT_VERSION,
        "device": info.device,
        "fs_hz": repr(float(info.fs_hz)),
        "channels": json.dumps(list(info.channels)),
        "units": json.dumps(list(info.units)),
        "gages": json.dumps([int(g) for g in info.gages]),
        "extra": json.dumps(info.extra, allow_nan=False),
        "ramdaq_version": ramdaq_version(),
        "created_utc": created_utc,
    }


def stream_info_from_metadata(meta: Mapping[str, str], rig_toml: str = "") -> StreamInfo:
    """Rebuild the :class:`StreamInfo` that :func:`stream_info_to_metadata` recorded.

    Raises
    ------
    NotARamdaqRecording
        A key is missing or does not parse, ``fs_hz`` is not positive and finite, or ``extra``
        is not a JSON object.
    """
    try:
        info = StreamInfo(
            device=meta["device"],
            fs_hz=float(meta["fs_hz"]),
            channels=tuple(json.loads(meta["channels"])),
            units=tuple(json.loads(meta["units"])),
            gages=tuple(int(g) for g in json.loads(meta["gages"])),
            rig_toml=rig_toml,
            extra=json.loads(meta.get("extra", "{}")),
        )
    except (KeyError, ValueError, TypeError) as err:
        raise NotARamdaqRecording(
            f"{STREAM_METADATA} metadata is incomplete or malformed ({type(err).__name__}: {err})"
        ) from err
    if not (math.isfinite(info.fs_hz) and info.fs_hz > 0):
        raise NotARamdaqRecording(f"{STREAM_METADATA} metadata: fs_hz {meta['fs_hz']!r} is not a "
                                  f"positive sample rate")
    if not isinstance(info.extra, dict):
        raise NotARamdaqRecording(f"{STREAM_METADATA} metadata: extra is a "
                                  f"{type(info.extra).__name__}, not a JSON object")
    return info
