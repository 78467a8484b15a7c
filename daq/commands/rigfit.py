"""``ramdaq rig fit TRIAL --rig START``: a rig's constants tuned to a trial's identified modes
and shapes (:mod:`ramdaq.analysis.gap.rigfit`), written as a new rig file, with the modes before
and after. The noise floor, and so every uncertainty, comes from the trial, not the rig file."""

from __future__ import annotations

import datetime
import math
from collections.abc import Callable
from pathlib import Path

from ...analysis.gap.modal_level import ModalComparison, trial_modes
from ...analysis.gap.rigfit import PINNED_SD, ModeFit, calibrate_to_modes, fit_params, fitted_rig_text
from ...analysis.model.rig import RigError
from ...analysis.model.units import from_si, report_unit
from ..gap_trial import load_trial, trial_data


def parse_bounds(items: list[str] | None) -> dict[str, tuple[float, float]]:
    """``["stock.I_m4=0.8:1.25", ...]`` as ``{name: (lo, hi)}`` multipliers. Raises RigError
    naming the item that is not ``NAME=LO:HI``."""
    out = {}
    for item in items or ():
        name, eq, rest = item.partition("=")
        lo, colon, hi = rest.partition(":")
        try:
            if not (eq and colon and name.strip()):
                raise ValueError
            out[name.strip()] = (float(lo), float(hi))
        except ValueError:
            raise RigError(f"--bound {item!r}: expected NAME=LO:HI, multipliers of the start "
                           "value, e.g. stock.I_m4=0.8:1.25") from None
    return out


def run_rig_fit(trial: str | Path, start: str | Path | None = None, *, out: Path | None = None,
                bounds: dict[str, tuple[float, float]] | None = None,
                progress: Callable[[str], None] | None = None,
                overwrite: bool = False) -> tuple[ModeFit, Path]:
    """Identify ``trial``'s modes, fit ``start``'s constants to them (``start`` None: the rig the
    trial was recorded with), write the fitted rig to ``out`` (default: the trial's folder,
    ``TRIAL_rig.toml``). ``bounds`` are checked against the rig before any identification; an
    existing ``out`` is refused (``FileExistsError``) before it too, unless ``overwrite``.
    Returns the fit and the path."""
    path = out if out is not None else Path(trial).with_name(Path(trial).stem + "_rig.toml")
    if path.exists() and not overwrite:
        same = start is not None and Path(start).exists() and path.resolve() == Path(start).resolve()
        raise FileExistsError(f"{path} exists{' (it is the start rig)' if same else ''}; "
                              "--overwrite replaces it")
    say = progress or (lambda s: None)
    lt = load_trial(trial, start, say)
    if start is None:
        say(f"start rig: the one {Path(trial).name} was recorded with ({lt.rig.name})")
    fit_params(lt.rig, bounds)  # a misspelt --bound fails here, not after the identification
    td = trial_data(lt)
    say(f"identifying modes on {td.n_seg} impacts")
    tm = trial_modes(td)
    if tm.n_modes == 0:
        raise ValueError(f"{trial}: no mode recurs across the impacts: nothing to fit the rig to")
    say(f"fitting the rig's constants to {tm.n_modes} modes")
    mf = calibrate_to_modes(tm, lt.rig, bounds)
    text = fitted_rig_text(mf, str(trial), datetime.date.today().isoformat())
    path.write_text(text, encoding="utf-8")
    return mf, path


def _f(v: float, fmt: str) -> str:
    return format(v, fmt) if math.isfinite(v) else "-".rjust(len(format(1.0, fmt)))


