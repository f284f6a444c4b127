"""Shared steps of the kill-and-resume tests (tests/test_resume.py, tests/test_triaxial_resume.py,
tests/test_resume_scenes.py)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

from orchestrator.registry import get_engine
from orchestrator.run_summary import read_summary


def _engine_running_in(run_dir: Path) -> bool:
    """Whether a process works in ``run_dir`` (engines run with the run directory as their cwd)."""
    want = str(Path(run_dir).resolve())
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                if os.readlink(p / "cwd") == want:
                    return True
            except OSError:             # gone meanwhile, or not ours to read
                continue
    return False


def kill_run(proc: subprocess.Popen, run_dir: Path) -> None:
    """Kill an ``orchestrator run`` started with ``start_new_session=True`` (its engine dies with it
    through PDEATHSIG) and check the run is left interrupted: ``running`` on disk, read as
    ``interrupted`` (no live process holds its lock), no frames.h5."""
    os.killpg(proc.pid, signal.SIGKILL)                 # the orchestrator dies...
    proc.wait()
    t0 = time.time()                                    # ...and its engine with it (PDEATHSIG)
    while _engine_running_in(run_dir) and time.time() - t0 < 10:
        time.sleep(0.05)
    assert not _engine_running_in(run_dir), "the engine outlived its killed orchestrator"
    assert json.loads((run_dir / "summary.json").read_text())["status"] == "running"    # as it was killed
    assert read_summary(run_dir)["status"] == "interrupted"       # no live owner: read as interrupted
    assert not (run_dir / "frames.h5").exists()


def rerun_resumes(cmd: list[str], run_dir: Path, timeout: float) -> dict:
    """Run the same command again; it must complete by resuming (summary ``resumed_from`` set)."""
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, done.stdout + done.stderr
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "complete"
    assert summary["resumed_from"], "the second run started afresh instead of resuming"
    return summary


def engine_step(run_dir: Path, engine: str) -> int | None:
    """The last step the engine reported in its log (LIGGGHTS thermo lines, YADE PROGRESS lines)."""
    eng = get_engine(engine)
    try:
        lines = (Path(run_dir) / "engine.log").read_text(errors="replace").splitlines()[-200:]
    except OSError:
        return None
    steps = [s for s in map(eng.progress_step, lines) if s is not None]
    return steps[-1] if steps else None


def wait_until(proc: subprocess.Popen, done, timeout: float, what: str) -> None:
    """Poll ``done()`` every 0.1 s until it is true; fail if ``proc`` ends first or after ``timeout`` s."""
    t0 = time.time()
    while not done():
        assert proc.poll() is None, f"the run ended before {what}"
        assert time.time() - t0 < timeout, f"no {what} within {timeout:.0f} s"
        time.sleep(0.1)
