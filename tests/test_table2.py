"""Report 1836 Table 2 recomputed from its own inputs, against the spec page and the report.

Reference numbers: /work/shared/spec/report-1836-equations.md, "Reference values (Table 2)"
(published = the report's Table 2; recomputed = checked numerically on that page).
"""

from __future__ import annotations

import math

import pytest

from ramdaq.analysis.model import units as u
from ramdaq.analysis.report1836.damping import C_translational, c_rotational
from ramdaq.analysis.report1836.table2 import (
    TABLE_2F_FIXED,
    TABLE_2F_MOVABLE,
    Row,
    check_report_consistency,
    reproduce_table2,
)
from ramdaq.analysis.report1836.virtual_mass import (
    Ix_vir,
    Iz_vir_elliptic,
    m_vir_flat_plate,
    m_vir_from_frequencies,
)

# quantity: (published, spec page's recomputed value), report units
SPEC_TABLE = {
    # Table 2c, Eq 16: m_a 0.0878 ton s^2/ft, f 24.5 Hz (2a), delta_v 0.0758 (2b) -> ton s/ft
    "ALBACORE C in air (Eq 16)": (0.3261, 0.3261),
    # Table 2c, Eq 16: m_y 0.3613, f 13.0, delta_v 0.1216 (2c; 2b prints 0.1212)
    "ALBACORE C in water (Eq 16)": (1.1424, 1.1423),
    # Table 2c, Eq 17: I_z 0.3320, I_xz -0.1687, a1/g1 -1.5877, f 24.5, delta_gamma 0.0524
    # -> ft ton s
    "ALBACORE c in air (Eq 17)": (0.1655, 0.1647),
    # Table 2c, Eq 17: I_z 0.6446, I_xz -0.1514, a1/g1 -0.9631, f 13.0, delta_gamma 0.0952
    "ALBACORE c in water (Eq 17)": (1.2346, 1.2346),
    # Table 2d, Eq 18: m_a 0.0878, f_air 24.5, f_water 13.0 -> ton s^2/ft
    "ALBACORE m_vir (Eq 18)": (0.2240, 0.2240),
    # Table 2d, Eq 19: x_bar 6.2084 ft, z_bar 10.1667 ft, rho 64.15 lb/ft^3, g 32.17 ft/s^2
    "ALBACORE m_vir (Eq 19)": (0.2735, 0.2740),
    # Table 2d, Eq 20: x_bar, y_bar 1.1250 ft, z_bar; r^2 m_vir ~ 0 -> ft ton s^2
    "ALBACORE (I_z)_vir (Eq 20)": (0.3085, 0.3087),
    # Table 2d, Eq 21 (reconstructed): x_bar, z_bar; s^2 m_vir ~ 0
    "ALBACORE (I_x)_vir (Eq 21)": (1.75, 1.770),
    # Table 2i, Eq 16: m_y 0.8420, f 2.18 (2g), delta 0.0402 (2h)
    "SAMPSON C in water (Eq 16)": (0.1479, 0.1476),
    # Table 2j, Eq 19: x_bar 9.9778 ft, z_bar 9.25 ft
    "SAMPSON m_vir (Eq 19)": (0.6467, 0.6439),
}


def _agree_4_sig(x: float, ref: float) -> bool:
    """x equals ref to four significant digits (half a unit in the 4th digit of ref)."""
    return abs(x - ref) <= 0.5 * 10 ** (math.floor(math.log10(abs(ref))) - 3)


@pytest.fixture(scope="module")
def rows() -> dict[str, Row]:
    return {row.quantity: row for row in reproduce_table2()}


def test_every_spec_quantity_is_reproduced(rows: dict[str, Row]) -> None:
    assert set(SPEC_TABLE) <= set(rows)


@pytest.mark.parametrize("quantity", sorted(SPEC_TABLE))
def test_row_matches_spec_and_report(rows: dict[str, Row], quantity: str) -> None:
    published, recomputed = SPEC_TABLE[quantity]
    row = rows[quantity]
    assert row.published == published
    assert _agree_4_sig(row.recomputed, recomputed), (row.recomputed, recomputed)
    assert abs(row.recomputed / published - 1) <= 0.015
    assert row.difference_pct == pytest.approx(100 * (row.recomputed - published) / published)


