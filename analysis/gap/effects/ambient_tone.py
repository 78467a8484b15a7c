"""A steady tone of the hull -- machinery, a pump, the dock (SAMPSON's 2.18 Hz) -- present before,
during and after every blow. Modelled as each hull mode driven at ``f`` (the gage pattern is the
model's frequency response to that drive), one steady amplitude and phase per hull mode over the
whole trial (phase continuous in the trial's time), solved linearly with the impacts' forces;
the frequency is fitted. A free amplitude per impact would also soak up the hull mode's own
decay where the tone sits on it (SAMPSON: both at 2.18 Hz)."""

from __future__ import annotations

import math

import numpy as np

from analysis.gap.effects.base import Effect, Placement, Term, placement, residual_peaks
from analysis.model import build_model
from analysis.response import ambient_gage_amplitudes


class AmbientTone(Effect):
    name = "ambient_tone"
    label = "persistent ambient tone"

    def placements(self, fw, fit) -> list[Placement]:
        hull = [g.number for g in fw.td.rig.gages_by_channel() if g.body == "hull"]
        out = []
        for f in residual_peaks(fw, fit, ("pre",), 3):
            out.append(placement({"f_hz": round(f, 3)}, ("f_hz",), ("Hz",), f, 0.97 * f, 1.03 * f, [[f]],
                                 gages=tuple(hull), mode_hz=f, window="pre"))
        return out

    def templates(self, fw, cal, pl) -> np.ndarray:
        cols = self._cols(fw, pl.x0[0])[:, fw.td.fitted]
        w = (fw.mask[fw.td.fitted] * fw.W[fw.td.fitted])[None]
        D = np.nan_to_num(cols * w).reshape(cols.shape[0], -1)
        return D[np.any(D != 0, axis=1)]

    def columns(self, fw, term: Term) -> np.ndarray:
        return self._cols(fw, term.value("f_hz"))

    def _cols(self, fw, f_hz: float) -> np.ndarray:
        td = fw.td
        key = ("ambient_patterns", round(f_hz, 9))
        cache = fw.__dict__.setdefault("_effect_cache", {})
        if key not in cache:
            model = build_model(td.rig)
            gain = fw._filter_gain(np.array([2j * math.pi * f_hz]))[0]
            pats = [ambient_gage_amplitudes(model, k + 1, f_hz, 1e-4) * gain
                    for k in range(len(td.rig.hull_modes))]
            t = td.seg_t0_s[:, None] + np.arange(td.n_s)[None, :] / td.fs_hz
            ph = np.exp(2j * math.pi * f_hz * t)                       # (n_seg, n_s)
            cols = []
            for pat in pats:
                z = pat[None, :, None] * ph[:, None, :]
                cols += [z.real, z.imag]
            cache[key] = np.stack(cols)
        return cache[key]
