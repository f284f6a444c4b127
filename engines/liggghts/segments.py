"""The files of a LIGGGHTS or LAMMPS run as the orchestrator's decks write them: the frame dumps
``dump/frames.bin``, then one segment ``dump/frames.<restart step>.bin`` per resume; the wall
sampler's ``walls.<n>.txt`` files; the restart files ``restart/state.<step>.restart``; the log's
``Loop time of`` lines."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from orchestrator.atomic import write_text

from ..lammps_dump import truncate_binary_dump


def dump_segments(run_dir) -> list[Path]:
    """The binary frame dumps of a run in writing order: frames.bin, then one segment per resume
    (frames.<restart step>.bin)."""
    d = Path(run_dir) / "dump"
    segs = sorted(d.glob("frames.*.bin"), key=lambda p: int(p.name.split(".")[1]))
    first = d / "frames.bin"
    return ([first] if first.exists() else []) + segs


def restart_resume_state(run_dir) -> dict | None:
    """Where a killed run resumes (:meth:`engines.base.Engine.resume_state`): the newest
    ``restart/state.<step>.restart`` file, its step, and every restart file newest first (the
    candidates, should the newest be damaged); None without one."""
    files = sorted((Path(run_dir) / "restart").glob("state.*.restart"), key=lambda p: int(p.name.split(".")[1]))
    if not files:
        return None
    return {"restart_file": f"restart/{files[-1].name}", "step": int(files[-1].name.split(".")[1]),
            "candidates": [f"restart/{f.name}" for f in reversed(files)]}


def loop_seconds(log) -> float:
    """Seconds the engine spent in its time loops [s]: the sum of the log's ``Loop time of`` lines
    (0 without a log)."""
    text = Path(log).read_text(errors="replace") if Path(log).exists() else ""
    return sum(float(x) for x in re.findall(r"Loop time of ([0-9.eE+-]+)", text))


class RestartFiles:
    """The run-file methods of an :class:`engines.base.Engine` whose decks write LAMMPS' restart
    files and log (LIGGGHTS and LAMMPS): the loop time from the log, where a killed run resumes,
    and the frames and wall series cut back to that step before it does."""

    def loop_time(self, log: Path) -> float:
        """Seconds the engine spent in its time loop [s] (:func:`loop_seconds`)."""
        return loop_seconds(log)

    def resume_state(self, run_dir: Path):
        """:func:`restart_resume_state`."""
        return restart_resume_state(run_dir)

    def prepare_resume(self, run_dir: Path, resume: dict):
        """Cut every frame segment and the wall series back to the restart step
        (:func:`cut_back_to_step`)."""
        cut_back_to_step(run_dir, resume["step"])


def wall_rows(run_dir) -> np.ndarray | None:
    """Rows of the deck's wall sampler (``fix ave/time`` into ``walls.<n>.txt``, one file per
    run segment), files in numeric order, or None when there are none."""
    files = sorted(Path(run_dir).glob("walls.*.txt"), key=lambda p: _number(p.name))
    rows = [a for a in (_rows(f) for f in files) if a.size]
    return np.vstack(rows) if rows else None


def _rows(path: Path) -> np.ndarray:
    """The numbers of one sampler file; an empty array for a file with only its header (the last
    segment of a run ends on the step the previous one sampled)."""
    lines = [ln for ln in path.read_text().splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    return np.loadtxt(lines, ndmin=2) if lines else np.zeros((0, 0))


def _number(name: str) -> int:
    """The integer between the first two dots of a file name (-1 when there is none)."""
    part = name.split(".")[1] if name.count(".") >= 2 else ""
    return int(part) if part.isdigit() else -1


def deck_segments(steps: int, restart_every: int, start: int = 0) -> list[dict]:
    """The segments a shear cell or plane shear deck runs in (templates/liggghts/partials/segments.j2):
    from ``start`` (0, or the restart step a resumed run starts from) to the end, cut at every
    multiple of ``restart_every``; each writes the frames of its own steps into
    ``dump/frames.bin`` (the first segment of a fresh run) or ``dump/frames.<start>.bin``, and
    ends with the restart the next one starts from."""
    cuts = [s for s in range(restart_every, steps, restart_every) if s > start]
    bounds = [start, *cuts, steps]
    return [{"start": a, "stop": b, "last": b == steps,
             "dump_file": "frames.bin" if a == 0 else f"frames.{a:012d}.bin"}
            for a, b in zip(bounds[:-1], bounds[1:])]


def cut_back_to_step(run_dir, step: int) -> None:
    """Cut a LIGGGHTS or LAMMPS run's files back to the restart ``step`` before it resumes: every
    frame segment to its last snapshot at or before ``step`` (a segment left empty is removed) and
    the wall series (:func:`cut_wall_series`). The resumed run writes a new segment and a new
    ``walls.<step>.txt`` from there; rows the killed run wrote after the restart step would
    otherwise be read twice. Without ``dump/columns.json`` no frame was written and there is
    nothing to cut in the dumps."""
    run_dir = Path(run_dir)
    cols = run_dir / "dump" / "columns.json"
    if cols.exists():
        n = len(json.loads(cols.read_text()))
        for seg in dump_segments(run_dir):
            if truncate_binary_dump(seg, n, step) == 0:
                seg.unlink()
    cut_wall_series(run_dir, step)


def cut_wall_series(run_dir, step: int) -> None:
    """Cut the wall series a deck writes with ``fix ave/time ... file walls.<start step>.txt`` back to
    the rows of steps <= ``step`` (a resumed run writes its own file from there; rows after the
    restart step would appear twice); a file begun after ``step`` is removed."""
    for f in Path(run_dir).glob("walls.*.txt"):
        start = f.name.split(".")[1]
        if start.isdigit() and int(start) > step:
            f.unlink()
            continue
        lines = f.read_text().splitlines(keepends=True)
        keep = [ln for ln in lines if ln.startswith("#") or not ln.split() or int(float(ln.split()[0])) <= step]
        if len(keep) != len(lines):
            write_text(f, "".join(keep))
