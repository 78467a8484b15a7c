"""CPU cost of one hit's analysis, and where it goes.

Run:  python benchmarks/hit_cost.py [--hits 5] [--medium water|air] [--seconds 6 14] [--ragged]
      [--stages] [--accuracy SEEDS]

A simulated ALBACORE trial (16 gages, 2048 Hz, noise as the rig states, one blow per record) gives
``--hits`` records of free decay for each length in ``--seconds`` (6 s, and 14 s: the decays of
a 10-minute water recording, 20 blows, whose replay target of >= 100x real time leaves <= 0.2 s
a hit including everything; from 14 s on the NLS data are decimated by 2); each goes through
:func:`ramdaq.analysis.impact.analyze_decay` (what ``ramdaq analyze``, replay and the live
trial's finals run per hit). Printed: the median and largest CPU seconds per hit (one core,
single-threaded BLAS), and the median CPU of its parts run on their own: the per-gage verdicts
(:func:`~ramdaq.analysis.modal.verdicts.assess_decay`: one joint automatic-order fit, each
gage's verdict read from it; the channels it could not vouch for searched on their own, counted)
and the joint fit of all gages (:func:`~ramdaq.analysis.modal.identify.identify_modes`); then
the automatic order's cost against a fit of the order it found, given (``n_modes``), for the
16 gages and for one gage. The report's chain is what ``analyze_decay`` costs beyond
:func:`~ramdaq.analysis.modal.verdicts.assess_decay_jointly`, the fit it starts with (its motion
fits, Eq 4-13; the peak decrements; the stock lengths; the damping constants). Issue 19's
targets: a whole 16-gage hit in <= 0.2 s CPU at unchanged accuracy; automatic order no dearer
than 2x a fit of known order. ``--ragged`` gives the records arbitrary lengths, as a replay's
finals see them (12 288 and 28 672 samples are FFT-fast; a length with a large prime factor
is not, and a hit takes ~9 Kaiser periodograms of it and its parts). ``--stages``: where
analyze_decay's CPU goes, stage by stage (:func:`stage_split`). The machine is shared: the
figures grow with its load (printed).
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from ramdaq.analysis.impact import analyze_decay  # noqa: E402
from ramdaq.analysis.modal.identify import identify_modes  # noqa: E402
from ramdaq.analysis.modal.verdicts import assess_decay, assess_decay_jointly  # noqa: E402
from ramdaq.analysis.model.rig import load_rig  # noqa: E402
from ramdaq.drivers.sim import SimDevice  # noqa: E402

ONSET_S, DECAY_S, SKIP_S = 1.0, 6.0, 0.03


RAGGED_MAX = 600
"""``--ragged``: a record is up to this many samples longer than ``decay_s`` (0.3 s at 2048 Hz)."""


def records(medium: str, hits: int, decay_s: float = DECAY_S, ragged: bool = False
            ) -> tuple[object, list[np.ndarray], float, tuple[int, ...]]:
    """The rig, ``hits`` free decays (n_gages, n) of ``decay_s`` seconds in m/s^2, the rate (Hz)
    and the gage per row. ``ragged``: each record 1 to :data:`RAGGED_MAX` samples longer (drawn
    from its seed), as a replay's or a live trial's are (a record closes where its decay reaches
    the noise floor: its length is arbitrary, 28 672 = 2^12 x 7 samples the exception; the FFT
    of a length with a large prime factor costs several times more)."""
    rig = load_rig("albacore").with_medium(medium)
    out = []
    for seed in range(hits):
        extra = int(np.random.default_rng(seed).integers(1, RAGGED_MAX + 1)) if ragged else 0
        with SimDevice(rig, duration_s=ONSET_S + SKIP_S + decay_s + (RAGGED_MAX + 1) * ragged
                       / rig.daq.sample_rate_hz, impacts=[ONSET_S], seed=seed) as dev:
            x = np.hstack([b.values() for b in dev])
            gages = dev.info.gages
        fs = rig.daq.sample_rate_hz
        i0 = round((ONSET_S + SKIP_S) * fs)
        out.append(x[:, i0:i0 + round(decay_s * fs) + extra])
    return rig, out, fs, gages


def cpu(fn) -> float:
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hits", type=int, default=5, help="records (default 5)")
    ap.add_argument("--medium", choices=("water", "air"), default="water")
    ap.add_argument("--seconds", type=float, nargs="+", default=[DECAY_S, 14.0],
                    help="decay lengths, s (default 6 14)")
    ap.add_argument("--accuracy", type=int, default=0, metavar="SEEDS",
                    help="also the joint fit's decrements against the rig's over SEEDS records")
    ap.add_argument("--ragged", action="store_true",
                    help=f"records 1-{RAGGED_MAX} samples longer than --seconds, of arbitrary length "
                    "as a replay's are (the default lengths, 12 288 and 28 672, FFT fast)")
    ap.add_argument("--stages", action="store_true",
                    help="also where analyze_decay's CPU goes, stage by stage (stage_split)")
    args = ap.parse_args()
    for decay_s in args.seconds:
        report(args.medium, args.hits, decay_s, args.ragged, args.stages)
        if args.accuracy:
            accuracy(args.medium, args.accuracy, decay_s, args.ragged)


def accuracy(medium: str, seeds: int, decay_s: float, ragged: bool = False) -> None:
    """The joint fit's decrement of each of the rig's modes over ``seeds`` simulated decays
    (``ragged``: of arbitrary lengths, :func:`records`): its bias from the rig's decrement and
    its spread, both in units of the mean standard error the fit reports (the Cramér-Rao bound
    where the estimator is efficient, as the decrement benchmark shows it is): at the bound,
    spread / SE ~ 1 (sampling s.e. 1 / sqrt(2 (seeds - 1))) and |bias| / SE within
    ~2 / sqrt(seeds). The SE assumes white noise of the whole band's variance; the converter's
    roll-off makes the noise denser in the band by the fit's ``noise_colour`` (~1.3 on the
    record, ~1.1 on 14 s decays' data decimated within the band), so the bound for that noise
    is SE x sqrt(colour): the spread against it is printed too. The same for the modes of
    :func:`~ramdaq.analysis.impact.analyze_decay` (the final's: on the usable gages, and on a
    decay cropped to an FFT-fast length where it crops one)."""
    from ramdaq.analysis.model.rig_modes import modes_in

    rig, xs, fs, gages = records(medium, seeds, decay_s, ragged)
    truth = modes_in(rig, medium).table
    got = [identify_modes(x, fs, per_channel=False) for x in xs]
    colour = float(np.mean([t.info["noise_colour"] for t in got]))
    lengths = [x.shape[1] for x in xs]
    print(f"  accuracy over {seeds} records of {decay_s:g} s ({min(lengths)}-{max(lengths)} samples;"
          f" rig's modes; spread s.e. {1 / np.sqrt(2 * (seeds - 1)):.2f}; noise colour {colour:.2f}):")
    finals = [analyze_decay(x, fs, rig, gages, onset_s=ONSET_S, decay_start_s=ONSET_S + SKIP_S)
              for x in xs]
    used = [a.analysed_samples if getattr(a, "analysed_samples", None) else x.shape[1]
            for a, x in zip(finals, xs, strict=True)]
    for label, tables in (("joint fit of the whole record (identify_modes)", got),
                          (f"analyze_decay's modes ({sum(u < n for u, n in zip(used, lengths, strict=True))}"
                           f" of {seeds} records cropped, {100 * (1 - sum(used) / sum(lengths)):.2f} % "
                           "of the samples)", [a.modes for a in finals])):
        print(f"   {label}:")
        mode_accuracy(tables, truth, colour)
    motion_accuracy(finals, truth)


def mode_accuracy(tables: list, truth, colour: float) -> None:
    """Per mode of ``truth`` (the rig's): how often ``tables`` found it, and the bias and spread
    of their decrements in units of their mean standard error (:func:`accuracy`)."""
    seeds = len(tables)
    for f0, d0 in zip(truth.frequency_hz, truth.decrement, strict=True):
        d, se = [], []
        for t in tables:
            k = int(np.argmin(np.abs(t.frequency_hz - f0))) if len(t) else -1
            if k >= 0 and abs(t.frequency_hz[k] / f0 - 1) < 0.02:
                d.append(t.delta[k])
                se.append(t.delta_se[k])
        if len(d) < 2:
            print(f"    {f0:8.2f} Hz  delta {d0:.5f}: found in {len(d)} of {seeds}")
            continue
        d, se = np.array(d), float(np.mean(se))
        print(f"    {f0:8.2f} Hz  delta {d0:.5f}: found in {d.size} of {seeds}, bias "
              f"{(d.mean() - d0) / se:+.2f} SE (± {d.std(ddof=1) / np.sqrt(d.size) / se:.2f}), "
              f"spread / SE {d.std(ddof=1) / se:.2f}, / (SE sqrt(colour)) "
              f"{d.std(ddof=1) / (se * np.sqrt(colour)):.2f}")


def motion_accuracy(finals: list, truth) -> None:
    """Each motion signal's own decrement of the predominant mode (analyze_decay's motion fits,
    Eq 1-3b, 8, 10-13) over the records ``finals`` (their analyses): its spread, in units of
    the rig's decrement (to compare runs on the same seeds: a change of the estimator moves it
    by more than the Monte-Carlo noise only if it moves the estimates themselves), and against
    the mean standard error the fits report."""
    got: dict[str, list[tuple[float, float]]] = {}
    d0 = np.nan
    for a in finals:
        k = int(np.argmin(np.abs(truth.frequency_hz - a.modes.frequency_hz[a.predominant])))
        d0 = float(truth.decrement[k])
        for group in (a.motions, a.relative, a.hull_motions):
            for name, dec in group.items():
                got.setdefault(name, []).append((dec.delta, dec.delta_se))
    print(f"  motion fits' decrements of the predominant mode (rig's delta {d0:.5f}): "
          "name: found, bias / SE, spread (% of delta), spread / SE")
    cells = []
    for name, v in got.items():
        d, se = np.array(v).T
        d, se = d[np.isfinite(d)], float(np.nanmean(se))
        if d.size < 2:
            cells.append(f"{name}: found {d.size}")
            continue
        cells.append(f"{name}: {d.size}, {(d.mean() - d0) / se:+.2f}, "
                     f"{100 * d.std(ddof=1) / d0:.3f} %, {d.std(ddof=1) / se:.2f}")
    for i in range(0, len(cells), 3):
        print("    " + "; ".join(cells[i:i + 3]))


def report(medium: str, hits: int, decay_s: float, ragged: bool = False,
           stages: bool = False) -> None:
    """The figures for ``hits`` decays of ``decay_s`` seconds (``ragged``: :func:`records`)."""
    rig, xs, fs, gages = records(medium, hits, decay_s, ragged)
    lengths = sorted({x.shape[1] for x in xs})
    whole = [cpu(lambda x=x: analyze_decay(x, fs, rig, gages, onset_s=ONSET_S,
                                           decay_start_s=ONSET_S + SKIP_S)) for x in xs]
    verdicts = [cpu(lambda x=x: assess_decay(x, fs)) for x in xs]
    jointly = [cpu(lambda x=x: assess_decay_jointly(x, fs, band_decimation=True)) for x in xs]
    own = [assess_decay_jointly(x, fs, band_decimation=True).own_searches for x in xs]
    joint = [cpu(lambda x=x: identify_modes(x, fs, per_channel=True, band_decimation=True))
             for x in xs]
    print(f"ALBACORE in {medium}, {decay_s:g} s decays: {len(gages)} gages x "
          f"{'-'.join(str(n) for n in (lengths[0], lengths[-1])[:len(lengths)])} samples "
          f"at {fs:g} Hz, {hits} hits; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    print(f"  analyze_decay  median {np.median(whole):.3f} s CPU, max {np.max(whole):.3f} s (target 0.2)")
    print(f"  of which, run alone: verdicts (assess_decay) {np.median(verdicts):.3f} s "
          f"({np.mean(own):.1f} gage(s) a hit searched on their own), "
          f"joint fit (identify_modes, band_decimation as a final's) {np.median(joint):.3f} s")
    print(f"  the rest of analyze_decay after its verdicts (assess_decay_jointly {np.median(jointly):.3f} s):"
          f" per-gage peak decrements and the report's chain (motion fits, stock lengths, damping) "
          f"{np.median(np.subtract(whole, jointly)):.3f} s (a difference of runs: noisy under load)")
    auto_known(xs, fs)
    if stages:
        stage_split(rig, xs, fs, gages)


STAGES = (  # (module, public name as that module calls it, label); nested ones count in both
    ("ramdaq.analysis.impact", "assess_decay_jointly", "verdicts and joint fit (assess_decay_jointly)"),
    ("ramdaq.analysis.modal.identify", "kaiser_periodogram",
     "  Kaiser periodograms (band tests, NLS, search data)"),
    ("ramdaq.analysis.modal.verdicts", "peak_above_noise", "  each gage's band test"),
    ("ramdaq.analysis.modal.verdicts", "identify_modes", "  joint fit (identify_modes)"),
    ("ramdaq.analysis.modal.identify", "decimate_valid", "    decimations (NLS data, search copy, starts)"),
    ("ramdaq.analysis.modal.order", "ModeSelector.try_add", "    order search: candidates tried"),
    ("ramdaq.analysis.modal.order", "ModeSelector.prune", "    order search: pruning"),
    ("ramdaq.analysis.modal.order", "ModeSelector.refit", "    full refits (search's, the NLS data's)"),
    ("ramdaq.analysis.modal.identify", "fit_channels_varpro", "    16 single-gage fits (per_channel)"),
    ("ramdaq.analysis.impact", "identify_modes", "usable gages' refit (when a gage is left out)"),
    ("ramdaq.analysis.impact", "bandpass_rows", "peak decrements (gages and motions)"),
    ("ramdaq.analysis.impact", "decrements_from_peaks", "peak decrements (gages and motions)"),
    ("ramdaq.analysis.impact", "fit_signals_at_poles", "motion fits (Eq 4-13)"),
    ("ramdaq.analysis.impact", "table_amplitude_covariance", "amplitude covariance (Eq 14/15 SE)"),
    ("ramdaq.analysis.impact", "full_damping", "Eq 14/15 with standard errors"),
)


def stage_split(rig, xs: list[np.ndarray], fs: float, gages: tuple[int, ...]) -> None:
    """Median CPU a hit of each stage of :data:`STAGES` (a wrapper timing each call of that
    name where the module calls it; a stage nested in another counts in both), over ``xs``."""
    import importlib

    spent: dict[str, list[float]] = {label: [] for _, _, label in STAGES}
    now: dict[str, float] = {}
    saved = []
    for mod_name, name, label in STAGES:
        owner = importlib.import_module(mod_name)
        *path, name = name.split(".")  # "ModeSelector.try_add": a method, patched on its class
        for part in path:
            owner = getattr(owner, part)
        fn = getattr(owner, name)
        saved.append((owner, name, fn))

        def timed(*a, _fn=fn, _label=label, **k):
            t0 = time.process_time()
            try:
                return _fn(*a, **k)
            finally:
                now[_label] = now.get(_label, 0.0) + time.process_time() - t0

        setattr(owner, name, timed)
    whole = []
    try:
        for x in xs:
            now.clear()
            t0 = time.process_time()
            analyze_decay(x, fs, rig, gages, onset_s=ONSET_S, decay_start_s=ONSET_S + SKIP_S)
            whole.append(time.process_time() - t0)
            for label in spent:
                spent[label].append(now.get(label, 0.0))
    finally:
        for owner, name, fn in saved:
            setattr(owner, name, fn)
    print(f"  where analyze_decay's {np.median(whole):.3f} s CPU goes (median a hit of each stage, "
          "timed by wrappers: ~1 us a call more; nested stages indented):")
    for label, v in spent.items():
        print(f"    {label:58s} {1e3 * np.median(v):7.1f} ms")


def auto_known(xs: list[np.ndarray], fs: float) -> None:
    """Automatic order against the order it found, given: 16 gages jointly, and gage 4 alone."""
    for label, pick in (("16 gages jointly", lambda x: x), ("one gage (4)", lambda x: x[3])):
        auto, known = [], []
        for x in xs:
            y = pick(x)
            k = len(identify_modes(y, fs, per_channel=False))
            auto.append(cpu(lambda y=y: identify_modes(y, fs, per_channel=False)))
            known.append(cpu(lambda y=y, k=k: identify_modes(y, fs, per_channel=False,
                                                             n_modes=max(k, 1))))
        print(f"  {label}: automatic order {1e3 * np.median(auto):.1f} ms, order given "
              f"{1e3 * np.median(known):.1f} ms: {np.median(auto) / np.median(known):.1f}x "
              f"(target <= 2x)")


if __name__ == "__main__":
    main()
