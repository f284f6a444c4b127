"""Run directories are reused exactly when the deck would be the same: the hash covers the
templates a scene's deck is rendered from (followed through Jinja includes and imports), not the
other scenes' templates, and not the wording of the pre-run stability report."""
from __future__ import annotations

import shutil

import pytest

import engines.render as render
from engines.yade.adapter import RUNTIME


@pytest.fixture
def templates_copy(tmp_path, monkeypatch):
    """A copy of templates/ that the hash reads (parsing needs no loader, so the cached
    environment serves as it is)."""
    root = tmp_path / "templates"
    shutil.copytree(render.TEMPLATES, root)
    monkeypatch.setattr(render, "TEMPLATES", root)
    (tmp_path / "engines").mkdir()
    monkeypatch.setattr(render, "RUNTIMES", tmp_path / "engines")
    return root


def test_scene_templates_follow_includes():
    names = render.scene_templates("liggghts", "shear_cell")
    assert "liggghts/shear_cell.in.j2" in names and "liggghts/partials/header.j2" in names
    assert "liggghts/triaxial.in.j2" not in names
    assert "yade/partials/contact_walls.py.j2" in render.scene_templates("yade", "shear_cell")
    assert render.scene_templates("yade", "no_such_scene") is None


def test_hash_ignores_other_scenes_but_not_shared_partials(templates_copy):
    before = {s: render.templates_hash("liggghts", s) for s in ("shear_cell", "triaxial")}
    (templates_copy / "liggghts" / "triaxial.in.j2").write_text(
        (templates_copy / "liggghts" / "triaxial.in.j2").read_text() + "\n# edited\n")
    after = {s: render.templates_hash("liggghts", s) for s in ("shear_cell", "triaxial")}
    assert after["shear_cell"] == before["shear_cell"] and after["triaxial"] != before["triaxial"]
    header = templates_copy / "liggghts" / "partials" / "header.j2"
    header.write_text(header.read_text() + "\n# edited\n")
    assert render.templates_hash("liggghts", "shear_cell") != after["shear_cell"]


def test_hash_covers_the_runtime_copied_beside_the_deck(templates_copy):
    """YADE's deck imports engines/yade_runtime (copied into the run directory): editing it changes
    every YADE scene's hash and no LIGGGHTS one."""
    runtime = templates_copy.parent / "engines" / "yade_runtime"
    shutil.copytree(RUNTIME, runtime)
    before = render.templates_hash("yade", "shear_cell"), render.templates_hash("liggghts", "shear_cell")
    (runtime / "control.py").write_text((runtime / "control.py").read_text() + "\n# edited\n")
    after = render.templates_hash("yade", "shear_cell"), render.templates_hash("liggghts", "shear_cell")
    assert after[0] != before[0] and after[1] == before[1]


def test_run_hash_ignores_the_stability_report_wording():
    from orchestrator.case import load_case
    from orchestrator.derive import derive
    from orchestrator.runner import run_hash
    from tests.conftest import CASES
    case = load_case(CASES / "shear_cell_smoke.yaml")
    params = derive(case)
    h = run_hash(case, "liggghts", "3.8.0", params)
    params = params.replace(stability=dict(params.stability, note="reworded"))
    assert run_hash(case, "liggghts", "3.8.0", params) == h
    assert run_hash(case, "liggghts", "3.8.0", params.replace(dt=params.dt * 0.5)) != h


def test_complete_run_drops_its_resume_points(tmp_path):
    """A complete run no longer needs its restart files and checkpoints: drop_resume_points removes
    exactly those and reports the bytes freed."""
    from orchestrator.runner import drop_resume_points
    (tmp_path / "restart").mkdir()
    for name, size in (("restart/state.100.restart", 10), ("restart/state.200.restart", 20),
                       ("checkpoint.yade.gz", 30)):
        (tmp_path / name).write_bytes(b"x" * size)
    (tmp_path / "restart" / "state.txt").write_text("100 1 0 1 0 0 0 0\n")
    (tmp_path / "frames.h5").write_bytes(b"keep")
    assert drop_resume_points(tmp_path) == 60
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == ["frames.h5", "state.txt"]
