"""A run directory's ``summary.json`` as it stands, and whether a live process holds the run
(the runner's lock, :mod:`orchestrator.runner`): what the runner, sweeps, ladders and ``orchestrator
status`` (:mod:`orchestrator.run_status`) read a run's state with."""
from __future__ import annotations

import fcntl
import json
import time
from pathlib import Path

from .atomic import write_json

__all__ = ["read_summary", "lock_held"]


def read_summary(run_dir) -> dict | None:
    """The run's summary.json; a run found ``running`` whose lock no live process holds (its
    orchestrator was killed) is marked ``interrupted`` on disk and in the answer."""
    p = Path(run_dir) / "summary.json"
    if not p.exists():
        return None
    try:
        s = json.loads(p.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError):
        s = None
    if not isinstance(s, dict):          # cut short, or not a summary at all
        return {"status": "interrupted", "error": f"{p}: unreadable (cut short); the run is resumed or redone"}
    if s.get("status") == "running" and not lock_held(Path(run_dir)):
        s["status"] = "interrupted"
        s["interrupted"] = {"found": time.strftime("%Y-%m-%dT%H:%M:%S"), "pid": s.get("pid"),
                            "note": "found 'running' with no live owner (its process was killed)"}
        try:
            write_json(p, s)
        except OSError:                  # a read-only run directory: report it, leave the file
            pass
    return s


def lock_held(run_dir: Path) -> bool:
    """True when some live process holds the run directory's lock (flock: released by the kernel
    when its owner dies, so a stale lock file is never held)."""
    lock = run_dir / ".lock"
    if not lock.exists():
        return False
    try:
        fh = open(lock, "r")
    except OSError:
        return False
    with fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return True
        fcntl.flock(fh, fcntl.LOCK_UN)
    return False
