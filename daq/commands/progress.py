"""Progress bars of the commands: ``rich.progress`` on stderr with the elapsed time and an ETA,
so that standard output keeps only the results (and a pipe reads them as before)."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager


@contextmanager
def progress_bar(description: str, total: float | None, *, show: bool | None = None,
                 unit: str = "", decimals: int = 0) -> Iterator[Callable[[float], None]]:
    """A bar over ``total`` steps (``None``: no bar, only the spinner and the time); yields
    ``advance(n=1)``, which moves it ``n`` steps on. Lines printed while it runs appear above
    it. ``unit`` follows the counts (``"MB"``, ``"hits"``). ``show``: default when standard
    error is a terminal (a log or a test's capture gets no bar); ``False``: nothing at all.
    ``decimals``: digits after the point of the counts shown (``1.4/3.2 MB``)."""
    if show is None:
        show = sys.stderr.isatty()
    if not show:
        yield lambda n=1: None
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        SpinnerColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    count = MofNCompleteColumn() if not decimals or total is None else \
        TextColumn(f"{{task.completed:.{decimals}f}}/{{task.total:.{decimals}f}}")
    cols = (SpinnerColumn(), TextColumn("{task.description}"), BarColumn(), count,
            TextColumn(unit), TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn())
    with Progress(*cols, console=Console(stderr=True), transient=False) as bar:
        task = bar.add_task(description, total=total)
        yield lambda n=1: bar.advance(task, n)


@contextmanager
def bytes_bar(description: str, total_bytes: int, *, show: bool | None = None
              ) -> Iterator[Callable[[int, int], None]]:
    """:func:`progress_bar` over a file read, in MB to one decimal (kB below 1 MB, where whole
    MB showed "0/0 MB"); yields ``update(bytes_read, total_bytes)`` (the signature of
    :func:`ramdaq.daq.recording.read_recording`'s ``progress``)."""
    big = total_bytes >= 1 << 20
    size, unit, decimals = (1 << 20, "MB", 1) if big else (1 << 10, "kB", 0)
    with progress_bar(description, round(total_bytes / size, decimals), show=show, unit=unit,
                      decimals=decimals) as advance:
        done = [0.0]

        def update(read: int, _total: int) -> None:
            now = round(read / size, decimals)
            advance(now - done[0])
            done[0] = now

        yield update
