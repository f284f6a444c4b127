"""Command group of orchestrator.stability: ``stability``, ``convergence``, ``sweep``, ``calibrate``
(registered by orchestrator.cli through ``add_parsers``)."""
from __future__ import annotations

import glob
import os
import sys
from pathlib import Path

from ..console import console
from ..registry import engine_names

REPO = Path(__file__).resolve().parents[2]
#: the members of cases/stability/ small enough for CI (soft grains, ~100 grains, seconds per probe)
CI_SUITE = ("mu0", "mu1", "very_soft", "fast_shear", "restitution_overdamped")


def _print_df(df, title, floatfmt="{:.4g}"):
    from rich.table import Table
    t = Table(title=title)
    for c in df.columns:
        t.add_column(str(c))
    for _, r in df.iterrows():
        from rich.markup import escape
        t.add_row(*[floatfmt.format(v) if isinstance(v, float) else escape(str(v)) for v in r.to_list()])
    console().print(t)


def _suite(which: str) -> list[str]:
    files = sorted(glob.glob(str(REPO / "cases" / "stability" / "[!_]*.yaml")))
    if which == "ci":
        files = [f for f in files if Path(f).stem in CI_SUITE]
    return files


def _check_out_file(path, option: str) -> None:
    """Refuse, before any run, an output file (``--csv``) that could not be written at the end:
    its folder missing or not a folder, or the path a folder (ValueError naming the option)."""
    if path is None:
        return
    p = Path(path)
    if p.is_dir():
        raise ValueError(f"{option} {path}: is a directory; give a file name, e.g. {option} {p / 'table.csv'}")
    if not p.parent.is_dir():
        raise ValueError(f"{option} {path}: the folder {p.parent} does not exist; create it (mkdir -p {p.parent}) "
                         f"or give a file in an existing folder")


def _check_workers(args) -> None:
    """``--workers`` is a count of local worker processes (0: one per core, as when it is left out);
    a negative one is refused before any worker starts."""
    w = getattr(args, "workers", None)
    if w is not None and w < 0:
        raise ValueError(f"--workers {w}: give a number of worker processes, e.g. --workers 2 (0: one per core)")


def cmd_stability(args) -> int:
    from .bisection import bisect, check_tolerance, probe_case, table
    from ..case import load_case
    from ..derive import derive
    cases = list(args.case) + (_suite(args.suite) if args.suite else [])
    if not cases:
        print("error: give a CASE or --suite ci|all", file=sys.stderr)
        return 2
    check_tolerance(args.tol)
    _check_out_file(args.csv, "--csv")
    # every case (and its shortened probe) is read and checked before the first bisection runs: a
    # bad second case found after the first case's hour of probes is the first case's hour lost
    loaded = []
    for c in cases:
        case = load_case(c)
        probe_case(c)
        loaded.append((c, case))
    con = console()
    results = []
    for c, case in loaded:
        rep = derive(case)["stability"]
        con.print(f"[bold]{case.name}[/bold]: dt = {rep['dt']:.3e} s; limits: "
                  + ", ".join(f"{k} {v:.3e} s ({rep['fractions'][k]:.3g})" for k, v in rep["limits"].items()))
        for w in rep.get("warnings", []):
            con.print(f"  [yellow]warning[/yellow]: {w}")
        for eng in ([args.engine] if args.engine != "all" else case.engines):
            b = bisect(c, eng, runs_root=args.runs, rel_tol=args.tol, log=con.print)
            results.append(b)
    df = table(results)
    _print_df(df, "Largest stable dt (fraction of derive's critical step) against the pre-run check")
    if args.csv:
        from ..atomic import write_text
        write_text(args.csv, df.to_csv(index=False))
    bad = df[df["check_safe_side"] != True]  # noqa: E712
    if len(bad):
        con.print(f"[red]the pre-run check is NOT on the safe side for {len(bad)} case/engine pair(s)[/red]")
        return 1
    con.print("[green]the pre-run check stays on the safe side everywhere[/green]")
    return 0


def _say_run_ended(con):
    """``on_result`` of a ladder or sweep: one line as each run ends (a ladder of hours says how far it is)."""
    def say(task, res):
        con.print(f"  {task['engine']} {task['point']} -> {res.get('status')}"
                  f"{' (reused)' if res.get('reused') else ''} {res.get('error') or ''}")
    return say


