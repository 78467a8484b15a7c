"""The live readout, on a (forced) terminal and in plain-line mode, fed by the real sim device."""

import io

import numpy as np
from rich.console import Console

from ramdaq.daq.readout import LiveReadout
from ramdaq.drivers.sim import SimDevice


def _feed(console, albacore):
    with SimDevice(albacore, duration_s=3.0, impacts=[1.0], seed=4) as dev:
        view = LiveReadout(dev.info, adc_bits=24, console=console)
        with view:
            for block in dev:
                view.update(block, impacts=[b.t_s for b in dev.delivered_impacts])
    return view


def test_terminal_table_shows_every_gage(albacore):
    out = io.StringIO()
    view = _feed(Console(file=out, force_terminal=True, width=200), albacore)
    text = out.getvalue()
    assert all(f"g{n:02d}" in text for n in range(1, 17))
    assert "impacts at 1.00 s" in text
    # peak of the loudest rudder gage after a 20 kN blow is metres per second squared, not noise
    assert view.peak.max() > 1.0 and view.clipped.sum() == 0


def test_plain_lines_every_two_seconds(albacore):
    out = io.StringIO()
    view = _feed(Console(file=out, force_terminal=False, width=300), albacore)
    lines = [ln for ln in out.getvalue().splitlines() if ln.startswith("t=")]
    assert len(lines) == 1 and "impacts 1" in lines[0]  # 3 s of stream: one line at t = 2 s
    # the 1 s rms window at the end covers samples 2..3 s: lower than the peak, above the floor
    assert np.all(view.rms > 0.5 * albacore.daq.noise_m_s2_rms)


def test_a_gage_the_final_does_not_use_loses_its_numbers_so_far(albacore):
    """A first look showed a noise-only gage's numbers "so far"; when the final does not use
    it, the table takes them off and says why (they stayed "so far" for the rest of the trial)."""
    out = io.StringIO()
    view = _feed(Console(file=out, force_terminal=True, width=200), albacore)
    view.set_result("g15", 24.612, 0.0312, final=False)
    view.set_result("g04", 24.503, 0.0581, final=True)
    view.set_unused("g15", "no decay")
    console = Console(file=io.StringIO(), force_terminal=True, width=200)
    console.print(view._table())
    text = console.file.getvalue()
    row15 = next(line for line in text.splitlines() if " g15 " in line)
    assert "not used: no decay" in row15 and "24.612" not in row15 and "0.0312" not in row15
    row4 = next(line for line in text.splitlines() if " g04 " in line)
    assert "24.503" in row4 and "final" in row4


def _table_text(view) -> str:
    console = Console(file=io.StringIO(), force_terminal=True, width=200)
    console.print(view._table())
    return console.file.getvalue()


def test_a_look_marks_a_gage_at_the_noise_level_unsure(albacore):
    """A new user saw g15/g16 at the noise level read '24.196 Hz, so far' like any other gage:
    each number so far carries its decrement's standard error, and one beyond 25 % says unsure."""
    view = _feed(Console(file=io.StringIO(), force_terminal=True, width=200), albacore)
    view.look(0.4, {"g04": (24.50, 0.0580, 0.0029), "g15": (24.20, 0.0385, 0.0310)})
    text = _table_text(view)
    row4 = next(line for line in text.splitlines() if " g04 " in line)
    row15 = next(line for line in text.splitlines() if " g15 " in line)
    assert "so far ±5%" in row4 and "unsure" not in row4
    assert "unsure ±81%" in row15


def test_without_a_terminal_a_look_prints_one_line_of_its_sure_gages(albacore):
    """Off a terminal (a log, CI) the first looks were never printed though the summary counted
    them: one line each, the median over the gages sure to 25 %, and how many were not."""
    out = io.StringIO()
    view = _feed(Console(file=out, force_terminal=False, width=300), albacore)
    view.look(0.45, {"g01": (13.01, 0.0950, 0.004), "g02": (13.03, 0.0990, 0.006),
                     "g03": (13.02, 0.0970, 0.005), "g16": (40.0, 0.01, 0.02)})
    line = out.getvalue().splitlines()[-1]
    assert line == ("  first look 0.45 s into the decay: f 13.020 Hz, delta 0.0970 "
                    "(median of 3 gages, 0.0950-0.0990); 1 unsure")


