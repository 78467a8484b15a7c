"""``ramdaq batch`` and the gap benchmark on real dask clusters: a LocalCluster of worker
processes started in this test process; a ``dask scheduler`` and two ``dask worker`` processes
started here on 127.0.0.1, one of them killed mid-batch; the command itself interrupted as a
terminal's Ctrl-C would. Recordings: the three samples, copies of them, and a truncated one.

Numbers are compared exactly: the same code on the same bytes with one BLAS thread gives the
same floating-point operations whichever process runs it, so any difference is a fault."""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import fields
from pathlib import Path

import pyarrow.parquet as pq
import pytest

import ramdaq.rigs
from ramdaq.daq.commands.batch import (
    BatchOutcome,
    expand_paths,
    finish,
    open_client,
    plan_batch,
    report_folders,
    run_batch,
    summary_lines,
)
from ramdaq.daq.commands.batch_tasks import (
    TaskResult,
    TaskSpec,
    analyze_task,
    file_sha256,
    gap_task,
    method_digest,
)
from ramdaq.daq.mode_table import ModeEstimate

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = [ROOT / "recordings" / n
           for n in ("albacore-air.mcap", "albacore-water.mcap", "sampson-water.mcap")]
ENV = os.environ | {"OPENBLAS_NUM_THREADS": "1"}
NUMBERS = [f.name for f in fields(ModeEstimate)]
"""A row's own columns; the result columns beside them (path, folder, worker, time) differ
from run to run by design."""
KEY = ["recording", "hit", "gage", "mode"]


def _same(a: object, b: object) -> bool:
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))


def _numbers(rows: list[dict]) -> list[tuple]:
    return [tuple(r[k] for k in NUMBERS) for r in sorted(rows, key=lambda r: (r["hit"], r["gage"] or 0,
                                                                             r["mode"] or 0))]


def _equal(rows_a: list[dict], rows_b: list[dict]) -> bool:
    a, b = _numbers(rows_a), _numbers(rows_b)
    return len(a) == len(b) and all(_same(x, y) for ra, rb in zip(a, b, strict=True)
                                    for x, y in zip(ra, rb, strict=True))


def _rows_of(table_rows: list[dict], name: str) -> list[dict]:
    return [r for r in table_rows if Path(r["recording"]).name == name]


@pytest.fixture(scope="module")
def fleet(tmp_path_factory) -> Path:
    """a/: the three samples; b/: a copy of one and a recording cut off after 300 kB; c/:
    copies of all three under other names."""
    d = tmp_path_factory.mktemp("fleet")
    for sub in "abc":
        (d / sub).mkdir()
    for p in SAMPLES:
        shutil.copy(p, d / "a" / p.name)
        shutil.copy(p, d / "c" / f"copy-{p.name}")
    shutil.copy(SAMPLES[2], d / "b" / "sampson-copy.mcap")
    (d / "b" / "truncated.mcap").write_bytes(SAMPLES[0].read_bytes()[:300_000])
    return d


@pytest.fixture(scope="module")
def serial_sampson(tmp_path_factory) -> list[dict]:
    """The sampson sample's rows computed in this process, without dask."""
    p = SAMPLES[2]
    r = analyze_task(TaskSpec(str(p), file_sha256(p), str(tmp_path_factory.mktemp("serial")), False))
    assert r.status == "ok", r.status_reason
    return [{k: getattr(row, k) for k in NUMBERS} for row in r.rows]


@pytest.fixture(scope="module")
def client():
    """A LocalCluster of two single-threaded worker processes, in this test process."""
    with open_client(workers=2) as c:
        yield c


