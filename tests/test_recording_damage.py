"""Damaged recordings, on real files: flipped bits and overwritten bytes anywhere in a file the
recorder wrote. Replay never hands out a sample of a damaged chunk and never ends quietly on a
damaged file; ``info`` says where the damage is; ``recover`` steps over it and keeps every
intact record after it.

Samples are compared bit for bit (``Block.same_as``): the format stores integer counts and float64
scales, so there is nothing to tolerate.
"""

import dataclasses
import json

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from ramdaq.daq.commands.info import describe_recording, format_info
from ramdaq.daq.errors import CorruptRecording, NotARamdaqRecording, RecordingError
from ramdaq.daq.recorder import Recorder
from ramdaq.daq.recover import recover
from ramdaq.drivers import mcap_format as fmt
from ramdaq.drivers.mcap_replay import McapReplayDevice
from tests.recording_helpers import stream, stream_info

pytestmark = pytest.mark.timeout(120)

SEED = 31
N_SAMPLES = 512  # per block: 20 ms at 25.6 kHz
CHUNK_S = 0.05  # 0.05 s of samples a chunk: 3 blocks, so a 60-block file has 20 chunks of blocks


def _chunks(path, blocks=True):
    """The chunk indexes of ``path`` in file order: those holding blocks (``blocks``), or those
    of the live view's topics, which the recorder writes in chunks of their own."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    ids = {i for i, ch in summary.channels.items() if ch.topic == fmt.BLOCK_TOPIC}
    return sorted((c for c in summary.chunk_indexes if blocks == bool(ids & set(c.message_index_offsets))),
                  key=lambda c: c.chunk_start_offset)


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A finished recording of 60 blocks in 20 chunks (and 20 of the live view's topics, each
    after the blocks' chunk of its time), its blocks, and the block chunks' indexes."""
    path = tmp_path_factory.mktemp("damage") / "trial.mcap"
    blocks = stream(60, SEED, full_range=False, n_samples=N_SAMPLES)
    with Recorder(path, stream_info(), chunk_seconds=CHUNK_S) as rec:
        for b in blocks:
            assert rec.put(b)
    chunks = _chunks(path)
    assert len(chunks) == 20 and len(_chunks(path, blocks=False)) == 20
    return path, blocks, chunks


def _damaged(recording, tmp_path, offsets, name="damaged.mcap", keep=None):
    """A copy with the bits ``offsets`` (byte, mask) flipped, cut to ``keep`` bytes if given."""
    path, _, _ = recording
    data = bytearray(path.read_bytes())
    for at, mask in offsets:
        data[at] ^= mask
    out = tmp_path / name
    out.write_bytes(bytes(data[:keep]))
    return out


def _replay_until_error(path, **kw):
    """The blocks replay hands out, and the error that ended it (``None`` if none)."""
    got = []
    try:
        with McapReplayDevice(path, **kw) as dev:
            for b in dev:
                got.append(b)
    except RecordingError as err:
        return got, err
    return got, None


def _chunk_data(c):
    """Offset of the middle byte of a chunk's compressed records."""
    return c.chunk_start_offset + c.chunk_length - c.compressed_size // 2


def _chunk_blocks(chunks, k):
    """Block seqs held by chunk ``k`` (3 blocks a chunk, in order)."""
    per = 60 // len(chunks)
    return list(range(k * per, (k + 1) * per))


def test_every_single_bit_flip_is_caught(recording, tmp_path):
    """A bit flipped anywhere (sampled: 150 random bytes, every bit position) makes replay
    refuse the file or stop with a one-line error naming it; every block handed out before
    that is bit-identical to the recorded one. Nothing in the file escapes a check: chunk
    CRCs cover the samples, the data-section CRC the chunk headers, indexes and metadata, the
    summary CRC the summary and footer."""
    path, blocks, _ = recording
    size = path.stat().st_size
    rng = np.random.default_rng(5)
    for at in rng.choice(size, 150, replace=False):
        bad = _damaged(recording, tmp_path, [(int(at), 1 << int(rng.integers(8)))])
        got, err = _replay_until_error(bad)
        assert err is not None, f"flip at byte {at} of {size} was not noticed"
        assert "\n" not in str(err) and "damaged.mcap" in str(err)
        assert all(b.same_as(blocks[i]) for i, b in enumerate(got)), f"byte {at}"


