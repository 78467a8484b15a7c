"""The homogeneity check's stiffness law is read across the blows at the same time after each blow
(issue 17: a modal split pair's beating read "its frequency rises by 1.4 % as its amplitude grows
within the decays"): two close linear modes beat the same way after every blow, whatever its
force, while an amplitude-dependent stiffness moves the frequency with the amplitude."""

from __future__ import annotations

import math

import numpy as np

from ramdaq.analysis.gap.homogeneity import STIFF_MIN, _law, _ols_slope, across_blows_slope

FS = 1024.0
N = int(2.0 * FS)
LEVELS = np.array([1.0, 0.5, 2.0, 0.7])
"""The blows' sizes (the benchmark's 4 blows, 0.5-2x)."""
NOISE = 1e-3
CHANCE = 4.0
"""About the two-sided normal quantile at 1e-3 Bonferroni over some ten slopes, as the check's."""


def _record(freq_of: callable, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Four decays, 3 s apart (0.5 s lead before each window), each ``freq_of(level, t)``'s
    signal, with white noise; returns the record and the windows' starts (samples)."""
    rng = np.random.default_rng(seed)
    lead = int(0.5 * FS)
    starts = lead + np.arange(LEVELS.size) * int(3 * FS)
    x = NOISE * rng.standard_normal(int(starts[-1] + N + lead))
    t = np.arange(-lead, N + lead) / FS
    for a, b in zip(starts, LEVELS, strict=True):
        x[a - lead:a + N + lead] += np.where(t >= -0.2, freq_of(b, np.maximum(t + 0.2, 0)), 0.0)
    return x, starts


def _split_pair(level: float, t: np.ndarray) -> np.ndarray:
    """Two linear modes 0.4 Hz apart near 19.4 Hz, the same ratio after every blow."""
    env = level * np.exp(-2 * math.pi * 19.4 * 0.004 * t)
    return env * (np.sin(2 * math.pi * 19.2 * t) + 0.6 * np.sin(2 * math.pi * 19.6 * t + 1.0))


def _softening(level: float, t: np.ndarray) -> np.ndarray:
    """One mode whose frequency falls by 4 % at the biggest blow's amplitude (a crack's
    softening): instantaneous frequency ``19.4 (1 - 0.04 A / A_max)``, phase integrated."""
    env = level * np.exp(-2 * math.pi * 19.4 * 0.004 * t)
    f = 19.4 * (1 - 0.04 * env / LEVELS.max())
    return env * np.sin(2 * math.pi * np.cumsum(f) / FS)


def test_a_split_pairs_beating_is_no_stiffness_law():
    x, starts = _record(_split_pair)
    law = _law(x, FS, 19.4, starts, N, 10 * NOISE, 1)
    assert law is not None and law.n_cycles > 40
    # the beating moves the band's frequency through each decay identically on every blow:
    # across the blows nothing is left beyond chance (measured |z| 0.5), nor a size to name
    assert abs(law.z_stiffness) < CHANCE and abs(law.df_rel) < STIFF_MIN, law


def test_pooled_cycles_would_read_the_beating_as_a_law():
    """The failure the across-blow reading mends, on the same record: the cycles pooled over the
    blows couple the frequency read to the beating envelope beyond chance."""
    x, starts = _record(_split_pair)
    from ramdaq.analysis.gap.homogeneity import _cycles

    u, y, c = [], [], []
    for a in starts:
        amp, freq = _cycles(x, FS, 19.4, int(a), N)
        ok = amp > 10 * NOISE
        n = int(np.argmin(ok)) if not ok.all() else amp.size
        u.append(amp[:n])
        y.append(freq[:n])
        c.append(np.arange(n))
    u, y, c = np.concatenate(u), np.concatenate(y), np.concatenate(c)
    _, z_pooled = _ols_slope(u / u.max(), y)
    _, z_across = across_blows_slope(u / u.max(), y, c)
    assert abs(z_pooled) > CHANCE > abs(z_across), (z_pooled, z_across)


def test_a_softening_mode_keeps_its_stiffness_law_across_blows():
    x, starts = _record(_softening)
    law = _law(x, FS, 19.4, starts, N, 10 * NOISE, 1)
    assert law is not None
    # a 4 % fall at the biggest amplitude: the law's change over the amplitudes read is 1-4 %
    assert law.z_stiffness < -CHANCE and law.df_rel <= -STIFF_MIN, law
