"""Command line: ``orchestrator <command>`` (``--help`` on each).

The commands import their modules when they run (not at the top): ``orchestrator --help`` and a
``validate`` then start in well under a second instead of loading pandas, h5py, pyvista and dask.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from .analysis_specs import parse_cli_spec, parse_specs
from .console import console
from .registry import engine_names, get_engine


def _num(x) -> str:
    """A figure for a message (the engine's value or limit; NaN or missing shown as such)."""
    return f"{x:.6g}" if isinstance(x, (int, float)) else str(x)


# ---------------------------------------------------------------------------------------------
def cmd_validate(args) -> int:
    from .case import load_case
    from .derive import derive
    from .runner import refusal
    case = load_case(args.case)
    p = derive(case)
    con = console()
    refusals = {eng: why for eng in case.engines if (why := refusal(case, eng, p))}
    verdict = (f"[green]{args.case}: valid[/green]" if not refusals else
               f"[red]{args.case}: not runnable on {', '.join(refusals)} as written[/red]")
    con.print(f"{verdict} — case '{case.name}', scene '{case.scene.kind}', engines {', '.join(case.engines)}")
    con.print(f"  dt = {p['dt']:.4g} s = {p['dt_fraction']:.3g} × critical {p['dt_critical']:.4g} s "
              f"(Rayleigh {p['dt_rayleigh']:.4g} s, Hertz t_c/10 {p['dt_hertz']:.4g} s)")
    con.print(f"  features: {', '.join(p['features'])}")
    from .sizing import busy_cores, busy_note, describe, estimate, problems
    busy_now = busy_cores()                     # sampled once: validate runs nothing
    for eng in case.engines:
        if eng in refusals:
            con.print(f"  [red]{eng}: cannot run this case: {refusals[eng]}[/red]")
            continue
        size = estimate(case, p, eng)
        con.print(f"  {eng}: {describe(size)}")
        busy = busy_note(get_engine(eng).workers(case), busy_now) if busy_now is not None else None
        if busy:
            con.print(f"  [yellow]{busy}[/yellow]")
        for prob in problems(case, size):
            con.print(f"  [yellow]{prob if prob.startswith('warning:') else 'too big: ' + prob + ' (run refuses it unless --force)'}[/yellow]")
    return 2 if refusals else 0


def cmd_run(args) -> int:
    from .case import load_case
    from .runner import refusal, run_case
    case = load_case(args.case)
    engines = case.engines if args.engine == "all" else [args.engine]
    con = console()
    status = 0
    from .derive import derive
    from .sizing import busy_cores, busy_note, check_fits, describe, estimate
    params = derive(case)
    from .case import CaseError
    refusals = [f"engine {eng}: {why}" for eng in engines if (why := refusal(case, eng, params))]
    if refusals:                                  # refused before any sizing, packing or run directory
        raise CaseError(case.source or args.case, refusals)
    # a dry run samples the machine's load once; a run, at each engine's start (the one before has just ended)
    busy_now = busy_cores() if args.dry_run else None
    for eng in engines:
        size = estimate(case, params, eng)
        warnings = check_fits(case, size, force=args.force)        # refuses a case too big for the machine
        busy = busy_note(get_engine(eng).workers(case), busy_now)
        con.print(f"[cyan]{eng}[/cyan]: {case.name}: {describe(size)}")
        if busy:
            warnings = [busy] + warnings
        for w in warnings:
            con.print(f"  [yellow]{w}[/yellow]")
        if args.dry_run:
            continue                              # sizing only: no packing, no meshes, no run directory
        out = run_case(case, eng, runs_root=args.runs, force=args.force, dry_run=args.dry_run,
                       progress=None if not args.quiet else False)
        s = out.summary
        wt = s.get("wall_time", {})
        tag = "reused" if out.reused else s["status"]
        if s["status"] == "unstable":
            status = 1
            u = s.get("unstable") or {}
            con.print(f"[red]{eng}: unstable[/red] {out.run_dir}: {u.get('meaning', u.get('figure'))}: "
                      f"{u.get('figure')} = {_num(u.get('value'))} against the limit {_num(u.get('limit'))} at step "
                      f"{u.get('step')}; lower timestep.fraction (the stability report is in summary.json) and "
                      "run again")
            continue
        con.print(f"[green]{eng}[/green]: {tag} {out.run_dir} — engine {wt.get('engine', 0):.1f} s, "
                  f"total {wt.get('total', 0):.1f} s")
        r = s.get("resumed_from")
        if r and not out.reused:
            at = f" (step {r['step']})" if r.get("step") is not None else ""
            con.print(f"  resumed from {r.get('restart_file') or r.get('checkpoint')}{at}")
        for sub in s.get("substitutions", []):
            con.print(f"  substitution: {sub['feature']} -> {sub['mechanism']}: {sub['note']}")
        if s.get("status") == "complete" and not args.no_report:
            _closing_results(out.run_dir, con)
    return status


def _closing_results(run_dir, con) -> None:
    """After a complete run: write report.html in the run directory (if missing) and print the
    key results with where the frames, figures and report are."""
    from .compare.report import write_run_report
    from .results import print_key_results
    if not (run_dir / "report.html").exists():
        try:
            write_run_report(run_dir)
        except (OSError, ValueError, KeyError) as exc:     # the run is complete; the page is a convenience
            con.print(f"  [yellow]report.html not written: {exc}[/yellow]")
    print_key_results(run_dir, con)


def cmd_clock(args) -> int:
    """``orchestrator clock show|refresh``: the fitted cost model per engine and scene."""
    from rich.table import Table
    from .clock import (load_table, machine_factor, machine_id, package_table_path, refresh, samples_from_runs,
                        speed_records, speed_table_path, user_table_path)
    con = console()
    if args.action == "refresh":
        missing = [r for r in args.runs if not Path(r).exists()]
        if missing or not args.runs:
            print(f"error: clock refresh: {'no such path ' + ', '.join(map(str, missing)) if missing else 'no runs given'}; "
                  "give run directories or runs/ trees, e.g. `orchestrator clock refresh runs`", file=sys.stderr)
            return 2
        if not samples_from_runs(args.runs):
            print(f"error: clock refresh: no complete run under {', '.join(map(str, args.runs))} (a run counts once "
                  "its summary.json says complete; a resumed run with the record of all its attempts); nothing written", file=sys.stderr)
            return 2
        out = package_table_path() if args.package else user_table_path()
        try:
            fitted = refresh(args.runs, out, steps_only=args.steps_only, add=args.add)
        except ValueError as exc:
            print(f"error: {exc}; nothing written", file=sys.stderr)
            return 2
        if args.steps_only:
            con.print(f"refreshed the step plans of {sum(len(v) for v in fitted.values())} engine/scene model(s) "
                      f"({', '.join(f'{e} {k}: {tp.units:g} units' for e, v in fitted.items() for k, tp in v.items())}); "
                      f"wrote {out}")
        else:
            n = sum(tp.runs for scenes in fitted.values() for tp in scenes.values())
            con.print(f"fitted {sum(len(v) for v in fitted.values())} engine/scene model(s) from {n} complete run(s); "
                      f"wrote {out}")
    t = Table(title="run-time model: t = startup (+ s_n n) + steps (a + b n^α) / (1 + e (workers - 1))")
    for col in ("engine", "scene", "startup [s]", "a [µs/step]", "b [ns/(particle^α step)]", "α", "e", "runs", "note"):
        t.add_column(col)
    for eng, scenes in sorted(load_table().items()):
        for sc, tp in sorted(scenes.items()):
            start = f"{tp.startup_s:.2f}" + (f" + {tp.startup_per_particle_s * 1e3:.3g} ms n" if tp.startup_per_particle_s else "")
            t.add_row(eng, sc, start, f"{tp.per_step_s * 1e6:.1f}", f"{tp.per_particle_step_s * 1e9:.1f}",
                      f"{tp.exponent:.2f}", f"{tp.parallel_efficiency:.2f}", str(tp.runs), tp.note)
    con.print(t)
    speeds = {eng: machine_factor(eng) for eng in sorted(load_table())}
    said = [f"{eng} × {f:.2f} ({k} run(s))" for eng, (f, k) in ((e, v) for e, v in speeds.items() if v)]
    how = ("; ".join(said) + " of the package table's times (medians; an estimate takes its scene's runs at "
           "its size, orchestrator.clock.speed_factor)") if said else "no complete run recorded yet"
    con.print(f"this machine ({machine_id()}): {how} ({speed_table_path()})", markup=False)
    records = speed_records()
    if records:
        r = Table(title="this machine's runs: engine time over the package table's prediction")
        for col in ("engine", "scene", "particles", "ranks/threads", "ratio", "quiet", "run"):
            r.add_column(col)
        for rec in records:
            quiet = {True: "yes", False: "no"}.get(rec.get("quiet"), "-")
            r.add_row(rec["engine"], str(rec.get("scene")), f"{rec['n']:,}" if rec.get("n") else "-",
                      str(rec.get("ranks") or 1), f"{rec['ratio']:.3f}", quiet, str(rec.get("run", "")))
        con.print(r)
    return 0


def cmd_engines(args) -> int:
    from rich.table import Table
    from engines.base import FEATURES
    con = console()
    t = Table(title="DEM engines")
    t.add_column("feature")
    engs = [get_engine(n) for n in engine_names()]
    for e in engs:          # versions on their own lines: with three engines a table cell wraps them
        con.print(f"{e.name}: {e.version() if e.available() else 'not installed'}")
        t.add_column(e.name)
    for f in FEATURES:
        row = [f]
        for e in engs:
            if f in e.capabilities:
                row.append("[green]yes[/green]: " + e.capabilities[f])
            elif f in e.substitutes:
                row.append("[yellow]substitute[/yellow]: " + "; ".join(e.substitutes[f]))
            else:
                row.append("[red]no[/red]")
        t.add_row(*row)
    con.print(t)
    return 0


def cmd_verify(args) -> int:
    from rich.table import Table
    from .verify import run_verification
    from .verify import verification_cases
    engines = list(engine_names()) if args.engine == "all" else [args.engine]
    cases = [p for p in verification_cases() if not args.case or any(c in p.stem for c in args.case)]
    if not cases:
        names = ", ".join(p.stem for p in verification_cases())
        print(f"error: --case {' '.join(args.case)}: no verification case's name contains it; the cases: {names}",
              file=sys.stderr)
        return 2
    tab = run_verification(engines=engines, cases=cases, runs_root=args.runs, force=args.force)
    con = console()
    for eng in engines:
        sub = tab[tab.engine == eng]
        t = Table(title=f"Contact-level verification (Chung & Ooi 2011) — {eng}")
        for c in ("case", "impact", "quantity", "analytic", "engine value", "rel. error", "wall time"):
            t.add_column(c, justify="right" if c not in ("case", "impact", "quantity") else "left")
        for _, r in sub.iterrows():
            err = f"{r.rel_error:+.2e}"
            err = f"[green]{err}[/green]" if r["pass"] else f"[red]{err}[/red]"
            t.add_row(r.case.replace("chung_ooi_", ""), r.impact, r.quantity, f"{r.analytic:.5g}",
                      f"{r.engine_value:.5g}", err, f"{r.wall_time_s:.2f} s")
        con.print(t)
    if args.csv:
        from .atomic import write_text
        write_text(args.csv, tab.to_csv(index=False))
    failed = tab[~tab["pass"]]
    if len(failed):
        con.print(f"[red]{len(failed)} check(s) outside tolerance[/red]")
        return 1
    con.print(f"[green]all {len(tab)} checks within tolerance[/green]")
    return 0


def cmd_analyze(args) -> int:
    from .case import yaml_or_case_error
    run_dir = Path(args.run_dir)
    if not run_dir.exists():
        print(f"error: {run_dir}: no such run directory or frames.h5; give a run directory "
              "(runs/<case>/<engine>-<hash>), a frames.h5 or a CT frame set", file=sys.stderr)
        return 2
    inside = sorted(p.parent for p in run_dir.glob("*/frames.h5")) if run_dir.is_dir() else []
    if inside and not (run_dir / "frames.h5").exists():
        print(f"error: {run_dir}: not a run directory (no frames.h5); it holds the runs "
              f"{', '.join(str(p) for p in inside)}: give one of them", file=sys.stderr)
        return 2
    if run_dir.is_dir() and not (run_dir / "frames.h5").exists():
        print(f"error: {run_dir}: no frames.h5 here (is the run complete? `orchestrator status {run_dir}` says how "
              f"far it got)", file=sys.stderr)
        return 2
    try:
        specs = [parse_cli_spec(a) for a in args.analysis or []]
        parse_specs(specs, where="--analysis")
    except ValueError as e:
        print(f"error: {e}" if str(e).startswith("--analysis") else f"error: --analysis {e}", file=sys.stderr)
        return 2
    # a frames.h5 given for its run: the case, the summary and the outputs are its directory's
    run_root = run_dir.parent if run_dir.is_file() else run_dir
    if not specs:
        case_file = run_root / "case.yaml"             # a damaged one is a CaseError naming it
        specs = (yaml_or_case_error(case_file) or {}).get("analysis", []) if case_file.exists() else []
    if not specs:
        print(f"error: {run_dir}: no analyses asked for (give --analysis NAME or list them in the case)", file=sys.stderr)
        return 2
    out_dir = Path(args.out) if args.out else run_root / "analysis"
    # an output directory the user may not write is said before the analysis stack is imported (~4 s)
    out_dir.mkdir(parents=True, exist_ok=True)
    where = "--analysis" if args.analysis else f"{run_root / 'case.yaml'}: analysis"
    _check_controls(run_dir, parse_specs(specs, where=where), where)
    from .runner import analyze_run
    out, _ = analyze_run(run_root, specs, out_dir if args.out else None, by_name=bool(args.analysis),
                         frames=run_dir)
    # the tracebacks stay in the file (analysis_summary.json), not on the screen
    print(json.dumps({k: {f: x for f, x in v.items() if f != "traceback"} for k, v in out.items()},
                     indent=2, default=str))
    failed = {k: v for k, v in out.items() if v.get("status") == "error"}
    for label, v in failed.items():
        print(f"error: {label} failed: {v.get('error')} (options {json.dumps(v.get('options') or {})}); "
              f"its traceback is in {out_dir / 'analysis_summary.json'}", file=sys.stderr)
    return 1 if failed else 0


def _check_controls(frames_path, specs, where: str) -> None:
    """An analysis's ``control`` option that the frames do not carry, as bad input (a ValueError
    naming the entry ``where[n]``, the option and the controls there are) before any analysis runs,
    not as an analysis that failed. ``specs``: :func:`parse_specs`' (name, options) pairs."""
    from .analysis._common import control_values
    from .frames import Frames
    fr = Frames(frames_path)
    for n, (name, opts) in enumerate(specs):
        if opts.get("control") is not None:
            try:
                control_values(fr, opts["control"])
            except ValueError as e:
                raise ValueError(f"{where}[{n}] ({name}): {e}") from None


def cmd_vtk(args) -> int:
    from .frames import Frames
    fr = Frames(args.run_dir)
    n = fr.n_frames
    which = f"{args.run_dir} has {n} frame(s): give an index from 0 to {n - 1} (negative from the end, -1 the last) or 'all'"
    if args.frame == "all":
        frames = range(n)
    else:
        try:
            frames = [int(args.frame)]
        except ValueError:
            print(f"error: --frame {args.frame!r} is not a frame index; {which}", file=sys.stderr)
            return 2
        if not -n <= frames[0] < n:
            print(f"error: --frame {frames[0]}: no such frame; {which}", file=sys.stderr)
            return 2
    out = Path(args.out or Path(args.run_dir) / "vtk")
    out.mkdir(parents=True, exist_ok=True)
    for k in frames:
        fr.to_vtk(k, out / f"frame_{range(n)[k]:05d}.vtu")
    print(f"wrote {len(frames)} VTK file(s) to {out}")
    return 0


def cmd_status(args) -> int:
    """``orchestrator status [PATH ...]``: how far each run got, its engine time so far and the time
    left (orchestrator.run_status)."""
    from rich.markup import escape
    from rich.table import Table
    from .atomic import write_text
    from .run_status import status_table
    from .humanize import fmt_s
    con = console()
    paths = args.paths or ["runs"]
    if not args.paths and not Path("runs").is_dir():
        con.print("no runs here yet: no ./runs directory (`orchestrator run CASE` makes it; or give the --runs "
                  "directory the runs went to)")
        return 0
    df = status_table(paths)
    if df.empty:
        con.print(f"no runs under {', '.join(paths)} (a run directory holds a summary.json)")
        return 0
    dirs = [os.path.abspath(d) for d in df.run_dir]
    root = os.path.commonpath([os.path.dirname(os.path.dirname(d)) for d in dirs])   # runs/<case>/<engine-hash>
    t = Table(title=f"Runs under {root}: engine time so far and left (CPU time on one rank, wall time on several)")
    for col in ("run", "status", "grains", "step", "tries", "engine time", "steps/s", "left: pace", "left: clock"):
        t.add_column(col, justify="left" if col in ("run", "status") else "right", overflow="fold",
                     no_wrap=col != "run")
    colour = {"complete": "green", "running": "cyan", "interrupted": "yellow"}

    def secs(x, complete):
        return "-" if x != x or (x == 0 and complete) else fmt_s(x)

    def known(x):                 # a figure the summary gives: neither missing (None) nor NaN
        return x is not None and x == x

    for label, r in zip((os.path.relpath(d, root) for d in dirs), df.itertuples()):
        done = r.status == "complete"
        st = f"[{colour.get(r.status, 'red')}]{escape(r.status)}[/]"
        # "~": the steps a scene that decides its step count as it runs is expected to take
        of = f"{'~' if r.steps_expected != r.steps else ''}{int(r.steps_expected):,}" if known(r.steps_expected) else "?"
        step = ("-" if not known(r.step) else
                f"{int(r.step):,}/{of} ({100 * r.done:.0f} %)" if known(r.done) else f"{int(r.step):,}")
        t.add_row(escape(label), st, f"{int(r.n_particles):,}" if known(r.n_particles) and r.n_particles else "-",
                  step, str(r.attempts), secs(r.engine_s, done), "-" if r.pace != r.pace else f"{r.pace:.0f}",
                  secs(r.left_pace_s, done), secs(r.left_clock_s, done))
    con.print(t)
    for damage in df.error[(df.status == "interrupted") & df.error.notna()]:    # an unreadable summary.json
        con.print(f"[red]damaged: {escape(str(damage))}[/red]")
    if (df.status == "interrupted").any():
        con.print("[yellow]an interrupted run resumes from its last restart point when the command that started it "
                  "is run again[/yellow]")
    if args.csv:
        write_text(args.csv, df.to_csv(index=False))
    return 0


# ---------------------------------------------------------------------------------------------
#: the commands defined in this module; the others come from command groups (ct, compare, stability)
CORE_COMMANDS = ("run", "validate", "engines", "verify", "analyze", "vtk", "status")


def build_parser(argv=None) -> argparse.ArgumentParser:
    """The parser; when ``argv`` names a core command the other command groups (whose imports take
    seconds: analysis, plotting) are not loaded."""
    p = argparse.ArgumentParser(prog="orchestrator", description=__doc__.split("\n")[0] + "\n\n"
                                "Runs LIGGGHTS and YADE on granular scenes from YAML cases, writes frames.h5, "
                                "analyses and compares them.", formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--debug", action="store_true", help="show the traceback of an error")
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("run", help="render, run and parse a case on one or both engines")
    r.add_argument("case", help="case YAML file")
    r.add_argument("--engine", choices=[*engine_names(), "all"], default="all",
                   help="engine to run (default: all engines the case lists)")
    r.add_argument("--force", action="store_true", help="redo a complete run from scratch; run a case bigger than "
                   "the machine")
    r.add_argument("--dry-run", action="store_true", help="print particle count, steps, memory and engine time "
                   "only (no packing, no run directory)")
    r.add_argument("--runs", default="runs", help="runs directory (default: ./runs)")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--no-report", action="store_true",
                   help="do not write report.html nor print the results table at the end")
    r.set_defaults(func=cmd_run)

    v = sub.add_parser("validate", help="validate a case file and show its derived time step")
    v.add_argument("case")
    v.set_defaults(func=cmd_validate)

    e = sub.add_parser("engines", help="installed engines, versions and capabilities")
    e.set_defaults(func=cmd_engines)

    ck = sub.add_parser("clock", help="the run-time model: show it, or refit it from complete runs")
    # show and refresh as sub-commands, so that refresh's options may stand before or after its runs
    # (one positional list after a choice made argparse drop "refresh --add RUNS")
    ck_sub = ck.add_subparsers(dest="action", required=True, metavar="{show,refresh}")
    ck_sub.add_parser("show", help="the table in use, entry by entry").set_defaults(func=cmd_clock)
    ckr = ck_sub.add_parser("refresh", help="refit the table from complete runs")
    ckr.add_argument("runs", nargs="*", default=["runs"], help="run directories or runs/ trees")
    ckr.add_argument("--package", action="store_true",
                     help="write the shipped table benchmarks/throughput.json (in a checkout) instead of the user table")
    ckr.add_argument("--steps-only", action="store_true",
                     help="refresh only how many steps the runs took (the same on every machine), keeping the "
                          "table's costs per step (fitted on its own machine)")
    ckr.add_argument("--add", action="store_true",
                     help="fit the runs given together with the runs each entry was fitted on before (kept in the "
                          "table), rather than in their place")
    ckr.set_defaults(func=cmd_clock)

    vf = sub.add_parser("verify", help="contact-level verification against Hertz (Chung & Ooi 2011 tests 1-4)")
    vf.add_argument("--engine", choices=[*engine_names(), "all"], default="all")
    vf.add_argument("--runs", default="runs")
    vf.add_argument("--force", action="store_true")
    vf.add_argument("--csv", help="also write the table as CSV")
    vf.add_argument("--case", action="append", help="only cases whose name contains this (repeatable)")
    vf.set_defaults(func=cmd_verify)

    a = sub.add_parser("analyze", help="run analyses on a run directory or CT frame set")
    a.add_argument("run_dir")
    a.add_argument("--analysis", action="append", help="analysis name, or name:JSON options, e.g. "
                   "'stress:{\"window\": [0.1, 0.2]}' (repeatable); default: the case's list")
    a.add_argument("--out", help="output directory (default RUN_DIR/analysis)")
    a.set_defaults(func=cmd_analyze)

    k = sub.add_parser("vtk", help="export frames as VTK (.vtu) for ParaView")
    k.add_argument("run_dir")
    k.add_argument("--frame", default="-1", help="frame index or 'all' (default: last)")
    k.add_argument("--out", help="output directory (default RUN_DIR/vtk)")
    k.set_defaults(func=cmd_vtk)

    st = sub.add_parser("status", help="how far runs got, their engine time so far and the time left")
    st.add_argument("paths", nargs="*", metavar="PATH",
                    help="run directories or runs trees (default: ./runs)")
    st.add_argument("--csv", help="also write the table as CSV")
    st.set_defaults(func=cmd_status)

    first = next((a for a in (sys.argv[1:] if argv is None else argv) if not a.startswith("-")), None)
    if first in CORE_COMMANDS:
        return p
    try:
        from .ct.cli import add_ct_parser
        add_ct_parser(sub)
    except ImportError:
        pass
    # further command groups register themselves: a module with add_parsers(subparsers)
    import importlib
    for name in ("orchestrator.cli_compare", "orchestrator.stability.cli"):
        try:
            mod = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name and name.startswith(exc.name):
                continue                      # that command group is not there
            raise
        mod.add_parsers(sub)
    return p


def main(argv=None) -> int:
    """Exit status: 0 done, 1 a run or check that failed, 2 bad input (a case, a path, a file),
    130 interrupted. Every error is one message; ``--debug`` adds the traceback."""
    args = build_parser(argv).parse_args(argv)
    # off a terminal (`run case > log 2>&1`, a batch job) Python block-buffers stdout: the start line
    # and the results would reach the log only at exit, after the progress lines on stderr
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.reconfigure(line_buffering=True)
        except (AttributeError, ValueError):       # a replaced stream (pytest's capture, StringIO)
            pass
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("interrupted: the run can be resumed by running the same command again", file=sys.stderr)
        return 130
    except BaseException as exc:               # noqa: BLE001 - every error becomes one message
        if isinstance(exc, SystemExit):
            raise
        if getattr(args, "debug", False):
            import traceback
            traceback.print_exc()
        msg, status = error_message(exc)
        print(f"error: {msg}", file=sys.stderr)
        return status


def error_message(exc: BaseException) -> tuple[str, int]:
    """One message for an error (naming the file, what is wrong and the fix) and its exit status:
    2 for bad input, 1 for a run or check that failed."""
    import errno
    from engines.base import EngineError
    from .case import CaseError
    from .frames import FramesError
    if isinstance(exc, CaseError):
        return str(exc), 2
    if isinstance(exc, FramesError):
        return str(exc), 2
    if type(exc).__name__ in ("SegmentationError", "ScanError", "DerivationError", "SizeError"):   # bad input, said in full
        return str(exc), 2
    if isinstance(exc, EngineError):
        return str(exc), 1
    if isinstance(exc, OSError) and exc.filename is not None:
        f = exc.filename
        if isinstance(exc, PermissionError) or exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
            return (f"{f}: permission denied ({exc.strerror}); write somewhere you may (e.g. --runs or --out "
                    f"in your home directory) or make the directory writable (chmod u+w)"), 2
        if isinstance(exc, IsADirectoryError):
            return f"{f}: is a directory; give a file", 2
        if isinstance(exc, FileExistsError) and not os.path.isdir(f):      # mkdir of an output folder
            return (f"{f}: exists and is not a directory; the output goes into a directory of that name: give "
                    f"--out (or --runs) an existing directory or a new path"), 2
        if isinstance(exc, NotADirectoryError):
            return f"{f}: a path component is not a directory; check the path", 2
        if isinstance(exc, FileNotFoundError):
            return f"{f}: no such file or directory; check the path", 2
        if exc.errno == errno.ENOSPC:
            return f"{f}: no space left on the device; free some space or use another --runs directory", 1
        return f"{f}: {exc.strerror}", 2
    if isinstance(exc, OSError):
        return f"{exc}", 2
    if isinstance(exc, ValueError):
        return f"{exc}", 2
    return (f"{type(exc).__name__}: {exc} (an internal error: please report it with the output of the same "
            f"command run with --debug)"), 1


if __name__ == "__main__":
    sys.exit(main())
