"""Estimate against actual engine time, for every complete run found (issue #15: within ±30 %).

    .venv/bin/python benchmarks/bench_estimate.py [RUNS_TREE ...] [--run CASE ...] [--engine E ...]

With ``--run``, the named cases are first run (or reused) under ``benchmarks/runs-estimate/``.
For every complete run (a resumed one costed from its attempts) it prints the engine time the model predicts before the run
(:mod:`orchestrator.clock`; for a triaxial, whose stage 1 goes on until it converges, from the
stage-1 chunks the engine's other runs took, not from the chunks this run took) in two ways:

- ``expected``: the steps the table expects the run to take (a triaxial's stage 1 from the units
  its entry learned: ``clock refresh --steps-only``), beside the ``steps`` it took;
- ``table``: with the shipped/user table as it is (what ``validate`` and ``run --dry-run`` print);
- ``leave-one-out``: refitted on the *other* runs of the same engine and scene, so a run never
  predicts itself (an honest out-of-sample figure; "n/a" when it is the only run of its kind);
- ``machine``: the package table times this machine's speed as the *other* quiet runs of the same
  engine given here measure it (their :func:`orchestrator.clock.speed_ratio`, those of the same
  scene where there are any, at this run's size, and of as many ranks or threads where there are
  any: :func:`orchestrator.clock.speed_factor`, what ``run --dry-run`` prints once the machine has
  recorded them; "n/a" without such a run, and for a run whose package entry was fitted on this
  machine, which the dry run takes unscaled: YADE's medium clump triaxial since session 41, whose
  machine column read 1.15 before its own run was fitted into the table).

``ms/step`` is the run's own loop time per step (one rank's, as the fit takes it) and ``start s``
its start-up and set-up (engine time minus loop time): what the table's per-step and start-up
terms are fitted to.

``load`` is the machine's mean load average over the run's cores (``orchestrator.attempts``; "-"
for runs recorded before it was kept). A multi-rank run with a load above its cores by more than
half a core is marked ``shared``: its wall time (the time that counts for ranks, which poll while
they wait) measured the other runs too; the fit leaves it out, and the largest error is given with
and without such runs. A run marked ``off-plan`` left its scene's step plan (a triaxial whose stage
1 ran out of chunks before it converged, ``isotropic_end.converged`` false, and skipped the drag ramp): the estimate is for a run that
follows the plan, and the ``machine`` column's largest error is given with and without such runs.

Then ``orchestrator clock refresh RUNS --package`` stores the fit of all of them.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

from orchestrator.case import load_case

from orchestrator.clock import (base_kind, estimate_engine_time, expected_steps, fit, fitted_here, load_table,
                                planned_steps, samples_from_runs, speed_factor, speed_ratio)
from orchestrator.runner import run_case
from orchestrator.scenes.triaxial import stage1_problems
from engines.base import UnsupportedFeature

HERE = Path(__file__).resolve().parent


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="*", help="run directories or runs/ trees")
    ap.add_argument("--run", action="append", default=[], help="case file to run first (repeatable)")
    ap.add_argument("--engine", action="append", help="engines for --run (default the case's)")
    a = ap.parse_args(argv)
    roots = [Path(r) for r in a.runs]
    if a.run:
        root = HERE / "runs-estimate"
        for path in a.run:
            case = load_case(path)
            for eng in a.engine or case.engines:
                try:
                    out = run_case(case, eng, runs_root=root, progress=False, analyze=False)
                except UnsupportedFeature as exc:           # --engine names one that cannot run this scene
                    print(f"{case.name} {eng}: skipped ({exc})")
                    continue
                print(f"{case.name} {eng}: {out.status} ({'reused' if out.reused else 'ran'})")
        roots.append(root)
    samples = samples_from_runs(roots)
    if not samples:
        raise SystemExit(f"no complete run (a directory with summary.json) under {', '.join(map(str, roots))}; "
                         "give run directories or runs/ trees, or --run CASE")
    table = load_table()
    print(f"{'engine':9s} {'scene':12s} {'n':>6s} {'steps':>9s} {'expected':>9s} {'w':>2s} {'actual s':>9s} "
          f"{'ms/step':>8s} {'start s':>7s} {'table s':>9s} {'ratio':>6s} {'loo s':>9s} {'ratio':>6s} {'machine':>7s} {'load':>9s}  run")
    package = _package()
    ratio_of = {s.source: speed_ratio(s, package) for s in samples}     # each run's speed, read once
    worst = worst_quiet = None
    machine_err = {"all": None, "kept": None}   # the machine column's largest error: every run; quiet, on-plan runs
    for s in samples:
        # what `run --dry-run` printed before the run: the step budget, or where the scene decides its
        # step count while it runs (triaxial stage 1), the steps the engine's measured runs took
        budget = s.plan.steps(s.plan.max_units) if s.plan is not None else s.steps
        est, _ = estimate_engine_time(s.engine, s.scene, s.n_particles, budget, s.ranks, table=table, plan=s.plan)
        others = [o for o in samples if (o.engine, o.scene) == (s.engine, s.scene) and o.source != s.source]
        tp = fit(others) if others else None
        loo = tp.engine_time(s.n_particles, expected_steps(budget, s.plan, tp), s.ranks) if tp else math.nan
        r1 = est / s.engine_s if est == est else math.nan
        r2 = loo / s.engine_s if loo == loo else math.nan
        mf = speed_factor([(o.scene, o.n_particles, ratio_of[o.source], o.quiet, o.ranks) for o in samples
                           if o.engine == s.engine and o.source != s.source], s.scene, s.n_particles, s.ranks)
        pk, _ = estimate_engine_time(s.engine, s.scene, s.n_particles, budget, s.ranks, table=package, plan=s.plan)
        # a package entry fitted on this machine is this machine's speed already (the dry run does not
        # scale it, clock.estimate_engine_time): scaled again it would say nothing, and unscaled it
        # is the run predicting itself where the entry was fitted on it ("n/a")
        r3 = (mf[0] * pk / s.engine_s if mf and pk == pk and not fitted_here(package.get(s.engine, {}), s.scene)
              else math.nan)
        if r2 == r2:
            worst = max(worst or 0.0, abs(r2 - 1))
            if not s.shared:
                worst_quiet = max(worst_quiet or 0.0, abs(r2 - 1))
        # a run that left its scene's step plan (a triaxial whose stage 1 ran out of chunks unconverged
        # and skipped the drag ramp): the estimate is for a run that follows it
        off_plan = base_kind(s.scene) == "triaxial" and bool(stage1_problems(Path(s.source)))
        if r3 == r3:
            machine_err["all"] = max(machine_err["all"] or 0.0, abs(r3 - 1))
            if not (s.shared or off_plan):
                machine_err["kept"] = max(machine_err["kept"] or 0.0, abs(r3 - 1))
        load = "-" if s.load is None else f"{s.load:.1f}/{s.cores}"
        # the steps the table expects this run to take (the plan's units: clock refresh --steps-only),
        # as the dry run counts them (a variant without its own entry: the engine that ran it)
        expected, _ = planned_steps(table, s.engine, s.scene, budget, s.plan)
        print(f"{s.engine:9s} {s.scene:12s} {s.n_particles:6d} {s.steps:9d} {expected:9d} {s.ranks:2d} {s.engine_s:9.1f} "
              f"{1e3 * s.loop_s / s.steps:8.3f} {s.engine_s - s.loop_s:7.1f} {est:9.1f} {r1:6.2f} {loo:9.1f} {r2:6.2f} {r3:7.2f} {load:>9s}  {Path(s.source).name}"
              + ("  shared" if s.shared else "") + ("  off-plan" if off_plan else ""))
    print("largest leave-one-out error: " + (f"{100 * worst:.0f} % (floor: 30 %)" if worst is not None
          else "n/a (no run has another of its engine and scene to be predicted from)"))
    if worst_quiet is not None and worst_quiet != worst:
        print(f"largest leave-one-out error, runs that did not share the machine: {100 * worst_quiet:.0f} %")
    if machine_err["all"] is not None:
        print(f"largest machine-column error: {100 * machine_err['all']:.0f} % (floor: 30 %)"
              + (f"; runs that neither shared the machine nor left their step plan: {100 * machine_err['kept']:.0f} %"
                 if machine_err["kept"] is not None and machine_err["kept"] != machine_err["all"] else ""))
    return 0


def _package() -> dict:
    """The shipped table alone (what this machine's speed is measured against)."""
    from orchestrator.clock import _as_throughputs, _package_table
    return _as_throughputs(_package_table())


if __name__ == "__main__":
    raise SystemExit(main())
