"""Run directories are reused exactly when the deck would be the same: the hash covers the
templates a scene's deck is rendered from (followed through Jinja includes and imports), not the
other scenes' templates, and not the wording of the pre-run stability report."""
from __future__ import annotations

import shutil

import pytest

import engines.render as render


@pytest.fixture
def templates_copy(tmp_path, monkeypatch):
    """A copy of templates/ that the hash reads (parsing needs no loader, so the cached
    environment serves as it is)."""
    root = tmp_path / "templates"
    shutil.copytree(render.TEMPLATES, root)
    monkeypatch.setattr(render, "TEMPLATES", root)
    return root


def test_scene_templates_follow_includes():
    names = render.scene_templates("liggghts", "shear_cell")
    assert "liggghts/shear_cell.in.j2" in names and "liggghts/partials/header.j2" in names
    assert "liggghts/triaxial.in.j2" not in names
    assert "yade/partials/wall_contacts.py.j2" in render.scene_templates("yade", "shear_cell")
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


def test_run_hash_ignores_the_stability_report_wording():
    from orchestrator.case import load_case
    from orchestrator.derive import derive
    from orchestrator.runner import run_hash
    from tests.conftest import CASES
    case = load_case(CASES / "shear_cell_smoke.yaml")
    params = derive(case)
    h = run_hash(case, "liggghts", "3.8.0", params)
    params["stability"] = dict(params["stability"], note="reworded")
    assert run_hash(case, "liggghts", "3.8.0", params) == h
    params["dt"] = params["dt"] * 0.5
    assert run_hash(case, "liggghts", "3.8.0", params) != h
