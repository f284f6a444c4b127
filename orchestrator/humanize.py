"""Durations and sizes as people read them ("4.3 min", "7.5 h", "455.2 MB"): one place for every
line the commands print (run sizes, `orchestrator status`, an engine's progress lines)."""
from __future__ import annotations


def fmt_bytes(b: float) -> str:
    """``b`` bytes in B, kB, MB, GB or TB (powers of 1000), one decimal above bytes."""
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if b < 1000 or unit == "TB":
            return f"{b:.0f} {unit}" if unit == "B" else f"{b:.1f} {unit}"
        b /= 1000
    return f"{b:.1f} TB"  # pragma: no cover


def fmt_s(seconds: float) -> str:
    """``seconds`` in ms, s (below 2 min), min (below 2 h), h (below 2 days) or days."""
    if seconds < 1:
        return f"{seconds * 1000:.0f} ms"
    if seconds < 120:
        return f"{seconds:.1f} s"
    if seconds < 7200:
        return f"{seconds / 60:.1f} min"
    if seconds < 172800:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} days"
