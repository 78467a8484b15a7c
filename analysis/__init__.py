"""The analysis layer, numpy and scipy only: it imports neither :mod:`ramdaq.daq` nor
:mod:`ramdaq.drivers`, so it runs on arrays from anywhere.

:mod:`~ramdaq.analysis.model` (the rig file, the rudder-stock-hull model, its exact response,
sensors, gage geometry, units), :mod:`~ramdaq.analysis.modal` (decay estimators, order
selection, per-channel verdicts, the Cramér–Rao bound, the report's peak method),
:mod:`~ramdaq.analysis.report1836` (the report's chain and Table 2), :mod:`ramdaq.analysis.impact`
(one impact through all of it), :mod:`ramdaq.analysis.onset` (the trigger's pickers),
:mod:`~ramdaq.analysis.gap` (the sim-to-real gap diagnosis) and :mod:`~ramdaq.analysis.truth`
(the gap benchmark's truth simulator, which the diagnosis never imports). SI units throughout;
multi-channel signals are arrays with samples last, (n_channels, n_samples).
"""
