"""The names of the analyses and the parsing of a case's ``analysis:`` list, without importing the
analysis stack (numba kernels, scikit-image, SciPy): ``validate`` and ``run --dry-run`` check a
case's analyses in milliseconds. ``orchestrator.analysis.ANALYSES`` maps the same names to their
functions (a test keeps the two in step)."""
from __future__ import annotations

import json
import math
import numbers

from .hints import unknown_name_hint

#: every analysis a case can name (keys of orchestrator.analysis.ANALYSES)
ANALYSIS_NAMES = ("clusters", "coordination", "d2min", "displacements", "energy", "fabric", "forcechains",
                  "friction", "profiles", "rdf", "shearband", "stress", "triaxial")


_TIME_SERIES = ("at", "control", "stride")
_PAIRS = ("pairs", "interval", "start", "control", "stride")

#: the options each analysis takes: the keyword parameters of ``orchestrator.analysis.ANALYSES[name]``
#: after ``frames`` (tests/test_results.py keeps the two in step), so that a misspelt
#: option is refused when the case is validated, not met as a TypeError after the run. The clusters
#: analysis passes the options it does not know to its D²min.
ANALYSIS_OPTIONS = {
    "clusters": ("top_fraction", "cutoff", "cutoff_d50", "s_min", "s_min_rg", "d2min_result"),
    "coordination": (*_TIME_SERIES, "source", "tolerance", "include_walls", "rattler_max", "wall_distance",
                     "container", "cutoff", "cutoff_d50"),
    "d2min": ("cutoff", "cutoff_d50", *_PAIRS, "min_neighbors", "wall_distance", "container", "stages"),
    "displacements": (*_PAIRS, "bins", "log_bins", "stages"),
    "energy": (*_TIME_SERIES, "youngs_modulus", "poisson_ratio", "limit"),
    "fabric": (*_TIME_SERIES, "plane", "bins", "source", "tolerance"),
    "forcechains": (*_TIME_SERIES, "max_angle", "factor", "min_length", "plane"),
    "friction": ("radius", "torque_wall", "force_wall", "geometry", "steady_from", "steady_control"),
    "profiles": ("center", "z_ref", "r_max", "z_range", "radial_z_range", "axial_r_range", "bins_r", "bins_z",
                 *_TIME_SERIES, "samples"),
    "rdf": ("r_max", "r_max_d50", "bins", "container", "edge_correction", *_TIME_SERIES),
    "shearband": ("radii", "dr", "n_radii", "center", "z_ref", "z_range", "bins_z", "pairs", "interval", "stride",
                  "control", "drive", "steady_from", "top_fraction", "stages"),
    "stress": ("window", "interval", "at", "control", "d2min_cutoff_d50", "d2min_cutoff", "stages"),
    "triaxial": ("smoothing_rows", "residual_from", "dilatancy_window", "wall"),
}
#: options that take one number (SI lengths in m, ``*_d50`` in median diameters; null keeps the
#: default), each the same kind in every analysis that takes it: the whole numbers among them (counts
#: of bins, samples, frames, neighbours, rows) and those that must be > 0 (a length, a cutoff, a
#: count of bins or samples). tests/test_bad_input_cli.py keeps them in step with the defaults of
#: ``orchestrator.analysis.ANALYSES``.
_COUNTS = ("bins", "bins_r", "bins_z", "n_radii", "samples", "stride", "min_neighbors", "min_length", "rattler_max",
           "s_min", "s_min_rg", "smoothing_rows")
_POSITIVE = ("cutoff", "cutoff_d50", "d2min_cutoff", "d2min_cutoff_d50", "r_max", "r_max_d50", "radius", "dr",
             "bins", "bins_r", "bins_z", "n_radii", "samples", "stride")
NUMBER_OPTIONS = frozenset((*_COUNTS, *_POSITIVE, "top_fraction", "tolerance", "wall_distance", "max_angle", "factor",
                            "limit", "youngs_modulus", "poisson_ratio", "residual_from", "dilatancy_window", "z_ref",
                            "steady_from", "interval"))

#: analyses that hand the options they do not take themselves to another analysis
_FORWARDS = {"clusters": "d2min"}


def allowed_options(name: str) -> tuple[str, ...]:
    """The option names analysis ``name`` accepts (its own and those it forwards)."""
    fwd = _FORWARDS.get(name)
    return ANALYSIS_OPTIONS.get(name, ()) + (ANALYSIS_OPTIONS[fwd] if fwd else ())


def parse_specs(specs, known=ANALYSIS_NAMES, where: str = "analysis") -> list[tuple[str, dict]]:
    """Normalise a case's ``analysis:`` list: each entry a name or ``{name: {options}}``.

    Raises ValueError naming the entry (``where[n]``, e.g. ``analysis[2]``) when a name is unknown,
    options are not a mapping, an option is not one the analysis takes (with the nearest name), or a
    number option's value is not the number it takes (:func:`_number`, which also reads YAML's
    ``1e-3``, a string, as the number).
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
                raise ValueError(f"{where}[{n}] ({name}): options must be a mapping, got {type(opts).__name__}")
        else:
            raise ValueError(f"{where}[{n}]: expected a name or {{name: {{options}}}}, got {s!r}")
        if name not in known:
            raise ValueError(f"{where}[{n}]: unknown analysis {name!r}; known: {sorted(known)}")
        allowed = allowed_options(name)
        for key in opts:
            if key not in allowed:
                raise ValueError(f"{where}[{n}] ({name}): option {key!r}: "
                                 f"{unknown_name_hint(allowed, str(key), 'option')}")
        out.append((name, {key: _number(f"{where}[{n}] ({name})", key, v) for key, v in opts.items()}))
    return out


def _number(entry: str, key: str, value):
    """``value`` of option ``key`` as the analysis takes it: unchanged unless ``key`` is one of
    :data:`NUMBER_OPTIONS`, then a finite number (a numeric string, as YAML reads ``1e-3``, made
    one), whole for a count and > 0 where it must be; else a ValueError naming ``entry``, the option,
    the value and what it must be."""
    if key not in NUMBER_OPTIONS or value is None:
        return value
    x = value
    if isinstance(x, str):
        try:
            x = float(x)
        except ValueError:
            pass
    ok = isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isfinite(x)
    if ok and key in _COUNTS:
        ok = float(x).is_integer()
        x = int(x) if ok else x
    if ok and key in _POSITIVE:
        ok = x > 0
    if not ok:
        what = ("a whole number" if key in _COUNTS else "a number") + (" > 0" if key in _POSITIVE else "")
        raise ValueError(f"{entry}: option {key!r} must be {what}, got {value!r}")
    return x


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
