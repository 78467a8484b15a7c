"""docs/example.py, the API end to end on the shipped recordings, runs and writes what it says."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

EXAMPLE = Path(__file__).parent.parent / "docs" / "example.py"


def test_example_runs_end_to_end(tmp_path: Path) -> None:
    out = tmp_path / "out"
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}  # ramdaq sets it
    r = subprocess.run([sys.executable, str(EXAMPLE), str(out)], capture_output=True, text=True,
                       timeout=600, cwd=tmp_path, env=env)
    assert r.returncode == 0, r.stderr
    assert "RuntimeWarning" not in r.stderr  # imported before numpy: one BLAS thread
    assert "3 blows at" in r.stdout and "gap diagnosis of sampson-water: explained" in r.stdout
    for kind in ("decay", "spectrum", "modeshape"):
        assert (out / f"impact0_{kind}.png").stat().st_size > 20_000
    for kind in ("map", "decays", "ranking"):
        assert (out / f"gap_{kind}.png").stat().st_size > 20_000
    rows = list(csv.DictReader((out / "modes.csv").open()))
    assert {"hit", "gage", "mode", "f_hz", "delta", "delta_se", "zeta", "verdict"} <= set(rows[0])
    cands = list(csv.DictReader((out / "gap_candidates.csv").open()))
    assert cands[0]["effect"] == "ambient_tone" and cands[0]["named"] == "True"
