"""A triaxial run killed (orchestrator and engine) resumes from its last restart (LIGGGHTS) or
checkpoint (YADE) and goes on exactly as an uninterrupted run (docs/engines.md, Resume; issue #16):

* ``test_killed_triaxial_resumes_exactly`` (default suite, both engines; the cheapest exact check):
  an uninterrupted run to its third resume point T, killed there; a second run killed at a random
  step after its first resume point and run again until T: every frame up to T once, at the
  uninterrupted run's steps, positions equal (bound 1e-9 r_min; bit-identical is what is measured),
  the ``triax.txt`` rows up to T equal. Both decks run in segments that end at their resume points
  and start again from the file written there (LIGGGHTS: ``clear`` + ``read_restart``; YADE:
  ``O.save`` + ``O.load``), in an uninterrupted run as in a resumed one.
* ``test_killed_triaxial_resumes`` (slow, both engines): killed during axial loading and run to the
  end, against a whole uninterrupted run: the same series rows, equal, and frames (no step twice,
  none missing), positions equal at every frame (1e-9 r_min), the same stage-1 end, the asked axial
  strain.
"""
from __future__ import annotations

import json
import random
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from engines.lammps_dump import read_binary_dump
from engines.liggghts.segments import dump_segments
from engines.yade.output import chunk_files
from orchestrator.frames import Frames
from resume_util import engine_step, kill_run, rerun_resumes, wait_until

pytestmark = pytest.mark.engine
SCHEDULE_MINUTES = 2          #: the exact check on both engines, ~55 s each (tests/conftest.py schedule_groups)
REPO = Path(__file__).resolve().parents[1]
SMOKE = REPO / "cases" / "triaxial_smoke.yaml"
#: largest position difference / r_min between a resumed and an uninterrupted run, at any frame: exact
EXACT = 1e-9


def orchestrator(*args):
    return [sys.executable, "-m", "orchestrator", *args]


def _loading_resume_point(engine: str, run_dir: Path) -> int | None:
    """Step of a resume point written after the loading started, once one exists."""
    if engine == "liggghts":
        from engines.liggghts.triaxial import read_restart_states
        states = read_restart_states(run_dir)
        loading = [s for s, st in states.items() if st["stage"] == 2 and s > st["shear_start"]
                   and (run_dir / "restart" / f"state.{s}.restart").exists()]
        return max(loading) if loading else None
    log = run_dir / "engine.log"
    if not (run_dir / "checkpoint.yade.gz").exists() or not log.exists():
        return None
    text = log.read_text(errors="replace")
    start = [int(x) for x in __import__("re").findall(r"SHEAR start at iter (\d+)", text)]
    ck = [int(x) for x in __import__("re").findall(r"CHECKPOINT iter (\d+)", text)]
    after = [c for c in ck if start and c > start[0]]
    return after[-1] if after else None


def _series(run_dir: Path) -> np.ndarray:
    return np.loadtxt(run_dir / "triax.txt", comments="#", ndmin=2)


def _metrics(run_dir: Path) -> dict:
    from orchestrator.scenes import triaxial as T
    params = json.loads((run_dir / "params.json").read_text())
    p = params["scene"]["pressure"]
    a = T.analyse(T.read_series(run_dir), p)
    sh = a["shear"]
    s1, s3 = a["sigma1"][sh], a["sigma3"][sh]
    w = T.smoothing_rows(int(sh.sum()))
    return {"final_ratio": float(np.mean(s1[-w:]) / np.mean(s3[-w:])),
            "stray": float(np.max(np.abs(T.running_mean(s3 / p - 1, w)))),
            "final_axial_strain": float(a["axial_strain"][-1])}


@pytest.mark.slow(reason="two whole smoke runs, one after the other (LIGGGHTS ~2 x 3.5 min, YADE longer on the "
                        "shared machine); the default suite's exact check is test_killed_triaxial_resumes_exactly")
