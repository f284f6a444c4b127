"""Benchmark (not a test) for issue #17 item 6: where the LIGGGHTS decks lose against a bare run.

For each case (default: the small shear cell and the small triaxial) the LIGGGHTS deck is rendered as
the orchestrator renders it (into a temporary directory; templates are not touched) and cut at its
first production ``run`` (shear cell: the relax stage from the sampled particles; triaxial: stage 1
from the packed sample). Each variant is that deck with one ingredient removed or changed
(rendered copies, edited as text):

- ``deck``: as rendered; the timed steps run with the deck's ``every M "<monitor commands>"``
  chunking, so a chunk's set-up (neighbour lists, mesh and fix set-up) is paid as in a real run;
- ``-monitors``: plain ``run`` (no chunks, no stability monitor commands);
- ``-outputs``: no dumps, no ``fix ave/time``/``print`` series, no per-atom stress compute;
- ``-walls``: no mesh walls (``fix mesh/surface*``, ``wall/gran``, ``move/mesh``) and what reads them;
  grains leaving the box are dropped (``thermo_modify lost ignore``);
- ``-cohesion/rolling``: ``pair_style gran model hertz tangential history`` (the chain LIGGGHTS
  whitelists; any other prints "not in whitelist" and takes a generic, slower path);
- ``-limitForce``: the same pair style without ``limitForce on``;
- ``skin/2``, ``skin/4``, ``skin x2``: the neighbour skin scaled;
- triaxial only: ``-shell`` (the shell-pressure substitute's 64-cell reductions and per-atom force
  variables: its ``store/state`` every 20 steps and the ``addforce``), ``-drag`` (stage 1's
  per-atom drag variables, evaluated every step);
- ``-cylinder``, ``-pistons``: only those mesh walls removed;
- ``shell every 100``: the shell-pressure update every 100 steps instead of 20;
- triaxial only: ``-servo`` (the top platen's speed a constant instead of the servo chain, which
  ``move/mesh`` and the speed samples evaluate every step), ``-shell-drag-servo`` (all three);
- ``bare+gravity``: ``bare`` with the deck's gravity (falling grains rebuild their neighbour lists);
- ``bare``: the same particles (``particles.data``), materials, time step, neighbour settings and
  Hertz-Mindlin contact law, ``nve/sphere``, nothing else.

Timing: the cost of the timed ``--steps`` (rounded up to whole monitor chunks) is the CPU time of a
run of warm-up + timed steps minus that of a run of the warm-up alone (both whole processes:
start-up cancels; one thread each); steps/s and the ratio to ``bare`` are printed, with LIGGGHTS'
own "Loop time" of the timed segment (set-up between chunks excluded) beside it. ``--mpi``: the deck
and bare on 1 and 2 MPI ranks (``mpirun.openmpi -np 2``, wall time: CPU time would add the ranks),
speed-up 2 ranks / 1 rank (floor 1.7); launched as the adapter launches it. The machine is shared: ``uptime`` is printed before and
after; repeat when it is quiet.

The initial states are the decks' own: the shear cell's grains are still falling in its first
steps (few contacts), the triaxial's packed sample is dense.

Run: ``.venv/bin/python benchmarks/bench_liggghts_speed.py [--steps 6000] [--warm 1000] [--mpi]
[--only deck,bare] [CASE ...]``
"""
from __future__ import annotations

import argparse
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
CASES = ["shear_cell_small.yaml", "triaxial_small.yaml"]

_RUN = re.compile(r"^run\s+([1-9]\d*)(\s+upto)?(\s+every\s+(\d+)\s+(.*))?$")


def render(case_file: str, run_dir: Path) -> Path:
    from orchestrator.case import load_case
    from orchestrator.runner import prepare
    from engines import get_engine
    case = load_case(REPO / "cases" / case_file)
    params, _ = prepare(case, "liggghts", run_dir)
    return get_engine("liggghts").render(case, params, run_dir, resume=None)


_IF = re.compile(r'^if\s+"([^"]*)"\s+then\s+(.*)$')
_CONST = re.compile(r"^variable\s+(\w+)\s+equal\s+(-?[0-9.eE+-]+)\s*$")


