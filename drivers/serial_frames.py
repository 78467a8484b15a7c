"""The serial wire format: framed ADC samples with a sync word, a checked header and a CRC.

One frame carries ``samples`` consecutive sample instants of all ``channels`` channels: a rig's
gages and then its force channels (``[[forces]]``, counts of the rig's force scale,
:func:`ramdaq.drivers.rig_channels.rig_channels` gives names, units and scales). Every
integer is little-endian::

    offset  size  field
    ------  ----  ---------------------------------------------------------------------------
     0      2     sync word 0xEB 0x90
     2      1     format version, 1
     3      1     flags: bit 0 = end of stream (the device stopped; no more frames); others 0
     4      1     sample width in bytes: 2 (int16), 3 (int24) or 4 (int32)
     5      1     channel count, 1..255
     6      2     samples per channel, uint16, 1..4096 (0 only in an end-of-stream frame)
     8      4     frame sequence number, uint32, +1 per frame the device made (wraps at 2**32)
    12      8     index of the frame's first sample since the stream started, uint64
    20      2     header CRC-16/CCITT-FALSE of bytes 0..19
    22      N     payload: samples x channels two's-complement integers of ``width`` bytes,
                  interleaved (sample 0 of channels 0..C-1, then sample 1, ...);
                  N = samples x channels x width, at most 65 536
    22+N    2     payload CRC-16/CCITT-FALSE of bytes 22..22+N-1

Why so:

* **Sync 0xEB90** is the classic 16-bit PCM telemetry frame-sync pattern: its shifted copies
  overlap it poorly, and neither byte is 0x00 or 0xFF, which fill the high bytes of the small
  signed samples that make up most of a quiet record.
* **A header CRC** lets the parser judge a sync word at once: a false sync in the data, or a
  header whose length is absurd, is refused on the spot instead of waited for, so garbage never
  stalls the stream for the length of a phantom frame.
* **Both a uint32 sequence and a uint64 first-sample index**: the sample index places every
  frame exactly (a gap's length in samples is read, not inferred, and stays right if the frame
  size changes), and never wraps; the sequence number counts frames the device made, so lost
  frames are counted as frames too. Twelve bytes per frame is under 1 % of a 16 x 32 x 3 frame.
* **Interleaved payload** is the order a simultaneous-sampling ADC produces: a device can send
  each conversion as it completes without buffering per channel, and a torn frame loses whole
  instants of all channels rather than one channel's tail.
* **CRC-16/CCITT-FALSE** (poly 0x1021, init 0xFFFF, no reflection, no final XOR; check value
  0x29B1 for ``b"123456789"``) catches every burst of up to 16 bits. The fast path is
  :func:`binascii.crc_hqx` seeded with 0xFFFF (C, table-driven); :func:`crc16_reference` is the
  plain table-driven twin the tests hold it equal to.

:class:`FrameParser` is streaming: ``feed(bytes) -> frames`` keeps the bytes of an incomplete
frame between calls, hunts for the sync word after garbage or a torn frame, and accounts for
every byte it was given (``bytes_in == bytes_framed + bytes_discarded + pending``).
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass

import numpy as np

__all__ = ["SYNC", "VERSION", "HEADER_BYTES", "CRC_BYTES", "MAX_PAYLOAD_BYTES", "MAX_SAMPLES",
           "FLAG_END", "Frame", "FrameParser", "crc16", "crc16_reference", "encode_frame",
           "width_for_bits"]

SYNC = b"\xeb\x90"
VERSION = 1
FLAG_END = 0x01
_HEADER = struct.Struct("<2sBBBBHIQ")  # sync, version, flags, width, channels, samples, seq, first
HEADER_BYTES = _HEADER.size + 2  # 22: the fields and their CRC
CRC_BYTES = 2
MAX_PAYLOAD_BYTES = 65536
MAX_SAMPLES = 4096
_CRC_INIT = 0xFFFF
_DTYPES = {2: np.dtype("<i2"), 4: np.dtype("<i4")}


def crc16(data: bytes | bytearray | memoryview, crc: int = _CRC_INIT) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (continue a running CRC by passing it as ``crc``)."""
    return binascii.crc_hqx(data, crc)


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else crc << 1
        table.append(crc & 0xFFFF)
    return tuple(table)


_TABLE = _crc_table()


