import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")   # as the ramdaq command sets it (daq/commands/cli.py)

import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import pytest

from ramdaq.analysis.model.rig import Rig, load_rig

RIGS = Path(__file__).resolve().parent.parent / "recordings" / "rigs"


@pytest.fixture(scope="session")
def albacore() -> Rig:
    return load_rig(RIGS / "albacore.toml")


@pytest.fixture(scope="session")
def sampson() -> Rig:
    return load_rig(RIGS / "sampson.toml")


def skip_unless_long_fuzz(request: pytest.FixtureRequest) -> None:
    """The 100 000-input fuzz runs go only with ``pytest -m slow`` or ``RAMDAQ_LONG_FUZZ=1``
    (the CI command runs every test, marked or not)."""
    expr = request.config.getoption("markexpr") or ""
    if os.environ.get("RAMDAQ_LONG_FUZZ") != "1" and ("slow" not in expr or "not slow" in expr):
        pytest.skip("long fuzz run: use pytest -m slow or RAMDAQ_LONG_FUZZ=1")


def tallied_long_run(request: pytest.FixtureRequest, capsys: pytest.CaptureFixture, tally: Counter,
                     unit: str) -> Iterator[Counter]:
    """Body of a long fuzz run's fixture: skip unless asked, clear the module's tally, hand it
    to the test and print what it counted (``yield from`` it in the module's fixture)."""
    skip_unless_long_fuzz(request)
    tally.clear()
    t = time.perf_counter()
    yield tally
    with capsys.disabled():
        print(f"\n{request.node.name}: {sum(tally.values())} {unit} in {time.perf_counter() - t:.0f} s: "
              f"{dict(tally)}")
