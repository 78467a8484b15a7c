"""The notebook API: ramdaq.read_recording, ramdaq.analyze, their tables, and a fast import."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import ramdaq
from ramdaq.daq.recorder import Recorder
from ramdaq.drivers.mcap_replay import McapReplayDevice
from tests.recording_helpers import stream, stream_info

WATER = Path(__file__).parent.parent / "recordings" / "albacore-water.mcap"


@pytest.fixture(scope="module")
def water() -> ramdaq.Recording:
    return ramdaq.read_recording(WATER)


@pytest.fixture(scope="module")
def analysed(water: ramdaq.Recording) -> ramdaq.TrialAnalysis:
    return ramdaq.analyze(water)


def test_import_is_lazy() -> None:
    """`import ramdaq` loads neither numpy nor the acquisition code; the API loads on first use."""
    code = ("import sys, ramdaq; print('numpy' in sys.modules, 'ramdaq.daq' in sys.modules); "
            "ramdaq.read_recording; print('ramdaq.daq.recording' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False", "True"]


def test_recording_values_are_the_blocks_in_si(water: ramdaq.Recording) -> None:
    with McapReplayDevice(WATER) as dev:
        blocks = list(dev)
    assert water.values.shape == (16, blocks[-1].next_sample)
    for b in (blocks[0], blocks[len(blocks) // 2], blocks[-1]):
        np.testing.assert_array_equal(water.values[:, b.first_sample:b.next_sample], b.values())
    assert water.fs_hz == 2048.0
    assert water.gages == tuple(range(1, 17)) and set(water.units) == {"m/s^2"}
    assert water.time_s[2048] == 1.0 and water.duration_s == water.n_samples / 2048.0
    assert water.rig is not None and water.rig.medium == "water"
    assert water.created_utc.endswith("Z")
    np.testing.assert_array_equal(water.gage_values([4, 1]), water.values[[3, 0]])
    with pytest.raises(KeyError, match="gage"):
        water.gage_values([17])


def test_impacts_are_the_simulated_blows(water: ramdaq.Recording) -> None:
    with McapReplayDevice(WATER) as dev:
        truth = [m.obj["t_s"] for m in dev.json_messages("/ramdaq/sim/impacts")]
    # 2 ms: four samples at 2048 Hz; the trigger's own tests hold its onset far tighter, this
    # only checks that the reader hands the trigger the stream in order
    assert [ev.onset_s for ev in water.impacts] == pytest.approx(truth, abs=2e-3)


def test_gap_is_nan_not_zero(tmp_path: Path) -> None:
    info = dataclasses.replace(stream_info(n_channels=3, fs_hz=1000.0), rig_toml="")
    blocks = stream(4, gap_after=1, gap_blocks=2, n_channels=3, fs_hz=1000.0, n_samples=100,
                    full_range=False)
    path = tmp_path / "gap.mcap"
    with Recorder(path, info) as rec:
        for b in blocks:
            rec.put(b)
    r = ramdaq.read_recording(path, trigger=False)
    assert r.values.shape == (3, 600) and r.rig is None
    assert np.isnan(r.values[:, 200:400]).all() and np.isfinite(r.values[:, :200]).all()
    np.testing.assert_array_equal(r.values[:, 400:500], blocks[2].values())
    assert [e.kind for e in r.events] == ["gap"]
    assert r.events[0].detail["missing_samples"] == 200
    with pytest.raises(Exception, match="carries no rig"):
        ramdaq.analyze(r)


def test_dataframe_and_xarray(water: ramdaq.Recording) -> None:
    pytest.importorskip("pandas")
    df = water.to_dataframe()
    assert df.shape == (water.n_samples, 16) and list(df.columns) == list(water.channels)
    np.testing.assert_array_equal(df["g04"].to_numpy(), water.values[3])
    assert df.index[2048] == 1.0 and df.attrs["units"]["g04"] == "m/s^2"
    pytest.importorskip("xarray")
    da = water.to_xarray()
    assert da.dims == ("channel", "time_s")
    np.testing.assert_array_equal(da.sel(channel="g10").values, water.values[9])
    assert int(da.gage.sel(channel="g10")) == 10


def test_analyze_rows_match_the_analysis(analysed: ramdaq.TrialAnalysis) -> None:
    """One row per hit x gage x mode; the predominant rows carry the report's per-gage decrement."""
    rows = analysed.rows()
    assert len(analysed.hits) == 3 and all(h.accepted for h in analysed.hits)
    for h in analysed.hits:
        a = h.analysis
        n_modes = len(a.modes.frequency_hz)
        mine = [r for r in rows if r.hit == h.index]
        assert len(mine) == len(a.active_gages) * n_modes + len(a.gage_numbers) - len(a.active_gages)
        for r in mine:
            if r.predominant:
                assert r.delta == a.gages[r.gage].delta and r.delta_se == a.gages[r.gage].delta_se
                assert r.f_hz == a.gages[r.gage].f_hz
                assert r.verdict == "ok"
            if r.fitted:  # zeta = delta / sqrt(4 pi^2 + delta^2), exactly
                assert r.zeta == pytest.approx(r.delta / np.sqrt(4 * np.pi**2 + r.delta**2), rel=1e-12)
    pytest.importorskip("pandas")
    df = analysed.to_dataframe()
    assert len(df) == len(rows)
    assert {"f_hz", "f_se_hz", "delta", "delta_se", "zeta", "zeta_se", "verdict"} <= set(df.columns)
    assert str(df["mode"].dtype) == "Int64" and df["fitted"].dtype == bool


