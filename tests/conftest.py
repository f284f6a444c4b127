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
