"""``ramdaq import`` of a folder (or several files, or a glob): each file imported as on its
own, a failure one line while the others go on, a count at the end."""

from __future__ import annotations

import numpy as np

from ramdaq.daq.commands.cli import main
from ramdaq.drivers.registry import open_device


def _csv(path, fs: float = 1000.0, n: int = 2000):
    """A 2-channel CSV at ``fs`` (Hz): decaying 8.3 Hz sines in m/s^2."""
    t = np.arange(n) / fs
    x = np.exp(-1.5 * t) * np.sin(2 * np.pi * 8.3 * t)
    path.write_text("time_s,A1 [m/s^2],A2 [m/s^2]\n" + "\n".join(
        f"{t[i]:.6f},{x[i]:.9e},{0.5 * x[i]:.9e}" for i in range(n)) + "\n")
    return path


def test_a_folder_imports_each_file_and_counts_the_failures(tmp_path, capsys):
    src = tmp_path / "archive"
    (src / "day2").mkdir(parents=True)
    _csv(src / "run1.csv")
    _csv(src / "day2" / "run2.txt", fs=2000.0)
    (src / "broken.csv").write_text("time_s,A1 [m/s^2]\n0,1\n0.001,x\n")
    (src / "notes.md").write_text("not a record\n")  # not an import suffix: not tried
    out = tmp_path / "out"
    rc = main(["import", str(src), "--out", str(out)])
    text = capsys.readouterr()
    assert rc == 1  # one file failed
    assert "imported 2 of 3 files; 1 failed: broken.csv" in text.out
    assert "broken.csv: line 3, column 'A1': 'x' is not a number" in text.err
    for name, fs in (("run1", 1000.0), ("run2", 2000.0)):
        with open_device(str(out / f"{name}.mcap")) as dev:
            assert dev.info.fs_hz == fs and len(dev.info.channels) == 2
        assert (out / f"{name}.rig.toml").is_file()


def test_two_files_into_one_recording_are_refused_first(tmp_path, capsys):
    _csv(tmp_path / "a.csv")
    _csv(tmp_path / "a.txt")
    rc = main(["import", str(tmp_path / "a.csv"), str(tmp_path / "a.txt")])
    err = capsys.readouterr().err
    assert rc == 1 and "would both be imported into" in err
    assert not (tmp_path / "a.mcap").exists()  # refused before anything was written
