"""Golden decks: every engine x scene smoke case renders exactly the committed deck.

The rendered deck (and every other text file the engine's ``render`` writes) is normalised (the
run directory and the package version replaced by placeholders; data files such as particle
tables and meshes are summarised by their SHA-256) and compared with ``tests/golden/``.

A change to a template, to ``derive`` or to an adapter that changes a deck makes this test fail
and shows the diff. If the change is intended, regenerate the golden files and commit them with
the reason in the commit message::

    .venv/bin/python tests/test_golden_decks.py --update

No engine runs here (engine-free tier): rendering needs neither binary.
"""
from __future__ import annotations

import difflib
import hashlib
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
GOLDEN = Path(__file__).resolve().parent / "golden"

#: (case file relative to cases/, engine) pairs: every scene's smoke case on every engine that
#: renders it, plus the full-physics shear cell (adhesion, rolling, torsion blocks)
CASES = [
    ("shear_cell_smoke.yaml", "liggghts"), ("shear_cell_smoke.yaml", "yade"),
    ("shear_cell_small.yaml", "liggghts"), ("shear_cell_small.yaml", "yade"),
    ("triaxial_smoke.yaml", "liggghts"), ("triaxial_smoke.yaml", "yade"),
    ("plane_shear_smoke.yaml", "liggghts"), ("plane_shear_smoke.yaml", "yade"),
    ("verification/chung_ooi_1_sphere_sphere_glass.yaml", "liggghts"),
    ("verification/chung_ooi_1_sphere_sphere_glass.yaml", "yade"),
    ("verification/chung_ooi_4_oblique.yaml", "liggghts"),
    ("verification/chung_ooi_4_oblique.yaml", "yade"),
    ("verification/chung_ooi_1_sphere_sphere_glass.yaml", "lammps"),
    ("verification/chung_ooi_4_oblique.yaml", "lammps"),
    ("plane_shear_smoke.yaml", "lammps"),
    ("shear_cell_smoke.yaml", "lammps"), ("shear_cell_small.yaml", "lammps"),
]

#: files written by render/prepare whose content is data, summarised by a hash
_DATA_SUFFIXES = {".txt", ".data", ".stl", ".vtk", ".npy", ".npz", ".json", ".h5"}
_SKIP = {"summary.json", "params.json", "case.yaml", ".lock"}


def _golden_name(case_rel: str, engine: str) -> str:
    return f"{Path(case_rel).stem}__{engine}.golden"


def render_normalised(case_rel: str, engine: str, tmp: Path) -> str:
    """Render ``case_rel`` for ``engine`` into ``tmp`` and return the normalised text."""
    from orchestrator import __version__
    from orchestrator.case import load_case
    from orchestrator.runner import prepare
    from engines import get_engine

    case = load_case(REPO / "cases" / case_rel)
    run_dir = tmp / "run"
    params, _subs = prepare(case, engine, run_dir)
    deck = get_engine(engine).render(case, params, run_dir, resume=None)
    parts = []
    for f in sorted(p for p in run_dir.rglob("*") if p.is_file()):
        rel = f.relative_to(run_dir).as_posix()
        if f.name in _SKIP:
            continue
        # data, and the runtime Python an engine copies beside its deck (its own unit tests cover it)
        if (f.suffix in _DATA_SUFFIXES and f != deck) or rel.split("/")[0].endswith("_runtime"):
            parts.append(f"=== {rel} sha256 {hashlib.sha256(f.read_bytes()).hexdigest()}\n")
            continue
        text = f.read_text()
        text = text.replace(str(run_dir), "<RUN_DIR>").replace(str(REPO), "<REPO>")
        text = text.replace(__version__, "<VERSION>")
        parts.append(f"=== {rel}\n{text}")
    return "".join(parts)


@pytest.mark.parametrize("case_rel,engine", CASES, ids=[f"{Path(c).stem}-{e}" for c, e in CASES])
def test_deck_matches_golden(case_rel, engine, tmp_path):
    golden = GOLDEN / _golden_name(case_rel, engine)
    assert golden.exists(), f"no golden file {golden}; run `python tests/test_golden_decks.py --update`"
    got = render_normalised(case_rel, engine, tmp_path)
    want = golden.read_text()
    if got != want:
        diff = "".join(difflib.unified_diff(want.splitlines(True), got.splitlines(True), "golden", "rendered", n=2))
        pytest.fail(f"{case_rel} on {engine}: rendered deck differs from {golden.name}:\n{diff[:6000]}")


def _update():
    import tempfile
    GOLDEN.mkdir(exist_ok=True)
    for case_rel, engine in CASES:
        with tempfile.TemporaryDirectory() as d:
            text = render_normalised(case_rel, engine, Path(d))
        (GOLDEN / _golden_name(case_rel, engine)).write_text(text)
        print(f"wrote {_golden_name(case_rel, engine)} ({len(text)} chars)")


if __name__ == "__main__":
    if "--update" in sys.argv:
        sys.path.insert(0, str(REPO))
        _update()
    else:
        print(__doc__)