def _fresh_branch(line: str, const: dict[str, str]) -> list[str] | None:
    """The commands an ``if "COND" then "A" ... [else "B" ...]`` line runs on a fresh start (COND read
    with the deck's constant stage variables), or None when COND reads anything else."""
    m = _IF.match(line)
    if not m:
        return None
    cond = re.sub(r"\$\{(\w+)\}", lambda v: const.get(v.group(1), "?"), m.group(1))
    if not re.fullmatch(r"[-0-9.eE\s=<>!&|()]*", cond):      # only numbers and comparisons are read
        return None
    branches = re.split(r"\s+else\s+", m.group(2), maxsplit=1)
    taken = branches[0] if eval(cond.replace("&&", " and ").replace("||", " or "), {}) else \
        (branches[1] if len(branches) > 1 else "")
    return re.findall(r'"([^"]*)"', taken)


def linearize(lines: list[str]) -> list[str]:
    """A segmented deck (``label segment`` ... ``jump SELF segment``, restart files between segments) as
    the straight-line deck of its first segment from a fresh start: the stage variables' ``if`` lines
    resolved with their initial values (``read_data``, stage 1's friction and drag), the control flow
    (``label``, ``jump``, ``clear``) dropped. A deck without segments comes back unchanged."""
    if not any(re.match(r"^label\s+segment\b", ln) for ln in lines):
        return lines
    const: dict[str, str] = {}
    for ln in lines:
        if re.match(r"^label\s+segment\b", ln):
            break
        m = _CONST.match(ln)
        if m:
            const[m.group(1)] = m.group(2)
    const.setdefault("stp", "0")            # variable stp equal step: 0 at the first segment's start
    out = []
    for ln in lines:
        if re.match(r"^(label|jump|clear)\b", ln):
            continue
        taken = _fresh_branch(ln, const)
        if taken is None:
            out.append(ln)
        else:
            out += [c for c in taken if not c.startswith("jump")]
    return out


def cut(lines: list[str]) -> tuple[list[str], int, str]:
    """The deck before its first production run, that run's chunk length and its monitor clause
    (a segmented deck is first made straight: ``linearize``)."""
    lines = linearize(lines)
    k = next(i for i, ln in enumerate(lines) if _RUN.match(ln))
    m = _RUN.match(lines[k])
    every = int(m.group(4)) if m.group(4) else 0
    return lines[:k], every, (m.group(5) or "")


# --- variants: functions of (head lines) -> head lines; None: not applicable ------------------------

def _drop(lines, *patterns):
    rx = [re.compile(p) for p in patterns]
    return [ln for ln in lines if not any(r.search(ln) for r in rx)]


def _sub(lines, pattern, repl):
    return [re.sub(pattern, repl, ln) for ln in lines]


def no_outputs(lines):
    """No dumps, no series written to files, no per-atom stress, no restart files."""
    lines = _drop(lines, r"^dump\s", r"^dump_modify\s", r"^undump\s", r"^fix\s+\S+\s+all\s+ave/time\s.*\sfile\s",
                  r"^fix\s+\S+\s+all\s+print\s", r"^compute\s+pstress\s", r"^restart\s+[1-9]",
                  r"^write_restart\s", r"^print\s.*append")
    return lines


def _drop_refs(lines, pattern):
    """Drop the lines matching ``pattern``; a dropped ``variable NAME ...`` becomes NAME = 0.0 (what
    reads it still runs)."""
    rx = re.compile(pattern)
    out = []
    for ln in lines:
        if rx.search(ln):
            m = re.match(r"^variable\s+(\S+)\s+equal\s", ln)
            if m:
                out.append(f"variable {m.group(1)} equal 0.0")
            continue
        out.append(ln)
    return out


def no_walls(lines):
    walls = [ln.split()[1] for ln in lines if re.match(r"^fix\s+\S+\s+all\s+mesh/surface", ln)]
    if not walls:
        return None
    refs = "|".join(re.escape(w) for w in walls)
    lines = _drop(lines, r"^fix\s+\S+\s+all\s+mesh/surface", r"wall/gran", r"move/mesh",
                  rf"^fix_modify\s+({refs})\s")
    lines = _drop_refs(lines, rf"\bf_({refs})\[")          # wall forces read by variables and series
    # monitors reading a wall force: their variables are gone; the deck's own monitor clause
    # keeps only its wall-free commands (see monitors())
    lines = _sub(lines, r"^(thermo_modify\s.*lost\s+)error", r"\1ignore")
    return lines + ["variable ORCH_w equal 0.0", "variable ORCH_wabs equal 0.0", "variable ORCH_wsw equal 0.0"]


