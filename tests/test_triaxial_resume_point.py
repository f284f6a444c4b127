"""LIGGGHTS' choice of a triaxial resume point (no engine run): a restart file is used only with
its line of restart/state.txt, the newest such one wins, the series and state lines after it are
cut, and without any the run starts afresh with the stale restart files removed. The choice lives
in the LIGGGHTS package (engines/liggghts/triaxial.py) and is reached through the adapter."""
from __future__ import annotations

from pathlib import Path

from engines.liggghts.triaxial import read_restart_states
from orchestrator.case import load_case
from orchestrator.registry import get_engine

CASE = load_case(Path(__file__).resolve().parents[1] / "cases" / "triaxial_smoke.yaml")


def resume_point(engine, rd, resume):
    return get_engine(engine).complete_resume(CASE, rd, resume)


def _run_dir(tmp_path, steps_with_files, state_lines, series_steps):
    rd = tmp_path / "run"
    (rd / "restart").mkdir(parents=True)
    for s in steps_with_files:
        (rd / "restart" / f"state.{s}.restart").write_bytes(b"x")
    (rd / "restart" / "state.txt").write_text("".join(state_lines))
    (rd / "triax.txt").write_text("# step time\n" + "".join(f"{s} {s * 1e-8}\n" for s in series_steps)
                                  + "4999 0.0")            # a last line cut by the kill
    return rd


def _engine_resume(rd):
    files = sorted(rd.glob("restart/state.*.restart"), key=lambda p: int(p.name.split(".")[1]))
    return {"restart_file": f"restart/{files[-1].name}", "step": int(files[-1].name.split(".")[1]),
            "candidates": [f"restart/{f.name}" for f in reversed(files)]}


def test_newest_restart_with_a_state_line(tmp_path):
    lines = ["100 1 0 1 -1 -1.5 -0.01 0 0 0.5 0.01\n", "# a comment\n",
             "300 2 0 0 -1 -3.25000000000001 -0.5 0.0066 200 2.75 0\n", "400 2 0 0 -1 -3.5"]    # 400: cut by the kill
    rd = _run_dir(tmp_path, [100, 300, 400], lines, [50, 100, 150, 300, 350, 400])
    states = read_restart_states(rd)
    assert sorted(states) == [100, 300]
    assert states[300] == {"step": 300, "stage": 2, "chunks": 0, "dragon": 0, "ramp_start": -1,
                           "ztot": -3.25000000000001, "vlast": -0.5, "H0": 0.0066, "shear_start": 200,
                           "esum": 2.75, "elast": 0.0,
                           # as LIGGGHTS printed them: the resumed deck sets them from this text
                           "text": {"ztot": "-3.25000000000001", "vlast": "-0.5", "H0": "0.0066",
                                    "esum": "2.75", "elast": "0"}}
    r = resume_point("liggghts", rd, _engine_resume(rd))
    assert r["restart_file"] == "restart/state.300.restart" and r["step"] == 300
    assert r["scene_state"]["stage"] == 2 and r["candidates"] == ["restart/state.300.restart",
                                                                 "restart/state.100.restart"]
    rows = [l for l in (rd / "triax.txt").read_text().splitlines() if not l.startswith("#")]
    assert [int(l.split()[0]) for l in rows] == [50, 100, 150, 300]
    # an older candidate asked for by the runner's fallback: cut back further
    r = resume_point("liggghts", rd, dict(r, restart_file="restart/state.100.restart", step=100))
    assert r["step"] == 100 and r["scene_state"]["dragon"] == 1
    rows = [l for l in (rd / "triax.txt").read_text().splitlines() if not l.startswith("#")]
    assert [int(l.split()[0]) for l in rows] == [50, 100]
    assert sorted(read_restart_states(rd)) == [100]


def test_no_usable_restart_starts_afresh(tmp_path):
    rd = _run_dir(tmp_path, [100], [], [50, 100])
    assert resume_point("liggghts", rd, _engine_resume(rd)) is None
    assert not list(rd.glob("restart/state.*.restart"))


def test_yade_resume_is_left_to_the_script(tmp_path):
    r = {"checkpoint": "checkpoint.yade.gz", "candidates": ["checkpoint.yade.gz"]}
    assert resume_point("yade", tmp_path, r) is r
