"""Report 1836, Table 2, recomputed from its own inputs, and the report's internal inconsistencies.

Every input is kept as the text the report prints (so its rounding is known), converted to SI,
passed through the Table 1 functions (:mod:`ramdaq.analysis.report1836.damping`,
:mod:`ramdaq.analysis.report1836.virtual_mass`) and converted back to report units only at the edge.

Each :class:`Row` also carries the *rounding envelope*: the worst-case change of the result when
every printed input moves by half a unit in its last printed digit (linear, summed). A published
value is consistent with its inputs if it lies within that envelope plus its own half-unit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..model.units import RHO_REPORT_KG_M3, from_si, report_unit, to_si
from .damping import C_translational, c_rotational
from .motions import percent_deviation_from_average
from .virtual_mass import (
    Ix_vir,
    Iz_vir_elliptic,
    m_vir_flat_plate,
    m_vir_from_frequencies,
)

__all__ = ["Input", "Row", "PrintedDecrements", "TABLE_2F_FIXED", "TABLE_2F_MOVABLE",
           "reproduce_table2", "check_report_consistency"]


def _half_ulp(text: str) -> float:
    """Half a unit in the last printed digit of a decimal number written as ``text``."""
    decimals = len(text.split(".")[1]) if "." in text else 0
    return 0.5 * 10.0**-decimals


@dataclass(frozen=True)
class Input:
    """One printed input: name, value as printed, ramdaq.analysis.model.units quantity and Table 2 source."""

    name: str
    text: str
    quantity: str
    source: str

    @property
    def value(self) -> float:
        """The value in report units."""
        return float(self.text)

    @property
    def unit(self) -> str:
        """The report unit of the value."""
        return report_unit(self.quantity)

    @property
    def half_ulp(self) -> float:
        """Half a unit in the last printed digit, report units."""
        return _half_ulp(self.text)


@dataclass(frozen=True)
class Row:
    """One Table 2 quantity, published against recomputed, both in report units.

    Attributes
    ----------
    quantity : str
        What it is, e.g. ``"ALBACORE C in air (Eq 16)"``.
    equation : str
        Table 1 equation number(s).
    inputs : tuple of Input
        The printed inputs with their Table 2 source.
    unit : str
        Report unit of ``published`` and ``recomputed``.
    published, recomputed : float
        Table 2's value and the value recomputed from ``inputs`` (computed in SI).
    difference_pct : float
        ``100 (recomputed - published) / published``.
    sensitivities : tuple of float
        ``d recomputed / d input`` for each input, report units.
    rounding_pct : float
        Worst-case effect of the inputs' print rounding, ``Σ |s_i| half_ulp_i``, % of published.
    consistent : bool
        ``|difference| <= rounding + half a unit of the published value's last digit``.
    note : str
        How the value is obtained, caveats.
    """

    quantity: str
    equation: str
    inputs: tuple[Input, ...]
    unit: str
    published: float
    recomputed: float
    difference_pct: float
    sensitivities: tuple[float, ...]
    rounding_pct: float
    consistent: bool
    note: str


SiFunc = Callable[[dict[str, float]], float]


@dataclass(frozen=True)
class _Spec:
    label: str
    equation: str
    inputs: tuple[Input, ...]
    out: str
    published: str
    func: SiFunc
    note: str = ""


def _rho(si: dict[str, float]) -> float:
    return si["rho"] / si["g"]  # weight density / g = mass density, kg/m^3


def _eq16(si: dict[str, float]) -> float:
    return C_translational(si["m"], si["f"], si["delta_v"])


def _eq17(si: dict[str, float]) -> float:
    return c_rotational(si["I_z"], si["I_xz"], si["alpha1/gamma1"], si["f"], si["delta_gamma"])


def _eq18(si: dict[str, float]) -> float:
    return m_vir_from_frequencies(si["m_a"], si["f_air"], si["f_water"])


def _eq19(si: dict[str, float]) -> float:
    return m_vir_flat_plate(_rho(si), si["x_bar"], si["z_bar"])


def _eq20(si: dict[str, float]) -> float:
    return Iz_vir_elliptic(_rho(si), si["x_bar"], si["y_bar"], si["z_bar"])


def _eq21(si: dict[str, float]) -> float:
    return Ix_vir(_eq19(si), si["z_bar"])


def _eq18_19_average(si: dict[str, float]) -> float:
    return (_eq18(si) + _eq19(si)) / 2


def _inp(name: str, text: str, quantity: str, source: str) -> Input:
    return Input(name, text, quantity, source)


_DL = "dimensionless"
_REF4 = "Table 2c (Reference 4, Table 4)"
_PLANS = "Table 2c (ship plans)"
_M_A = _inp("m_a", "0.0878", "mass", _REF4)
_F_AIR = _inp("f", "24.5", "frequency", "Table 2a (predominant, in air)")
_F_WATER = _inp("f", "13.0", "frequency", "Table 2a (predominant, in water)")
_FREQS = (_inp("f_air", "24.5", "frequency", "Table 2a"),
          _inp("f_water", "13.0", "frequency", "Table 2a"))
_ALB_PLATE = (_inp("x_bar", "6.2084", "length", "Table 2d"),
              _inp("z_bar", "10.1667", "length", "Table 2d"),
              _inp("rho", "64.15", "weight_density", "Table 2d"),
              _inp("g", "32.17", "acceleration", "Table 2d"))
_Y_BAR = _inp("y_bar", "1.1250", "length", "Table 2d")

_SPECS = (
    _Spec("ALBACORE C in air", "16", (
        _inp("m", "0.0878", "mass", _REF4 + ", m_a"), _F_AIR,
        _inp("delta_v", "0.0758", _DL, "Table 2b/2c (Eq 6a)")),
        "damping_translational", "0.3261", _eq16, "C = 2 m_a f delta_v"),
    _Spec("ALBACORE C in water", "16", (
        _inp("m", "0.3613", "mass", _REF4 + ", m_y"), _F_WATER,
        _inp("delta_v", "0.1216", _DL, "Table 2c (Table 2b prints 0.1212)")),
        "damping_translational", "1.1424", _eq16, "with Table 2c's delta_v = 0.1216"),
    _Spec("ALBACORE c in air", "17", (
        _inp("I_z", "0.3320", "inertia", _PLANS), _inp("I_xz", "-0.1687", "inertia", _PLANS),
        _inp("alpha1/gamma1", "-1.5877", _DL, "Table 2c (experimental data)"), _F_AIR,
        _inp("delta_gamma", "0.0524", _DL, "Table 2b/2c (Eq 4)")),
        "damping_rotational", "0.1655", _eq17,
        "I_z - I_xz alpha1/gamma1 = 0.0642 is a small difference of large terms"),
    _Spec("ALBACORE c in water", "17", (
        _inp("I_z", "0.6446", "inertia", _REF4), _inp("I_xz", "-0.1514", "inertia", _REF4),
        _inp("alpha1/gamma1", "-0.9631", _DL, "Table 2c (experimental data)"), _F_WATER,
        _inp("delta_gamma", "0.0952", _DL, "Table 2b/2c (Eq 4)")),
        "damping_rotational", "1.2346", _eq17),
    _Spec("ALBACORE m_vir", "18", (_M_A, *_FREQS), "mass", "0.2240", _eq18,
          "measured (coupled) predominant frequencies, as the report did"),
    _Spec("ALBACORE m_vir", "19", _ALB_PLATE, "mass", "0.2735", _eq19,
          "rho/g = 64.15 lb/ft^3 / 32.17 ft/s^2"),
    _Spec("ALBACORE (I_z)_vir", "20", (*_ALB_PLATE, _Y_BAR), "inertia", "0.3085", _eq20,
          "r^2 m_vir ~ 0"),
    _Spec("ALBACORE (I_x)_vir", "21", _ALB_PLATE, "inertia", "1.75", _eq21,
          "Eq 21 reconstructed (printed formula lost): m_vir z^2/16, Eq 19's m_vir, s^2 m_vir ~ 0"),
    _Spec("SAMPSON C in water", "16", (
        _inp("m", "0.8420", "mass", "Table 2i (m_a + m_vir)"),
        _inp("f", "2.18", "frequency", "Table 2g/2i"),
        _inp("delta_v", "0.0402", _DL, "Table 2h/2i (delta_modal average)")),
        "damping_translational", "0.1479", _eq16, "delta_v approximated by delta_modal"),
    _Spec("SAMPSON m_vir", "19", (
        _inp("x_bar", "9.9778", "length", "Table 2j"), _inp("z_bar", "9.25", "length", "Table 2j"),
        _inp("rho", "64.15", "weight_density", "Table 2j"),
        _inp("g", "32.17", "acceleration", "Table 2j")), "mass", "0.6467", _eq19),
    _Spec("ALBACORE m_vir average", "18, 19", (_M_A, *_FREQS, *_ALB_PLATE), "mass", "0.2488",
          _eq18_19_average, "Table 2d: average of the Eq 18 and Eq 19 values"),
)


def _evaluate(spec: _Spec, shift: dict[str, float]) -> float:
    si = {i.name: float(to_si(i.value + shift.get(i.name, 0.0), i.quantity)) for i in spec.inputs}
    return float(from_si(spec.func(si), spec.out))


def _row(spec: _Spec) -> Row:
    value = _evaluate(spec, {})
    sens = []
    for i in spec.inputs:
        h = max(abs(i.value), 1.0) * 1e-6
        sens.append((_evaluate(spec, {i.name: h}) - _evaluate(spec, {i.name: -h})) / (2 * h))
    published = float(spec.published)
    envelope = sum(abs(s) * i.half_ulp for s, i in zip(sens, spec.inputs, strict=True))
    difference = value - published
    return Row(
        quantity=f"{spec.label} (Eq {spec.equation})",
        equation=spec.equation,
        inputs=spec.inputs,
        unit=report_unit(spec.out),
        published=published,
        recomputed=value,
        difference_pct=100 * difference / published,
        sensitivities=tuple(sens),
        rounding_pct=100 * envelope / abs(published),
        consistent=abs(difference) <= envelope + _half_ulp(spec.published) + 1e-12,
        note=spec.note,
    )


def reproduce_table2() -> list[Row]:
    """Recompute every Table 2 result from the report's printed inputs.

    Returns
    -------
    list of Row
        One row per quantity, in the order of Table 2, in report units.
    """
    return [_row(spec) for spec in _SPECS]


# --------------------------------------------------------------------------- consistency

@dataclass(frozen=True)
class PrintedDecrements:
    """One column of a printed decrement table, every number as the text the report prints.

    ``names`` the decrements (``delta_alpha``...), ``values`` their printed values (1),
    ``deviations_pct`` the printed percent deviations from the average, ``average`` and
    ``mean_abs_deviation_pct`` the printed AVERAGE row (value and its ±), ``source`` where in the
    report they stand.
    """

    table: str
    names: tuple[str, ...]
    values: tuple[str, ...]
    deviations_pct: tuple[str, ...]
    average: str
    mean_abs_deviation_pct: str
    source: str

    def as_check(self) -> tuple:
        """The arguments of the consistency check of a decrement table."""
        return (self.table, self.names, self.values, self.deviations_pct, self.average,
                self.mean_abs_deviation_pct)


TABLE_2F_FIXED = PrintedDecrements(
    table="Table 2f stern planes, fixed portion (20 Hz, air)",
    names=("delta_alpha", "delta_beta", "delta_w"),   # no delta_modal: printed "----"
    values=("0.0933", "0.0792", "0.1116"),             # 0.0792 is printed "0.0792."
    deviations_pct=("-1.5", "-16.4", "+11.8"),
    average="0.0947", mean_abs_deviation_pct="11.9",
    source="Report 1836, Table 2 (cont'd) 2. Stern planes (f), 'Logarithmic decrement (20 cps)', "
           "FIXED PORTION columns (shared/reference/dtmb-report-1836.md, lines 323-336)")
"""Table 2f's fixed portion: alpha, beta, w are motions about x, about y and along z (its
footnote: the stern planes' orientation)."""

