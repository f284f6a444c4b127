"""Every fault a new user met (issue #16) ends in one message naming the file or field, what is wrong
and the fix, with exit status 2 for bad input and 1 for a failed run, and no traceback; files follow
the user's umask; a damaged or stale run is detected."""
from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.frames import write_frames

from cli_util import main_here

SCHEDULE_MINUTES = 0.16   #: engine-free tests, ~10 s quiet: early in the fast tier (tests/conftest.py schedule_groups)

REPO = Path(__file__).resolve().parents[1]
CASES = REPO / "cases"
IMPACT = CASES / "verification" / "chung_ooi_4_oblique.yaml"        # 17 spheres, ~1 s per engine
SMOKE = CASES / "shear_cell_smoke.yaml"
NOBODY = 65534


def cli(*args, as_nobody=False, timeout=600, env=None):
    """``orchestrator ARGS``: in this process (the imports are paid once), or as an unprivileged user
    in a subprocess when the tests run as root (root ignores directory permissions)."""
    args = [str(a) for a in args]
    if as_nobody:
        pre = ["setpriv", f"--reuid={NOBODY}", f"--regid={NOBODY}", "--clear-groups"] if os.geteuid() == 0 else []
        r = subprocess.run(pre + [sys.executable, "-m", "orchestrator", *args], capture_output=True, text=True,
                           timeout=timeout, cwd="/", env=dict(os.environ, **(env or {})))
        return r
    return main_here(*args)


def one_message(out, status: int, *words: str):
    """Exit ``status``, no traceback, and every one of ``words`` in stderr."""
    assert out.returncode == status, (out.returncode, out.stdout[-2000:], out.stderr[-2000:])
    assert "Traceback" not in out.stderr + out.stdout, out.stderr
    for w in words:
        assert w in out.stderr, (w, out.stderr)


def case_file(tmp_path: Path, name: str, body: str, base: Path = SMOKE) -> Path:
    p = tmp_path / name
    p.write_text(f"extends: {base}\n{body}")
    return p


@pytest.fixture
def shared_dir():
    """A directory an unprivileged user may reach and write into (for the permission faults; pytest's
    own tmp_path lies under a 0700 directory of the user running the tests)."""
    import shutil
    import tempfile
    d = Path(tempfile.mkdtemp(prefix="faults-", dir="/tmp"))
    d.chmod(0o777)
    yield d
    for q in d.rglob("*"):
        if q.is_dir():
            q.chmod(0o755)
    shutil.rmtree(d, ignore_errors=True)


def synthetic_run(run_dir: Path, scene_kind: str = "shear_cell", n_frames: int = 4) -> Path:
    """A run directory holding a frames.h5 of a few frames (a lattice drifting in x) and its case."""
    rng = np.random.default_rng(1)
    n = 27
    g = np.stack(np.meshgrid(*[np.arange(3.0)] * 3, indexing="ij"), -1).reshape(-1, 3) * 2e-5
    pos = np.stack([g + [k * 1e-6, 0, 0] + rng.normal(0, 1e-8, g.shape) for k in range(n_frames)])
    case = {"name": f"syn_{scene_kind}", "scene": {"kind": scene_kind, "cell_diameter": "0.3 mm"},
            "material": {"density": "2500 kg/m^3"}}
    run_dir.mkdir(parents=True, exist_ok=True)
    write_frames(run_dir / "frames.h5", np.arange(1, n + 1), np.full(n, 1e-5), np.arange(n_frames) * 1e-3, pos,
                 step=np.arange(n_frames) * 100, meta={"case": case, "engine": "synthetic"})
    (run_dir / "case.yaml").write_text("analysis: [displacements]\n")
    return run_dir


# --------------------------------------------------------------------------------- case files
def test_binary_file_as_case(tmp_path):
    p = tmp_path / "scan.yaml"
    p.write_bytes(bytes(range(256)) * 4)
    one_message(cli("validate", p), 2, str(p), "not a text file", "give a YAML case file")


def test_directory_as_case(tmp_path):
    one_message(cli("run", tmp_path, "--dry-run"), 2, str(tmp_path), "is a directory", "give a YAML case file")


