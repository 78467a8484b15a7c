"""Live terminal readout of a running acquisition: per-gage level, peak and clipping, with the
stream's health (blocks, gaps, recorder queue, overflows, impacts).

On a terminal it redraws a rich table in place; otherwise (CI, a log file) it prints one plain
line every ``every_s`` seconds of stream time.
"""

from __future__ import annotations

import re
from collections import deque
from typing import TYPE_CHECKING

import numpy as np
from rich.console import Console, Group

if TYPE_CHECKING:  # imported where used: only a terminal draws the live table
    from rich.live import Live

from ..drivers.block import Block, StreamInfo
from .analyzer import is_sure

_RICH_MARKS = re.compile(r"\[|:\S*?:")
"""What rich's ``print`` may read as markup (``[style]``) or an emoji code (``:name:``)."""


def accepted_line(index: int, onset_s: float, a, v_label: str = "v") -> str:
    """A hit's one-line headline once its final analysis is in: the predominant mode's
    frequency and decrement from the joint fit over every gage, each with its standard error,
    its damping ratio in %, the report's modal decrement (Eq 7: the mean over the rudder gages)
    and the decrement of the rudder's translation ``v`` (gages 2-6; ``w`` on a stern plane)
    where the layout has it. ``a`` is an :class:`~ramdaq.analysis.impact.ImpactAnalysis`."""
    m, k = a.modes, a.predominant
    d, d_se = float(m.delta[k]), float(m.delta_se[k])
    text = (f"hit {index} at {onset_s:.3f} s accepted: mode {k}, f = {a.f_hz:.3f} Hz "
            f"(se {float(m.frequency_se_hz[k]):.2g}), delta = {d:.4f} (se {d_se:.2g}), "
            f"zeta {100 * float(m.zeta[k]):.2f} %; delta_modal (Eq 7) = "
            f"{a.damping['delta_modal']:.4f}")
    v = a.motions.get("v_2_6")  # no motions on a channels-only rig
    if v is not None:
        text += f", delta_{v_label} (motion {v_label}) = {v.delta:.4f} (se {v.delta_se:.2g})"
    return text


