"""The ``ramdaq`` command under faults, as a user meets them: real subprocesses (``python -m
ramdaq``), real files and folders, real permissions, real sockets on 127.0.0.1, real signals.

Every failure is one line on stderr naming what and where, with exit code 1 (bad input or a
failure at run time), 2 (usage) or 3 (internal error); nothing is opened for writing before every
refusal is checked; names stay inside ``recordings/``; SIGTERM finishes the files as Ctrl-C does.
"""

from __future__ import annotations

import ctypes
import dataclasses
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from ramdaq.daq.commands import cli
from ramdaq.daq.record import record
from ramdaq.daq.recorder import Recorder
from ramdaq.daq.rerun_view import rerun_binary
from ramdaq.drivers import mcap_format as fmt
from ramdaq.drivers.mcap_replay import McapReplayDevice
from ramdaq.drivers.sim import SimDevice
from tests.conftest import RIGS
from tests.recording_helpers import stream_info

pytestmark = pytest.mark.timeout(120)

REPO = Path(__file__).resolve().parent.parent
RIG = RIGS / "albacore.toml"
_CAP_DAC_OVERRIDE, _CAP_DAC_READ_SEARCH, _PR_CAPBSET_DROP = 1, 2, 24


def _drop_file_capabilities() -> None:
    """In the child, before exec: root loses the right to ignore file permissions (the two
    capabilities leave the bounding set, so the exec'd program never gets them)."""
    libc = ctypes.CDLL(None, use_errno=True)
    for cap in (_CAP_DAC_OVERRIDE, _CAP_DAC_READ_SEARCH):
        if libc.prctl(_PR_CAPBSET_DROP, cap, 0, 0, 0) != 0:
            raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")


