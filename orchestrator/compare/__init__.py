"""Compare anything with anything: simulation vs CT, engine vs engine, run vs itself.

>>> from orchestrator.compare import compare, crossval, write_run_report
>>> cmp = compare("runs/shear_cell_smoke/liggghts-abc", "ct/frames.h5", out_dir="cmp/")   # doctest: +SKIP
>>> cmp.table            # one row per measure, quantity and state: metric, distance, A, B
>>> cmp.grain.tables["states"]   # per-grain trajectory error and displacement agreement
>>> cv = crossval("cases/shear_cell_smoke.yaml", runs_root="runs")                         # doctest: +SKIP
>>> write_run_report("runs/shear_cell_smoke/liggghts-abc")                                 # doctest: +SKIP

See docs/compare.md. Modules: :mod:`.align` (states, coordinates, identity), :mod:`.measures`
(the papers' measures on both sides), :mod:`.distances` (L2, KS, relative error), :mod:`.grain`
(grain-by-grain errors), :mod:`.crossval`, :mod:`.report` (HTML), :mod:`.browser` (headless
Chromium check of a page).
"""
from importlib import import_module

#: where each public name lives; imported on first use (PEP 562), so that ``orchestrator --help``
#: and the CLI's command table need not load the analysis stack behind :mod:`.measures`
_WHERE = {"Alignment": "align", "Source": "align", "align": "align", "match_identity": "align",
          "match_states": "align", "open_source": "align", "Comparison": "core", "compare": "core",
          "CrossValidation": "crossval", "crossval": "crossval", "ks": "distances", "l2": "distances",
          "rel_error": "distances", "GrainComparison": "grain", "grain_errors": "grain", "MEASURES": "measure_names",
          "run_checks": "report", "write_compare_report": "report", "write_run_report": "report"}

__all__ = list(_WHERE)


def __getattr__(name):
    if name in _WHERE:
        value = getattr(import_module(f".{_WHERE[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_WHERE))
