"""Command group: ``orchestrator compare A B``, ``orchestrator crossval CASE``, ``orchestrator report RUN``.

Outside :mod:`orchestrator.compare`, whose ``__init__`` loads the analysis stack: building the
command table (``orchestrator --help``) then imports none of it; each command imports what it runs."""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from .console import console
from .hints import unknown_name_hint
from .registry import engine_names


def _parse_options(items) -> dict:
    """``--option measure.key=value`` (value parsed as JSON when possible) and ``--states all``.
    Another form, or a measure not in :data:`MEASURES`, is a ValueError naming the option."""
    from .measure_names import MEASURES
    out: dict = {}
    for it in items or []:
        key, eq, val = it.partition("=")
        m, dot, k = key.partition(".")
        if not (eq and dot and m and k):
            raise ValueError(f"--option {it!r}: expected MEASURE.KEY=VALUE, e.g. --option d2min.cutoff_d50=1.5")
        if m not in MEASURES:
            raise ValueError(f"--option {it!r}: {unknown_name_hint(MEASURES, m, 'measure')}")
        try:
            v = json.loads(val)
        except ValueError:
            v = val
        out.setdefault(m, {})[k] = v
    return out


def _print_table(cmp, con):
    from rich.table import Table
    t = Table(title=f"{cmp.alignment.a.label} vs {cmp.alignment.b.label} (states by {cmp.alignment.control})")
    for c in ("measure", "quantity", "state", "metric", "distance", "note"):
        t.add_column(c, justify="right" if c == "distance" else "left")
    for _, r in cmp.table.iterrows():
        d = r["distance"]
        ds = "" if d != d else f"{d:.3g}"
        note = str(r["note"] or "")
        if r.get("substitutions"):
            note = (note + " [subst: " + str(r["substitutions"]) + "]").strip()
        t.add_row(str(r["measure"]), str(r["quantity"]), str(r["state"]), str(r["metric"]), ds, note[:90])
    con.print(t)
    if cmp.grain is not None:
        g = cmp.grain.scalars
        con.print(f"grain by grain ({g['identity']}, {g['grains_identified']} grains): median trajectory error up to "
                  f"{g['max_median_error_d50']:.3g} d50, displacement agrees for {100 * g['final_fraction_agree']:.1f} % "
                  "at the last state")


def cmd_compare(args) -> int:
    from .compare.core import compare
    con = console()
    opts = _parse_options(args.option)
    if args.states:
        opts["states"] = args.states
    diffs, kinds = case_differences(args.a, args.b)
    if diffs and len(kinds) > 1 and not args.different_cases:
        print(f"error: {args.a} and {args.b} are runs of different scenes ({' vs '.join(kinds)}); nothing in them "
              "matches state by state. Differences: " + "; ".join(diffs[:8])
              + ". Compare runs of one case (on two engines), or give --different-cases to compare anyway",
              file=sys.stderr)
        return 2
    if diffs:
        print(f"warning: {args.a} and {args.b} are runs of different cases: " + "; ".join(diffs[:8])
              + (f" (and {len(diffs) - 8} more)" if len(diffs) > 8 else ""), file=sys.stderr)
    out = Path(args.out) if args.out else Path("compare") / f"{Path(args.a).name}__vs__{Path(args.b).name}"
    cmp = compare(args.a, args.b, out_dir=out, measures=args.measure, options=opts, control=args.control,
                  tolerance=args.tolerance, frame=args.frame, identity=not args.no_identity,
                  max_distance=args.max_distance, grain_atol_d50=args.atol, grain_rtol=args.rtol)
    _print_table(cmp, con)
    con.print(f"wrote {cmp.files['table']} and {cmp.files['html']}")
    return 0


