"""A gage's phase misfit read at a coupled hull mode is the coupling's complex shape, not a
channel fault (issue 17, modal development seed 59004): the model level's coupled mode answers."""

from __future__ import annotations

from ramdaq.analysis.gap.datamodel import Finding, Layer
from ramdaq.analysis.gap.layers import answer, phase_at_coupled

# modal development seed 59004: a hull mode at 28.47 Hz (zeta 0.020) coupled to the rudder at
# 14457x its chance level; the effect search's hull_coupling closes 54 % held out; the data
# layer read gage 2's phase off the others' at 7.1x its chance level on the 24.9 and 28.4 Hz modes
COUPLED = {"f_hz": 28.4697, "zeta": 0.0200, "hull_share": 0.914, "nonrigid": 0.215,
           "statistic": 43672.5, "chance_level": 3.0208, "gages": [5, 14, 13, 9]}
HULL = {"name": "hull_coupling", "dbic": -1.4e8, "closed_held": 0.543, "closed_fit": 0.543,
        "location": {"gages": [2, 4, 5, 1, 9, 11], "window": "pre", "band_hz": 33.244,
                     "effect_mode_hz": 29.096}}
FORM = {3, 4, 6, 12}


def _misfit(mode_hz: tuple[float, ...]) -> dict:
    return Finding(check="chain_misfit", layer=Layer.SENSOR, gages=(2,), statistic=122.954,
                   chance_level=17.34, size=111.5, unit="chi2/dof", window="decay", mode_hz=mode_hz,
                   text="gage 2's phase departs from the other gages'").to_json()


def test_a_phase_misfit_at_a_coupled_mode_gives_way_to_the_coupling():
    at = _misfit((24.866, 28.433))
    assert phase_at_coupled(at, [COUPLED])
    a = answer("hull_coupling", [HULL], None, FORM, [at], (), [], [COUPLED])
    assert a.named == "hull_coupling" and sorted(a.location["gages"]) == [5, 9, 13, 14]


def test_a_phase_misfit_off_the_coupled_modes_still_answers():
    # the same misfit read at modes 2 zeta f (1.14 Hz) or more from the coupled one, or on a
    # trial with no coupled mode: a phase no one delay fits, "unexplained" at gage 2
    off = _misfit((24.866, 30.0))
    assert not phase_at_coupled(off, [COUPLED])
    # (a coupled mode nearer its chance level than the misfit, 5x against 7.1x: a stronger one
    # answers before any weaker "unexplained", layers.coupled_over_data)
    weak = COUPLED | {"statistic": 5.0 * COUPLED["chance_level"]}
    a = answer("hull_coupling", [HULL], None, FORM, [off], (), [], [weak])
    assert a.named == "unexplained" and a.by == "data" and a.location["gages"] == [2]
    at = _misfit((24.866, 28.433))
    assert answer("hull_coupling", [HULL], None, FORM, [at], (), [], []).named == "unexplained"
    # only the phase misfit is set aside: a gain changing between impacts on the same gage stays
    drift = Finding(check="gain_invariance", layer=Layer.SENSOR, gages=(2,), statistic=200.0,
                    chance_level=22.1, size=0.3, unit="1", window="decay", mode_hz=(28.433,),
                    text="gage 2's gain changes between impacts").to_json()
    assert not phase_at_coupled(drift, [COUPLED])
    assert answer("hull_coupling", [HULL], None, FORM, [drift], (), [], [weak]).named == "unexplained"
