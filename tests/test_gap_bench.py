"""The gap benchmark's pipeline on a small fixed subset of its development scenarios: the richer
simulator's trial, written to MCAP by the recorder, diagnosed from the file and the nominal rig.
A regression guard for the whole chain (the benchmark's figures come from its own seeds, run by
``ramdaq gap benchmark``): each scenario here is one the development run identified."""

from __future__ import annotations

import pytest

from daq.gap_bench import _located, scenarios, score

SUBSET = [("none", 1001), ("hull_coupling", 2001), ("tiller", 5001), ("gage_alignment", 9005),
          ("time_skew", 11005)]


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    from daq.gap_bench import run_one

    pick = {(s["effect"], s["seed"]): s for s in scenarios(6, dev=True)}
    out = tmp_path_factory.mktemp("gap_bench")
    return [run_one(pick[key], str(out)) for key in SUBSET]


def test_subset_is_diagnosed(results):
    for r in results:
        assert "error" not in r, r.get("error")
        assert r["n_impacts_found"] == r["n_impacts_true"]
        if r["effect"] == "none":
            assert r["verdict"] == "no gap beyond noise"
            continue
        assert r["named"] == r["effect"], (r["effect"], r["named"], r["candidates"][:3])
        assert all(_located(r, r["location"]).values()), (r["location"], r["truth"])
        assert r["closed_held"] > 0.7


def test_score_counts_the_subset(results):
    thr = {e: 0.0 for e, _ in SUBSET}
    s = score(results, thr, 5.0, 10.0, 0.0)
    assert s["top1"] == 1.0 and s["false_alarms"] == 0.0 and s["n_above"] == 4
    assert s["confusion"]["time_skew"]["time_skew"] == 1