def cmd_ladder(args, con) -> int:
    """``orchestrator crossval CASE --ladder``: the physics ladder on every engine and seed."""
    from rich.table import Table
    from .compare.ladder import run_ladder

    def progress(row):
        con.print(f"  {row['rung']} {row['engine']} seed {row['seed']}: {row['status']}"
                  + (f" ({row['error']})" if row.get("error") else ""))

    res = run_ladder(args.case, engines=args.engine, seeds=args.seeds, runs_root=args.runs,
                     scheduler=args.scheduler, workers=args.workers, out_dir=args.out, progress=progress,
                     rungs=args.rung)
    t = Table(title=f"cross-validation ladder: {res.case} (A vs B per row; scatter = 2 sem of the seeds, relative)")
    for col in ("rung", "engines", "observable", "A", "B", "|A−B|/mean", "scatter", "floor", "ok"):
        t.add_column(col, no_wrap=True)
    for _, r in res.comparison.iterrows():
        if r["observable"] == "density_profile":
            a = b = "profile"
        else:
            a, b = f"{r['mean A']:.4g}", f"{r['mean B']:.4g}"
        ok = "" if r["ok"] is None or r["ok"] != r["ok"] else ("[green]ok[/green]" if r["ok"] else "[red]no[/red]")
        floor = "" if r["floor"] is None or r["floor"] != r["floor"] else f"{r['floor']:.3g}"
        t.add_row(r["rung"], r["engines"], r["observable"], a, b, f"{100 * r['relative difference']:.1f} %",
                  f"{100 * r['scatter (2 sem, relative)']:.1f} %", floor, ok)
    if not con.is_terminal:
        con.width = max(con.width, 150)       # a log keeps every column whole
    con.print(t)
    one_seed = bool(len(res.comparison)) and res.comparison["significant"].isna().all()
    if not len(res.comparison):
        con.print("one engine ran: no pair to compare (its runs are in ladder_runs.csv; run the other engines "
                  "with the same --runs to compare them)")
    else:
        con.print(f"engines part at: {res.parts_at or 'no rung (every difference within its floor or the scatter)'}"
                  + (" (one seed per engine: no scatter, the floors alone decide)" if one_seed else ""))
    if len(res.explanation):
        con.print(res.explanation.to_string(index=False))
    con.print("wrote " + ", ".join(res.files.values()))
    return 0


#: case fields that do not change what a run simulates (how it is launched, what is done after)
_NOT_PHYSICS = ("name", "description", "engines", "engine_options", "analysis", "ct")


def case_differences(a, b) -> tuple[list[str], list[str]]:
    """The fields (dotted paths) in which the simulated cases of two sources differ, and their scene
    kinds; empty when either is not a simulation (a CT frame set) or carries no case."""
    from .frames import Frames
    cases = []
    for src in (a, b):
        try:
            meta = Frames(src).meta
        except (FileNotFoundError, ValueError, OSError):
            return [], []
        case = meta.get("case")
        if meta.get("source") != "simulation" or not isinstance(case, dict):
            return [], []
        cases.append(case)
    out: list[str] = []

    def walk(x, y, path):
        if isinstance(x, dict) and isinstance(y, dict):
            for k in sorted(set(x) | set(y)):
                if not path and k in _NOT_PHYSICS:
                    continue
                walk(x.get(k), y.get(k), f"{path}.{k}" if path else k)
        elif x != y:
            out.append(f"{path}: {x!r} vs {y!r}" if len(repr(x)) + len(repr(y)) < 80 else f"{path} differs")
    walk(cases[0], cases[1], "")
    kinds = sorted({str((c.get("scene") or {}).get("kind")) for c in cases})
    return out, kinds


def cmd_crossval(args) -> int:
    from .compare.crossval import crossval
    con = console()
    if args.dry_run:
        return _crossval_dry_run(args)
    if args.ladder:
        return cmd_ladder(args, con)
    conc = {"auto": "auto", "yes": True, "no": False}[args.concurrent]
    opts = _parse_options(args.option)
    if args.states:
        opts["states"] = args.states
    cv = crossval(args.case, runs_root=args.runs, out_dir=args.out, concurrent=conc, force=args.force,
                  measures=args.measure, options=opts, engines=args.engine)
    for r in cv.engines:
        con.print(f"[green]{r['engine']}[/green] {'reused' if r['reused'] else 'ran'} {r['run_dir']}: total "
                  f"{(r['wall_time_total_s'] or 0):.1f} s, engine loop {(r['engine_loop_s'] or 0):.1f} s; "
                  f"substitutions: {r['substitutions']}")
    con.print(f"runs: {cv.mode}")
    for cmp in cv.comparisons.values():
        _print_table(cmp, con)
        con.print(f"wrote {cmp.files['table']} and {cmp.files['html']}")
    return 0


def _crossval_dry_run(args) -> int:
    """``crossval --dry-run`` (and ``--ladder --dry-run``): every run, reused or to run, its estimate,
    and the total, as ``sweep --dry-run`` prints them; nothing is packed or run."""
    from .stability.cli import _print_plan
    if args.ladder:
        from .compare.ladder import ladder_plan
        plan = ladder_plan(args.case, engines=args.engine, seeds=args.seeds, runs_root=args.runs, rungs=args.rung)
        return _print_plan(plan, f"crossval --ladder of {args.case}: the runs before any of them",
                           args.workers or (os.cpu_count() if args.scheduler is None else None))
    from .compare.crossval import crossval_plan
    conc = {"auto": "auto", "yes": True, "no": False}[args.concurrent]
    plan, at_once, mode = crossval_plan(args.case, engines=args.engine, runs_root=args.runs, concurrent=conc)
    code = _print_plan(plan, f"crossval of {args.case}: the runs before any of them", at_once)
    console().print(f"runs: {mode}")
    return code


