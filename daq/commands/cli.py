"""``ramdaq`` command line: thin -- it parses, builds a device and a recorder, runs, prints.

Commands: ``trial`` (record, detect hits, analyse and show them live), ``replay`` (a recording
through the same pipeline), ``analyze`` (the trial report), ``record`` (a device into an MCAP
file, with a live readout), ``info`` (what a recording holds), ``recover`` (a valid copy of a
recording whose writer was killed or whose bytes were damaged), ``rig`` (a rig's modes in air
and in water, and Eq 18 on them; ``rig fit`` tunes a rig's constants to a trial's identified
modes and writes the new rig), ``import`` (CSV, UFF 58, TDMS into MCAP), ``export-uff``
(modes and decays as UFF) and ``export-csv`` (every recorded sample as CSV).

Outputs: ``--name NAME`` writes ``recordings/NAME.mcap`` and cannot leave ``recordings/`` (no
absolute name, no ``..``); a rig's name used as the default is reduced to letters, digits,
``-`` and ``_``. Only an explicit path (``--out``, ``--rrd``, ``--json``, ``-o``) writes
elsewhere. Before anything is opened for writing, every refusal is checked: an existing output
without ``--overwrite``, an output folder that cannot be written, a Rerun port that is taken.

Exit codes::

    0    done (also a recording or trial ended by Ctrl-C or SIGTERM: its files are finished)
    1    bad input or a failure at run time, in one line on stderr: a file that is missing,
         unreadable, damaged or not a recording, an output that exists or cannot be written, a
         taken port, a device that failed or vanished (after the trial's summary)
    2    usage: arguments argparse rejects
    3    internal error (a bug): one line, and the traceback with ``--debug``
    130  interrupted (Ctrl-C or SIGTERM) in a command with nothing to finish

SIGTERM is handled like Ctrl-C: the recording and the ``.rrd`` get their footers. The reader of
standard output going away (``ramdaq info FILE | head``) ends the command quietly, with 1.
"""

from __future__ import annotations

import os

# one BLAS thread per process, set before numpy loads: the estimators make thousands of small
# BLAS calls that threads only slow down (5-10x, measured), and a live trial and its replay
# must run with the same setting to give the same digits (analysis/modal/identify.py, "Threads")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import re  # noqa: E402
import signal  # noqa: E402
import sys  # noqa: E402
import threading  # noqa: E402
import traceback  # noqa: E402
from collections.abc import Callable, Iterator  # noqa: E402
from pathlib import Path  # noqa: E402

from ...analysis.model.rig import Rig, RigError, load_rig, parse_rig
from ...analysis.model.surface import Surface
from ...drivers.errors import DeviceError
from ..errors import RecordingError, ViewError
from .gap_sizes import BLOWS, MIN_BLOWS, PER_CLASS, SEED_SETS

RECORDINGS = Path("recordings")
DESCRIPTION = """\
Impact vibration trials of ship rudders and stern planes (after DTMB Report 1836): record 16
accelerometers while a ram strikes, find each blow, and give every gage's frequency and
logarithmic decrement, the rudder's damping constants and virtual mass -- live, and again from
the recording.

  ramdaq trial --rig albacore --duration 30 --impact-every 10 --name demo    a simulated trial
  ramdaq analyze recordings/albacore-water.mcap                               the trial report
  ramdaq gap recordings/sampson-water.mcap                                    model against trial
"""

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2  # argparse's own
EXIT_INTERNAL = 3
EXIT_INTERRUPTED = 130

# what a user can cause and read a one-line message about; anything else is a bug
_FAILURES = (RigError, DeviceError, RecordingError, ViewError, OSError, ValueError, KeyError)


REPLAY_JOIN_S = 1.0
"""``ramdaq replay`` flat out with no view: recorded blocks joined into blocks of up to this
many seconds (:class:`~ramdaq.drivers.mcap_replay.McapReplayDevice`'s ``join_s``)."""