def cmd_convergence(args) -> int:
    from .convergence import ladder, ladder_plan
    _check_workers(args)
    _check_out_file(args.csv, "--csv")
    if args.dry_run:
        return _print_plan(ladder_plan(args.case, args.knob, [_val(v) for v in args.values],
                                       engines=None if args.engine == "all" else [args.engine],
                                       runs_root=args.runs, seeds=args.seeds, reference=args.reference,
                                       full=args.full, target_error=args.target_error),
                           f"ladder of {args.case}, knob {args.knob}: the runs before any of them", args.workers)
    out = ladder(args.case, args.knob, [_val(v) for v in args.values],
                 engines=None if args.engine == "all" else [args.engine], runs_root=args.runs,
                 reference=args.reference, target_error=args.target_error, scheduler=args.scheduler,
                 workers=args.workers, plot=args.plot or Path(args.runs) / "convergence" /
                 f"{Path(args.case).stem}-{args.knob}.png", full=args.full, seeds=args.seeds,
                 on_result=_say_run_ended(console()))
    df = out["table"]
    cols = ["engine", args.knob] + (["seed"] if args.seeds else []) + ["status", "sample", "engine_time_s", "error"] \
        + [c for c in df.columns if c.startswith("err_")]
    show = df[cols].rename(columns=lambda c: c.replace("err_", "e:"))
    _print_df(show, f"Error against run time: {args.case}, knob {args.knob} (e: relative errors)")
    obs = [c for c in df.columns if c not in cols and c not in ("total_time_s", "reference", "run_id", "seed")
           and not c.startswith("err_") and not c.endswith("_sem")]
    if obs:
        _print_df(df[["engine", args.knob] + (["seed"] if args.seeds else []) + obs], "observables")
    ext = out["extrapolation"]
    if len(ext):
        full = "the ideal limit" if args.full is None else f"{args.knob} = {args.full}"
        _print_df(ext[["engine", "observable", "rungs", "value_full", "sem_full", "cheapest", "cheapest_time_s",
                       "where"]], f"Extrapolated to full fidelity ({full}): y = a + b h({args.knob}); the cheapest "
                                  f"{args.knob} predicted within {args.target_error:g} of it")
    if args.csv:
        from ..atomic import write_text
        write_text(args.csv, df.to_csv(index=False))
        if len(ext):        # the extrapolation beside it: CSV.csv -> CSV-extrapolation.csv
            csv = Path(args.csv)
            write_text(csv.with_name(f"{csv.stem}-extrapolation{csv.suffix or '.csv'}"), ext.to_csv(index=False))
    con = console()
    from rich.markup import escape
    for eng, r in out["recommendation"].items():
        ff = r.get("full_fidelity") or {}
        if ff.get("value") is not None:
            con.print(f"[green]{eng}[/green]: within {args.target_error:g} of full fidelity for every observable: "
                      f"{args.knob} = {ff['value']:.3g} (set by {ff['observable']}; predicted engine time "
                      f"{ff['engine_time_s']:.3g} s; {ff['where']})")
        con.print(f"[green]{eng}[/green]: recommended {args.knob} = {r[args.knob]} (error {r['error']:.3g}, "
                  f"engine time {r['engine_time_s']:.3g} s{', ' + r['note'] if 'note' in r else ''}); "
                  + escape(f"Pareto front: {r['pareto']}"))
    con.print(f"plot: {out['plot']}")
    return 0


def _print_plan(plan, title: str, workers: int | None) -> int:
    """Print a ladder's or sweep's runs as a dry run lists them, and the engine time of those still
    to run on one worker and on ``workers`` (each run's estimate; no packing, mesh or run
    directory); 0, or 2 when every run is refused."""
    import pandas as pd
    from rich.markup import escape

    from ..humanize import fmt_s
    show = plan.drop(columns=["run_dir", "note"]).copy()
    show["engine_time"] = [fmt_s(t) if t == t else "" for t in show.pop("engine_time_s")]
    show["note"] = plan["note"]
    for c in ("particles", "steps"):
        show[c] = ["" if pd.isna(v) else f"{int(v):,}" for v in show[c]]
    _print_df(show, title)
    todo = plan[plan["status"] == "to run"]
    total = float(todo["engine_time_s"].sum())
    con = console()
    n_w = max(int(workers or 1), 1)
    longest = float(todo["engine_time_s"].max()) if len(todo) else 0.0
    counts = (f"{len(todo)} run(s) to do, {int((plan['status'] == 'reused').sum())} reused, "
              f"{int((plan['status'] == 'refused').sum())} refused")
    con.print(counts + (f": ~{fmt_s(total)} of engine time on one worker"
                        + (f", at least ~{fmt_s(max(total / n_w, longest))} on {n_w}" if n_w > 1 and len(todo) > 1 else "")
                        + " (each run's estimate, as `run --dry-run` prints it)" if len(todo) else ": nothing to run"))
    refused = int((plan["status"] == "refused").sum())
    for why in dict.fromkeys(plan.loc[plan["status"] == "refused", "note"].astype(str)):
        con.print(escape(f"refused: {why}"))        # in full: the table's note column may be cut to its width
    if len(plan) and refused == len(plan):
        con.print("[red]every run is refused[/red] (the reasons above): fix the values given; nothing would run")
        return 2
    if refused:     # docs/stability.md: an invalid point fails alone, the others still run
        con.print(f"[yellow]{refused} run(s) refused[/yellow] (the reasons above): a real run leaves them out "
                  "(marked failed) and runs the others")
    return 0


