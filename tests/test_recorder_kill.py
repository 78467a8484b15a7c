"""SIGKILL a real recording process mid-run, recover the file, and count what was lost.

The child (``tests/record_child.py``) records 16 channels at 25.6 kHz in 50 ms blocks at a steady
real-time pace and prints every block it has handed to the recorder. The recorder finishes a
chunk every 0.25 s of samples and hands it straight to the OS, so what a kill can lose is the open
chunk (< 0.25 s) plus what is still queued (nothing, at this pace): the test allows 0.5 s.
"""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ramdaq.daq.errors import TruncatedRecording
from ramdaq.daq.recover import recover
from ramdaq.drivers.mcap_replay import McapReplayDevice
from tests.recording_helpers import FS_HZ, block

pytestmark = pytest.mark.timeout(60)

REPO = Path(__file__).resolve().parent.parent
SEED = 21
KILL_AFTER_BLOCKS = 32  # 1.6 s of stream: two blocks into a chunk
MAX_LOSS_S = 0.5


def _put_lines(lines):
    return [tuple(int(x) for x in line.split()[1:]) for line in lines if line.startswith("put ")]


def test_sigkill_loses_less_than_half_a_second(tmp_path):
    path, dst = tmp_path / "killed.mcap", tmp_path / "killed.recovered.mcap"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    child = subprocess.Popen(
        [sys.executable, "-m", "tests.record_child", str(path), str(SEED), "400"],
        cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1,
    )
    lines = []
    try:
        deadline = time.monotonic() + 30
        while len(_put_lines(lines)) < KILL_AFTER_BLOCKS:
            line = child.stdout.readline()
            assert line, f"child exited early: {child.stderr.read()}"
            lines.append(line)
            assert time.monotonic() < deadline, "child too slow to start"
        os.kill(child.pid, signal.SIGKILL)
        assert child.wait(timeout=10) == -signal.SIGKILL
        lines += child.stdout.read().splitlines()  # anything printed before the kill landed
    finally:
        if child.poll() is None:
            child.kill()
        child.stdout.close()
        child.stderr.close()

    puts = _put_lines(lines)
    assert all(ok for *_, ok in puts), "no overflow at a real-time pace"
    handed_end = max(first + n for _, first, n, _ in puts)  # samples the recorder was given

    with pytest.raises(TruncatedRecording, match="no footer"):
        McapReplayDevice(path).open()
    report = recover(path, dst)
    assert report.truncated
    with McapReplayDevice(dst) as dev:
        back = list(dev)
    assert [b.seq for b in back] == list(range(len(back)))  # an unbroken prefix
    assert all(b.same_as(block(b.seq, SEED, full_range=False)) for b in back)  # bit-identical
    recovered_end = back[-1].next_sample if back else 0
    loss_s = (handed_end - recovered_end) / FS_HZ
    print(f"\nSIGKILL after {len(puts)} blocks ({handed_end / FS_HZ:.2f} s handed over): "
          f"recovered {len(back)} blocks ({recovered_end / FS_HZ:.2f} s), lost {loss_s:.3f} s, "
          f"torn tail {report.tail_bytes} bytes")
    assert report.last_sample == recovered_end - 1
    assert 0 <= loss_s < MAX_LOSS_S
