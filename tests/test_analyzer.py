"""Each hit accepted or rejected with its reason, on real simulated trials."""

import dataclasses

from ramdaq.daq.session import Session
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
