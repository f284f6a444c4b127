"""Benchmark (not a test): YADE's shear cell with and without the wall-facet pairs (session 28).

YADE 2023.02's collider pairs every two bodies whose bounding boxes overlap, fixed wall facets too
(``Collider::mayCollide`` does not ask whether a body moves). The shear cell's 1 728 facets overlap
their neighbours' boxes: ~34 000 facet pairs at 4 108 grains, which no functor serves (no force)
but which the InteractionLoop visited every step. The deck now gives the facets a group mask that the
collider's ``avoidSelfInteractionMask`` keeps apart (templates/yade/shear_cell.py.j2,
``WALL_FACET_MASK``). This benchmark runs the deck as rendered and its variant with
``WALL_FACET_MASK = 1`` (the grains' mask: the facet pairs are made again, the deck of before):

    .venv/bin/python benchmarks/bench_yade_facet_pairs.py [CASE]
        whole runs of a case (default ``shear_cell_smoke.yaml``), one after the other, one thread:
        the engine's CPU time of each, their ratio, the pair census at the end (``interactions.json``)
        and the final piston height (the same cell to within the trajectory's divergence: the
        summation order of the forces changes with the pairs, not the forces)
    .venv/bin/python benchmarks/bench_yade_facet_pairs.py --run-dir RUN_DIR [--steps 1000]
        from a YADE shear-cell run's last checkpoint (a copy; the run is left alone; a run of before
        session 28 will do: the masks are set here), ``--steps`` steps each way, the pairs of the
        checkpoint cleared in both (the contacts' history restarts alike): steps per CPU second and
        the census

Run it on a quiet core (``taskset -c 1`` beside a long run on core 0): the figures are CPU times.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

from bench_yade_speed import render                      # noqa: E402  (the orchestrator's own rendering)
from yade_timing_probe import probe_script             # noqa: E402  (a resumed deck cut before its own loop)

MASKED = "WALL_FACET_MASK = 3"
UNMASKED = "WALL_FACET_MASK = 1"

PROBE = '''
O.interactions.clear()
_t0, _i0 = time.process_time(), O.iter
O.run({steps}, True)
_census = {{}}
for _i in O.interactions.all():
    _pair = _census.setdefault("-".join(sorted((O.bodies[_i.id1].shape.__class__.__name__,
                                                O.bodies[_i.id2].shape.__class__.__name__))), {{"pairs": 0, "real": 0}})
    _pair["pairs"] += 1
    _pair["real"] += int(_i.isReal)
print("PROBE %.3f %s" % ((O.iter - _i0) / (time.process_time() - _t0), json.dumps(_census)), flush=True)
os._exit(0)
'''


def template_masks() -> tuple[int, int]:
    """(WALL_FACET_MASK, AVOID_SELF_MASK) as templates/yade/shear_cell.py.j2 sets them."""
    text = (REPO / "templates" / "yade" / "shear_cell.py.j2").read_text()
    return tuple(int(re.search(rf"^{name} = (\d+)$", text, re.M).group(1)) for name in ("WALL_FACET_MASK", "AVOID_SELF_MASK"))


def variant(script: Path, masked: bool) -> None:
    """Make ``script`` the deck as rendered (``masked``) or its variant with the facet pairs."""
    text = script.read_text()
    if MASKED not in text and UNMASKED not in text:
        raise SystemExit(f"{script}: no '{MASKED}' line (not a YADE shear-cell deck of session 28 or later)")
    script.write_text(text.replace(UNMASKED, MASKED) if masked else text.replace(MASKED, UNMASKED))


def yade_cpu(script: Path, args=()) -> tuple[float, str]:
    """Run ``yade -n -j 1 -x script`` in its directory; the child's CPU time [s] and its stdout."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    pr = subprocess.run(["yade", "-n", "-j", "1", "-x", script.name, *args], cwd=script.parent, capture_output=True,
                        text=True, env=dict(os.environ, OMP_NUM_THREADS="1"))
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if pr.returncode != 0 and "PROBE" not in pr.stdout:
        raise SystemExit(f"{script}: yade failed\n{pr.stdout[-2000:]}\n{pr.stderr[-2000:]}")
    return (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime), pr.stdout


