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
