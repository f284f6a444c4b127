"""A run whose engine input is byte-for-byte a complete run's, found by its deck, not its hash.

The run hash (:func:`orchestrator.runner.run_hash`) covers the case, the derived numbers, the
engine's version and the templates, so that nothing which could change a run is missed. It also
changes when a number is added that leaves a scene's decks as they were (27 Nov 2026: the shear
cell's ``servo.v_max_shear`` and ``wall_friction_from``, new for other cases), and the complete runs
of every such case were then redone from step 0, bit for bit (the small shear cell's L0 runs: the
same deck, the same μ_macro to the last digit, ~1.5 h of engine time on three engines).

What an engine computes is fixed by what it reads: its deck and the files beside it. After a fresh
run is prepared and rendered, :func:`find_twin` compares those files (every file in the run
directory but the orchestrator's own records, :data:`NOT_INPUT`) with each complete sibling run of
the same engine and version; an intact sibling whose files are identical *is* this run, and
:func:`adopt_twin` makes the new run directory a link to it (the runner then treats it as any
complete run: its analyses are redone if the case asks for others).
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

from .integrity import verify_run

__all__ = ["input_manifest", "find_twin", "adopt_twin", "NOT_INPUT"]

#: files in a run directory that the orchestrator writes about a run, not for the engine to read
NOT_INPUT = frozenset({"case.yaml", "params.json", "summary.json", ".lock", "attempts.json"})


def input_manifest(run_dir) -> dict[str, str]:
    """SHA-256 of every file the engine may read in a freshly rendered ``run_dir`` (relative path
    -> hex digest), all but :data:`NOT_INPUT`."""
    run_dir = Path(run_dir)
    out = {}
    for f in sorted(run_dir.rglob("*")):
        rel = f.relative_to(run_dir).as_posix()
        if f.is_file() and rel not in NOT_INPUT:
            out[rel] = hashlib.sha256(f.read_bytes()).hexdigest()
    return out


def _same_files(twin: Path, fresh: Path, manifest: dict[str, str]) -> bool:
    """``twin`` holds every file of the manifest with the same bytes (sizes compared first)."""
    if any(not (twin / rel).is_file() or (twin / rel).stat().st_size != (fresh / rel).stat().st_size
           for rel in manifest):
        return False
    return all(hashlib.sha256((twin / rel).read_bytes()).hexdigest() == digest for rel, digest in manifest.items())


def find_twin(run_dir, engine_name: str, engine_version: str) -> Path | None:
    """The complete sibling of the freshly rendered ``run_dir`` (same case directory, same engine
    and version) whose engine input files are identical to ``run_dir``'s; None when there is none."""
    run_dir = Path(run_dir)
    manifest = input_manifest(run_dir)
    if not manifest:
        return None
    for sib in sorted(run_dir.parent.glob(f"{engine_name}-*")):
        if sib.resolve() == run_dir.resolve() or sib.is_symlink() or not (sib / "frames.h5").is_file():
            continue
        try:
            s = json.loads((sib / "summary.json").read_text())
        except (OSError, ValueError):
            continue
        if s.get("status") != "complete" or s.get("engine_version") != engine_version:
            continue
        if _same_files(sib, run_dir, manifest) and not verify_run(sib, s):     # intact, analyses included
            return sib
    return None


def adopt_twin(run_dir, twin) -> Path:
    """Replace the freshly prepared ``run_dir`` by a relative link to ``twin`` (a sibling), so the
    new hash finds the complete run from now on; returns ``run_dir``."""
    run_dir, twin = Path(run_dir), Path(twin)
    shutil.rmtree(run_dir)
    os.symlink(twin.name, run_dir, target_is_directory=True)
    return run_dir
