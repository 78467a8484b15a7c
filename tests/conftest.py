import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")   # as the ramdaq command sets it (daq/cli.py)

from pathlib import Path

import pytest

from analysis.rig import Rig, load_rig

RIGS = Path(__file__).resolve().parent.parent / "recordings" / "rigs"


@pytest.fixture(scope="session")
def albacore() -> Rig:
    return load_rig(RIGS / "albacore.toml")


@pytest.fixture(scope="session")
def sampson() -> Rig:
    return load_rig(RIGS / "sampson.toml")
