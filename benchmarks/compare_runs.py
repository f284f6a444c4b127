"""Two runs of one case side by side (issue #16: does a deck change alter the physics, is a resumed
run equal to an uninterrupted one?): frames at the same steps, the largest grain-position
difference per frame in units of the smallest radius, the wall series (same times, largest
difference), and the scalars a deck change must keep: the friction analysis' mu_mean, the servo
check's mean force, the servo wall's travel.

    .venv/bin/python benchmarks/compare_runs.py RUN_A RUN_B

RUN_A/B: complete run directories (frames.h5). Prints a table; exit 0.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from orchestrator.frames import Frames


def _scalars(run: Path, f: Frames) -> dict:
    out = {}
    s = json.loads((run / "summary.json").read_text())
    fr = s.get("analysis", {}).get("friction", {}).get("scalars", {})
    if "mu_mean" in fr:
        out["mu_mean"] = fr["mu_mean"]
    for name in ("shear_cell_checks.json", "plane_shear_checks.json"):
        if (run / name).exists():
            c = json.loads((run / name).read_text()).get("compression", {})
            if "mean_force" in c:
                out["servo mean force [N]"] = c["mean_force"]
    for wall, w in f.walls.items():
        if "position_z" in w and len(w):
            z = np.asarray(w["position_z"], dtype=float)
            out[f"{wall} z travel [m]"] = float(z[-1] - z[0])
        if {"force_x", "force_z"} <= set(w.columns) and len(w) > 4:
            late = w.iloc[-len(w) // 4:]                  # the last quarter of the series (shear)
            fz = np.abs(np.asarray(late["force_z"], dtype=float))
            if np.all(fz > 0):
                out[f"{wall} |Fx|/|Fz|, last quarter"] = float(np.mean(np.abs(late["force_x"]) / fz))
    return out


def compare(a: Path, b: Path) -> dict:
    fa, fb = Frames(a), Frames(b)
    r_min = float(fa.radius.min())
    res = {"steps_equal": list(fa.step) == list(fb.step), "frames": (len(fa.step), len(fb.step)), "per_frame": []}
    if res["steps_equal"]:
        for k, s in enumerate(fa.step):
            d = float(np.nanmax(np.abs(fa.position[k] - fb.position[k]))) / r_min
            res["per_frame"].append((int(s), d))
    res["walls"] = {}
    for name in fa.walls:
        wa, wb = fa.wall(name), fb.wall(name)
        same_t = len(wa) == len(wb) and np.array_equal(np.asarray(wa["time"]), np.asarray(wb["time"]))
        diff = float(np.nanmax(np.abs(wa.to_numpy() - wb.to_numpy()))) if same_t else float("nan")
        res["walls"][name] = (len(wa), len(wb), same_t, diff)
    res["scalars"] = (_scalars(a, fa), _scalars(b, fb))
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("a")
    ap.add_argument("b")
    args = ap.parse_args()
    r = compare(Path(args.a), Path(args.b))
    print(f"frames: {r['frames'][0]} / {r['frames'][1]}, same steps: {r['steps_equal']}")
    for s, d in r["per_frame"]:
        print(f"  step {s:>9d}: max |dx| = {d:.3g} r_min")
    for name, (na, nb, same, diff) in r["walls"].items():
        print(f"wall {name}: rows {na} / {nb}, same times: {same}, largest difference {diff:.3g}")
    sa, sb = r["scalars"]
    for k in sa:
        if k in sb:
            rel = (sb[k] - sa[k]) / abs(sa[k]) if sa[k] else float("nan")
            print(f"{k}: {sa[k]:.6g} / {sb[k]:.6g} (relative difference {rel:+.3g})")


if __name__ == "__main__":
    main()
