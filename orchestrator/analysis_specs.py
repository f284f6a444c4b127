"""The names of the analyses and the parsing of a case's ``analysis:`` list, without importing the
analysis stack (numba kernels, scikit-image, SciPy): ``validate`` and ``run --dry-run`` check a
case's analyses in milliseconds. ``orchestrator.analysis.ANALYSES`` maps the same names to their
functions (a test keeps the two in step)."""
from __future__ import annotations

import json

#: every analysis a case can name (keys of orchestrator.analysis.ANALYSES)
ANALYSIS_NAMES = ("clusters", "coordination", "d2min", "displacements", "energy", "fabric", "forcechains",
                  "friction", "profiles", "rdf", "shearband", "stress", "triaxial")


def parse_specs(specs, known=ANALYSIS_NAMES) -> list[tuple[str, dict]]:
    """Normalise a case's ``analysis:`` list: each entry a name or ``{name: {options}}``.

    Raises ValueError naming the entry when a name is unknown or options are not a mapping.
    """
    if specs is None:
        return []
    if isinstance(specs, (str, dict)):
        specs = [specs]
    out = []
    for n, s in enumerate(specs):
        if isinstance(s, str):
            name, opts = s, {}
        elif isinstance(s, dict) and len(s) == 1:
            (name, opts), = s.items()
            opts = {} if opts is None else opts
            if not isinstance(opts, dict):
                raise ValueError(f"analysis[{n}] ({name}): options must be a mapping, got {type(opts).__name__}")
        else:
            raise ValueError(f"analysis[{n}]: expected a name or {{name: {{options}}}}, got {s!r}")
        if name not in known:
            raise ValueError(f"analysis[{n}]: unknown analysis {name!r}; known: {sorted(known)}")
        out.append((name, dict(opts)))
    return out


def parse_cli_spec(text: str):
    """One analysis from the command line: ``name`` or ``name:{JSON options}``, e.g.
    ``'stress:{"window": [0.1, 0.2], "interval": 0.005}'``; returns what a case's ``analysis:`` list
    holds (a name or ``{name: {options}}``). Raises ValueError naming the text when the JSON does not
    parse to a mapping."""
    name, _, opts = text.partition(":")
    if not opts:
        return name
    try:
        o = json.loads(opts)
    except json.JSONDecodeError as e:
        raise ValueError(f"{text!r}: the options after '{name}:' are not JSON ({e.msg} at column "
                         f"{e.colno}); write e.g. '{name}:{{\"interval\": 0.01}}'") from None
    if not isinstance(o, dict):
        raise ValueError(f"{text!r}: the options after '{name}:' must be a JSON object {{...}}, got {opts}")
    return {name: o}
