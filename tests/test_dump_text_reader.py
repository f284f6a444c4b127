"""The text ``dump custom`` reader (engines/lammps_dump.read_dump): its compiled fast parser
(engines/_textparse.py) gives bit for bit the doubles Python's ``float`` gives, hands what it cannot
convert exactly to the general parser, and names a truncated file."""
from __future__ import annotations

import numpy as np
import pytest

from engines import _textparse
from engines.lammps_dump import DumpError, read_dump

COLS = "id type x y z vx vy vz fx fy fz radius".split()


def write_dump(path, rows, fmt="%g", n=None, cols=COLS):
    head = (f"ITEM: TIMESTEP\n1234\nITEM: NUMBER OF ATOMS\n{len(rows) if n is None else n}\n"
            "ITEM: BOX BOUNDS ff ff ff\n0 1\n0 1\n0 1\nITEM: ATOMS " + " ".join(cols) + " \n")
    body = "\n".join(" ".join(fmt % v for v in r) + " " for r in rows)
    path.write_text(head + body + "\n")
    return head + body


def rng_rows(n, seed=1):
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((n, len(COLS))) * 10.0 ** rng.integers(-12, 12, (n, len(COLS)))
    a[:, 0] = np.arange(1, n + 1)
    a[:, 1] = 1
    a[::7, 5] = 0.0
    a[::11, 6] = -0.0
    return a


@pytest.mark.parametrize("fmt", ["%g", "%.10g", "%.15g", "%.6e", "%.3f", "%.16e"])
def test_large_dump_parses_to_the_doubles_python_reads(tmp_path, fmt):
    rows = rng_rows(3000)                      # 36 000 numbers: the compiled path
    text = write_dump(tmp_path / "d.txt", rows, fmt)
    step, cols, a = read_dump(tmp_path / "d.txt")
    want = np.array([float(t) for t in text.split("radius \n", 1)[1].split()]).reshape(a.shape)
    assert step == 1234 and cols == COLS
    assert np.array_equal(a.view(np.int64), want.view(np.int64))          # bit for bit, -0.0 too


def test_fast_parser_declines_what_it_cannot_convert_exactly():
    out = _textparse.parse(b"1 2.5 -3e-4\n", 3)
    assert np.array_equal(out, [1.0, 2.5, -3e-4])
    for tok in (b"0.10000000000000001", b"nan", b"-inf", b"1.5x", b"1e400", b"ITEM:", b"e5", b"."):
        assert _textparse.parse(b"1 " + tok + b" 2\n", 3) is None, tok
    assert _textparse.parse(b"1 2 3 4\n", 3) == 4                          # count, not an array
    # 17 significant digits: outside the fast path, the general parser is exact
    assert _textparse.parse(b"0.30000000000000004", 1) is None


def test_nan_and_17_digit_values_go_through_the_general_parser(tmp_path):
    rows = rng_rows(2000)
    rows[5, 4] = np.nan
    text = write_dump(tmp_path / "d.txt", rows, "%.17g")
    _, _, a = read_dump(tmp_path / "d.txt")
    want = np.array([float(t) for t in text.split("radius \n", 1)[1].split()]).reshape(a.shape)
    assert np.isnan(a[5, 4])
    ok = ~np.isnan(want)
    assert np.array_equal(a[ok], want[ok])


def test_truncated_large_dump_is_named_with_its_count(tmp_path):
    rows = rng_rows(2000)
    write_dump(tmp_path / "d.txt", rows[:-1], n=2000)
    with pytest.raises(DumpError, match=r"d.txt: truncated dump \(23988 numbers for 2000 atoms x 12"):
        read_dump(tmp_path / "d.txt")


def test_small_and_empty_dumps(tmp_path):
    rows = rng_rows(3)
    write_dump(tmp_path / "s.txt", rows, "%.17g")
    _, _, a = read_dump(tmp_path / "s.txt")
    assert np.array_equal(a, rows)
    write_dump(tmp_path / "e.txt", [], n=0)
    step, cols, a = read_dump(tmp_path / "e.txt")
    assert a.shape == (0, 12)
    (tmp_path / "h.txt").write_text("ITEM: TIMESTEP\n5\nITEM: NUMBER OF ATOMS\n")
    with pytest.raises(DumpError, match="h.txt: truncated dump"):
        read_dump(tmp_path / "h.txt")
