"""The data-only layer of one gap-benchmark scenario on the impacts the diagnosis compares and on
the generator's own blows: whether a finding comes from an impact the trigger found that is no
blow.

The scenario is generated, recorded and loaded as ``ramdaq gap-benchmark`` does
(:func:`~ramdaq.daq.commands.gap_bench.run_one`: the generator's counts through the recorder, the
rig perturbed as the benchmark hands it); the onsets the trigger found, those the diagnosis
compares and the generator's are printed, then the data-only checks
(:func:`~ramdaq.analysis.gap.sensors.check_trial`) run twice: on the compared impacts, and on
those of them within ``--tol`` s of a generator's blow. Each finding is printed with its
statistic over its chance level and its first ``more`` values.

Measured at main 95a0242 (2026-11-28, load average 18-22 on 2 cores), modal development seed
58004 (friction, SAMPSON in water, 4 blows): the trigger found 8 onsets, the diagnosis compared
5 (3.000, 9.001, 11.176, 15.001, 21.001 s; 11.176 s is no blow, 2.2 s after the smallest one);
on those 5 the homogeneity check read an amplitude slope (exponent 0.03) at 54.7x its chance
level and three gages' phase misfits at 30-50x, answered "unexplained"; on the 4 blows it read
Coulomb's law on the 7.5 Hz mode (z 11.4, size 1.40) at 2.8x its chance level and nothing else.

    python benchmarks/gap_onsets.py SEED EFFECT [--seeds dev] [--blows 4]  (modal family)
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np


def _print_findings(title: str, onsets: np.ndarray, dc) -> None:
    print(f"{title}: {np.round(onsets, 3).tolist()}  free poles {np.round(dc.modal.f_hz, 2).tolist()} Hz")
    for f in dc.findings:
        more = [(m[0], round(float(m[1]), 3)) for m in f.more][:3]
        print(f"    {f.check:18s} gages {list(f.gages)}  {f.statistic / f.chance_level:.2f}x chance  "
              f"modes {np.round(f.mode_hz[:3], 2).tolist()}  {more}")


def main() -> None:
    from ramdaq.analysis.gap.sensors import check_trial
    from ramdaq.analysis.model.rig import load_rig
    from ramdaq.analysis.truth.modal_family import generate
    from ramdaq.daq.commands.gap_bench import perturbed_rig, rudder_modes_hz, scenarios
    from ramdaq.daq.gap_layers import declared_lines
    from ramdaq.daq.gap_trial import load_trial, trial_data
    from ramdaq.daq.record import record
    from ramdaq.drivers.array_device import ArrayDevice

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("seed", type=int)
    ap.add_argument("effect")
    ap.add_argument("--seeds", default="dev", choices=("dev", "check"))
    ap.add_argument("--blows", type=int, default=4, help="blows per trial (the benchmark's 4)")
    ap.add_argument("--perturb", type=float, default=0.25)
    ap.add_argument("--tol", type=float, default=0.01, help="an onset within this of a blow is the blow, s")
    a = ap.parse_args()
    scs = scenarios(6, a.seeds, (a.effect,), a.perturb, "modal", a.blows)
    sc = next((s for s in scs if s["seed"] == a.seed), None)
    if sc is None:
        raise SystemExit(f"no modal {a.effect} scenario of seed {a.seed} in the {a.seeds} seeds")
    rig = load_rig(sc["rig"]).with_medium(sc["medium"])     # as gap_bench._generate_modal
    tr = generate(rig.text, rudder_modes_hz(rig), sc["effect"], sc["size"], sc["seed"], n_impacts=a.blows)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "trial.mcap"
        dev = ArrayDevice(tr.counts, tr.scale, tr.fs_hz, gages=tr.gage_numbers, rig_toml=rig.text,
                          extra={"medium": sc["medium"], "adc_bits": tr.adc_bits})
        record(dev, path, readout=False, overwrite=True)
        lt = load_trial(path, perturbed_rig(rig, a.perturb, sc["seed"]) if a.perturb else None)
        td = trial_data(lt)
    blows = np.asarray(tr.onsets_s, float)
    print(f"modal {a.effect} {a.seed} ({sc['rig']} in {sc['medium']}): "
          f"blows at {np.round(blows, 3).tolist()}; "
          f"the trigger found {len(lt.onsets_s)} onsets {np.round(lt.onsets_s, 3).tolist()}")
    gages, declared = lt.rig.gages_by_channel(), declared_lines(lt.rig)
    dc = check_trial(lt.x, lt.fs_hz, td.onsets_s, gages, declared=declared)
    _print_findings("compared", td.onsets_s, dc)
    real = np.array([o for o in td.onsets_s if np.min(np.abs(blows - o)) <= a.tol])
    if real.size != td.onsets_s.size:
        _print_findings("blows only", real, check_trial(lt.x, lt.fs_hz, real, gages, declared=declared))
    else:
        print("every compared impact is a blow")


if __name__ == "__main__":
    main()
