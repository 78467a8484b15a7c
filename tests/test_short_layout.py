"""A field system with fewer gages than the report's 16 (gages 1-8 under their report numbers):
simulated, analysed and diagnosed end to end. The rudder's motions come out as with all 16
gages; the steps that need a gage left out say so; the gap diagnosis runs on the 8 gages there
are (a new user had to invent gages 9-16, session 16)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from ramdaq.analysis.model.rig import parse_rig
from ramdaq.daq.commands.analyze import run_analysis
from ramdaq.daq.record import record
from ramdaq.drivers.sim import SimDevice

RIGS = Path(__file__).resolve().parents[1] / "recordings" / "rigs"


def _eight(tmp_path: Path) -> Path:
    text = (RIGS / "albacore.toml").read_text()
    for n in range(9, 17):
        block = re.search(r"\[\[gages\]\]\nnumber = " + str(n) + r"\n.*?(?=\n\[\[gages\]\]|\Z)", text, re.S)
        text = text.replace(block.group(0), "")
    path = tmp_path / "eight.toml"
    path.write_text(text.replace('name = "albacore-like"', 'name = "eight"', 1))
    return path


def _trial(rig: Path, path: Path) -> list:
    with SimDevice(rig, duration_s=8.0, impacts=[2.0], seed=4, pace="fast") as dev:
        record(dev, path, readout=False)
    _, hits = run_analysis(path)
    assert [h.accepted for h in hits] == [True], [h.reason for h in hits]
    return hits[0].analysis


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("short")
    eight = _eight(tmp)
    return (_trial(RIGS / "albacore.toml", tmp / "all.mcap"), _trial(eight, tmp / "eight.mcap"),
            eight, tmp / "eight.mcap")


def test_the_rudder_motions_of_eight_gages_are_those_of_sixteen(both):
    """The same structure and blow (the simulator's seed differs only in the noise of the
    channels there are): each rudder motion's decrement agrees within 4 combined standard errors
    (a 4-sigma band: the two noise draws are independent)."""
    full, short, _, _ = both
    assert set(short.motions) == set(full.motions) and short.motions
    for name, m in short.motions.items():
        f = full.motions[name]
        assert abs(m.delta - f.delta) <= 4 * (m.delta_se ** 2 + f.delta_se ** 2) ** 0.5, name
    assert not short.hull_motions  # gages 13 and 14 are not there
    skipped = {s.step for s in short.skipped}
    assert "decrements relative to the hull (Eq 8-13)" in skipped
    assert "rudder motions (Eq 1-6b)" not in skipped


def test_gap_runs_on_the_gages_there_are(both):
    from ramdaq.daq.commands.gap import run_gap

    _, _, rig, mcap = both
    said: list[str] = []
    _, td, d = run_gap(mcap, progress=said.append)
    assert td.n_gages == 8 == len(parse_rig(rig.read_text()).gages)
    assert not any("have no channel" in s for s in said), said
    assert d.headline
