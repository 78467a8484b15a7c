"""ramdaq: data acquisition and live analysis for impact vibration trials of ship control
surfaces, after DTMB Report 1836.

The installed package's subpackages are the repository's top-level folders:
:mod:`ramdaq.drivers` (devices that stream blocks), :mod:`ramdaq.daq` (acquisition, trigger,
live session; :mod:`ramdaq.daq.commands` the command line), :mod:`ramdaq.analysis` (the physics
model, modal estimators, the report's equations, the gap diagnosis) and :mod:`ramdaq.rigs`
(the shipped rig files).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("ramdaq")
except PackageNotFoundError:  # imported from a source tree that was never installed
    __version__ = "0+unknown"
