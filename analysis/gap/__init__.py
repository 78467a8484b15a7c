"""Sim-to-real gap diagnosis: where the rig's model misses a trial, which unmodelled effect
causes it, and how far adding that effect closes the gap on held-out impacts.

:func:`ramdaq.analysis.gap.trialdata.prepare` cuts a trial into impacts,
:func:`ramdaq.analysis.gap.diagnose.diagnose` diagnoses it; the candidate effects are a registry
(:mod:`ramdaq.analysis.gap.effects`), one module each. The benchmark's richer simulator of trials
with a hidden effect is apart from the diagnosis, in :mod:`ramdaq.analysis.truth`.
"""