def test_negative_friction_and_list_restitution_say_the_fix(tmp_path):
    p = case_file(tmp_path, "bad.yaml", "contact: {friction: -0.1, restitution: [0.5, 0.6]}\n")
    out = cli("validate", p)
    one_message(out, 2, str(p), "contact.friction", "set contact.friction to a value of at least 0",
                "contact.restitution", "takes one value, not a list")


def test_misspelt_scene_field_gets_did_you_mean(tmp_path):
    p = case_file(tmp_path, "typo.yaml", "scene: {psd: {medain: 30 um}}\n")
    one_message(cli("validate", p), 2, "scene.psd.medain", "did you mean 'median'")


def test_error_in_parent_case_is_reported_against_the_parent(tmp_path):
    parent = case_file(tmp_path, "parent.yaml", "contact: {friction: -0.2}\n")
    child = tmp_path / "child.yaml"
    child.write_text("extends: parent.yaml\nname: child\n")
    out = cli("validate", child)
    one_message(out, 2, str(parent), "contact.friction")
    assert out.stderr.index(str(parent)) < out.stderr.index("contact.friction")


def _safe_fraction(msg: str) -> float:
    import re
    m = re.search(r"timestep\.fraction <= ([0-9.]+)", msg)
    assert m, msg
    return float(m.group(1))


def test_time_step_fraction_limit_is_one_figure_and_it_holds(tmp_path):
    """Every refusal names the same largest safe fraction for the case, that fraction is accepted
    and a little more is refused (it read '<= 0.3' for 5 while 0.65 was accepted)."""
    figs = []
    for f in (5, 1.5, 0.9):
        out = cli("validate", case_file(tmp_path, f"f{f}.yaml", f"timestep: {{fraction: {f}}}\n"))
        one_message(out, 2, "timestep.fraction <=")
        figs.append(_safe_fraction(out.stderr))
    assert len(set(figs)) == 1, figs
    ok = cli("validate", case_file(tmp_path, "ok.yaml", f"timestep: {{fraction: {figs[0]}}}\n"))
    assert ok.returncode == 0, ok.stderr
    over = cli("validate", case_file(tmp_path, "over.yaml", f"timestep: {{fraction: {figs[0] + 0.01}}}\n"))
    one_message(over, 2, f"timestep.fraction <= {figs[0]:g}")


# --------------------------------------------------------------------------------- sizing
def test_enormous_case_is_sized_at_once_and_refused(tmp_path):
    p = case_file(tmp_path, "huge.yaml", "name: huge\nscene: {cell_diameter: 100 mm}\n")
    t0 = time.perf_counter()
    val = cli("validate", p)
    assert val.returncode == 0, val.stderr
    for w in ("particles", "steps", "memory", "engine time", "too big"):
        assert w in val.stdout, (w, val.stdout)
    runs = tmp_path / "runs"
    dry = cli("run", p, "--dry-run", "--runs", runs)
    wall = time.perf_counter() - t0
    one_message(dry, 2, "too big for this machine", "particles", "--force")
    assert not runs.exists(), "a refused dry run left a directory"
    assert wall < 120, f"validate + dry run took {wall:.0f} s (it packed for > 300 s before)"


def test_dry_run_prints_sizing_without_a_run_directory(tmp_path):
    out = cli("run", SMOKE, "--dry-run", "--runs", tmp_path / "runs")
    assert out.returncode == 0, out.stderr
    n_engines = len(load_case(SMOKE).engines)        # every installed engine with a deck for the scene
    assert n_engines >= 2
    assert out.stdout.count("particles") == n_engines and "memory" in out.stdout and "engine time" in out.stdout
    assert not (tmp_path / "runs").exists()


# --------------------------------------------------------------------------------- paths and files
def test_analyze_on_a_missing_path(tmp_path):
    one_message(cli("analyze", tmp_path / "nope"), 2, str(tmp_path / "nope"), "no such run directory")


def test_analyze_in_a_read_only_directory(shared_dir):
    run = synthetic_run(shared_dir / "run")
    for f in run.iterdir():
        f.chmod(0o644)
    run.chmod(0o555)
    out = cli("analyze", run, as_nobody=True, env={"MPLCONFIGDIR": str(shared_dir)})
    one_message(out, 2, str(run), "permission denied", "--out")


