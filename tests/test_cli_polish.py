"""The command line's surface: --version, gap-benchmark's own help, help on every positional,
progress bars with an ETA on a terminal (a real pty)."""

from __future__ import annotations

import argparse
import os
import pty
import subprocess
import sys
from pathlib import Path

import pytest

import ramdaq
from ramdaq.daq.commands.cli import build_parser, main

WATER = Path(__file__).parent.parent / "recordings" / "albacore-water.mcap"
BENCH_ONLY = ("--per-class", "--seeds", "--dev", "--check", "--jobs", "--rescore", "--thresholds")


def _help(argv: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as end:
        main(argv)
    assert end.value.code == 0
    return capsys.readouterr().out


def test_version(capsys) -> None:
    assert _help(["--version"], capsys).strip() == f"ramdaq {ramdaq.__version__}"


def test_benchmark_options_only_in_gap_benchmark(capsys) -> None:
    gap = _help(["gap", "--help"], capsys)
    bench = _help(["gap-benchmark", "--help"], capsys)
    assert not [o for o in BENCH_ONLY if o in gap]
    assert all(o in bench for o in BENCH_ONLY)
    # the older spelling is the same command
    assert _help(["gap", "benchmark", "--help"], capsys) == bench


def test_every_positional_has_help() -> None:
    parsers = [build_parser()]
    seen = 0
    while parsers:
        p = parsers.pop()
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                parsers += list(action.choices.values())
            elif not action.option_strings:
                assert action.help, f"{p.prog} {action.dest}: no help"
                seen += 1
    assert seen >= 9


def test_analyze_shows_progress_with_eta_on_a_terminal(tmp_path) -> None:
    main_fd, term = pty.openpty()
    env = os.environ | {"COLUMNS": "160", "TERM": "xterm"}
    proc = subprocess.Popen([sys.executable, "-m", "ramdaq.daq.commands.cli", "analyze", str(WATER),
                             "--no-plots", "--out", str(tmp_path / "a")],
                            stdin=term, stdout=term, stderr=term, env=env, close_fds=True)
    os.close(term)
    out = b""
    while True:
        try:
            chunk = os.read(main_fd, 65536)
        except OSError:  # the child closed the terminal
            break
        if not chunk:
            break
        out += chunk
    os.close(main_fd)
    assert proc.wait(timeout=120) == 0
    text = out.decode(errors="replace")
    assert "reading albacore-water.mcap" in text and "analysing albacore-water.mcap" in text
    assert "ETA" in text and "3/3" in text and "hits" in text
    assert "3 of 3 hits accepted" in text


def test_no_bar_when_not_a_terminal(tmp_path) -> None:
    """Piped or captured, standard error carries no bar: one-line errors stay one line."""
    r = subprocess.run([sys.executable, "-m", "ramdaq.daq.commands.cli", "analyze", str(WATER),
                        "--no-plots", "--impact", "7", "--out", str(tmp_path / "b")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 1
    assert r.stderr.count("\n") == 1 and "impact 7 asked for, but 3 impacts found" in r.stderr
