"""The notebooks run top to bottom (nbclient) on the smoke cases, reusing the session's runs."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
NOTEBOOKS = REPO / "notebooks"

pytestmark = pytest.mark.engine


def _execute(name, runs_root, out, timeout=600):
    import nbformat
    from nbclient import NotebookClient
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    env = {"ORCH_RUNS": str(runs_root), "ORCH_OUT": str(out), "ORCH_ROOT": str(REPO)}
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        NotebookClient(nb, timeout=timeout, kernel_name="python3", resources={"metadata": {"path": str(REPO)}}).execute()
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.get("output_type") == "error"]
    assert not errors
    return nb


@pytest.mark.parametrize("name", ["shear_cell_postprocessing.ipynb", "engine_crossval.ipynb", "sim_vs_ct.ipynb"])
def test_notebook_runs(name, crossval_smoke, runs_root, tmp_path):
    nb = _execute(name, runs_root, tmp_path)
    images = sum(1 for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
                 if "image/png" in o.get("data", {}))
    assert images >= 2, f"{name}: expected plots in the outputs"


def test_triaxial_notebook_runs(runs_root, tmp_path, engines_installed):
    _execute("triaxial_postprocessing.ipynb", runs_root, tmp_path, timeout=1800)


def test_notebooks_use_public_api_only():
    import json
    for p in NOTEBOOKS.glob("*.ipynb"):
        src = "\n".join("".join(c["source"]) for c in json.loads(p.read_text())["cells"] if c["cell_type"] == "code")
        assert "._" not in src.replace("._repr", ""), f"{p.name} reaches into a private name"
        assert "from engines" not in src and "import engines" not in src, p.name
