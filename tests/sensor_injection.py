"""Sensor effects injected outside the library, in plain numpy on the recorded values of a
simulated ALBACORE-in-water trial (six blows), written as another system's CSV export (values in
g) and brought back with ``ramdaq import``: the checks of issue 17's second "Done when" bullet.

Nothing here imports ``ramdaq.analysis.gap``: each effect is built from its physical description
alone (a gain, a delay of whole samples, a converter's limit, a tone, a first-order high-pass,
a second blow)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.signal

from ramdaq.analysis.model.rig import load_rig
from ramdaq.daq.commands.cli import main
from ramdaq.drivers.sim import SimDevice

RIGS = Path(__file__).resolve().parents[1] / "recordings" / "rigs"
IMPACTS = [3.0 + 5.0 * i for i in range(6)]
G = 9.80665
HULL = (5, 9, 13, 14, 15, 16)


@dataclass(frozen=True)
class Injected:
    """What was done: ``effect`` name, the ``gages`` (numbers) it touched, and its size."""

    effect: str
    gages: tuple[int, ...]
    size: float


def albacore_water():
    return load_rig(RIGS / "albacore.toml").with_medium("water")


def simulate(seed: int, noise: bool = True) -> tuple[np.ndarray, float, list[int]]:
    """The trial at its recorded rate, m/s^2 (n_gages, n), its rate (Hz) and each row's gage."""
    rig = albacore_water()
    dev = SimDevice(rig, seed=seed, duration_s=IMPACTS[-1] + 5, impacts=IMPACTS, pace="fast",
                    noise=noise)
    with dev:
        blocks = list(dev)
    x = np.concatenate([b.counts * b.scale[:, None] for b in blocks], axis=1)
    return x, blocks[0].fs_hz, [g.number for g in rig.gages_by_channel()]


def _rows(gages: list[int], which) -> list[int]:
    return [gages.index(g) for g in which]


def _gain(x, fs, gages, seed):
    y = x.copy()
    (r,) = _rows(gages, [3])
    y[r] *= 1.15
    return y, Injected("gain", (3,), 1.15)


def _skew(x, fs, gages, seed):
    y = x.copy()
    (r,) = _rows(gages, [6])
    y[r, 3:] = x[r, :-3]                           # this channel's samples 3 late
    return y, Injected("skew", (6,), 3 / fs)


def _clipping(x, fs, gages, seed):
    y = x.copy()
    (r,) = _rows(gages, [1])
    top = 0.5 * np.max(np.abs(x[r]))
    y[r] = np.clip(x[r], -top, top)
    return y, Injected("clipping", (1,), 0.5)


def _tone(x, fs, gages, seed):
    y = x.copy()
    t = np.arange(x.shape[1]) / fs
    k0 = int(IMPACTS[0] * fs)
    for r in _rows(gages, HULL):
        ring = np.max(np.abs(x[r, k0:k0 + int(2 * fs)]))    # the hull gage's ringing after a blow
        y[r] += 0.12 * ring * np.sin(2 * np.pi * 2.3 * t + r)
    return y, Injected("tone", HULL, 2.3)


def _highpass(x, fs, gages, seed):
    y = x.copy()
    rows = _rows(gages, [1, 2, 3, 4])
    b, a = scipy.signal.butter(1, 1.5, btype="highpass", fs=fs)
    y[rows] = scipy.signal.lfilter(b, a, x[rows], axis=1)
    return y, Injected("highpass", (1, 2, 3, 4), 1.5)


def _double_hit(x, fs, gages, seed):
    clean, _, _ = simulate(seed, noise=False)
    k = int(round(0.030 * fs))
    y = x.copy()
    y[:, k:] += 0.3 * clean[:, :-k]                # the ram back 30 ms later at 30 % of the blow
    return y, Injected("double_hit", tuple(gages), 0.030)


def _noisy(x, fs, gages, seed):
    y = x.copy()
    (r,) = _rows(gages, [10])
    y[r] += np.random.default_rng(seed + 100).normal(0.0, 3 * albacore_water().daq.noise_m_s2_rms,
                                                      x.shape[1])
    return y, Injected("noisy", (10,), 3.0)


def _dead(x, fs, gages, seed):
    y = x.copy()
    y[_rows(gages, [8])] = 0.0                     # a broken cable reads zero
    return y, Injected("dead", (8,), 0.0)


INJECT = {"gain": _gain, "skew": _skew, "clipping": _clipping, "tone": _tone,
          "highpass": _highpass, "double_hit": _double_hit, "noisy": _noisy, "dead": _dead,
          "none": lambda x, fs, gages, seed: (x.copy(), Injected("none", (), 0.0))}
"""Each effect: (x m/s^2, rate Hz, gage per row, seed) -> (a changed copy, what was done)."""


def inject(effect: str, x: np.ndarray, fs: float, gages: list[int], seed: int) -> tuple[np.ndarray, Injected]:
    """``x`` with one sensor effect applied (a copy)."""
    if effect not in INJECT:
        raise ValueError(f"unknown injected effect {effect!r}")
    return INJECT[effect](x, fs, gages, seed)


def write_csv(path: Path, x: np.ndarray, fs: float, gages: list[int]) -> None:
    """Another system's export: a time column (s) and one column per gage in g."""
    t = np.arange(x.shape[1]) / fs
    with open(path, "w") as f:
        f.write("# exported by another acquisition system\n")
        f.write("time (s)," + ",".join(f"g{g:02d} (g)" for g in gages) + "\n")
        np.savetxt(f, np.column_stack([t, x.T / G]), delimiter=",", fmt=["%.6f"] + ["%.8e"] * x.shape[0])


def injected_recording(tmp: Path, effect: str, seed: int = 7) -> tuple[Path, Injected]:
    """The trial with ``effect`` injected, exported as CSV and imported: the MCAP's path."""
    x, fs, gages = simulate(seed)
    y, what = inject(effect, x, fs, gages, seed)
    csv = tmp / f"{effect}.csv"
    write_csv(csv, y, fs, gages)
    rig = tmp / "rig.toml"
    rig.write_text(albacore_water().text)
    mcap = tmp / f"{effect}.mcap"
    if main(["import", str(csv), "--rig", str(rig), "--out", str(mcap)]) != 0:
        raise RuntimeError(f"ramdaq import refused {csv}")
    return mcap, what
