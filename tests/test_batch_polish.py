"""What a new user met with ``ramdaq batch`` on a folder of their records, without a cluster
(fast): files left out are counted and said, failure reasons are words, an empty file is
'empty (0 bytes)', a log gets unwrapped lines, and counts agree with their nouns."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from ramdaq.daq.commands.batch import BatchOutcome, finish, plan_batch, progress_bar, summary_lines
from ramdaq.daq.commands.batch_tasks import TaskResult, TaskSpec, analyze_task

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "recordings" / "albacore-air.mcap"


@pytest.fixture
def archive(tmp_path) -> Path:
    """The new user's archive: a recording, an empty file, a truncated one and a stray CSV."""
    d = tmp_path / "archive"
    d.mkdir()
    shutil.copy(SAMPLE, d / "1998_B.mcap")
    (d / "empty.mcap").write_bytes(b"")
    (d / "corrupt_trunc.mcap").write_bytes(SAMPLE.read_bytes()[:300_000])
    (d / "stray.csv").write_text("time_s,g01\n0,1\n")
    return d


def test_left_out_files_are_counted_and_said(archive, tmp_path):
    """'batch analyze of 3 recordings' for 4 files said nothing of the CSV left out."""
    plan = plan_batch("analyze", [str(archive)], tmp_path / "out")
    assert len(plan.specs) == 3 and [p.name for p in plan.left_out] == ["stray.csv"]
    outcome = BatchOutcome(plan, {s.path: TaskResult.not_run(s, "interrupted", "not run")
                                  for s in plan.todo}, cluster="tcp://127.0.0.1:1", workers=1)
    finish(outcome)
    lines = summary_lines(outcome)
    assert "left out 1 file that is not a .mcap recording (stray.csv); CSV, UFF and TDMS " \
           "records are made recordings first with ramdaq import" in lines[1]
    assert "of 3 recordings" in lines[0]


def test_failure_reasons_are_words_and_an_empty_file_says_so(archive, tmp_path):
    """``TruncatedRecording: ...`` and, for an empty file, 'does not start with the MCAP
    magic'; now the message alone, and 'empty (0 bytes)'."""
    def reason(name: str) -> str:
        p = archive / name
        r = analyze_task(TaskSpec(str(p), "", str(tmp_path / name), False))
        assert r.status == "failed"
        return r.status_reason

    assert reason("empty.mcap") == "empty (0 bytes), not a recording"
    why = reason("corrupt_trunc.mcap")  # the row names the recording: the reason does not repeat it
    assert why.startswith("recording has no footer") and "TruncatedRecording" not in why
    # a damaged chunk's reason is long (its byte, the CRCs, how far it was read) and its advice
    # comes last: a new user's row was cut at 300 characters, mid-word in the advice
    data = bytearray(SAMPLE.read_bytes())
    data[len(data) // 3] ^= 0x10
    (archive / "flipped.mcap").write_bytes(bytes(data))
    why = reason("flipped.mcap")
    assert why.startswith("damaged chunk at byte") and len(why) > 300, why
    assert why.endswith("copies every intact chunk to a new file"), why


def test_a_log_gets_unwrapped_lines(archive, tmp_path, capsys):
    """Not a terminal: stderr was hard-wrapped at 80 columns mid-path by the bar's console."""
    plan = plan_batch("analyze", [str(archive)], tmp_path / "out")
    long = "/" + "x" * 120 + "/empty.mcap"
    r = TaskResult(long, "", "failed", f"{long}: empty (0 bytes), not a recording", "", False)
    with progress_bar(plan, True) as advance:
        advance(r)
    err = capsys.readouterr().err
    assert err == f"failed: {long}: {long}: empty (0 bytes), not a recording\n"


def test_one_worker_is_singular(archive, tmp_path):
    plan = plan_batch("analyze", [str(archive / "1998_B.mcap")], tmp_path / "out")
    s = plan.todo[0]
    outcome = BatchOutcome(plan, {s.path: TaskResult.not_run(s, "lost", "x")},
                           cluster="tcp://127.0.0.1:1", workers=1)
    finish(outcome)
    lines = summary_lines(outcome)
    assert "batch analyze of 1 recording:" in lines[0] and "  on 1 worker at" in lines[1]


def test_the_table_says_rig_medium_units_channels_and_numbers_modes_as_report_json(tmp_path):
    """tester9: analyze.parquet had an empty ``rig`` column and no medium, no flag for a decay
    cut short, no units, no channel names, and gages with no decay had mode = -1 while the CLI
    printed 1-based modes. Now: ``rig_name`` and ``medium``; ``decay_cut`` as report.json's
    flags.too_short; a unit for every column; hits and modes from 0 as report.json (and the
    CLI's ``mode 0``), ``mode`` null and ``fitted`` False where no mode was fitted."""
    import json

    import pyarrow.parquet as pq

    from ramdaq.daq.commands.batch import results_table, write_table

    p = ROOT / "recordings" / "albacore-water.mcap"
    r = analyze_task(TaskSpec(str(p), "x", str(tmp_path / "rep"), False))
    assert r.status == "ok", r.status_reason
    write_table(results_table([r], "analyze"), tmp_path / "analyze.parquet", partial=False,
                pending=0)
    t = pq.read_table(tmp_path / "analyze.parquet")
    rows = t.to_pylist()
    assert {x["rig_name"] for x in rows} == {"albacore-like"} and {x["medium"] for x in rows} \
        == {"water"}
    units = json.loads(t.schema.metadata[b"ramdaq.units"])
    assert set(units) == set(t.schema.names)
    assert units["f_hz"] == "Hz" and units["amplitude"] == "m/s^2" and units["mode"] == \
        "index from 0"
    assert all(f.metadata[b"unit"] for f in t.schema)
    doc = json.loads((tmp_path / "rep" / "report.json").read_text())
    for x in rows:
        assert (x["mode"] is None) == (not x["fitted"])
        assert x["decay_cut"] == doc["impacts"][x["hit"]]["flags"]["too_short"]
        if x["fitted"]:
            a = doc["impacts"][x["hit"]]["analysis"]
            assert a["modes"][x["mode"]]["f_hz"] == pytest.approx(x["mode_f_hz"], rel=1e-12)
            assert x["predominant"] == (x["mode"] == a["predominant_mode"])
            assert x["channel"] == f"g{x['gage']:02d}" and x["source_channel"] == ""
            # the samples the analysis used, as report.json says (the crop to an FFT-fast length)
            assert (x["record_samples"], x["analysed_samples"]) == (a["record_samples"],
                                                                    a["analysed_samples"])
            assert units["record_samples"] == "samples"
    assert any(x["fitted"] for x in rows)


def test_a_small_file_read_shows_kilobytes_not_0_of_0_mb(capsys):
    """tester9: reading a 0.3 MB recording showed "0/0 MB". Below 1 MB the bar counts kB, above
    it MB to one decimal."""
    from ramdaq.daq.commands.progress import bytes_bar

    for size, want in ((300_000, "293/293 kB"), (3_500_000, "3.3/3.3 MB")):
        with bytes_bar("reading x", size, show=True) as update:
            update(size, size)
        err = capsys.readouterr().err
        assert want in err and "0/0" not in err
