"""LIGGGHTS-PUBLIC 3.8 adapter (Debian ``liggghts``).

Render: ``templates/liggghts/<scene>.in.j2`` with the derived parameters; particles go in through
``read_data`` from the orchestrator's particle table, except where the deck inserts them itself
(clumps: substitute ``inserted_clumps``; :mod:`engines.liggghts.triaxial` then writes the
particle table from the first frame). Run: ``liggghts -in deck.in`` (under ``mpirun -np N`` for
N > 1 ranks), progress from thermo lines. Parse: the binary ``dump custom`` segments
(:mod:`engines.liggghts.segments`, read by :mod:`engines.lammps_dump`) into frames.h5, with the
scene's controls and wall series from its ``post`` (the scene sees the frames through
:class:`DumpOutput`). Resume: ``restart`` files ``restart/state.<step>.restart`` and ``run N upto``.
"""
from __future__ import annotations

import json
import shutil
import re
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from orchestrator.atomic import write_json, write_text
from orchestrator.frames import FrameWriter
from orchestrator.particles_io import read_particle_table
from orchestrator.registry import get_scene

from ..base import Engine, EngineError, tail
from ..lammps_dump import COLUMNS, per_atom_arrays, read_binary_dump, stress_tensors
from ..render import render_template
from . import triaxial
from .numbers import liggghts_numbers, seed_term_ratios
from .segments import RestartFiles, deck_segments, dump_segments, wall_rows

_THERMO = re.compile(rb"^\s*(\d+)\s+\d+\s+[-+0-9.eE]+(\s|$)")



def openmpi_launcher() -> str:
    """Debian's LIGGGHTS is built against OpenMPI: its launcher by its own name, so that another
    ``mpirun`` earlier on PATH (the mpich wheel's, in the venv's bin/ for LAMMPS) is never taken."""
    for name in ("mpirun.openmpi", "orterun"):
        path = shutil.which(name)
        if path:
            return path
    return "mpirun"

