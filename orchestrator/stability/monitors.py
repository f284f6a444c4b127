"""The in-deck monitors' verdict, read from an engine log.

Both engines' decks (templates/liggghts/partials/monitors.j2, templates/yade/partials/
monitors.py.j2) print ``ORCH_UNSTABLE:<figure>:<value>:<limit>:<step>`` and stop when a check
trips. An engine that dies of an instability before a check sees it (LIGGGHTS "Lost atoms",
"Out of range atoms", a NaN) is classified from its own message.
"""
from __future__ import annotations

import re
from pathlib import Path

_LINE = re.compile(r"^ORCH_UNSTABLE:([a-z_]+):([^:]+):([^:]+):(\d+)\s*$", re.M)
#: engine messages that mean the integration blew up (pattern -> figure)
_FATAL = [
    (re.compile(r"ERROR: Lost atoms: original (\d+) current (\d+)"), "grains_outside"),
    (re.compile(r"ERROR: Out of range atoms"), "grains_outside"),
    (re.compile(r"ERROR: .*(?:[Nn]a[Nn]|inf)\b"), "nan"),
    (re.compile(r"ERROR: .*[Bb]in.*out of range"), "grains_outside"),
]

FIGURES = {
    "kinetic_energy": "kinetic energy [J] above the limit",
    "overlap": "largest overlap / r_min above the limit",
    "grains_outside": "grains left in the domain below the count inserted",
    "nan": "NaN in the state",
    "wall_force": "|wall force| [N] above the limit",
    "wall_force_swing": "wall force [N] swung by more than the limit between two checks",
}


def _num(x: str) -> float:
    try:
        return float(x)
    except ValueError:
        return float("nan")


def verdict(log_text: str, dt: float | None = None, failed: bool = False) -> dict | None:
    """``{"figure", "value", "limit", "step", "time", "meaning"}`` when the run was stopped as
    unstable, else None. ``failed``: the engine exited with an error (then its fatal messages
    count too)."""
    m = _LINE.findall(log_text)
    if m:
        fig, val, lim, step = m[0]
        out = {"figure": fig, "value": _num(val), "limit": _num(lim), "step": int(step)}
    elif failed:
        out = None
        for pat, fig in _FATAL:
            mm = pat.search(log_text)
            if mm:
                steps = re.findall(r"^\s*(\d+)\s+\d+\s", log_text[:mm.start()], flags=re.M)
                out = {"figure": fig, "value": float("nan"), "limit": float("nan"),
                       "step": int(steps[-1]) if steps else None, "engine_message": mm.group(0)}
                if fig == "grains_outside" and mm.groups():
                    out["value"], out["limit"] = float(mm.group(2)), float(mm.group(1))
                break
        if out is None:
            return None
    else:
        return None
    out["time"] = out["step"] * dt if (dt is not None and out["step"] is not None) else None
    out["meaning"] = FIGURES.get(out["figure"], out["figure"])
    return out


def read_verdict(run_dir, dt: float | None = None, failed: bool = False) -> dict | None:
    log = Path(run_dir) / "engine.log"
    if not log.exists():
        return None
    return verdict(log.read_text(errors="replace"), dt, failed)
