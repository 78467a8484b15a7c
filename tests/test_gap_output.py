"""What ``ramdaq gap`` prints and writes, as a new user read it: a held-out score of -inf on the
terminal, gap.json's verdict not the answer printed, labels overlapping in the map and ranking
plots. One small diagnosis (a 30 s ALBACORE-in-water trial of 6 blows held against the rig with
gage 4 placed 5 cm off, three candidate effects), read by every test here."""

from __future__ import annotations

import itertools
import json
import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.text import Text

from ramdaq.analysis.gap.diagnose import Settings
from ramdaq.daq.commands.cli import main
from ramdaq.daq.commands.gap import run_gap, summary_lines, write_report
from ramdaq.daq.reports.gap_plots import map_figure, ranking_figure

ALBACORE = Path(__file__).resolve().parents[1] / "recordings" / "rigs" / "albacore.toml"


@pytest.fixture(scope="module")
def moved(tmp_path_factory):
    """The diagnosis, its printed lines and its gap.json (what ``ramdaq gap`` prints and writes:
    the same functions)."""
    tmp = tmp_path_factory.mktemp("gapout")
    mcap = tmp / "t.mcap"
    assert main(["record", "--rig", "albacore", "--medium", "water", "--duration", "30",
                 "--impact-every", "5", "--seed", "0", "--fast", "--quiet", "--out", str(mcap)]) == 0
    text = ALBACORE.read_text()
    rig = re.sub(r"(number = 4\n(?:.*\n)??position_m = \[)0\.60,", r"\g<1>0.65,", text)
    assert rig != text
    (tmp / "moved.toml").write_text(rig.replace('medium = "air"', 'medium = "water"', 1))
    _, _, d = run_gap(mcap, rig=tmp / "moved.toml",
                      settings=Settings(effects=("gage_alignment", "clipping", "time_skew")))
    write_report(d, tmp / "g", plots=False)
    return d, summary_lines(d), json.loads((tmp / "g" / "gap.json").read_text())


def test_no_held_out_cell_is_said_in_words_never_as_minus_inf(moved):
    """New user: "the largest the held-out impacts reproduce z = -inf". No held-out cell is
    beyond chance here (the score is -inf by construction): the line says so in words."""
    d, lines, _ = moved
    assert d.z_detect == -np.inf                      # the case at hand
    line = next(ln for ln in lines if ln.startswith("  largest map cell z = "))
    assert "no cell reproduces on the held-out impacts (none of theirs beyond z 3)" in line, line
    assert not any(re.search(r"\b(-?inf|nan)\b", ln) for ln in lines), [
        ln for ln in lines if re.search(r"\b(-?inf|nan)\b", ln)]


def test_gap_json_verdict_is_the_answer_printed(moved):
    """New user: gap.json's verdict read "no gap beyond noise" (the map's) while the terminal
    answered from the data-only layer. Now it is the terminal's answer; the map's own verdict
    is ``map_verdict``."""
    d, lines, doc = moved
    verdict = next(ln for ln in lines if ln.startswith("verdict: "))
    assert doc["answer"]["by"] == "data"              # the case at hand: the data-only layer answered
    assert doc["verdict"] == "explained by the data-only layer: gage_alignment"
    assert verdict.removeprefix("verdict: ").lower().startswith(doc["verdict"].lower()), verdict
    assert doc["map_verdict"] == d.verdict == "no gap beyond noise"


def _overlaps(fig) -> list[tuple[str, str]]:
    """Every pair of visible, non-empty texts of ``fig`` whose boxes overlap (by more than a
    pixel), and every text in an axes that reaches out of it below (onto its tick labels)."""
    fig.set_canvas(FigureCanvasAgg(fig))
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    texts = [t for t in fig.findobj(Text) if t.get_visible() and t.get_text().strip()]
    boxes = [(t, t.get_window_extent(r).expanded(1.0, 1.0).padded(-1)) for t in texts]
    bad = [(a.get_text(), b.get_text()) for (a, ba), (b, bb) in itertools.combinations(boxes, 2)
           if ba.overlaps(bb)]
    for ax in fig.axes:
        for t in ax.texts:
            if t.get_window_extent(r).y0 < ax.get_window_extent(r).y0 - 0.5:
                bad.append((t.get_text(), "below its axes"))
    return bad


def test_the_map_and_ranking_plots_have_no_overlapping_labels(moved):
    """New user: the map's threshold labels sat on the colour bar's tick labels ("gap 8" on
    "8"), and the ranking's last "no score" row on its axis. Every text of both figures is
    now clear of every other."""
    d, _, _ = moved
    assert any(not np.isfinite(s.z) for s in d.signatures)    # a "no score" row is drawn
    for fig in (map_figure(d), ranking_figure(d)):
        assert _overlaps(fig) == []