def _val(v: str):
    import yaml
    return yaml.safe_load(v)


def _every_point_refused(args) -> bool:
    """Whether the loader refuses every point of ``sweep`` (checked before the sweep creates its
    folder or starts a worker): then each point's reason goes to stderr and the sweep is bad input
    (status 2), as the dry run says. Some points refused: the sweep runs the others (an invalid
    point fails alone, docs/stability.md)."""
    from ..case import CaseError, load_case
    from .sweep import nested, parse_sets, points, refuse_unknown_fields
    sets = parse_sets(args.set)
    refuse_unknown_fields(load_case(args.case), args.case, list(sets))
    why = []
    for pt in points(sets, args.grid):
        try:
            load_case(args.case, overrides=nested(pt))
            return False
        except CaseError as exc:
            why.append((pt, exc))
    print(f"error: sweep of {args.case}: every point is refused, nothing to run; fix the values given:", file=sys.stderr)
    for pt, exc in why:
        print(f"  {', '.join(f'{k}={v}' for k, v in pt.items())}: {exc}", file=sys.stderr)
    return True


def cmd_sweep(args) -> int:
    from .sweep import sweep, sweep_plan
    _check_workers(args)
    if args.dry_run:
        return _print_plan(sweep_plan(args.case, args.set, grid=args.grid,
                                      engines=None if args.engine == "all" else [args.engine], runs_root=args.runs),
                           f"sweep of {args.case}: the runs before any of them", args.workers or os.cpu_count())
    if _every_point_refused(args):
        return 2
    df = sweep(args.case, args.set, grid=args.grid, engines=None if args.engine == "all" else [args.engine],
               runs_root=args.runs, scheduler=args.scheduler, workers=args.workers, on_result=_say_run_ended(console()),
               force=args.force)
    _print_df(df.drop(columns=["run_id"]), f"sweep of {args.case}")
    failed = df[df["status"] == "failed"]
    return 1 if len(failed) else 0


def _mu_list(text: str) -> list[float]:
    """``--mu 0.1,0.3,0.6``: the friction coefficients, or a ValueError naming --mu and the form."""
    form = "give comma-separated friction coefficients of at least 0, e.g. --mu 0.2,0.4,0.6"
    parts = [x.strip() for x in text.split(",")]
    if not text.strip() or any(x == "" for x in parts):
        raise ValueError(f"--mu {text!r}: an empty value; {form}")
    out = []
    for x in parts:
        try:
            out.append(float(x))
        except ValueError:
            which = "" if x == text.strip() else f": {x!r}"
            raise ValueError(f"--mu {text!r}{which} is not a number; {form}") from None
    return out


def cmd_calibrate(args) -> int:
    from .calibration import calibrate
    _check_workers(args)
    mus = _mu_list(args.mu)
    out = calibrate(args.case, mus, target=args.target, engines=None if args.engine == "all" else [args.engine],
                    runs_root=args.runs, scheduler=args.scheduler, workers=args.workers,
                    plot=args.plot or Path(args.runs) / "calibration" / f"{Path(args.case).stem}.png")
    df = out["table"]
    keep = [c for c in ("contact.friction", "engine", "status", "mu_macro", "mu_macro_sem", "solid_fraction_nominal",
                        "engine_time_s") if c in df.columns]
    _print_df(df[keep], f"mu_macro(mu), {args.case}")
    con = console()
    for eng, f in out["fits"].items():
        if "error" in f:
            con.print(f"[red]{eng}: {f['error']}[/red]")
            continue
        con.print(f"{eng}: mu_macro = {f['mu0']:.4f} + {f['A']:.4f} (1 - exp(-mu/{f['mu_c']:.4f})), "
                  f"rms residual {f['rms_residual']:.3g}")
        if args.target is not None:
            r = out["mu_for_target"].get(eng, {})
            con.print(f"  mu for mu_macro = {args.target}: " + (f"{r['mu']:.4f} ± {r['mu_std']:.2g}" if "mu" in r
                                                                else r.get("error", "?")))
    con.print(f"plot: {out['plot']}")
    return 0


