"""Friction in the stock's bearings: damping that depends on amplitude. A Coulomb force takes a
fixed amount of amplitude per second on top of the viscous decay, so a mode's envelope goes
``a(t) = (a0 + mu/sigma) e^{-sigma t} - mu/sigma`` (until it sticks) instead of
``a0 e^{-sigma t}``: the decrement grows as the ringing dies, and a harder blow decays
relatively slower. ``kappa = mu / (sigma a_mean)`` is the friction's size against the viscous
decay at the trial's mean blow."""

from __future__ import annotations

import numpy as np

from .base import Effect, Placement, Term, compared_modes, placement


class Friction(Effect):
    name = "friction"
    label = "amplitude-dependent (friction) damping"
    needs_force = True

    def placements(self, fw, fit) -> list[Placement]:
        return [placement({"mode_hz": round(f, 3)}, ("kappa",), ("1",), 0.0, 0.0, 5.0, [[0.05]],
                          mode_hz=f, window="late") for i, f in compared_modes(fw, fit)]

    def units(self, U, dU, ms, fw, force, term: Term):
        # U is the caller's own (Forward.unit_responses makes it for this): changed in place,
        # not copied -- a copy is (n_seg, n_seg, n_g, n_s), 77 MB for 20 impacts
        for j, change in self._changes(ms, fw, force, term):
            U[j] += change
        return U, dU

    def units_on_blocks(self, blocks, ms, fw, force, term: Term) -> bool:
        zero = None     # the derivative of a block only the friction writes (read, not changed)
        for j, change in self._changes(ms, fw, force, term):
            for s in range(j, fw.td.n_seg):
                b = blocks.get((j, s))
                if b is None:
                    if not change[s].any():
                        continue        # all zero, as the dense form's block: not alive
                    zero = np.zeros(change.shape[1:]) if zero is None else zero
                    b = blocks[(j, s)] = [np.zeros(change.shape[1:]), zero]
                b[0] += change[s]
        return True

    def _changes(self, ms, fw, force, term: Term):
        """Per impact ``j``, the friction's change of its unit response, (n_seg, n_g, n_s)."""
        kappa = term.value("kappa")
        if kappa == 0:
            return
        f0 = term.placement.mode_hz
        i = int(np.argmin(np.abs(ms.f_hz - f0)))
        sigma = max(-ms.lam[i].real, 1e-6)
        td = fw.td
        F = np.ones(td.n_seg) if force is None else np.abs(np.asarray(force, float))
        a0 = F / max(F.mean(), 1e-12)
        for j in range(td.n_seg):
            u = fw.mode_unit(ms, i, j)                                 # (n_seg, n_g, n_s)
            t = td.seg_t0_s[:, None] + np.arange(td.n_s)[None, :] / td.fs_hz - td.onsets_s[j]
            g = 1 + (kappa / max(a0[j], 1e-3)) * (1 - np.exp(np.minimum(sigma * np.clip(t, 0, None), 50.0)))
            g = np.clip(g, 0.0, 1.0)
            yield j, (g[:, None, :] - 1.0) * u
