"""YADE 2023.02 adapter (Debian ``yade``, its own python3.11 and numpy 1.24).

Render: ``templates/yade/<scene>.py.j2``; the script reads the orchestrator's particle table.
Run: ``yade -n -x script.py`` (``-j N`` threads), progress from ``PROGRESS <iter>`` lines.
Parse: frame chunks ``dump/chunk.<iter>.npz`` into frames.h5. Resume: ``checkpoint.yade.gz``
written by ``O.save`` (atomic rename) and reloaded with ``O.load``.
"""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np

from orchestrator.frames import FrameWriter
from orchestrator.particles_io import read_particle_table
from orchestrator.registry import get_scene

from ..base import Engine, EngineError, Substitution, UnsupportedFeature, tail
from ..render import render_template
from .numbers import yade_numbers, seed_term_ratios
from .output import ChunkOutput, chunk_files, membrane_series

#: the step counter the progress lines follow: the runtime's ``PROGRESS <iter>``, and the triaxial
#: deck's ``RESUMED at iter <iter>`` (a resumed run's lines start there, not at 0)
_PROGRESS = re.compile(r"^(?:PROGRESS|RESUMED at iter) (\d+)")
#: the decks' Python (controllers, membrane, recorder, monitors), copied beside every script
RUNTIME = Path(__file__).resolve().parents[1] / "yade_runtime"