class Liggghts(RestartFiles, Engine):
    name = "liggghts"
    executable = "liggghts"
    throughput = 6e6        # ENGINES.md: 2000 dense Hertz spheres on one core of this machine
    startup = 0.5
    # an atom (~40 doubles with the granular fix properties), a half neighbour list of ~15
    # neighbours and the tangential history (3 doubles per contact); the parse stacks every frame
    # of the dump once more
    bytes_per_particle = 2_000
    base_bytes = 50e6
    parse_copies = 2
    workers_field = "mpi_ranks"           # MPI ranks, each a process of its own (base_bytes each)
    workers_are_processes = True
    capabilities = {
        "hertz": "pair_style gran model hertz",
        "restitution_damping": "model hertz with coefficientRestitution (Tsuji damping), limitForce on",
        "sliding_friction": "tangential history (Coulomb limit mu*Fn)",
        "tangential_history_displacement": "tangential history: the total displacement, projected onto the "
                                           "tangent plane (not rescaled), F_t = k_t(delta) xi (its only form)",
        "rolling_friction": "rolling_friction cdt (constant mu_rol, elastic-plastic torque limit)",
        "plane_wall": "fix wall/gran primitive zplane",
        "cylinder_wall": "fix wall/gran primitive zcylinder",
        "mesh_walls": "fix mesh/surface + fix wall/gran mesh",
        "rotating_walls": "fix move/mesh rotate",
        "servo_wall": "fix mesh/surface/stress/servo",
        "clumps": "fix multisphere",
        "particle_stress": "compute stress/atom",
        "contact_output": "compute pair/gran/local + dump local",
        "periodic": "boundary p",
    }
    substitutes = {
        "low_restitution": {
            "hertz_stiffness_calibrated": "model hertz/stiffness: exact Hertz elasticity, damping force "
                                          "γ m* √(R* δ) δ̇ with γ set to deliver e_n at the case's largest "
                                          "impact speed (e_n then varies with speed like v^(1/5))",
        },
        "adhesion": {
            "edinburgh_per_type_pair": "model edinburgh pullOffForce per type pair; each PSD bin its own "
                                       "type with F_ij = F_adh r_ij/<r_eff> (exact per bin, binned in r)",
            "sjkr_matched_overlap": "cohesion sjkr (F = k A, A ~ 2 pi r_eff xi: proportional to r_eff like the seed, "
                                    "but growing with the overlap) with k matched so F = F_adh at the expected overlap",
        },
        "seed000_damping": {
            "tsuji_restitution": "Tsuji damping (force ∝ δ^1/4 δ̇) with the restitution that seed 000's "
                                 "γ_n = sqrt(4/3 E* m*) delivers, instead of force ∝ δ^1/2 δ̇",
        },
        "rolling_friction_load": {
            "epsd2_constant": "rolling_friction epsd2 with a constant μ_rol = √(2 r_eff ξ) at the expected overlap; "
                              "its spring is LIGGGHTS' Mindlin k_t(ξ) r_eff² (0.36 of the seed's k_t r_eff² at ξ_σ "
                              "on the seed shear cell), no dashpot",
            "epsd3_matched": "rolling_friction epsd3 with a constant μ_rol = √(2 r_eff ξ) at the expected overlap; "
                             "its spring C k_n(ξ) μ_rol² r_eff² set to the seed's k_t r_eff² at contact.match_overlap, "
                             "and the seed's critical dashpot for the median pair",
        },
        "torsion_friction": {
            "luding_torsion": "rolling_friction luding torsion on (same stiffness and μ as rolling)",
            "epsd2_torsion_torque": "rolling_friction epsd2 with torsionTorque on: the twist loads the rolling "
                                    "spring (same stiffness and limit as rolling, no separate mu_tor)",
            "epsd3_torsion_torque": "rolling_friction epsd3 with torsionTorque on: the twist loads the rolling "
                                    "spring (same stiffness, dashpot and limit as rolling, no separate mu_tor)",
        },
        "placed_clumps": {
            "inserted_clumps": "the library shapes as particletemplate/multisphere (mass and inertia from the "
                               "orchestrator's grid integration), the same number of grains of each shape in "
                               "scene.particles.size_classes volume-mean sizes, inserted by fix insert/pack at random "
                               "places and orientations into the sample cylinder (not the orchestrator's packing), "
                               "integrated by fix multisphere (scenes/triaxial.py liggghts_clumps, engines/liggghts/triaxial.py)",
        },
        "membrane": {
            "shell_pressure": "radial forces p·(band envelope area)·r_i²/Σr_j² on the outer shell of grains of "
                              "each horizontal band, recomputed during the run (templates/liggghts/triaxial.in.j2)",
        },
    }

    def _probe_version(self) -> str:
        try:
            with tempfile.TemporaryDirectory() as tmp:   # `liggghts -h` leaves a log.liggghts behind
                out = subprocess.run([self.executable, "-h"], capture_output=True, text=True, timeout=30,
                                     cwd=tmp).stdout
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise EngineError(f"cannot run {self.executable}: {exc}") from None
        m = re.search(r"Version (LIGGGHTS-PUBLIC [^,]+)", out)
        return m.group(1) if m else out.splitlines()[0] if out else "unknown"

    # -- numbers ----------------------------------------------------------------------------
    def engine_params(self, case, params):
        return liggghts_numbers(case, params)

    def seed_term_ratios(self, case, params, overlaps):
        return seed_term_ratios(case, params, overlaps)

    def required_features(self, case, params) -> list[str]:
        feats = list(params.features)
        if self.engine_params(case, params).low_restitution:
            feats.append("low_restitution")      # below what model hertz can be fed: a substitute
        return feats

    # -- render -----------------------------------------------------------------------------
    def render(self, case, params, run_dir: Path, resume=None) -> Path:
        run_dir = Path(run_dir)
        for d in ("dump", "restart"):
            (run_dir / d).mkdir(exist_ok=True)
        data = run_dir / "particles.data"
        sc = params["scene"]
        if not data.exists() and not _inserted(params):
            write_data_file(data, run_dir / "particles.txt", params["scene"]["box_lo"], params["scene"]["box_hi"])
        ctx = {
            "case": case, "p": params, "engine": self.engine_params(case, params), "resume": resume,
            "files": {"data": data.name, **{k: Path(v).name for k, v in params.get("files", {}).items()}},
            "dump_every": sc["dump_every"], "thermo_every": max(1, sc["steps"] // 200),
            "restart_every": max(1, sc.get("restart_every", sc["steps"] // 10)),
        }
        ctx["dump_columns"] = dump_columns(case)
        ctx["dump_file"] = f"frames.{resume['step']:012d}.bin" if resume else "frames.bin"
        ctx["segments"] = deck_segments(sc["steps"], ctx["restart_every"], resume["step"] if resume else 0)
        write_json(run_dir / "dump" / "columns.json", ctx["dump_columns"])
        deck = run_dir / ("resume.in" if resume else "deck.in")
        render_template(f"liggghts/{case.scene.kind}.in.j2", ctx, deck)
        return deck

    def complete_resume(self, case, run_dir: Path, resume):
        """The triaxial deck re-enters its stage from ``restart/state.txt``: a restart file is usable
        only with its line there (:func:`engines.liggghts.triaxial.resume_point`)."""
        if case.scene.kind == "triaxial":
            return triaxial.resume_point(run_dir, resume)
        return resume

    def print_monitors(self, deck_text: str, overlap_limit: float) -> str:
        """templates/liggghts/partials/monitors.j2: the trip threshold, and a print at each check (the
        wall-force bookkeeping command runs every check)."""
        limit = overlap_limit
        text = re.sub(r"if '\$\{ORCH_ov\} > [0-9.e+-]+'", f"if '${{ORCH_ov}} > {limit!r}'", deck_text)
        text = re.sub(r"print ORCH_UNSTABLE:overlap:\$\{ORCH_ov\}:[0-9.e+-]+:",
                      f"print ORCH_UNSTABLE:overlap:${{ORCH_ov}}:{limit!r}:", text)
        return text.replace('"variable ORCH_wprev equal ${ORCH_w}"',
                            '"print \'ORCH_OV ${ORCH_s} ${ORCH_ov} ${ORCH_ke}\'" "variable ORCH_wprev equal ${ORCH_w}"')

    def command(self, deck: Path, case) -> list[str]:
        # stdbuf: LIGGGHTS' stdout is block-buffered in a pipe and MPI_Abort discards the
        # buffer, which would swallow the ERROR line that explains a failure
        # -echo screen: the log shows each deck command before its output, so a failure can be
        # traced to its deck line (LIGGGHTS 3.8 does not print the failing command itself)
        cmd = ["stdbuf", "-oL", "-eL", self.executable, "-in", deck.name, "-log", "none", "-echo", "screen"]
        n = case.engine_options.mpi_ranks
        if n > 1:
            cmd = [openmpi_launcher(), "--allow-run-as-root", "--oversubscribe", "-np", str(n)] + cmd
        return cmd

    def progress_step(self, line: str):
        m = _THERMO.match(line.encode() if isinstance(line, str) else line)
        return int(m.group(1)) if m else None

    def explain_failure(self, log: Path) -> str:
        text = Path(log).read_text(errors="replace") if Path(log).exists() else ""
        lines = text.splitlines()
        err_at = [k for k, l in enumerate(lines) if l.startswith("ERROR")]
        msg = ""
        if err_at:
            k = err_at[-1]
            msg = "LIGGGHTS says: " + lines[k] + "\n"
            deck_path = _deck_beside(log)
            if deck_path is not None:
                deck = [d.strip() for d in deck_path.read_text(errors="replace").splitlines()]
                for echoed in reversed(lines[:k]):          # the last echoed deck command
                    e = echoed.strip()
                    if e and e in deck:
                        msg += f"on {deck_path.name} line {deck.index(e) + 1}: {e}\n"
                        break
        return msg + tail(log, 12)

    # -- parse ------------------------------------------------------------------------------
    def parse(self, case, params, run_dir: Path, meta: dict) -> Path:
        run_dir = Path(run_dir)
        if _inserted(params):
            # the deck inserted the particles (inserted_clumps): check the insertion and write the
            # particle table from the first frame
            triaxial.check_inserted_clumps(run_dir, params)
        segments = dump_segments(run_dir)
        if not segments:
            raise EngineError(f"{run_dir / 'dump'}: LIGGGHTS wrote no frames\n{tail(run_dir / 'engine.log')}")
        table = read_particle_table(run_dir / "particles.txt")
        ids = table["id"]
        mass = table["mass"]
        fields = _fields(case)
        dt = params["dt"]
        cols = json.loads((run_dir / "dump" / "columns.json").read_text())
        snaps = list(read_binary_dump(segments, len(cols)))
        steps = np.array([s for s, _ in snaps], dtype=np.int64)
        extras = get_scene(case.scene.kind).post(run_dir, params, DumpOutput(run_dir, snaps, cols, ids))
        if _inserted(params):
            triaxial.clumps_summary(run_dir, params, steps[0])
        controls = extras.get("controls", {})
        order = np.argsort(ids)
        with FrameWriter(run_dir / "frames.h5", ids, table["radius"], fields=fields,
                         controls=controls.keys(), mass=mass, meta=meta) as w:
            same = len({a.shape for _, a in snaps}) == 1
            if same and snaps:
                block = np.stack([a for _, a in snaps])                  # (T, n, ncols)
                sid = block[:, :, cols.index("id")].astype(np.int64)
                if (sid == sid[0]).all():                                # sorted ids, none lost: one mapping
                    rows = order[np.searchsorted(ids[order], sid[0])]
                    arrays = {}
                    for field, names in COLUMNS.items():
                        if field in fields and names[0] in cols:
                            out = np.full((len(steps), len(ids), 3), np.nan)
                            out[:, rows] = block[:, :, [cols.index(c) for c in names]]
                            arrays[field] = out
                    if "stress" in fields:
                        out = np.full((len(steps), len(ids), 3, 3), np.nan)
                        out[:, rows] = stress_tensors(block, cols)
                        arrays["stress"] = out
                    ctl = {c: np.asarray(v, float)[:len(steps)] for c, v in controls.items()}
                    ctl = {c: np.pad(v, (0, len(steps) - len(v)), constant_values=np.nan) for c, v in ctl.items()}
                    done = w.append_block(steps * dt, steps, controls=ctl, **arrays)
                    if case.output.contacts:
                        for k, step in zip(done, steps):
                            c = read_contacts(run_dir / "dump" / f"contacts.{step}.txt")
                            if c is not None:
                                w.write_contacts(k, c)
                    snaps = []
            for step, a in snaps:                                        # atoms lost or inserted: frame by frame
                rows, arrays = per_atom_arrays(a, cols, ids, order, fields)
                if "stress" in fields:
                    out = np.full((len(ids), 3, 3), np.nan)
                    out[rows] = stress_tensors(a, cols)
                    arrays["stress"] = out
                contacts = read_contacts(run_dir / "dump" / f"contacts.{step}.txt") if case.output.contacts else None
                k = w.t
                w.append(step * dt, step, controls={c: v[k] if k < len(v) else np.nan for c, v in controls.items()},
                         contacts=contacts, **arrays)
            for name, series in extras.get("walls", {}).items():
                series = dict(series)
                w.write_wall(name, series.pop("time"), **series)
        return run_dir / "frames.h5"


class DumpOutput:
    """The run's frames as a scene reads them (orchestrator.scenes.base.EngineOutput)."""

    def __init__(self, run_dir: Path, snaps: list, cols: list[str], ids: np.ndarray):
        self.run_dir = Path(run_dir)
        self._snaps, self._cols = snaps, cols
        self._row = {int(i): k for k, i in enumerate(ids)}
        self._n = len(ids)
        self.frame_steps = np.array([st for st, _ in snaps], dtype=np.int64)

    def positions(self, k: int) -> np.ndarray:
        a = self._snaps[k][1]
        out = np.full((self._n, 3), np.nan)
        rows = [self._row[int(i)] for i in a[:, self._cols.index("id")]]
        out[rows] = a[:, [self._cols.index(c) for c in ("x", "y", "z")]]
        return out

    def wall_rows(self) -> np.ndarray | None:
        return wall_rows(self.run_dir)


def dump_columns(case) -> list[str]:
    """The per-atom columns the case needs in LIGGGHTS' dump (id first)."""
    cols = ["id"]
    for field in _fields(case):
        cols += list(COLUMNS.get(field, ()))
    if case.output.stress:
        cols += ["radius"] + [f"c_pstress[{k}]" for k in range(1, 7)]
    if getattr(getattr(case.scene, "particles", None), "shape", None) == "clumps":
        # inserted clumps: the body each member belongs to (fix multisphere keeps it in the molecule
        # id), the body's mass (every member carries it) and the member radius (particles.txt and
        # the clump map are written from the first frame: engines/liggghts/triaxial.py)
        cols += ["mol", "mass"] + ([] if "radius" in cols else ["radius"])
    return cols


def _inserted(params) -> bool:
    """True when the deck inserts its particles itself (no read_data file)."""
    sc = params.get("scene", {})
    return bool(sc.get("clumps") and sc["clumps"].get("inserted"))


#: frames.h5 fields LIGGGHTS' dump custom gives (spheres: no orientation)
FRAME_FIELDS = ("position", "velocity", "angular_velocity", "force", "torque", "stress")


def _fields(case) -> list[str]:
    return case.output.fields(FRAME_FIELDS)


def _deck_beside(log: Path):
    for name in ("resume.in", "deck.in"):
        p = Path(log).parent / name
        if p.exists():
            return p
    return None


def write_data_file(path: Path, table_path: Path, lo, hi):
    """Turn the particle table into a LIGGGHTS ``read_data`` file (atom_style granular:
    ``id type diameter density x y z``; ``Velocities``: ``id vx vy vz wx wy wz``)."""
    t = read_particle_table(table_path)
    n = len(t["id"])
    lo, hi = [float(v) for v in lo], [float(v) for v in hi]
    f = lambda x: repr(float(x))  # full precision, plain Python floats
    out = [f"LIGGGHTS data file written by orchestrator from {table_path.name}", "",
           f"{n} atoms", "2 atom types", "",
           f"{lo[0]!r} {hi[0]!r} xlo xhi", f"{lo[1]!r} {hi[1]!r} ylo yhi", f"{lo[2]!r} {hi[2]!r} zlo zhi",
           "", "Atoms", ""]
    for k in range(n):
        x, y, z = t["position"][k]
        out.append(f"{t['id'][k]} 1 {f(2 * t['radius'][k])} {f(t['density'][k])} {f(x)} {f(y)} {f(z)}")
    out += ["", "Velocities", ""]
    for k in range(n):
        vx, vy, vz = t["velocity"][k]
        out.append(f"{t['id'][k]} {f(vx)} {f(vy)} {f(vz)} 0.0 0.0 0.0")
    write_text(path, "\n".join(out) + "\n")


def read_contacts(path) -> dict | None:
    """One frame of ``compute pair/gran/local pos id force_normal force_tangential contactPoint``
    (dump local): ids i, j; contact point; unit normal from i to j; normal and tangential force
    on i. None when the file is missing."""
    path = Path(path)
    if not path.exists():
        return None
    lines = path.read_bytes().split(b"\n", 9)
    n = int(lines[3])
    a = np.array(lines[9].split(), dtype=np.float64).reshape(n, 18) if n else np.zeros((0, 18))
    d = a[:, 3:6] - a[:, 0:3]
    normal = d / np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
    return {"i": a[:, 6].astype(np.int64), "j": a[:, 7].astype(np.int64), "point": a[:, 15:18],
            "normal": normal, "fn": a[:, 9:12], "ft": a[:, 12:15]}