def walls_subset(which):
    """Remove only the named mesh walls (the others stay), with what reads them."""
    def f(lines):
        walls = [ln.split()[1] for ln in lines if re.match(r"^fix\s+\S+\s+all\s+mesh/surface", ln)]
        gone = [w for w in walls if w in which]
        if not gone or len(gone) == len(walls):
            return None
        keep = [w for w in walls if w not in gone]
        refs = "|".join(re.escape(w) for w in gone)
        out = _drop(lines, rf"^fix\s+({refs})\s", rf"^fix_modify\s+({refs})\s", rf"move/mesh\s+mesh\s+({refs})\b")
        out = _drop_refs(out, rf"\bf_({refs})\[")
        out = [re.sub(r"n_meshes\s+\d+\s+meshes\s+.*?(\s+limitForce|$)",
                      lambda m: f"n_meshes {len(keep)} meshes {' '.join(keep)}{m.group(1)}", ln)
               if "wall/gran" in ln else ln for ln in out]
        out = _sub(out, r"^(thermo_modify\s.*lost\s+)error", r"\1ignore")
        defined = set(re.findall(r"^variable\s+(\S+)", "\n".join(out), re.M))
        return out + [f"variable {v} equal 0.0" for v in ("ORCH_w", "ORCH_wabs", "ORCH_wsw") if v not in defined]
    return f


def plain_hertz(lines):
    return _sub(lines, r"^pair_style\s+gran\s+model\s+hertz\s+tangential\s+history.*$",
                "pair_style      gran model hertz tangential history")


def no_limit_force(lines):
    return _sub(lines, r"^(pair_style\s+gran.*?)\s+limitForce\s+on", r"\1")


def skin(factor):
    def f(lines):
        return [re.sub(r"^neighbor\s+(\S+)", lambda m: f"neighbor        {float(m.group(1)) * factor!r}", ln)
                for ln in lines]
    return f


def no_shell(lines):
    if not any(re.match(r"^fix\s+st\s+all\s+store/state", ln) for ln in lines):
        return None
    # the shell updates every 20 steps -> never within the run (same fixes, same variables)
    lines = _sub(lines, r"^(fix\s+(cs|sel|st)\s+all\s+store/state)\s+20\s", r"\1 100000000 ")
    return _drop(lines, r"^fix\s+press\s")


def shell_every(n):
    """The shell-pressure update every ``n`` steps instead of the rendered 20."""
    def f(lines):
        if not any(re.match(r"^fix\s+st\s+all\s+store/state", ln) for ln in lines):
            return None
        return _sub(lines, r"^(fix\s+(cs|sel|st)\s+all\s+store/state)\s+\d+\s", rf"\1 {n} ")
    return f


def no_drag(lines):
    if not any(re.match(r"^fix\s+drag\s", ln) for ln in lines):
        return None
    return _drop(lines, r"^fix\s+drag\s")


def no_servo(lines):
    """The top platen's speed a constant: the servo chain behind ``v_vtop`` (platen force, boundary
    volume and height, pressure ramp: equal-style variables LIGGGHTS parses at every evaluation) is
    not evaluated by ``move/mesh`` and the speed samples."""
    if not any(re.match(r"^variable\s+vtop\s", ln) for ln in lines):
        return None
    return [("variable vtop  equal 0.0" if re.match(r"^variable\s+vtop\s", ln) else ln) for ln in lines]


def bare(lines, gravity=False):
    """Same particles, materials, time step, neighbour settings and Hertz-Mindlin law; nothing else
    (``gravity``: and the deck's gravity, which makes the falling grains rebuild neighbour lists)."""
    keep = []
    for ln in lines:
        if re.match(r"^(atom_style|atom_modify|boundary|newton|communicate|units|processors|read_data|neighbor|"
                    r"neigh_modify|hard_particles|timestep)\s", ln):
            keep.append(ln)
        elif re.match(r"^fix\s+m_(E|nu|e|mu)\s", ln):
            keep.append(ln)
        elif re.match(r"^unfix\s+m_mu", ln):
            keep.append(ln)
    keep += ["pair_style      gran model hertz tangential history", "pair_coeff      * *",
             *[ln for ln in lines if gravity and re.match(r"^fix\s+\S+\s+all\s+gravity\s", ln)],
             "fix integrate all nve/sphere", "thermo_style custom step atoms ke", "thermo 1000",
             "thermo_modify   norm no lost ignore"]
    return keep


