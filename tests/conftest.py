"""Shared fixtures. Engine tests run the real `liggghts`, `yade` and `lmp` binaries: a missing engine
is a failure, not a skip (the README's set-up command installs all three)."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CASES = REPO / "cases"


@pytest.fixture(scope="session")
def runs_root(tmp_path_factory) -> Path:
    """One runs/ directory for the session, so engine runs are shared between tests."""
    return tmp_path_factory.mktemp("runs")


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
    schedule_groups(items)


def schedule_groups(items) -> None:
    """Scheduling for the two xdist workers (``--dist loadgroup --no-loadscope-reorder``,
    pyproject.toml): each test file is one group, so a file's module fixtures (shared engine runs)
    stay in one process, as with ``loadfile``; a file that sets ``SPLIT_BY_ENGINE = True`` is one
    group per value of its ``eng`` parameter instead (the YADE triaxial smoke run alone takes ~6 min:
    it must not queue behind the LIGGGHTS one on the same worker). xdist hands groups out in
    collection order, so the groups are sorted longest first (a long group started last is the
    whole suite's tail) by the module's ``SCHEDULE_MINUTES``: its expected minutes on a quiet
    2-core machine, a number or a dict by engine (0 when absent). Files that share a session fixture
    (one engine run reused by several files) name one ``SCHEDULE_GROUP`` so that it runs once."""
    def group(it):
        name = getattr(it.module, "SCHEDULE_GROUP", None) or it.nodeid.split("::")[0]
        eng = getattr(getattr(it, "callspec", None), "params", {}).get("eng")
        if getattr(it.module, "SPLIT_BY_ENGINE", False) and eng is not None:
            name += f"::{eng}"
        return name, eng

    def minutes(it, eng):
        m = getattr(it.module, "SCHEDULE_MINUTES", 0)
        return m.get(eng, m.get(None, 0)) if isinstance(m, dict) else m

    order = {}
    for it in items:
        name, eng = group(it)
        it.add_marker(pytest.mark.xdist_group(name))
        order[id(it)] = -minutes(it, eng)
    items.sort(key=lambda it: order[id(it)])                   # stable: order within a group is kept
