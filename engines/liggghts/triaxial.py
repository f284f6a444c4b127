"""LIGGGHTS' side of the triaxial deck (templates/liggghts/triaxial.in.j2): the inserted-clumps
substitute's check and particle table, and the stage state that makes a restart file resumable.

Everything here reads files the LIGGGHTS deck writes; the scene (orchestrator.scenes.triaxial)
never sees them.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from orchestrator.atomic import write_json, write_text
from orchestrator.particles_io import read_particle_table, write_particle_table

from ..base import EngineError
from ..lammps_dump import read_binary_dump
from .segments import dump_segments


def check_inserted_clumps(run_dir, params) -> None:
    """Inserted clumps (substitute ``inserted_clumps``): LIGGGHTS numbered the member spheres it
    inserted, so the run's particle table and clump map are written from its first frame (taken when
    stage 1 starts, after the insertion and the platens' closing; the members have not moved): ``particles.txt`` (member id, radius [m], density [kg/m^3], position
    [m] in that frame), ``clumps.txt`` (member id, clump index 0 ... n-1 = LIGGGHTS body id - 1) and,
    in YADE's format, ``dump/clumps_start.txt`` / ``clumps_end.txt`` (body id, mass [kg] as LIGGGHTS
    carries it on the members in the first / last frame, principal moments of inertia [kg m^2] of the
    template it was inserted from (what LIGGGHTS was given), member ids). The orchestrator's placed
    packing (prepare) is kept as ``particles_placed.txt`` / ``clumps_placed.txt``. Stops with the
    deck's fix named when the first frame holds fewer clumps than asked (the deck itself stops with
    an ERROR line right after an incomplete insertion)."""
    sc = params["scene"]
    C = (sc.get("clumps") or {}).get("inserted")
    if not C:
        return
    run_dir = Path(run_dir)
    hint = ("raise scene.particles.insertion_attempts or lower scene.packing_fraction (the sample is sized so "
            "that the clumps' bounding spheres fill it at packing_fraction)")
    cols = json.loads((run_dir / "dump" / "columns.json").read_text())
    first = last = None
    for frame in read_binary_dump(dump_segments(run_dir), len(cols)):    # only the first and last are kept
        first = first or frame
        last = frame
    if first is None:
        raise EngineError(f"{run_dir / 'dump'}: LIGGGHTS wrote no frames")
    (step0, a0), (_, a1) = first, last
    col = {c: cols.index(c) for c in ("id", "mol", "mass", "radius", "x", "y", "z")}
    ids = a0[:, col["id"]].astype(np.int64)
    mol = a0[:, col["mol"]].astype(np.int64)
    bodies = np.unique(mol)
    if len(bodies) != C["count"] or len(ids) != C["members"]:
        raise EngineError(
            f"{run_dir / 'deck.in'}: fix ms_ins (insert/pack): the first frame (step {step0}) holds {len(bodies)} "
            f"of {C['count']} clumps ({len(ids)} of {C['members']} member spheres): {hint}")
    placed = run_dir / "particles_placed.txt"
    if not placed.exists():
        os.replace(run_dir / "particles.txt", placed)
        if (run_dir / "clumps.txt").exists():
            os.replace(run_dir / "clumps.txt", run_dir / "clumps_placed.txt")
    rho = float(read_particle_table(placed)["density"][0])
    write_particle_table(run_dir / "particles.txt", ids, a0[:, col["radius"]], rho,
                         a0[:, [col["x"], col["y"], col["z"]]])
    write_text(run_dir / "clumps.txt", "# member_id clump (LIGGGHTS body id - 1)\n" +
               "".join(f"{i} {m - 1}\n" for i, m in zip(ids, mol)))
    # the template of every body: member count and sorted radii (distinct per shape and size class)
    keys = [(t["nspheres"], np.sort([sp[3] for sp in t["spheres"]])) for t in C["templates"]]
    r0 = a0[:, col["radius"]]

    def template_of(rows):
        rr = np.sort(r0[rows])
        for k, (m, tr) in enumerate(keys):
            if m == len(rr) and np.allclose(rr, tr, rtol=1e-9, atol=0):
                return k
        raise EngineError(f"{run_dir}: a LIGGGHTS body with member radii {rr.tolist()} matches no template")

    by_id1 = {int(i): k for k, i in enumerate(a1[:, col["id"]].astype(np.int64))}
    start, end = [], []
    for b in bodies:
        rows = np.flatnonzero(mol == b)
        t = C["templates"][template_of(rows)]
        mem = " ".join(str(int(i)) for i in np.sort(ids[rows]))
        pr = " ".join("%.17g" % v for v in t["principal"])
        start.append(f"{b} {a0[rows[0], col['mass']]:.17g} {pr} {mem}\n")
        r1 = [by_id1[int(i)] for i in ids[rows] if int(i) in by_id1]
        if r1:
            end.append(f"{b} {a1[r1[0], col['mass']]:.17g} {pr} {mem}\n")
    write_text(run_dir / "dump" / "clumps_start.txt", "".join(start))
    write_text(run_dir / "dump" / "clumps_end.txt", "".join(end))


#: columns of LIGGGHTS' restart/state.txt, one line per restart file (templates/liggghts/triaxial.in.j2):
#: step, stage (1, 2), stage-1 chunks tested, grains' drag on (1/0), step the drag's ramp began (-1:
#: none), sum of the top platen's speed samples [m/s] over steps 0..step and the one of the step,
#: sample height H0 [m], step when loading began (0 before), and the sum of the stage-1 servo's windowed
#: force error over steps 0..step with the one of the step (its integral term)
RESTART_STATE_COLUMNS = ("step", "stage", "chunks", "dragon", "ramp_start", "ztot", "vlast", "H0", "shear_start",
                         "esum", "elast")
#: the column a deck with the creep test (scene.isotropic.creep_tolerance) adds: the last chunk-mean
#: boundary volume [m^3], as printed (text, like TEXT_COLUMNS)
CREEP_COLUMN = "vprev"
#: the columns a deck with inserted clumps adds (after the creep column when both are there): the bottom
#: and top platens' heights [m] once closed on the inserted sample, as printed
CLUMP_COLUMNS = ("zb0", "zt0")
#: the columns a resumed deck sets from their text as LIGGGHTS printed it (15 digits): the deck it
#: resumes gave them the same text (``variable ZS equal ${ztend}``), so both runs hold the same double
TEXT_COLUMNS = ("ztot", "vlast", "H0", "esum", "elast")


def _state_columns(n: int) -> tuple[str, ...] | None:
    """The columns of a state line of ``n`` fields: the base ones, then the creep column, the clump
    columns or both (their counts tell them apart); None for any other count."""
    extra = {0: (), 1: (CREEP_COLUMN,), 2: CLUMP_COLUMNS, 3: (CREEP_COLUMN,) + CLUMP_COLUMNS}
    more = n - len(RESTART_STATE_COLUMNS)
    return RESTART_STATE_COLUMNS + extra[more] if more in extra else None


def read_restart_states(run_dir: Path) -> dict[int, dict]:
    """{step: stage state} from LIGGGHTS' ``restart/state.txt`` (the last line of each step wins:
    a resumed run may write a step again); ``text`` holds the printed text of :data:`TEXT_COLUMNS`."""
    f = Path(run_dir) / "restart" / "state.txt"
    out = {}
    if not f.exists():
        return out
    for line in f.read_text().splitlines():
        parts = line.split()
        cols = _state_columns(len(parts))
        if cols is None:
            continue                                    # a line cut by a kill, or a comment
        try:
            row = dict(zip(cols, (float(x) for x in parts)))
        except ValueError:
            continue
        for k in ("step", "stage", "chunks", "dragon", "ramp_start", "shear_start"):
            row[k] = int(row[k])
        row["text"] = {k: parts[cols.index(k)] for k in TEXT_COLUMNS + (CREEP_COLUMN,) + CLUMP_COLUMNS if k in cols}
        out[row["step"]] = row
    return out


def _keep_rows_upto(path: Path, step: int) -> None:
    """Rewrite a whitespace table whose first column is the step, keeping comment lines and the
    rows with step <= ``step`` (atomic; a last line cut by a kill goes too)."""
    if not path.exists():
        return
    keep = []
    for line in path.read_text().splitlines():
        if line.startswith("#"):
            keep.append(line)
            continue
        try:
            if int(float(line.split()[0])) <= step:
                keep.append(line)
        except (ValueError, IndexError):
            continue
    write_text(path, "\n".join(keep) + ("\n" if keep else ""))


def resume_point(run_dir: Path, resume: dict | None) -> dict | None:
    """Complete LIGGGHTS' resume point for a triaxial run: a restart file is usable only with its line of ``restart/state.txt`` (stage, chunks
    done, drag on/off, the integrated platen velocity, H0 and the loading start: what the resumed
    deck needs to re-enter the right stage); the newest such file is taken (or the one the runner
    asks for when an older one is tried), ``triax.txt`` and ``state.txt`` are cut back to its step.
    With no usable file the run starts afresh, and stale restart files are removed."""
    run_dir = Path(run_dir)
    states = read_restart_states(run_dir)
    if resume is not None:
        step_of = lambda c: int(Path(c).name.split(".")[1])
        wanted = resume.get("restart_file")
        cands = [c for c in resume.get("candidates", [resume.get("restart_file")]) if c and step_of(c) in states]
        if wanted and step_of(wanted) in states:
            cands = [wanted] + [c for c in cands if step_of(c) < step_of(wanted)]
        if cands:
            step = step_of(cands[0])
            resume = dict(resume, restart_file=cands[0], step=step, candidates=cands,
                          scene_state=states[step])
            _keep_rows_upto(run_dir / "triax.txt", step)
            _keep_rows_upto(run_dir / "restart" / "state.txt", step)
            _keep_rows_upto(run_dir / "dump" / "clump_energy.txt", step)     # inserted clumps' energies
            return resume
    # starting afresh: no stale restart file or state line may be picked up later
    for f in (run_dir / "restart").glob("state.*.restart"):
        f.unlink()
    (run_dir / "restart" / "state.txt").unlink(missing_ok=True)
    return None


def clumps_summary(run_dir: Path, params: dict, first_step: int) -> None:
    """The substitute's figures in ``scene_summary.json`` (the runner copies it into summary.json)."""
    C = (params["scene"].get("clumps") or {}).get("inserted")
    f = Path(run_dir) / "scene_summary.json"
    if not C or not f.exists():
        return
    summ = json.loads(f.read_text())
    summ["clumps"] = {"substitute": "inserted_clumps", "clumps": C["count"], "member_spheres": C["members"],
                      "templates": len(C["templates"]), "size_classes": C["classes"],
                      "first_frame_step": int(first_step)}
    write_json(f, summ)
