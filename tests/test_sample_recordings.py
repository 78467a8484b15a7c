"""The committed sample recordings are what their documented commands make with today's code."""

import re
import shlex
import subprocess
from pathlib import Path

import pytest

from ramdaq.daq.commands.cli import main
from ramdaq.drivers.registry import open_device
from tests.conftest import RIGS

README = RIGS.parent / "README.md"
COMMANDS = re.findall(r"\| `(\w[\w-]*\.mcap)` \|[^|]*\| `(ramdaq record [^`]+)` \|", README.read_text())


def committed_samples() -> set[str]:
    """The recordings git tracks in ``recordings/`` (a trial the README's main job records
    there, ``demo.mcap``, is ignored by git and is not a sample); without git, every file."""
    try:
        out = subprocess.run(["git", "ls-files", "*.mcap"], cwd=RIGS.parent, capture_output=True,
                             text=True, check=True).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        return {p.name for p in RIGS.parent.glob("*.mcap")}
    return {Path(p).name for p in out}


def test_readme_lists_the_samples():
    assert {name for name, _ in COMMANDS} == committed_samples()


@pytest.mark.parametrize(("name", "command"), COMMANDS, ids=[n for n, _ in COMMANDS])
def test_sample_matches_its_command(name, command, tmp_path, monkeypatch):
    monkeypatch.chdir(RIGS.parent.parent)
    argv = shlex.split(command)[1:] + ["--out", str(tmp_path / name)]
    assert main(argv) == 0
    with open_device(str(RIGS.parent / name)) as committed, open_device(str(tmp_path / name)) as fresh:
        assert committed.info.rig_toml == fresh.info.rig_toml
        pairs = list(zip(committed, fresh, strict=True))
    assert pairs and all(a.same_as(b) for a, b in pairs)
