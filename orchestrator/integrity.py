"""Integrity of a run's results: what ``summary.json`` records of ``frames.h5`` and of each analysis
output (size in bytes, SHA-256, frame count), and the check of a reused run against it.

A complete run is reused only when every recorded file is there with its size and checksum and
``frames.h5`` opens with its frame count; otherwise :func:`verify_run` names what is damaged and
the runner redoes the run (orchestrator.runner).
"""
from __future__ import annotations

import hashlib
from pathlib import Path
from .frames import Frames, FramesError

#: read files in blocks of this many bytes while hashing
_BLOCK = 1 << 22


def sha256(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(_BLOCK), b""):
            h.update(block)
    return h.hexdigest()


def file_record(path) -> dict:
    """``{"size": bytes, "sha256": hex}`` of one file."""
    path = Path(path)
    return {"size": path.stat().st_size, "sha256": sha256(path)}


def frames_record(path) -> dict:
    """:func:`file_record` of a frames.h5 plus its frame and particle counts."""
    fr = Frames(path)
    return {**file_record(path), "frames": fr.n_frames, "particles": fr.n_particles}


def run_record(run_dir, analysis: dict | None = None) -> dict:
    """The integrity record of a complete run: ``frames.h5`` and every analysis output file
    (paths relative to the run directory)."""
    run_dir = Path(run_dir)
    rec = {"frames.h5": frames_record(run_dir / "frames.h5")}
    adir = run_dir / "analysis"
    if analysis and adir.is_dir():
        for f in sorted(adir.rglob("*")):
            if f.is_file() and not f.name.startswith("."):
                rec[str(f.relative_to(run_dir))] = file_record(f)
    return rec


def verify_run(run_dir, summary: dict) -> list[tuple[str, str]]:
    """What is wrong with a complete run's recorded files: (file name relative to the run, problem)
    per missing, resized, altered or unreadable file (empty when all is well, or when the summary
    predates the record and frames.h5 opens)."""
    run_dir = Path(run_dir)
    rec = summary.get("integrity")
    problems = []
    if not rec:                                   # a run completed before integrity records: open it
        try:
            Frames(run_dir / "frames.h5")
        except (FramesError, OSError) as exc:
            problems.append(("frames.h5", str(exc)))
        return problems
    for name, want in rec.items():
        f = run_dir / name
        if not f.is_file():
            problems.append((name, f"{f}: missing"))
            continue
        size = f.stat().st_size
        if size != want["size"]:
            problems.append((name, f"{f}: {size} bytes, recorded {want['size']} (truncated or rewritten)"))
        elif sha256(f) != want["sha256"]:
            problems.append((name, f"{f}: checksum differs from the recorded one (altered)"))
        elif "frames" in want:
            try:
                n = Frames(f).n_frames
            except (FramesError, OSError) as exc:
                problems.append((name, str(exc)))
                continue
            if n != want["frames"]:
                problems.append((name, f"{f}: {n} frames, recorded {want['frames']}"))
    return problems
