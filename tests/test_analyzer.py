"""Each hit accepted or rejected with its reason, on real simulated trials."""

import dataclasses

import numpy as np

from ramdaq.daq.session import Session
from ramdaq.drivers.array_device import ArrayDevice
from ramdaq.drivers.sim import Impact, SimDevice


def _run(rig, duration_s, impacts):
    dev = SimDevice(rig, duration_s=duration_s, impacts=impacts, seed=5)
    return Session(dev, readout=False).run()


def test_double_hit_and_short_decay_rejected(albacore):
    spec = albacore.impact
    second = Impact(3.08, spec.peak_force_N, spec.duration_s, spec.location_m)
    outcome = _run(albacore, 6.2, [3.0, second, 6.0])
    reasons = [h.reason for h in outcome.hits]
    assert len(outcome.hits) == 2, reasons
    assert reasons[0].startswith("double hit: second contact at 3.08")
    # the last blow leaves 0.2 s of stream: less than the 0.25 s a decrement needs
    assert reasons[1].startswith("decay too short")
    assert outcome.summary["accepted"] == 0 and set(outcome.summary["rejected"]) == {0, 1}


def test_overload_rejected(albacore):
    daq = dataclasses.replace(albacore.daq, adc_full_scale_V=0.02)  # rails at ~2 m/s^2
    outcome = _run(dataclasses.replace(albacore, daq=daq), 5.0, [3.0])
    (hit,) = outcome.hits
    assert not hit.accepted and hit.reason.startswith("overload: clipped on ")


def test_a_hit_whose_analysis_fails_stays_in_the_trial(albacore):
    """Three of the rig's gages only (1, 3, 5): the report's chain needs others and the
    analysis raises. The hit is rejected with the failure as its reason and counted, not lost
    (before: 'analyzer error on hit 0: 4' and 0 hits)."""
    with SimDevice(albacore, seed=3, duration_s=6.0, impacts=[3.0]) as sim:
        blocks, info = list(sim), sim.info
    counts, rows = np.hstack([b.counts for b in blocks]), [0, 2, 4]
    dev = ArrayDevice(counts[rows], blocks[0].scale[rows], info.fs_hz, gages=(1, 3, 5),
                      rig_toml=info.rig_toml, extra=info.extra)
    outcome = Session(dev, readout=False).run()
    (hit,) = outcome.hits
    assert outcome.summary["hits"] == 1 and round(hit.event.onset_s, 3) == 3.0
    assert hit.accepted or hit.reason.startswith("analysis failed: ")
