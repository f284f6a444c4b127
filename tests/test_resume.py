"""A run killed mid-way (orchestrator and engine) resumes from its last restart/checkpoint and
ends with the same frames as an uninterrupted run."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from orchestrator.attempts import read_attempts, run_cost
from orchestrator.clock import samples_from_runs
from orchestrator.frames import Frames
from orchestrator.run_status import run_status
from resume_util import kill_run, rerun_resumes

pytestmark = pytest.mark.engine
REPO = Path(__file__).resolve().parents[1]
SCHEDULE_MINUTES = 1.5        #: tests/conftest.py schedule_groups


#: long enough to be killed after a restart on either engine (YADE is ~5x slower per step)
AFTER_CONTACT = {"liggghts": 4000.0, "yade": 800.0, "lammps": 4000.0}


def long_case(tmp_path: Path, engine: str) -> Path:
    base = REPO / "cases" / "verification" / "chung_ooi_4_oblique.yaml"   # 17 spheres
    p = tmp_path / "long_impact.yaml"
    p.write_text(f"extends: {base}\nname: long_impact\n"
                 f"scene: {{after_contact: {AFTER_CONTACT[engine]}, frames_per_contact: 1}}\n")
    return p


def orchestrator(*args, **kw):
    return [sys.executable, "-m", "orchestrator", *args]


@pytest.mark.parametrize("engine", ["liggghts", "yade", "lammps"])
def test_killed_run_resumes(engine, tmp_path, engines_installed):
    case = long_case(tmp_path, engine)
    runs = tmp_path / "runs"
    proc = subprocess.Popen(orchestrator("run", str(case), "--engine", engine, "--runs", str(runs), "--quiet"),
                            start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env={**os.environ, "ORCHESTRATOR_ATTEMPT_EVERY": "0"})
    restarts = engine in ("liggghts", "lammps")
    marker = "restart/state.*.restart" if restarts else "checkpoint.yade.gz"
    t0 = time.time()
    run_dir = None
    while time.time() - t0 < 120:
        found = list(runs.glob(f"long_impact/{engine}-*/{marker}"))
        if len(found) >= (2 if restarts else 1):
            run_dir = found[0].parents[1] if restarts else found[0].parent
            break
        assert proc.poll() is None, "the run ended before it could be killed: make the case longer"
        time.sleep(0.2)
    assert run_dir is not None, "no restart written within 120 s"
    if restarts:        # kill once the attempt record has reached the newest restart (it follows the progress lines)
        newest = max(int(p.name.split(".")[1]) for p in run_dir.glob("restart/state.*.restart"))
        while time.time() - t0 < 120 and proc.poll() is None and \
                max((a.get("last_step") or 0 for a in read_attempts(run_dir)), default=0) < newest:
            time.sleep(0.05)
        assert proc.poll() is None, "the run ended before it could be killed: make the case longer"
    kill_run(proc, run_dir)
    first_estimate = json.loads((run_dir / "summary.json").read_text())["estimated_engine_time_s"]
    st = run_status(run_dir)                      # what `orchestrator status` prints of it
    assert st["status"] == "interrupted" and st["attempts"] == 1 and st["engine_s"] > 0
    assert 0 < st["step"] < st["steps"] and 0 < st["done"] < 1 and st["left_pace_s"] > 0
    rerun_resumes(orchestrator("run", str(case), "--engine", engine, "--runs", str(runs), "--quiet"),
                  run_dir, timeout=600)
    # the engine time of both attempts is on record, and the clock counts the resumed run with it
    summary = json.loads((run_dir / "summary.json").read_text())
    att = summary["attempts"]
    assert len(att) == 2 and att[0]["first_step"] == 0 and not att[0]["done"] and att[1]["done"]
    # the estimate made before the first attempt is kept beside the resumed attempt's own
    assert first_estimate > 0 and summary["first_estimated_engine_time_s"] == first_estimate
    assert 0 < att[0]["last_step"] and 0 < att[1]["first_step"] < att[1]["last_step"] == summary["steps_run"]
    assert all(a["wall_s"] > 0 and a["cpu_s"] > 0 for a in att)
    cost = run_cost(att, summary["steps_run"], use_cpu=True)
    assert cost is not None and cost > 0          # (run_cost's arithmetic: tests/test_attempts.py)
    assert samples_from_runs([run_dir])[0].engine_s == pytest.approx(cost)
    st = run_status(run_dir)
    assert st["status"] == "complete" and st["done"] == 1 and st["attempts"] == 2
    assert st["engine_s"] == pytest.approx(cost)

    ref_runs = tmp_path / "ref"
    ref = subprocess.run(orchestrator("run", str(case), "--engine", engine, "--runs", str(ref_runs), "--quiet"),
                         capture_output=True, text=True, timeout=600)
    assert ref.returncode == 0, ref.stderr
    a = Frames(run_dir)
    b = Frames(next(ref_runs.glob(f"long_impact/{engine}-*")))
    assert a.n_frames == b.n_frames
    np.testing.assert_array_equal(a.step, b.step)
    np.testing.assert_allclose(a.position, b.position, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.velocity, b.velocity, rtol=1e-9, atol=1e-12)


def test_complete_run_is_reused_and_force_redoes_it(tmp_path, engines_installed):
    case = REPO / "cases" / "verification" / "chung_ooi_1_sphere_sphere_glass.yaml"
    runs = tmp_path / "runs"
    cmd = orchestrator("run", str(case), "--engine", "liggghts", "--runs", str(runs), "--quiet")
    first = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    second = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    # (a sizing line comes first, then the run's own line)
    assert any(ln.startswith("liggghts: reused") for ln in second.stdout.splitlines()), second.stdout
    third = subprocess.run(cmd + ["--force"], capture_output=True, text=True, timeout=300)
    assert any(ln.startswith("liggghts: complete") for ln in third.stdout.splitlines()), third.stdout
