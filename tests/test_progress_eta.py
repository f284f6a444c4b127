"""The off-terminal progress line: its ETA follows the recent step rate, not the mean since the
start, and a run whose scene decides its length while it runs counts toward the steps expected."""
import re
from pathlib import Path

import engines.base as base
from engines import get_engine

#: "step 150,000/200,000 (75 %), 10.0 min, ETA 8.3 min" (or ".../~100,000 expected (at most 200,000) ...")
LINE = re.compile(r"step ([\d,]+)/~?([\d,]+)(?: expected \(at most ([\d,]+)\))? \((\d+) %\), .*?"
                  r"(?:, ETA ([\d.]+) (ms|s|min|h|days))?$")
SECONDS = {"ms": 1e-3, "s": 1.0, "min": 60.0, "h": 3600.0, "days": 86400.0}


def _lines(monkeypatch, capsys, rates, **progress):
    """A :class:`engines.base._Progress` of ``progress`` on a fake clock, fed one report a second
    at the step ``rates`` [steps/s] (one per second); the progress lines it printed, parsed:
    (step, goal, budget or None, percent, ETA [s] or None)."""
    clock = [0.0]
    monkeypatch.setattr(base.time, "perf_counter", lambda: clock[0])
    p = base._Progress("run", **progress)
    assert p.lines                                   # pytest's stderr is not a terminal
    step = 0
    for t, rate in enumerate(rates):
        clock[0] = float(t)
        step += rate
        p.update(step)
    out = []
    for line in capsys.readouterr().err.strip().splitlines()[1:]:
        m = LINE.search(line)
        assert m, line
        num = lambda g: int(g.replace(",", "")) if g else None
        eta = float(m.group(5)) * SECONDS[m.group(6)] if m.group(5) else None
        out.append((num(m.group(1)), num(m.group(2)), num(m.group(3)), int(m.group(4)), eta))
    return out


def test_eta_uses_the_recent_rate(monkeypatch, capsys):
    # a fast first stage (1 000 steps/s for 100 s), then 100 steps/s
    step, goal, budget, _, eta = _lines(monkeypatch, capsys, [1000] * 100 + [100] * 500, total=200_000)[-1]
    assert goal == 200_000 and budget is None
    remaining = (200_000 - step) / 100               # at the current rate
    assert abs(eta - remaining) / remaining < 0.05, (step, eta)


def test_a_run_counts_toward_the_steps_expected_then_the_budget(monkeypatch, capsys):
    """A triaxial's budget allows every stage-1 chunk; its measured runs took about half: the lines
    say the expected steps and the budget, count the percentage and the ETA toward the expected
    steps, and toward the budget once the run has passed them."""
    lines = _lines(monkeypatch, capsys, [500] * 300, total=200_000, expected=100_000)   # 150 000 steps
    before = [l for l in lines if l[0] <= 100_000]
    after = [l for l in lines if l[0] > 100_000]
    assert before and after
    step, goal, budget, percent, eta = before[-1]
    assert (goal, budget) == (100_000, 200_000) and percent == round(100 * step / 100_000)
    assert abs(eta - (100_000 - step) / 500) <= 0.05 * (100_000 - step) / 500 + 1
    step, goal, budget, percent, eta = after[-1]
    assert (goal, budget) == (200_000, None) and percent == round(100 * step / 200_000)
    assert abs(eta - (200_000 - step) / 500) / ((200_000 - step) / 500) < 0.05


def test_a_run_whose_deck_says_its_end_counts_toward_it(monkeypatch, capsys):
    """A triaxial's deck prints the step its run ends at once the loading starts (engines.base.RUN_ENDS):
    from then on the lines count toward that step, exactly (no "expected", no budget), and the ETA with
    them, though the clock's guess at stage 1 was shorter."""
    clock = [0.0]
    monkeypatch.setattr(base.time, "perf_counter", lambda: clock[0])
    p = base._Progress("run", total=1_008_000, expected=528_000)
    assert base.Engine.progress_end("RUN ENDS at step 704001") == 704_001
    assert base.Engine.progress_end("SHEAR start at iter 384201, H0 = 0.02 m") is None
    step = 496_000
    for t in range(200):
        clock[0] = float(t)
        step += 30
        p.update(step)
        if t == 100:
            p.end_at(base.Engine.progress_end("RUN ENDS at step 704001"))
    err = capsys.readouterr().err.strip().splitlines()
    last = LINE.search(err[-1])
    assert last.group(2) == "704,001" and last.group(3) is None and "expected" not in err[-1], err[-1]
    assert int(last.group(4)) == round(100 * step / 704_001)
    eta = float(last.group(5)) * SECONDS[last.group(6)]
    assert abs(eta - (704_001 - step) / 30) / ((704_001 - step) / 30) < 0.05, err[-1]


def test_an_expected_count_at_the_budget_is_the_budget(capsys):
    """A scene of fixed length: the expected steps are the budget, and the line says the budget only."""
    base._Progress("run", total=200_000, expected=200_000)
    first = capsys.readouterr().err
    assert "200,000 steps;" in first and "expected" not in first