def test_table_2d_average_row(rows: dict[str, Row]) -> None:
    # Table 2d: average of Eq 18 and Eq 19 m_vir, printed 0.2488
    row = rows["ALBACORE m_vir average (Eq 18, 19)"]
    eq18, eq19 = rows["ALBACORE m_vir (Eq 18)"], rows["ALBACORE m_vir (Eq 19)"]
    assert row.recomputed == pytest.approx((eq18.recomputed + eq19.recomputed) / 2)
    assert abs(row.difference_pct) < 0.1


def test_rows_carry_report_units_and_sources(rows: dict[str, Row]) -> None:
    assert rows["ALBACORE C in air (Eq 16)"].unit == "ton·s/ft"
    assert rows["ALBACORE c in water (Eq 17)"].unit == "ft·ton·s"
    assert rows["SAMPSON m_vir (Eq 19)"].unit == "ton·s^2/ft"
    for row in rows.values():
        assert row.inputs and all(i.source.startswith("Table 2") for i in row.inputs)
        assert all(i.unit == u.report_unit(i.quantity) for i in row.inputs)


def test_rows_are_computed_in_si() -> None:
    """The recomputation goes through the SI functions, not report-unit shortcuts."""
    m = u.to_si(0.3613, "mass")
    assert u.from_si(C_translational(m, 13.0, 0.1216), "damping_translational") == pytest.approx(
        2 * 0.3613 * 13.0 * 0.1216, rel=1e-12
    )
    iz, ixz = u.to_si(0.6446, "inertia"), u.to_si(-0.1514, "inertia")
    c = u.from_si(c_rotational(iz, ixz, -0.9631, 13.0, 0.0952), "damping_rotational")
    assert c == pytest.approx(2 * (0.6446 - 0.1514 * 0.9631) * 13.0 * 0.0952, rel=1e-12)
    # Eq 19 in report units: (pi/4)(rho/g) x^2 z with rho/g in ton s^2/ft^4
    rho_g = 64.15 / 32.17 / 2240
    x_bar, y_bar, z_bar = (u.to_si(x, "length") for x in (6.2084, 1.1250, 10.1667))
    m_vir = m_vir_flat_plate(u.RHO_REPORT_KG_M3, x_bar, z_bar)
    assert u.from_si(m_vir, "mass") == pytest.approx(math.pi / 4 * rho_g * 6.2084**2 * 10.1667)
    iz_vir = Iz_vir_elliptic(u.RHO_REPORT_KG_M3, x_bar, y_bar, z_bar)
    assert u.from_si(iz_vir, "inertia") == pytest.approx(0.3087, abs=5e-5)
    ix_vir = u.from_si(Ix_vir(m_vir, z_bar), "inertia")
    assert ix_vir == pytest.approx(1.770, abs=5e-4)
    m_a = u.to_si(0.0878, "mass")
    m_vir_18 = u.from_si(m_vir_from_frequencies(m_a, 24.5, 13.0), "mass")
    assert m_vir_18 == pytest.approx(0.2240, abs=5e-5)


def test_rounding_envelope(rows: dict[str, Row]) -> None:
    # f = 24.5 Hz printed to 0.1 Hz alone moves Eq 16 by 0.05/24.5 = 0.20 %
    assert rows["ALBACORE C in air (Eq 16)"].rounding_pct > 0.2
    assert rows["ALBACORE C in air (Eq 16)"].consistent
    assert not rows["ALBACORE (I_x)_vir (Eq 21)"].consistent  # 1.770 vs 1.75 is not rounding


# --------------------------------------------------------------------------- consistency


@pytest.fixture(scope="module")
def statements() -> list[str]:
    return check_report_consistency()


def _find(statements: list[str], *needles: str) -> str:
    hits = [s for s in statements if all(n in s for n in needles)]
    assert len(hits) == 1, (needles, hits)
    return hits[0]


def test_in_water_decrement_average(statements: list[str]) -> None:
    s = _find(statements, "in water (13.0 Hz)", "average 0.120425", "printed 0.1285")
    assert s.startswith("INCONSISTENT")
    assert "imply averages 0.1202 to 0.1211" in s