VARIANTS = {
    "deck": lambda ln: ln,
    "-monitors": "monitors",
    "-outputs": no_outputs,
    "-walls": no_walls,
    "-cylinder": walls_subset({"cyl"}),
    "-pistons": walls_subset({"upper", "lower", "bot", "top"}),
    "-cohesion/rolling": plain_hertz,
    "-limitForce": no_limit_force,
    "skin/2": skin(0.5),
    "skin/4": skin(0.25),
    "skin x2": skin(2.0),
    "-shell": no_shell,
    "shell every 100": shell_every(100),
    "-drag": no_drag,
    "-shell-drag": lambda ln: no_drag(no_shell(ln)) if no_shell(ln) is not None else None,
    "-servo": no_servo,
    "-shell-drag-servo": lambda ln: no_servo(no_drag(no_shell(ln))) if no_shell(ln) is not None else None,
    "bare+gravity": lambda ln: bare(ln, gravity=True),
    "bare": bare,
}


def _monitor_clause(clause: str, lines: list[str]) -> str:
    """The monitor clause without commands that read variables the variant deleted."""
    defined = set(re.findall(r"^variable\s+(\S+)", "\n".join(lines), re.M))
    cmds = re.findall(r'"([^"]*)"', clause)
    ok = [c for c in cmds if all(v in defined for v in re.findall(r"\$\{(\w+)\}", c))]
    return " ".join(f'"{c}"' for c in ok)


def deck_text(head, every, clause, name, variant, warm, steps):
    chunked = name not in ("-monitors", "bare", "bare+gravity") and every > 0
    lines = head if variant == "monitors" else variant(list(head))
    if lines is None:
        return None
    if chunked:
        mon = _monitor_clause(clause, lines)
        timed = f"run {steps} every {every} {mon}" if mon else f"run {steps} every {every} \"print ORCH_CHUNK\""
    else:
        timed = f"run {steps}"
    warm_only = "\n".join(lines + [f"run {warm}"]) + "\n"
    full = "\n".join(lines + [f"run {warm}", timed]) + "\n"
    return warm_only, full


def run_one(path: Path, ranks: int = 1) -> dict:
    cmd = ["liggghts", "-in", path.name, "-echo", "none", "-log", "none"]
    if ranks > 1:
        from engines.liggghts.adapter import openmpi_launcher      # as the adapter runs it
        cmd = [openmpi_launcher(), "--allow-run-as-root", "--oversubscribe", "-np", str(ranks)] + cmd
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    pr = subprocess.run(cmd, cwd=path.parent, capture_output=True, text=True, errors="replace",
                        env=dict(os.environ, OMP_NUM_THREADS="1"))
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if pr.returncode != 0 or "ERROR" in pr.stdout:
        err = [ln for ln in (pr.stdout + pr.stderr).splitlines() if "ERROR" in ln][:1]
        return {"error": (err[0] if err else f"exit {pr.returncode}")[:120]}
    loops = [(float(t), int(n)) for t, n in
             re.findall(r"Loop time of ([0-9.eE+-]+) on \d+ procs for (\d+) steps", pr.stdout)]
    warn = "whitelist" in pr.stdout
    parts = {k: [float(v) for v in re.findall(rf"^{k}\s+time \(%\) = ([0-9.eE+-]+)", pr.stdout, re.M)]
             for k in ("Pair", "Neigh", "Comm", "Outpt", "Other")}
    builds = [int(v) for v in re.findall(r"Neighbor list builds = (\d+)", pr.stdout)]
    return {"cpu": cpu, "wall": wall, "loops": loops, "whitelist": warn, "parts": parts, "builds": builds}


