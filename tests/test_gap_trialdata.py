"""The gap diagnosis reads only the windows it compares: a trial cut and low-passed window by
window is the trial low-passed whole and cut, to rounding; a recording read block by block keeps
the gages' counts and gives the same samples as reading it whole, gaps included."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import scipy.signal

from ramdaq.analysis.gap.trialdata import ScaledCounts, _lowpass, analysis_band, prepare
from ramdaq.analysis.model.rig import load_rig
from ramdaq.daq.gap_trial import _joined, load_trial
from ramdaq.daq.recording import read_recording

ROOT = Path(__file__).resolve().parents[1]


def _whole_trial_reference(x, fs, onsets, rig, pre_s=1.0, post_s=4.0):
    """The segments as filtering the whole trial gives them (the pre-windowed algorithm)."""
    corner, _ = analysis_band(rig, fs)
    q = max(1, int(fs // (2.5 * corner)))
    gaps = ~np.isfinite(x)
    xf = scipy.signal.sosfiltfilt(_lowpass(corner, fs), np.where(gaps, 0.0, x), axis=1)
    reach = int(math.ceil(3 * fs / corner))
    c = np.cumsum(np.pad(gaps, ((0, 0), (reach + 1, reach))), axis=1)
    xf[(c[:, 2 * reach + 1:] - c[:, : -2 * reach - 1]) > 0] = np.nan
    n_s = int(round(pre_s * fs / q)) + int(round(post_s * fs / q))
    starts = np.maximum(np.rint((np.asarray(onsets) - pre_s) * fs).astype(int), 0) // q * q
    idx = starts[:, None] + q * np.arange(n_s)[None, :]
    out = xf[:, np.clip(idx, 0, x.shape[1] - 1)].transpose(1, 0, 2)
    out[np.broadcast_to((idx >= x.shape[1])[:, None, :], out.shape)] = np.nan
    return out


def test_windowed_segments_are_the_whole_trial_filtered():
    """Filtering each segment with the low-pass's reach either side gives what filtering the
    whole trial gives, to 1e-12 of the signal (float64 rounding through a 16th-order filter is
    ~1e-15; the reach is where the edge transient has fallen to 1e-14), and a gap's NaN in the
    same places."""
    rig = load_rig(ROOT / "recordings" / "rigs" / "albacore.toml").with_medium("water")
    rng = np.random.default_rng(0)
    fs, n = 2048.0, int(2048 * 29.5)
    t = np.arange(n) / fs
    x = np.stack([np.sin(2 * math.pi * (13 + g) * t) * np.exp(-0.1 * (t % 7))
                  + 0.01 * rng.standard_normal(n) for g in range(4)])
    x[:, int(9.3 * fs): int(9.3 * fs) + 40] = np.nan        # a gap in the second decay
    onsets = np.array([2.0, 9.0, 16.0, 26.0])
    # the last decay runs to the end: 3.5 s
    scale = np.full(4, 1e-6)
    counts = np.round(np.nan_to_num(x) / scale[:, None]).astype(np.int32)
    x = counts * scale[:, None]
    x[:, int(9.3 * fs): int(9.3 * fs) + 40] = np.nan
    sc = ScaledCounts(counts, scale, np.array([[int(9.3 * fs), int(9.3 * fs) + 40]]))
    ref = _whole_trial_reference(x, fs, onsets, rig, post_s=3.5)
    np.testing.assert_array_equal(prepare(x, fs, onsets, rig).x, ref)   # an array: filtered whole
    td = prepare(sc, fs, onsets, rig, post_max_s=4.0)
    assert td.x.shape == ref.shape
    np.testing.assert_array_equal(np.isnan(td.x), np.isnan(ref))
    assert np.isnan(td.x[1]).any() and not np.isnan(td.x[[0, 2, 3]]).any()
    ok = np.isfinite(ref)
    assert np.max(np.abs(td.x[ok] - ref[ok])) < 1e-12 * np.max(np.abs(ref[ok]))


def test_scaled_counts_read_as_the_array_they_stand_for():
    """Counts and a scale with a missing stretch read back, window by window, as the float
    array with NaN there, and the same segments come out of either."""
    rig = load_rig(ROOT / "recordings" / "rigs" / "albacore.toml").with_medium("water")
    rng = np.random.default_rng(1)
    counts = rng.integers(-3000, 3000, size=(3, 2048 * 14)).astype(np.int16)
    scale = np.array([1e-3, 2e-3, 5e-4])
    sc = ScaledCounts(counts, scale, np.array([[5000, 5100]]))
    x = counts * scale[:, None]
    x[:, 5000:5100] = np.nan
    np.testing.assert_array_equal(sc.full(), x)
    np.testing.assert_array_equal(sc.window(4990, 5010), x[:, 4990:5010])
    a = prepare(sc, 2048.0, np.array([2.0, 8.0]), rig)
    b = prepare(x, 2048.0, np.array([2.0, 8.0]), rig)
    np.testing.assert_array_equal(np.isnan(a.x), np.isnan(b.x))
    ok = np.isfinite(b.x)     # window by window against whole: rounding (see the test above)
    assert np.max(np.abs(a.x[ok] - b.x[ok])) < 1e-12 * np.max(np.abs(b.x[ok]))
    np.testing.assert_array_equal(a.peak_full, b.peak_full)


def test_blocks_joined_with_a_gap():
    """Blocks with a hole between them join at their stream index, the hole missing."""
    parts = [(100, np.full((2, 10), 3, np.int16)), (110, np.full((2, 5), -2, np.int16)),
             (120, np.full((2, 10), 7, np.int16))]
    sc = _joined(parts, True, np.array([0.5, 2.0]), -2, 7)
    assert isinstance(sc, ScaledCounts) and sc.counts.dtype == np.int16
    np.testing.assert_array_equal(sc.missing, [[15, 20]])
    x = sc.full()
    assert np.isnan(x[:, 15:20]).all() and np.isfinite(x[:, :15]).all() and np.isfinite(x[:, 20:]).all()
    np.testing.assert_array_equal(x[:, 25], [3.5, 14.0])


def test_a_recording_read_block_by_block_is_the_recording_read_whole():
    """``load_trial`` keeps the gages' counts; the samples and impacts are those of
    ``read_recording``."""
    path = ROOT / "recordings" / "albacore-water.mcap"
    lt = load_trial(path)
    rec = read_recording(path)
    assert isinstance(lt.data, ScaledCounts)
    np.testing.assert_array_equal(lt.x, rec.gage_values([g.number for g in lt.rig.gages_by_channel()]))
    np.testing.assert_array_equal(lt.onsets_s, [ev.onset_s - rec.first_sample / rec.info.fs_hz
                                                for ev in rec.impacts])


def test_a_blow_in_the_first_second_is_found_by_gap_as_by_analyze(tmp_path):
    """``ramdaq analyze`` (``read_recording``) arms the trigger offline on the whole record, so
    a blow inside the live arming time is found; ``ramdaq gap`` reads block by block and must
    find the same impacts (it armed live before, and lost that blow)."""
    from ramdaq.daq.commands.cli import main

    out = tmp_path / "early.mcap"
    assert main(["record", "--rig", str(ROOT / "recordings" / "rigs" / "albacore.toml"),
                 "--medium", "water", "--duration", "8", "--impacts", "0.3,4.5", "--fast",
                 "--quiet", "--out", str(out)]) == 0
    rec = read_recording(out)
    lt = load_trial(out)
    onsets = [ev.onset_s - rec.first_sample / rec.info.fs_hz for ev in rec.impacts]
    assert len(onsets) == 2 and abs(onsets[0] - 0.3) < 0.01  # 0.01 s: the trigger's onset pick
    np.testing.assert_array_equal(lt.onsets_s, onsets)


def test_a_calibrated_rig_does_not_narrow_the_band_compared():
    """``min_corner_hz`` holds the band the modes were identified on: a rig whose own band is
    narrower than it (a benchmark trial's calibrated rig put its corner at 8.8 Hz, under the
    13 Hz the trial rang with, and the pre window came out one sample long) is compared up to
    it all the same; without it, or below the rig's own, the rig's band stands."""
    rig = load_rig(ROOT / "recordings" / "rigs" / "albacore.toml").with_medium("water")
    x = np.random.default_rng(2).standard_normal((16, 2048 * 14)) * 1e-3
    onsets = np.array([2.0, 8.0])
    own = prepare(x, 2048.0, onsets, rig)
    assert prepare(x, 2048.0, onsets, rig, min_corner_hz=50.0).lowpass_hz == own.lowpass_hz
    held = prepare(x, 2048.0, onsets, rig, min_corner_hz=300.0)
    assert own.lowpass_hz < 300.0 <= held.lowpass_hz and held.rig_lowpass_hz >= 300.0
    assert held.fs_hz > own.fs_hz    # decimated less: the band is sampled


def _events(impacts) -> list[tuple]:
    """Every field of each impact but its copy of the samples (``record``), for comparison."""
    from dataclasses import fields

    return [tuple((f.name, repr(getattr(ev, f.name))) for f in fields(ev) if f.name != "record")
            for ev in impacts]


@pytest.mark.parametrize("cut", ["whole", "a gap in a ringing", "a scale change"])
def test_the_gap_read_finds_the_same_impacts_on_joined_blocks(cut, tmp_path):
    """``ramdaq gap`` reads up to READ_JOIN_S of contiguous recorded blocks of one scale as one
    block, as ``read_recording`` does: every blow's every field is the one the trigger finds on
    the blocks as recorded -- a stream does not see where its blocks were cut -- with a gap just
    before the second blow (blocks 7.5-7.8 s dropped) and the scale doubled halfway (the counts
    halved), where no run is joined across."""
    from ramdaq.daq.recorder import Recorder
    from ramdaq.daq.recording import _join, _trigger_offline
    from ramdaq.daq.trigger import NO_BLOW, Trigger
    from ramdaq.drivers.block import Block
    from ramdaq.drivers.mcap_replay import McapReplayDevice

    with McapReplayDevice(ROOT / "recordings" / "albacore-water.mcap") as dev:
        info, blocks = dev.info, list(dev)
    fs = info.fs_hz
    if cut == "a gap in a ringing":
        blocks = [b for b in blocks if not 7.5 * fs <= b.first_sample < 7.8 * fs]
    elif cut == "a scale change":
        half = len(blocks) // 2
        blocks = blocks[:half] + [Block(b.seq, b.first_sample, b.t0_ns, b.fs_hz, b.counts // 2,
                                        2 * b.scale) for b in blocks[half:]]
    path = tmp_path / "trial.mcap"
    with Recorder(path, info, queue_blocks=len(blocks)) as rec:   # every block queued: none dropped
        for b in blocks:
            assert rec.put(b)
    # the trigger on the blocks as recorded; load_trial keeps the blows (the step at the scale
    # change fires the trigger: no blow)
    whole = [ev for ev in _trigger_offline(Trigger(info), blocks, _join(blocks, info.n_channels)[0])
             if not (ev.not_analysable or "").startswith(NO_BLOW)]
    assert len(whole) >= 3 if cut != "a gap in a ringing" else len(whole) >= 2
    assert _events(load_trial(path).events) == _events(whole)


def test_decays_cut_short_by_the_records_end_are_said(tmp_path):
    """A new user's recovered recording kept 1.2 s after its last blow: every impact's decay was
    then compared over 1.2 s instead of the 4 s asked (the default), and nothing said so. The cut is now said,
    with what cut it (the record's end, or the next blow's pre-trigger window); a record with
    room after every blow says nothing. Onsets are picked to ~0.01 s: lengths read to 0.1 s."""
    from ramdaq.daq.commands.cli import main
    from ramdaq.daq.gap_trial import trial_data

    rig = str(ROOT / "recordings" / "rigs" / "albacore.toml")
    cases = (("end", "1.5,6.0", "over 2.0", "the record ends 2.0", "after impact 2"),
             ("close", "1.5,4.0", "over 1.5", "impact 2's pre-trigger window begins 1.5",
              "after impact 1"),
             ("room", "1.5", None, None, None))
    for name, impacts, *said in cases:
        out = tmp_path / f"{name}.mcap"
        assert main(["record", "--rig", rig, "--medium", "water", "--duration", "8",
                     "--impacts", impacts, "--fast", "--quiet", "--out", str(out)]) == 0
        cut = trial_data(load_trial(out)).decay_cut
        if said[0] is None:
            assert cut is None, cut
            continue
        assert cut.startswith(f"decays compared {said[0]}") and "s (at most 4 s): " in cut, cut
        assert said[1] in cut and f"{said[2]}, and every impact is compared over the same length" in cut
