"""Benchmark (not a test) for issue #14 item 3: YADE at full speed.

For each case (default: the small shear cell and the small triaxial), the YADE deck is rendered as
the orchestrator renders it and run for ``--warm`` steps, then timed over ``--steps`` steps, twice:

- ``deck``: the deck as rendered (every PyRunner and C++ engine it has);
- ``bare``: the same script, bodies and contact law, with every PyRunner removed from O.engines
  after the warm-up (no Python callbacks; the membrane's nodal forces stay as last set).

Both from the same state, one thread each (``yade -n -j 1``); steps/s from the process CPU time
spent in O.run (the machine is shared; wall time is printed too). The bare run's dynamics differ
(no servo, no pressure update), so the deck's own per-engine times (``O.timingEnabled``) give a
second figure from one run: the C++ share of its loop (1 - the PyRunners' share), what deck/bare
would be if the Python cost nothing else. Target: both >= 0.67.
``--liggghts`` also runs the LIGGGHTS deck of the same case for the same steps (its first timed
segment cut to warm + steps) and prints YADE/LIGGGHTS steps/s.

Run: ``.venv/bin/python benchmarks/bench_yade_speed.py [--steps 3000] [--warm 1000] [--liggghts]
[--repo DIR] [--set JSON] [CASE ...]`` (``--repo``: render with another checkout, e.g. an export of an older
commit, for before/after figures).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CASES = ["shear_cell_small.yaml", "triaxial_small.yaml"]

#: the first line of a YADE deck's main run section (shear cell, plane shear, triaxial; old and new decks)
_RUN_START = re.compile(r"^(_loop = 0\.0|_t0 = time\.time\(\)|O\.stopAtIter = control)", re.M)

_BENCH = """
# --- benchmark (benchmarks/bench_yade_speed.py) ---------------------------------------------
import time as _bt
O.run({warm}, True)
if {bare}:
    O.engines = [e for e in O.engines if not isinstance(e, PyRunner)]
O.timingEnabled = True                 # per-engine time (yade.timing): the Python share within one run
for _e in O.engines:
    _e.execTime, _e.execCount = 0, 0
_w0, _c0 = _bt.time(), _bt.process_time()
O.run({steps}, True)
_w, _c = _bt.time() - _w0, _bt.process_time() - _c0
print("BENCH %d %.6f %.6f %d" % ({steps}, _w, _c, sum(1 for i in O.interactions if i.isReal)), flush=True)
print("ENGINES " + json.dumps([[e.label or type(e).__name__, type(e).__name__, e.execTime * 1e-9] for e in O.engines]),
      flush=True)
