"""Engine failures come back as one clear error: exit status, the engine's own message, the deck
line it choked on, the log's last lines; a hung engine is killed at its wall-clock limit."""
from __future__ import annotations

from pathlib import Path

import pytest

from engines import get_engine
from engines.base import EngineError
from orchestrator.case import load_case

pytestmark = pytest.mark.engine
CASE = Path(__file__).resolve().parents[1] / "cases" / "verification" / "chung_ooi_2_sphere_plane_alumina.yaml"


def test_liggghts_error_names_message_and_deck_line(tmp_path, engines_installed):
    deck = tmp_path / "deck.in"
    deck.write_text("units si\natom_style granular\nregion r block 0 1 0 1 0 1\ncreate_box 1 r\n"
                    "fix broken all nonexistent/style 1 2 3\n")
    with pytest.raises(EngineError) as exc:
        get_engine("liggghts").run(deck, load_case(CASE), 10, tmp_path / "engine.log", timeout=60, progress=False)
    msg = str(exc.value)
    assert "exit status 1" in msg
    assert "LIGGGHTS says: ERROR" in msg and "Invalid fix style" in msg
    assert "fix broken all nonexistent/style" in msg          # the deck line
    assert "last lines of" in msg


def test_lammps_error_names_message_and_deck_line(tmp_path, engines_installed):
    deck = tmp_path / "deck.in"
    deck.write_text("units si\natom_style sphere\nregion r block 0 1 0 1 0 1\ncreate_box 1 r\n"
                    "fix broken all nonexistent/style 1 2 3\n")
    with pytest.raises(EngineError) as exc:
        get_engine("lammps").run(deck, load_case(CASE), 10, tmp_path / "engine.log", timeout=60, progress=False)
    msg = str(exc.value)
    assert "exit status 1" in msg
    assert "LAMMPS says: ERROR" in msg and "nonexistent/style" in msg
    assert "on deck.in line 5: fix broken all nonexistent/style 1 2 3" in msg          # the deck line
    assert "last lines of" in msg


def test_yade_error_names_script_line(tmp_path, engines_installed):
    script = tmp_path / "script.py"
    script.write_text("from yade import *\nO.dt = 1e-6\nraise ValueError('bad parameter in the scene')\n")
    with pytest.raises(EngineError) as exc:
        get_engine("yade").run(script, load_case(CASE), 10, tmp_path / "engine.log", timeout=120, progress=False)
    msg = str(exc.value)
    assert "exit status 1" in msg
    assert "bad parameter in the scene" in msg
    assert "script.py line 3" in msg


def test_hung_engine_is_killed_at_timeout(tmp_path, engines_installed):
    script = tmp_path / "script.py"
    script.write_text("import time\nwhile True:\n    time.sleep(0.1)\n")
    with pytest.raises(EngineError, match="wall-clock limit of 3 s"):
        get_engine("yade").run(script, load_case(CASE), 10, tmp_path / "engine.log", timeout=3, progress=False)