def cmd_report(args) -> int:
    from .compare.report import write_run_report
    p = write_run_report(args.run, out=args.out, analyses=args.analysis, rerun=args.rerun)
    print(f"wrote {p}")
    return 0


def add_parsers(sub) -> None:
    from .measure_names import MEASURES
    c = sub.add_parser("compare", help="compare two runs or CT frame sets (any mix): table (CSV) and HTML report")
    c.add_argument("a", help="run directory or frames.h5 (A, the reference)")
    c.add_argument("b", help="run directory or frames.h5 (B)")
    c.add_argument("--out", help="output directory (default compare/<A>__vs__<B>)")
    c.add_argument("--measure", action="append", choices=MEASURES, help="measure to compare (repeatable; default all)")
    c.add_argument("--control", help="control to match states by (axial_strain, angle, time …; default automatic)")
    c.add_argument("--tolerance", type=float, help="largest control difference of matched states (SI)")
    c.add_argument("--frame", choices=["none", "centroid", "rigid"], default="none",
                   help="coordinate alignment of B onto A (default none: same world frame)")
    c.add_argument("--different-cases", action="store_true", help="compare runs of different scenes anyway")
    c.add_argument("--no-identity", action="store_true", help="skip grain identity and the grain-by-grain errors")
    c.add_argument("--max-distance", type=float, help="position-matching cut-off [m] (default d50/2)")
    c.add_argument("--atol", type=float, default=0.1, help="displacement agreement: absolute tolerance [d50]")
    c.add_argument("--rtol", type=float, default=0.2, help="displacement agreement: relative tolerance")
    c.add_argument("--states", choices=["ends", "all"], help="single-frame measures at the first and last (ends) "
                                                             "or all matched states")
    c.add_argument("--option", action="append", metavar="MEASURE.KEY=VALUE", help="analysis option, e.g. "
                   "d2min.cutoff_d50=1.5 (repeatable; value as JSON)")
    c.set_defaults(func=cmd_compare)

    x = sub.add_parser("crossval", help="run a case on two or more engines (concurrently when 2 cores are free) and "
                                        "compare the first with each of the others")
    x.add_argument("case", help="case YAML file")
    x.add_argument("--runs", default="runs", help="runs directory (default ./runs)")
    x.add_argument("--out", help="output directory (default RUNS/<case>/crossval)")
    x.add_argument("--concurrent", choices=["auto", "yes", "no"], default="auto")
    x.add_argument("--force", action="store_true", help="redo complete runs")
    x.add_argument("--measure", action="append", choices=MEASURES)
    x.add_argument("--states", choices=["ends", "all"])
    x.add_argument("--option", action="append", metavar="MEASURE.KEY=VALUE")
    x.add_argument("--ladder", action="store_true", help="the physics ladder L0 (Hertz-Mindlin + Coulomb) .. L4 "
                   "(full case) on every engine and seed, with run-to-run scatter (docs/crossval.md)")
    x.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3], help="packings per rung and engine (--ladder)")
    x.add_argument("--rung", action="append", choices=["L0", "L1", "L2", "L3", "L4"],
                   help="run only this rung (repeatable; --ladder; default every rung the case has)")
    x.add_argument("--engine", action="append", choices=engine_names(),
                   help="engine to run (repeatable, the first is the reference A; default the case's engines)")
    x.add_argument("--scheduler", help="Dask scheduler address for --ladder (default: local processes)")
    x.add_argument("--workers", type=int, help="local worker processes for --ladder (default one per core)")
    x.add_argument("--dry-run", action="store_true", help="list every run (reused or to run) with its estimate and "
                                                          "the total; run nothing")
    x.set_defaults(func=cmd_crossval)

    r = sub.add_parser("report", help="self-contained HTML page of one run (case, substitutions, checks, "
                                      "run time, analyses)")
    r.add_argument("run", help="run directory")
    r.add_argument("--out", help="HTML file (default RUN/report.html)")
    r.add_argument("--analysis", action="append", help="analysis to run and show (repeatable; default the case's "
                                                       "list, else the scene's default set)")
    r.add_argument("--rerun", action="store_true", help="recompute analyses already in RUN/analysis")
    r.set_defaults(func=cmd_report)