def test_a_flip_in_a_chunk_names_the_file_the_byte_and_the_last_good_block(recording, tmp_path):
    path, blocks, chunks = recording
    c = chunks[7]
    bad = _damaged(recording, tmp_path, [(_chunk_data(c), 0x10)])
    got, err = _replay_until_error(bad)
    assert isinstance(err, CorruptRecording)
    first_lost = _chunk_blocks(chunks, 7)[0]
    assert [b.seq for b in got] == list(range(first_lost))
    assert f"damaged.mcap: damaged chunk at byte {c.chunk_start_offset} (" in str(err)
    assert f"read up to seq {first_lost - 1}" in str(err) and "ramdaq recover" in str(err)


def test_a_flipped_sample_rate_in_the_metadata_is_caught(recording, tmp_path):
    """fs_hz is stored as text in the metadata, which no chunk CRC covers: '25600.0' with
    '0' -> '1' would move every frequency by 39 ppm. The data-section CRC catches it."""
    path, blocks, _ = recording
    data = path.read_bytes()
    at = data.index(b"25600.0") + 6
    bad = _damaged(recording, tmp_path, [(at, 0x01)])
    assert bad.read_bytes()[at - 6:at + 1] == b"25600.1"
    got, err = _replay_until_error(bad)
    assert isinstance(err, CorruptRecording) and "data section fails its CRC" in str(err)
    assert len(got) == len(blocks)  # found at the end of the data section
    d = describe_recording(bad)
    assert d.data_crc_ok is False and [x.what for x in d.damaged] == ["data section"]


def test_info_locates_damage_and_does_not_call_it_a_missing_footer(recording, tmp_path):
    _, _, chunks = recording
    c = chunks[7]
    bad = _damaged(recording, tmp_path, [(_chunk_data(c) + k, 0xFF) for k in range(16)])
    d = describe_recording(bad)
    lost = _chunk_blocks(chunks, 7)
    assert d.footer and d.complete and d.summary_ok
    assert [(x.start, x.what, x.after_seq) for x in d.damaged] == [
        (c.chunk_start_offset, "chunk", lost[0] - 1)]
    view = _chunks(bad, blocks=False)[7]  # the live view's chunk of chunk 7's time, right after it
    assert c.chunk_start_offset < view.chunk_start_offset < chunks[8].chunk_start_offset
    assert d.damaged[0].end == view.chunk_start_offset  # the next chunk read on
    assert d.blocks == 60 - len(lost) and d.gaps == [
        (lost[0] - 1, len(lost), len(lost) * N_SAMPLES)]
    text = format_info(d)
    assert "NO FOOTER" not in text and "DAMAGED: 1 damaged stretch(es)" in text
    assert "footer intact" in text.splitlines()[0]
    assert f"DAMAGED    chunk at byte {c.chunk_start_offset}" in text and "DAMAGED chunk" in text
    json.dumps(dataclasses.asdict(d))


@pytest.mark.parametrize("where", ["records", "record length"])
def test_recover_steps_over_16_bad_bytes_and_keeps_everything_after(recording, tmp_path, where):
    """16 bytes overwritten in chunk 5 of 20: in its compressed records (CRC fails), or over its
    record length (where the next record starts is lost: the next intact chunk is searched
    for). Every block of the other 19 chunks comes back."""
    path, blocks, chunks = recording
    c = chunks[5]
    start = {"records": _chunk_data(c), "record length": c.chunk_start_offset + 1}[where]
    bad = _damaged(recording, tmp_path, [(start + k, 0xA5) for k in range(16)])
    dst = tmp_path / "fixed.mcap"
    report = recover(bad, dst)
    lost = _chunk_blocks(chunks, 5)
    got, err = _replay_until_error(dst)
    assert err is None
    assert [b.seq for b in got] == [k for k in range(60) if k not in lost]
    assert all(b.same_as(blocks[b.seq]) for b in got)
    assert not report.truncated and len(report.skipped) == 1 and not report.data_crc_failed
    s = report.skipped[0]
    assert (s.damage.start, s.after_seq, s.next_seq, s.missing_samples) == (
        c.chunk_start_offset, lost[0] - 1, lost[-1] + 1, len(lost) * N_SAMPLES)
    d = describe_recording(dst)
    assert not d.damaged and d.recovery["damaged"][0]["after_seq"] == lost[0] - 1
    assert "damaged chunk left out by recover" in format_info(d)