TABLE_2F_MOVABLE = PrintedDecrements(
    table="Table 2f stern planes, movable portion (20 Hz, air; values from the OCR text only)",
    names=("delta_alpha", "delta_beta", "delta_w", "delta_modal"),
    values=("0.1098", "0.0568", "0.0971", "0.1163"),
    deviations_pct=("+17.7", "-37.7", "+4.1", "+20.6"),
    average="0.0933", mean_abs_deviation_pct="20.4",
    source="Report 1836, Table 2 (cont'd) 2. Stern planes (f), 'Logarithmic decrement (20 cps)', "
           "MOVABLE PORTION columns (shared/reference/dtmb-report-1836.md, lines 323-336)")
"""Table 2f's movable portion; delta_modal is Eq 7's mean over the gages of the stern-plane
system (the report's text, 'one value for the stern plane system')."""


_DECREMENT_TABLES = (
    # (table, names, values, printed deviations %, printed average, printed mean |deviation| %)
    ("Table 2b ALBACORE rudder in air (24.5 Hz)",
     ("delta_gamma", "delta_alpha", "delta_v", "delta_modal"),
     ("0.0524", "0.0671", "0.0758", "0.0783"), ("-23.4", "-2.0", "+10.8", "+14.5"),
     "0.0684", "12.1"),
    ("Table 2b ALBACORE rudder in water (13.0 Hz)",
     ("delta_gamma", "delta_alpha", "delta_v", "delta_modal"),
     ("0.0952", "0.0936", "0.1212", "0.1717"), ("-20.8", "-22.3", "+0.1", "+42.5"),
     "0.1285", "21.3"),
    TABLE_2F_FIXED.as_check(),
    TABLE_2F_MOVABLE.as_check(),
    ("Table 2h SAMPSON rudder delta_modal (2.18 Hz, two records)",
     ("record 1", "record 2"), ("0.02225", "0.0582"), ("-44.8", "+44.8"), "0.0402", "44.8"),
)


