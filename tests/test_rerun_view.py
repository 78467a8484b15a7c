"""RerunView against real Rerun recordings: a simulated trial is logged headless to an .rrd, which is
read back with Rerun's own reader (``rerun.chunk.RrdReader``); and the web viewer is served on
localhost and stopped."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import urllib.request
from pathlib import Path

import numpy as np
import psutil
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader

from ramdaq.daq import rerun_view
from ramdaq.daq.errors import ViewError
from ramdaq.daq.rerun_view import RerunView, check_ports
from ramdaq.drivers.block import Block
from ramdaq.drivers.sim import SimDevice

RIG = Path(__file__).resolve().parent.parent / "recordings" / "rigs" / "albacore.toml"
DURATION_S = 3.0
LIVE_HZ = 500.0


def _rows(path: Path) -> tuple[dict[str, int], dict[str, list]]:
    """Temporal row count and chunks of every entity in the .rrd's recording."""
    rows: dict[str, int] = {}
    chunks: dict[str, list] = {}
    for ch in RrdReader(path).store().stream():
        if not ch.is_static:
            rows[ch.entity_path] = rows.get(ch.entity_path, 0) + ch.num_rows
            chunks.setdefault(ch.entity_path, []).append(ch)
    return rows, chunks


def _values(chunks: list, column: str) -> list:
    out: list = []
    for ch in chunks:
        rb = ch.to_record_batch()
        out.extend(rb.column(rb.schema.get_field_index(column)).to_pylist())
    return out


def _series(chunks: list) -> tuple[np.ndarray, np.ndarray]:
    """Times (int ns) and scalar rows (n, width) of a Scalars entity, sorted by time."""
    t, v = [], []
    for ch in chunks:
        rb = ch.to_record_batch()
        t.append(rb.column(rb.schema.get_field_index("time")).cast(pa.int64()).to_numpy())
        v.extend(rb.column(rb.schema.get_field_index("Scalars:scalars")).to_pylist())
    times = np.concatenate(t)
    order = np.argsort(times, kind="stable")
    return times[order], np.array(v)[order]


@pytest.fixture(scope="module")
def trial(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Block], float]:
    """A 3 s albacore stream with one impact at 1 s, logged with everything RerunView offers."""
    path = tmp_path_factory.mktemp("rerun") / "trial.rrd"
    with SimDevice(RIG, duration_s=DURATION_S, impacts=[1.0], seed=3) as dev:
        info = dev.open()
        fs = info.fs_hz
        blocks: list[Block] = []
        with RerunView(info, rrd_path=path, recording_name="test trial", live_rate_hz=LIVE_HZ) as view:
            for block in dev:
                view.log_block(block)
                blocks.append(block)
            view.log_impact(0, 1.0, {"double_hit": False, "clipped": False}, None)
            view.log_impact(0, 1.0, {"double_hit": False, "clipped": False}, True, "clean hit")
            values = np.concatenate([b.values() for b in blocks], axis=1)
            i0, n = int(0.95 * fs), int(0.5 * fs)
            view.log_full_rate(i0, values[:, i0:i0 + n], fs, k=0)
            t = np.arange(int(1.0 * fs), int(1.4 * fs)) / fs
            for t_s in (1.1, 1.2, 1.3):
                view.log_gage_result(0, "g04", t_s, 11.5, 0.06, 2.0, final=False)
            view.log_gage_result(0, 4, 1.4, 11.6, 0.055, 2.0, final=True, decay_t_s=t,
                                 decay=np.exp(-(t - 1) / 0.3) * np.sin(73 * t),
                                 envelope=np.exp(-(t - 1) / 0.3))
            view.log_mode_shape(0, 11.6, {f"g{i:02d}": complex(np.cos(i), 0.2 * np.sin(i))
                                          for i in range(1, 17)})
    return path, blocks, fs


