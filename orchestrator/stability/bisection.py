"""The largest stable time step per case and engine, found by bisection, against the pre-run check.

A probe runs the case (shortened by :data:`PROBE` for the plane-shear scene) at
dt = f × dt_critical (derive's critical step: min of the Rayleigh step and t_c/10, both times the
damping factor) with ``timestep.allow_unsafe`` so that the pre-run check does not refuse it. It is
*stable* when it completes without a monitor tripping or the engine dying of it; the figure
that tripped is recorded otherwise. Starting from the largest fraction the pre-run check accepts,
the fraction is doubled until a probe is unstable, then bisected to a relative tolerance.

The check is on the safe side when its largest accepted fraction is at most the largest stable
one measured. A check whose accepted fraction is itself unstable is reported as UNSAFE.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING

from engines.base import EngineError

from ..case import load_case
from ..clock import engine_seconds
from ..derive import derive
from ..runner import run_case

if TYPE_CHECKING:
    import pandas as pd

#: shortening of a plane-shear probe: compression, a short settling and a little shear
PROBE = {"plane_shear": {"scene": {"shear_strain": 0.1, "settle_time_constants": 3, "shear_frames": 1,
                                   "wall_samples": 20}}}
#: members shortened further (by case name): at real stiffness the compression from the loose
#: packing at I_c = 0.02 alone is 3-5e5 steps per probe (dt ~ 6e-9 s); compressing 5x faster
#: (I_c = 0.1) and, for quartz, starting denser (0.35, the schema's largest loose fraction; the
#: narrow glass PSD jams there in random sequential addition) cuts a probe to ~1e5 steps. Faster
#: walls raise the largest expected speed, so the pre-run check of the *probe* is the one the probe
#: is compared with (its binding limit may differ from the full member's; both in docs/stability.md)
MEMBER_PROBE = {"stability_quartz_stiff": {"scene": {"loose_fraction": 0.35, "compression_inertial_number": 0.1}},
                "stability_glass_25um": {"scene": {"compression_inertial_number": 0.1}}}


@dataclass
class Bisection:
    case: str
    engine: str
    dt_critical: float
    check_fraction: float            # largest fraction of dt_critical the pre-run check accepts
    binding: str                     # the limit that sets it
    stable_fraction: float | None    # largest stable fraction measured
    unstable_fraction: float | None  # smallest unstable fraction measured
    tripped: dict | None             # what stopped the smallest unstable probe
    safe_side: bool | None
    probes: list = field(default_factory=list)

    def as_dict(self):
        return asdict(self)


def _merge(a: dict, b: dict) -> dict:
    out = dict(a)
    for k, v in b.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def probe(case_path, engine: str, fraction: float, runs_root, overrides: dict | None = None) -> dict:
    """One probe run at dt = fraction × dt_critical; returns {fraction, stable, status, tripped, ...}."""
    base = load_case(case_path, overrides=overrides)
    p = derive(base)
    dt = fraction * p["dt_critical"]
    ov = _merge(overrides or {}, {"timestep": {"dt": f"{dt!r} s", "allow_unsafe": True}})
    case = load_case(case_path, overrides=ov)
    try:
        out = run_case(case, engine, runs_root=runs_root, progress=False, analyze=False)
        status, summ = out.status, out.summary
    except EngineError as exc:
        status, summ = "failed", {"error": str(exc).splitlines()[0]}
    tripped = summ.get("unstable")
    return {"fraction": fraction, "dt": dt, "status": status, "stable": status == "complete",
            "tripped": tripped if tripped else ({"figure": "engine_failed", "message": summ.get("error")}
                                               if status == "failed" else None),
            "engine_time": engine_seconds(summ)}


def check_tolerance(rel_tol) -> float:
    """The relative bisection tolerance (``--tol``), or a ValueError: it must lie strictly between 0
    and 1 (at 0 or below the bisection would never end; at 1 or above it would stop at once)."""
    try:
        tol = float(rel_tol)
    except (TypeError, ValueError):
        tol = math.nan
    if not 0 < tol < 1:
        shown = rel_tol if math.isnan(tol) else format(tol, "g")
        raise ValueError(f"--tol {shown}: the relative bisection tolerance must lie between 0 and 1 (exclusive); "
                         f"give e.g. --tol 0.15 (the default)")
    return tol


def probe_case(case_path, probe_overrides: dict | None = None):
    """(overrides, case) of the probes of ``case_path``: the case shortened by :data:`PROBE` and
    :data:`MEMBER_PROBE` (or by ``probe_overrides``), loaded and checked, as no probe has run yet."""
    base = load_case(case_path)
    ov = probe_overrides if probe_overrides is not None else _merge(PROBE.get(base.scene.kind, {}),
                                                                    MEMBER_PROBE.get(base.name, {}))
    return ov, load_case(case_path, overrides=ov or None)


def bisect(case_path, engine: str, runs_root="runs", rel_tol: float = 0.15, max_fraction: float = 64.0,
           probe_overrides: dict | None = None, log=None) -> Bisection:
    """Largest stable dt fraction of ``case_path`` on ``engine`` (see the module docstring).
    ``rel_tol`` must lie in (0, 1) (:func:`check_tolerance`), checked before any probe."""
    rel_tol = check_tolerance(rel_tol)
    ov, case = probe_case(case_path, probe_overrides)
    p = derive(case)
    rep = p["stability"]
    f_check = rep["dt_max_safe"] / p["dt_critical"]
    probes = []

    def run(f):
        r = probe(case_path, engine, f, runs_root, ov or None)
        probes.append(r)
        if log:
            log(f"  {engine} f = {f:.4g}: {'stable' if r['stable'] else 'UNSTABLE ' + str((r['tripped'] or {}).get('figure'))}")
        return r

    lo = hi = None
    tripped = None
    r = run(f_check)
    if r["stable"]:
        lo = f_check
        f = f_check * 2
        while f <= max_fraction:
            r = run(f)
            if r["stable"]:
                lo = f
                f *= 2
            else:
                hi, tripped = f, r["tripped"]
                break
    else:
        hi, tripped = f_check, r["tripped"]
        f = f_check / 2
        while f > f_check / 64:
            r = run(f)
            if r["stable"]:
                lo = f
                break
            hi, tripped = f, r["tripped"]
            f /= 2
    if lo is not None and hi is not None:
        while (hi - lo) / lo > rel_tol:
            mid = math.sqrt(lo * hi)
            r = run(mid)
            if r["stable"]:
                lo = mid
            else:
                hi, tripped = mid, r["tripped"]
    safe = None if lo is None else (f_check <= lo * (1 + 1e-9))
    if lo is None:
        safe = False
    return Bisection(case=case.name, engine=engine, dt_critical=p["dt_critical"], check_fraction=f_check,
                     binding=rep["binding"], stable_fraction=lo, unstable_fraction=hi, tripped=tripped,
                     safe_side=safe, probes=probes)


def table(results: list[Bisection]) -> "pd.DataFrame":
    import pandas as pd
    rows = []
    for b in results:
        rows.append({"case": b.case, "engine": b.engine, "dt_critical_s": b.dt_critical,
                     "check_max_fraction": b.check_fraction, "binding_limit": b.binding,
                     "largest_stable_fraction": b.stable_fraction, "smallest_unstable_fraction": b.unstable_fraction,
                     "tripped_by": (b.tripped or {}).get("figure"),
                     "margin": (b.stable_fraction / b.check_fraction) if b.stable_fraction else None,
                     "check_safe_side": b.safe_side, "probes": len(b.probes)})
    return pd.DataFrame(rows)
