"""Golden decks: every engine x scene smoke case renders exactly the committed deck.

The rendered deck (and every other text file the engine's ``render`` writes) is normalised (the
run directory and the package version replaced by placeholders; data files such as particle
tables and meshes are summarised by their text with the numbers taken out, hashed, and three sums
over their numbers) and compared with ``tests/golden/``: the text exactly, every number to a
relative 1e-9. Floating point is not bit-for-bit the same on every CPU: NumPy dispatches SIMD
kernels at run time (its AVX-512 ``power`` differs from the C library's ``pow`` by an ulp), and
numba compiles for the host. Session 37's AMD EPYC rendered the triaxial smoke's packing 1e-12
apart from the machine that wrote the golden files until the packer cubed portably
(``psd.portable_cube``); a difference of that size is not a change of behaviour.

A change to a template, to ``derive`` or to an adapter that changes a deck makes this test fail
and shows the diff. If the change is intended, regenerate the golden files and commit them with
the reason in the commit message::

    .venv/bin/python tests/test_golden_decks.py --update

No engine runs here (engine-free tier): rendering needs neither binary.
"""
from __future__ import annotations

import difflib
import hashlib
import re
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
GOLDEN = Path(__file__).resolve().parent / "golden"

#: (case file relative to cases/, engine) pairs: every scene's smoke case on every engine that
#: renders it, plus the full-physics shear cell (adhesion, rolling, torsion blocks)
CASES = [
    ("shear_cell_smoke.yaml", "liggghts"), ("shear_cell_smoke.yaml", "yade"),
    ("shear_cell_small.yaml", "liggghts"), ("shear_cell_small.yaml", "yade"),
    ("triaxial_smoke.yaml", "liggghts"), ("triaxial_smoke.yaml", "yade"),
    ("plane_shear_smoke.yaml", "liggghts"), ("plane_shear_smoke.yaml", "yade"),
    ("verification/chung_ooi_1_sphere_sphere_glass.yaml", "liggghts"),
    ("verification/chung_ooi_1_sphere_sphere_glass.yaml", "yade"),
    ("verification/chung_ooi_4_oblique.yaml", "liggghts"),
    ("verification/chung_ooi_4_oblique.yaml", "yade"),
    ("verification/chung_ooi_1_sphere_sphere_glass.yaml", "lammps"),
    ("verification/chung_ooi_4_oblique.yaml", "lammps"),
    ("plane_shear_smoke.yaml", "lammps"),
    ("shear_cell_smoke.yaml", "lammps"), ("shear_cell_small.yaml", "lammps"),
]

#: files written by render/prepare whose content is data, summarised by a hash
_DATA_SUFFIXES = {".txt", ".data", ".stl", ".vtk", ".npy", ".npz", ".json", ".h5"}
_SKIP = {"summary.json", "params.json", "case.yaml", ".lock"}

#: a decimal number with a fraction or an exponent (integers, e.g. ids and counts, stay text)
_FLOAT = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+(?=[eE]))(?:[eE][-+]?\d+)?")
#: how close a rendered number must be to the golden one (relative): far above the last-digit
#: differences between CPUs, far below any change a template or ``derive`` makes
RTOL = 1e-9


def split_numbers(text: str) -> tuple[str, np.ndarray]:
    """``text`` with every decimal number replaced by ``#``, and those numbers in order."""
    values = [float(m.group()) for m in _FLOAT.finditer(text)]
    return _FLOAT.sub("#", text), np.asarray(values, dtype=float)


def data_summary(rel: str, raw: bytes) -> str:
    """One line for a data file: its skeleton's SHA-256 and three sums over its numbers.

    The sums (of |x|, of x^2 and of |x| weighted by the position mod 7) carry no cancellation, so
    they are stable to a relative 1e-9 across CPUs, while a moved grain or a changed mesh changes
    them. A file that is not text keeps its plain SHA-256.
    """
    try:
        text = raw.decode()
    except UnicodeDecodeError:
        return f"=== {rel} sha256 {hashlib.sha256(raw).hexdigest()}\n"
    skeleton, x = split_numbers(text)
    weights = np.arange(x.size) % 7 + 1
    sums = [float(v) for v in (np.abs(x).sum(), (x * x).sum(), (np.abs(x) * weights).sum())]
    return (f"=== {rel} skeleton-sha256 {hashlib.sha256(skeleton.encode()).hexdigest()} numbers {x.size} "
            f"sums {sums[0]!r} {sums[1]!r} {sums[2]!r}\n")


