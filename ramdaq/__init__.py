"""ramdaq: data acquisition and live analysis for impact vibration trials of ship control
surfaces, after DTMB Report 1836.

The installed package's subpackages are the repository's top-level folders:
:mod:`ramdaq.drivers` (devices that stream blocks), :mod:`ramdaq.daq` (acquisition, trigger,
live session; :mod:`ramdaq.daq.commands` the command line), :mod:`ramdaq.analysis` (the physics
model, modal estimators, the report's equations, the gap diagnosis) and :mod:`ramdaq.rigs`
(the shipped rig files).

The notebook API (:mod:`ramdaq.daq.recording`, :mod:`ramdaq.daq.api`), imported when first used
so that ``import ramdaq`` stays fast::

    rec = ramdaq.read_recording("recordings/albacore-water.mcap")   # Recording, SI values
    res = ramdaq.analyze(rec)            # TrialAnalysis; res.to_dataframe(), res.figures(0)
    gap = ramdaq.diagnose(rec)           # TrialDiagnosis; gap.to_dataframe(), gap.figures()

Importing ramdaq before NumPy sets ``OPENBLAS_NUM_THREADS=1`` (unless already set): the
estimators' numbers then equal the ``ramdaq`` command's to the last digit, and their many small
BLAS calls run faster on one thread (``docs/estimators.md``, "Threads").
"""

import os
import sys
from importlib import import_module
from typing import Any

if "numpy" not in sys.modules:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

_LAZY = {  # public name -> module that defines it
    "read_recording": "ramdaq.daq.recording", "Recording": "ramdaq.daq.recording",
    "RecordedEvent": "ramdaq.daq.recording",
    "analyze": "ramdaq.daq.api", "diagnose": "ramdaq.daq.api", "TrialAnalysis": "ramdaq.daq.api",
    "TrialDiagnosis": "ramdaq.daq.api", "ModeEstimate": "ramdaq.daq.api", "Candidate": "ramdaq.daq.api",
}

__all__ = ["__version__", *_LAZY]


def _version() -> str:
    """The installed distribution's version; ``importlib.metadata`` (~40 ms) is imported only
    when it is asked for (``--version``, a recording's header), not by every command."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("ramdaq")
    except PackageNotFoundError:  # imported from a source tree that was never installed
        return "0+unknown"


def __getattr__(name: str) -> Any:
    if name == "__version__":
        globals()[name] = value = _version()
        return value
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'ramdaq' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
