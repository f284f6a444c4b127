"""The notebooks run top to bottom (nbclient) on the smoke cases, reusing the session's runs (the
triaxial notebook runs in tests/test_triaxial.py, on that file's LIGGGHTS run)."""
from __future__ import annotations

from pathlib import Path

import pytest
from notebook_util import execute_notebook, notebook_images

REPO = Path(__file__).resolve().parents[2]
NOTEBOOKS = REPO / "notebooks"

pytestmark = pytest.mark.engine
SCHEDULE_MINUTES = 4


@pytest.mark.parametrize("name", ["shear_cell_postprocessing.ipynb", "engine_crossval.ipynb", "sim_vs_ct.ipynb"])
def test_notebook_runs(name, crossval_smoke, runs_root, tmp_path, request):
    # the crossval notebook on the crossval fixture's two engines (its runs reused). sim_vs_ct writes
    # its CT series where the ct_frames fixture wrote the same one (same scans, segmentation and
    # tracking), so its run from the scanned packing is test_simulation_from_scanned_packing's run
    # (same case, same grains: orchestrator.initial_packing.packing_digest) when both are on one worker, not a second engine run
    out = request.getfixturevalue("ct_frames").parent if name == "sim_vs_ct.ipynb" else tmp_path
    nb = execute_notebook(name, runs_root, out, env={"ORCH_ENGINES": "liggghts,yade"})
    assert notebook_images(nb) >= 2, f"{name}: expected plots in the outputs"


def test_notebooks_use_public_api_only():
    import json
    for p in NOTEBOOKS.glob("*.ipynb"):
        src = "\n".join("".join(c["source"]) for c in json.loads(p.read_text())["cells"] if c["cell_type"] == "code")
        assert "._" not in src.replace("._repr", ""), f"{p.name} reaches into a private name"
        assert "from engines" not in src and "import engines" not in src, p.name
