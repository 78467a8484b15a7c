"""A stern plane is the rudder's chain with its axes turned: the rig says what the surface is.

The strongest check is physics-neutral: the ALBACORE-like rudder rewritten as a stern plane in
ship axes (stock athwartship, motions alpha, beta, w) must give the very same model -- mass,
stiffness and damping matrices and every gage's row of the output map -- on either side of the
hull, since a proper rotation of axes changes no physics.
"""

import tomllib

import numpy as np
import pytest

from ramdaq.analysis.model.rig import RigError, parse_rig
from ramdaq.analysis.model.structure import build_model
from ramdaq.analysis.model.surface import Surface
from tests.conftest import RIGS

PLANE_KEYS = {"Iz_kg_m2": "Iy_kg_m2", "Ixz_kg_m2": "Ixy_kg_m2", "attach_z_m": "attach_m"}
BODIES = {"rudder": "movable", "stock": "stock", "hull": "fixed"}


def _toml_value(v) -> str:
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(c) for c in v) + "]"
    return repr(v)


def _dumps(doc: dict, prefix: str = "") -> str:
    """Just enough TOML for a rig document: scalars, tables, arrays of tables."""
    lines = [f"{k} = {_toml_value(v)}" for k, v in doc.items()
             if not isinstance(v, dict) and not (isinstance(v, list) and v and isinstance(v[0], dict))]
    for k, v in doc.items():
        if isinstance(v, dict):
            lines += [f"\n[{prefix}{k}]", _dumps(v, f"{prefix}{k}.")]
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for item in v:
                lines += [f"\n[[{prefix}{k}]]", _dumps(item, f"{prefix}{k}.")]
    return "\n".join(lines)


def as_stern_plane(rudder_text: str, side: str) -> str:
    """A rudder's rig text rewritten as a stern plane on ``side``, in ship axes."""
    surface = Surface("stern_plane", side)
    doc = tomllib.loads(rudder_text)
    doc["surface"] = {"kind": "stern_plane", "side": side}
    doc["plane"] = {PLANE_KEYS.get(k, k): v for k, v in doc.pop("rudder").items()}
    signs = surface.signs
    for m in doc["hull"]["modes"]:
        m["w_b"] = signs["v"] * m.pop("v_b")
        m["beta_b"] = signs["gamma"] * m.pop("gamma_b")
    imp = doc["impact"]
    imp["location_m"] = list(surface.to_ship(imp["location_m"]))
    imp["direction"] = surface.ship_axis(imp.get("direction", "y"))
    for g in doc["gages"]:
        g["position_m"] = list(surface.to_ship(g["position_m"]))
        g["axis"] = surface.ship_axis(g["axis"])
        g["body"] = BODIES[g["body"]]
    return _dumps(doc)


@pytest.mark.parametrize("side", ["starboard", "port"])
def test_stern_plane_is_the_rudder_turned(side):
    text = (RIGS / "albacore.toml").read_text()
    rudder = parse_rig(text, "albacore.toml")
    plane = parse_rig(as_stern_plane(text, side), "plane.toml")
    assert rudder.surface.kind == "rudder" and plane.surface == Surface("stern_plane", side)
    a, b = build_model(rudder), build_model(plane)
    for name in ("M", "K", "C", "gage_dofs"):
        # the same numbers through a rotation by exact quarter turns: only rounding differs
        np.testing.assert_allclose(getattr(b, name), getattr(a, name), rtol=1e-12, atol=1e-9,
                                   err_msg=name)
    assert plane.impact == rudder.impact
    assert [(g.body, g.axis) for g in plane.gages] == [(g.body, g.axis) for g in rudder.gages]


def test_stern_plane_axes_in_ship_terms():
    s = Surface("stern_plane", "starboard")
    # the stock runs inboard along -y: the surface frame's z (towards the hull) is ship -y,
    # its normal y is ship z (so w = v), and a turn about ship y is minus one about the stock
    assert s.to_ship((0.0, 0.0, 1.0)) == (0.0, -1.0, 0.0)
    assert s.to_ship((0.0, 1.0, 0.0)) == (0.0, 0.0, 1.0)
    assert s.signs == {"v": 1.0, "gamma": -1.0, "alpha": 1.0}
    assert Surface("stern_plane", "port").signs == {"v": -1.0, "gamma": 1.0, "alpha": 1.0}
    assert s.surface_axis("z") == "y" and s.ship_axis("z") == "-y"
    p = (0.3, -1.2, 0.4)
    assert np.allclose(s.to_ship(s.to_surface(p)), p)