class LiveReadout:
    """Accumulates per-channel statistics block by block and shows them.

    Parameters
    ----------
    info : StreamInfo
        The stream being shown.
    adc_bits : int or None
        ADC resolution, to count samples at the rails; ``None`` skips clip counting.
    window_s : float
        Window of the RMS level, seconds.
    every_s : float
        Plain-text mode: stream seconds between lines.
    """

    def __init__(self, info: StreamInfo, *, adc_bits: int | None = None, window_s: float = 1.0,
                 every_s: float = 2.0, console: Console | None = None) -> None:
        self.info = info
        self._own_console = console is None  # made here: plain lines may skip rich's pipeline
        self.console = console or Console(soft_wrap=True)
        self.tty = self.console.is_terminal
        self.rails = None if adc_bits is None else (-(2 ** (adc_bits - 1)), 2 ** (adc_bits - 1) - 1)
        n = info.n_channels
        self.peak = np.zeros(n)
        self.clipped = np.zeros(n, dtype=np.int64)
        self._sq: deque[tuple[int, np.ndarray]] = deque()
        self._window_n = max(1, round(window_s * info.fs_hz))
        self.samples = 0
        self.blocks = 0
        self.gaps = 0
        self.impacts: list[float] = []
        self.queue = 0
        self.overflows = 0
        self.results: dict[str, tuple[float, float, str]] = {}  # channel -> (f, delta, status)
        self.results_of = ""  # which hit and which look the f / delta columns show
        self._next_print = every_s
        self.every_s = every_s
        self._live: Live | None = None

    def __enter__(self) -> LiveReadout:
        if self.tty:
            from rich.live import Live  # here: a readout that prints plain lines never imports it

            self._live = Live(self._table(), console=self.console, refresh_per_second=4)
            self._live.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._live is not None:
            self._live.update(self._table())
            self._live.__exit__(None, None, None)
            self._live = None

    def update(self, block: Block, *, queue: int = 0, overflows: int = 0, gap: bool = False,
               impacts: list[float] | None = None) -> None:
        """Fold one block in and refresh the display."""
        # the peak from the counts' extremes (|c * s| = |c| * |s| exactly, and the largest |c|
        # gives the largest product), the clip count only where an extreme is at a rail, and
        # the squares in place: the same numbers for a third of the passes over the samples
        counts = block.counts
        hi, lo = counts.max(axis=1).astype(np.int64), counts.min(axis=1).astype(np.int64)
        self.peak = np.maximum(self.peak, np.maximum(hi, -lo) * np.abs(block.scale))
        if self.rails is not None and ((lo <= self.rails[0]) | (hi >= self.rails[1])).any():
            self.clipped += ((counts <= self.rails[0]) | (counts >= self.rails[1])).sum(1)
        x = block.values()
        self._sq.append((block.n_samples, np.square(x, out=x).sum(axis=1)))
        while sum(n for n, _ in self._sq) - self._sq[0][0] >= self._window_n:
            self._sq.popleft()
        self.samples += block.n_samples
        self.blocks += 1
        self.gaps += int(gap)
        self.queue, self.overflows = queue, overflows
        if impacts is not None:
            self.impacts = impacts
        if self._live is not None:
            self._live.update(self._table())
        elif self.samples / self.info.fs_hz >= self._next_print:
            self._next_print += self.every_s
            self._print_plain(self.line())

    def set_result(self, channel: str, f_hz: float, delta: float, final: bool,
                   delta_se: float = np.nan) -> None:
        """Show a gage's latest frequency (Hz) and decrement; ``final`` once the decay ended.
        ``delta_se``, the decrement's standard error, is shown beside "so far" or "final" in %
        of the decrement (a gage at the noise level reads a number with an error as large as
        itself: "unsure"; a decrement <= 0 is no decay and is "unsure" whatever its error)."""
        status = "final" if final else "so far"
        if np.isfinite(delta_se) and delta:  # short: an 80-column table
            if not final and not is_sure(delta, delta_se):
                status = "unsure"
            rel = 100 * abs(delta_se / delta)  # its SE, in % of it; beyond 100 % no number
            status = f"{status} ±{rel:.2g}%" if rel < 99.5 else f"{status} ±>100%"  # says more
        self.results[channel] = (f_hz, delta, status)
        self._refresh()

    def showing(self, text: str) -> None:
        """Say which hit (and which look of it) the f and delta columns show, e.g. "hit 2: look
        0.42 s in" or "hit 2: final"."""
        self.results_of = text
        self._refresh()

    def look(self, after_s: float, gages: dict[str, tuple[float, float, float]],
             hit: int | None = None) -> None:
        """Show a first look taken ``after_s`` seconds into a decay: each gage's (f Hz, δ, δ's
        standard error). On a terminal the table shows them; otherwise one plain line says
        the median frequency and decrement over the gages whose decrement is sure to
        :data:`UNSURE_REL_SE` (and positive), and how many were not. ``hit``, the blow's index,
        heads the table's result column."""
        if hit is not None:
            self.results_of = f"hit {hit}: look {after_s:.2f} s in"
        for name, (f, d, se) in gages.items():
            self.set_result(name, f, d, final=False, delta_se=se)
        if self._live is not None:
            return
        sure = [(f, d) for f, d, se in gages.values() if is_sure(d, se)]
        if not sure:
            return
        f_med, d_med = np.median(np.array(sure), axis=0)
        d_all = [d for _, d in sure]
        who = "  " if hit is None else f"  hit {hit}: "
        self.console.print(
            f"{who}first look {after_s:.2f} s into the decay: f {f_med:.3f} Hz, delta {d_med:.4f} "
            f"(median of {len(sure)} gage{'s' if len(sure) != 1 else ''}, "
            f"{min(d_all):.4f}-{max(d_all):.4f}); {len(gages) - len(sure)} unsure", highlight=False)

    def set_unused(self, channel: str, why: str) -> None:
        """The final analysis did not use this gage (``why``: its verdict, a few words): its
        numbers so far are taken off and the status says so."""
        self.results[channel] = (np.nan, np.nan, f"not used: {why}")
        self._refresh()

    def clear_results(self, text: str = "") -> None:
        """A new hit rings: the previous hit's per-gage numbers are no longer the ones shown;
        ``text`` says what the columns will show (:meth:`showing`)."""
        self.results.clear()
        self.results_of = text
        self._refresh()

    def hit(self, text: str) -> None:
        """Report a hit's status (detected, preliminary, accepted, rejected and why)."""
        # on a terminal too: printed above the live table, wrapped and kept in the scrollback
        # (the table's last lines alone cropped a long line and lost it at the next blow)
        self.console.print(text, highlight=False)
        self._refresh()

    def _print_plain(self, text: str) -> None:
        """``console.print(text, highlight=False)``; on the readout's own console (not wrapping,
        not recording) when it is no terminal, and for a printable ``text`` that rich would
        print as it is (no markup, no emoji code), written to the console's file as rich writes
        it (the line, a newline, a flush): a tenth of a millisecond a line less (the 300 lines
        of a 10-minute replay ~0.05 s). A console given by the caller is always rich's."""
        c = self.console
        if not self._own_console or self.tty or not text.isprintable() or _RICH_MARKS.search(text):
            c.print(text, highlight=False)
            return
        c.file.write(text + "\n")
        c.file.flush()

    def _refresh(self) -> None:
        if self._live is not None:
            self._live.update(self._table())

    @property
    def rms(self) -> np.ndarray:
        """RMS of each channel over the last ``window_s`` (SI units), shape (n_channels,)."""
        if not self._sq:
            return np.zeros(self.info.n_channels)
        n = sum(k for k, _ in self._sq)
        return np.sqrt(sum(s for _, s in self._sq) / n)

    def line(self) -> str:
        """One plain line: time, health and the three loudest channels of each unit (the
        accelerometers' m/s^2 and a load cell's N are not ranked against each other)."""
        t = self.samples / self.info.fs_hz
        clip = f", CLIPPED {int(self.clipped.sum())}" if self.clipped.any() else ""
        rms, units = self.rms, self.info.units
        parts = []
        for unit in dict.fromkeys(units):
            rows = [i for i, u in enumerate(units) if u == unit]
            loud = sorted(rows, key=lambda i: -rms[i])[:3]
            parts.append(f"rms {unit}: " + ", ".join(
                f"{self.info.channels[i]} {rms[i]:.3g}" for i in loud))
        return (f"t={t:7.2f} s  blocks {self.blocks}  gaps {self.gaps}  queue {self.queue}  "
                f"overflows {self.overflows}  impacts {len(self.impacts)}{clip}  |  "
                + "  |  ".join(parts))

    def _table(self) -> Group:
        from rich import box  # here, with Live: only a terminal draws the table
        from rich.table import Table
        from rich.text import Text

        t = self.samples / self.info.fs_hz
        health = (f"blocks {self.blocks}  gaps {self.gaps}  queue {self.queue}  "
                  f"overflows {self.overflows}  impacts at "
                  + (", ".join(f"{s:.2f}" for s in self.impacts[-3:]) or "-") + " s")
        # no outer edge: 16 gages, the last hits and the health line fit an 80 x 24 terminal
        table = Table(title=f"ramdaq  {self.info.device}  t = {t:.2f} s  "
                            f"({self.info.fs_hz:g} Hz, {self.info.n_channels} ch)",
                      box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False)
        table.add_column("gage", justify="right")
        table.add_column("rms (1 s)", justify="right")
        table.add_column("peak", justify="right")
        table.add_column("unit")
        table.add_column("clipped", justify="right")
        table.add_column("f (Hz)", justify="right")
        table.add_column("delta", justify="right")
        table.add_column(self.results_of or "result", justify="left")
        rms = self.rms
        for i, name in enumerate(self.info.channels):
            clip = str(int(self.clipped[i])) if self.clipped[i] else ""
            f, d, status = self.results.get(name, (np.nan, np.nan, ""))
            table.add_row(name, f"{rms[i]:.4g}", f"{self.peak[i]:.4g}", self.info.units[i],
                          f"[red]{clip}[/red]" if clip else "",
                          "" if not np.isfinite(f) else f"{f:.3f}",
                          "" if not np.isfinite(d) else f"{d:.4f}",
                          status)
        return Group(table, Text(health))