def same_within_rtol(want: str, got: str) -> bool:
    """True when the two normalised renderings have the same text and numbers within RTOL."""
    skel_w, x_w = split_numbers(want)
    skel_g, x_g = split_numbers(got)
    return skel_w == skel_g and x_w.size == x_g.size and bool(np.allclose(x_g, x_w, rtol=RTOL, atol=0.0))


def _golden_name(case_rel: str, engine: str) -> str:
    return f"{Path(case_rel).stem}__{engine}.golden"


def render_normalised(case_rel: str, engine: str, tmp: Path) -> str:
    """Render ``case_rel`` for ``engine`` into ``tmp`` and return the normalised text."""
    from orchestrator import __version__
    from orchestrator.case import load_case
    from orchestrator.runner import prepare
    from engines import get_engine

    case = load_case(REPO / "cases" / case_rel)
    run_dir = tmp / "run"
    params, _subs = prepare(case, engine, run_dir)
    deck = get_engine(engine).render(case, params, run_dir, resume=None)
    parts = []
    for f in sorted(p for p in run_dir.rglob("*") if p.is_file()):
        rel = f.relative_to(run_dir).as_posix()
        if f.name in _SKIP:
            continue
        # data, and the runtime Python an engine copies beside its deck (its own unit tests cover it)
        if rel.split("/")[0].endswith("_runtime"):
            parts.append(f"=== {rel} sha256 {hashlib.sha256(f.read_bytes()).hexdigest()}\n")
            continue
        if f.suffix in _DATA_SUFFIXES and f != deck:
            parts.append(data_summary(rel, f.read_bytes()))
            continue
        text = f.read_text()
        text = text.replace(str(run_dir), "<RUN_DIR>").replace(str(REPO), "<REPO>")
        text = text.replace(__version__, "<VERSION>")
        parts.append(f"=== {rel}\n{text}")
    return "".join(parts)


@pytest.mark.parametrize("case_rel,engine", CASES, ids=[f"{Path(c).stem}-{e}" for c, e in CASES])
def test_deck_matches_golden(case_rel, engine, tmp_path):
    golden = GOLDEN / _golden_name(case_rel, engine)
    assert golden.exists(), f"no golden file {golden}; run `python tests/test_golden_decks.py --update`"
    got = render_normalised(case_rel, engine, tmp_path)
    want = golden.read_text()
    if not same_within_rtol(want, got):
        diff = "".join(difflib.unified_diff(want.splitlines(True), got.splitlines(True), "golden", "rendered", n=2))
        pytest.fail(f"{case_rel} on {engine}: rendered deck differs from {golden.name}:\n{diff[:6000]}")


def test_the_comparison_forgives_last_digits_and_nothing_else():
    deck = "variable zbot  equal -1.1914067836260936e-06\nfix 1 all wall 3 0.5\nRB = 1604.2530754625357\n"
    # the triaxial smoke's numbers as an AMD EPYC renders them (1e-12 relative apart)
    assert same_within_rtol(deck, deck.replace("-1.1914067836260936e-06", "-1.1914067836247925e-06")
                            .replace("1604.2530754625357", "1604.253075462535"))
    assert not same_within_rtol(deck, deck.replace("0.5", "0.5000001"))      # 2e-7: a change
    assert not same_within_rtol(deck, deck.replace("wall 3", "wall 4"))      # integers are text
    assert not same_within_rtol(deck, deck.replace("zbot", "ztop"))
    table = b"1 0.00029147422935693612 2650 -0.00054840878927075738\n2 0.0003362 2650 0.0004990797611301417\n"
    nudged = table.replace(b"0.0004990797611301417", b"0.0004990797611301418")     # 2e-16 relative
    assert same_within_rtol(data_summary("p.txt", table), data_summary("p.txt", nudged))
    swapped = table.replace(b"0.00029147422935693612", b"0.0003362").replace(b"2 0.0003362", b"2 0.00029147422935693612")
    assert not same_within_rtol(data_summary("p.txt", table), data_summary("p.txt", swapped))


def _update():
    import tempfile
    GOLDEN.mkdir(exist_ok=True)
    for case_rel, engine in CASES:
        with tempfile.TemporaryDirectory() as d:
            text = render_normalised(case_rel, engine, Path(d))
        (GOLDEN / _golden_name(case_rel, engine)).write_text(text)
        print(f"wrote {_golden_name(case_rel, engine)} ({len(text)} chars)")


if __name__ == "__main__":
    if "--update" in sys.argv:
        sys.path.insert(0, str(REPO))
        _update()
    else:
        print(__doc__)