def test_paths_from_files_folders_and_globs(fleet):
    a = sorted((fleet / "a").glob("*.mcap"))
    assert expand_paths([str(fleet / "a")]) == a
    assert expand_paths([str(a[0]), str(fleet / "a")]) == [a[0], a[1], a[2]]   # each once, in order
    assert expand_paths([str(fleet / "*" / "sampson*.mcap")]) == [fleet / "a" / "sampson-water.mcap",
                                                                  fleet / "b" / "sampson-copy.mcap"]
    assert len(expand_paths([str(fleet / "**")])) == 8
    with pytest.raises(FileNotFoundError, match="nothing-here"):
        expand_paths([str(fleet / "nothing-here")])
    with pytest.raises(FileNotFoundError, match=r"\*\.txt: matches no \.mcap"):
        expand_paths([str(fleet / "*.txt")])
    folders = report_folders(expand_paths([str(fleet / "a"), str(fleet / "b")]), fleet / "out", "analyze")
    assert folders[0] == fleet / "out" / "a" / "albacore-air_analysis"
    assert folders[-1] == fleet / "out" / "b" / "truncated_analysis"


def test_local_cluster_batch(client, fleet, serial_sampson, tmp_path):
    out = tmp_path / "out"
    outcome = run_batch("analyze", [str(fleet / "a"), str(fleet / "b")], out, client=client, plots=False)
    t = pq.read_table(out / "analyze.parquet")
    assert t.schema.metadata[b"ramdaq.partial"] == b"false"
    rows = t.to_pylist()
    keys = [tuple(r[k] for k in KEY) for r in rows]
    assert len(set(keys)) == len(keys)
    status = {Path(r["recording"]).name: (r["status"], r["status_reason"]) for r in rows}
    assert {k: v[0] for k, v in status.items()} == {
        "albacore-air.mcap": "ok", "albacore-water.mcap": "ok", "sampson-water.mcap": "ok",
        "sampson-copy.mcap": "ok", "truncated.mcap": "failed"}
    why = status["truncated.mcap"][1]
    assert "no footer" in why and "truncated.mcap" in why and "TruncatedRecording" not in why
    # through dask, the same numbers as in this process, and a copy the same as its original
    assert _equal(_rows_of(rows, "sampson-water.mcap"), serial_sampson)
    assert _equal(_rows_of(rows, "sampson-copy.mcap"), serial_sampson)
    # the table agrees with the report folder each task wrote
    for r in (r for r in rows if r["status"] == "ok" and r["accepted"] and r["gage"] == 1
              and r["fitted"]):
        doc = json.loads((Path(r["folder"]) / "report.json").read_text())
        assert doc["impacts"][r["hit"]]["analysis"]["modes"][r["mode"]]["delta"] == r["mode_delta"]
    assert outcome.table.num_rows == len(rows)

    # a re-run: everything current, nothing submitted, the same table
    again = run_batch("analyze", [str(fleet / "a"), str(fleet / "b")], out, client=client, plots=False)
    assert again.results == {} and again.skipped == 5
    carried = pq.read_table(out / "analyze.parquet").to_pylist()
    assert len(carried) == len(rows)
    assert all(_same(r[k], c[k]) for r, c in zip(rows, carried, strict=True) for k in r)
    # --force: all of them again; plots wanted where there were none: all of them again
    plan = plan_batch("analyze", [str(fleet / "a"), str(fleet / "b")], out, plots=False, force=True)
    assert len(plan.todo) == 5
    plan = plan_batch("analyze", [str(fleet / "a"), str(fleet / "b")], out, plots=True)
    assert len(plan.todo) == 5


def test_a_changed_recording_runs_again(fleet, tmp_path):
    """Re-run after one recording's bytes changed: only that one is to do."""
    src = tmp_path / "src"
    src.mkdir()
    for p in SAMPLES[:2]:
        shutil.copy(p, src / p.name)
    out = tmp_path / "out"
    plan = plan_batch("analyze", [str(src)], out, plots=False)
    # results as a finished run leaves them (report folders present), without running the analysis
    fake = {}
    for s in plan.specs:
        Path(s.folder).mkdir(parents=True)
        (Path(s.folder) / "report.json").write_text("{}")
        fake[s.path] = TaskResult(s.path, s.sha256, "ok", folder=s.folder, plots=False,
                                  method=method_digest())
    finish(BatchOutcome(plan, fake))
    assert plan_batch("analyze", [str(src)], out, plots=False).todo == ()
    with open(src / SAMPLES[1].name, "ab") as f:
        f.write(b"\0")
    todo = plan_batch("analyze", [str(src)], out, plots=False).todo
    assert [Path(s.path).name for s in todo] == [SAMPLES[1].name]
    # a report folder that was deleted: not current either
    shutil.rmtree(plan.specs[0].folder)
    assert len(plan_batch("analyze", [str(src)], out, plots=False).todo) == 2


