"""A steady tone of the hull -- machinery, a pump, the dock (SAMPSON's 2.18 Hz) -- present before,
during and after every blow. Modelled as each hull mode driven at ``f`` (the gage pattern is the
model's frequency response to that drive), solved linearly with the impacts' forces; the
frequency is fitted. Two placements per line: *steady* -- one amplitude and phase per hull mode
over the whole trial, phase continuous in the trial's time -- or *wandering* -- its own amplitude
and phase around every impact (a sea or a machine whose tone drifts). The steady tone has far
fewer parameters, and a free amplitude per impact would also soak up the hull mode's own decay
where the tone sits on it (SAMPSON: both at 2.18 Hz), so the information criterion takes the
wandering one only when the tone really drifts.

Where it can sit: the lines standing out of the first impact's pre window -- before the first
blow nothing the model knows can ring, so a line there is the hull's own. (Later pre windows
carry earlier blows' ringing, which a tone would happily imitate.)"""

from __future__ import annotations

import math

import numpy as np

from ...model.response import ambient_gage_amplitudes
from ...model.structure import build_model
from .base import Effect, Placement, Term, placement, summed_spectrum


class AmbientTone(Effect):
    name = "ambient_tone"
    label = "persistent ambient tone"

    def placements(self, fw, fit) -> list[Placement]:
        hull = [g.number for g in fw.td.rig.gages_by_channel() if g.body == "hull"]
        out = []
        span = fw.td.seg_t0_s[-1] + fw.td.n_s / fw.td.fs_hz - fw.td.seg_t0_s[0]
        for f0 in first_quiet_lines(fw, 3):
            f = refine_line(fw, fit, f0)
            df = 3.0 / span            # the fit may move it a few bins of the whole trial
            for wander in (False, True):
                out.append(placement({"f_hz": round(f, 4), "wandering": wander}, ("f_hz",), ("Hz",),
                                     f, f - df, f + df, [[f]], gages=tuple(hull), mode_hz=f, window="pre"))
        return out

    def templates(self, fw, cal, pl) -> np.ndarray:
        cols = self._cols(fw, pl.x0[0], pl.key["wandering"])[:, fw.td.fitted]
        w = (fw.mask[fw.td.fitted] * fw.W[fw.td.fitted])[None]
        D = np.nan_to_num(cols * w).reshape(cols.shape[0], -1)
        return D[np.any(D != 0, axis=1)]

    def columns(self, fw, term: Term) -> np.ndarray:
        return self._cols(fw, term.value("f_hz"), term.placement.key["wandering"])

    def _cols(self, fw, f_hz: float, wander: bool) -> np.ndarray:
        td = fw.td
        key = ("ambient_patterns", round(f_hz, 9), wander)
        cache = fw.cache
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
                if not wander:
                    cols += [z.real, z.imag]
                    continue
                for s in range(td.n_seg):
                    zs = np.zeros_like(z)
                    zs[s] = z[s]
                    cols += [zs.real, zs.imag]
            cache[key] = np.stack(cols)
        return cache[key]


LINE_RATIO = 10.0
"""A line stands out when its bin is this many times the spectrum's median: a 1 s window summed
over 16 gages is a chi-square of ~32 degrees of freedom per bin (sd ~25 % of its mean)."""


def first_quiet_lines(fw, n: int) -> list[float]:
    """Up to ``n`` line frequencies (Hz) in the first segment's pre window, strongest first."""
    td = fw.td
    x = np.nan_to_num(td.x[0, :, td.windows.pre] * fw.W[0, :, td.windows.pre])
    m = x.shape[-1]
    if m < 16:
        return []
    f, P = summed_spectrum(x - x.mean(axis=-1, keepdims=True), td.fs_hz)
    ok = (f > 1.5 * td.fs_hz / m) & (f < td.lowpass_hz)
    ref = np.median(P[ok])
    idx = [i for i in np.flatnonzero(ok)[1:-1]
           if P[i] >= P[i - 1] and P[i] > P[i + 1] and P[i] > LINE_RATIO * ref]
    idx.sort(key=lambda i: -P[i])
    out: list[float] = []
    for i in idx:
        if all(abs(f[i] - o) > 1.5 * td.fs_hz / m for o in out):
            out.append(float(f[i]))
        if len(out) == n:
            break
    return out


def refine_line(fw, fit, f0: float) -> float:
    """The line near ``f0`` (Hz) read off the whole trial's residual, phase continuous over all
    segments: the peak of the summed periodogram over +-1.5 bins of the first pre window, on a
    grid of a fifth of a bin of the whole trial. A frequency off by a bin of the whole trial
    would put the tone out of phase with itself from one impact to the next."""
    td = fw.td
    m = td.windows.pre.stop - td.windows.pre.start
    half = 1.5 * td.fs_hz / max(m, 1)
    t = td.seg_t0_s[:, None] + np.arange(td.n_s)[None, :] / td.fs_hz      # (n_seg, n_s)
    span = t.max() - t.min()
    grid = np.arange(max(f0 - half, 0.2 * f0), f0 + half, 0.2 / span)
    r = np.nan_to_num(fit.resid * fw.W)                                       # (n_seg, n_g, n_s)
    tt = t.ravel()
    R = r.transpose(1, 0, 2).reshape(r.shape[1], -1)                         # (n_g, N)
    best, fbest = -1.0, f0
    for chunk in np.array_split(grid, max(1, len(grid) // 64)):
        E = np.exp(-2j * math.pi * chunk[:, None] * tt[None, :])              # (k, N)
        p = (np.abs(R @ E.T) ** 2).sum(axis=0)
        i = int(np.argmax(p))
        if p[i] > best:
            best, fbest = float(p[i]), float(chunk[i])
    return fbest
