"""Shared fixtures. Engine tests run the real `liggghts` and `yade` binaries: a missing engine is
a failure, not a skip (the README's set-up command installs both)."""
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
    missing = [e for e in ("liggghts", "yade") if shutil.which(e) is None]
    if missing:
        pytest.fail(f"engine(s) not installed: {missing}; run `bash .ci/setup` (README)")
    return True