def crc16_reference(data: bytes | bytearray | memoryview, crc: int = _CRC_INIT) -> int:
    """Plain table-driven CRC-16/CCITT-FALSE, the reference twin of :func:`crc16`."""
    for byte in bytes(data):
        crc = ((crc << 8) & 0xFFFF) ^ _TABLE[((crc >> 8) ^ byte) & 0xFF]
    return crc


def width_for_bits(adc_bits: int) -> int:
    """Smallest sample width in bytes (2, 3 or 4) that holds a signed ``adc_bits``-bit count."""
    if not 2 <= adc_bits <= 32:
        raise ValueError(f"adc_bits ({adc_bits}) must be within 2..32")
    return 2 if adc_bits <= 16 else 3 if adc_bits <= 24 else 4


@dataclass(frozen=True, eq=False)
class Frame:
    """One decoded frame.

    Attributes
    ----------
    seq : int
        Frame sequence number (uint32, wraps).
    first_sample : int
        Index of the frame's first sample since the stream started.
    counts : numpy.ndarray
        ADC counts, ``int32``, shape ``(n_channels, n_samples)``.
    width : int
        Sample width on the wire, bytes.
    flags : int
        Header flags (:data:`FLAG_END`).
    skipped_bytes : int
        Bytes the parser discarded between the previous frame and this one (0 when in sync).
    failed_crc : int
        CRC failures the parser met between the previous frame and this one.
    payload_crc : int
        The payload's CRC-16 as sent: with ``seq`` and ``first_sample``, what tells a repeated
        frame (the same bytes again) from another frame with the same header.
    """

    seq: int
    first_sample: int
    counts: np.ndarray
    width: int
    flags: int = 0
    skipped_bytes: int = 0
    failed_crc: int = 0
    payload_crc: int = 0

    @property
    def end(self) -> bool:
        """True for the end-of-stream frame."""
        return bool(self.flags & FLAG_END)

    @property
    def n_channels(self) -> int:
        return int(self.counts.shape[0])

    @property
    def n_samples(self) -> int:
        return int(self.counts.shape[1])


def encode_frame(seq: int, first_sample: int, counts: np.ndarray, *, width: int = 3,
                 flags: int = 0) -> bytes:
    """One frame on the wire.

    Parameters
    ----------
    seq : int
        Frame sequence number; taken modulo 2**32.
    first_sample : int
        Index of the first sample since the stream started, 0 <= first_sample < 2**64.
    counts : numpy.ndarray
        Integer counts, shape ``(n_channels, n_samples)``; every value must fit ``width`` bytes.
    width : {2, 3, 4}
        Sample width on the wire, bytes.
    flags : int
        Header flags (:data:`FLAG_END` for the end-of-stream frame).
    """
    counts = np.asarray(counts)
    if counts.ndim != 2 or not np.issubdtype(counts.dtype, np.integer):
        raise ValueError(f"encode_frame: counts must be a 2-D integer array, got {counts.dtype} "
                         f"with shape {counts.shape}")
    n_ch, n = counts.shape
    if width not in (2, 3, 4):
        raise ValueError(f"encode_frame: width ({width}) must be 2, 3 or 4 bytes")
    if not 1 <= n_ch <= 255 or not 0 <= n <= MAX_SAMPLES or (n == 0 and not flags & FLAG_END):
        raise ValueError(f"encode_frame: {n_ch} channels x {n} samples is outside 1..255 x "
                         f"1..{MAX_SAMPLES}")
    if n * n_ch * width > MAX_PAYLOAD_BYTES:
        raise ValueError(f"encode_frame: payload of {n * n_ch * width} bytes exceeds "
                         f"{MAX_PAYLOAD_BYTES}")
    if not 0 <= first_sample < 2**64 or not 0 <= flags < 256:
        raise ValueError(f"encode_frame: first_sample {first_sample} or flags {flags} out of range")
    lo, hi = -(2 ** (8 * width - 1)), 2 ** (8 * width - 1) - 1
    if counts.size and (counts.min() < lo or counts.max() > hi):
        raise ValueError(f"encode_frame: counts span {counts.min()}..{counts.max()}, "
                         f"beyond the {width}-byte range {lo}..{hi}")
    inter = counts.T.astype("<i4")  # (samples, channels), interleaved once flattened
    if width == 3:
        payload = inter.reshape(-1, 1).view(np.uint8)[:, :3].tobytes()
    else:
        payload = inter.astype(_DTYPES[width]).tobytes()
    head = _HEADER.pack(SYNC, VERSION, flags, width, n_ch, n, seq & 0xFFFF_FFFF, first_sample)
    return b"".join((head, crc16(head).to_bytes(2, "little"), payload,
                     crc16(payload).to_bytes(2, "little")))