def final_piston_z(run_dir: Path) -> float:
    """The lower piston's last displacement [m] (the wall series' first column, yade_runtime/series.py)."""
    rows = np.concatenate([np.load(f) for f in sorted(run_dir.glob("walls.yade.*.npy"))])
    return float(rows[-1, 1])


def whole_runs(case_file: str) -> None:
    with tempfile.TemporaryDirectory(prefix="bench_facets_") as tmp:
        base = Path(tmp) / "masked"
        script = render(case_file, "yade", base, REPO)
        other = Path(tmp) / "facet_pairs"
        shutil.copytree(base, other)
        variant(other / script.name, masked=False)
        rows = []
        for label, d in (("facet pairs kept apart (the deck)", base), ("facet pairs made (before)", other)):
            cpu, _ = yade_cpu(d / script.name)
            census = json.loads((d / "interactions.json").read_text())
            rows.append((label, cpu, census, final_piston_z(d)))
            print(f"{label}: {cpu:.1f} s of CPU; pairs at the end {census}", flush=True)
    (_, c0, _, z0), (_, c1, _, z1) = rows
    print(f"\n{case_file}, YADE, whole runs, one thread: {c0:.1f} s against {c1:.1f} s of CPU: "
          f"{c1 / c0:.2f}x faster without the facet pairs; final piston displacement {z0 * 1e6:.2f} against "
          f"{z1 * 1e6:.2f} um")


def from_checkpoint(run_dir: Path, steps: int) -> None:
    if not (run_dir / "checkpoint.yade.gz").exists():
        raise SystemExit(f"error: {run_dir}: no checkpoint.yade.gz (a YADE shear-cell run that has checkpointed)")
    rates = []
    for label, masked in (("facet pairs kept apart (the deck)", True), ("facet pairs made (before)", False)):
        with tempfile.TemporaryDirectory(prefix="bench_facets_") as tmp:
            # the masks as the deck of today sets them, or the grains' mask on the facets too (before):
            # set here whatever the run's own template did, so that any YADE shear-cell run will do
            wall, avoid = template_masks() if masked else (1, 0)
            remask = ("for _b in O.bodies:\n    if _b.shape.__class__.__name__ == 'Facet':\n"
                      f"        _b.groupMask = {wall}\n"
                      f"for _e in O.engines:\n    if isinstance(_e, Collider):\n        _e.avoidSelfInteractionMask = {avoid}\n")
            probe = probe_script(run_dir, Path(tmp), remask + PROBE.format(steps=steps))
            _, out = yade_cpu(probe)
            line = next((ln for ln in out.splitlines() if ln.startswith("PROBE ")), None)
            if line is None:
                raise SystemExit(f"{run_dir}: the probe printed no PROBE line\n{out[-2000:]}")
            rate, census = line.split(" ", 2)[1:]
            rates.append(float(rate))
            print(f"{label}: {float(rate):.2f} steps per CPU second; pairs {census}", flush=True)
    print(f"\n{run_dir}, {steps} steps from its checkpoint: {rates[0] / rates[1]:.2f}x faster without the facet pairs")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", nargs="?", default="shear_cell_smoke.yaml", help="case file under cases/")
    ap.add_argument("--run-dir", type=Path, help="a YADE shear-cell run with a checkpoint: time steps from it")
    ap.add_argument("--steps", type=int, default=1000)
    a = ap.parse_args(argv)
    if a.run_dir:
        from_checkpoint(a.run_dir, a.steps)
    else:
        whole_runs(a.case)
    return 0


if __name__ == "__main__":
    sys.exit(main())