def test_gap_batch(client, fleet, tmp_path):
    """Held against a rig given for the whole batch (the shipped SAMPSON file the sample was made
    from): the rig and its digest in the row, the numbers those of a serial run with that rig."""
    out = tmp_path / "out"
    rig = Path(ramdaq.rigs.__file__).parent / "sampson.toml"
    paths = [str(fleet / "a" / "sampson-water.mcap"), str(fleet / "b" / "truncated.mcap")]
    outcome = run_batch("gap", paths, out, client=client, plots=False, rig=rig)
    rows = {Path(r["recording"]).name: r for r in pq.read_table(out / "gap.parquet").to_pylist()}
    assert rows["truncated.mcap"]["status"] == "failed"
    r = rows["sampson-water.mcap"]
    assert r["rig"] == str(rig.resolve()) and len(r["rig_sha256"]) == 64
    serial = gap_task(TaskSpec(r["recording"], r["sha256"], str(tmp_path / "serial"), False,
                               r["rig"], r["rig_sha256"]))
    assert r["status"] == "ok" and r["verdict"] == serial.rows[0].verdict
    assert {k: r[k] for k in serial.rows[0].__dataclass_fields__} == {
        k: (list(v) if isinstance(v, tuple) else v) for k, v in serial.rows[0].__dict__.items()}
    doc = json.loads((Path(r["folder"]) / "gap.json").read_text())
    # the table's verdict is the effect search's map's (gap.json's map_verdict); gap.json's
    # verdict is the answer ramdaq gap prints, which the table has as answer / answered_by
    assert doc["map_verdict"] == r["verdict"] and doc["effect"] == r["effect"]
    assert r["answer"] == doc["answer"]["named"] and r["answered_by"] == doc["answer"]["by"]
    # the summary counts the answers ramdaq gap prints, not the map's verdicts
    assert f"  answers: {r['answer']} 1" in summary_lines(outcome), summary_lines(outcome)


def test_a_rig_for_the_batch_is_read_first_and_part_of_what_is_current(fleet, tmp_path):
    """``batch gap --rig``: a bad rig is one error before any task; a finished run is current
    for the same rig and not for another (nor for the recordings' own)."""
    from ramdaq.analysis.model.rig import RigError

    src = [str(fleet / "a" / "sampson-water.mcap")]
    out = tmp_path / "out"
    with pytest.raises(RigError, match="no-such-rig"):
        plan_batch("gap", src, out, plots=False, rig=tmp_path / "no-such-rig.toml")
    with pytest.raises(ValueError, match="--rig goes with 'batch gap'"):
        plan_batch("analyze", src, out, plots=False, rig="sampson")
    plan = plan_batch("gap", src, out, plots=False, rig="sampson")
    (s,) = plan.specs
    assert s.rig == "sampson" and len(s.rig_sha256) == 64
    Path(s.folder).mkdir(parents=True)
    (Path(s.folder) / "gap.json").write_text("{}")
    done = TaskResult(s.path, s.sha256, "ok", folder=s.folder, plots=False, rig=s.rig,
                      rig_sha256=s.rig_sha256, method=method_digest())
    finish(BatchOutcome(plan, {s.path: done}))
    assert plan_batch("gap", src, out, plots=False, rig="sampson").todo == ()
    assert len(plan_batch("gap", src, out, plots=False, rig="albacore").todo) == 1
    assert len(plan_batch("gap", src, out, plots=False).todo) == 1


