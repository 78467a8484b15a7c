"""Issue 17: an early-less-late frequency shift is read as an amplitude-dependent stiffness only
where it grows with the blow (layers.shift_not_grown); one the same at every blow size is no
stiffness law and does not place an "unexplained" answer over a line the blows switch on."""

from __future__ import annotations

from ramdaq.analysis.gap.layers import answer, shift_not_grown


def _shift(gages: list[int], mode_hz: float, ratio: float, size: float, z: float) -> dict:
    return {"check": "homogeneity", "layer": "nonlinearity", "gages": gages, "window": "early",
            "mode_hz": [mode_hz], "statistic": 20.0 * ratio, "chance_level": 20.0, "closed_held": None,
            "more": {"stiffness_law_z": {"value": 8.7, "unit": "1"},
                     "frequency_change": {"value": size, "unit": "1"},
                     "shift_per_doubling": {"value": size / 100, "unit": "1"},
                     "shift_per_doubling_z": {"value": z, "unit": "1"}}}


# modal check seed 162003's pair: mains pickup at 60 Hz on gages 13, 14 (switched on by the
# blows, 2.37x), and the 23.13 Hz mode "3.0 % lower early" at 3.77x, its slope z -0.07
LINE = {"check": "line_persistence", "layer": "excitation", "gages": [13, 14], "window": "decay",
        "mode_hz": [60.0, 180.0, 300.0], "statistic": 2.37 * 9.0, "chance_level": 9.0,
        "closed_held": None, "more": {}}
FLAT = _shift([1, 2, 3, 6], 23.13, 3.77, -0.030, -0.07)
WHERE = {"gages": [4, 3], "window": "early", "band_hz": 84.5, "band_edges_hz": [48.3, 178.8]}


def test_a_shift_the_same_at_every_blow_size_does_not_place_the_answer_over_a_switched_line():
    assert shift_not_grown(FLAT)
    a = answer("unexplained", [], WHERE, set(), [FLAT, LINE])
    assert a.named == "unexplained" and a.by == "data" and a.location["gages"] == [13, 14]


def test_a_shift_that_grows_with_the_blow_still_answers_at_its_gages():
    # modal check seed 160005, a crack: 1.2 % lower early, z -4.43 in its own sense
    grown = _shift([1, 4, 8], 25.0, 3.77, -0.012, -4.43)
    assert not shift_not_grown(grown)
    assert answer("unexplained", [], WHERE, set(), [grown, LINE]).location["gages"] == [1, 4, 8]
    # a slope against the shift's sense is no growth either
    assert shift_not_grown(_shift([1, 4, 8], 25.0, 3.77, -0.012, +4.43))


def test_a_finding_without_the_slope_is_left_as_it_was():
    law = _shift([1, 4, 8], 25.0, 3.77, -0.012, 0.0)
    del law["more"]["shift_per_doubling_z"]
    assert not shift_not_grown(law) and not shift_not_grown(LINE)