@pytest.mark.engine
def test_read_only_runs_directory(shared_dir, engines_installed):
    runs = shared_dir / "runs"
    runs.mkdir()
    runs.chmod(0o555)
    out = cli("run", IMPACT, "--engine", "liggghts", "--runs", runs, as_nobody=True,
              env={"MPLCONFIGDIR": str(shared_dir)})
    one_message(out, 2, str(runs), "permission denied")


def test_analyze_takes_a_run_by_its_frames_file(tmp_path):
    """``orchestrator analyze RUN/frames.h5`` is the run: the case's analyses, outputs in RUN/analysis
    (it was 'RUN/frames.h5/analysis: a path component is not a directory')."""
    run = synthetic_run(tmp_path / "run")
    out = cli("analyze", run / "frames.h5", "--analysis", "displacements")
    assert out.returncode == 0, out.stderr
    assert json.loads((run / "analysis" / "analysis_summary.json").read_text())["displacements"]["status"] == "ok"


def test_an_analysis_run_by_name_keeps_the_others_on_record(tmp_path):
    """Nothing computed is lost: ``analyze RUN --analysis rdf`` after the run's own analyses adds rdf
    to analysis_summary.json (and to a complete run's summary) instead of leaving rdf alone there;
    run again, an analysis replaces its own earlier result; ``report RUN --analysis NAME`` too."""
    from orchestrator.runner import merge_analyses
    run = synthetic_run(tmp_path / "run")
    summary_file = run / "analysis" / "analysis_summary.json"
    assert cli("analyze", run, "--analysis", "displacements").returncode == 0
    first = json.loads(summary_file.read_text())["displacements"]
    assert cli("analyze", run, "--analysis", "rdf").returncode == 0
    both = json.loads(summary_file.read_text())
    assert set(both) == {"displacements", "rdf"} and both["displacements"] == first
    assert cli("analyze", run, "--analysis", 'rdf:{"bins": 20}').returncode == 0
    again = json.loads(summary_file.read_text())
    assert set(again) == {"displacements", "rdf"} and again["rdf"]["options"] == {"bins": 20}
    # the report's --analysis takes the same path: it shows and adds, it does not drop the others
    assert cli("report", run, "--analysis", "displacements").returncode == 0
    shown = json.loads(summary_file.read_text())
    assert set(shown) == {"displacements", "rdf"} and shown["rdf"] == again["rdf"]
    assert "<h3>rdf</h3>" in (run / "report.html").read_text()
    # the spec list follows the results: one entry per analysis name, the newest options
    done = {"friction": {"name": "friction"}, "d2min": {"name": "d2min"}, "d2min_2": {"name": "d2min"}}
    res, specs = merge_analyses(done, ["friction", {"d2min": {"cutoff": 1}}, "d2min"], {"d2min": {"name": "d2min"}},
                                [{"d2min": {"cutoff": 2}}])
    assert set(res) == {"friction", "d2min"} and specs == ["friction", {"d2min": {"cutoff": 2}}]


def test_a_rerun_case_keeps_analyses_added_by_name_and_does_not_redo_its_own(tmp_path):
    """``orchestrator run`` of a complete case reuses it: an analysis added by name since
    (``analyze RUN --analysis rdf``) neither makes it redo the case's analyses every time nor leaves
    the record; an analysis the case now lists and the record lacks is run, beside the others."""
    from types import SimpleNamespace
    from orchestrator.integrity import run_record, verify_run
    from orchestrator.run_summary import read_summary
    from orchestrator.runner import _reuse
    run = synthetic_run(tmp_path / "run")
    (run / "summary.json").write_text(json.dumps({"status": "complete", "integrity": run_record(run)}))
    assert cli("analyze", run).returncode == 0                       # the case's own: displacements
    assert cli("analyze", run, "--analysis", "rdf").returncode == 0
    record = run / "analysis" / "analysis_summary.json"
    stamp = record.stat().st_mtime_ns
    out = _reuse(SimpleNamespace(analysis=["displacements"]), run, read_summary(run), True)
    assert record.stat().st_mtime_ns == stamp and set(out.summary["analysis"]) == {"displacements", "rdf"}
    out = _reuse(SimpleNamespace(analysis=["displacements", "coordination"]), run, read_summary(run), True)
    assert set(json.loads(record.read_text())) == {"displacements", "rdf", "coordination"}
    assert set(out.summary["analysis"]) == {"displacements", "rdf", "coordination"}
    assert verify_run(run, out.summary) == []


