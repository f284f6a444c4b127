"""Benchmark (not a test): a shear cell's frictionless sidewall on LIGGGHTS, the analytic cylinder
against the 720-triangle mesh it replaced (session 25), whole runs.

    .venv/bin/python benchmarks/bench_sidewall.py [CASE] [--ranks N]

Renders the case's LIGGGHTS deck as the orchestrator does (default ``shear_cell_default.yaml``, the
README's case; a frictionless sidewall renders as ``fix wall/gran ... primitive ... zcylinder``) into a
temporary directory, makes the mesh variant of it as text (``fix mesh/surface/stress`` of
``cylinder.stl`` in the walls' ``wall/gran``, turned by ``move/mesh`` in the shear stage: the deck of
before), runs both whole, one after the other, on the case's MPI ranks as the adapter launches them,
and prints the wall and CPU times, their ratio and the final piston height of each (the same cell
to within the packing's response: the mesh's flat faces sit 0.1 % of the radius inside the circle).
Run it on a quiet machine: two ranks beside another process wait on each other.
"""
from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

from bench_liggghts_speed import render, run_one      # noqa: E402  (the same rendering and launch)


def mesh_variant(deck: str) -> str:
    """The deck with its analytic sidewall replaced by the cylinder mesh (rotating in the shear stage)."""
    out = []
    for line in deck.splitlines():
        if line.startswith(("fix cylw ", "variable cylTz ")):
            continue
        if line.startswith("fix upper "):          # the mesh is defined before the walls' wall/gran reads it
            out.append("fix cyl   all mesh/surface/stress file cylinder.stl type 2 reference_point 0.0 0.0 0.0")
        if line.startswith("fix walls ") and "n_meshes 2 meshes upper lower" in line:
            line = line.replace("n_meshes 2 meshes upper lower", "n_meshes 3 meshes cyl upper lower")
        line = line.replace("v_cylTz", "f_cyl[6]")
        m = re.match(r"fix rot_up\s+all move/mesh mesh upper (rotate .*)$", line)
        if m:
            out.append(f"fix rot_cyl all move/mesh mesh cyl {m.group(1)}")
        out.append(line)
    return "\n".join(out) + "\n"


def final_piston_z(run_dir: Path) -> float | None:
    """The lower piston's last sampled height [m] (the walls.*.txt series, column z_lower)."""
    files = sorted(run_dir.glob("walls.*.txt"))
    for f in reversed(files):
        rows = [ln.split() for ln in f.read_text().splitlines() if ln and not ln.startswith("#")]
        if rows:
            return float(rows[-1][1])
    return None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", nargs="?", default="shear_cell_default.yaml", help="a case file under cases/")
    ap.add_argument("--ranks", type=int, default=None, help="MPI ranks (default: the case's)")
    a = ap.parse_args(argv)
    from orchestrator.case import load_case
    ranks = a.ranks or load_case(REPO / "cases" / a.case).engine_options.mpi_ranks
    print("uptime:", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
    with tempfile.TemporaryDirectory(prefix="bench_sidewall_") as tmp:
        results = {}
        for variant in ("analytic", "mesh"):
            d = Path(tmp) / variant
            d.mkdir()
            deck = render(a.case, d)
            text = deck.read_text()
            if "primitive type 2 zcylinder" not in text:
                print(f"{a.case}: its sidewall is not the analytic cylinder (wall friction?): nothing to compare")
                return 2
            if variant == "mesh":
                deck.write_text(mesh_variant(text))
            r = run_one(deck, ranks)
            if "error" in r:
                print(f"{variant}: {r['error']}")
                return 1
            r["piston"] = final_piston_z(d)
            results[variant] = r
            print(f"{variant:9s} wall {r['wall']:8.1f} s   CPU {r['cpu']:8.1f} s   final piston z "
                  f"{r['piston'] * 1e6:.1f} µm", flush=True)
        an, me = results["analytic"], results["mesh"]
        print(f"mesh / analytic: wall {me['wall'] / an['wall']:.2f}x, CPU {me['cpu'] / an['cpu']:.2f}x "
              f"({ranks} rank(s)); piston heights differ by {abs(me['piston'] - an['piston']) * 1e6:.1f} µm")
        print("uptime:", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
    return 0


if __name__ == "__main__":
    sys.exit(main())
