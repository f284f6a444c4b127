"""Running a notebook top to bottom (nbclient) against a test's runs directory."""
from __future__ import annotations

import os
from pathlib import Path

import nbformat
from nbclient import NotebookClient

REPO = Path(__file__).resolve().parents[1]
NOTEBOOKS = REPO / "notebooks"


def execute_notebook(name, runs_root, out, timeout=600, env: dict | None = None):
    """Execute ``notebooks/<name>`` with ORCH_RUNS = ``runs_root`` (its runs are reused when they
    exist), ORCH_OUT = ``out`` and the variables in ``env``; asserts no cell raised and returns the
    executed notebook."""
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    env = {"ORCH_RUNS": str(runs_root), "ORCH_OUT": str(out), "ORCH_ROOT": str(REPO), **(env or {})}
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


def notebook_images(nb) -> int:
    """How many PNG figures the executed notebook's cells output."""
    return sum(1 for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
               if "image/png" in o.get("data", {}))


def notebook_text(nb) -> str:
    """The text the executed notebook's cells printed."""
    return "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
