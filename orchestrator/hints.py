"""The one wording of "unknown name" messages: a case field, a command-line field, an analysis
option. Pure string work (no imports beyond difflib): the case model and the analysis names use it
without importing each other."""
from __future__ import annotations

import difflib


def did_you_mean(allowed, key: str) -> str:
    """``did you mean 'x'? `` for the name in ``allowed`` closest to ``key``; "" when none is close."""
    near = difflib.get_close_matches(key, list(allowed), n=1)
    return f"did you mean '{near[0]}'? " if near else ""


def unknown_name_hint(allowed, key: str, what: str = "field") -> str:
    """``unknown field; did you mean 'x'? allowed here: a, b, x`` for ``key`` among ``allowed``."""
    allowed = list(allowed)
    return f"unknown {what}; {did_you_mean(allowed, key)}allowed here: {', '.join(sorted(allowed))}"
