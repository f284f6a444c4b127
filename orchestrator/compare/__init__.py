"""Compare anything with anything: simulation vs CT, engine vs engine, run vs itself.

>>> from orchestrator.compare import compare, crossval, write_run_report
>>> cmp = compare("runs/shear_cell_smoke/liggghts-abc", "ct/frames.h5", out_dir="cmp/")   # doctest: +SKIP
>>> cmp.table            # one row per measure, quantity and state: metric, distance, A, B
>>> cmp.grain.tables["states"]   # per-grain trajectory error and displacement agreement
>>> cv = crossval("cases/shear_cell_smoke.yaml", runs_root="runs", engines=["liggghts", "yade"])   # doctest: +SKIP
>>> write_run_report("runs/shear_cell_smoke/liggghts-abc")                                 # doctest: +SKIP

See docs/compare.md. Modules: :mod:`.align` (states, coordinates, identity), :mod:`.measures`
(the papers' measures on both sides), :mod:`.distances` (L2, KS, relative error), :mod:`.grain`
(grain-by-grain errors), :mod:`.crossval`, :mod:`.report` (HTML), :mod:`.browser` (headless
Chromium check of a page).
"""
from .align import Alignment, Source, align, match_identity, match_states, open_source
from .core import Comparison, compare
from .crossval import CrossValidation, crossval
from .distances import ks, l2, rel_error
from .grain import GrainComparison, grain_errors
from .measures import MEASURES
from .report import run_checks, write_compare_report, write_run_report

__all__ = ["Alignment", "Source", "align", "match_identity", "match_states", "open_source", "Comparison", "compare",
           "CrossValidation", "crossval", "ks", "l2", "rel_error", "GrainComparison", "grain_errors", "MEASURES",
           "run_checks", "write_compare_report", "write_run_report"]