def test_gap_benchmark_through_dask_is_the_serial_run(client, tmp_path):
    from ramdaq.daq.commands.gap_bench import _run, run_one, scenarios

    scs = scenarios(1, "check", effects=("tiller",))
    serial = [run_one(sc, str(tmp_path)) for sc in scs]
    dask = _run(scs, tmp_path, "check", 1, lambda m: None, client)
    timing = {"seconds", "seconds_generate", "cpu_seconds"}  # clocks, not results
    assert [{k: v for k, v in r.items() if k not in timing} for r in dask] == \
        [{k: v for k, v in r.items() if k not in timing} for r in serial]
    assert "error" not in dask[0] and dask[0]["candidates"]


# -- real processes ------------------------------------------------------------------------------

def _sigint_as_at_a_terminal() -> None:
    """A terminal's foreground command has SIGINT at its default; a shell's background job (how
    a CI script may run pytest) inherits it ignored, and Python then never raises
    KeyboardInterrupt."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start(cmd: list[str], log: Path) -> subprocess.Popen:
    """A process in its own process group (killed as a group), output to ``log``, with SIGINT
    as at a terminal."""
    with open(log, "wb") as f:
        return subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, start_new_session=True, env=ENV,
                                cwd=log.parent, preexec_fn=_sigint_as_at_a_terminal)


def _stop(p: subprocess.Popen) -> None:
    if p.poll() is None:
        os.killpg(p.pid, signal.SIGTERM)
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(10)
    try:  # anything the group left behind
        os.killpg(p.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def _wait_for(what: str, cond, timeout: float, procs=()) -> object:
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if v := cond():
            return v
        dead = [p.args for p in procs if p.poll() is not None]
        assert not dead, f"exited while waiting for {what}: {dead}"
        time.sleep(0.2)
    raise AssertionError(f"no {what} within {timeout} s")


@pytest.mark.timeout(420)
def test_a_worker_killed_mid_batch_loses_and_duplicates_nothing(fleet, serial_sampson, tmp_path):
    from distributed import Client

    sched_file = tmp_path / "scheduler.json"
    dask = [sys.executable, "-m", "dask"]
    procs = [_start([*dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                     "--scheduler-file", str(sched_file)], tmp_path / "scheduler.log")]
    cli = None
    try:
        _wait_for("scheduler file", lambda: sched_file.is_file() and sched_file.stat().st_size, 60, procs)
        for name in ("victim", "survivor"):
            procs.append(_start([*dask, "worker", "--scheduler-file", str(sched_file), "--name", name,
                                 "--nthreads", "1", "--nworkers", "1", "--host", "127.0.0.1",
                                 "--no-dashboard"], tmp_path / f"{name}.log"))
        addr = json.loads(sched_file.read_text())["address"]
        assert addr.startswith("tcp://127.0.0.1:")
        with Client(addr, timeout=30) as mon:
            mon.wait_for_workers(2, timeout=120)
            by_name = {w["name"]: a for a, w in mon.scheduler_info()["workers"].items()}
            pids = mon.run(os.getpid)
            host = socket.gethostname()
            victim, survivor = by_name["victim"], by_name["survivor"]
            cli = _start([sys.executable, "-m", "ramdaq", "batch", "analyze", str(fleet / "a"),
                          str(fleet / "c"), "--scheduler", addr, "--out", str(tmp_path / "out"), "--no-plots",
                          "--quiet"], tmp_path / "cli.log")
            # kill the victim two seconds into a task (each takes several seconds): its whole
            # process group, nanny and worker, as when a machine dies
            _wait_for("a task on the victim", lambda: mon.processing([victim]).get(victim), 180, [cli])
            time.sleep(2.0)
            # what the victim itself is executing now (the scheduler's `processing` can be stale
            # under load: a result already sent but not yet handled there, so the task was
            # done by the victim after all -- CI, 2026-11-28, the suite on both cores)
            def executing(dask_worker) -> list[str]:  # local: pickled by value to the worker
                return [str(ts.key) for ts in dask_worker.state.executing]

            running = mon.run(executing, workers=[victim])[victim]
            assert running, "the victim finished its task within 2 s: tasks too short for this test"
            os.killpg(procs[1].pid, signal.SIGKILL)
            rc = cli.wait(timeout=300)
        log = (tmp_path / "cli.log").read_text()
        assert rc == 0, log
        assert "6 to run, 0 skipped" in log and "6 ok, 0 failed, 0 lost" in log, log
    finally:
        for p in ([cli] if cli else []) + procs[::-1]:
            _stop(p)
    t = pq.read_table(tmp_path / "out" / "analyze.parquet")
    assert t.schema.metadata[b"ramdaq.partial"] == b"false"
    rows = t.to_pylist()
    keys = [tuple(r[k] for k in KEY) for r in rows]
    assert len(set(keys)) == len(keys), "a row twice"
    names = sorted({Path(r["recording"]).name for r in rows})
    assert names == sorted([p.name for p in SAMPLES] + [f"copy-{p.name}" for p in SAMPLES])
    assert {r["status"] for r in rows} == {"ok"}
    # each copy has exactly its original's rows, and sampson's are the serial numbers
    for p in SAMPLES:
        assert _equal(_rows_of(rows, p.name), _rows_of(rows, f"copy-{p.name}"))
    assert _equal(_rows_of(rows, "sampson-water.mcap"), serial_sampson)
    # what the victim was running when it died was run again, by the survivor
    for key in running:
        stem = str(key).split("-", 4)[4]
        done_by = {r["worker"] for r in rows if Path(r["recording"]).stem == stem}
        assert done_by == {f"{host}:{pids[survivor]}"}, (key, done_by, pids)


@pytest.mark.timeout(300)
def test_ctrl_c_writes_the_partial_table(fleet, tmp_path):
    out = tmp_path / "out"
    cli = _start([sys.executable, "-m", "ramdaq", "batch", "analyze", str(fleet / "a"), "--workers", "1",
                  "--out", str(out), "--no-plots"], tmp_path / "cli.log")
    try:
        _wait_for("a first report", lambda: list(out.rglob("report.json")), 240, [cli])
        time.sleep(1.0)   # its result handed back (ms after the report is written)
        os.killpg(cli.pid, signal.SIGINT)   # as a terminal's Ctrl-C: to the whole process group
        rc = cli.wait(timeout=60)
        log = (tmp_path / "cli.log").read_text()
        assert rc == 130, log
        # the local cluster's workers went with it (bounded: a loaded machine takes a while)
        _wait_for("the command's process group to empty", lambda: not _group_alive(cli.pid), 20)
    finally:
        _stop(cli)
    assert "PARTIAL" in log, log
    t = pq.read_table(out / "analyze.parquet")
    assert t.schema.metadata[b"ramdaq.partial"] == b"true"
    status = {Path(r["recording"]).name: r["status"] for r in t.to_pylist()}
    assert sorted(status) == sorted(p.name for p in SAMPLES)
    assert set(status.values()) == {"ok", "interrupted"}, status
    assert int(t.schema.metadata[b"ramdaq.pending"]) == sum(v == "interrupted" for v in status.values())
    # the next run does only what was not done
    todo = plan_batch("analyze", [str(fleet / "a")], out, plots=False).todo
    left = sorted(k for k, v in status.items() if v == "interrupted")
    assert sorted(Path(s.path).name for s in todo) == left


def test_an_unreachable_scheduler_is_one_line(fleet, tmp_path):
    with socket.socket() as s:   # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    r = subprocess.run([sys.executable, "-m", "ramdaq", "batch", "analyze", str(fleet / "a"), "--scheduler",
                        f"tcp://127.0.0.1:{port}", "--out", str(tmp_path / "out")], capture_output=True,
                       text=True, timeout=120, env=ENV)
    assert r.returncode == 1
    err = r.stderr.strip().splitlines()
    assert len(err) == 1, r.stderr
    assert err[0].startswith(f"ramdaq batch: --scheduler tcp://127.0.0.1:{port}: "), r.stderr
    assert not (tmp_path / "out" / "analyze.parquet").exists()