def test_a_resumed_yade_triaxial_counts_from_its_checkpoint():
    """YADE's checkpoint does not name its step, so the resume point's step is unknown until the
    engine says it: the triaxial deck's ``RESUMED at iter N`` line is read as step N (the progress
    lines and the attempt record start there, not at 0 or at the first PROGRESS line after it)."""
    yade = get_engine("yade")
    deck = (Path(__file__).resolve().parents[1] / "templates" / "yade" / "triaxial.py.j2").read_text()
    resumed = re.search(r'print\("(RESUMED at iter %d[^"]*)"', deck).group(1)     # the line the deck prints
    lines = [resumed % (176000, 1), "ISO chunk 10: sigma1/p = 1.0007 sigma3/p = 1.0000",
             "PROGRESS 176400", "176401 0.0038 1 1.9e-05"]
    assert [yade.progress_step(l) for l in lines] == [176000, None, 176400, None]


def test_a_resumed_run_loading_its_checkpoint_does_not_slow_its_eta(monkeypatch, capsys):
    """A resumed run shows its resume step while the engine loads its checkpoint (60 s here, no
    report), then reports 100 steps/s: the ETA follows those 100 steps/s, not a rate diluted by the
    loading."""
    clock = [0.0]
    monkeypatch.setattr(base.time, "perf_counter", lambda: clock[0])
    p = base._Progress("run", total=400_000)
    for t in range(60):                                  # loading: the lines go on at the resume step
        clock[0] = float(t)
        p.update(176_000, reported=False)
    step = 176_000
    for t in range(60, 300):
        clock[0] = float(t)
        step += 100
        p.update(step)
    lines = [LINE.search(l) for l in capsys.readouterr().err.strip().splitlines()[1:]]
    assert lines[0] and int(lines[0].group(1).replace(",", "")) == 176_000       # not "step 0"
    moving = [m for m in lines if int(m.group(1).replace(",", "")) > 176_000 and m.group(5)]
    assert len(moving) >= 5
    for m in moving:                                     # from the first line after the reports began
        s = int(m.group(1).replace(",", ""))
        eta = float(m.group(5)) * SECONDS[m.group(6)]
        assert abs(eta - (400_000 - s) / 100) / ((400_000 - s) / 100) < 0.05, (s, eta)


def test_the_lines_give_the_clocks_time_left_where_the_pace_says_otherwise(monkeypatch, capsys):
    """YADE's medium shear cell on two threads said "ETA 16.6 min" 90.3 s in (the loose packing) and
    "ETA 2.1 h" at 33.7 min, once packed: the lines give the clock's time left (its
    estimate for the run shared evenly over the steps) beside the ETA where the two differ by more
    than 1.5x, and the ETA alone where they agree."""
    def last_line(rate, estimate_s):
        clock = [0.0]
        monkeypatch.setattr(base.time, "perf_counter", lambda: clock[0])
        p = base._Progress("run", total=100_000, estimate_s=estimate_s)
        step = 0
        for t in range(200):
            clock[0] = float(t)
            step += rate
            p.update(step)
        return capsys.readouterr().err.strip().splitlines()[-1]
    line = last_line(100, 2000.0)        # 100 steps/s: 1 000 s for the run, the clock says 2 000 s
    m = re.search(r"step ([\d,]+)/.*ETA ([\d.]+) (s|min) \(the clock's estimate: ([\d.]+) (s|min) left\)$", line)
    assert m, line
    step = int(m.group(1).replace(",", ""))
    eta, left = float(m.group(2)) * SECONDS[m.group(3)], float(m.group(4)) * SECONDS[m.group(5)]
    assert abs(eta - (100_000 - step) / 100) < 0.05 * (100_000 - step) / 100
    assert abs(left - 2000.0 * (100_000 - step) / 100_000) < 0.01 * left
    line = last_line(100, 1200.0)            # within 1.5x: the ETA alone
    assert LINE.search(line) and "clock" not in line
    line = last_line(100, None)              # no estimate: the ETA alone
    assert LINE.search(line) and "clock" not in line


def test_the_terminal_bar_gives_the_clocks_time_left_too(monkeypatch):
    """On a terminal the rich bar's own time remaining follows the pace; a column beside it gives the
    clock's time left where the two differ by more than 1.5x, as the off-terminal lines do."""
    clock = [0.0]
    monkeypatch.setattr(base.time, "perf_counter", lambda: clock[0])
    monkeypatch.setattr(base.sys.stderr, "isatty", lambda: True)
    p = base._Progress("run", total=100_000, estimate_s=2000.0)
    assert p.p is not None
    try:
        step = 0
        for t in range(200):
            clock[0] = float(t)
            step += 100
            p.update(step)
        task = p.p.tasks[0]
        left = task.time_remaining
        assert left is not None and abs(left - (100_000 - step) / 100) < 0.1 * left      # rich: the pace's
        m = re.fullmatch(r" \(the clock's estimate: ([\d.]+) (s|min) left\)", task.fields["clock"])
        assert m and abs(float(m.group(1)) * SECONDS[m.group(2)] - 2000.0 * (100_000 - step) / 100_000) < 0.01 * 2000
    finally:
        p.close()
