"""Monitor-figure histories of bisection probes: is a tripped figure physics or instability?

``python -m orchestrator.stability.history CASE ENGINE F1 F2 ... [--overlap-limit X] [--runs DIR]``

Renders the probe of :func:`.bisection.probe` at each fraction f of dt_critical (dry run), patches
the rendered deck so that the in-deck monitors *print* their figures (step, largest overlap /
r_min, translational kinetic energy) at every check and the overlap trip sits at
``overlap_limit`` r_min, runs the engine directly in the run directory, and summarises per f:
the largest overlap, the largest KE and the KE of the settled packing (the smallest KE over the
second half of the checks before the shear starts), and what tripped. An overlap that does not
shrink as f → 0 is physics; a settled-packing KE that grows by orders of magnitude with f is
numerical heating (docs/stability.md, very_soft). The runs live under ``DIR/<case>/`` (not the
project's runs: the decks are patched).
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import time
from pathlib import Path


def _patch_liggghts(text: str, limit: float) -> str:
    text = re.sub(r"if '\$\{ORCH_ov\} > [0-9.e+-]+'", f"if '${{ORCH_ov}} > {limit!r}'", text)
    text = re.sub(r"print ORCH_UNSTABLE:overlap:\$\{ORCH_ov\}:[0-9.e+-]+:",
                  f"print ORCH_UNSTABLE:overlap:${{ORCH_ov}}:{limit!r}:", text)
    # the figures are printed at each check (the wall-force bookkeeping command runs every check)
    return text.replace('"variable ORCH_wprev equal ${ORCH_w}"',
                        '"print \'ORCH_OV ${ORCH_s} ${ORCH_ov} ${ORCH_ke}\'" "variable ORCH_wprev equal ${ORCH_w}"')


def _patch_yade(text: str, limit: float) -> str:
    """The monitor settings (yade_runtime/monitors.py reads them) get the overlap limit and
    ``print_figures`` (an ORCH_OV line at every check)."""
    return re.sub(r"^(ORCH_MON = json\.loads\(.*\)\n)",
                  lambda m: m.group(1) + f"ORCH_MON['overlap_limit'] = {limit!r}\nORCH_MON['print_figures'] = True\n",
                  text, count=1, flags=re.M)


def history(case_path, engine: str, fractions: list[float], runs_root="/tmp/orch_history",
            overlap_limit: float | None = None, timeout: float = 3600) -> list[dict]:
    """One probe per fraction; returns one summary dict per fraction (see the module docstring)."""
    import numpy as np
    from ..case import load_case
    from ..derive import derive
    from ..runner import run_case
    from .bisection import MEMBER_PROBE, PROBE, _merge
    base = load_case(case_path)
    ov0 = _merge(PROBE.get(base.scene.kind, {}), MEMBER_PROBE.get(base.name, {}))
    p = derive(load_case(case_path, overrides=ov0 or None))
    limit = overlap_limit if overlap_limit is not None else p["monitors"]["overlap_limit"]
    out = []
    for f in fractions:
        dt = f * p["dt_critical"]
        case = load_case(case_path, overrides=_merge(ov0, {"timestep": {"dt": f"{dt!r} s", "allow_unsafe": True}}))
        rd = Path(run_case(case, engine, runs_root=runs_root, dry_run=True, progress=False, analyze=False).run_dir)
        if engine == "liggghts":
            deck = rd / "deck.in"
            deck.write_text(_patch_liggghts(deck.read_text(), limit))
            cmd = ["liggghts", "-in", deck.name, "-log", "none", "-echo", "none"]
        else:
            deck = rd / "script.py"
            deck.write_text(_patch_yade(deck.read_text(), limit))
            cmd = ["yade", "-n", "-j", "1", "-x", deck.name]
        t0 = time.perf_counter()
        pr = subprocess.run(cmd, cwd=rd, capture_output=True, text=True, timeout=timeout,
                            env=dict(os.environ, OMP_NUM_THREADS="1"))
        log = pr.stdout + pr.stderr
        (rd / "history.log").write_text(log)
        hist = [(int(s), float(o), float(k)) for s, o, k in re.findall(r"^ORCH_OV (\d+) (\S+) (\S+)", log, re.M)]
        shear_start = case_shear_start(rd)
        pre = [k for s, o, k in hist if shear_start is None or s < shear_start]
        ovs = np.array([o for _, o, _ in hist] or [np.nan])
        trip = re.findall(r"^ORCH_UNSTABLE:(\S+)", log, re.M)
        out.append({"fraction": f, "checks": len(hist), "overlap_max": float(np.nanmax(ovs)),
                    "ke_max": max((k for _, _, k in hist), default=None),
                    "ke_settled": min(pre[len(pre) // 2:]) if len(pre) >= 4 else None,
                    "tripped": trip[0] if trip else None, "returncode": pr.returncode,
                    "wall_s": round(time.perf_counter() - t0, 2), "run_dir": str(rd)})
        (rd / "history.json").write_text(json.dumps({"summary": out[-1], "history": hist}))
    return out


def case_shear_start(run_dir: Path) -> int | None:
    """The step the shear stage begins at (plane shear), from the run's params.json."""
    try:
        params = json.loads((Path(run_dir) / "params.json").read_text())
        return int(params["scene"]["stages"]["shear"][0])
    except (OSError, KeyError, ValueError, TypeError):
        return None


def main(argv=None) -> int:
    import argparse
    ap = argparse.ArgumentParser(prog="python -m orchestrator.stability.history", description=__doc__.splitlines()[0])
    ap.add_argument("case")
    ap.add_argument("engine", choices=["liggghts", "yade"])
    ap.add_argument("fractions", nargs="+", type=float)
    ap.add_argument("--overlap-limit", type=float, default=None, help="overlap trip [r_min] (default: the case's)")
    ap.add_argument("--runs", default="/tmp/orch_history")
    a = ap.parse_args(argv)
    print(f"{'f':>7} {'overlap max':>11} {'KE max [J]':>11} {'KE settled [J]':>14}  tripped")
    for r in history(a.case, a.engine, a.fractions, a.runs, a.overlap_limit):
        kes = f"{r['ke_settled']:.2g}" if r["ke_settled"] is not None else "-"
        kem = f"{r['ke_max']:.2g}" if r["ke_max"] is not None else "-"
        print(f"{r['fraction']:>7.3g} {r['overlap_max']:>11.3g} {kem:>11} {kes:>14}  {r['tripped'] or ''}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
