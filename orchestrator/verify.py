"""Contact-level verification after Chung & Ooi (2011, Granular Matter 13, 643-656), tests 1-4.

Each case under ``cases/verification/`` runs through the normal pipeline (case → derived
parameters → templates → engine → frames.h5); :func:`impact_metrics` measures from the frames
the contact time, the largest overlap, the peak force and the normal and tangential restitution
of every impact, and :func:`verification_table` sets them beside the analytic values:

- elastic Hertz (``derive.hertz_*``): contact time, largest overlap, peak force, when e_n = 1;
- the requested normal restitution e_n;
- the rigid-body sliding limit e_t = 1 − μ(1+e_n)/tan θ above the sliding threshold
  tan θ > 7/2 μ (1+e_n) (sphere centre velocity).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pandas as pd

from .case import load_case
from .derive import (hertz_contact_time, hertz_max_overlap, hertz_peak_force,
                     sliding_limit_tangential_restitution, sliding_threshold_angle)
from .frames import Frames
from .registry import engine_names
from .runner import run_case

REPO = Path(__file__).resolve().parents[1]
VERIFICATION_DIR = REPO / "cases" / "verification"

#: tolerances asserted by the tests and flagged by ``orchestrator verify`` (issue #2)
TOLERANCE = {"contact_time": 0.01, "peak_force": 0.01, "max_overlap": 0.01, "e_n": 0.01, "e_t": 0.02}


def _crossings(t: np.ndarray, d: np.ndarray) -> tuple[float, float]:
    """First rise of d above 0 and the following fall below 0, linearly interpolated [s]."""
    inside = d > 0
    if not inside.any():
        return np.nan, np.nan
    k0 = int(np.argmax(inside))
    after = np.nonzero(~inside[k0:])[0]
    k1 = k0 + int(after[0]) if len(after) else len(d) - 1
    def cross(a, b):
        if a < 0 or d[b] == d[a]:
            return t[b]
        return t[a] + (t[b] - t[a]) * (0 - d[a]) / (d[b] - d[a])
    return cross(k0 - 1, k0), cross(k1 - 1, k1)


def impact_metrics(frames, params: dict) -> pd.DataFrame:
    """One row per impact: measured contact time [s], largest overlap [m], peak normal force [N],
    e_n and e_t [-], and the analytic values for the case's parameters."""
    sc = params["scene"]
    R = sc["radius"]
    m = sc["mass"]
    t = frames.time
    x = frames.position
    v = frames.velocity
    f = frames.force if "force" in frames.fields else None
    e_req = params["restitution"]["target"]
    mu = params["friction"]
    rows = []
    if sc["target"] == "sphere":
        d = x[:, 1] - x[:, 0]
        dist = np.linalg.norm(d, axis=1)
        overlap = 2 * R - dist
        n0 = d[0] / dist[0]
        vrel = v[:, 0] - v[:, 1]
        vn_in, vn_out = vrel[0] @ n0, vrel[-1] @ n0
        t0, t1 = _crossings(t, overlap)
        F = np.abs(f[:, 0] @ n0).max() if f is not None else np.nan   # normal component
        m_eff, R_eff, E_eff, speed = m / 2, R / 2, params["E_eff_pp"], abs(vn_in)
        rows.append(_row("sphere-sphere", 0.0, t1 - t0, overlap.max(), F, -vn_out / vn_in, np.nan,
                         m_eff, R_eff, E_eff, speed, e_req, mu))
    else:
        for k, ang in enumerate(sc["angles"]):
            overlap = R - x[:, k, 2]
            vn_in, vn_out = -v[0, k, 2], v[-1, k, 2]
            vt_in, vt_out = v[0, k, 0], v[-1, k, 0]
            t0, t1 = _crossings(t, overlap)
            F = np.abs(f[:, k, 2]).max() if f is not None else np.nan   # normal (z) component
            e_t = vt_out / vt_in if abs(vt_in) > 1e-12 else np.nan
            rows.append(_row("sphere-plane", ang, t1 - t0, overlap.max(), F, vn_out / vn_in, e_t,
                             m, R, params["E_eff_pw"], vn_in, e_req, mu))
    return pd.DataFrame(rows)


def _row(kind, ang, tc, dmax, F, e_n, e_t, m_eff, R_eff, E_eff, vn, e_req, mu):
    elastic = e_req >= 1.0
    sliding = ang > sliding_threshold_angle(mu, e_req) if mu > 0 else False
    return {
        "impact": kind, "angle_deg": np.degrees(ang),
        "contact_time": tc, "contact_time_hertz": hertz_contact_time(m_eff, R_eff, E_eff, vn) if elastic else np.nan,
        "max_overlap": dmax, "max_overlap_hertz": hertz_max_overlap(m_eff, R_eff, E_eff, vn) if elastic else np.nan,
        "peak_force": F, "peak_force_hertz": hertz_peak_force(m_eff, R_eff, E_eff, vn) if elastic else np.nan,
        "e_n": e_n, "e_n_requested": e_req,
        "e_t": e_t, "e_t_sliding_limit": sliding_limit_tangential_restitution(ang, mu, e_req) if sliding else np.nan,
    }


def verification_table(metrics: pd.DataFrame, engine: str, case: str, wall_time: float) -> pd.DataFrame:
    """Long table: case, engine, quantity, analytic, engine value, relative error, tolerance, pass."""
    pairs = [("contact_time", "contact_time_hertz"), ("max_overlap", "max_overlap_hertz"),
             ("peak_force", "peak_force_hertz"), ("e_n", "e_n_requested"), ("e_t", "e_t_sliding_limit")]
    out = []
    for _, r in metrics.iterrows():
        label = r["impact"] + (f" {r['angle_deg']:.0f}°" if r["impact"] == "sphere-plane" else "")
        for q, ref in pairs:
            if not np.isfinite(r[ref]) or not np.isfinite(r[q]):
                continue
            err = (r[q] - r[ref]) / r[ref]
            out.append({"case": case, "engine": engine, "impact": label, "quantity": q, "analytic": r[ref],
                        "engine_value": r[q], "rel_error": err, "tolerance": TOLERANCE[q],
                        "pass": bool(abs(err) <= TOLERANCE[q]), "wall_time_s": wall_time})
    return pd.DataFrame(out)


def verification_cases() -> list[Path]:
    return sorted(p for p in VERIFICATION_DIR.glob("*.yaml") if not p.name.startswith("_"))


def run_verification(engines=None, cases=None, runs_root="runs", force=False,
                     progress=False) -> pd.DataFrame:
    """Run every verification case on every engine (default: every installed engine); return the
    long verification table."""
    engines = engine_names() if engines is None else engines
    tables = []
    for path in cases or verification_cases():
        case = load_case(path)
        for eng in engines:
            if eng not in case.engines:
                continue
            t0 = time.perf_counter()
            out = run_case(case, eng, runs_root=runs_root, force=force, progress=progress)
            wall = out.summary.get("wall_time", {}).get("total", time.perf_counter() - t0)
            params = json.loads((out.run_dir / "params.json").read_text())
            m = impact_metrics(Frames(out.run_dir / "frames.h5"), params)
            tables.append(verification_table(m, eng, case.name, wall))
    return pd.concat(tables, ignore_index=True) if tables else pd.DataFrame()
