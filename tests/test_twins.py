"""A run whose engine input is byte for byte a complete run's is that run (orchestrator.twins):
found by its deck when its hash changed for a number the deck does not use."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from orchestrator.case import load_case
from orchestrator.integrity import file_record
from orchestrator.twins import adopt_twin, find_twin, input_manifest

CASES = Path(__file__).resolve().parents[1] / "cases"


def _run(root: Path, name: str, files: dict, status="complete", version="v1") -> Path:
    d = root / name
    d.mkdir(parents=True)
    for rel, text in files.items():
        (d / rel).parent.mkdir(parents=True, exist_ok=True)
        (d / rel).write_text(text)
    (d / "frames.h5").write_text("frames")
    (d / "summary.json").write_text(json.dumps({"status": status, "engine_version": version,
                                                "integrity": {"frames.h5": file_record(d / "frames.h5")}}))
    return d


def test_only_a_complete_run_with_the_same_input_files_is_a_twin(tmp_path):
    inputs = {"deck.in": "run 100\n", "particles.data": "1 atoms\n", "dump/columns.json": "[]"}
    old = _run(tmp_path, "liggghts-aaaa", inputs)
    _run(tmp_path, "liggghts-bbbb", {**inputs, "deck.in": "run 200\n"})          # another deck
    _run(tmp_path, "liggghts-cccc", inputs, status="running")                    # not complete
    _run(tmp_path, "liggghts-dddd", inputs, version="v2")                        # another engine version
    _run(tmp_path, "yade-eeee", inputs)                                          # another engine
    new = tmp_path / "liggghts-ffff"
    new.mkdir()
    for rel, text in inputs.items():
        (new / rel).parent.mkdir(parents=True, exist_ok=True)
        (new / rel).write_text(text)
    (new / "case.yaml").write_text("new: field\n")                   # the orchestrator's records differ
    (new / "params.json").write_text("{}")
    assert set(input_manifest(new)) == set(inputs)
    assert find_twin(new, "liggghts", "v1") == old
    assert find_twin(new, "liggghts", "v2").name == "liggghts-dddd"      # the run of that version
    assert find_twin(new, "liggghts", "v3") is None
    (tmp_path / "liggghts-dddd" / "frames.h5").write_text("cut")               # damaged: not a twin
    assert find_twin(new, "liggghts", "v2") is None
    adopt_twin(new, old)
    assert new.is_symlink() and new.resolve() == old.resolve()
    (old / "particles.data").write_text("2 atoms\n")
    other = tmp_path / "liggghts-gggg"
    other.mkdir()
    for rel, text in inputs.items():
        (other / rel).parent.mkdir(parents=True, exist_ok=True)
        (other / rel).write_text(text)
    assert find_twin(other, "liggghts", "v1") is None           # an input file differs


@pytest.mark.engine
def test_a_new_hash_with_the_same_deck_reuses_the_complete_run(tmp_path, engines_installed, monkeypatch):
    """Chung & Ooi's oblique impact on LIGGGHTS (17 spheres, ~1 s): run once; then a number the deck
    does not read joins the hashed parameters (as servo.v_max_shear did for the shear cell): the new
    run directory is a link to the complete run and no engine starts. A change the deck does read
    (the impact speed) runs anew."""
    import orchestrator.runner as runner
    from orchestrator.runner import run_case
    case = load_case(CASES / "verification" / "chung_ooi_4_oblique.yaml")
    first = run_case(case, "liggghts", runs_root=tmp_path, progress=False, analyze=False)
    assert first.status == "complete" and not first.reused
    hash_params = runner.hash_params
    monkeypatch.setattr(runner, "hash_params", lambda *a: {**hash_params(*a), "a_new_number": 1.0})

    real_run = runner._run_with_fallback

    def no_engine(*a, **k):
        raise AssertionError("the engine ran although a complete run read the same files")
    monkeypatch.setattr(runner, "_run_with_fallback", no_engine)
    again = run_case(case, "liggghts", runs_root=tmp_path, progress=False, analyze=False)
    assert again.run_dir != first.run_dir and again.reused and again.status == "complete"
    assert again.run_dir.is_symlink() and again.run_dir.resolve() == first.run_dir.resolve()
    monkeypatch.setattr(runner, "_run_with_fallback", real_run)
    redone = run_case(case, "liggghts", runs_root=tmp_path, progress=False, analyze=False, force=True)
    assert not redone.reused and not redone.run_dir.is_symlink() and first.run_dir.is_dir()   # --force redoes
    monkeypatch.undo()
    faster = load_case(CASES / "verification" / "chung_ooi_4_oblique.yaml", overrides={"scene": {"speed": "3.0 m/s"}})
    third = run_case(faster, "liggghts", runs_root=tmp_path, progress=False, analyze=False)
    assert not third.reused and not third.run_dir.is_symlink()