@pytest.mark.parametrize("engine", ["liggghts", "yade"])
def test_killed_triaxial_resumes(engine, tmp_path, engines_installed):
    runs, ref_runs = tmp_path / "runs", tmp_path / "ref"
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    # the uninterrupted reference first (one engine at a time on the shared machine)
    done = subprocess.run(orchestrator("run", str(SMOKE), "--engine", engine, "--runs", str(ref_runs), "--quiet"),
                          timeout=3600, **quiet)
    assert done.returncode == 0
    ref_dir = next(ref_runs.glob(f"triaxial_smoke/{engine}-*"))
    proc = subprocess.Popen(orchestrator("run", str(SMOKE), "--engine", engine, "--runs", str(runs), "--quiet"),
                            start_new_session=True, **quiet)
    t0, run_dir, point = time.time(), None, None
    while time.time() - t0 < 2400:              # YADE on a shared machine: ~10 min
        found = list(runs.glob(f"triaxial_smoke/{engine}-*"))
        if found:
            run_dir = found[0]
            point = _loading_resume_point(engine, run_dir)
            if point is not None:
                break
        assert proc.poll() is None, "the run ended before it could be killed during loading"
        time.sleep(0.1)
    assert point is not None, "no resume point written during loading"
    kill_run(proc, run_dir)

    t1 = time.time()
    summary = rerun_resumes(orchestrator("run", str(SMOKE), "--engine", engine, "--runs", str(runs), "--quiet"),
                            run_dir, timeout=2400)
    resumed_wall = time.time() - t1
    log = (run_dir / "engine.log").read_text(errors="replace")
    if engine == "liggghts":
        st = summary["resumed_from"]["scene_state"]
        assert st["stage"] == 2 and summary["resumed_from"]["step"] >= st["shear_start"]
        assert "SHEAR from step %d" % summary["resumed_from"]["step"] in log
    else:
        assert "RESUMED at iter" in log and ", stage 2" in log.split("RESUMED at iter")[-1].splitlines()[0]

    # the series: the same rows as the uninterrupted run, none twice, none missing, equal
    a, b = _series(run_dir), _series(ref_dir)
    np.testing.assert_array_equal(a[:, 0], b[:, 0])
    steps = a[:, 0]
    assert np.all(np.diff(steps[:-1]) > 0) and steps[-1] >= steps[-2]   # YADE's final row may repeat the last
    np.testing.assert_array_equal(a, b)
    iso, iso_ref = summary["scene"]["isotropic_end"], json.loads((ref_dir / "summary.json").read_text())["scene"]["isotropic_end"]
    assert iso == iso_ref
    # frames: strictly increasing steps, the uninterrupted run's, positions equal at every frame
    fa, fb = Frames(run_dir), Frames(ref_dir)
    assert np.all(np.diff(fa.step) > 0)
    np.testing.assert_array_equal(fa.step, fb.step)
    r_min = float(fb.radius.min())
    err = float(np.nanmax(np.abs(fa.position - fb.position))) / r_min
    assert err <= EXACT, f"{err:.3g} r_min after resuming at step {point}"
    if engine == "yade":             # the membrane frames, those from before the kill too
        ma = np.load(run_dir / "dump" / "membrane.npz")
        mb = np.load(ref_dir / "dump" / "membrane.npz")
        np.testing.assert_array_equal(ma["iter"], mb["iter"])
        np.testing.assert_array_equal(ma["position"], mb["position"])
    m = _metrics(run_dir)
    assert m["final_axial_strain"] == pytest.approx(0.05, rel=0.002)
    print(f"\n{engine}: resumed at step {point}, resumed run {resumed_wall:.1f} s wall; {fa.n_frames} frames, "
          f"max |dx| = {err:.3g} r_min; final sigma1/sigma3 {m['final_ratio']:.4f}")


