"""A number the analysis cannot give (a NaN decrement) never stops a trial or a report: it is
written as null with its reason and everything else is still written (issue 22 item 1, issue 18).

The fault is injected from outside the analysis: a real hit of a sample recording, analysed by
the real chain, with one motion's decrement replaced by NaN -- as the 10-minute, 20-blow trial of
the issue gave for one hit's delta_gamma."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import pytest

from ramdaq.daq.analyzer import HitResult, finite_json, hit_to_json, trial_summary
from ramdaq.daq.commands.analyze import build_report, run_analysis

WATER = Path(__file__).resolve().parents[1] / "recordings" / "albacore-water.mcap"


@pytest.fixture(scope="module")
def hits() -> tuple:
    rig, hits = run_analysis(WATER)
    assert sum(h.accepted for h in hits) >= 2, "the sample recording's hits are accepted"
    return rig, hits


def _with_nan_gamma(hit: HitResult) -> HitResult:
    a = hit.analysis
    motions = dict(a.motions) | {"gamma": dataclasses.replace(a.motions["gamma"], delta=float("nan"))}
    return dataclasses.replace(hit, analysis=dataclasses.replace(a, motions=motions))


def test_table2b_leaves_a_nan_decrement_out_and_says_so(hits) -> None:
    _, hs = hits
    clean = hs[0].analysis.table2b()
    t = _with_nan_gamma(hs[0]).analysis.table2b()
    assert t["rows"]["gamma"] == {"delta": None, "deviation_pct": None}
    assert "gamma" in t["left_out"] and "nan" in t["left_out"]["gamma"]
    others = [clean["rows"][k]["delta"] for k in ("alpha", "v_2_6", "modal")]
    assert t["average"] == pytest.approx(sum(others) / 3, rel=1e-12)
    assert "left_out" not in clean


def test_a_hit_with_a_nan_is_valid_json_with_null(hits) -> None:
    _, hs = hits
    doc = hit_to_json(_with_nan_gamma(hs[0]))
    text = json.dumps(doc, allow_nan=False)        # raises on any NaN or infinity left
    assert json.loads(text)["analysis"]["motions"]["gamma"]["delta"] is None


def test_the_report_and_summary_are_written_with_a_nan_hit(hits) -> None:
    rig, hs = hits
    bad = [_with_nan_gamma(hs[0]), *hs[1:]]
    summary = trial_summary(bad)
    assert summary["accepted"] == sum(h.accepted for h in hs)
    # the NaN hit is left out of delta_gamma's mean, not of the others
    assert summary["delta_motion"]["gamma"]["n"] == summary["delta_motion"]["alpha"]["n"] - 1
    report = build_report(WATER, rig, bad)
    json.dumps(report, allow_nan=False)
    assert report["impacts"][0]["analysis"]["table2b"]["rows"]["gamma"]["delta"] is None


def test_finite_json_turns_every_non_finite_number_into_null() -> None:
    import numpy as np

    doc = {"a": float("nan"), "b": [np.float32("inf"), -np.inf, 1.5], "c": (np.int64(3), "x"),
           "d": {"e": np.float64(2.0), "f": True}}
    assert finite_json(doc) == {"a": None, "b": [None, None, 1.5], "c": [3, "x"],
                                "d": {"e": 2.0, "f": True}}


def test_a_summary_row_whose_hits_disagree_is_marked():
    """Three hits of one decrement: 0.05, 0.05, 0.08 with standard errors 0.001 cannot be one
    number (chi-square ~600 over 2 dof); with errors 0.02 they can (chi-square ~1.5, chance
    ~0.5). NaN values, and errors of NaN, count for neither."""
    from ramdaq.daq.analyzer import _mean_scatter

    tight = _mean_scatter([0.05, 0.05, 0.08, math.nan], [0.001, 0.001, 0.001, 0.001])
    loose = _mean_scatter([0.05, 0.05, 0.08], [0.02, 0.02, 0.02])
    assert tight["n"] == 3 and tight["p_agree"] < 1e-100
    assert 0.3 < loose["p_agree"] < 0.7
    assert _mean_scatter([0.05, 0.06], [math.nan, 0.01])["p_agree"] is None