def test_table_2c_delta_v(statements: list[str]) -> None:
    s = _find(statements, "uses delta_v = 0.1216", "Table 2b gives 0.1212")
    assert s.startswith("INCONSISTENT") and "C = 1.1423 with 0.1216" in s and "Table 2c's" in s


def test_eq21_reconstruction_difference(statements: list[str]) -> None:
    s = _find(statements, "(I_x)_vir (Eq 21)")
    assert s.startswith("INCONSISTENT") and "published 1.75" in s and "recomputed 1.7700" in s
    assert "+1.14 %" in s and "reconstructed" in s


def test_sampson_average_checks_out(statements: list[str]) -> None:
    s = _find(statements, "SAMPSON", "average 0.040225")
    assert s.startswith("consistent") and "printed 0.0402" in s


def test_albacore_c_in_air(statements: list[str]) -> None:
    s = _find(statements, "ALBACORE c in air (Eq 17)")
    assert "published 0.1655" in s and "recomputed 0.1647" in s and "-0.47 %" in s
    assert not s.startswith("consistent")


def test_other_findings(statements: list[str]) -> None:
    assert _find(statements, "fixed portion", "delta_w printed +11.8").startswith("INCONSISTENT")
    assert _find(statements, "in air (24.5 Hz)", "printed ±12.1").startswith("INCONSISTENT")
    assert _find(statements, "Table 2d:", "0.24875").startswith("consistent")
    assert _find(statements, "Eq 19: the printed m_vir imply").startswith("INCONSISTENT")
    assert all(s.split(":")[0] in {"consistent", "INCONSISTENT", "DIFFERS within input rounding"}
               for s in statements)


# --------------------------------------------------------------------------- Table 2f

def test_table_2f_fixtures_as_printed() -> None:
    # the fixtures are the printed text (source: Report 1836 Table 2f, lines 323-336 of
    # shared/reference/dtmb-report-1836.md); every value is a decrement, every deviation a %
    assert TABLE_2F_FIXED.values == ("0.0933", "0.0792", "0.1116")
    assert TABLE_2F_MOVABLE.values == ("0.1098", "0.0568", "0.0971", "0.1163")
    assert "delta_modal" not in TABLE_2F_FIXED.names  # printed "----"
    for t in (TABLE_2F_FIXED, TABLE_2F_MOVABLE):
        assert len(t.names) == len(t.values) == len(t.deviations_pct)
        assert "Table 2" in t.source and "lines 323-336" in t.source


def test_table_2f_fixed_portion(statements: list[str]) -> None:
    # 0.0933, 0.0792, 0.1116 average 0.0947 as printed, and the ± 11.9 % is their mean
    # |deviation|; but delta_w = 0.1116 is +17.8 % above 0.0947, not the printed +11.8 %
    avg = _find(statements, "fixed portion", "average 0.094700")
    assert avg.startswith("consistent") and "printed 0.0947" in avg
    dev = _find(statements, "fixed portion", "deviations:")
    assert dev.startswith("INCONSISTENT") and "delta_w printed +11.8 %, computed +17.8 %" in dev
    assert "delta_alpha" not in dev and "delta_beta" not in dev
    mad = _find(statements, "fixed portion", "printed ±11.9")
    assert mad.startswith("consistent") and "11.90 % from the values" in mad
    assert "a printed deviation is off" in mad


def test_table_2f_movable_portion(statements: list[str]) -> None:
    # the four printed values average 0.0950, 1.8 % above the printed 0.0933; delta_beta's and
    # delta_modal's deviations fit neither average, and the ± 20.4 % fits neither mean
    avg = _find(statements, "movable portion", "average 0.095000")
    assert avg.startswith("INCONSISTENT") and "printed 0.0933 (-1.8 %)" in avg
    dev = _find(statements, "movable portion", "deviations:")
    assert dev.startswith("INCONSISTENT")
    assert "delta_beta printed -37.7 %" in dev and "delta_modal printed +20.6 %" in dev
    assert "delta_alpha" not in dev and "delta_w" not in dev
    mad = _find(statements, "movable portion", "printed ±20.4")
    assert mad.startswith("INCONSISTENT") and "20.11 % from the values" in mad
