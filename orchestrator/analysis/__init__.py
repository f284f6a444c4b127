"""Analysis of particle frames (simulation or CT), every measure of the two seed papers.

Each measure is an array function (arrays in, arrays/DataFrames out, SI) plus an
``analyze_<measure>(frames, **options) -> Result`` wrapper registered in :data:`ANALYSES`.
A :class:`~._common.Result` holds DataFrames (``.tables``), scalars and ``.plot() -> Figure``.

>>> from orchestrator import load
>>> from orchestrator.analysis import ANALYSES, run_analyses, d2min
>>> out = d2min(ref_xyz, cur_xyz, cutoff=1.5 * d50, wall_distance=d50)   # doctest: +SKIP
>>> fr = load("runs/triaxial_small/liggghts-abc")                    # doctest: +SKIP
>>> res = ANALYSES["d2min"](fr, interval=0.01)                        # doctest: +SKIP
>>> res.tables["particles"].head(); res.plot()                        # doctest: +SKIP
>>> run_analyses(fr, ["rdf", {"d2min": {"interval": 0.01}}], "out/")  # doctest: +SKIP

This package works on frames and arrays only; it never imports the engines.
"""
from __future__ import annotations

import time
import traceback
from pathlib import Path

from ..analysis_specs import parse_specs as _parse_specs
from ..frames import Frames
from ._common import Result, atomic_savefig, atomic_write_csv, atomic_write_json, d50, frame_indices, frame_pairs
from .clusters import analyze_clusters, cluster_properties, find_clusters
from .containers import Box, Cylinder, infer_container, make_container
from .coordination import analyze_coordination, coordination_from_pairs, frame_contacts, neighbor_counts
from .d2min import analyze_d2min, d2min, local_strain
from .displacements import analyze_displacements, incremental_displacements
from .energy import analyze_energy, effective_modulus, hertz_normal_energy, kinetic_energy, nonaffine_kinetic_energy
from .fabric import analyze_fabric, anisotropy, contact_vectors, fabric_tensor, rose
from ._fits import erf_profile, fractal_dimension, powerlaw_fit
from .forcechains import analyze_forcechains, force_chains
from .friction import analyze_friction, mu_macro
from .neighbors import contacts_to_rows, geometric_contacts, pairs_within
from .profiles import analyze_profiles, density_profile
from .rdf import analyze_rdf, pair_counts, rdf
from .shearband import analyze_shearband, angular_profiles, fit_erf_profile, rotation_center
from .stress import analyze_stress, deviatoric_q, love_weber_stress, particle_stress, volatility
from .triaxial import (analyze_triaxial, dilatancy_angle, friction_angle, local_slope, plot_triaxial_runs,
                       running_mean, triaxial_curves)

#: the array functions (arrays in, arrays / DataFrames out), importable by name:
#: ``from orchestrator.analysis import d2min, rdf, neighbor_counts`` gives the functions (the modules
#: of the same name stay importable as ``orchestrator.analysis.d2min`` etc. through ``from ... import``)
ARRAY_FUNCTIONS = [
    "d2min", "local_strain", "rdf", "pair_counts", "neighbor_counts", "coordination_from_pairs",
    "frame_contacts", "pairs_within", "geometric_contacts", "contacts_to_rows", "find_clusters",
    "cluster_properties", "powerlaw_fit", "fractal_dimension", "erf_profile", "fit_erf_profile",
    "rotation_center", "angular_profiles", "density_profile", "incremental_displacements",
    "fabric_tensor", "anisotropy", "rose", "contact_vectors", "force_chains", "mu_macro",
    "deviatoric_q", "love_weber_stress", "volatility", "particle_stress", "kinetic_energy",
    "nonaffine_kinetic_energy", "hertz_normal_energy", "effective_modulus", "running_mean",
    "local_slope", "friction_angle", "dilatancy_angle", "triaxial_curves", "d50", "frame_pairs",
    "frame_indices", "infer_container", "make_container", "Box", "Cylinder",
]

__all__ = ["ANALYSES", "run_analyses", "parse_specs", "Result", "Frames", "plot_triaxial_runs",
           *ARRAY_FUNCTIONS, *(f"analyze_{k}" for k in (
               "clusters", "coordination", "d2min", "displacements", "energy", "fabric", "forcechains",
               "friction", "profiles", "rdf", "shearband", "stress", "triaxial"))]

#: name -> callable(frames, **options) -> Result
ANALYSES = {
    "profiles": analyze_profiles,
    "shearband": analyze_shearband,
    "friction": analyze_friction,
    "displacements": analyze_displacements,
    "d2min": analyze_d2min,
    "clusters": analyze_clusters,
    "rdf": analyze_rdf,
    "coordination": analyze_coordination,
    "fabric": analyze_fabric,
    "forcechains": analyze_forcechains,
    "stress": analyze_stress,
    "energy": analyze_energy,
    "triaxial": analyze_triaxial,
}


def parse_specs(specs) -> list[tuple[str, dict]]:
    """Normalise a case's ``analysis:`` list (:func:`orchestrator.analysis_specs.parse_specs`
    against :data:`ANALYSES`)."""
    return _parse_specs(specs, known=ANALYSES)


def run_analyses(frames, specs, out_dir, plots: bool = True, raise_errors: bool = False) -> dict:
    """Run a case's ``analysis:`` list on ``frames`` and write results into ``out_dir``.

    For each entry, every table is written as ``<label>_<table>.csv`` and the plot as
    ``<label>.png`` (atomically: temporary file, then :func:`os.replace`); ``<label>`` is the
    analysis name, suffixed ``_2``, ``_3`` … when a name appears more than once. The summary is
    also written to ``analysis_summary.json``.

    An analysis that fails is recorded with ``status: "error"`` and its message, and the others
    still run (set ``raise_errors`` to stop at the first failure). Unknown names are rejected
    before anything runs.

    Returns ``{label: {"name", "status", "options", "scalars", "files", "seconds", ["error"]}}``.
    """
    if not hasattr(frames, "position"):
        frames = Frames(frames)
    parsed = parse_specs(specs)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary, seen = {}, {}
    for name, opts in parsed:
        seen[name] = seen.get(name, 0) + 1
        label = name if seen[name] == 1 else f"{name}_{seen[name]}"
        t0 = time.perf_counter()
        entry = {"name": name, "options": opts, "files": []}
        try:
            res = ANALYSES[name](frames, **opts)
            for tname, df in res.tables.items():
                entry["files"].append(atomic_write_csv(df, out / f"{label}_{tname}.csv").name)
            if plots:
                fig = res.plot()
                entry["files"].append(atomic_savefig(fig, out / f"{label}.png").name)
            entry.update(status="ok", scalars=res.scalars, resolved_options=res.options)
        except Exception as e:  # noqa: BLE001 - recorded, reported, and optionally re-raised
            if raise_errors:
                raise
            entry.update(status="error", error=f"{type(e).__name__}: {e}",
                         traceback=traceback.format_exc(limit=3))
        entry["seconds"] = round(time.perf_counter() - t0, 3)
        summary[label] = entry
    atomic_write_json(summary, out / "analysis_summary.json")
    return summary
