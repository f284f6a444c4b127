"""How long do `orchestrator validate` and `orchestrator run --dry-run` take? (issue #15 item 3,
#16 item 4: within 2 s for any case). Runs each command as a user would (a new process) on the
shipped seed and smoke cases and prints wall and CPU seconds (CPU time is the honest figure on a
loaded machine; the load average is printed with it), with the user's table of remembered
integrations (orchestrator.contact_law.remembered) empty ("cold": only the package's table) and
filled ("warm").

    .venv/bin/python benchmarks/bench_validate.py [CASE ...] [--repeat N]
    .venv/bin/python benchmarks/bench_validate.py --memo     # rewrite the package's table

``--memo`` derives every shipped case and writes the integrations it needed into
orchestrator/_data/contact_law_memo.json (the values are the functions' own results; the table
is keyed by scipy's version, so another scipy computes them afresh).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DEFAULT = ["shear_cell_seed", "triaxial_seed", "plane_shear_seed", "shear_cell_smoke"]


def timed(cmd: list[str], env: dict) -> tuple[float, float, int]:
    """(wall s, CPU s of the child, exit status)."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=REPO)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime), out.returncode


def write_memo() -> None:
    from orchestrator import contact_law
    from orchestrator.case import load_case
    from orchestrator.derive import derive
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["ORCHESTRATOR_MEMO"] = str(Path(tmp) / "memo.json")
        contact_law._memo.cache_clear()
        contact_law._memo().clear()                          # compute everything afresh
        for case in sorted((REPO / "cases").rglob("*.yaml")):
            try:
                derive(load_case(case))
            except Exception as exc:                         # noqa: BLE001 - a case meant to fail
                print(f"  {case.relative_to(REPO)}: {type(exc).__name__}")
        table = json.loads(Path(os.environ["ORCHESTRATOR_MEMO"]).read_text())
    from orchestrator.atomic import write_text
    write_text(contact_law.PACKAGE_MEMO, json.dumps(table, indent=0, sort_keys=True) + "\n")
    print(f"wrote {len(table)} values to {contact_law.PACKAGE_MEMO}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("cases", nargs="*", default=DEFAULT)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--memo", action="store_true", help="rewrite the package's table of integrations")
    a = ap.parse_args()
    if a.memo:
        write_memo()
        return
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; best of {a.repeat}")
    print(f"{'case':<22} {'command':<14} {'cold wall':>9} {'cold CPU':>9} {'warm wall':>9} {'warm CPU':>9}")
    for name in a.cases:
        case = REPO / "cases" / f"{name}.yaml"
        for cmd_name, extra in (("validate", ["validate", str(case)]),
                                ("run --dry-run", ["run", str(case), "--dry-run", "--runs", "/nonexistent"])):
            cmd = [sys.executable, "-m", "orchestrator", *extra]
            res = []
            with tempfile.TemporaryDirectory() as tmp:
                env = dict(os.environ, ORCHESTRATOR_MEMO=str(Path(tmp) / "memo.json"))
                cold = []
                for _ in range(a.repeat):
                    Path(env["ORCHESTRATOR_MEMO"]).unlink(missing_ok=True)
                    cold.append(timed(cmd, env))
                warm = [timed(cmd, env) for _ in range(a.repeat)]
            for runs in (cold, warm):
                bad = [r for r in runs if r[2] != 0]
                if bad:
                    raise SystemExit(f"{' '.join(cmd)} exited with {bad[0][2]}")
                res += [min(r[0] for r in runs), min(r[1] for r in runs)]
            print(f"{name:<22} {cmd_name:<14} " + " ".join(f"{x:>8.2f}s" for x in res))


if __name__ == "__main__":
    main()
