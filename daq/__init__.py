"""Acquisition: a device's blocks through the recorder (:mod:`~ramdaq.daq.recorder`, MCAP from
its own thread), the trigger (:mod:`~ramdaq.daq.trigger`), the analyzer
(:mod:`~ramdaq.daq.analyzer`) and the live views (terminal readout, Rerun), run together by
:mod:`~ramdaq.daq.session` for a live trial or a replay; :mod:`~ramdaq.daq.recover` salvages a
recording whose writer was killed. :mod:`~ramdaq.daq.commands` is the command line and the
commands that read recordings; :mod:`~ramdaq.daq.reports` their plots.
"""
