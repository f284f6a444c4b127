"""Shared fixtures. Engine tests run the real `liggghts`, `yade` and `lmp` binaries: a missing engine
is a failure, not a skip (the README's set-up command installs all three)."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest

# one BLAS thread per test process, set before numpy is first imported: the two xdist workers fill
# the two cores, and OpenBLAS threads spinning beside them slowed a small lstsq (the CT shape fit)
# from 0.04 s to 1.7 s on a busy machine
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# the engine runs of the suite record this machine's speed (orchestrator.clock.record_speed) in a
# file of their own, so that neither the user's record nor the estimates the tests check change; one
# per process: an xdist worker inherits the controller's environment, and with one file for both
# workers a run one of them finished between two estimates of a test of the other's changed the
# second (session 38: `convergence --dry-run`'s 0.636 s against `estimate`'s 0.624 s, one test apart)
if os.environ.get("_ORCHESTRATOR_TEST_SPEED", "") == os.environ.get("ORCHESTRATOR_MACHINE_SPEED", ""):
    os.environ["ORCHESTRATOR_MACHINE_SPEED"] = os.environ["_ORCHESTRATOR_TEST_SPEED"] = os.path.join(
        tempfile.mkdtemp(prefix="orchestrator-speed-"), "machine_speed.json")

REPO = Path(__file__).resolve().parents[1]
CASES = REPO / "cases"


@pytest.fixture(scope="session")
def runs_root(tmp_path_factory) -> Path:
    """One runs/ directory for the whole session, so engine runs are shared between tests, and
    between the two xdist workers: each worker's base temp is ``pytest-N/popen-gwK``, and their
    common parent ``pytest-N`` belongs to this session alone. A case one worker is running, the other
    waits for (the run directory's lock) and then reuses, as `orchestrator run` does for two
    processes (orchestrator/runner.py; tests/test_faults.py, three runs at once); before, the
    two workers each ran the cases their files share (the shear-cell smoke case on two engines)
    whenever xdist put those files on different workers."""
    base = tmp_path_factory.getbasetemp()
    root = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "runs"
    root.mkdir(exist_ok=True)
    return root


@pytest.fixture(scope="session")
def engines_installed():
    from engines import engine_names, get_engine
    missing = [e for e in engine_names() if not get_engine(e).available()]
    if missing:
        pytest.fail(f"engine(s) not installed: {missing}; run `bash .ci/setup` (README)")
    return True


def pytest_collection_modifyitems(config, items):
    """Every test that needs the engines (the ``engines_installed`` fixture, directly or through a
    fixture that runs one) carries the ``engine`` marker, so ``-m "not engine"`` (the fast tier,
    README) never starts an engine: an unmarked one is a collection error naming it."""
    bad = [it.nodeid for it in items if "engines_installed" in getattr(it, "fixturenames", ())
           and it.get_closest_marker("engine") is None]
    if bad:
        raise pytest.UsageError("tests that start an engine without @pytest.mark.engine: " + ", ".join(bad))
    deselect_slow_unless_asked(config, items)
    schedule_groups(items)


def deselect_slow_unless_asked(config, items) -> None:
    """The ``slow`` tier (long validation runs) runs only when the ``-m`` expression names it
    (``-m slow``, ``-m "slow or not slow"``): so ``pytest``, ``pytest -m engine`` and the fast tier
    ``pytest -m "not engine"`` (README) leave it out, whatever else ``-m`` selects."""
    if "slow" in (config.option.markexpr or ""):
        return
    slow = [it for it in items if it.get_closest_marker("slow") is not None]
    if slow:
        config.hook.pytest_deselected(items=slow)
        items[:] = [it for it in items if it.get_closest_marker("slow") is None]


def schedule_groups(items) -> None:
    """Scheduling for the two xdist workers (``--dist loadfile --no-loadscope-reorder``,
    pyproject.toml): xdist hands out test files in collection order, so the items are sorted
    longest file first (a long file started last is the whole suite's tail) by the module's
    ``SCHEDULE_MINUTES``: its expected minutes on a quiet 2-core machine, a number or a dict by
    the ``eng`` parameter (0 when absent). (``--dist loadgroup`` with one group per engine was tried
    on 24 Nov 2026: xdist's worker hook adds the group suffix before a conftest hook can mark the
    items, so the groups were ignored and every test went to either worker.)"""
    def minutes(it):
        m = getattr(it.module, "SCHEDULE_MINUTES", 0)
        if isinstance(m, dict):
            eng = getattr(getattr(it, "callspec", None), "params", {}).get("eng")
            return max(m.values()) if eng is None else m.get(eng, 0)
        return m

    order = {id(it): -minutes(it) for it in items}
    items.sort(key=lambda it: order[id(it)])                   # stable: order within a file is kept