def _parse_impacts(text: str) -> list[float]:
    try:
        return [float(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--impacts {text!r}: expected seconds separated by commas, e.g. 1,4.5,8") from None


def _plot_spec(text: str) -> str:
    """An argparse type: ``--plots`` kinds that exist (a usage error, exit 2, names the known)."""
    from .analyze import plot_kinds

    try:
        plot_kinds(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err).removeprefix(f"--plots {text!r}: ")) from None
    return text


def _positive(text: str) -> float:
    """An argparse type: a finite number above zero (seconds, Hz)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text!r}: must be a number above 0")
    return value


def cmd_record(args: argparse.Namespace) -> int:
    from ...drivers.registry import open_device
    from ..record import record

    options, default_name = _device_options(args)
    out = _recording_path(args, default_name)
    _check_outputs([out], args.overwrite)
    _make_folders([out])
    device = open_device(args.device, **options)
    print(f"recording {device.info.device} ({device.info.n_channels} ch at "
          f"{device.info.fs_hz:g} Hz) into {out}; Ctrl-C ends it cleanly", flush=True)
    try:
        # the device's faults as they come, on standard output as a trial's are: standard
        # error holds only the one line of a failure
        s = record(device, out, readout=not args.quiet, overwrite=args.overwrite,
                   say=lambda line: print(line, flush=True))
    except DeviceError as err:  # the recorder finished the file before this got here
        raise DeviceError(f"{err}; {out} holds what came before, finished") from err
    print(f"{'interrupted: ' if s.interrupted else ''}wrote {out}: {s.duration_s:.2f} s, "
          f"{s.blocks} blocks, {s.samples * device.info.n_channels:,} samples, {s.gaps} gaps, "
          f"{s.overflows} overflows, {s.impacts} impacts, in {s.wall_s:.1f} s wall time")
    if s.faults:
        print(s.faults)
    return EXIT_OK


def cmd_info(args: argparse.Namespace) -> int:
    from .info import describe_recording, format_info

    d = describe_recording(args.file)
    print(json.dumps(dataclasses.asdict(d), indent=2, default=str) if args.json else format_info(d))
    return EXIT_OK


def cmd_recover(args: argparse.Namespace) -> int:
    from ..recover import recover

    src = Path(args.file)
    dst = Path(args.out) if args.out else src.with_name(src.stem + ".recovered.mcap")
    report = recover(src, dst)
    print(f"recovered {dst}: {report}")
    return EXIT_OK


SIM_DURATION_S = 10.0
"""A simulated trial's length without ``--duration``, s."""
MAX_SIM_FS_HZ = 51_200.0
"""Highest simulated rate, Hz: the trigger's (:mod:`ramdaq.daq.trigger`, 50 Hz to 51.2 kHz)."""


def _sim_options(args: argparse.Namespace, pace: str) -> tuple[dict, str]:
    """Device options and a default recording name for ``--device sim``."""
    if not args.rig:
        raise SystemExit(f"ramdaq {args.command}: --rig is required with --device sim")
    rig = load_rig(args.rig)
    if args.medium:
        rig = rig.with_medium(args.medium)
    duration = SIM_DURATION_S if args.duration is None else args.duration
    if args.impacts and args.impact_every:
        raise ValueError("--impacts and --impact-every: give one (the blows at the times listed, "
                         "or one every so many seconds), not both")
    late = [t for t in args.impacts or [] if not 0 <= t < duration]
    if late:
        raise ValueError(f"--impacts {', '.join(f'{t:g}' for t in late)} s: outside the "
                         f"{duration:g} s trial (--duration)")
    if args.fs is not None and args.fs > MAX_SIM_FS_HZ:
        raise ValueError(f"--fs {args.fs:g} Hz: above the {MAX_SIM_FS_HZ:g} Hz the trigger runs at")
    impacts = list(args.impacts or [])
    if args.impact_every:
        t = args.impact_every / 2
        while t < duration:
            impacts.append(t)
            t += args.impact_every
    return (dict(rig=rig, seed=args.seed or 0, duration_s=duration, impacts=impacts, pace=pace,
                 fs_hz=args.fs), f"{rig.name}-{rig.medium}")


def _device_options(args: argparse.Namespace) -> tuple[dict, str]:
    """Options for ``open_device(args.device, ...)`` and the default recording name (made safe
    for a file name); nothing is opened."""
    options: dict = {}
    default_name = "trial"
    if args.device == "sim":
        options, default_name = _sim_options(args, "fast" if args.fast else "realtime")
        return options, safe_name(default_name)
    given = [opt for opt, v in (("--medium", args.medium), ("--duration", args.duration),
                                ("--impacts", args.impacts), ("--impact-every", args.impact_every),
                                ("--seed", args.seed), ("--fs", args.fs), ("--fast", args.fast))
             if v not in (None, False)]
    if given:
        raise ValueError(f"{', '.join(given)}: for the simulator (--device sim) only; "
                         f"--device {args.device} gives its own")
    if args.rig:
        if "://" not in args.device:  # a recording or another system's file carries its rig
            raise ValueError(f"--rig: --device {args.device} is a file that carries its own rig; "
                             "--rig is for sim, can:// and serial:// devices")
        options = {"rig": args.rig}
    return options, safe_name(default_name)


def safe_name(text: str) -> str:
    """``text`` (a rig's name) as a file name: runs of anything but ASCII letters, digits, ``-``
    and ``_`` become one ``_``; ``"trial"`` if nothing is left."""
    return re.sub(r"[^A-Za-z0-9_-]+", "_", text).strip("_") or "trial"


def _recording_path(args: argparse.Namespace, default_name: str) -> Path:
    """``--out`` as given, else ``recordings/NAME.mcap``; a ``--name`` that would leave
    ``recordings/`` (absolute, ``..``) is refused."""
    if args.out:
        return Path(args.out)
    name = default_name if args.name is None else args.name
    path = RECORDINGS / f"{name}.mcap"
    inside = path.resolve().is_relative_to(RECORDINGS.resolve())
    if not name or Path(name).is_absolute() or ".." in Path(name).parts or not inside:
        raise ValueError(f"--name {name!r}: a recording name, not a path; it must stay inside "
                         f"{RECORDINGS}/ (--out takes a path)")
    return path


def _check_outputs(paths: list[Path | None], overwrite: bool) -> None:
    """Refuse an output that exists (without ``overwrite``) or is a folder, or whose folder
    cannot be written -- all before anything is opened for writing."""
    for path in filter(None, paths):
        if path.is_dir():
            raise IsADirectoryError(21, "is a folder; an output file was expected", str(path))
        if path.exists() and not overwrite:
            raise FileExistsError(f"{path} exists; --overwrite replaces it")
        folder = next(p for p in path.absolute().parents if p.exists())
        if not folder.is_dir():
            raise NotADirectoryError(20, f"{folder} is not a folder", str(path))
        if not os.access(folder, os.W_OK | os.X_OK):
            raise PermissionError(13, f"cannot write into {folder}", str(path))


def _make_folders(paths: list[Path | None]) -> None:
    for path in filter(None, paths):
        path.parent.mkdir(parents=True, exist_ok=True)


def _check_ports(args: argparse.Namespace) -> None:
    if getattr(args, "web", False):
        from ..rerun_view import check_ports

        try:
            check_ports(args.web_port, args.grpc_port)
        except ViewError as err:
            raise ViewError(f"{err}; --web-port and --grpc-port choose others") from err


def _run_session(device, args: argparse.Namespace, record_path: Path | None, rrd: Path | None):
    from ..session import Session

    view = None
    if rrd is not None or args.web:
        from ..rerun_view import RerunView

        view = RerunView(device.info, rrd_path=rrd, serve_web=args.web, web_port=args.web_port,
                         grpc_port=args.grpc_port)
        if args.web:
            print(f"Rerun web viewer: {view.web_url}", flush=True)
    try:
        outcome = Session(device, record_path=record_path, overwrite=args.overwrite, view=view,
                          readout=False if args.quiet else None,
                          log=print).run()
    finally:
        if view is not None:
            view.close()
    return outcome


def _print_outcome(outcome, args: argparse.Namespace, rig_toml: str = "") -> None:
    """The trial summary on the terminal, its motions named as the stream's rig names them
    (``rig_toml``), and, with ``--json``, the per-hit results in a file."""
    from .analyze import json_default, motions_not_used, summary_table

    surface = parse_rig(rig_toml, "rig").surface if rig_toml else Surface()
    for k, why in outcome.summary["rejected"].items():
        print(f"hit {k} rejected: {why}")
    print("\n".join(summary_table(surface.relabel(outcome.summary), args.units)
                    + motions_not_used(outcome.results_json(), outcome.summary)))
    load = outcome.load
    print(f"analyzer: {load.looks_shown} first looks shown while ringing, {load.looks_skipped} "
          f"skipped because it was busy; {load.finals_coarse} final(s) coarse, "
          f"{load.finals_unanalysed} not analysed (no samples skipped)")
    if args.json:
        Path(args.json).write_text(json.dumps(outcome.results_json(), indent=1,
                                              default=json_default))


def _stream_result(outcome, args: argparse.Namespace) -> int:
    """1 (with the reason on stderr) if the device failed or vanished before the stream's end."""
    for note in outcome.notes:
        print(f"ramdaq {args.command}: the device ended the stream: {note}", file=sys.stderr)
    return EXIT_FAILED if outcome.notes else EXIT_OK


def _import_live(view: bool) -> None:
    """Import what a live session loads when it starts (the session, its recorder and, with
    ``view``, the Rerun view), before the device opens: a device streams from its opening, and
    imports after it (scipy.signal for the recorder's trace ~0.5 s, Rerun's SDK) delay the first
    read -- an adapter silent for 0.3 s after opening would not be reported as such."""
    from ..recorder import Recorder  # noqa: F401
    from ..session import Session  # noqa: F401

    if view:
        from ..rerun_view import RerunView  # noqa: F401


def cmd_trial(args: argparse.Namespace) -> int:
    from ...drivers.registry import open_device

    options, default_name = _device_options(args)
    out = _recording_path(args, default_name)
    rrd = None if args.no_rerun else (Path(args.rrd) if args.rrd else out.with_suffix(".rrd"))
    outputs = [out, rrd, Path(args.json) if args.json else None]
    _check_outputs(outputs, args.overwrite)
    _check_ports(args)
    _make_folders(outputs)
    _import_live(view=rrd is not None or args.web)
    device = open_device(args.device, **options)
    print(f"trial: {device.info.device} ({device.info.n_channels} ch at {device.info.fs_hz:g} Hz)"
          f" recording into {out}" + (f", Rerun view into {rrd}" if rrd else "")
          + "; Ctrl-C ends it cleanly", flush=True)
    outcome = _run_session(device, args, out, rrd)
    print(f"{'interrupted: ' if outcome.interrupted else ''}wrote {out}"
          + (f" and {rrd}" if rrd else ""))
    _print_outcome(outcome, args, device.info.rig_toml)
    return _stream_result(outcome, args)


def cmd_replay(args: argparse.Namespace) -> int:
    from ...drivers.mcap_replay import McapReplayDevice

    rrd = Path(args.rrd) if args.rrd else None
    outputs = [rrd, Path(args.json) if args.json else None]
    _check_outputs(outputs, args.overwrite)
    _check_ports(args)
    _make_folders(outputs)
    # flat out with no view: no first looks (Session's default), so the recorded blocks may come
    # joined into longer ones -- the same samples and events, a twentieth of the per-block CPU
    flat_out = not args.realtime and rrd is None and not args.web
    device = McapReplayDevice(args.file, pace="realtime" if args.realtime else "fast",
                              join_s=REPLAY_JOIN_S if flat_out else 0.0)
    print(f"replaying {args.file} ({'real time' if args.realtime else 'as fast as possible'})",
          flush=True)
    outcome = _run_session(device, args, None, rrd)
    _print_outcome(outcome, args, device.info.rig_toml)
    return _stream_result(outcome, args)


def cmd_analyze(args: argparse.Namespace) -> int:
    from ..recording import recorded_rig
    from .analyze import check_air_twin, format_summary, plot_kinds, run_analysis, write_analysis

    src = Path(args.file)
    out = Path(args.out) if args.out else src.with_name(src.stem + "_analysis")

    def progress_of(path: Path) -> Callable[[str], None]:
        """Progress lines, named by file when there are two (``--air``)."""
        return lambda msg: print(f"{path.name}: {msg}" if args.air else msg, flush=True)

    plots = plot_kinds(args.plots, off=args.no_plots)  # checked before the analysis
    if args.air:  # both rigs from the files' summaries: refused before either is analysed
        check_air_twin(recorded_rig(src), recorded_rig(args.air), args.air)
    rig, hits = run_analysis(src, impact=args.impact, progress=progress_of(src), bars=None,
                             mode_hz=args.mode_hz)
    air = run_analysis(Path(args.air), progress=progress_of(Path(args.air)),
                       bars=None) if args.air else None
    report, files = write_analysis(src, rig, hits, out, plots=plots, air=air)
    print(format_summary(report, args.units))
    plural = "s" if len(files) != 1 else ""
    print(f"\nwrote {len(files)} file{plural} to {out}/ (report.json with every number, SI units)")
    return EXIT_OK


def cmd_gap(args: argparse.Namespace) -> int:
    """Sim-to-real gap diagnosis of a recording (``ramdaq gap-benchmark`` proves it)."""
    from ...analysis.gap.diagnose import Settings
    from .gap import (
        earlier_report,
        parse_effects,
        remove_stale,
        rig_record,
        run_gap,
        summary_lines,
        write_report,
    )
    from .progress import progress_bar

    effects = parse_effects(args.effects)

    src = Path(args.file)
    out = Path(args.out) if args.out else src.with_name(src.stem + "_gap")
    earlier = earlier_report(out, args.overwrite)  # refused before the minutes of the diagnosis
    with progress_bar(f"gap diagnosis of {src.name}", None):  # steps unknown: spinner and time
        lt, td, d = run_gap(src, rig=args.rig, settings=Settings(effects=effects),
                            progress=lambda m: print(m, flush=True), pre_s=args.pre_s,
                            post_max_s=args.post_s, held_out_every=args.held_out_every)
    files = write_report(d, out, plots=not args.no_plots, source=str(src), rig=rig_record(lt, args.rig))
    stale = remove_stale(earlier, files)
    print("\n".join(summary_lines(d)))
    plural = "s" if len(files) != 1 else ""
    print(f"\nwrote {len(files)} file{plural} to {out}/ (gap.json with every number)"
          + (f", replacing the earlier diagnosis there ({len(stale)} of its files not written again "
             f"removed: {', '.join(p.name for p in stale)})" if stale else
             ", replacing the earlier diagnosis there" if earlier else ""))
    return EXIT_OK


def cmd_import(args: argparse.Namespace) -> int:
    """Another system's recording (CSV, UFF 58, TDMS) into a ramdaq MCAP recording; its
    messages name the command's options (``--fs``), not the Python arguments."""
    from ...drivers.files.import_common import cli_option_names

    with cli_option_names():
        if len(args.file) == 1 and not Path(args.file[0]).is_dir():
            return _import_file(argparse.Namespace(**{**vars(args), "file": args.file[0]}))
        return _import_many(args)


def _import_many(args: argparse.Namespace) -> int:
    """Several files, folders or globs: each file imported as ``_import_file`` does, beside it
    or into the folder ``--out``; a file that fails is one line and the others go on; a last
    line counts them. Exit 1 if any failed."""
    from .bulk_import import bulk_outputs, import_sources

    files = import_sources(args.file)
    out_dir = Path(args.out) if args.out else None
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    outs = bulk_outputs(files, out_dir)
    failed = []
    for k, (src, out) in enumerate(zip(files, outs, strict=True)):
        print(f"[{k + 1}/{len(files)}] {src}")
        try:
            _import_file(argparse.Namespace(**{**vars(args), "file": str(src), "out": str(out)}))
        except _FAILURES as err:
            failed.append(src)
            print(f"ramdaq import: {_one_line(err)}", file=sys.stderr)
    print(f"imported {len(files) - len(failed)} of {len(files)} files"
          + (f"; {len(failed)} failed: {', '.join(f.name for f in failed[:5])}"
             + (" ..." if len(failed) > 5 else "") if failed else ""))
    return EXIT_FAILED if failed else EXIT_OK


def _import_file(args: argparse.Namespace) -> int:
    from ...drivers.files.import_common import G0, parse_channel_map, parse_sensitivities
    from ...drivers.registry import open_device
    from ..record import record

    src = Path(args.file)
    out = Path(args.out) if args.out else src.with_suffix(".mcap")
    fmt = args.format or _SUFFIX_FORMAT.get(src.suffix.lower(), src.suffix.lower().lstrip("."))
    rig_out = None if args.rig else out.with_name(out.stem + ".rig.toml")
    for path in filter(None, (out, rig_out)):
        if path.exists() and not args.overwrite:
            raise FileExistsError(f"{path} exists; --overwrite replaces it")
    options: dict = {"channels": parse_channel_map(args.channels), "fs_hz": args.fs,
                     "force_channel": args.force_channel, "allow_gaps": args.allow_gaps,
                     "sensitivity": parse_sensitivities(args.sensitivity)}
    if args.rig:
        options["rig"] = load_rig(args.rig)
    else:
        options["rig"], options["channels"] = _channels_only_rig(args, src, fmt, rig_out,
                                                                 options["sensitivity"])
    if args.medium:
        options["medium"] = args.medium
    if args.time_unit:
        if fmt != "csv":
            raise ValueError(f"--time-unit is for a CSV file, not {src}")
        options["time_unit"] = args.time_unit
    if args.group:
        if fmt != "tdms":
            raise ValueError(f"--group is for a TDMS file, not {src}")
        options["group"] = args.group
    from .progress import progress_bar

    device = open_device(f"{fmt}://{src}" if fmt in ("csv", "uff", "tdms") else str(src), **options)
    with progress_bar(f"reading {src.name}", None):  # parsing the file: no count to show
        info, imp = device.info, device.info.extra.get("import", {})
    chans = imp.get("channels", {}).values()
    exact = sum(c["method"] != "requantised" for c in chans)
    stated = sum(c["method"] == "stated" for c in chans)
    worst = {u: max(c["max_error_si"] for c in chans if c["si_unit"] == u)
             for u in sorted({c["si_unit"] for c in chans}, reverse=True)}
    with progress_bar(f"writing {out.name}", imp.get("rows"), unit="samples") as advance:
        s = record(device, out, readout=False, overwrite=args.overwrite,
                   progress=lambda b: advance(b.n_samples))
    print(f"imported {src} ({imp.get('format')}, {info.n_channels} ch at {info.fs_hz:g} Hz) into "
          f"{out}: {s.duration_s:.2f} s, {s.blocks} blocks, {s.gaps} gaps "
          f"({imp.get('missing_samples', 0)} samples missing)")
    for line in _read_notes(imp, rig_given=rig_out is None):
        print(line, file=sys.stderr if line.startswith("warning:") else sys.stdout)
    volts = [(c["source"], c.get("sensitivity_from", ""), c["sensitivity_V_per_m_s2"])
             for c in chans if "sensitivity_V_per_m_s2" in c]
    for v, whose in sorted({(v, f) for _, f, v in volts}):  # what turned volts into m/s^2, said
        names = [n for n, f, w in volts if (w, f) == (v, whose)]
        print(f"{_channels_are(names, most=4)} in volts: converted at {1e3 * v:.4g} mV/(m/s^2) "
              f"= {1e3 * v * G0:.4g} mV/g" + (f" ({whose})" if whose else ""))
    odd = [(c["source"], c["unit"], c["rig_unit_not_applied"]) for c in chans
           if "rig_unit_not_applied" in c]
    for unit, rig_unit in sorted({(u, r) for _, u, r in odd}):  # one line per disagreement
        names = [src_ for src_, u, r in odd if (u, r) == (unit, rig_unit)]
        print(f"warning: {_channels_are(names, most=4)} in {unit} by the file's header, but rig "
              f"{info.extra.get('rig_name')!r} says {rig_unit}: the header's unit was applied",
              file=sys.stderr)
    print(f"counts: {exact} channel{' kept its' if exact == 1 else 's kept their'} source step"
          + (f" ({stated} at the scale the file states)" if stated else "") + ", "
          f"{info.n_channels - exact} requantised to 24 bits; largest error "
          + ", ".join(f"{e:.3g} {u}" for u, e in worst.items()))
    left = _not_recorded(options["rig"], info.channels)
    if left:
        print(f"warning: rig {options['rig'].name!r} declares {left}, which no column of {src.name} "
              f"fills: not recorded (the analysis uses the recorded channels; --channels / "
              f"--force-channel map columns named otherwise)", file=sys.stderr)
    if rig_out is not None:
        rig_out.write_text(options["rig"].text)
        print(f"wrote the channels-only rig it was imported with to {rig_out} (no --rig given; "
              f"medium {device.rig.medium}" + ("" if args.medium or device.rig.medium == "water"
                                               else ", --medium water for a flooded trial")
              + f"); ramdaq analyze {out} "
              "gives each gage's frequency and decrement")
    return EXIT_OK


def _not_recorded(rig, channels: tuple[str, ...]) -> str:
    """The rig's gages and force channels a recording's ``channels`` lack, in words ("" if none)."""
    gages = [str(g.number) for g in rig.gages_by_channel() if f"g{g.number:02d}" not in channels]
    forces = [repr(f.name) for f in rig.forces if f.name not in channels]
    return " and ".join(([f"gage(s) {', '.join(gages)}"] if gages else [])
                        + ([f"force channel {', '.join(forces)}"] if forces else []))


_SUFFIX_FORMAT = {".tsv": "csv", ".txt": "csv", ".unv": "uff"}
"""Suffixes ``import`` reads as another format's (a tab-separated file is a CSV to it)."""


def _channels_are(names: list[str], most: int | None = None) -> str:
    """``channel 'a' is`` or ``channels 'a', 'b' are``, naming at most ``most`` (then "and N
    more")."""
    shown = ", ".join(repr(n) for n in names[:most])
    if most is not None and len(names) > most:
        shown += f" and {len(names) - most} more"
    return f"channels {shown} are" if len(names) > 1 else f"channel {shown} is"


def _counted(per_channel: dict[str, int], most: int = 4) -> str:
    """``'a' (60), 'b' (60)``, naming at most ``most`` channels (then "and N more")."""
    items = list(per_channel.items())
    text = ", ".join(f"{n!r} ({k})" for n, k in items[:most])
    return text + (f" and {len(items) - most} more" if len(items) > most else "")


def _medium_lines(imp: dict, rig_given: bool) -> list[str]:
    """The medium the import applied and what decided it, in one line: the file (its CSV
    header, TDMS property, UFF header: where), ``--medium``, or the rig when the file states
    none (not said for a channels-only rig, whose line names its medium)."""
    stated = imp.get("medium_stated")
    if not stated:
        return []
    where = imp.get("medium_where") or "the file's header"
    if stated["file"] is None:
        if stated["by"] == "given":
            return [f"medium {stated['applied']} as --medium gives (the file states none)"]
        return [f"medium {stated['applied']}, the rig's: the file states none (--medium overrides)"] \
            if rig_given else []
    if stated["by"] == "file" and stated["file"] != stated["rig"]:
        return [f"medium {stated['file']}, as {where} states (the rig says {stated['rig']}; "
                "--medium overrides)"]
    if stated["by"] == "given" and stated["file"] != stated["applied"]:
        return [f"warning: medium {stated['applied']} as --medium gives, but {where} states "
                f"{stated['file']}"]
    return [f"medium {stated['file']}, as {where} states"]


def _read_notes(imp: dict, rig_given: bool = True) -> list[str]:
    """What the reader made of the file: the medium (:func:`_medium_lines`); the CSV
    dialect: lines skipped, decimal commas."""
    out = []
    skipped = imp.get("skipped_lines")
    if skipped:
        n, a, b = skipped["count"], skipped["first"], skipped["last"]
        out.append(f"skipped {n} line{'s' if n > 1 else ''} above the column names (line"
                   f"{f's {a}-{b}' if b > a else f' {a}'}: a header block, not data)")
    out += _medium_lines(imp, rig_given)
    dropped = imp.get("dropped_with_gaps", {})
    if dropped.get("good"):
        good, lost = dropped["good"], dropped["missing"]
        out.append(f"warning: --allow-gaps: {sum(good.values())} good values on {_counted(good)} "
                   f"were dropped with the gaps, the rows where {_counted(lost)} had no value: "
                   f"a recording's gap is on every channel (no value is invented for it)")
    if "time_column" in imp and imp["time_column"] is None:
        out.append(f"no time column (no column is named like time, t [s], time_s): every column "
                   f"is a channel, the rows are samples at {imp.get('fs_hz'):g} Hz as --fs "
                   f"states, time 0 at the first row")
    if imp.get("time_resolution_s"):
        res, fs = imp["time_resolution_s"], imp.get("fs_hz")
        to = (f"{imp['time_digits']} significant digits, down to {res:g} s at its latest rows"
              if imp.get("time_digits") else f"{res:g} s")
        out.append(f"the time column is printed to {to} ({res * fs:.2f} sample at {fs:g} "
                   f"Hz): each row is placed on the {fs:g} Hz grid within that rounding")
    if imp.get("cut_last_line"):
        out.append(f"warning: line {imp['cut_last_line']}, the last, has no line end (the file "
                   f"cut off mid-line?): left out, as its last value may be a cut number")
    if imp.get("decimal") == ",":
        out.append(f"read decimal commas as decimal points (the delimiter is "
                   f"{'a tab' if imp.get('delimiter') == chr(9) else repr(imp.get('delimiter'))})")
    return out


def _channels_only_rig(args: argparse.Namespace, src: Path, fmt: str, rig_out: Path,
                       sensitivity: float | dict[str, float] | None) -> tuple[object, dict[str, int]]:
    """Without ``--rig``: a channels-only rig for the file's channels (every one), at the
    file's own rate (``--fs`` checks it), each gage in the unit its samples are in: the file's
    header unit where it states one (a differing ``--units`` is warned of and not applied),
    else ``--units``; m/s^2 for a channel in volts that ``sensitivity`` (V per m/s^2, parsed
    ``--sensitivity``) converts. Returns the rig and the source -> gage map."""
    from ...analysis.model.rig import parse_rig
    from ...drivers.files.import_common import find_channel, sensitivity_of
    from ...drivers.files.minimal_rig import minimal_rig, source_channels

    if args.channels:
        raise ValueError("without --rig, every channel is imported (--force-channel names the "
                         "force); --channels maps channels onto a rig's gages")
    found = source_channels(src, "uff" if fmt == "unv" else fmt, time_unit=args.time_unit,
                            fs_hz=args.fs, group=args.group if fmt == "tdms" else None)
    force = args.force_channel and (find_channel(args.force_channel, found.names, found.aliases)
                                    or args.force_channel)
    # a channel in volts whose sensitivity is given records m/s^2 (its volts are converted)
    sens = {n: v for n, u in zip(found.names, found.units, strict=True)
            if (v := sensitivity_of(sensitivity, n, u)) is not None}
    file_units = [("m/s^2" if n in sens else u) for n, u in zip(found.names, found.units, strict=True)]
    try:
        made = minimal_rig(found.names, name=src.stem, fs_hz=args.fs or found.fs_hz,
                           units=args.units, force_channel=force,
                           medium=args.medium or found.medium or "air", file_units=file_units,
                           anti_alias=found.anti_alias, sensitivities=sens)
    except ValueError as err:  # a channel it cannot make a gage of: say in which file
        raise ValueError(f"{src}: {err}") from None
    if found.anti_alias is not None:
        print(f"anti-alias filter order {found.anti_alias[0]} at {found.anti_alias[1]:g} Hz, as the "
              f"file states: written into {rig_out.name}, so onsets have its delay removed")
    for unit in sorted({u for _, u in made.overridden}):
        names = [c for c, u in made.overridden if u == unit]
        print(f"warning: {_channels_are(names)} in "
              f"{unit} by the file's header; --units {args.units} applies only to channels that "
              f"state no unit, so {unit} is applied and recorded in {rig_out.name}",
              file=sys.stderr)
    return parse_rig(made.text, source=str(rig_out)), made.channels


def cmd_export_csv(args: argparse.Namespace) -> int:
    """Every sample of a recording as CSV, with its events and gaps in the comment lines."""
    from ...drivers.files.export_csv import export_csv

    src = Path(args.file)
    out = Path(args.out) if args.out else src.with_suffix(".csv")
    _check_outputs([out], args.overwrite)
    r = export_csv(src, out, units=args.units)
    print(f"wrote {out}: {r.rows:,} samples of {r.channels} channels ({args.units}), "
          f"{r.gaps} gap(s) ({r.missing} samples missing), {r.events} event(s) in its comments")
    return EXIT_OK


def cmd_export_uff(args: argparse.Namespace) -> int:
    """A recording's identified modes and decay records as UFF 15/55/58 for modal software."""
    from ...drivers.files.export_uff import export_uff
    from .analyze import run_analysis

    src = Path(args.file)
    out = Path(args.out) if args.out else src.with_suffix(".uff")
    _check_outputs([out], args.overwrite)  # before the analysis, not after it
    rig, hits = run_analysis(src, progress=lambda m: print(m, flush=True))
    r = export_uff(out, hits, rig, source=str(src), binary=args.binary)
    print(f"wrote {out}: {r.nodes} gage nodes, {r.modes} mode shapes and {r.records} decay "
          f"records from {r.hits} accepted of {len(hits)} hits")
    if r.left_out:
        print(r.left_out)
    return EXIT_OK


def cmd_rig(args: argparse.Namespace) -> int:
    from ...analysis.impact import skipped_steps
    from ...analysis.model.rig_modes import eq18_check, modes_in

    rig = load_rig(args.rig)    # 'rig fit ...' has its own parser (rig_fit_parser)
    print(f"rig {rig.name} ({args.rig}): {rig.surface.title}, {len(rig.gages)} gages, "
          f"{rig.daq.sample_rate_hz:g} Hz, medium {rig.medium}")
    if not rig.structural:
        print("channels only (no rudder, stock or hull): no modes to compute")
        return EXIT_OK
    for s in skipped_steps(rig, tuple(g.number for g in rig.gages)):  # a layout short of 16
        print(f"not computed with these gages: {s.step}: {s.reason}")
    for medium in ("air", "water"):
        if medium not in rig.damping:
            continue
        m = modes_in(rig, medium)
        print(f"\nmodes in {medium}:  (* predominant after the rig's default ram blow)")
        print("   f (Hz)    delta   zeta (%)")  # zeta in percent, as analyze prints it
        for i, (f, d, z) in enumerate(zip(m.table.frequency_hz, m.table.decrement,
                                          m.table.damping_ratio, strict=True)):
            print(f"{'*' if i == m.predominant else ' '} {f:8.3f}  {d:7.4f}  {100 * z:8.3f}")
        nyquist = rig.daq.sample_rate_hz / 2
        above = [f for f in m.table.frequency_hz if f >= nyquist]
        if above:  # e.g. a unit slip: a mass in the report's ton s^2/ft read as kg
            print(f"warning: mode(s) at {', '.join(f'{f:.0f}' for f in above)} Hz lie above half "
                  f"the sample rate ({nyquist:g} Hz): no trial at this rate records them; a mass "
                  f"or inertia in the report's units (ton s^2/ft, ft ton s^2) rather than SI?")
    if rig.structural:
        _warn_added_mass_ratio(rig)
    if {"air", "water"} <= set(rig.damping):
        from ...analysis.model.units import from_si

        c = eq18_check(rig)
        report = args.units == "report"
        unit, fmt = ("ton s^2/ft", ".4f") if report else ("kg", ".0f")
        m_a, m18, m19 = (from_si(v, "mass") if report else v
                         for v in (c.m_a_kg, c.m_vir_eq18_kg, c.m_vir_model_kg))
        print(f"\nEq 18: m_vir = m_a[(f_air/f_water)^2 - 1] = {m_a:{fmt}} {unit} x "
              f"[({c.f_air_hz:.2f}/{c.f_water_hz:.2f})^2 - 1] = {m18:{fmt}} {unit}")
        print(f"model's own added mass (Eq 19): {m19:{fmt}} {unit}; Eq 18 is "
              f"{100 * c.difference:+.1f} % off it. Eq 18 assumes an uncoupled translation mode;"
              f" the predominant mode couples v with alpha and gamma, whose added inertias "
              f"(Eq 20, 21) differ in proportion from Eq 19's (Report 1836 found 0.2240 against "
              f"0.2735 ton s^2/ft, -18 %).")
        ratio = c.m_vir_eq18_kg / c.m_vir_model_kg
        off = max(ratio, 1 / ratio) if ratio > 0 else math.inf
        if off > 2.0:  # beyond the report's own -18 % by far, either way: the rig, not Eq 18
            print(f"warning: Eq 18 is {off:.3g}x off the model's own added mass: "
                  "check the rig's masses, inertias and their units (the air and water modes "
                  "compared may not be the same mode)")
    return EXIT_OK


ADDED_OVER_MASS_MAX = 30.0
"""Largest plausible ratio of a surface's added mass in water (Eq 19) to its own mass: a steel
plate's is ~0.1 chord / thickness (1-3 for a rudder; ALBACORE's and SAMPSON's rigs 3.1 and
3.3); ten times that is a unit slip (kg for tonnes) or a typo."""


def _warn_added_mass_ratio(rig: Rig) -> None:
    """A warning line when the rig's surface is far lighter than the water it moves."""
    from ...analysis.model.structure import added_mass

    mass = rig.rudder.mass_kg
    added = added_mass(rig.with_medium("water"))["m_vir"] if "water" in rig.damping else math.nan
    if mass > 0 and added / mass > ADDED_OVER_MASS_MAX:
        print(f"warning: the {rig.surface.title.lower()}'s mass ({mass:.4g} kg) is {added / mass:.3g}x "
              f"smaller than the added mass of the water it moves ({added:.4g} kg, Eq 19), beyond "
              f"the {ADDED_OVER_MASS_MAX:g}x a steel surface can be: a mass in tonnes, or a typo?")


def cmd_rig_fit(args: argparse.Namespace) -> int:
    """``ramdaq rig fit TRIAL --rig START``: the rig's constants tuned to the trial's modes."""
    from .rigfit import fit_lines, parse_bounds, run_rig_fit

    if not args.trial:
        raise SystemExit("ramdaq rig fit: give the trial (and, unless it carries its rig, the "
                         "start rig): ramdaq rig fit TRIAL.mcap [--rig START.toml]")
    mf, path = run_rig_fit(args.trial, args.start, out=Path(args.out) if args.out else None,
                           bounds=parse_bounds(args.bound), progress=lambda m: print(m, flush=True),
                           overwrite=args.overwrite)
    print("\n".join(fit_lines(mf, path, args.units)))
    return EXIT_OK


# -- batch and gap-benchmark on a dask cluster (ramdaq.daq.commands.batch) ---------------------

def cmd_batch(args: argparse.Namespace) -> int:
    """Many recordings at once on a dask cluster: one Parquet table, a report folder each."""
    from .batch import ClusterError, exit_code, run_batch, summary_lines

    out = Path(args.out or f"batch_{args.kind}")
    try:
        outcome = run_batch(args.kind, args.paths, out, workers=args.workers, scheduler=args.scheduler,
                            plots=not args.no_plots, force=args.force, progress=not args.quiet,
                            rig=getattr(args, "rig", None))
    except (ConnectionError, ClusterError) as err:
        print(f"ramdaq batch: {err}", file=sys.stderr)
        return 1
    print("\n".join(summary_lines(outcome)))
    return exit_code(outcome)


def cmd_gap_benchmark(args: argparse.Namespace) -> int:
    """The gap benchmark on worker processes, or with --scheduler on a dask cluster."""
    from ...analysis.truth.modal_family import EFFECTS as MODAL
    from ...analysis.truth.trial import EFFECTS as TRUTH
    from .gap_bench import run_benchmark

    effects = tuple(e.strip() for e in args.effects.split(",")) if args.effects else None
    for e in effects or ():
        if e not in TRUTH + MODAL:
            raise SystemExit(f"ramdaq gap-benchmark: --effects {e!r}: not an effect of either generator "
                             f"family ({', '.join(dict.fromkeys(TRUTH + MODAL))})")
    if sum((args.dev, args.check, args.seeds is not None)) > 1:
        raise SystemExit("ramdaq gap-benchmark: give one of --dev, --check, --seeds")
    seeds = "dev" if args.dev else "check" if args.check else args.seeds or "benchmark"
    from .progress import progress_bar

    kw = dict(per_class=args.per_class, seeds=seeds, jobs=args.jobs, effects=effects, rescore=args.rescore,
              thresholds=args.thresholds, family=args.family, blows=args.blows,
              perturb=(0.0 if args.dev else 0.25) if args.perturb is None else args.perturb,
              progress=lambda m: print(m, flush=True),
              bar=lambda n: progress_bar("gap benchmark", n, unit="scenarios"))
    out = Path(args.out or "gap_benchmark")
    if not args.scheduler or args.rescore:
        return run_benchmark(out, **kw)
    from .batch import open_client

    local = args.scheduler == "local"
    try:
        with open_client(args.jobs if local else None, None if local else args.scheduler) as client:
            return run_benchmark(out, client=client, **kw)
    except ConnectionError as err:
        print(f"ramdaq gap-benchmark: {err}", file=sys.stderr)
        return 1


def _batch_parsers(sub: argparse._SubParsersAction) -> None:
    """``batch analyze|gap`` and ``gap-benchmark``."""
    b = sub.add_parser("batch", help="many recordings on a dask cluster: one Parquet table and a "
                       "report folder per recording")
    kinds = b.add_subparsers(dest="kind", required=True)
    for kind, what in (("analyze", "ramdaq analyze of each recording"),
                       ("gap", "ramdaq gap of each recording (default settings)")):
        k = kinds.add_parser(kind, help=what)
        k.add_argument("paths", nargs="+", help="recordings: files, folders (every .mcap below), globs")
        k.add_argument("--out", help=f"output folder: {kind}.parquet and a report folder per recording "
                       f"(default batch_{kind}/)")
        k.add_argument("--workers", type=int, help="worker processes of the local cluster (default: the "
                       "core count)")
        k.add_argument("--scheduler", help="tcp://HOST:8786: run on this running dask cluster instead; its "
                       "workers must see the recordings and --out at the same paths")
        k.add_argument("--force", action="store_true", help="run every recording, also those whose results "
                       "are current (same content, same code)")
        k.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
        k.add_argument("--quiet", action="store_true", help="no progress bar")
        if kind == "gap":
            k.add_argument("--rig", help="rig file or shipped rig's name to hold every recording "
                           "against (default: the rig each recording carries; an import's "
                           "channels-only rig has no model to hold)")
        k.set_defaults(func=cmd_batch)

    g = sub.add_parser("gap-benchmark", help="the gap diagnosis proven on simulated trials with a hidden "
                       "effect (as 'gap benchmark'), optionally on a dask cluster")
    g.add_argument("--out", help="output folder (default gap_benchmark/)")
    g.add_argument("--per-class", type=int, default=PER_CLASS,
                   help=f"scenarios per effect class (default {PER_CLASS}: the whole run within 20 min on "
                        "two cores)")
    g.add_argument("--blows", type=int, default=BLOWS,
                   help=f"blows per trial (default {BLOWS}; at least {MIN_BLOWS}: three fitted, one held "
                        "out)")
    g.add_argument("--seeds", choices=list(SEED_SETS), help="the seed set: " + "; ".join(
        f"{k}, {v[1]}" for k, v in SEED_SETS.items()) + " (default benchmark)")
    g.add_argument("--dev", action="store_true", help="--seeds dev (tunes the thresholds)")
    g.add_argument("--check", action="store_true", help="--seeds check")
    g.add_argument("--effects", help="comma-separated effect classes (default: all)")
    g.add_argument("--jobs", type=int, default=2, help="worker processes (default 2); with --scheduler "
                   "local, the local cluster's workers")
    g.add_argument("--scheduler", help="tcp://HOST:8786: run the scenarios on this dask cluster; 'local': "
                   "on a local dask cluster of --jobs workers")
    g.add_argument("--perturb", type=float, default=None, metavar="FRACTION",
                   help="hand the diagnosis rigs whose masses, inertias and stiffnesses are off by up "
                        "to this fraction (0.25: +-25 %%), calibrated to each trial's modes first "
                        "(default 0.25, issue 17; 0 with --dev, which tunes on the generator's rigs; "
                        "--seeds dev with a perturbation runs every family and tunes nothing)")
    g.add_argument("--family", choices=("truth", "modal", "all"), default="all",
                   help="generator family: truth (the richer simulator), modal (free modal superposition "
                        "sharing nothing with the diagnosis's model), all (default)")
    g.add_argument("--rescore", action="store_true", help="score the results stored in --out again")
    g.add_argument("--thresholds", type=Path, help="thresholds file to score with (default: the shipped "
                   "ones)")
    g.set_defaults(func=cmd_gap_benchmark)


def _device_args(r: argparse.ArgumentParser) -> None:
    r.add_argument("--device", default="sim", help="sim, FILE.mcap, can://..., serial://...")
    r.add_argument("--rig", help="rig file (TOML) or a shipped rig's name (albacore, sampson, "
                   "stern_plane), required for the simulator")
    r.add_argument("--medium", choices=("air", "water"), help="override the rig's medium")
    r.add_argument("--duration", type=_positive, help="seconds to record (sim; default 10)")
    r.add_argument("--impacts", type=_parse_impacts, help="ram blows at these seconds, e.g. 1,4,7")
    r.add_argument("--impact-every", type=_positive,
                   help="a ram blow every S seconds, at S/2, 3S/2, ... (half a period of quiet first)")
    r.add_argument("--seed", type=int, help="noise seed (sim; default 0)")
    r.add_argument("--fs", type=_positive, help="override the rig's sample rate, Hz")
    r.add_argument("--fast", action="store_true", help="simulate as fast as possible")
    r.add_argument("--name", help="recording name: writes recordings/NAME.mcap (a name, not a "
                   "path: it cannot leave recordings/; default: the rig's name and medium)")
    r.add_argument("--out", help="output file, any path (overrides --name)")
    r.add_argument("--overwrite", action="store_true", help="replace an existing file")
    r.add_argument("--quiet", action="store_true", help="no live readout")


def build_parser() -> argparse.ArgumentParser:
    from ramdaq import __version__

    p = argparse.ArgumentParser(prog="ramdaq", description=DESCRIPTION,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--version", action="version", version=f"ramdaq {__version__}")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("record", help="record a device into an MCAP file")
    _device_args(r)
    r.set_defaults(func=cmd_record)

    t = sub.add_parser("trial", help="the live trial: record, detect hits, analyse, show live")
    _device_args(t)
    t.add_argument("--rrd", help="Rerun recording of the live view (default: beside the MCAP). "
                   "Finished on Ctrl-C and SIGTERM; a SIGKILL or a power cut leaves it without "
                   "its footer, and nothing repairs that (the MCAP recording: ramdaq recover)")
    t.add_argument("--no-rerun", action="store_true", help="no Rerun view")
    _web_args(t)
    t.add_argument("--units", choices=("si", "report"), default="si", help="summary units")
    t.add_argument("--json", help="also write the final per-hit results here (JSON)")
    t.set_defaults(func=cmd_trial)

    p_ = sub.add_parser("replay", help="a recording through the same trigger and analyzer")
    p_.add_argument("file", help="a recording (.mcap)")
    p_.add_argument("--realtime", action="store_true", help="at the recording's own pace")
    p_.add_argument("--rrd", help="write a Rerun view of the replay here")
    _web_args(p_)
    p_.add_argument("--quiet", action="store_true", help="no live table")
    p_.add_argument("--overwrite", action="store_true", help="replace existing --rrd, --json files")
    p_.add_argument("--units", choices=("si", "report"), default="si", help="summary units")
    p_.add_argument("--json", help="also write the final per-hit results here (JSON)")
    p_.set_defaults(func=cmd_replay)

    i = sub.add_parser("info", help="describe a recording")
    i.add_argument("file", help="a recording (.mcap), finished or not")
    i.add_argument("--json", action="store_true", help="print JSON")
    i.set_defaults(func=cmd_info)

    c = sub.add_parser("recover", help="write a valid copy of a recording that lost its footer "
                       "or has damaged chunks (every intact record kept)")
    c.add_argument("file", help="the damaged or unfinished recording (.mcap); it is only read")
    c.add_argument("-o", "--out", help="output file (default FILE.recovered.mcap)")
    c.set_defaults(func=cmd_recover)

    a = sub.add_parser("analyze", help="trial report: frequency, decrement, Report 1836 chain")
    a.add_argument("file", help="a recording (.mcap) that carries its rig")
    a.add_argument("--impact", type=int, help="analyse only this hit (0-based)")
    a.add_argument("--mode-hz", type=float, metavar="F",
                   help="run the report's chain (motions, Eq 14-17) on the identified mode nearest F Hz "
                   "instead of the most energetic one; an error if none is within the decay's "
                   "resolution (1 / its length) of F")
    a.add_argument("--air", help="the same rudder's in-air recording, for Eq 18 (file is in water)")
    a.add_argument("--out", help="output folder (default FILE_analysis/)")
    a.add_argument("--units", choices=("si", "report"), default="si",
                   help="terminal units: SI, or the report's ft / long ton / s")
    a.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    a.add_argument("--plots", metavar="KINDS", type=_plot_spec,
                   help="plot kinds per hit, comma-separated, or 'all': decay, spectrum, "
                        "modeshape, stock (default: decay)")
    a.set_defaults(func=cmd_analyze)

    gp = sub.add_parser("gap", help="sim-to-real gap: where the model misses, which unmodelled "
                       "effect, how far adding it closes the gap ('gap-benchmark' proves it)")
    gp.add_argument("file", help="recording (.mcap; ramdaq's own or imported)")
    gp.add_argument("--rig", help="rig file, if the recording carries none (or to hold it against another)")
    gp.add_argument("--out", help="output folder (default FILE_gap/)")
    gp.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    gp.add_argument("--overwrite", action="store_true",
                    help="replace an earlier diagnosis in the --out folder (refused without it)")
    gp.add_argument("--effects", help="comma-separated candidate effects (default: all registered); "
                    "'none': no library effect, only the data-only checks and the rig's model form "
                    "(gap-benchmark's 'none' is its class of trials made without an effect)")
    gp.add_argument("--pre-s", type=float, default=1.0, help="pre-trigger window, s (default 1)")
    gp.add_argument("--post-s", type=float, default=4.0, help="longest decay compared, s (default 4)")
    gp.add_argument("--held-out-every", type=int, default=3,
                   help="every Nth impact is held out of the calibration (default 3)")
    gp.set_defaults(func=cmd_gap)

    g = sub.add_parser("rig", help="a rig's modes in air and water, and Eq 18 on them; "
                       "'rig fit TRIAL --rig START' tunes a rig to a trial's modes")
    g.add_argument("rig", help="rig file or shipped rig's name ('ramdaq rig fit --help': tune a rig "
                   "to a trial's modes)")
    g.add_argument("--units", choices=("si", "report"), default="si",
                   help="masses in Eq 18's lines: SI (kg), or the report's ton s^2/ft")
    g.set_defaults(func=cmd_rig)

    m = sub.add_parser("import", help="another system's recording (CSV, UFF 58, TDMS) into MCAP")
    m.add_argument("file", nargs="+", help="FILE.csv, FILE.uff/.unv or FILE.tdms; several "
                   "files, folders (their .csv/.tsv/.txt/.uff/.unv/.tdms files) or globs import "
                   "each one, beside it or into the folder --out")
    m.add_argument("--rig", help="rig file (TOML) of the trial; without it, a channels-only rig "
                   "(the file's channels, units and rate) is written beside the output as "
                   "OUT.rig.toml")
    m.add_argument("--units", choices=("g", "m/s^2"), help="without --rig: the unit of the "
                   "acceleration channels whose file states none (a unit the file states wins, "
                   "with a warning where they differ)")
    m.add_argument("--out", help="output recording (default FILE.mcap); with several files, the "
                   "folder their recordings go to")
    m.add_argument("--channels", help="source channel to gage map, e.g. 'Accel 1=g01,Accel 2=2'"
                   " (default: names like g01, gage 1, 1)")
    m.add_argument("--format", choices=("csv", "uff", "tdms"), help="instead of the file suffix")
    m.add_argument("--medium", choices=("air", "water"), help="override the rig's medium")
    m.add_argument("--fs", type=_positive, help="the file's sample rate, Hz, when it differs from the "
                   "rig's (the file's own rate must agree with it); without --rig the file's own "
                   "rate is taken, and --fs only checks it")
    m.add_argument("--time-unit", choices=("s", "ms", "us"), help="CSV: the time column's unit, "
                   "when its header does not say it (time_s, 't [ms]', 'time (us)')")
    m.add_argument("--force-channel", help="the source channel that is the force (a load cell or "
                   "instrumented hammer, in N, kN or lbf); its header text with the unit ('Load "
                   "cell [N]') or a UFF record's ID line 1 ('Hammer') names it too")
    m.add_argument("--sensitivity", help="accelerometers recorded in volts (V, mV): their "
                   "sensitivity, one for all ('100mV/g') or per channel ('Accel 1=100mV/g,Accel "
                   "2=10.2mV/(m/s^2)')")
    m.add_argument("--group", help="TDMS: import only this group's channels (a file whose groups "
                   "are at different rates, LabVIEW's decimated copies, needs it)")
    m.add_argument("--allow-gaps", action="store_true", help="import a missing value (empty, NaN) "
                   "as a gap in the recording instead of refusing the file")
    m.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    m.set_defaults(func=cmd_import)

    x = sub.add_parser("export-uff", help="modes and decay records as UFF 15/55/58")
    x.add_argument("file", help="a recording (MCAP), analysed as by ramdaq analyze")
    x.add_argument("--out", help="output file (default FILE.uff)")
    x.add_argument("--binary", action="store_true", help="binary 58b decay records")
    x.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    x.set_defaults(func=cmd_export_uff)

    xc = sub.add_parser("export-csv", help="every recorded sample as CSV (what ramdaq import reads back)")
    xc.add_argument("file", help="a recording (MCAP)")
    xc.add_argument("--out", help="output file (default FILE.csv)")
    xc.add_argument("--units", choices=("m/s^2", "g"), default="m/s^2",
                    help="the gages' unit (a force channel stays in N); default m/s^2")
    xc.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    xc.set_defaults(func=cmd_export_csv)

    _batch_parsers(sub)
    p.add_argument("--debug", action="store_true", help="the traceback of an internal error")
    for command in sub.choices.values():  # --debug after the command too
        command.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                             help="the traceback of an internal error")
    return p


def rig_fit_parser() -> argparse.ArgumentParser:
    """``ramdaq rig fit``'s own parser: ``rig`` takes a rig's name where ``fit`` stands, so the
    fit's arguments are parsed here (:func:`main` sends ``rig fit ...`` to it), and its help and
    usage errors name ``ramdaq rig fit`` and its own options, not ``ramdaq rig``'s."""
    f = argparse.ArgumentParser(prog="ramdaq rig fit",
                                description="tune a rig's uncertain constants to the modes identified "
                                            "in a trial and write the fitted rig")
    f.add_argument("trial", help="the recording (.mcap) whose modes the rig is tuned to")
    f.add_argument("--rig", dest="start", help="the start rig (file or shipped name; default: the rig "
                   "the trial was recorded with)")
    f.add_argument("--out", help="the fitted rig file (default TRIAL_rig.toml beside the trial)")
    f.add_argument("--bound", action="append", metavar="NAME=LO:HI",
                   help="bounds of a constant as multipliers of its start value, e.g. "
                        "stock.I_m4=0.8:1.25 (1:1 holds it); repeatable")
    f.add_argument("--units", choices=("si", "report"), default="si",
                   help="the constants' start and fitted values: SI, as the rig file's keys, or the "
                        "report's ft / long ton / s (ton s^2/ft, ft ton s^2, ft^4, ton s/ft, ft ton s); "
                        "the fitted file is SI either way")
    f.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    f.add_argument("--debug", action="store_true", help="the traceback of an internal error")
    f.set_defaults(func=cmd_rig_fit, command="rig fit")
    return f


def _parse(argv: list[str]) -> argparse.Namespace:
    """The command line: ``rig fit ...`` (after any leading ``--debug``) by
    :func:`rig_fit_parser`, everything else by :func:`build_parser`."""
    k = next((i for i, a in enumerate(argv) if a != "--debug"), len(argv))
    if argv[k:k + 2] == ["rig", "fit"]:
        return rig_fit_parser().parse_args(argv[:k] + argv[k + 2:])
    return build_parser().parse_args(argv)


def _port(text: str) -> int:
    try:
        port = int(text)
    except ValueError:
        port = 0
    if not 1 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{text!r} is not a TCP port (1-65535)")
    return port


def _web_args(r: argparse.ArgumentParser) -> None:
    r.add_argument("--web", action="store_true", help="serve Rerun's web viewer on localhost")
    r.add_argument("--web-port", type=_port, default=9090,
                   help="port of the web viewer on 127.0.0.1 (default 9090)")
    r.add_argument("--grpc-port", type=_port, default=9876,
                   help="port of the gRPC server feeding it, on 127.0.0.1 (default 9876)")


@contextlib.contextmanager
def _sigterm_as_ctrl_c() -> Iterator[None]:
    """While the command runs, SIGTERM raises KeyboardInterrupt in the main thread, so it ends a
    recording or trial as Ctrl-C does (files finished); a second SIGTERM is ignored so that it
    cannot cut the footers short. Off the main thread (a test calling main) nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def terminate(signum: int, frame: object) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise KeyboardInterrupt("SIGTERM")

    previous = signal.signal(signal.SIGTERM, terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _one_line(err: BaseException) -> str:
    """An error as one line; an OSError as ``FILE: what`` (``[Errno 13] ...`` says less)."""
    if isinstance(err, OSError) and err.filename is not None and err.strerror:
        text = f"{err.filename}: {err.strerror}"
    elif isinstance(err, KeyError) and len(err.args) == 1 and isinstance(err.args[0], str):
        text = err.args[0]  # str() of a KeyError is its message's repr, in quotes
    else:
        text = str(err) or type(err).__name__
    return " ".join(text.split())


def _quiet_stdout() -> None:
    """The reader of stdout went away: point stdout at /dev/null, so the flush at exit cannot
    raise again."""
    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # not a real file (a test's capture)
        pass


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit code (module docstring, *Exit codes*)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:2] == ["gap", "benchmark"]:  # the older spelling of gap-benchmark
        argv = ["gap-benchmark", *argv[2:]]
    args = _parse(argv)  # usage errors: SystemExit(2)
    where = f"ramdaq {args.command}"
    with _sigterm_as_ctrl_c():
        try:
            code = args.func(args)
            sys.stdout.flush()  # here, where a reader that went away can still be caught
            return code
        except BrokenPipeError:
            _quiet_stdout()
            return EXIT_FAILED
        except KeyboardInterrupt:
            print(f"{where}: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
        except _FAILURES as err:
            print(f"{where}: {_one_line(err)}", file=sys.stderr)
            return EXIT_FAILED
        except Exception as err:
            print(f"{where}: internal error, {type(err).__name__}: {_one_line(err)}"
                  + ("" if args.debug else " (--debug shows where)"), file=sys.stderr)
            if args.debug:
                traceback.print_exc()
            return EXIT_INTERNAL


if __name__ == "__main__":
    sys.exit(main())