def _decode_payload(payload: bytes, width: int, n_ch: int, n: int) -> np.ndarray:
    """Interleaved payload -> int32 counts, shape ``(n_ch, n)`` (a transposed view)."""
    if width == 3:
        b = np.frombuffer(payload, np.uint8).reshape(-1, 3)
        wide = np.zeros((b.shape[0], 4), np.uint8)
        wide[:, 1:] = b  # little-endian: the int24 lands in the top 3 bytes, >> 8 sign-extends
        values = wide.view("<i4").reshape(-1) >> 8
    else:
        values = np.frombuffer(payload, _DTYPES[width]).astype(np.int32)
    return values.astype(np.int32, copy=False).reshape(n, n_ch).T


class FrameParser:
    """Streaming decoder: bytes in, CRC-valid :class:`Frame` s out, every other byte counted.

    Attributes
    ----------
    frames : int
        Frames returned.
    crc_errors : int
        Candidates with a sync word and a plausible header whose header or payload CRC failed.
    bad_headers : int
        Sync words followed by an impossible header (version, width, sizes): refused at once.
    resyncs : int
        Times a frame was found after bytes had to be discarded to reach it.
    bytes_in, bytes_framed, bytes_discarded : int
        Bytes fed; bytes that were part of returned frames; bytes thrown away.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.frames = self.crc_errors = self.bad_headers = self.resyncs = 0
        self.bytes_in = self.bytes_framed = self.bytes_discarded = 0
        self._skipped = self._failed = 0  # since the last frame

    @property
    def pending(self) -> int:
        """Bytes held for an incomplete frame (or a trailing first sync byte)."""
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> list[Frame]:
        """Add received bytes; return the frames they completed, in stream order."""
        self.bytes_in += len(data)
        self._buf += data
        return self._scan(final=False)

    def flush(self) -> list[Frame]:
        """End of input (port lost, file ended): return the complete frames still buffered and
        discard the rest, so a torn frame never swallows the frames behind it."""
        return self._scan(final=True)

    def _discard(self, n: int) -> None:
        self.bytes_discarded += n
        self._skipped += n

    def _crc_failed(self) -> None:
        self.crc_errors += 1
        self._failed += 1
        self._discard(1)

    def _scan(self, final: bool) -> list[Frame]:
        buf, out, pos = self._buf, [], 0
        end = len(buf)
        while True:
            i = buf.find(SYNC, pos)
            if i < 0:  # keep a trailing first sync byte: the second may be in the next read
                keep = 1 if not final and end > pos and buf[end - 1] == SYNC[0] else 0
                self._discard_span(pos, end - keep)
                pos = end - keep
                break
            self._discard_span(pos, i)
            pos = i
            if end - pos < HEADER_BYTES:
                if final:
                    self._discard(end - pos)
                    pos = end
                break
            _, version, flags, width, n_ch, n, seq, first = _HEADER.unpack_from(buf, pos)
            size = n * n_ch * width
            if (version != VERSION or width not in (2, 3, 4) or n_ch == 0 or n > MAX_SAMPLES
                    or size > MAX_PAYLOAD_BYTES or (n == 0 and not flags & FLAG_END)):
                self.bad_headers += 1
                self._discard(1)
                pos += 1
                continue
            if crc16(buf[pos:pos + _HEADER.size]) != int.from_bytes(
                    buf[pos + _HEADER.size:pos + HEADER_BYTES], "little"):
                self._crc_failed()
                pos += 1
                continue
            total = HEADER_BYTES + size + CRC_BYTES
            if end - pos < total:
                if not final:
                    break
                self._discard(1)  # torn frame at the end of input: look for frames inside it
                pos += 1
                continue
            payload = bytes(buf[pos + HEADER_BYTES:pos + HEADER_BYTES + size])
            payload_crc = crc16(payload)
            if payload_crc != int.from_bytes(buf[pos + total - 2:pos + total], "little"):
                self._crc_failed()
                pos += 1
                continue
            out.append(Frame(seq, first, _decode_payload(payload, width, n_ch, n), width, flags,
                             self._skipped, self._failed, payload_crc))
            self.frames += 1
            self.bytes_framed += total
            self.resyncs += self._skipped > 0
            self._skipped = self._failed = 0
            pos += total
        del buf[:pos]
        return out

    def _discard_span(self, start: int, stop: int) -> None:
        if stop > start:
            self._discard(stop - start)