def test_rrd_has_the_entity_layout(trial: tuple[Path, list[Block], float]) -> None:
    path, _, _ = trial
    reader = RrdReader(path)
    assert len(reader.recordings()) == 1
    assert reader.blueprints(), "the default blueprint travels in the file"
    rows, _ = _rows(path)
    static = {ch.entity_path for ch in reader.store().stream() if ch.is_static}
    assert "/gages" in rows and "/impacts/0/traces" in rows
    for entity in ("/impacts/markers", "/impacts/log", "/impacts/0", "/results/g04/f_hz",
                   "/results/g04/delta", "/results/g04/amplitude", "/results/log",
                   "/impacts/0/decay/g04", "/impacts/0/decay/g04/envelope", "/impacts/0/mode",
                   "/layout/mode"):
        assert entity in rows, entity
    assert {"/layout/gages", "/layout/axes", "/layout/rudder", "/layout/stock"} <= static
    assert rows["/results/g04/delta"] == 1  # the final; the three first looks are rows of
    _, chunks = _rows(path)  # results/looks: a column per gage (g04's the 4th), NaN where none
    t_ns, looks = _series(chunks["/results/looks/delta"])
    assert looks.shape == (3, 16)
    np.testing.assert_array_equal(t_ns, [1.1e9, 1.2e9, 1.3e9])
    assert np.all(looks[:, 3] == 0.06) and np.isnan(np.delete(looks, 3, axis=1)).all()
    assert _values(chunks["/impacts/0"], "status") == [["pending"], ["accepted"]]
    (vectors,) = _values(chunks["/layout/mode"], "Arrows3D:vectors")
    lengths = np.linalg.norm(np.array(vectors), axis=1)
    assert lengths[2] == pytest.approx(0.3 * 5.7, rel=1e-6)  # g03 is largest; layout spans 5.7 m
    assert lengths.max() == lengths[2]
    assert rows["/impacts/0/traces"] == int(0.5 * trial[2])
    t_ns, traces = _series(chunks["/impacts/0/traces"])
    assert traces.shape == (int(0.5 * trial[2]), 16)  # a series per channel, in channel order
    values = np.concatenate([b.values() for b in trial[1]], axis=1)
    i0 = int(0.95 * trial[2])
    np.testing.assert_array_equal(traces[:, 3], values[3, i0:i0 + traces.shape[0]])