def _resume_points(engine: str, run_dir: Path) -> list[int]:
    """Steps of the resume points written so far: LIGGGHTS restart files (each with its state line),
    YADE checkpoints (logged once saved)."""
    if engine == "liggghts":
        from engines.liggghts.triaxial import read_restart_states
        states = read_restart_states(run_dir)
        return sorted(s for s in states if (run_dir / "restart" / f"state.{s}.restart").exists())
    try:
        text = (run_dir / "engine.log").read_text(errors="replace")
    except OSError:
        return []
    return [int(x) for x in re.findall(r"^CHECKPOINT iter (\d+)", text, flags=re.M)]


def _raw_output(engine: str, run_dir: Path, upto: int):
    """What the engine wrote up to step ``upto``: {step: positions (n, 3) [m] in id order}, how often
    each step was written, and the ``triax.txt`` rows. LIGGGHTS' segments repeat the frame of their
    first step (the reader keeps the later copy); YADE writes each frame once."""
    frames, count = {}, {}
    if engine == "liggghts":
        cols = json.loads((run_dir / "dump" / "columns.json").read_text())
        xi, ii = [cols.index(c) for c in ("x", "y", "z")], cols.index("id")
        for step, a in read_binary_dump(dump_segments(run_dir), len(cols)):
            if step <= upto:
                frames[step] = a[np.argsort(a[:, ii])][:, xi]
                count[step] = 1
    else:
        for c in chunk_files(run_dir):
            with np.load(c) as z:
                for k, it in enumerate(z["iter"].astype(int)):
                    if it <= upto:
                        count[it] = count.get(it, 0) + 1
                        frames.setdefault(int(it), z["position"][k])
    rows = np.loadtxt(run_dir / "triax.txt", comments="#", ndmin=2)
    return frames, count, rows[rows[:, 0] <= upto]


def _chunk_tests(run_dir: Path) -> dict[int, str]:
    """{chunk: its test's lines} from a run's log: the "ISO chunk k" line and the "ISO creep" line that
    follows it (the last printing of each chunk: a resumed run's log holds the killed part too)."""
    out, k = {}, None
    for line in re.findall(r"^ISO (?:chunk|creep).*$", (run_dir / "engine.log").read_text(errors="replace"), re.M):
        if line.startswith("ISO chunk"):
            k = int(line.split()[2].rstrip(":"))
            out[k] = line
        elif k is not None:
            out[k] += "\n" + line
    return out


#: the smoke case with the drag stage's volume-creep test: its last chunk-mean volume is resume state
CREEP = REPO / "tests" / "data" / "triaxial_smoke_creep.yaml"
#: the smoke case on 100 inserted clumps (LIGGGHTS' multisphere deck): the bodies' state comes back from
#: the restart file once the templates and fix multisphere are defined again; the platens' heights once
#: closed on the inserted sample are resume state
CLUMPS = REPO / "tests" / "data" / "triaxial_smoke_clumps.yaml"


@pytest.mark.parametrize("engine,case", [pytest.param("liggghts", SMOKE, id="liggghts"),
                                         pytest.param("yade", SMOKE, id="yade"),
                                         pytest.param("liggghts", CREEP, id="liggghts-creep",
                                                      marks=pytest.mark.slow(reason="a third kill-and-resume "
                                                                             "sequence, ~40 s")),
                                         pytest.param("liggghts", CLUMPS, id="liggghts-clumps")])