def _label(ok: bool) -> str:
    return "consistent" if ok else "INCONSISTENT"


def _check_decrement_table(
    table: str,
    names: tuple[str, ...],
    texts: tuple[str, ...],
    dev_texts: tuple[str, ...],
    avg_text: str,
    mad_text: str,
) -> list[str]:
    values = [float(t) for t in texts]
    printed_devs = [float(t) for t in dev_texts]
    avg, mad = float(avg_text), float(mad_text)
    mean, devs_mean, mad_mean = percent_deviation_from_average(values)
    devs_avg = [100 * (v - avg) / avg for v in values]
    implied = [v / (1 + d / 100) for v, d in zip(values, printed_devs, strict=True)]
    out = []
    # 1. the average
    ok = abs(mean - avg) <= _half_ulp(avg_text) + max(_half_ulp(t) for t in texts)
    msg = (f"{_label(ok)}: {table}: the {len(values)} values ({', '.join(texts)}) average "
           f"{mean:.6f}; printed {avg_text}")
    if not ok:
        centre = float(np.mean(implied))
        closer = "computed" if abs(centre - mean) < abs(centre - avg) else "printed"
        msg += (f" ({100 * (avg - mean) / mean:+.1f} %). The printed deviations imply averages "
                f"{min(implied):.4f} to {max(implied):.4f} (value / (1 + deviation)), closer to "
                f"the "
                f"{closer} average")
    out.append(msg + ".")
    # 2. the deviations, against either the printed or the computed average
    bad = []
    for k, (v, t, d) in enumerate(zip(values, texts, printed_devs, strict=True)):
        tol = 0.05 + 100 * (_half_ulp(t) / v + _half_ulp(avg_text) / avg)
        if min(abs(d - devs_avg[k]), abs(d - devs_mean[k])) > tol:
            bad.append(f"{names[k]} printed {dev_texts[k]} %, computed {devs_avg[k]:+.1f} % from "
                       f"the printed average and {devs_mean[k]:+.1f} % from the computed one")
    if bad:
        out.append(f"INCONSISTENT: {table}: deviations: " + "; ".join(bad) + ".")
    else:
        out.append(f"consistent: {table}: printed deviations ({', '.join(dev_texts)} %) "
                   f"follow from the values.")
    # 3. the mean absolute deviation (the table's '±')
    mad_printed = float(np.mean(np.abs(printed_devs)))
    ok_computed, ok_printed = abs(mad_mean - mad) <= 0.1, abs(mad_printed - mad) <= 0.1
    msg = (f"{_label(ok_computed or ok_printed)}: {table}: printed ±{mad_text} %; mean |deviation| "
           f"is {mad_mean:.2f} % from the values and {mad_printed:.2f} % from the printed "
           f"deviations")
    if ok_computed and not ok_printed:
        msg += ", so the ± was computed from the values and a printed deviation is off"
    out.append(msg + ".")
    return out