def test_live_traces_are_decimated_not_full_rate(trial: tuple[Path, list[Block], float]) -> None:
    path, blocks, fs = trial
    rows, chunks = _rows(path)
    n_rows = rows["/gages"]
    assert n_rows == pytest.approx(LIVE_HZ * DURATION_S, rel=0.05)
    assert n_rows < 0.3 * fs * DURATION_S
    # each row is [min, max] of its bucket, at the time of the bucket's first sample
    bucket = round(fs / LIVE_HZ)
    x = np.concatenate([b.values()[3] for b in blocks])  # g04
    t_ns, got = _series(chunks["/gages"])
    assert got.shape[1] == 32  # [min, max] of each of the 16 gages, channel-major
    got = got[:, 6:8]  # g04
    want = x[: len(x) // bucket * bucket].reshape(-1, bucket)
    np.testing.assert_allclose(got[:, 0], want.min(axis=1))
    np.testing.assert_allclose(got[:, 1], want.max(axis=1))
    np.testing.assert_array_equal(t_ns, np.round(np.arange(len(got)) * bucket * 1e9 / fs))


@pytest.mark.parametrize("si_per_count", [1e-3, -1e-3])
def test_block_edges_and_gaps_do_not_matter(tmp_path: Path, si_per_count: float) -> None:
    """Uneven blocks give the same rows as one big block; a gap flushes the partial bucket; a
    negative scale still gives [min, max]."""
    with SimDevice(RIG, duration_s=1.0, seed=1) as dev:
        info = dev.open()
        big = np.concatenate([b.counts for b in dev], axis=1)
    scale = np.full(info.n_channels, si_per_count)

    def block(seq: int, first: int, n: int) -> Block:
        return Block(seq, first, 0, info.fs_hz, np.ascontiguousarray(big[:, first:first + n]), scale)

    cuts = [(0, 101), (101, 7), (108, 497), (1003, 42)]  # gap from 605 to 1003
    path = tmp_path / "edges.rrd"
    with RerunView(info, rrd_path=path, live_rate_hz=info.fs_hz / 8) as view:
        for i, (first, n) in enumerate(cuts):
            view.log_block(block(i, first, n))
    _, chunks = _rows(path)
    t_ns, got = _series(chunks["/gages"])
    got = got[:, 0:2]  # g01
    t = np.round(t_ns * info.fs_hz / 1e9).astype(int)
    # buckets on multiples of 8; [600, 605) sent alone at the gap, [1003, 1008) after it,
    # [1040, 1045) at close
    spans = [(s, s + 8) for s in range(0, 600, 8)] + [(600, 605), (1003, 1008)]
    spans += [(s, s + 8) for s in range(1008, 1040, 8)] + [(1040, 1045)]
    assert t.tolist() == [a for a, _ in spans]
    x = big[0] * si_per_count
    np.testing.assert_allclose(got[:, 0], [x[a:b].min() for a, b in spans])
    np.testing.assert_allclose(got[:, 1], [x[a:b].max() for a, b in spans])


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_web_viewer_serves_on_localhost_only(tmp_path: Path) -> None:
    with SimDevice(RIG, duration_s=0.2, seed=0) as dev:
        info = dev.open()
        web, grpc = _free_port(), _free_port()
        view = RerunView(info, rrd_path=tmp_path / "w.rrd", serve_web=True, web_port=web,
                         grpc_port=grpc, live_rate_hz=200.0)
        try:
            for block in dev:
                view.log_block(block)
            assert view.web_url is not None and view.web_url.startswith(f"http://127.0.0.1:{web}/")
            with urllib.request.urlopen(f"http://127.0.0.1:{web}/", timeout=5) as r:
                assert r.status == 200
                assert b"Rerun" in r.read()
            proc = psutil.Process(view._web_proc.pid)
            listening = [c.laddr for c in proc.net_connections("inet") if c.status == "LISTEN"]
            assert listening and all(a.ip == "127.0.0.1" for a in listening), listening
            ours = [c.laddr for c in psutil.Process().net_connections("inet") if c.status == "LISTEN"]
            assert any(a.port == grpc for a in ours)
            assert all(a.ip == "127.0.0.1" for a in ours if a.port == grpc)
        finally:
            view.close()
        assert view._web_proc is None and not proc.is_running()
        # both servers are gone: the web server's process has ended (above) and this process
        # listens on neither port (asked of our own sockets, not by connecting: on a shared
        # machine another program may be handed the freed port at once)
        ours = {c.laddr.port for c in psutil.Process().net_connections("inet")
                if c.status == "LISTEN"}
        assert not ours & {web, grpc}, ours


def test_needs_a_sink_without_display(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with SimDevice(RIG, duration_s=0.1) as dev:
        info = dev.open()
    if not sys.platform.startswith("linux"):
        pytest.skip("a display is assumed off Linux")
    with pytest.raises(ValueError, match="rrd_path"):
        RerunView(info)


def test_a_taken_port_is_named_before_anything_starts(tmp_path: Path) -> None:
    """Both ports are bound for real first: a port another program holds is refused by name,
    and no .rrd, no gRPC server and no web viewer are started."""
    with SimDevice(RIG, duration_s=0.1) as dev:
        info = dev.open()
    with socket.create_server(("127.0.0.1", 0)) as held:
        busy = held.getsockname()[1]
        for ports in ({"web_port": busy, "grpc_port": _free_port()},
                      {"web_port": _free_port(), "grpc_port": busy}):
            with pytest.raises(ViewError, match=f"port {busy} on 127.0.0.1 is taken by another"):
                RerunView(info, rrd_path=tmp_path / "x.rrd", serve_web=True, **ports)
        with pytest.raises(ViewError, match="cannot share port"):
            check_ports(busy, busy)
    assert not (tmp_path / "x.rrd").exists()
    check_ports(_free_port(), _free_port())  # free ones pass


_PURGE_PROBE = ("import os, sys; import ramdaq.daq.rerun_view as v; "
                "print(v.PURGE_APPLIED, os.environ.get(v.PURGE_ENV))")


@pytest.mark.parametrize(("given", "expected"), [(None, "0"), ("250", "250")])
def test_rerun_allocator_purges_at_once_unless_told_otherwise(given: str | None,
                                                              expected: str) -> None:
    """Importing the view sets Rerun's mimalloc purge delay to 0 before rerun's library loads (a
    fresh interpreter, as the CLI starts), so pages freed by Rerun's threads go back to the OS; a
    value the user gave is kept. (The RSS it saves is a benchmark's: benchmarks/rerun_rss.py
    --pace 1.)"""
    env = {k: v for k, v in os.environ.items() if k != "MIMALLOC_PURGE_DELAY"}
    if given is not None:
        env["MIMALLOC_PURGE_DELAY"] = given
    out = subprocess.run([sys.executable, "-c", _PURGE_PROBE], env=env, capture_output=True,
                         text=True, check=True).stdout.split()
    assert out == ["True", expected]


def test_viewers_started_here_get_the_users_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    """The purge delay is for this process's Rerun: a viewer spawned by _run does not inherit the
    value set here (it would when the user set it)."""
    seen: dict[str, dict] = {}

    def fake_popen(args: list[str], **kw: object) -> None:
        seen["env"] = kw["env"]

    monkeypatch.setattr(rerun_view.subprocess, "Popen", fake_popen)
    monkeypatch.setattr(rerun_view, "_SET_PURGE", True)
    rerun_view._run(["--version"])
    assert rerun_view.PURGE_ENV not in seen["env"]
    assert seen["env"].get("PATH") == os.environ.get("PATH")
