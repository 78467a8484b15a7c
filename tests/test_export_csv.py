"""``ramdaq export-csv``: every recorded sample out as CSV, and back in through ``ramdaq import``
unchanged, gaps and events included (a new user had no way to hand a trial to another system
but the decay windows of ``export-uff``)."""

from __future__ import annotations

import numpy as np

from ramdaq.daq.commands.cli import main
from ramdaq.daq.record import record
from ramdaq.daq.recorder import Recorder
from ramdaq.drivers.files.export_csv import G_M_S2
from ramdaq.drivers.mcap_replay import McapReplayDevice
from ramdaq.drivers.sim import SimDevice
from tests.conftest import RIGS
from tests.recording_helpers import stream, stream_info


def _table(path) -> np.ndarray:
    """The CSV's rows as numbers (comment lines and the header skipped)."""
    lines = path.read_text().splitlines()
    return np.loadtxt(path, delimiter=",", skiprows=sum(t.startswith("#") for t in lines) + 1)


def _blocks(path):
    with McapReplayDevice(path) as dev:
        return dev.info, list(dev)


def test_a_simulated_trial_comes_back_count_for_count(albacore, tmp_path):
    """16-bit counts times their scale, printed to 9 digits, give the importer each channel's
    own step back: the very counts, at the very sample indices."""
    path = tmp_path / "trial.mcap"
    record(SimDevice(albacore, duration_s=3.0, impacts=[0.5], seed=5), path, readout=False)
    assert main(["export-csv", str(path)]) == 0
    csv = path.with_suffix(".csv")
    back = tmp_path / "back.mcap"
    assert main(["import", str(csv), "--rig", str(RIGS / "albacore.toml"), "--out", str(back)]) == 0
    (info, a), (info_b, b) = _blocks(path), _blocks(back)
    assert info_b.channels == info.channels
    xa = np.concatenate([k.values() for k in a], axis=1)
    xb = np.concatenate([k.values() for k in b], axis=1)
    assert xa.shape == xb.shape
    step = a[0].scale  # the simulator's per-channel step, m/s^2 a count
    # the same count on every sample: within a hundredth of a step (9 printed digits)
    assert np.all(np.abs(xa - xb) <= 0.01 * step[:, None])
    assert [k.first_sample for k in b][0] == 0 and sum(k.n_samples for k in b) == xa.shape[1]


def test_a_gap_and_its_events_survive_the_round_trip(tmp_path):
    """A recording with 256 missing samples and a device fault: the CSV says both in its
    comment lines (at stream time from sample 0), has no row for a missing sample, and
    the import puts the gap back where it was."""
    fs, n = 2048.0, 256
    blocks = stream(6, seed=3, gap_after=2, gap_blocks=1, n_channels=4, fs_hz=fs,
                    full_range=False, n_samples=n)
    path = tmp_path / "gap.mcap"
    with Recorder(path, stream_info(n_channels=4, fs_hz=fs)) as rec:
        for blk in blocks:
            rec.put(blk)
        rec.event("seq_gap", blocks[3].t0_ns, frames=1)
    assert main(["export-csv", str(path)]) == 0
    text = path.with_suffix(".csv").read_text().splitlines()
    assert text[1] == ("# 1536 samples of 4 channels; 1 gap(s), 256 sample(s) missing "
                       "(steps in the time column)")
    assert text[2] == "# force channel(s): g04 (ramdaq import --force-channel)"
    gap_at = 4 * n / fs  # the first sample after the gap: block 4's, at 0.5 s
    assert any(t.startswith(f"# event seq_gap at {gap_at:.6f} s: ") for t in text)
    rows = [t for t in text if not t.startswith("#")][1:]
    times = np.array([float(r.split(",")[0]) for r in rows])
    assert len(rows) == 6 * n and np.count_nonzero(np.diff(times) > 1.5 / fs) == 1
    back = tmp_path / "back.mcap"
    assert main(["import", str(path.with_suffix(".csv")), "--out", str(back), "--units", "m/s^2",
                 "--force-channel", "g04"]) == 0
    _, got = _blocks(back)
    present = np.concatenate([np.arange(k.first_sample, k.next_sample) for k in got])
    assert np.array_equal(present, np.r_[0:3 * n, 4 * n:7 * n])  # block 3's samples missing

