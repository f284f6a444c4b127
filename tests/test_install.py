"""A non-editable ``pip install`` runs a case from outside the checkout: templates and data files
ship as package data (orchestrator.resources), engines and scenes are found through the installed
entry points. Builds the wheel from a copy of the checkout's files into a fresh virtual
environment, then runs Chung & Ooi test 1 (glass spheres) on LIGGGHTS with the installed package
and checks the Hertz figures against the analytic solution.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

pytestmark = [pytest.mark.engine, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "verification" / "chung_ooi_1_sphere_sphere_glass.yaml"


def _copy_checkout(dst: Path) -> None:
    """The files git tracks or would track (untracked, not ignored), links kept as links."""
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=ROOT, capture_output=True,
                           text=True, check=True).stdout.splitlines()
    for rel in files:
        src = ROOT / rel
        if not (src.exists() or src.is_symlink()):
            continue                                  # deleted in the working tree
        out = dst / rel
        out.parent.mkdir(parents=True, exist_ok=True)
        if src.is_symlink():
            out.symlink_to(os.readlink(src))
        else:
            shutil.copy2(src, out)


@pytest.mark.skipif(shutil.which("liggghts") is None, reason="LIGGGHTS not installed")
def test_non_editable_install_runs_a_verification_case(tmp_path):
    src, venv, work = tmp_path / "src", tmp_path / "venv", tmp_path / "elsewhere"
    _copy_checkout(src)
    work.mkdir()
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    py = venv / "bin" / "python"
    # the new environment's own pip installs the project (a pip of this environment would also
    # remove this environment's editable install); the build pulls setuptools as pyproject asks
    r = subprocess.run([str(py), "-m", "pip", "install", "-q", "--disable-pip-version-check", "--no-deps", str(src)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    # then the dependencies come from this environment (a .pth line): only the project is installed
    site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    (Path(site) / "_deps_from_test_env.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    shutil.rmtree(src)                                # nothing may be read from the copied checkout
    code = f"""
import json, orchestrator, engines
from pathlib import Path
from orchestrator.case import load_case
from orchestrator.runner import run_case
from orchestrator.verify import impact_metrics, verification_table
from orchestrator.frames import Frames
assert Path(orchestrator.__file__).is_relative_to({str(venv)!r}), orchestrator.__file__
assert Path(engines.__file__).is_relative_to({str(venv)!r}), engines.__file__
case = load_case({str(CASE)!r})
out = run_case(case, "liggghts", runs_root="runs", progress=False)
params = json.loads((out.run_dir / "params.json").read_text())
t = verification_table(impact_metrics(Frames(out.run_dir / "frames.h5"), params), "liggghts", case.name, 0.0)
print(json.dumps({{"status": out.status, "pass": bool(t["pass"].all()), "rows": len(t)}}))
"""
    r = subprocess.run([str(py), "-c", code], cwd=work, capture_output=True, text=True, timeout=600,
                       env={k: v for k, v in os.environ.items() if k not in ("PYTHONPATH",)})
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-4000:]
    res = json.loads(r.stdout.strip().splitlines()[-1])
    assert res == {"status": "complete", "pass": True, "rows": res["rows"]} and res["rows"] > 0
    # this environment's editable install is untouched
    assert subprocess.run([sys.executable, "-c", "import importlib.metadata as m; m.distribution(\"orchestrator\")"]).returncode == 0
    assert (work / "runs" / "chung_ooi_1_sphere_sphere_glass").is_dir()