def test_labels_follow_the_surface():
    s = Surface("stern_plane")
    assert [s.label(n) for n in ("v_2_6", "gamma", "alpha", "v_R_4_8", "gamma_R", "delta_v",
                                 "alpha1_over_gamma1", "I_z_kg_m2", "I_xz_kg_m2", "m_vir",
                                 "delta_modal", "c_N_m_s_per_rad", "hull_motions")] == [
        "w_2_6", "beta", "alpha", "w_R_4_8", "beta_R", "delta_w", "alpha1_over_beta1",
        "I_y_kg_m2", "I_xy_kg_m2", "m_vir", "delta_modal", "c_N_m_s_per_rad",
        "fixed_portion_motions"]
    assert Surface().label("v_2_6") == "v_2_6"
    # alpha1/beta1 = -alpha1/gamma1 on the starboard side, where beta = -gamma
    assert s.relabel({"alpha1_over_gamma1": -1.5, "motions": {"gamma": 1}}) == {
        "alpha1_over_beta1": 1.5, "motions": {"beta": 1}}
    assert s.body("rudder") == "movable" and s.body("hull") == "fixed"
    assert s.words("gamma_b left out: hull gages 5 and 13 are not level") == \
        "beta_b left out: fixed portion gages 5 and 13 are not level"
    assert s.words("stock lengths: not computed, a stock, rudder-top or hull gage is unusable") \
        == "stock lengths: not computed, a stock, plane-root or fixed portion gage is unusable"
    assert Surface().words("a rudder or hull gage") == "a rudder or hull gage"


@pytest.mark.parametrize(("old", "new", "message"), [
    ('kind = "stern_plane"', 'kind = "canard"',
     r"surface\.kind: 'canard' is not one of rudder, stern_plane"),
    ('side = "starboard"', 'side = "aft"', r"surface\.side: 'aft' is not one of starboard, port"),
    ('body = "movable"', 'body = "rudder"', r"gages\[0\]\.body: 'rudder' is not one of movable, "
                                            r"stock, fixed \(a stern plane's bodies\)"),
    ("mass_kg = 1200.0", "mass_kg = -1200.0", r"plane\.mass_kg: must be positive"),
    ("Iy_kg_m2 = 144.83", "Iy_kg_m2_ = 144.83", r"plane\.Iy_kg_m2: missing"),
    ("w_b = 1.0", "v_b = 1.0", r"hull\.modes\[0\]\.v_b: a stern plane's hull modes give w_b"),
    ("beta_b = 0.10", "beta_b = true", r"hull\.modes\[0\]\.beta_b: expected a finite number"),
    ("Ixy_kg_m2 = -40.0", "Ixy_kg_m2 = -40.0\nIz_kg_m2 = 100.0",
     r"plane\.Iz_kg_m2: a rudder's key; a stern plane's is Iy_kg_m2 \(about the stock\)"),
])
def test_stern_plane_errors_name_its_own_fields(old, new, message):
    text = (RIGS / "stern_plane.toml").read_text()
    assert old in text
    with pytest.raises(RigError, match=rf"^bad\.toml: {message}"):
        parse_rig(text.replace(old, new, 1), "bad.toml")


def test_rudder_has_no_side():
    text = (RIGS / "albacore.toml").read_text()
    with pytest.raises(RigError, match=r"^bad\.toml: surface\.side: only a stern plane has a side"):
        parse_rig(text + '\n[surface]\nside = "port"\n', "bad.toml")


TABLE_2E_HZ = (20.0, 77.0, 120.0)
"""Report 1836, Table 2e: the stern planes' measured frequencies in air, 20 (predominant)."""


def test_stern_plane_model_gives_table_2e():
    from ramdaq.analysis.model.rig import load_rig
    from ramdaq.analysis.model.rig_modes import modes_in

    rig = load_rig("stern_plane")
    assert rig.surface.kind == "stern_plane" and rig.medium == "air"
    m = modes_in(rig, "air")
    f = m.table.frequency_hz
    for target in TABLE_2E_HZ:  # the brief's (issue 18's) 2 % on each measured frequency
        assert np.min(np.abs(f / target - 1)) < 0.02, (target, f)
    assert abs(m.predominant_hz / 20.0 - 1) < 0.02
    # damping tuned to Table 2f's 0.0933 (both portions' average); C rounded to 3 figures
    # moves it by under 0.1 %, so 1 % holds it to the tuning, not to chance
    assert m.table.decrement[m.predominant] == pytest.approx(0.0933, rel=0.01)
    with pytest.raises(RigError, match=r"damping\.water: missing"):
        rig.with_medium("water")  # tested in air only


def test_stern_plane_geometry_errors_in_its_own_terms():
    from ramdaq.analysis.model.geometry import gage_geometry

    text = (RIGS / "stern_plane.toml").read_text()
    for old in ("position_m = [0.0, -0.70, 0.0]", "position_m = [0.0, 0.70, 0.0]"):  # 2 and 6
        assert old in text
        text = text.replace(old, old.replace("[0.0,", "[0.05,"))
    rig = parse_rig(text, "bad.toml")
    with pytest.raises(RigError, match=r"^bad\.toml: gage 2 is off the line along the stock "
                                       r"through the centre of mass \(\(0\.05, -0\.7, 0\.0\)\)"):
        gage_geometry(rig)
