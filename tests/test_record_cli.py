"""End to end: the simulated device through the record loop into MCAP, replayed bit-identical;
and the command line as a user runs it."""

import json
import re
import subprocess
import sys

import numpy as np
import pytest

from ramdaq.analysis.model.rig_modes import eq18_check
from ramdaq.daq.record import record
from ramdaq.drivers.mcap_replay import McapReplayDevice
from ramdaq.drivers.registry import open_device
from ramdaq.drivers.sim import SimDevice
from tests.conftest import RIGS


def test_sim_recording_replays_bit_identical(albacore, tmp_path):
    kw = dict(duration_s=3.0, impacts=[0.5, 2.0], seed=11)
    with SimDevice(albacore, **kw) as dev:
        produced = list(dev)
    path = tmp_path / "trial.mcap"
    summary = record(SimDevice(albacore, **kw), path, readout=False)
    assert summary.blocks == len(produced) and summary.impacts == 2 and summary.overflows == 0
    with open_device(str(path)) as replay:
        assert isinstance(replay, McapReplayDevice)
        got = list(replay)
        assert replay.info.rig_toml == albacore.text
        assert replay.info.channels == tuple(f"g{g.number:02d}" for g in albacore.gages_by_channel())
    assert len(got) == len(produced)
    assert all(a.same_as(b) for a, b in zip(produced, got, strict=True))