def add_parsers(sub):
    s = sub.add_parser("stability", help="largest stable dt per case and engine (bisection) vs the pre-run check")
    s.add_argument("case", nargs="*", help="case YAML file(s)")
    s.add_argument("--suite", choices=["ci", "all"], help="the cases/stability/ suite (ci: its small members)")
    s.add_argument("--engine", choices=[*engine_names(), "all"], default="all")
    s.add_argument("--runs", default="runs/stability")
    s.add_argument("--tol", type=float, default=0.15, help="relative bisection tolerance")
    s.add_argument("--csv", help="also write the table as CSV")
    s.set_defaults(func=cmd_stability)

    c = sub.add_parser("convergence", help="error against run time over a ladder of one knob")
    c.add_argument("case")
    c.add_argument("--knob", required=True, help="dt_fraction, stiffness_scale, rate_scale, particle_scale, count, "
                                                 "size_scale, or a dotted case field")
    c.add_argument("--values", nargs="+", required=True, help="ladder values, cheapest first (the last is the "
                                                              "reference unless --reference)")
    c.add_argument("--reference", help="the value to compare against (default: the last)")
    c.add_argument("--target-error", type=float, default=0.05)
    c.add_argument("--full", type=float, help="the knob's full-fidelity value to extrapolate to, e.g. the seed's "
                                              "stiffness as a multiple of the case's (default: the ideal limit: "
                                              "dt -> 0, quasi-static, rigid, infinite system)")
    c.add_argument("--seeds", type=int, nargs="+", help="run every rung on each of these packings (the case's "
                                                        "seed): each rung's mean and run-to-run standard error "
                                                        "enter the extrapolation")
    c.add_argument("--engine", choices=[*engine_names(), "all"], default="all")
    c.add_argument("--runs", default="runs")
    c.add_argument("--scheduler", help="Dask scheduler address (default: local processes)")
    c.add_argument("--workers", type=int, default=1, help="local worker processes (default 1: clean timings)")
    c.add_argument("--plot", help="plot file (default RUNS/convergence/CASE-KNOB.png)")
    c.add_argument("--dry-run", action="store_true",
                   help="list the ladder's runs (reused, to run, refused), each one's size and estimated engine "
                        "time, and the total; nothing is packed or run")
    c.add_argument("--csv", help="also write the table as CSV (and the extrapolation as CSV-extrapolation.csv)")
    c.set_defaults(func=cmd_convergence)

    w = sub.add_parser("sweep", help="run a case over field values (list or --grid), reusing finished runs")
    w.add_argument("case")
    w.add_argument("--set", action="append", required=True, help="FIELD=V1,V2,... (dotted field, repeatable)")
    w.add_argument("--grid", action="store_true", help="Cartesian product of the --set lists (default: zip)")
    w.add_argument("--engine", choices=[*engine_names(), "all"], default="all")
    w.add_argument("--runs", default="runs")
    w.add_argument("--scheduler", help="Dask scheduler address, e.g. tcp://host:8786 (default: local processes)")
    w.add_argument("--workers", type=int, help="local worker processes (default: one per core)")
    w.add_argument("--force", action="store_true", help="re-run finished runs too")
    w.add_argument("--dry-run", action="store_true",
                   help="list the sweep's runs (reused, to run, refused), each one's size and estimated engine "
                        "time, and the total; nothing is packed or run")
    w.set_defaults(func=cmd_sweep)

    k = sub.add_parser("calibrate", help="mu calibration in plane shear (seed 000 §3.2)")
    k.add_argument("case", help="a plane_shear case")
    k.add_argument("--mu", required=True, help="friction coefficients, e.g. 0.1,0.3,0.6,1.0")
    k.add_argument("--target", type=float, help="target steady mu_macro")
    k.add_argument("--engine", choices=[*engine_names(), "all"], default="all")
    k.add_argument("--runs", default="runs")
    k.add_argument("--scheduler")
    k.add_argument("--workers", type=int)
    k.add_argument("--plot")
    k.set_defaults(func=cmd_calibrate)