def _ramdaq(*args: str, cwd: Path, permissions: bool = False, timeout: float = 90,
            ) -> subprocess.CompletedProcess:
    """``python -m ramdaq ARGS``; ``permissions``: file permissions hold even for root."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    pre = _drop_file_capabilities if permissions and os.geteuid() == 0 else None
    return subprocess.run([sys.executable, "-m", "ramdaq", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout, preexec_fn=pre)


def _one_line(r: subprocess.CompletedProcess, rc: int, *words: str) -> str:
    """Exit code ``rc`` and one line on stderr holding every one of ``words``."""
    lines = r.stderr.strip().splitlines()
    assert r.returncode == rc, (r.returncode, r.stderr)
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert all(w in lines[0] for w in words), (words, lines[0])
    return lines[0]


def _chunks(path: Path) -> list:
    """The chunk indexes of ``path`` that hold blocks, in file order (the recorder writes the live
    view's topics in chunks of their own, which a replay steps over: a flip there is caught by the
    data section's CRC, ``test_recording_damage``)."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    ids = {i for i, ch in summary.channels.items() if ch.topic == fmt.BLOCK_TOPIC}
    return sorted((c for c in summary.chunk_indexes if ids & set(c.message_index_offsets)),
                  key=lambda c: c.chunk_start_offset)


@pytest.fixture(scope="module")
def trial_file(tmp_path_factory) -> Path:
    """4 s of the albacore rig with a blow at 1.5 s, recorded as ``ramdaq record`` does."""
    path = tmp_path_factory.mktemp("cli") / "albacore.mcap"
    record(SimDevice(RIG, duration_s=4.0, impacts=[1.5], seed=2), path, readout=False)
    return path


def _flip(src: Path, dst: Path, at: int, mask: int = 0x10) -> Path:
    data = bytearray(src.read_bytes())
    data[at] ^= mask
    dst.write_bytes(bytes(data))
    return dst


# -- item 7: chunk CRCs on every read path, info and recover on damage ------------------------
def test_a_flipped_bit_stops_replay_analyze_and_gap_naming_file_and_byte(trial_file, tmp_path):
    c = _chunks(trial_file)[1]  # before the blow: no analysis runs before the damage is read
    bad = _flip(trial_file, tmp_path / "flipped.mcap",
                c.chunk_start_offset + c.chunk_length - c.compressed_size // 2)
    where = f"damaged chunk at byte {c.chunk_start_offset}"
    for args in (["replay", bad, "--quiet"], ["analyze", bad, "--no-plots"],
                 ["gap", bad, "--no-plots"]):
        _one_line(_ramdaq(*args, cwd=tmp_path), 1, "flipped.mcap", where, "ramdaq recover")
    assert not (tmp_path / "flipped_analysis").exists() and not (tmp_path / "flipped_gap").exists()

    info = _ramdaq("info", bad, cwd=tmp_path)
    assert info.returncode == 0 and "NO FOOTER" not in info.stdout
    assert "DAMAGED: 1 damaged stretch(es)" in info.stdout.splitlines()[0]
    assert f"DAMAGED    chunk at byte {c.chunk_start_offset}" in info.stdout

    r = _ramdaq("recover", bad, "-o", tmp_path / "fixed.mcap", cwd=tmp_path)
    assert r.returncode == 0 and "DAMAGED chunk at byte" in r.stdout, r.stderr
    assert _ramdaq("replay", tmp_path / "fixed.mcap", "--quiet", cwd=tmp_path).returncode == 0


def test_recover_of_an_8_byte_file_is_an_error_and_writes_nothing(tmp_path):
    (tmp_path / "eight.mcap").write_bytes(fmt.MCAP_MAGIC)
    r = _ramdaq("recover", "eight.mcap", cwd=tmp_path)
    _one_line(r, 1, "eight.mcap: nothing to recover")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["eight.mcap"]


# -- item 8: every refusal before anything is opened for writing ------------------------------
@pytest.mark.parametrize("existing", [("t.mcap", "t.rrd"), ("t.rrd",), ("hits.json",)])
def test_trial_refuses_existing_outputs_before_writing_any(tmp_path, existing):
    for name in existing:
        (tmp_path / name).write_text(f"precious {name}")
    r = _ramdaq("trial", "--rig", RIG, "--duration", "1", "--fast", "--quiet", "--out", "t.mcap",
                "--json", "hits.json", cwd=tmp_path)
    _one_line(r, 1, f"{existing[0]} exists; --overwrite replaces it")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(existing)
    assert all((tmp_path / n).read_text() == f"precious {n}" for n in existing)


# -- item 9: names stay inside recordings/ -----------------------------------------------------
def test_names_and_rig_names_cannot_leave_recordings(tmp_path):
    work = tmp_path / "a" / "b" / "work"
    work.mkdir(parents=True)
    for name in ("../../escape", str(tmp_path / "abs"), "sub/../../escape", ""):
        r = _ramdaq("record", "--rig", RIG, "--duration", "0.5", "--fast", "--quiet", "--name",
                    name, cwd=work)
        _one_line(r, 1, f"--name {name!r}: a recording name, not a path")
    evil = work / "evil.toml"
    evil.write_text(RIG.read_text().replace('name = "', 'name = "../../x/y/', 1))
    r = _ramdaq("record", "--rig", evil, "--duration", "0.5", "--fast", "--quiet", cwd=work)
    assert r.returncode == 0, r.stderr
    made = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    assert made == ["a", "a/b", "a/b/work", "a/b/work/evil.toml", "a/b/work/recordings",
                    "a/b/work/recordings/x_y_albacore-like-air.mcap"], made  # rig albacore-like


def test_safe_name():
    assert cli.safe_name("../../x/y") == "x_y"
    assert cli.safe_name("Albacore (1/4 scale)") == "Albacore_1_4_scale"
    assert cli.safe_name("/..") == "trial"


# -- item 10: one line and an exit code, never a traceback -------------------------------------
def test_unreadable_input_is_one_line(trial_file, tmp_path):
    locked = tmp_path / "locked.mcap"
    locked.write_bytes(trial_file.read_bytes())
    locked.chmod(0)
    for args in (["info", locked], ["replay", locked, "--quiet"], ["analyze", locked],
                 ["recover", locked], ["gap", locked]):
        _one_line(_ramdaq(*args, cwd=tmp_path, permissions=True), 1, "locked.mcap",
                  "Permission denied")


def test_unwritable_outputs_are_refused_before_anything_is_written(trial_file, tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    r = _ramdaq("record", "--rig", RIG, "--duration", "0.5", "--fast", "--quiet", "--out",
                ro / "x.mcap", cwd=tmp_path, permissions=True)
    _one_line(r, 1, "ro/x.mcap", "cannot write into")
    r = _ramdaq("recover", trial_file, "-o", ro / "x.mcap", cwd=tmp_path, permissions=True)
    _one_line(r, 1, "ro/x.mcap: Permission denied")
    r = _ramdaq("trial", "--rig", RIG, "--duration", "0.5", "--fast", "--quiet", "--out",
                tmp_path / "t.mcap", "--rrd", ro / "t.rrd", cwd=tmp_path, permissions=True)
    _one_line(r, 1, "ro/t.rrd", "cannot write into")
    assert not (tmp_path / "t.mcap").exists() and not list(ro.iterdir())


def test_a_folder_given_as_a_file_is_one_line(tmp_path):
    for args in (["info", tmp_path], ["recover", tmp_path], ["replay", tmp_path]):
        _one_line(_ramdaq(*args, cwd=tmp_path), 1, str(tmp_path))


def test_damaged_summary_and_zero_sample_rate_are_one_line(trial_file, tmp_path):
    size = trial_file.stat().st_size
    data = trial_file.read_bytes()
    summary_start = int.from_bytes(data[size - 37 + 9:size - 37 + 17], "little")
    bad = _flip(trial_file, tmp_path / "summary.mcap", summary_start + 20)
    for args in (["replay", bad, "--quiet"], ["analyze", bad], ["gap", bad]):
        _one_line(_ramdaq(*args, cwd=tmp_path), 1, "summary.mcap",
                  "summary section or footer fails its CRC")
    zero = tmp_path / "zero.mcap"
    with Recorder(zero, dataclasses.replace(stream_info(), fs_hz=0.0)):
        pass
    _one_line(_ramdaq("info", zero, cwd=tmp_path), 1, "zero.mcap", "fs_hz '0.0' is not a positive")


def _listener() -> socket.socket:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen()
    return s


@pytest.mark.parametrize("which", ["--grpc-port", "--web-port"])
def test_a_taken_port_is_named_and_nothing_is_written(tmp_path, which):
    with _listener() as taken, _listener() as other:
        busy, free = taken.getsockname()[1], other.getsockname()[1]
    # 'free' is closed again (so free); 'busy' is held open by a new listener
    with socket.create_server(("127.0.0.1", busy)):
        ports = {which: busy, ({"--grpc-port", "--web-port"} - {which}).pop(): free}
        r = _ramdaq("trial", "--rig", RIG, "--duration", "0.5", "--fast", "--quiet", "--web",
                    "--out", "t.mcap", *[str(x) for kv in ports.items() for x in kv], cwd=tmp_path)
    _one_line(r, 1, f"port {busy} on 127.0.0.1 is taken", "--web-port and --grpc-port")
    assert not list(tmp_path.iterdir())


def test_a_closed_stdout_ends_quietly(trial_file, tmp_path):
    """``ramdaq info FILE | head``: the reader goes away before ramdaq writes."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    p = subprocess.Popen([sys.executable, "-m", "ramdaq", "info", str(trial_file), "--json"],
                         cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()
    err = p.stderr.read().decode()
    p.stderr.close()
    assert p.wait(60) == 1 and err == "", err


def test_exit_codes_usage_and_internal_error(tmp_path, monkeypatch, capsys):
    r = _ramdaq("info", cwd=tmp_path)
    assert r.returncode == 2 and "usage:" in r.stderr

    def broken(args):  # stands for a bug: an exception no command expects
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(cli, "cmd_rig", broken)
    assert cli.main(["rig", str(RIG)]) == 3
    err = capsys.readouterr().err
    assert err.strip() == ("ramdaq rig: internal error, ZeroDivisionError: division by zero "
                           "(--debug shows where)")
    assert cli.main(["rig", str(RIG), "--debug"]) == 3
    err = capsys.readouterr().err
    assert "Traceback" in err and "in broken" in err


# -- item 12: exit codes of a failed stream, SIGTERM ----------------------------------------
def _emulator(tmp_path: Path) -> tuple[subprocess.Popen, str]:
    """The serial front-end emulator on a TCP port, at real-time pace for a minute."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "ramdaq.drivers.emulators.serial_emulator", "--tcp", "127.0.0.1:0",
         "--rig", str(RIG), "--duration", "60", "--pace", "realtime", "--seed", "1"],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    address = proc.stdout.readline().strip()
    assert address, proc.stderr.read()
    return proc, address


def _start(tmp_path: Path, *args: str) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.Popen([sys.executable, "-m", "ramdaq", *map(str, args)], cwd=tmp_path,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _wait_for_bytes(path: Path, n: int, proc: subprocess.Popen, timeout: float = 60) -> None:
    """Until ``path`` holds ``n`` bytes (its first chunks reached the disk)."""
    deadline = time.monotonic() + timeout
    while not (path.exists() and path.stat().st_size >= n):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "nothing recorded"
        time.sleep(0.1)


@pytest.mark.parametrize("command", ["record", "trial"])
def test_a_vanished_device_is_a_failure_and_the_file_is_finished(tmp_path, command):
    emu, address = _emulator(tmp_path)
    out = tmp_path / "t.mcap"
    url = f"serial://{address}?rig={RIG}&reconnect_s=0.05&give_up_s=0.5"
    extra = ["--no-rerun"] if command == "trial" else []
    proc = _start(tmp_path, command, "--device", url, "--out", out, "--quiet", *extra)
    try:
        _wait_for_bytes(out, 100_000, proc)
        emu.kill()
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        for p in (emu, proc):
            if p.poll() is None:
                p.kill()
            p.wait(10)
        emu.stdout.close()
        emu.stderr.close()
    r = subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)
    _one_line(r, 1, address, "vanished")
    with McapReplayDevice(out) as dev:  # finished: it has its footer
        assert sum(b.n_samples for b in dev) > 0


def test_sigterm_finishes_a_recording_like_ctrl_c(tmp_path):
    out = tmp_path / "t.mcap"
    proc = _start(tmp_path, "record", "--rig", RIG, "--duration", "60", "--quiet", "--out", out)
    try:
        _wait_for_bytes(out, 100_000, proc)
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr
    assert "interrupted: wrote" in stdout and "Traceback" not in stderr
    with McapReplayDevice(out) as dev:
        blocks = list(dev)
        events = list(dev.events())
    assert blocks and events[-1]["kind"] == "interrupted"
    assert events[-1]["detail"]["reason"] == "SIGTERM"   # not "Ctrl-C": the event says what ended it


def test_sigterm_finishes_a_trials_rrd(tmp_path):
    """The .rrd of a trial ended by SIGTERM passes Rerun's own check (with SIGKILL it could
    not: the footer is written at close)."""
    out, rrd = tmp_path / "t.mcap", tmp_path / "t.rrd"
    proc = _start(tmp_path, "trial", "--rig", RIG, "--duration", "60", "--quiet", "--out", out)
    try:
        _wait_for_bytes(out, 100_000, proc)
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr
    assert "interrupted: wrote" in stdout
    verify = subprocess.run([str(rerun_binary()), "rrd", "verify", str(rrd)], capture_output=True,
                            text=True, timeout=60)
    assert verify.returncode == 0, verify.stderr
    with McapReplayDevice(out) as dev:
        assert list(dev)
