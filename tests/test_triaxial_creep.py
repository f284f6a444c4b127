"""The volume-creep test of the triaxial's drag stage (``scene.isotropic.creep_tolerance``, issue #14):
the drag-supported sample creeps (densifies) long after its stresses converge and collapses once the
drag goes, so the drag stage may also wait until the chunk-mean boundary volume stops changing.

Checked: the option reaches the params only when asked (runs without it keep their hash and deck),
a case without a drag stage is refused, LIGGGHTS' resume line carries the last chunk-mean volume,
and on a real LIGGGHTS run the creep the deck prints after every chunk is the change of the chunk
means of the boundary volume computed here from ``triax.txt``, and the drag stage ends at the first
chunk that passes both tests (the YADE controller's run is in the slow tier).
"""
from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from orchestrator.case import CaseError, load_case
from orchestrator.derive import derive

REPO = Path(__file__).resolve().parents[1]
SMOKE = REPO / "cases" / "triaxial_smoke.yaml"
TOL = 2e-3


def _case(**iso):
    # 150 grains, the drag switched off at once (no 76 800-step ramp), 0.2 % of loading: a short run
    scene = {"grains": 150, "axial_strain": 0.002, "frames": 2,
             "isotropic": {"max_chunks": 8, "drag_ramp": 0, **iso}}
    return load_case(SMOKE, overrides={"scene": scene})


def test_creep_tolerance_reaches_the_params_only_when_asked():
    assert "creep_tolerance" not in derive(load_case(SMOKE))["scene"]["iso"]
    assert derive(_case(creep_tolerance=TOL))["scene"]["iso"]["creep_tolerance"] == TOL


def test_creep_tolerance_without_a_drag_stage_is_refused():
    """Asked for but without a drag stage to test, the option would be dropped silently: the case is
    refused, naming the file and the field."""
    with pytest.raises(CaseError, match=r"(?s)triaxial_smoke.yaml.*creep_tolerance .* no drag stage"):
        _case(creep_tolerance=TOL, drag=False)


def test_liggghts_resume_line_carries_the_last_chunk_volume(tmp_path):
    from engines.liggghts.triaxial import read_restart_states
    (tmp_path / "restart").mkdir()
    (tmp_path / "restart" / "state.txt").write_text(
        "3840 1 1 1 -1 0.25 -0.001 0 0 0.5 0.01\n"                                   # without the creep test
        "7680 1 2 1 -1 0.5 -0.002 0 0 0.75 0.01 2.81234567890123e-08\n")               # with it
    st = read_restart_states(tmp_path)
    assert "vprev" not in st[3840]["text"]
    assert st[7680]["text"]["vprev"] == "2.81234567890123e-08" and st[7680]["chunks"] == 2


#: the creep tolerance per engine: stresses within 10 % from chunk 2 on while the volume still creeps,
#: so the drag must wait (measured: LIGGGHTS' shell sample 4-8e-4 per chunk, passing at chunk 4; YADE's
#: membrane sample 2.3-7.7e-3, passing at chunk 8: the membrane creeps more, docs/triaxial.md)
CREEP_TOL = {"liggghts": 4.5e-4, "yade": 2.4e-3}


@pytest.mark.engine
@pytest.mark.parametrize("eng", ["liggghts", pytest.param("yade", marks=pytest.mark.slow)])
def test_drag_stage_waits_for_the_volume_creep_to_stop(eng, tmp_path):
    from orchestrator.runner import run_case
    if shutil.which(eng) is None:
        pytest.fail(f"{eng} is not installed; run `bash .ci/setup`")
    tol = CREEP_TOL[eng]
    case = _case(creep_tolerance=tol, tolerance=0.1)
    out = run_case(case, eng, runs_root=tmp_path, progress=False, analyze=False)
    assert out.status == "complete", out.status
    log = (out.run_dir / "engine.log").read_text(errors="replace")
    iso = derive(case)["scene"]["iso"]
    chunk = iso["chunk"]
    # the chunk means of the boundary volume from the series (the rows of each chunk: its
    # series_every samples after its start, as the deck's fix ave/time and YADE's chunk rows take them)
    a = np.loadtxt(out.run_dir / "triax.txt", comments="#", ndmin=2)
    step, stage, vol = a[:, 0].astype(int), a[:, 2], a[:, 9]
    printed = [float("nan") if x == "n/a" else float(x)
               for x in re.findall(r"^ISO creep: chunk-mean volume change (\S+)", log, re.M)]
    assert np.isnan(printed[0]) and not np.isnan(printed[1:]).any()        # no change to give for the first
    tested = [int(k) for k in re.findall(r"^ISO chunk (\d+):", log, re.M)]
    assert printed and len(printed) == len(tested)
    # chunk windows (end - chunk, end] at every multiple of the chunk in stage 1 (a YADE row is stamped
    # with the step it ends, so its windows may sit one step later): the printed creep must be the
    # change of consecutive window means, for the windows of the tested chunks
    def matches(shift):
        ends = np.arange(chunk, step[stage == 1].max() + 1, chunk) + shift
        means = np.array([vol[(step > e - chunk) & (step <= e) & (stage == 1)].mean() for e in ends])
        change = means[1:] / means[:-1] - 1
        for j0 in range(len(change) - len(printed) + 2):
            if np.allclose(printed[1:], change[j0:j0 + len(printed) - 1], rtol=1e-6, atol=1e-12):
                return True
        return False
    assert matches(0) or matches(1), f"printed creep {printed} is not the change of the chunk-mean volumes"
    # the drag went at the first chunk whose stresses and creep both passed; not before
    conv = re.findall(r"^ISO chunk (\d+): sigma1/p = (\S+) sigma3/p = (\S+)", log, re.M)
    ok = [abs(float(s1) - 1) < iso["tolerance"] and abs(float(s3) - 1) < iso["tolerance"] for _, s1, s3 in conv]
    still = [k > 0 and abs(printed[k]) < tol for k in range(len(printed))]
    off = [m.start() for m in re.finditer(r"^ISO converged with drag: drag off", log, re.M)]
    both = [k for k in range(len(ok)) if ok[k] and still[k]]
    waited = [k for k in range(len(ok)) if ok[k] and not still[k]]
    assert both and off, "no chunk passed both tests: the drag never went (retune the case above)"
    assert waited and waited[0] < both[0], "the stresses never passed before the creep did: nothing was waited for"
    # the chunk whose test switched the drag off is the first that passed both, and every converged
    # chunk before it was told to wait
    before = log[:off[0]]
    assert len(re.findall(r"^ISO chunk \d+:", before, re.M)) == both[0] + 1
    assert len(re.findall(r"^ISO converged with drag, still creeping", before, re.M)) == len(
        [k for k in waited if k < both[0]])
