"""Case files: units, validation messages (file, field path, what was wrong, what is right), extends."""
from __future__ import annotations

import math
import textwrap

import pytest

from orchestrator.case import CaseError, load_case
from orchestrator.units import UnitError, to_si

GOOD = """
name: probe
material: {density: 2500 kg/m^3, youngs_modulus: 63 GPa, poisson_ratio: 0.2}
contact: {restitution: 0.5, friction: 0.58}
scene: {kind: impact, target: plane, radius: 30 um, speed: 0.1 m/s}
"""


def write(tmp_path, text, name="case.yaml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


@pytest.mark.parametrize("text,kind,si", [
    ("30 um", "length", 30e-6), ("0.5 kPa", "pressure", 500.0), ("39.5 deg", "angle", math.radians(39.5)),
    ("0.1 deg/s", "angular_velocity", math.radians(0.1)), ("2.65 g/cm^3", "density", 2650.0),
    ("92.1 GPa", "pressure", 92.1e9), (0, "length", 0.0), ("1 uN", "force", 1e-6),
])
def test_units_convert_to_si(text, kind, si):
    assert to_si(text, kind) == pytest.approx(si, rel=1e-12)


@pytest.mark.parametrize("value,kind,words", [
    (5, "length", "has no unit"), ("5 s", "length", "not a length"), ("abc", "length", "cannot read"),
    (39.5, "angle", "has no unit"), ("3 m", "angle", "not an angle"),
])
def test_bad_units_are_refused_with_a_fix(value, kind, words):
    with pytest.raises(UnitError, match=words) as exc:
        to_si(value, kind)
    assert "e.g." in str(exc.value)


def test_good_case_loads_in_si(tmp_path):
    case = load_case(write(tmp_path, GOOD))
    assert case.scene.radius == pytest.approx(30e-6)
    assert case.material.youngs_modulus == pytest.approx(63e9)


BAD = [
    # (replace this, with that, expected field path, expected words)
    ("poisson_ratio: 0.2", "poisson_ratio: 0.5", "material.poisson_ratio", "Poisson's ratio must lie in (-1, 0.5)"),
    ("restitution: 0.5", "restitution: 1.2", "contact.restitution", "restitution must lie in (0, 1]"),
    ("restitution: 0.5", "restitution: 0", "contact.restitution", "restitution must lie in (0, 1]"),
    ("radius: 30 um", "radius: -30 um", "scene.radius", "must be positive"),
    ("radius: 30 um", "radius: 30", "scene.radius", "has no unit"),
    ("radius: 30 um", "radius: 30 kPa", "scene.radius", "not a length"),
    ("youngs_modulus: 63 GPa", "youngs_modulus: 63 GPa, colour: red", "material.colour", "unknown field"),
    ("youngs_modulus: 63 GPa", "youngs_modulus: 63 GPa, poison_ratio: 0.2", "material.poison_ratio", "did you mean 'poisson_ratio'"),
    ("density: 2500 kg/m^3, ", "", "material.density", "required field is missing"),
    ("friction: 0.58", "friction: lots", "contact.friction", "valid number"),
    ("kind: impact", "kind: pendulum", "scene.kind", "'pendulum' is not a scene; set it to one of"),
    ("kind: impact", "kind: impakt", "scene.kind", "did you mean 'impact'? set it to one of impact, plane_shear"),
    ("friction: 0.58}", "friction: 0.58}\nanalysis: [d2minn]", "analysis", "unknown analysis 'd2minn'"),
    ("friction: 0.58}", "friction: 0.58}\nengine_options: {timeout: -3 min}", "engine_options.timeout",
     "must be positive"),
    ("friction: 0.58}", "friction: 0.58}\ntimestep: {dt: -1 ns}", "timestep.dt", "must be positive"),
]


@pytest.mark.parametrize("old,new,path,words", BAD, ids=[b[2] + ":" + b[3][:20] for b in BAD])
def test_bad_input_names_file_field_and_fix(tmp_path, old, new, path, words):
    assert old in GOOD
    p = write(tmp_path, GOOD.replace(old, new))
    with pytest.raises(CaseError) as exc:
        load_case(p)
    msg = str(exc.value)
    assert str(p) in msg
    assert path in msg, msg
    assert words in msg, msg


def test_time_step_above_critical_is_refused_with_numbers(tmp_path):
    p = write(tmp_path, GOOD + "timestep: {dt: 1 ms}\n")
    with pytest.raises(CaseError) as exc:
        load_case(p)
    msg = str(exc.value)
    assert "above the critical time step" in msg and "Rayleigh" in msg and "timestep.fraction" in msg


def test_time_step_fraction_above_one_is_refused(tmp_path):
    p = write(tmp_path, GOOD + "timestep: {fraction: 1.5}\n")
    with pytest.raises(CaseError, match="timestep.fraction"):
        load_case(p)


def test_extends_merges_and_overrides(tmp_path):
    write(tmp_path, GOOD, "base.yaml")
    child = write(tmp_path, """
        extends: base.yaml
        name: child
        contact: {restitution: 0.8}
        scene: {speed: 0.3 m/s}
        """, "child.yaml")
    case = load_case(child)
    assert case.name == "child"
    assert case.contact.restitution == 0.8
    assert case.contact.friction == 0.58          # kept from the base
    assert case.scene.speed == pytest.approx(0.3)
    assert case.scene.radius == pytest.approx(30e-6)


def test_extends_cycle_and_missing_parent(tmp_path):
    write(tmp_path, "extends: b.yaml\nname: a\n", "a.yaml")
    write(tmp_path, "extends: a.yaml\nname: b\n", "b.yaml")
    with pytest.raises(CaseError, match="cycle"):
        load_case(tmp_path / "a.yaml")
    with pytest.raises(CaseError, match="no such file"):
        load_case(write(tmp_path, "extends: nowhere.yaml\n", "c.yaml"))


def test_resolved_case_round_trips(tmp_path):
    from orchestrator.case import case_from_dict
    case = load_case(write(tmp_path, GOOD))
    again = case_from_dict(case.resolved())
    assert again.resolved() == case.resolved()
    assert again.scene.radius == case.scene.radius


def test_every_shipped_case_validates():
    from pathlib import Path
    root = Path(__file__).parents[1] / "cases"
    # cases/shapes/ holds clump shape libraries (orchestrator.clumps), not cases
    cases = [p for p in root.rglob("*.yaml") if not p.name.startswith("_") and "shapes" not in p.relative_to(root).parts]
    assert cases
    for p in cases:
        load_case(p)


@pytest.mark.parametrize("base, scene, words", [
    ("shear_cell_smoke.yaml", "{psd: {d_max: 5 mm}}", ["scene", "particles larger than their container"]),
    # the medium case at size_scale 0.5 (0.36 mm, the seed's 0.1 mm gap) left the pistons no room for
    # the vanes; it validated and then failed while meshing the pistons
    ("shear_cell_medium.yaml", "{cell_diameter: 0.36 mm}", ["scene.cell_diameter", "widen the cell to more than 0.38 mm"]),
])
def test_a_container_too_small_for_its_contents_is_refused(tmp_path, base, scene, words):
    from pathlib import Path
    case = tmp_path / "small.yaml"
    case.write_text(f"extends: {Path(__file__).parents[1] / 'cases' / base}\nscene: {scene}\n")
    with pytest.raises(CaseError) as exc:
        load_case(case)
    msg = str(exc.value)
    assert str(case) in msg and all(w in msg for w in words)


@pytest.mark.parametrize("base, section, fix", [
    ("triaxial_smoke.yaml", "scene: {isotropic: {max_chunks: zero}}",
     "write scene.isotropic.max_chunks as an integer, e.g. 60"),
    ("shear_cell_smoke.yaml", "output: {velocity: maybe}", "write output.velocity as true or false, e.g. true"),
])
def test_a_value_of_the_wrong_type_is_answered_in_the_case_files_words(tmp_path, base, section, fix):
    """The fix names the type as a case file writes it: "an integer", YAML's true or false."""
    from pathlib import Path
    case = tmp_path / "wrong.yaml"
    case.write_text(f"extends: {Path(__file__).parents[1] / 'cases' / base}\n{section}\n")
    with pytest.raises(CaseError) as exc:
        load_case(case)
    assert str(case) in str(exc.value) and fix in str(exc.value), str(exc.value)