os._exit(0)
"""


def render(case_file: str, engine: str, run_dir: Path, repo: Path, overrides: dict | None = None) -> Path:
    from orchestrator.case import load_case
    from orchestrator.runner import prepare
    from engines import get_engine
    case = load_case(repo / "cases" / case_file, overrides=overrides or None)
    params, _ = prepare(case, engine, run_dir)
    return get_engine(engine).render(case, params, run_dir, resume=None)


def run_yade(script: Path, warm: int, steps: int, bare: bool) -> dict:
    text = script.read_text()
    m = _RUN_START.search(text)
    if m is None:
        raise SystemExit(f"{script}: no main run section found (expected one of {_RUN_START.pattern})")
    bench = script.with_name(f"bench_{'bare' if bare else 'deck'}.py")
    bench.write_text(text[:m.start()] + _BENCH.format(warm=warm, steps=steps, bare=bare))
    pr = subprocess.run(["yade", "-n", "-j", "1", "-x", bench.name], cwd=script.parent, capture_output=True,
                        text=True, env=dict(os.environ, OMP_NUM_THREADS="1"))
    line = [ln for ln in pr.stdout.splitlines() if ln.startswith("BENCH ")]
    if not line:
        raise SystemExit(f"{bench}: no BENCH line\n{pr.stdout[-3000:]}\n{pr.stderr[-3000:]}")
    n, wall, cpu, contacts = line[0].split()[1:]
    eng = json.loads(next(ln for ln in pr.stdout.splitlines() if ln.startswith("ENGINES "))[8:])
    total = sum(t for _, _, t in eng)
    py = {label: t / total for label, cls, t in eng if cls == "PyRunner" and t > 0}
    return {"steps": int(n), "wall": float(wall), "cpu": float(cpu), "contacts": int(contacts),
            "rate": int(n) / float(cpu), "rate_wall": int(n) / float(wall), "python": py,
            "cxx_share": 1.0 - sum(py.values())}


def run_liggghts(deck: Path, warm: int, steps: int) -> dict:
    """The deck up to its first timed segment, cut to ``warm`` steps, then ``steps`` more; the
    rate from LIGGGHTS' own 'Loop time' of the second segment."""
    lines = deck.read_text().splitlines()
    k = next(i for i, ln in enumerate(lines) if re.match(r"^run\s+[1-9]", ln))
    # the segment bookkeeping (labels and jumps of engines/liggghts/segments.py) and the run's own
    # stop checks (every ... "if ... quit") are not part of the timed physics
    head = [ln for ln in lines[:k] if not re.match(r"^\s*label\b", ln) and "jump SELF" not in ln]
    bench = deck.with_name("bench.in")
    bench.write_text("\n".join(head + [f"run {warm}", f"run {steps}"]) + "\n")
    pr = subprocess.run(["liggghts", "-in", bench.name, "-echo", "none"], cwd=deck.parent, capture_output=True,
                        text=True, env=dict(os.environ, OMP_NUM_THREADS="1"))
    loops = re.findall(r"Loop time of ([0-9.eE+-]+) on \d+ procs for (\d+) steps", pr.stdout)
    if len(loops) < 2:
        raise SystemExit(f"{bench}: no second 'Loop time' line\n{pr.stdout[-3000:]}")
    t, n = float(loops[-1][0]), int(loops[-1][1])
    return {"steps": n, "wall": t, "rate_wall": n / t}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("cases", nargs="*", default=CASES, help="case files under cases/")
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--warm", type=int, default=1000)
    ap.add_argument("--liggghts", action="store_true")
    ap.add_argument("--repo", type=Path, default=REPO, help="checkout to render with (default: this one)")
    ap.add_argument("--set", default="{}", help='case overrides as JSON, e.g. \'{"scene": {"membrane": '
                                                '{"contact_damping_lagged": true}}}\'')
    a = ap.parse_args(argv)
    sys.path.insert(0, str(a.repo))
    rows = []
    for case_file in a.cases:
        with tempfile.TemporaryDirectory(prefix="bench_yade_") as tmp:
            script = render(case_file, "yade", Path(tmp) / "yade", a.repo, json.loads(a.set))
            deck = run_yade(script, a.warm, a.steps, bare=False)
            bare = run_yade(script, a.warm, a.steps, bare=True)
            lig = None
            if a.liggghts:
                lig = run_liggghts(render(case_file, "liggghts", Path(tmp) / "liggghts", a.repo, json.loads(a.set)),
                                   a.warm, a.steps)
        rows.append((case_file, deck, bare, lig))
        print(f"{case_file}: deck {deck['rate']:.1f} steps/s CPU ({deck['rate_wall']:.1f} wall), bare "
              f"{bare['rate']:.1f} ({bare['rate_wall']:.1f} wall), contacts {deck['contacts']}/{bare['contacts']}",
              flush=True)
        print("  Python share of the deck's loop: " + ", ".join(f"{k} {v:.3f}" for k, v in deck["python"].items()),
              flush=True)
    print(f"\n{'case':24s} {'deck steps/s':>13s} {'bare steps/s':>13s} {'deck/bare':>10s} {'C++ share':>10s} "
          f"{'target':>7s} {'LIGGGHTS steps/s':>17s} {'YADE/LIGGGHTS':>14s}")
    for case_file, deck, bare, lig in rows:
        r = deck["rate"] / bare["rate"]
        lr = f"{lig['rate_wall']:17.1f} {deck['rate_wall'] / lig['rate_wall']:14.3f}" if lig else f"{'-':>17s} {'-':>14s}"
        print(f"{Path(case_file).stem:24s} {deck['rate']:13.1f} {bare['rate']:13.1f} {r:10.3f} {deck['cxx_share']:10.3f} "
              f"{'ok' if min(r, deck['cxx_share']) >= 0.67 else 'BELOW':>7s} {lr}")
    print(f"(steps/s over {a.steps} steps after {a.warm} warm-up steps, one thread; deck/bare from CPU time of two "
          "runs; C++ share = the deck's loop time outside PyRunners (yade timing, one run: robust to the machine's "
          "load); YADE/LIGGGHTS from wall time of the timed segment)")


if __name__ == "__main__":
    main()
