"""The one wording of "unknown name" messages: a case field, a command-line field, an analysis
option. Pure string work (no imports beyond difflib): the case model and the analysis names use it
without importing each other."""
from __future__ import annotations

import difflib


def unknown_name_hint(allowed, key: str, what: str = "field") -> str:
    """``unknown field; did you mean 'x'? allowed here: a, b, x`` for ``key`` among ``allowed``."""
    allowed = list(allowed)
    near = difflib.get_close_matches(key, allowed, n=1)
    alt = f"did you mean '{near[0]}'? " if near else ""
    return f"unknown {what}; {alt}allowed here: {', '.join(sorted(allowed))}"