def mode_table(before: ModalComparison, after: ModalComparison) -> list[str]:
    """The identified modes beside the start and the fitted model's: frequency, damping ratio
    (percent, as ``analyze`` and ``rig`` print it; the identified ones with their standard
    errors), MAC over all gages and per body."""
    tm = before.trial
    out = [f"modes identified on {tm.n_impacts} impacts (+- standard error from their spread) "
           "against the start rig and the fitted one:",
           f"{'identified':>13s}{'':23s}|  start rig                  |  fitted rig",
           f"{'f (Hz)':>9s} {'+-':>7s} {'zeta %':>7s} {'+-':>7s}   |  f (Hz)   df % zeta %  MAC  |"
           "  f (Hz)   df % zeta %  MAC   MAC rudder/hull"]
    b = {p.i_id: p for p in before.pairs}
    a = {p.i_id: p for p in after.pairs}
    for i in range(tm.n_modes):
        row = f"{tm.f_hz[i]:9.4f} {tm.f_se_hz[i]:7.1e} {100 * tm.zeta[i]:7.3f} {100 * tm.zeta_se[i]:7.1e}   |"
        for p in (b.get(i), a.get(i)):
            if p is None:
                row += "  (no model mode pairs with it)  |"
                continue
            row += (f" {p.f_model_hz:8.3f} {100 * p.df_rel:+6.2f} {100 * p.zeta_model:6.3f} "
                    f"{p.mac:6.4f} |")
        p = a.get(i)
        if p is not None:
            row += f"  {_f(p.mac_rudder, '.4f')}/{_f(p.mac_hull, '.4f')}"
        out.append(row.rstrip(" |"))
    return out


_REPORT_UNITS = (("_kg_m2", "inertia"), ("_kg", "mass"), ("C_N_s_per_m", "damping_translational"),
                 ("_N_m_s_per_rad", "damping_rotational"), ("_m4", "area_moment"))
"""A constant's key ending -> its quantity (:mod:`ramdaq.analysis.model.units`), for
``--units report``."""


def report_value(name: str, value: float) -> tuple[float, str]:
    """A fitted constant's SI value in the report's units (Report 1836: ft, long ton, s) and the
    unit's name; a constant with no length or mass in it (a frequency, a ratio, a factor) as it
    is, with "" for its unit."""
    for end, quantity in _REPORT_UNITS:
        if name.endswith(end):
            return float(from_si(value, quantity)), report_unit(quantity)
    return value, ""


def fit_lines(mf: ModeFit, path: Path, units: str = "si") -> list[str]:
    """What ``ramdaq rig fit`` prints: the modes, the constants, the solver's end, the form.
    ``units="report"``: the constants' start and fitted values in the report's units (masses
    in ton s^2/ft, inertias in ft ton s^2, the stock's I and J in ft^4, the dashpots in ton s/ft
    and ft ton s), each row naming its unit; the keys stay the rig file's (SI) ones."""
    report = units == "report"
    out = mode_table(mf.before, mf.after)
    out.append("")
    out.append("constants: start, fitted"
               + (" (in the report's units, named after the key)" if report else "")
               + ", x start, +- posterior sd (relative), bounds, and what these modes make of it:")
    out.append(f"  (pinned: fitted, within +-{100 * PINNED_SD:.0f} % at 1 sd; loose: fitted, but the "
               f"modes leave it beyond +-{100 * PINNED_SD:.0f} %, so its value is no better than "
               "that; NOT PINNED, held: kept at its start)")
    rows = []
    for p in mf.params:
        start, value, unit = p.start, p.value, ""
        if report:
            (start, unit), (value, _) = report_value(p.name, p.start), report_value(p.name, p.value)
        rows.append((p, f"{p.name} [{unit}]" if unit else p.name, start, value))
    width = max([38] + [len(r[1]) for r in rows])
    for p, name, start, value in rows:
        out.append(f"  {name:{width}s} {start:11.5g} {value:11.5g}  x{p.factor:6.4f} "
                   f"+-{_f(100 * p.sd, '5.1f')} %  [{p.lo:g}, {p.hi:g}]  {p.pin_text()}"
                   + ("  AT BOUND" if p.at_bound else ""))
    if mf.misfit_scale > 1:
        out.append(f"  (sds widened x{mf.misfit_scale:.3g}: the modes differ from the fitted model by "
                   "that much more than the identification's standard errors say; the damping "
                   "constants' sds are from the damping ratios alone, fitted after the others)")
    out.append(f"solver: {mf.solver_text()}")
    out.append(f"model form left: {mf.form_text()}")
    if mf.scale is not None:
        out += mf.scale.check_lines()
    out.append(f"wrote {path}")
    return out