class Yade(Engine):
    name = "yade"
    executable = "yade"
    throughput = 1.5e6      # ENGINES.md: 2000 dense Hertz spheres on one core of this machine
    startup = 2.0
    # a Body, State, Shape and Material object per sphere and ~6 Interactions of ~0.5 kB (IGeom + IPhys)
    bytes_per_particle = 5_000
    base_bytes = 300e6
    parse_copies = 1
    capabilities = {
        "hertz": "Ip2_FrictMat_FrictMat_MindlinPhys + Law2_ScGeom_MindlinPhys_Mindlin",
        "restitution_damping": "Mindlin en/es (Tsuji damping); the tensile damping force is not clipped, so e_n = en exactly",
        "low_restitution": "Mindlin en has no lower bound",
        "sliding_friction": "Mindlin shear spring with Coulomb limit",
        "tangential_history_force": "Law2_ScGeom_MindlinPhys_Mindlin: the shear force, turned with the contact "
                                    "and incremented by k_t(delta) du_t (its only form)",
        "adhesion": "Mindlin includeAdhesion (DMT, F = 4 pi gamma R*, constant per contact)",
        "plane_wall": "utils.wall",
        "cylinder_wall": "geom.facetCylinder",
        "mesh_walls": "ymport.stl / utils.facet",
        "rotating_walls": "RotationEngine",
        "servo_wall": "ServoPIDController",
        "membrane": "GridNode/GridConnection/PFacet with nodal pressure forces",
        "clumps": "Clump",
        "placed_clumps": "O.bodies.clump(member ids) on spheres placed by the orchestrator",
        "particle_stress": "bodyStressTensors()",
        "contact_output": "O.interactions",
        "periodic": "O.periodic",
    }
    tangential_history = "force"         # Law2_ScGeom_MindlinPhys_Mindlin increments the shear force
    substitutes = {
        "rolling_friction": {
            "mindlin_moment": "Mindlin includeMoment: one absolute krot for all contacts, limit from |Fn|, no dashpot",
        },
        "rolling_friction_load": {
            "mindlin_moment": "Mindlin includeMoment with a constant μ_rol at the expected overlap",
        },
        "torsion_friction": {
            "mindlin_ktwist_elastic": "Mindlin ktwist: elastic twisting spring with no limit",
        },
        "membrane": {
            "shell_pressure": "instead of the PFacet membrane (which YADE has), the LIGGGHTS deck's lateral "
                              "boundary: radial forces p·(cell envelope area)·r_i²/Σr_j² on the outer shell of "
                              "grains of each band x sector cell (yade_runtime/shell.py), for like-for-like "
                              "comparisons; only when named as yade.membrane",
        },
        "seed000_damping": {
            "tsuji_restitution": "Tsuji damping (force ∝ δ^1/4 δ̇) with the restitution that seed 000's "
                                 "γ_n = sqrt(4/3 E* m*) delivers, instead of force ∝ δ^1/2 δ̇",
        },
    }

    def check(self, features, accepted):
        """As :meth:`Engine.check`; a case may also name ``yade.membrane: shell_pressure`` although
        YADE has a membrane: the substitution is then recorded like any other."""
        subs = super().check(features, accepted)
        choice = accepted.get(f"{self.name}.membrane")
        if "membrane" in features and choice is not None:
            offered = self.substitutes["membrane"]
            if choice not in offered:
                raise UnsupportedFeature(f"contact.substitutes: '{self.name}.membrane: {choice}' is not offered by "
                                         f"{self.name}; it offers " + "; ".join(f"'{k}': {v}" for k, v in offered.items()))
            subs.append(Substitution("membrane", choice, offered[choice]))
        return subs

    def _probe_version(self) -> str:
        try:
            out = subprocess.run([self.executable, "--version"], capture_output=True, text=True, timeout=60).stdout
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise EngineError(f"cannot run {self.executable}: {exc}") from None
        m = re.search(r"Yade version:\s*(\S+)", out)
        return f"YADE {m.group(1)}" if m else "unknown"

    def engine_params(self, case, params):
        return yade_numbers(case, params)

    def seed_term_ratios(self, case, params, overlaps):
        return seed_term_ratios(case, params, overlaps)

    def render(self, case, params, run_dir: Path, resume=None) -> Path:
        run_dir = Path(run_dir)
        (run_dir / "dump").mkdir(exist_ok=True)
        sc = params["scene"]
        o = case.output
        fields = o.fields()
        n = max(1, len(sc.get("ids", [])) or 1)
        ctx = {
            "case": case, "p": params, "engine": self.engine_params(case, params), "resume": resume,
            "files": {k: Path(v).name for k, v in params.get("files", {}).items()},
            "dump_every": sc["dump_every"], "thermo_every": max(1, sc["steps"] // 200),
            "restart_every": max(1, sc.get("restart_every", sc["steps"] // 10)),
            "yade_fields": fields, "yade_contacts": bool(o.contacts),
            # keep a chunk under ~20 MB of doubles
            "chunk_frames": int(max(1, min(256, 20e6 / (8 * 13 * n)))),
            # triaxial lateral boundary: the PFacet membrane, or the LIGGGHTS deck's shell pressure
            "yade_shell": case.contact.substitutes.get("yade.membrane") == "shell_pressure",
        }
        script = run_dir / ("resume.py" if resume else "script.py")
        shutil.copytree(RUNTIME, run_dir / "yade_runtime", dirs_exist_ok=True,
                        ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        render_template(f"yade/{case.scene.kind}.py.j2", ctx, script)
        return script

    def print_monitors(self, deck_text: str, overlap_limit: float) -> str:
        """The monitor settings (``ORCH_MON``, read by yade_runtime/monitors.py) get the overlap
        limit and ``print_figures`` (an ORCH_OV line at every check)."""
        return re.sub(r"^(ORCH_MON = json\.loads\(.*\)\n)",
                      lambda m: m.group(1) + f"ORCH_MON['overlap_limit'] = {overlap_limit!r}\nORCH_MON['print_figures'] = True\n",
                      deck_text, count=1, flags=re.M)

    def command(self, deck: Path, case) -> list[str]:
        return [self.executable, "-n", "-j", str(case.engine_options.threads), "-x", deck.name]

    def progress_step(self, line: str):
        m = _PROGRESS.match(line)
        return int(m.group(1)) if m else None

    def explain_failure(self, log: Path) -> str:
        text = Path(log).read_text(errors="replace") if Path(log).exists() else ""
        m = re.findall(r'File "(script\.py|resume\.py)", line (\d+)', text)
        msg = ""
        if m:
            fname, line = m[-1]
            try:
                src = (Path(log).parent / fname).read_text().splitlines()[int(line) - 1]
                msg = f"in {fname} line {line}: {src.strip()}\n"
            except (OSError, IndexError):
                pass
        return msg + tail(log)

    def loop_time(self, log: Path) -> float:
        """Seconds YADE spent in O.run (the script prints LOOP_TIME)."""
        text = Path(log).read_text(errors="replace") if Path(log).exists() else ""
        return sum(float(x) for x in re.findall(r"^LOOP_TIME ([0-9.eE+-]+)", text, flags=re.M))

    def resume_state(self, run_dir: Path):
        ck = Path(run_dir) / "checkpoint.yade.gz"
        if not ck.exists():
            return None
        return {"checkpoint": ck.name, "candidates": [ck.name]}

    def prepare_resume(self, run_dir: Path, resume: dict):
        """Drop frame chunks written after the checkpoint (they will be written again); a fresh
        start (step < 0) drops them all."""
        ck = Path(run_dir) / "checkpoint.yade.gz"
        ck_time = ck.stat().st_mtime if resume.get("step", 0) >= 0 and ck.exists() else float("-inf")
        for f in chunk_files(run_dir):
            if f.stat().st_mtime > ck_time:
                f.unlink()

    def parse(self, case, params, run_dir: Path, meta: dict) -> Path:
        run_dir = Path(run_dir)
        chunks = chunk_files(run_dir)
        if not chunks:
            raise EngineError(f"{run_dir}/dump: YADE wrote no frames\n{tail(run_dir / 'engine.log')}")
        table = read_particle_table(run_dir / "particles.txt")
        ids = table["id"]
        mass = table["mass"]
        extras = get_scene(case.scene.kind).post(run_dir, params, ChunkOutput(run_dir))
        membrane = membrane_series(run_dir)
        if membrane is not None:                # the triaxial membrane's nodes at the frame times
            extras.setdefault("walls", {})["membrane"] = membrane
        controls = extras.get("controls", {})
        first = np.load(chunks[0])
        fields = [f for f in ("position", "velocity", "angular_velocity", "orientation", "force", "torque",
                              "stress") if f in first.files]
        has_contacts = "c_count" in first.files
        seen = set()
        with FrameWriter(run_dir / "frames.h5", ids, table["radius"], fields=fields,
                         controls=controls.keys(), mass=mass, meta=meta) as w:
            for c in chunks:
                with np.load(c) as z:          # NpzFile re-reads a member on every access
                    d = {k: z[k] for k in z.files}
                if has_contacts:
                    off = np.concatenate([[0], np.cumsum(d["c_count"])]).astype(int)
                for k in range(len(d["iter"])):
                    it = int(d["iter"][k])
                    if it in seen:
                        continue
                    seen.add(it)
                    kk = w.t
                    contacts = None
                    if has_contacts:       # grain-grain contacts of this frame (Recorder.grab_contacts)
                        sl = slice(off[k], off[k + 1])
                        contacts = {key: d["c_" + key][sl] for key in ("i", "j", "point", "normal", "fn", "ft")}
                        for key in ("point", "normal", "fn", "ft"):
                            contacts[key] = contacts[key].reshape(-1, 3)
                    w.append(float(d["time"][k]), it,
                             controls={n: v[kk] if kk < len(v) else np.nan for n, v in controls.items()},
                             contacts=contacts, **{f: d[f][k] for f in fields})
            for name, series in extras.get("walls", {}).items():
                series = dict(series)
                w.write_wall(name, series.pop("time"), **series)
        return run_dir / "frames.h5"
