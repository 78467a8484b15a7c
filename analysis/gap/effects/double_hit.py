"""The ram bounced: a second contact after each blow, ``ratio`` of its peak force, ``delay_j``
after blow ``j`` -- every blow bounces its own way, so each impact has its own delay (a nuisance
found like its force: from its own segment). Seen in the early decay, as mode amplitudes and
phases that no single blow at the ram's point explains."""

from __future__ import annotations

import numpy as np

from .base import Effect, Placement, Term, placement

DELAY_RANGE_S = (0.004, 0.055)
"""Second contacts looked for: from just after a contact to where the trigger would see a new
blow."""
DELAY_TOL_S = 0.002
"""How far the refit may move a delay from the one the scan found (two steps of its grid)."""


SCAN_STEP_S = 0.001


def scan_delays(fw, fit) -> np.ndarray:
    """Each impact's most likely bounce delay (s), (n_seg,): the delay, on a 1 ms grid then a
    parabola through the best three, whose second contact best explains the impact's own
    segment's residual once its force and onset columns are projected out."""
    td = fw.td
    basis = fw.pulse_basis(fit.modes)
    own = [fw.pulse_response(fit.modes, td.seg_t0_s[j] - td.onsets_s[j], basis) for j in range(td.n_seg)]
    grid = np.arange(DELAY_RANGE_S[0], DELAY_RANGE_S[1] + SCAN_STEP_S / 2, SCAN_STEP_S)
    gain = np.zeros((td.n_seg, len(grid)))
    W = np.sqrt(fw.mask * fw.W**2)
    Q = []
    for j in range(td.n_seg):
        B = np.stack([(own[j][0] * W[j]).ravel(), (own[j][1] * W[j]).ravel()], axis=1)
        Q.append(np.linalg.qr(B)[0])
    r = np.nan_to_num(fit.resid) * W
    for i, d in enumerate(grid):
        for j in range(td.n_seg):
            u, _ = fw.pulse_response(fit.modes, td.seg_t0_s[j] - td.onsets_s[j] - d, basis)
            x = (u * W[j]).ravel()
            x -= Q[j] @ (Q[j].T @ x)
            nx, c = float(x @ x), float(x @ r[j].ravel())
            gain[j, i] = c * c / nx if nx > 0 and c > 0 else 0.0
    out = np.zeros(td.n_seg)
    for j in range(td.n_seg):
        i = int(np.argmax(gain[j]))
        d = 0.0
        if 0 < i < len(grid) - 1:
            y0, y1, y2 = gain[j, i - 1: i + 2]
            den = y0 - 2 * y1 + y2
            d = float(np.clip(0.5 * (y0 - y2) / den, -0.5, 0.5)) if den < 0 else 0.0
        out[j] = grid[i] + d * SCAN_STEP_S
    return out


def _placement(delays: np.ndarray, fitted: np.ndarray) -> Placement:
    """Parameters: the ratio and the fitted impacts' delays; a held-out impact keeps the delay
    its own segment's scan gave (the refit sees only fitted impacts), carried in the key."""
    d = delays[fitted]
    names = ("ratio",) + tuple(f"delay{j + 1}_s" for j in np.flatnonzero(fitted))
    lo = np.maximum(d - DELAY_TOL_S, 0.5 * DELAY_RANGE_S[0])
    return placement({"delays_ms": [round(1e3 * float(x), 2) for x in delays]}, names,
                     ("1",) + ("s",) * len(d), [0.0, *d], [0.0, *lo], [1.5, *(d + DELAY_TOL_S)],
                     [[0.1, *d]], window="early")


class DoubleHit(Effect):
    name = "double_hit"
    label = "double hit (ram bounce)"

    def placements(self, fw, fit) -> list[Placement]:
        return [_placement(scan_delays(fw, fit), fw.td.fitted)]

    def placement_after(self, fw, cal) -> Placement:
        # the calibration hides a bounce in a longer contact, and a scan against that model
        # finds the shortest delays; scanned again with the refit's constants, the term off
        return _placement(scan_delays(fw, fw.fit(cal.theta, [])), fw.td.fitted)

    def pulses(self, term: Term) -> list[tuple[np.ndarray, float]]:
        delays = 1e-3 * np.array(term.placement.key["delays_ms"])
        fitted = [int(n[5:-2]) - 1 for n in term.placement.names[1:]]
        delays[fitted] = term.x[1:]
        return [(delays, term.value("ratio"))]