def test_a_flip_in_a_chunk_replay_steps_over_is_caught_by_the_data_section_crc(recording, tmp_path):
    """A replay does not decompress the live view's chunks (the summary's chunk index says they
    hold no block): every block comes back, bit-identical, and then the data section's CRC,
    which covers those chunks' bytes, stops it with one line saying what may be damaged; ``info``
    reads every chunk and locates it."""
    path, blocks, _ = recording
    got, err = _replay_until_error(path)
    assert err is None and all(a.same_as(b) for a, b in zip(got, blocks, strict=True))
    with McapReplayDevice(path) as dev:
        assert len(list(dev)) == 60 and dev.chunks_read == (20, 20)
    view = _chunks(path, blocks=False)[7]
    bad = _damaged(recording, tmp_path, [(_chunk_data(view), 0x10)])
    got, err = _replay_until_error(bad)
    assert len(got) == 60 and all(a.same_as(b) for a, b in zip(got, blocks, strict=True))
    assert isinstance(err, CorruptRecording) and "data section fails its CRC" in str(err)
    assert "one of the 20 chunks of topics not read is damaged" in str(err) and "\n" not in str(err)
    d = describe_recording(bad)
    assert [(x.start, x.what) for x in d.damaged] == [(view.chunk_start_offset, "chunk")]


def test_damage_outside_the_records_keeps_every_sample_and_says_so(recording, tmp_path):
    """16 bytes over a chunk's time fields, which its CRC does not cover: its samples are
    intact (the CRC of its records matches) and recover keeps them, but says that the data
    section's CRC failed, in its report and in the copy's ``ramdaq.recovery`` record."""
    path, blocks, chunks = recording
    bad = _damaged(recording, tmp_path, [(chunks[5].chunk_start_offset + 9 + k, 0xA5)
                                         for k in range(16)])
    got, err = _replay_until_error(bad)
    assert isinstance(err, CorruptRecording) and "data section fails its CRC" in str(err)
    report = recover(bad, tmp_path / "fixed.mcap")
    got, err = _replay_until_error(tmp_path / "fixed.mcap")
    assert err is None and all(a.same_as(b) for a, b in zip(got, blocks, strict=True))
    assert report.skipped == () and report.data_crc_failed and "WARNING" in str(report)
    text = format_info(describe_recording(tmp_path / "fixed.mcap"))
    assert "WARNING    the source's data-section CRC failed" in text


def test_recover_a_killed_and_damaged_file(recording, tmp_path):
    """No footer and a damaged chunk before the torn tail: the chunks between are kept."""
    path, blocks, chunks = recording
    bad = _damaged(recording, tmp_path, [(_chunk_data(chunks[4]), 0x04)],
                   keep=_chunk_data(chunks[15]))
    report = recover(bad, tmp_path / "fixed.mcap")
    got, err = _replay_until_error(tmp_path / "fixed.mcap")
    assert err is None and report.truncated and report.tail_bytes > 0
    assert [b.seq for b in got] == [k for k in range(45) if k not in _chunk_blocks(chunks, 4)]
    assert all(b.same_as(blocks[b.seq]) for b in got)


def test_damaged_summary_refuses_replay_and_recover_rewrites_it(recording, tmp_path):
    path, blocks, _ = recording
    footer = path.stat().st_size - 8 - 29  # the footer record: opcode, length, summary_start, ...
    data = path.read_bytes()
    summary_start = int.from_bytes(data[footer + 9:footer + 17], "little")
    bad = _damaged(recording, tmp_path, [(summary_start + 40, 0x02)])
    got, err = _replay_until_error(bad)
    assert isinstance(err, CorruptRecording) and got == []
    assert "summary section or footer fails its CRC" in str(err)
    assert describe_recording(bad).summary_ok is False
    recover(bad, tmp_path / "fixed.mcap")
    got, err = _replay_until_error(tmp_path / "fixed.mcap")
    assert err is None and all(a.same_as(b) for a, b in zip(got, blocks, strict=True))