def test_killed_triaxial_resumes_exactly(engine, case, tmp_path, engines_installed):
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    cmd = lambda runs: orchestrator("run", str(case), "--engine", engine, "--runs", str(runs), "--quiet")
    n_points = 3
    # 1. uninterrupted to its n-th resume point T, then killed there
    ref = subprocess.Popen(cmd(tmp_path / "ref"), **quiet)
    ref_dir = lambda: next(iter((tmp_path / "ref").glob(f"triaxial_smoke/{engine}-*")), None)
    wait_until(ref, lambda: ref_dir() and len(_resume_points(engine, ref_dir())) >= n_points, 900,
               f"resume point {n_points} of the uninterrupted run")
    points = _resume_points(engine, ref_dir())
    T = points[n_points - 1]
    thermo_every = json.loads((ref_dir() / "params.json").read_text())["scene"]["steps"] // 200
    kill_run(ref, ref_dir())
    # 2. killed at a random step between the first resume point and T ...
    runs = tmp_path / "runs"
    proc = subprocess.Popen(cmd(runs), **quiet)
    run_dir = lambda: next(iter(runs.glob(f"triaxial_smoke/{engine}-*")), None)
    wait_until(proc, lambda: run_dir() and _resume_points(engine, run_dir()), 900, "a first resume point")
    first = _resume_points(engine, run_dir())[0]
    # before the second resume point: the log reports the step every thermo_every steps, so the engine
    # may be up to that far on when it is killed (the run must resume before T)
    kill_at = random.randint(first + 1, max(first + 1, points[1] - thermo_every - 100))
    wait_until(proc, lambda: (engine_step(run_dir(), engine) or 0) >= kill_at, 900, f"step {kill_at}")
    kill_run(proc, run_dir())
    # 3. ... and run again: it resumes; killed once it has passed T
    again = subprocess.Popen(cmd(runs), **quiet)
    wait_until(again, lambda: (run_dir() / ("resume.in" if engine == "liggghts" else "resume.py")).exists(), 120,
               "a resumed deck")
    wait_until(again, lambda: T in _resume_points(engine, run_dir()), 900, f"resume point {T} of the resumed run")
    kill_run(again, run_dir())
    log = (run_dir() / "engine.log").read_text(errors="replace")
    summary = json.loads((run_dir() / "summary.json").read_text())
    assert summary.get("resumed_from"), "the second run started afresh instead of resuming"
    if engine == "liggghts":
        resumed_at = summary["resumed_from"]["step"]
        assert f"read_restart restart/state.{resumed_at}.restart" in log
    else:
        resumed_at = int(re.search(r"^RESUMED at iter (\d+)", log, flags=re.M).group(1))
    assert first <= resumed_at < T

    # the stage-1 chunk tests as the uninterrupted run printed them (with the creep test: the change of
    # the chunk-mean volume, whose last mean a resumed deck takes from its state line)
    a, b = _chunk_tests(run_dir()), _chunk_tests(ref_dir())
    common = sorted(set(a) & set(b))
    assert all(a[k] == b[k] for k in common), [(a[k], b[k]) for k in common if a[k] != b[k]]
    assert common or case != CREEP, "no chunk test before T: the creep state was not exercised"
    want, n_want, rows_want = _raw_output(engine, ref_dir(), T)
    got, n_got, rows_got = _raw_output(engine, run_dir(), T)
    # frames up to T (YADE's are stamped one step after its checkpoint multiples), some after the resume
    assert sorted(got) == sorted(want) and max(got) > resumed_at, (sorted(got), sorted(want), resumed_at)
    assert set(n_got.values()) == {1} and set(n_want.values()) == {1}, "a frame written twice"
    r_min = float(np.loadtxt(ref_dir() / "particles.txt", ndmin=2)[:, 1].min())
    err = max(float(np.abs(got[s] - want[s]).max()) for s in want) / r_min
    print(f"\n{engine}: killed at step {kill_at}, resumed from {resumed_at}, compared to step {T}: "
          f"{len(got)} frames, max |dx| = {err:.3g} r_min; {len(rows_got)} series rows")
    assert err <= EXACT, f"{err:.3g} r_min (killed at step {kill_at}, resumed from {resumed_at})"
    # the series: the same rows, each step once, equal
    assert np.all(np.diff(rows_got[:, 0]) > 0) and rows_got[-1, 0] > resumed_at
    np.testing.assert_array_equal(rows_got, rows_want)