def measure(workdir: Path, name: str, texts, steps: int, warm: int, ranks: int = 1) -> dict:
    warm_only, full = texts
    tag = re.sub(r"\W", "_", name)
    a, b = workdir / f"bench_{tag}_warm.in", workdir / f"bench_{tag}_full.in"
    a.write_text(warm_only)
    b.write_text(full)
    ra, rb = run_one(a, ranks), run_one(b, ranks)
    if "error" in ra or "error" in rb:
        return {"error": ra.get("error") or rb.get("error")}
    # Loop times after the warm-up run(s): the timed segment's chunks
    nwarm = len(ra["loops"])
    timed = rb["loops"][nwarm:]
    loop = sum(t for t, _ in timed)
    nsteps = sum(n for _, n in timed)
    # zero-step runs print no breakdown: the timed segment's chunks are the last ones
    nt = len(timed)
    share = {k: sum(v[-nt:]) / loop if loop > 0 and nt else float("nan") for k, v in rb["parts"].items()}
    builds = sum(rb["builds"][-nt:]) if nt else 0
    cost = rb["cpu"] - ra["cpu"]
    wcost = rb["wall"] - ra["wall"]
    return {"steps": nsteps, "rate": nsteps / cost if cost > 0 else float("nan"),
            "rate_wall": nsteps / wcost if wcost > 0 else float("nan"),
            "rate_loop": nsteps / loop if loop > 0 else float("nan"), "whitelist": rb["whitelist"],
            "share": share, "builds": builds}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("cases", nargs="*", default=CASES, help="case files under cases/")
    ap.add_argument("--steps", type=int, default=6000, help="timed steps (rounded up to whole monitor chunks)")
    ap.add_argument("--warm", type=int, default=1000)
    ap.add_argument("--mpi", action="store_true", help="also deck and bare on 2 MPI ranks vs 1 (wall time)")
    ap.add_argument("--only", default="", help="comma-separated variant names")
    a = ap.parse_args(argv)
    only = set(a.only.split(",")) if a.only else None
    print("load before:", os.getloadavg(), flush=True)
    for case_file in a.cases:
        with tempfile.TemporaryDirectory(prefix="bench_lig_") as tmp:
            deck = render(case_file, Path(tmp) / "run")
            head, every, clause = cut(deck.read_text().splitlines())
            steps = -(-a.steps // every) * every if every else a.steps
            natoms = int(re.search(r"^(\d+)\s+atoms", (deck.parent / "particles.data").read_text(), re.M).group(1))
            print(f"\n{Path(case_file).stem}: {natoms} grains, {a.warm} warm-up + {steps} timed steps "
                  f"(monitor chunks of {every})", flush=True)
            rows = {}
            for name, variant in VARIANTS.items():
                if only and name not in only:
                    continue
                texts = deck_text(head, every, clause, name, variant, a.warm, steps)
                if texts is None:
                    continue
                r = measure(deck.parent, name, texts, steps, a.warm)
                rows[name] = r
                if "error" in r:
                    print(f"  {name:18s} error: {r['error']}", flush=True)
                else:
                    sh = r["share"]
                    print(f"  {name:18s} {r['rate']:9.0f} steps/s CPU  ({r['rate_loop']:9.0f} loop time)  loop: pair "
                          f"{sh['Pair']:.0%} neigh {sh['Neigh']:.0%} other (fixes) {sh['Other']:.0%}, "
                          f"{r['builds']} neighbour builds{'  [whitelist warning]' if r['whitelist'] else ''}",
                          flush=True)
            b = rows.get("bare", {}).get("rate")
            print(f"\n  {'variant':18s} {'steps/s':>9s} {'particle-steps/s':>17s} {'/ bare':>7s} {'/ deck':>7s}")
            d = rows.get("deck", {}).get("rate")
            for name, r in rows.items():
                if "error" in r:
                    continue
                print(f"  {name:18s} {r['rate']:9.0f} {r['rate'] * natoms:17.3g} "
                      f"{r['rate'] / b if b else float('nan'):7.3f} {r['rate'] / d if d else float('nan'):7.3f}")
            if a.mpi:
                for name in ("deck", "bare"):
                    texts = deck_text(head, every, clause, name, VARIANTS[name], a.warm, steps)
                    one = measure(deck.parent, name + "_np1", texts, steps, a.warm, ranks=1)
                    two = measure(deck.parent, name + "_np2", texts, steps, a.warm, ranks=2)
                    if "error" in one or "error" in two:
                        print(f"  MPI {name}: error {one.get('error') or two.get('error')}")
                        continue
                    print(f"  MPI {name}: 2 ranks / 1 rank = {two['rate_loop'] / one['rate_loop']:.2f} (loop time), "
                          f"{two['rate_wall'] / one['rate_wall']:.2f} (wall, start-up cancelled); floor 1.7", flush=True)
    print("\nload after:", os.getloadavg())


if __name__ == "__main__":
    main()