def test_gages_in_g_force_in_newtons(albacore, tmp_path):
    """``--units g``: each gage's value is its m/s^2 over standard gravity; the force channel
    (none on this rig) would stay in N; the header says each column's unit."""
    path = tmp_path / "t.mcap"
    record(SimDevice(albacore, duration_s=1.0, impacts=[0.3], seed=2), path, readout=False)
    si, g = tmp_path / "si.csv", tmp_path / "g.csv"
    assert main(["export-csv", str(path), "--out", str(si)]) == 0
    assert main(["export-csv", str(path), "--out", str(g), "--units", "g"]) == 0
    head_si = [t for t in si.read_text().splitlines() if not t.startswith("#")][0]
    head_g = [t for t in g.read_text().splitlines() if not t.startswith("#")][0]
    assert head_si.startswith("time [s],g") and "[m/s^2]" in head_si and "[g]" not in head_si
    assert head_g == head_si.replace("[m/s^2]", "[g]")
    a, b = _table(si), _table(g)
    assert np.array_equal(a[:, 0], b[:, 0])
    np.testing.assert_allclose(b[:, 1:], a[:, 1:] / G_M_S2, rtol=1e-8, atol=1e-12)


def test_an_existing_output_is_refused(albacore, tmp_path, capsys):
    path = tmp_path / "t.mcap"
    record(SimDevice(albacore, duration_s=0.5, impacts=[], seed=2), path, readout=False)
    path.with_suffix(".csv").write_text("keep me")
    assert main(["export-csv", str(path)]) == 1
    assert "exists" in capsys.readouterr().err
    assert path.with_suffix(".csv").read_text() == "keep me"


def test_a_water_trial_comes_back_in_water_with_its_own_scale(albacore, tmp_path, capsys):
    """tester9: a water trial exported and imported with ``--rig albacore`` (an air rig) came
    back in air without a word (the damping chain changes ~4x), and each channel's scale came
    back 1e-10 off. The header states the medium and the scale (repr of the float): the import
    applies both, says where the rig disagreed, and a contrary --medium is warned of."""
    path = tmp_path / "wet.mcap"
    record(SimDevice(albacore.with_medium("water"), duration_s=1.0, impacts=[0.3], seed=2), path,
           readout=False)
    assert main(["export-csv", str(path)]) == 0
    csv = path.with_suffix(".csv")
    assert "# medium: water" in csv.read_text()[:4000].splitlines()
    back = tmp_path / "back.mcap"
    rig = str(RIGS / "albacore.toml")
    capsys.readouterr()
    assert main(["import", str(csv), "--rig", rig, "--out", str(back)]) == 0
    out = capsys.readouterr().out
    assert "medium water, as the file's header states (the rig says air" in out
    (_, a), (info_b, b) = _blocks(path), _blocks(back)
    assert info_b.extra["medium"] == "water"
    # bit for bit: the very counts and the very float scale
    assert np.array_equal(np.concatenate([k.counts for k in a], 1),
                          np.concatenate([k.counts for k in b], 1))
    assert all(np.array_equal(k.scale, a[0].scale) for k in b)
    assert main(["import", str(csv), "--rig", rig, "--medium", "air", "--out",
                 str(tmp_path / "dry.mcap")]) == 0
    err = capsys.readouterr().err
    assert "warning: medium air as --medium gives, but the file's header states water" in err
    assert _blocks(tmp_path / "dry.mcap")[0].extra["medium"] == "air"
    assert main(["import", str(csv), "--out", str(tmp_path / "norig.mcap")]) == 0
    assert "medium = \"water\"" in (tmp_path / "norig.rig.toml").read_text()
    assert _blocks(tmp_path / "norig.mcap")[0].extra["medium"] == "water"


def test_a_channels_only_reimport_keeps_the_onsets(tmp_path, capsys):
    """tester10: the shipped water trial exported and imported without --rig started hit 0's
    decay one sample late: the channels-only rig named no anti-alias filter, so the trigger
    removed no front-end delay (0.47 sample, 4th order at 800 Hz, 2048 Hz) and the refined onset
    3.00037 s rounded to the next sample. The CSV states the recorded rig's filter and the
    channels-only rig names it: every onset is the original's, to the digit."""
    from pathlib import Path

    import ramdaq

    water = Path(__file__).resolve().parents[1] / "recordings" / "albacore-water.mcap"
    csv = tmp_path / "water.csv"
    assert main(["export-csv", str(water), "--out", str(csv)]) == 0
    assert "# anti-alias: order 4, 800.0 Hz" in csv.read_text()[:4000].splitlines()
    back = tmp_path / "water.mcap"
    assert main(["import", str(csv), "--out", str(back)]) == 0
    assert "anti-alias filter order 4 at 800 Hz, as the file states" in capsys.readouterr().out
    assert "anti_alias_hz = 800.0\nanti_alias_order = 4" in (tmp_path / "water.rig.toml").read_text()
    a, b = ramdaq.read_recording(water).impacts, ramdaq.read_recording(back).impacts
    assert len(a) == len(b) == 3
    assert [(e.onset_sample, e.onset_s) for e in a] == [(e.onset_sample, e.onset_s) for e in b]
