"""A case's ``ct:`` section -> ``runs/<case>/ct-<hash>/frames.h5`` (segment every scan, track,
export), through the same steps as ``orchestrator ct segment`` and ``orchestrator ct track``.

The hash covers the ``ct:`` section and the scan files' names, sizes and modification times, so
a finished series is reused and a changed scan is processed again.
"""
from __future__ import annotations

import argparse
import glob
import hashlib
import json
from pathlib import Path

from .commands import segment_main, track_main


class CTCaseError(ValueError):
    pass


def scan_paths(case) -> list[Path]:
    """The case's scans, globs expanded (sorted), relative to the case file."""
    base = Path(case.source).parent if case.source else Path.cwd()
    out = []
    for entry in case.ct.scans:
        pattern = entry if Path(entry).is_absolute() else str(base / entry)
        hits = sorted(glob.glob(pattern)) if any(ch in entry for ch in "*?[") else [pattern]
        if not hits or not all(Path(h).exists() for h in hits):
            raise CTCaseError(f"{case.source}: ct.scans: {entry!r} matches no file (looked in {base})")
        out += [Path(h) for h in hits]
    return out


def ct_run_dir(case, runs_root="runs") -> Path:
    h = hashlib.sha256(json.dumps(case.ct.model_dump(mode="json"), sort_keys=True).encode())
    for p in scan_paths(case):
        st = p.stat()
        h.update(f"{p.name}:{st.st_size}:{st.st_mtime_ns}".encode())
    return Path(runs_root) / case.name / f"ct-{h.hexdigest()[:12]}"


def run_ct_case(case, runs_root="runs", force: bool = False) -> Path:
    """Segment and track the case's scan series; return the frames.h5 path (reused if complete)."""
    if case.ct is None:
        raise CTCaseError(f"{case.source}: the case has no ct: section (scans to segment and track); add one "
                          "with the scans, e.g. `ct: {scans: [\"scans/scan_*.tif\"], voxel_size: 2.2 um}` (docs/ct.md)")
    run_dir = ct_run_dir(case, runs_root)
    frames = run_dir / "frames.h5"
    if frames.exists() and not force:
        return frames
    run_dir.mkdir(parents=True, exist_ok=True)
    scans = [str(p) for p in scan_paths(case)]
    c = case.ct
    vs = None if c.voxel_size is None else f"{c.voxel_size!r} m"
    seg = argparse.Namespace(scans=scans, out=str(run_dir / "segment"), voxel_size=vs, shape=None, dtype=None,
                             sigma=c.segment.sigma, h=None if c.segment.h is None else f"{c.segment.h!r} m",
                             no_shape=not c.segment.shape, degree=c.segment.degree, labels=False)
    if segment_main(seg) != 0:
        raise CTCaseError(f"{case.source}: ct: segmentation failed (see the messages above)")
    trk = argparse.Namespace(segdir=str(run_dir / "segment"), out=str(frames), method=c.track.method,
                             max_disp=None if c.track.max_disp is None else f"{c.track.max_disp!r} m",
                             scans=scans, voxel_size=vs, rings=c.track.rings)
    if track_main(trk) != 0:
        raise CTCaseError(f"{case.source}: ct: tracking failed (see the messages above)")
    return frames