def test_analyze_one_hit_marks_the_others(water: ramdaq.Recording) -> None:
    res = ramdaq.analyze(water, impact=1)
    assert [h.accepted for h in res.hits] == [False, True, False]
    skipped = [r for r in res.rows() if not r.accepted]
    # tester10: rows() said mode -1 where the Parquet table says null and fitted false
    assert [(r.hit, r.gage, r.mode, r.fitted, r.reason) for r in skipped] == \
        [(0, 0, None, False, "not requested"), (2, 0, None, False, "not requested")]
    from ramdaq.daq.commands.batch_tasks import analyze_rows
    table = [t for h in res.hits for t in analyze_rows(h, tuple(water.channels), {})]
    assert [(r.hit, r.gage, r.mode, r.fitted) for r in res.rows()] == \
        [(t.hit, t.gage, t.mode, t.fitted) for t in table]       # one convention, row for row
    assert all((r.mode is None) == (not r.fitted) for r in res.rows())
    with pytest.raises(ValueError, match="impact 5 asked for, but 3 impacts found"):
        ramdaq.analyze(water, impact=5)


def test_shared_mode_columns_repeat_the_mode_table(analysed: ramdaq.TrialAnalysis) -> None:
    """mode_* columns are the fit shared by all gages: one value per hit and mode."""
    h = analysed.hits[0]
    m = h.analysis.modes
    for r in (r for r in analysed.rows() if r.hit == 0 and r.fitted):
        assert (r.mode_f_hz, r.mode_delta, r.mode_zeta_se) == (
            m.frequency_hz[r.mode], m.delta[r.mode], m.zeta_se[r.mode])
        assert -np.pi <= r.phase_rad <= np.pi and r.amplitude > 0


def test_diagnose_runs_every_layer_and_answers_as_ramdaq_gap() -> None:
    """``ramdaq.diagnose`` runs the layers ``ramdaq gap`` runs (the model level calibrating the
    rig to the trial's modes, the data-only checks) and carries the same one answer; it ran
    the effect search alone and its ``effect`` was the model layer's choice."""
    from ramdaq.daq.gap_layers import one_answer

    air = Path(__file__).parent.parent / "recordings" / "albacore-air.mcap"
    d = ramdaq.diagnose(air)
    assert d.diagnosis.model_level is not None and d.diagnosis.data is not None
    assert d.answer is not None and d.answer == one_answer(d.diagnosis)
    # the simulator's own clean trial with its own rig: nothing to name
    assert d.answer.named == "none" and d.effect is None