def _ramdaq(*args, cwd):
    return subprocess.run([sys.executable, "-m", "ramdaq", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=120)


def test_cli_record_and_info(tmp_path):
    out = tmp_path / "t.mcap"
    r = _ramdaq("record", "--rig", str(RIGS / "sampson.toml"), "--duration", "4", "--impacts",
                "1,2.5", "--fast", "--out", str(out), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "wrote" in r.stdout and "2 impacts" in r.stdout
    info = _ramdaq("info", str(out), "--json", cwd=tmp_path)
    assert info.returncode == 0, info.stderr
    d = json.loads(info.stdout)
    assert abs(d["duration_s"] - 4.0) < 1 / 2048  # one sample period
    assert len(d["channels"]) == 16
    text = _ramdaq("info", str(out), cwd=tmp_path)
    assert "g16" in text.stdout
    # ``record`` runs no trigger: its file holds no detections, which is not "0 impacts" (a new
    # user's import read "impacts 0 detected" for a file of six blows)
    assert ("impacts    none written by a live trigger, 2 simulated (truth) (the file may still "
            "hold blows: ramdaq replay or analyze detects them)") in text.stdout


def test_cli_bad_rig_is_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text((RIGS / "albacore.toml").read_text().replace('axis = "z"', 'axis = "up"', 1))
    r = _ramdaq("record", "--rig", str(bad), "--duration", "1", "--fast", "--out",
                str(tmp_path / "x.mcap"), cwd=tmp_path)
    assert r.returncode == 1
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "axis: unknown axis 'up'" in lines[0] and "bad.toml" in lines[0]


def test_cli_rig_prints_eq18_beside_model_added_mass(albacore, tmp_path):
    r = _ramdaq("rig", str(RIGS / "albacore.toml"), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    c = eq18_check(albacore)
    assert f"{c.m_vir_eq18_kg:.0f} kg" in r.stdout and f"{c.m_vir_model_kg:.0f} kg" in r.stdout
    # Report 1836 Table 2d: Eq 18 0.2240 vs Eq 19 0.2735 ton s^2/ft, i.e. -18.1 %. Our model,
    # tuned to the same frequencies with the same m_a and Eq 19, shows a gap of that sign and
    # size (a coupled mode, not Eq 18's uncoupled translation); 5 points either side allowed.
    report_gap = 0.2240 / 0.2735 - 1
    assert abs(c.difference - report_gap) < 0.05
    assert np.isfinite(c.difference)
    assert "warning: Eq 18" not in r.stdout  # the shipped rig's -18 % is the report's own


def test_cli_rig_warns_when_eq18_is_far_off_the_models_added_mass(tmp_path):
    """tester10: a rig with the rudder's mass x10 and its dashpots x0.2 printed "Eq 18 is +67036 %
    off" and nothing else (the air trial's predominant mode became another mode than the water
    one's): beyond 2x (the report's own gap is -18 %) one line points at the rig's masses."""
    text = (RIGS / "albacore.toml").read_text()

    def times(k: float):
        return lambda m: f"{m[1]}{k * float(m[2])!r}"

    spoiled = re.sub(r"(?m)^(mass_kg\s*=\s*)([0-9.eE+-]+)", times(10.0), text, count=1)
    spoiled = re.sub(r"(?m)^((?:C_N_s_per_m|c_N_m_s_per_rad|c_alpha_N_m_s_per_rad)\s*=\s*)([0-9.eE+-]+)",
                     times(0.2), spoiled)
    assert spoiled.count("\n") == text.count("\n") and spoiled != text
    (tmp_path / "heavy.toml").write_text(spoiled)
    r = _ramdaq("rig", str(tmp_path / "heavy.toml"), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    warn = [ln for ln in r.stdout.splitlines() if ln.startswith("warning: Eq 18 is ")]
    assert len(warn) == 1 and "check the rig's masses" in warn[0]


@pytest.mark.parametrize(("option", "value"), [("--duration", "-5"), ("--impact-every", "0"),
                                               ("--fs", "nan"), ("--duration", "ten")])
def test_cli_refuses_a_time_or_rate_that_is_not_above_zero(option, value, tmp_path):
    """A negative duration used to write an empty recording and exit 0; a blow every 0 s gave none."""
    out = tmp_path / "x.mcap"
    r = _ramdaq("trial", "--rig", str(RIGS / "albacore.toml"), option, value, "--fast", "--out",
                str(out), "--no-rerun", cwd=tmp_path)
    assert r.returncode == 2, r.stderr  # argparse's usage error
    assert f"argument {option}: {value!r}" in r.stderr and not out.exists()


@pytest.mark.parametrize(("extra", "named"), [(("--rig", "sampson"), "--rig"),
                                              (("--medium", "water", "--seed", "3"), "--medium, --seed")])
def test_a_recording_as_the_device_refuses_the_simulators_options(extra, named, tmp_path):
    """A new user gave --rig with a recording as the device: 'internal error, TypeError' (exit 3);
    --medium, --seed, --fs, --duration were ignored without a word. Each is a one-line refusal
    naming the options, before anything is written."""
    out = tmp_path / "x.mcap"
    r = _ramdaq("trial", "--device", str(RIGS.parent / "albacore-air.mcap"), *extra,
                "--quiet", "--out", str(out), "--no-rerun", cwd=tmp_path)
    assert r.returncode == 1 and not out.exists()
    line, = r.stderr.strip().splitlines()
    assert line.startswith(f"ramdaq trial: {named}: ") and "Traceback" not in r.stderr


@pytest.mark.parametrize(("extra", "says"), [
    (("--impacts", "12", "--duration", "5"), "--impacts 12 s: outside the 5 s trial"),
    (("--impacts", "1,4", "--impact-every", "2"), "--impacts and --impact-every: give one"),
    (("--fs", "100000", "--duration", "1"), "--fs 100000 Hz: above the 51200 Hz"),
])
def test_simulator_options_that_cannot_be_met_are_refused(extra, says, tmp_path):
    """The new user's: a blow after the trial's end gave 0 hits with no word; --impacts with
    --impact-every merged both (a blow 0.5 s after another reads as a double hit); a rate the
    trigger cannot run at was taken. Each is one line, before anything is written."""
    out = tmp_path / "x.mcap"
    r = _ramdaq("record", "--rig", str(RIGS / "albacore.toml"), *extra, "--fast", "--quiet",
                "--out", str(out), cwd=tmp_path)
    assert r.returncode == 1 and not out.exists(), r.stderr
    line, = r.stderr.strip().splitlines()
    assert line.startswith("ramdaq record: " + says), line


def test_cli_rig_warns_of_a_rudder_a_thousand_times_too_light(tmp_path):
    """The new user's typo, the rudder's 2870.2 kg as 2.8702: `ramdaq rig` printed 8955 kg of
    added mass on it and "Eq 18 is -99.7 % off" without a warning (the check looked only at
    Eq 18 too large). Both lines now warn; the shipped rigs (ratio 3.1 and 3.3) do not."""
    text = (RIGS / "albacore.toml").read_text()
    light = re.sub(r"(?m)^mass_kg = 2870.2$", "mass_kg = 2.8702", text, count=1)
    assert light != text
    (tmp_path / "light.toml").write_text(light)
    r = _ramdaq("rig", str(tmp_path / "light.toml"), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    warn = [ln for ln in r.stdout.splitlines() if ln.startswith("warning: ")]
    assert any(w.startswith("warning: the rudder's mass (2.87 kg) is 3.12e+03x smaller") for w in warn)
    assert any(w.startswith("warning: Eq 18 is 289x off") for w in warn)
    for name in ("albacore.toml", "sampson.toml"):
        r = _ramdaq("rig", str(RIGS / name), cwd=tmp_path)
        assert "warning" not in r.stdout, r.stdout