def test_bad_frame_index_and_analysis_options_are_one_message(tmp_path):
    """vtk --frame outside the run or not a number, an option an analysis does not take, and an
    analysis that fails on an option's value: one message each, no traceback on the screen (the
    failed analysis' traceback stays in analysis_summary.json), and nothing written for bad input."""
    run = synthetic_run(tmp_path / "run")
    for frame, says in (("4", "--frame 4: no such frame"), ("x", "--frame 'x' is not a frame index")):
        one_message(cli("vtk", run, "--frame", frame, "--out", tmp_path / "vtk"), 2, says, "has 4 frame(s)",
                    "from 0 to 3")
    assert not (tmp_path / "vtk").exists()
    assert cli("vtk", run, "--frame", "-4", "--out", tmp_path / "vtk").returncode == 0
    one_message(cli("analyze", run, "--analysis", 'displacements:{"bin": 5}', "--out", tmp_path / "a"), 2,
                "option 'bin'", "did you mean 'bins'")
    out = cli("analyze", run, "--analysis", 'displacements:{"pairs": "x"}', "--out", tmp_path / "a")
    one_message(out, 1, "displacements failed", str(tmp_path / "a" / "analysis_summary.json"))
    assert "traceback" in json.loads((tmp_path / "a" / "analysis_summary.json").read_text())["displacements"]


