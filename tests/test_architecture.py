"""The boundary between scenes and engines (issue #13, docs/architecture.md), without an engine:
registries, refused case terms, declared control names, the layering (import-linter), and the
folded file discovery of the engine packages."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from engines.liggghts.segments import wall_rows as liggghts_wall_rows
from engines.yade.output import ChunkOutput, chunk_files
from engines.yade.output import wall_rows as yade_wall_rows
from orchestrator.case import CaseError, load_case
from orchestrator.registry import engine_names, get_engine, get_scene, scene_kinds
from orchestrator.scenes import plane_shear
from orchestrator.scenes.base import OPTIONAL_TERMS

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"


def test_registries_list_the_installed_engines_and_scenes():
    assert engine_names() == ("lammps", "liggghts", "yade")
    assert scene_kinds() == ("impact", "plane_shear", "shear_cell", "triaxial")
    for name in engine_names():
        assert get_engine(name).name == name
    for kind in scene_kinds():
        sc = get_scene(kind)
        assert sc.kind == kind and sc.section.model_fields["kind"].annotation.__args__ == (kind,)
        assert set(sc.honoured) <= set(OPTIONAL_TERMS), kind


def test_unknown_engine_is_refused_naming_the_installed_ones():
    with pytest.raises(CaseError, match=r"engines: unknown engine 'pfc'; installed engines: lammps, liggghts, yade"):
        load_case(CASES / "triaxial_smoke.yaml", overrides={"engines": ["pfc"]})


@pytest.mark.parametrize("case, term, override", [
    ("triaxial_smoke.yaml", "contact.adhesion", {"contact": {"adhesion": {"force": "0.1 uN"}}}),
    ("triaxial_smoke.yaml", "contact.rolling", {"contact": {"rolling": {"coefficient": 0.1}}}),
    ("triaxial_smoke.yaml", "contact.torsion", {"contact": {"torsion": {"coefficient": 0.1}}}),
    ("triaxial_smoke.yaml", "gravity", {"gravity": "9.81 m/s^2"}),
    ("verification/chung_ooi_1_sphere_sphere_glass.yaml", "contact.adhesion",
     {"contact": {"adhesion": {"force": "0.1 uN"}}}),
    ("verification/chung_ooi_1_sphere_sphere_glass.yaml", "contact.rolling", {"contact": {"rolling": {"coefficient": 0.1}}}),
    ("plane_shear_smoke.yaml", "output.contacts", {"output": {"contacts": True}}),
    ("triaxial_smoke.yaml", "initial_packing", {"initial_packing": {"frames": "scan.h5"}}),   # prepare packs its own
])
def test_silent_physics_is_refused(case, term, override):
    """A term no deck of the scene contains (neither LIGGGHTS' nor YADE's) is refused when the case
    loads, naming the field and the scene; before, triaxial and impact cases with adhesion or rolling
    validated and ran without them."""
    kind = load_case(CASES / case).scene.kind
    with pytest.raises(CaseError) as exc:
        load_case(CASES / case, overrides=override)
    msg = str(exc.value)
    assert f"{term.split(':')[0]}: the {kind} scene does not realise '{term}'" in msg
    assert "silently" in msg


def test_honoured_terms_still_load():
    case = load_case(CASES / "shear_cell_smoke.yaml", overrides={"contact": {"rolling": {"coefficient": 0.1}}})
    assert case.contact.rolling.coefficient == 0.1


def test_every_scene_declares_its_controls_with_units():
    for kind in scene_kinds():
        sc = get_scene(kind)
        assert all(isinstance(u, str) and u for u in sc.controls.values()), kind
    assert get_scene("plane_shear").controls == {"shear_strain": "1", "stage": "1"}
    assert get_scene("shear_cell").controls == {"angle": "rad", "stage": "1"}
    assert {"axial_strain", "sigma1", "sigma3"} <= set(get_scene("triaxial").controls)


def test_plane_shear_writes_the_control_analysis_and_compare_read():
    """Plane shear wrote its strain as the control ``strain`` while analysis and compare order states
    by ``shear_strain``, so plane-shear states were matched by time. The controls the scene computes
    are the ones it declares, and its strain is the one compare aligns on."""
    from orchestrator.compare.align import CONTROL_ORDER
    params = {"dt": 1e-6, "scene": {"stages": {"shear": [100, 1100]}, "shear_rate": 10.0,
                                    "frame_steps": [100, 600, 1100], "frame_stage": [1, 2, 2]}}
    ctl = plane_shear._controls(params, np.array([100, 600, 1100]))
    assert set(ctl) == set(get_scene("plane_shear").controls)
    assert "shear_strain" in CONTROL_ORDER
    np.testing.assert_allclose(ctl["shear_strain"], [0.0, 500 * 1e-6 * 10.0, 1000 * 1e-6 * 10.0])


def test_yade_chunks_are_found_in_numeric_order(tmp_path):
    """chunk.99 precedes chunk.100 (a lexical sort put it last); an iteration written twice (a
    resumed segment) is taken once, from its first chunk."""
    (tmp_path / "dump").mkdir()
    np.savez(tmp_path / "dump" / "chunk.100.npz", iter=np.array([100, 150]), position=np.full((2, 1, 3), 2.0))
    np.savez(tmp_path / "dump" / "chunk.99.npz", iter=np.array([50, 100]), position=np.full((2, 1, 3), 1.0))
    assert [p.name for p in chunk_files(tmp_path)] == ["chunk.99.npz", "chunk.100.npz"]
    out = ChunkOutput(tmp_path)
    assert out.frame_steps.tolist() == [50, 100, 150]
    assert out.positions(1)[0, 0] == 1.0 and out.positions(2)[0, 0] == 2.0


def test_wall_rows_in_numeric_file_order(tmp_path):
    np.savetxt(tmp_path / "walls.000000000200.txt", [[200, 1.0]])
    np.savetxt(tmp_path / "walls.000000000000.txt", [[0, 0.5], [100, 0.7]])
    assert liggghts_wall_rows(tmp_path)[:, 0].tolist() == [0, 100, 200]
    np.save(tmp_path / "walls.yade.1000.npy", np.array([[1000, 2.0]]))
    np.save(tmp_path / "walls.yade.999.npy", np.array([[999, 1.0]]))
    assert yade_wall_rows(tmp_path)[:, 0].tolist() == [999, 1000]
    assert yade_wall_rows(tmp_path / "missing") is None


def test_import_layers_hold():
    """import-linter's contracts in pyproject.toml (layers, forbidden imports, no sibling cycles)."""
    exe = shutil.which("lint-imports", path=str(Path(sys.executable).parent))
    assert exe, "import-linter is not installed (pip install -e '.[test]')"
    r = subprocess.run([exe, "--no-cache"], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "0 broken" in r.stdout


def test_one_output_field_selection():
    """Output.fields is the one selection both adapters use: frames.h5 order, position always, an
    engine's unwritable fields left out (LIGGGHTS' spheres carry no orientation)."""
    from engines.liggghts.adapter import FRAME_FIELDS, _fields
    case = load_case(CASES / "triaxial_smoke.yaml", overrides={"output": {"velocity": True, "torque": True,
                                                                          "orientation": True, "stress": False}})
    want = [f for f in ("position", "velocity", "angular_velocity", "orientation", "force", "torque", "stress")
            if f == "position" or getattr(case.output, f)]
    assert case.output.fields() == want
    assert _fields(case) == [f for f in want if f != "orientation"] and "orientation" not in FRAME_FIELDS
