"""The files a YADE run of the orchestrator's scripts leaves (templates/yade/*): frame chunks
``dump/chunk.<iter>.npz`` (Recorder), the wall sampler's ``walls.yade.<n>.npy`` and the triaxial
membrane's ``dump/membrane.npz``. One chunk discovery for the adapter, resume and scenes' output.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np


def _number(path: Path) -> int:
    """The integer between the first two dots of ``name.<n>.ext``."""
    return int(path.name.split(".")[1])


def chunk_files(run_dir) -> list[Path]:
    """The frame chunks ``dump/chunk.<iter>.npz`` in iteration order (numeric, not lexical:
    chunk.99 comes before chunk.100)."""
    return sorted((Path(run_dir) / "dump").glob("chunk.*.npz"), key=_number)


def wall_rows(run_dir) -> np.ndarray | None:
    """Rows of the script's wall sampler (``walls.yade.<n>.npy``, one file per run segment), in
    numeric file order, or None when there are none."""
    files = sorted(Path(run_dir).glob("walls.yade.*.npy"), key=lambda p: int(p.name.split(".")[2]))
    starts = [int(f.name.split(".")[2]) for f in files]
    rows = []
    for k, f in enumerate(files):
        a = np.load(f)
        if a.size and k + 1 < len(files):
            a = a[a[:, 0] <= starts[k + 1]]       # rows the next segment wrote again (a resumed run)
        if a.size:
            rows.append(a)
    return np.vstack(rows) if rows else None


class ChunkOutput:
    """The run's frames as a scene reads them (orchestrator.scenes.base.EngineOutput): the first
    occurrence of every iteration, in chunk order; positions are read from their chunk on demand."""

    def __init__(self, run_dir):
        self.run_dir = Path(run_dir)
        steps, self._refs, seen = [], [], set()
        for c in chunk_files(run_dir):
            with np.load(c) as z:
                iters = z["iter"]
            for k, it in enumerate(iters):
                if int(it) in seen:
                    continue
                seen.add(int(it))
                steps.append(int(it))
                self._refs.append((c, k))
        self.frame_steps = np.array(steps, dtype=np.int64)

    def positions(self, k: int) -> np.ndarray:
        c, kk = self._refs[k]
        with np.load(c) as z:
            return z["position"][kk]

    def wall_rows(self) -> np.ndarray | None:
        return wall_rows(self.run_dir)


def membrane_series(run_dir) -> dict | None:
    """The triaxial membrane's node positions at the frame times (``dump/membrane.npz``), as a
    frames.h5 wall series, or None when the script wrote none."""
    f = Path(run_dir) / "dump" / "membrane.npz"
    if not f.exists():
        return None
    m = np.load(f)
    return {"time": m["time"], "step": m["iter"], "node_position": m["position"],
            "triangles": m["triangles"], "node_radius": np.array([m["node_radius"]])}
