"""Sim-to-real gap diagnosis: where the rig's model misses a trial, which unmodelled effect
causes it, and how far adding that effect closes the gap on held-out impacts.

:func:`analysis.gap.trialdata.prepare` cuts a trial into impacts, :func:`analysis.gap.diagnose.diagnose`
diagnoses it; the candidate effects are a registry (:mod:`analysis.gap.effects`), one module each;
:mod:`analysis.gap.truth` is the benchmark's richer simulator of trials with a hidden effect.
"""