@pytest.mark.parametrize("content", [fmt.MCAP_MAGIC, fmt.MCAP_MAGIC + b"\x01" + bytes(12)])
def test_recover_refuses_a_file_with_no_recording_in_it(tmp_path, content):
    """8 bytes of magic (or a torn header) hold no recording: an error, and no output file."""
    src, dst = tmp_path / "tiny.mcap", tmp_path / "tiny.recovered.mcap"
    src.write_bytes(content)
    with pytest.raises(NotARamdaqRecording, match=r"tiny\.mcap: nothing to recover") as err:
        recover(src, dst)
    assert "\n" not in str(err.value) and not dst.exists()


def test_undecodable_block_with_a_valid_crc_is_an_error(tmp_path):
    """A block message the writer itself got wrong (its chunk's CRC matches): replay stops
    with the file's name instead of ending the stream as if it were over."""
    path = tmp_path / "garbled.mcap"
    blocks = [dataclasses.replace(b, scale=np.ones(b.n_channels))
              for b in stream(6, SEED, n_samples=N_SAMPLES)]
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        w.add_metadata(fmt.STREAM_METADATA, fmt.stream_info_to_metadata(stream_info()))
        ch = w.register_channel(fmt.BLOCK_TOPIC, "protobuf", w.register_schema(
            fmt.BLOCK_SCHEMA_NAME, "protobuf", fmt.block_schema_data()))
        for k, b in enumerate(blocks):
            data = fmt.encode_block(b) if k != 3 else b"\xff\xff\xff\xff"
            w.add_message(ch, log_time=b.t0_ns, data=data, publish_time=b.t0_ns)
        w.finish()
    got, err = _replay_until_error(path)
    assert [b.seq for b in got] == [0, 1, 2]
    assert isinstance(err, CorruptRecording) and "garbled.mcap: a block message" in str(err)
    assert "does not decode" in str(err) and "\n" not in str(err)
    # blocks joined (ramdaq replay flat out): the three before it come first, as one, then the error
    joined, err = _replay_until_error(path, join_s=1.0)
    assert len(joined) == 1 and joined[0].seq == 0 and isinstance(err, CorruptRecording)
    assert "garbled.mcap: a block message" in str(err)
    assert np.array_equal(joined[0].counts, np.hstack([b.counts for b in got]))


@pytest.mark.parametrize(("key", "value", "what"), [("fs_hz", "0.0", "fs_hz '0.0' is not a positive"),
                                                     ("extra", "[1, 2]", "extra is a list")])
def test_impossible_stream_metadata_is_refused(tmp_path, key, value, what):
    meta = {**fmt.stream_info_to_metadata(stream_info()), key: value}
    with pytest.raises(NotARamdaqRecording, match=what):
        fmt.stream_info_from_metadata(meta)


def test_chunks_are_stepped_over_only_where_crcs_check_the_index_and_their_bytes(tmp_path):
    """A file whose summary and data section carry no CRC (another writer's): nothing would
    check the chunk index that says which chunks hold no block, nor the chunks stepped over,
    so every chunk is read, and the blocks come back the same."""
    blocks = stream(6, SEED, n_samples=N_SAMPLES)
    paths = {}
    for crcs in (True, False):
        paths[crcs] = path = tmp_path / f"crcs-{crcs}.mcap"
        with open(path, "wb") as f:
            w = Writer(f, enable_crcs=crcs, enable_data_crcs=crcs)
            w.start()
            w.add_metadata(fmt.STREAM_METADATA, fmt.stream_info_to_metadata(stream_info()))
            ch = w.register_channel(fmt.BLOCK_TOPIC, "protobuf", w.register_schema(
                fmt.BLOCK_SCHEMA_NAME, "protobuf", fmt.block_schema_data()))
            view = w.register_channel("/ramdaq/gages", "json", w.register_schema("g", "jsonschema", b"{}"))
            for b in blocks:
                w.add_message(ch, log_time=b.t0_ns, data=fmt.encode_block(b), publish_time=b.t0_ns)
                w.flush()  # a chunk of the block, then one of the view
                w.add_message(view, log_time=b.t0_ns, data=b"{}", publish_time=b.t0_ns)
                w.flush()
            w.finish()
    for crcs, stepped in ((True, 6), (False, 0)):
        with McapReplayDevice(paths[crcs]) as dev:
            got = list(dev)
            assert dev.chunks_read == (12 - stepped, stepped)
        assert all(a.same_as(b) for a, b in zip(got, blocks, strict=True))
