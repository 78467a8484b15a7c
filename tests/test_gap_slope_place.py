"""Issue 17: an "unexplained" answer is placed where the evidence is. A homogeneity slope across
the blows (a mode's amplitude not growing as the blow) is read against the best-measured mode,
so it does not say which of the two modes departs; a stiffness law the decays tell within each
blow reads one mode's own backbone, and places the answer (layers.slope_placed_by_law)."""

from __future__ import annotations

from ramdaq.analysis.gap.layers import answer


def _homogeneity(gages: list[int], mode_hz: float, ratio: float, more: dict) -> dict:
    return {"check": "homogeneity", "layer": "nonlinearity", "gages": gages, "window": "decay",
            "mode_hz": [mode_hz], "statistic": 3.8 * ratio, "chance_level": 3.8, "closed_held": None,
            "more": more}


# modal check seed 160002's pair (a crack on the 25.1 Hz mode, truth gages 1, 6, 8): the 7.26 Hz
# mode's amplitude "as the blow to the power 0.38" at 15.8x, the 25.0 Hz mode's frequency falling
# by 10 % as its amplitude grows within the decays at 2.03x
SLOPE = _homogeneity([3, 5, 7, 9, 10, 11, 12, 13, 14, 16], 7.26, 15.76,
                     {"amplitude_per_doubling": {"value": -0.62, "unit": "1"}})
LAW = _homogeneity([1, 2, 3, 4, 5, 6, 8, 9, 11, 12, 13, 14], 25.0, 2.03,
                   {"stiffness_law_z": {"value": -7.7, "unit": "1"},
                    "frequency_change": {"value": -0.10, "unit": "1"}})
WHERE = {"gages": [6], "window": "early", "band_hz": 22.2, "band_edges_hz": [12.6, 40.9]}


def test_a_told_stiffness_law_places_the_unexplained_answer_over_a_stronger_slope():
    a = answer("unexplained", [], WHERE, set(), [SLOPE, LAW])
    assert a.named == "unexplained" and a.by == "data"
    assert a.location["gages"] == LAW["gages"] and a.location["effect_mode_hz"] == 25.0
    assert a.finding["more"] == LAW["more"]


def test_a_slope_alone_or_beside_a_law_below_the_bar_still_answers_at_its_gages():
    assert answer("unexplained", [], WHERE, set(), [SLOPE]).location["gages"] == SLOPE["gages"]
    # a law below PRECEDENCE_STRENGTH answers nothing by itself, so it places nothing either
    weak = LAW | {"statistic": 3.8 * 1.5}
    assert answer("unexplained", [], WHERE, set(), [SLOPE, weak]).location["gages"] == SLOPE["gages"]


def test_coulombs_law_is_not_taken_for_the_place_of_an_unexplained_slope():
    # a Coulomb law names friction (a library effect) by its own rules; it does not relocate a
    # slope's "unexplained"
    coulomb = _homogeneity([1, 6, 8], 25.0, 2.03, {"coulomb_law_z": {"value": 7.7, "unit": "1"}})
    a = answer("unexplained", [], WHERE, set(), [SLOPE, coulomb])
    assert a.named == "friction"