def test_plain_line_ranks_each_unit_on_its_own(albacore):
    """A load cell's newtons were listed under 'rms m/s^2' and ranked against the gages."""
    from dataclasses import replace

    out = io.StringIO()
    with SimDevice(albacore, duration_s=2.5, impacts=[1.0], seed=4) as dev:
        info = dev.info
        units = list(info.units)
        units[-1] = "N"
        view = LiveReadout(replace(info, units=tuple(units)), console=Console(file=out, width=300))
        with view:
            for block in dev:
                view.update(block)
    line = next(ln for ln in out.getvalue().splitlines() if ln.startswith("t="))
    accel, force = line.split("|")[1:]
    assert accel.strip().startswith("rms m/s^2: ") and info.channels[-1] not in accel
    assert force.strip().startswith(f"rms N: {info.channels[-1]} ")  # its level when printed (t = 2 s)


def test_the_result_column_says_which_hit_and_look_it_shows(albacore):
    """A new analyst could not tell which blow the f / delta columns belonged to while the next
    hit rang and the last one's final was pending; the column's head says it, a final keeps its
    standard error, and a first look's decrement <= 0 (no decay) is unsure whatever its error."""
    view = _feed(Console(file=io.StringIO(), force_terminal=True, width=200), albacore)
    view.clear_results("hit 2: ringing")
    assert "hit 2: ringing" in _table_text(view)
    view.look(0.42, {"g04": (24.50, 0.0580, 0.0029), "g12": (24.40, -0.1085, 0.0200)}, hit=2)
    text = _table_text(view)
    assert "hit 2: look 0.42 s in" in text
    row12 = next(line for line in text.splitlines() if " g12 " in line)
    assert "unsure ±18%" in row12  # 0.0200 / 0.1085: sure by its error, but not a decay
    # an error many times the decrement: one short cell, not '±1.6e+03%' across the table
    view.look(0.26, {"g12": (24.40, -0.0081, 0.13)}, hit=2)
    row12 = next(line for line in _table_text(view).splitlines() if " g12 " in line)
    assert "unsure ±>100%" in row12 and "e+" not in row12
    view.showing("hit 2: final")
    view.set_result("g04", 24.503, 0.0581, final=True, delta_se=0.0012)
    text = _table_text(view)
    row4 = next(line for line in text.splitlines() if " g04 " in line)
    assert "hit 2: final" in text and "final ±2.1%" in row4


def test_a_look_with_a_negative_decrement_is_left_out_of_the_plain_line(albacore):
    out = io.StringIO()
    view = _feed(Console(file=out, force_terminal=False, width=300), albacore)
    view.look(0.45, {"g01": (13.01, 0.0950, 0.004), "g02": (13.03, -0.0990, 0.006)})
    assert out.getvalue().splitlines()[-1].endswith("(median of 1 gage, 0.0950-0.0950); 1 unsure")


def test_plain_lines_of_its_own_console_are_what_rich_prints(albacore, capsys):
    """The readout's own console (no terminal) writes its plain lines without rich's pipeline:
    the same text as rich prints, also where rich would read a channel name as markup."""
    from dataclasses import replace

    with SimDevice(albacore, duration_s=4.5, impacts=[1.0], seed=4) as dev:
        info, blocks = dev.info, list(dev)
    marked = replace(info, channels=("g01[b]",) + tuple(info.channels[1:]))
    for stream_info in (info, marked):
        outputs = []
        for console in (None, Console(file=io.StringIO(), soft_wrap=True)):
            view = LiveReadout(stream_info, adc_bits=24, console=console)
            with view:
                for block in blocks:
                    view.update(block)
            outputs.append(capsys.readouterr().out if console is None else console.file.getvalue())
        assert outputs[0] == outputs[1] and outputs[0].count("\nt=") + outputs[0].startswith("t=") == 2
    assert "g01[b]" not in outputs[0]  # rich took "[b]" as markup: it printed the line