def _check_rows(rows: list[Row]) -> list[str]:
    out, exact = [], []
    for r, spec in zip(rows, _SPECS, strict=True):
        if abs(r.recomputed - r.published) <= _half_ulp(spec.published):
            exact.append(r.quantity)
            continue
        shares = [abs(s) * i.half_ulp for s, i in zip(r.sensitivities, r.inputs, strict=True)]
        k = int(np.argmax(shares))
        top, s_top = r.inputs[k], r.sensitivities[k]
        rss = 100 * float(np.sqrt(np.sum(np.square(shares)))) / abs(r.published)
        needed = top.value + (r.published - r.recomputed) / s_top if s_top else float("nan")
        msg = (f"{r.quantity}: published {r.published:g} {r.unit}, recomputed {r.recomputed:.4f} "
               f"({r.difference_pct:+.2f} %); print rounding of the inputs allows "
               f"±{r.rounding_pct:.2f} % worst case (±{rss:.2f} % RSS)")
        if r.consistent:
            msg = (f"DIFFERS within input rounding: {msg}, mostly from {top.name} = {top.text}; "
                   f"the published value would follow from {top.name} = {needed:.5g}")
        else:
            msg = f"INCONSISTENT: {msg}"
        out.append(msg + (f". Note: {r.note}" if r.note else "") + ".")
    out.insert(0, f"consistent: reproduced to the printed digits: {', '.join(exact)}.")
    return out


