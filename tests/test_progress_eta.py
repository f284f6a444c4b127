"""The off-terminal progress line's ETA follows the recent step rate, not the mean since the start."""
import re

import engines.base as base


def test_eta_uses_the_recent_rate(monkeypatch, capsys):
    clock = [0.0]
    monkeypatch.setattr(base.time, "perf_counter", lambda: clock[0])
    p = base._Progress("run", total=200_000)
    assert p.lines                                   # pytest's stderr is not a terminal
    # a fast first stage (1 000 steps/s for 100 s), then 100 steps/s
    step = 0
    for t in range(0, 600):
        clock[0] = float(t)
        step += 1000 if t < 100 else 100
        p.update(step)
    last = capsys.readouterr().err.strip().splitlines()[-1]
    m = re.search(r"step (\d+)/200000.*ETA (\d+) s", last)
    remaining = (200_000 - int(m.group(1))) / 100    # at the current rate
    eta = float(m.group(2))
    assert abs(eta - remaining) / remaining < 0.05, last