def test_truncated_frames_file_is_named_by_load_and_analyze(tmp_path):
    import orchestrator
    run = synthetic_run(tmp_path / "run")
    f = run / "frames.h5"
    f.write_bytes(f.read_bytes()[: f.stat().st_size // 2])
    with pytest.raises(orchestrator.frames.FramesError, match=str(f)):
        orchestrator.load(run).position
    one_message(cli("analyze", run, "--analysis", "displacements"), 2, str(f), "truncated or damaged")


def test_compare_of_different_cases_is_refused_with_what_differs(tmp_path):
    a = synthetic_run(tmp_path / "a", "shear_cell")
    b = synthetic_run(tmp_path / "b", "triaxial")
    out = cli("compare", a, b, "--out", tmp_path / "cmp")
    one_message(out, 2, "different scenes", "scene.kind", "--different-cases")


def test_ct_segment_of_an_all_zero_volume(tmp_path):
    v = tmp_path / "zero.npy"
    np.save(v, np.zeros((16, 16, 16), np.uint16))
    one_message(cli("ct", "segment", v, "--voxel-size", "2 um", "--out", tmp_path / "seg"), 2, str(v),
                "single grey value", "check that the file holds")


def test_a_2d_tiff_is_refused(tmp_path):
    import tifffile
    im = tmp_path / "slice.tif"
    tifffile.imwrite(im, (np.random.default_rng(0).random((32, 32)) * 255).astype(np.uint8))
    out = cli("ct", "segment", im, "--voxel-size", "2 um", "--out", tmp_path / "seg")
    assert out.returncode == 2 and "2-D image" in out.stdout + out.stderr and "grains" not in out.stdout


def test_outputs_follow_the_umask(tmp_path):
    """Analysis outputs were 0600 (a mkstemp file renamed): with umask 022 they must be 0644."""
    from orchestrator.analysis import run_analyses
    from orchestrator.frames import Frames
    run = synthetic_run(tmp_path / "run")
    old = os.umask(0o022)
    try:
        run_analyses(Frames(run), ["displacements"], run / "analysis")
    finally:
        os.umask(old)
    files = [f for f in (run / "analysis").rglob("*") if f.is_file()]
    assert files
    modes = {f.name: stat.S_IMODE(f.stat().st_mode) for f in files}
    assert set(modes.values()) == {0o644}, modes


# --------------------------------------------------------------------------------- stale state
def test_a_killed_writers_temporary_files_are_swept_and_nothing_else(tmp_path):
    """A SIGKILL between a temporary file's creation and its rename leaves ``.<name>.<8 chars><suffix>``
    (session 37: ``analysis/.profiles_axial.csv.zu2ysuqa.csv`` beside a resumed run's tables). The
    sweep a run does under its lock removes those and keeps every other file, hidden ones too."""
    from orchestrator.atomic import remove_stale_temp_files, temp_file
    (tmp_path / "analysis").mkdir()
    stale = [temp_file(tmp_path / "analysis" / "profiles_axial.csv", ".csv"),
             temp_file(tmp_path / "analysis" / "friction.png", ".png"), temp_file(tmp_path / "summary.json")]
    keep = [tmp_path / ".lock", tmp_path / "frames.h5.partial", tmp_path / "analysis" / "profiles_axial.csv",
            tmp_path / ".hidden_notes.txt", tmp_path / "dump" / "dump.100.liggghts"]
    for f in keep:
        f.parent.mkdir(exist_ok=True)
        f.write_text("x")
    assert sorted(remove_stale_temp_files(tmp_path)) == sorted(stale)
    assert not any(f.exists() for f in stale) and all(f.exists() for f in keep)


def test_running_without_a_live_owner_is_marked_interrupted(tmp_path):
    from orchestrator.run_summary import read_summary
    run = tmp_path / "run"
    run.mkdir()
    (run / "summary.json").write_text(json.dumps({"status": "running", "pid": 999999}))
    (run / ".lock").write_text("")
    # a live owner holds the lock: still running
    holder = subprocess.Popen([sys.executable, "-c", "import fcntl, sys, time; f = open(sys.argv[1], 'w'); "
                               "fcntl.flock(f, fcntl.LOCK_EX); print('locked', flush=True); time.sleep(60)",
                               str(run / ".lock")], stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "locked"
    assert read_summary(run)["status"] == "running"
    holder.kill()
    holder.wait()
    # its owner died: interrupted, on disk too
    assert read_summary(run)["status"] == "interrupted"
    assert json.loads((run / "summary.json").read_text())["status"] == "interrupted"


def test_forced_restart_files_are_dropped_with_the_resume_points(tmp_path):
    from orchestrator.runner import drop_resume_points
    (tmp_path / "restart").mkdir()
    (tmp_path / "restart" / "state.100.restart").write_bytes(b"x" * 10)
    (tmp_path / "restart_forced_liggghts_1234.data").write_bytes(b"x" * 7)
    assert drop_resume_points(tmp_path) == 17
    assert not list(tmp_path.rglob("*restart*.*"))


def test_engine_signal_is_named_with_the_way_to_resume():
    from engines.base import _exit_words
    assert _exit_words(-11) == "was killed by signal SIGSEGV (11)"
    assert _exit_words(139) == "was killed by signal SIGSEGV (11)"
    assert _exit_words(1) == "failed with exit status 1"


def test_debug_flag_shows_the_traceback(tmp_path):
    p = tmp_path / "bin.yaml"
    p.write_bytes(b"\xff\xfe\x00")
    assert "Traceback" not in cli("validate", p).stderr
    assert "Traceback" in cli("--debug", "validate", p).stderr


# --------------------------------------------------------------------------------- damaged runs
@pytest.mark.engine
def test_truncated_frames_file_of_a_complete_run_is_redone(tmp_path, engines_installed):
    runs = tmp_path / "runs"
    first = cli("run", IMPACT, "--engine", "liggghts", "--runs", runs, "--quiet")
    assert first.returncode == 0, first.stderr
    (run,) = runs.glob("*/liggghts-*")
    summary = json.loads((run / "summary.json").read_text())
    rec = summary["integrity"]["frames.h5"]
    assert rec["frames"] > 1 and rec["size"] == (run / "frames.h5").stat().st_size and len(rec["sha256"]) == 64
    ref = np.array(__import__("orchestrator").load(run).position)
    f = run / "frames.h5"
    f.write_bytes(f.read_bytes()[: f.stat().st_size // 2])
    again = cli("run", IMPACT, "--engine", "liggghts", "--runs", runs, "--quiet")
    assert again.returncode == 0, again.stderr
    assert "reused" not in again.stdout and "damaged" in again.stderr and str(f) in again.stderr
    assert np.array_equal(np.array(__import__("orchestrator").load(run).position), ref)
    third = cli("run", IMPACT, "--engine", "liggghts", "--runs", runs, "--quiet")
    assert "reused" in third.stdout and "damaged" not in third.stderr


@pytest.mark.engine
def test_same_case_started_three_times_at_once(tmp_path, engines_installed):
    """Runs of one case started together share its run directory: one drives it, the others wait
    for its lock and reuse the result (it said 'is being run by another process', exit 1). One
    engine at a time, so it fits the test machine (benchmarks/load_check.py: 8 runs, 5 cases)."""
    runs = tmp_path / "runs"
    cmd = [sys.executable, "-m", "orchestrator", "run", str(IMPACT), "--engine", "liggghts", "--runs", str(runs),
           "--quiet"]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(3)]
    outs = [p.communicate(timeout=600) + (p.returncode,) for p in procs]
    assert all(code == 0 for _, _, code in outs), [e[-2000:] for _, e, _ in outs]
    assert sum("reused" in o for o, _, _ in outs) == 2, [o for o, _, _ in outs]
    (run,) = runs.glob("*/liggghts-*")
    assert json.loads((run / "summary.json").read_text())["status"] == "complete"


@pytest.mark.engine
def test_progress_reaches_a_redirected_log_while_the_engine_runs(tmp_path, engines_installed):
    """`orchestrator run case > log 2>&1`: the start line (sizing) and progress lines are in the log
    while the engine still runs (issue #16 item 6; stdout was block-buffered off a terminal, so the
    start line only arrived at exit). The 30 s period is shortened to 2 s for the test."""
    log = tmp_path / "run.log"
    with open(log, "w") as fh:
        proc = subprocess.Popen([sys.executable, "-m", "orchestrator", "run", str(SMOKE), "--engine", "liggghts",
                                 "--runs", str(tmp_path / "runs"), "--no-report"], stdout=fh, stderr=subprocess.STDOUT,
                                env=dict(os.environ, ORCHESTRATOR_PROGRESS_EVERY="2"), start_new_session=True)
    try:
        seen, t0 = "", time.time()
        while time.time() - t0 < 600 and proc.poll() is None:
            seen = log.read_text()
            if "particles" in seen and " step " in seen and "%" in seen:
                break
            time.sleep(0.5)
        alive = proc.poll() is None
    finally:
        # what the test needs is in the log now: stop the run (SIGTERM, its engine with it) rather than
        # wait ~20 s for the whole smoke case
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=900)
    assert alive, f"the run ended before its log showed a start and a progress line:\n{seen}"
    assert "shear_cell_smoke: 228 particles" in seen, seen          # the start line, with the sizing
    assert "liggghts shear_cell_smoke: step " in seen, seen          # a progress line


def test_remembered_integrations_equal_a_fresh_computation():
    """The package's table of remembered integrations (orchestrator/_data/contact_law_memo.json,
    benchmarks/bench_validate.py --memo) holds exactly what the functions compute today: a change
    to their numerics without a new MEMO_VERSION fails here."""
    import importlib
    import inspect
    from orchestrator import contact_law
    table = json.loads(contact_law.PACKAGE_MEMO.read_text())
    mine = {k: v for k, v in table.items() if k.startswith(contact_law._memo_prefix())}
    assert mine, "no entries for this scipy: regenerate with benchmarks/bench_validate.py --memo"
    for key, value in mine.items():
        call = key[len(contact_law._memo_prefix()):]
        qual, args = call.split("(", 1)
        module, name = qual.rsplit(".", 1)
        fn = inspect.unwrap(getattr(importlib.import_module(module), name))
        got = float(fn(*[float(x) for x in args.rstrip(")").split(", ")]))
        assert got == value, f"{call}: table {value!r}, computed {got!r}"


def test_segments_end_at_the_restart_steps_and_a_resumed_deck_is_the_same_text(tmp_path):
    """Exact resume by segments (docs/engines.md, Resume): a LIGGGHTS deck's segments end at the
    multiples of restart_every; the deck resumed from one restart is the full deck's text from that
    segment on (its `clear` aside); YADE scripts stop at the same steps."""
    import re
    from engines import get_engine
    from engines.liggghts.segments import deck_segments
    from engines.yade_runtime.series import stop_steps
    from orchestrator.case import load_case
    from orchestrator.runner import prepare
    segs = deck_segments(100, 30)
    assert [(s["start"], s["stop"], s["last"]) for s in segs] == [(0, 30, False), (30, 60, False), (60, 90, False),
                                                                  (90, 100, True)]
    assert [s["dump_file"] for s in segs] == ["frames.bin"] + [f"frames.{k:012d}.bin" for k in (30, 60, 90)]
    assert [s["start"] for s in deck_segments(100, 30, start=60)] == [60, 90]
    assert stop_steps([{"step": 0}, {"step": 45}, {"step": 100}], 30) == [0, 30, 45, 60, 90, 100]

    def from_segment(text, s):
        rest = text[text.index(f"# === segment {s}-"):].split("\n", 1)[1]
        return rest[len("clear\n"):] if rest.startswith("clear\n") else rest

    for name in ("shear_cell_smoke", "plane_shear_smoke"):
        case = load_case(CASES / f"{name}.yaml")
        eng = get_engine("liggghts")
        params, _ = prepare(case, "liggghts", tmp_path / name)
        full = eng.render(case, params, tmp_path / name).read_text()
        every, steps = params["scene"]["restart_every"], params["scene"]["steps"]
        cuts = [int(s) for s in re.findall(r"^write_restart\s+restart/state\.(\d+)\.restart\.partial", full, re.M)]
        assert cuts == list(range(every, steps, every))
        assert "restart " + str(every) not in full            # no periodic restarts inside a segment
        s = cuts[len(cuts) // 2]
        resumed = eng.render(case, params, tmp_path / name, resume={"step": s, "restart_file": f"restart/state.{s}.restart"})
        assert from_segment(resumed.read_text(), s) == from_segment(full, s)


def test_yade_wall_rows_a_later_segment_wrote_again_are_taken_once(tmp_path):
    """A YADE segment file may hold rows past the checkpoint the next segment starts from (killed
    between its flush and the checkpoint): those rows come from the later file, once."""
    from engines.yade.output import wall_rows
    np.save(tmp_path / "walls.yade.000000000000.npy", np.array([[10.0, 1], [20, 2], [30, 3]]))
    np.save(tmp_path / "walls.yade.000000000020.npy", np.array([[30.0, 3], [40, 4]]))
    assert wall_rows(tmp_path)[:, 0].tolist() == [10, 20, 30, 40]


def test_analyze_of_a_case_directory_names_the_runs_in_it(tmp_path):
    """`analyze runs/<case>` (the case's directory, not one run) said "no analyses asked for"."""
    run = tmp_path / "shear_cell_smoke" / "liggghts-0123456789ab"
    run.mkdir(parents=True)
    (run / "frames.h5").write_bytes(b"")
    one_message(cli("analyze", tmp_path / "shear_cell_smoke"), 2, "not a run directory", str(run))


def test_an_estimate_without_measured_runs_says_it_is_a_lower_bound(tmp_path, monkeypatch, capsys):
    """An engine never measured on any scene is estimated from its bare throughput: the line says so
    (the LAMMPS shear cell printed ~16 s for a case LIGGGHTS runs in 200 s). The shipped table
    measures every engine now, so this runs with an empty one."""
    import orchestrator.clock as clock
    from orchestrator.cli import main
    monkeypatch.setattr(clock, "_package_table", lambda: {})
    monkeypatch.setenv("ORCHESTRATOR_THROUGHPUT", str(tmp_path / "none.json"))
    assert main(["validate", str(case_file(tmp_path, "lmp", "engines: [lammps]\n"))]) in (0, None)
    line = next(l for l in capsys.readouterr().out.splitlines() if l.strip().startswith("lammps:"))
    assert "lower bound" in line, line


def test_clock_refresh_of_a_missing_or_empty_path_is_refused(tmp_path):
    """`clock refresh` of a path that does not exist, or holds no complete run, wrote the table
    unchanged and said it had fitted 0 models."""
    one_message(cli("clock", "refresh", tmp_path / "nope"), 2, "no such path", "orchestrator clock refresh runs")
    one_message(cli("clock", "refresh", tmp_path), 2, "no complete run", "nothing written")