def _check_table2c_decrements() -> list[str]:
    out = []
    for medium, m_text, f, text_2b, text_2c, c_text in (
        ("air", "0.0878", 24.5, "0.0758", "0.0758", "0.3261"),
        ("water", "0.3613", 13.0, "0.1212", "0.1216", "1.1424"),
    ):
        m = to_si(float(m_text), "mass")
        c_2b = from_si(C_translational(m, f, float(text_2b)), "damping_translational")
        c_2c = from_si(C_translational(m, f, float(text_2c)), "damping_translational")
        if text_2b == text_2c:
            out.append(f"consistent: in {medium}, Table 2c's delta_v = {text_2c} is Table 2b's.")
            continue
        match = "2c" if abs(c_2c - float(c_text)) < abs(c_2b - float(c_text)) else "2b"
        out.append(
            f"INCONSISTENT: in {medium}, Table 2c uses delta_v = {text_2c} where Table 2b gives "
            f"{text_2b}; Eq 16 gives C = {c_2c:.4f} with {text_2c} and {c_2b:.4f} with {text_2b} "
            f"({100 * (c_2b / float(c_text) - 1):+.2f} %); the printed C = {c_text} follows "
            f"Table {match}'s value.")
    return out


def _check_other() -> list[str]:
    out = []
    # Table 2d: average of the two printed m_vir and its deviation
    mean, devs, _ = percent_deviation_from_average([0.2240, 0.2735])
    ok = abs(mean - 0.2488) <= 0.00005 + 1e-12 and abs(abs(devs[0]) - 10) <= 0.5
    out.append(f"{_label(ok)}: Table 2d: (0.2240 + 0.2735)/2 = {mean:.5f} (printed 0.2488), "
               f"deviation ±{abs(devs[0]):.2f} % (printed 10).")
    # Table 2i: m_y = m_a + m_vir
    m_y = 0.1953 + 0.6467
    m_vir_re = next(
        r.recomputed for r in reproduce_table2() if r.quantity == "SAMPSON m_vir (Eq 19)"
    )
    c_re = from_si(C_translational(to_si(0.1953 + m_vir_re, "mass"), 2.18, 0.0402),
                   "damping_translational")
    out.append(f"{_label(abs(m_y - 0.8420) < 1e-9)}: Table 2i: m_a + m_vir = 0.1953 + 0.6467 = "
               f"{m_y:.4f} (printed m_y 0.8420); with the recomputed m_vir {m_vir_re:.4f} it would "
               f"be {0.1953 + m_vir_re:.4f} and C = {c_re:.4f}.")
    # Eq 19: the density each printed value implies
    k = from_si(RHO_REPORT_KG_M3, "mass_density")
    implied = {ship: p / (np.pi / 4 * x**2 * z) for ship, p, x, z in (
        ("ALBACORE", 0.2735, 6.2084, 10.1667), ("SAMPSON", 0.6467, 9.9778, 9.25))}
    a, s = implied["ALBACORE"], implied["SAMPSON"]
    ok = abs(a / s - 1) <= 2 * 0.00005 / 0.2735 + 2 * 0.00005 / 0.6467
    out.append(f"{_label(ok)}: Eq 19: the printed m_vir imply rho/g = {a:.4e} (ALBACORE) and "
               f"{s:.4e} (SAMPSON) ton s^2/ft^4, {100 * (s / a - 1):+.2f} % apart, against "
               f"{k:.4e} from 64.15/32.17/2240"
               + ("." if ok else "; no single density gives both."))
    return out


def check_report_consistency() -> list[str]:
    """The report's own (in)consistencies, each computed from its printed numbers.

    Returns
    -------
    list of str
        One statement per check, starting with ``"INCONSISTENT"``, ``"DIFFERS within input
        rounding"`` or ``"consistent"``: decrement averages, deviations and ± entries of
        Table 2b, 2f, 2h; Table 2c's decrements against Table 2b's; each Table 2 result against
        its inputs; Table 2d's average, Table 2i's m_y, and the density implied by Eq 19.
    """
    out = []
    for table in _DECREMENT_TABLES:
        out.extend(_check_decrement_table(*table))
    out.extend(_check_table2c_decrements())
    out.extend(_check_rows(reproduce_table2()))
    out.extend(_check_other())
    return out
