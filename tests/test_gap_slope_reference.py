"""Issue 17: a mode's amplitude across the blows is read against the blow's level, the median of
the other modes' (homogeneity.reference_level), not against the best-measured mode, which may be
the one an amplitude-dependent stiffness acts on (modal check seed 161002: a rattle on the
13.3 Hz mode read as the 6.87 Hz hull mode's amplitude "as the blow to the power 2.91").
Plain numpy."""

from __future__ import annotations

import numpy as np

from ramdaq.analysis.gap.homogeneity import _slope, reference_level

BLOW = np.log(np.array([0.5, 0.7, 1.0, 1.4, 2.0, 2.8]))      # six blows, log of their size


def _logs(rng: np.random.Generator) -> dict[int, np.ndarray]:
    # mode 0, the best measured, limited by a stop: its amplitude as the blow^0.45; modes 1-4
    # linear, each at its own shape's scale; 1 % noise
    logs = {0: np.log(3.0) + 0.45 * BLOW}
    for k, scale in zip(range(1, 5), (0.2, 0.5, 1.1, 0.05), strict=True):
        logs[k] = np.log(scale) + BLOW
    return {k: v + 0.01 * rng.standard_normal(v.size) for k, v in logs.items()}


def test_the_stopped_mode_departs_and_the_linear_ones_do_not():
    logs = _logs(np.random.default_rng(0))
    se = np.full(BLOW.size, 0.01)
    b = {k: _slope(reference_level(logs, k, logs[0], 0), logs[k], se)[0] for k in logs}
    assert abs(b[0] - 0.45) < 0.05
    assert all(abs(b[k] - 1) < 0.05 for k in (1, 2, 3, 4))
    # against the best-measured mode, as before, every linear mode read as the blow^2.2
    assert abs(_slope(logs[0], logs[1], se)[0] - 1 / 0.45) < 0.1


def test_with_one_other_mode_the_best_measured_is_the_reference():
    logs = {k: v for k, v in _logs(np.random.default_rng(1)).items() if k in (0, 1)}
    assert reference_level(logs, 0, logs[0], 0) is None
    assert reference_level(logs, 1, logs[0], 0) is logs[0]
