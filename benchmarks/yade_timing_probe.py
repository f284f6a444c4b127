"""Where a YADE run's time goes: YADE's own per-engine timing over a few steps from the run's last
checkpoint, in a copy of the run directory (the run itself is left untouched).

    python benchmarks/yade_timing_probe.py RUN_DIR [--steps 1000] [--threads 1 2] [--verlet-dist D]

Prints the steps per CPU second and per wall second, the interactions (potential and real) and
``yade.timing.stats()`` (``O.timingEnabled``: the share of every engine, the orchestrator's
PyRunners among them). ``--threads``: YADE's OpenMP threads (``yade -j N``), one probe each, from
the same checkpoint: the wall-time speed-up of N threads over the first (on a quiet machine).
``--verlet-dist``: the collider's sweep distance for the probe (YADE's ``verletDist``; negative: a
fraction of the smallest radius, the decks keep YADE's -0.5), 50 steps before the timing.
docs/validation.md quotes it for the medium clump triaxial (session 24), docs/engines.md for the shear cell.
"""
from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

PROBE = '''
{verlet}
O.timingEnabled = True
from yade import timing
_t0, _w0, _i0 = time.process_time(), time.perf_counter(), O.iter
O.run({steps}, True)
print("PROBE steps per CPU second %.2f, per wall second %.2f; interactions %d, real %d" % (
    (O.iter - _i0) / (time.process_time() - _t0), (O.iter - _i0) / (time.perf_counter() - _w0),
    len(O.interactions), O.interactions.countReal()), flush=True)
timing.stats()
sys.stdout.flush()
os._exit(0)
'''
#: the collider's sweep distance set before the probe, and 50 steps for it to rebuild its pairs
VERLET = '''
for _e in O.engines:
    if isinstance(_e, Collider):
        _e.verletDist = {dist}
O.run(50, True)
'''
#: what a resumed YADE deck reads besides its checkpoint
FILES = ("checkpoint.yade.gz", "clumps.txt", "particles.txt", "params.json", "resume.py", "triax.txt", "walls.yade.*.npy")
#: where each scene's resumed script has set up its Python side and enters its own loop (the probe runs there instead)
LOOP_STARTS = ("_pid_of = dict(", "_loop = 0.0")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--threads", type=int, nargs="+", default=[1], help="YADE's OpenMP threads, a probe each")
    ap.add_argument("--verlet-dist", type=float, default=None, help="the collider's verletDist for the probe")
    a = ap.parse_args(argv)
    run = a.run_dir
    if not (run / "checkpoint.yade.gz").exists() or not ((run / "resume.py").exists() or (run / "script.py").exists()):
        print(f"error: {run}: no checkpoint.yade.gz and YADE script here (a YADE run that has checkpointed)", file=sys.stderr)
        return 2
    wall = {}
    for threads in a.threads:
        with tempfile.TemporaryDirectory(prefix="yade_probe_") as tmp:
            probe = probe_script(run, Path(tmp), PROBE.format(steps=int(a.steps), verlet=VERLET.format(
                dist=a.verlet_dist) if a.verlet_dist is not None else ""))
            out = subprocess.run(["yade", "-n", "-j", str(threads), "-x", probe.name], cwd=tmp, capture_output=True,
                                 text=True)
        if "PROBE" not in out.stdout:
            print(out.stdout + out.stderr)
            return 1
        text = out.stdout[out.stdout.find("PROBE"):]
        print(f"-j {threads}: {text}")
        wall[threads] = float(re.search(r"per wall second ([\d.]+)", text).group(1))
    first = a.threads[0]
    for threads, speed in wall.items():
        if threads != first:
            print(f"{threads} threads against {first}: {speed / wall[first]:.2f}x the steps per wall second")
    return 0


def probe_script(run: Path, tmp: Path, tail: str) -> Path:
    """A copy in ``tmp`` of what ``run``'s resumed YADE deck reads, and ``tmp/probe.py``: the resumed
    deck up to its own loop (the scene loaded from the checkpoint, its Python side set up), then
    ``tail``. The run itself is left untouched."""
    for pattern in FILES:
        for f in run.glob(pattern):
            shutil.copy2(f, tmp / f.name)
    shutil.copytree(run / "yade_runtime", tmp / "yade_runtime")
    (tmp / "dump").mkdir()
    # a run not resumed yet has only its script, which is the resumed deck but for RESUME
    deck = (run / "resume.py").read_text() if (run / "resume.py").exists() else \
        (run / "script.py").read_text().replace("\nRESUME = False\n", "\nRESUME = True\n", 1)
    cut = min(deck.index(m) for m in LOOP_STARTS if m in deck)   # after the resume, before the run's own loop
    (tmp / "probe.py").write_text(deck[:cut] + tail)
    return tmp / "probe.py"


if __name__ == "__main__":
    sys.exit(main())
