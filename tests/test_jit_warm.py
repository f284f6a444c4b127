"""``python -m orchestrator.jit`` (orchestrator/jit.py :func:`warm`) leaves in numba's on-disk cache every
kernel signature that the project's public functions use, so that a later process compiles nothing.

Two fresh processes share a temporary ``NUMBA_CACHE_DIR``: the first runs the warm-up, the second runs
the public calls of the engine-free tests on small inputs (CT rendering, segmentation, shapes and
contacts; D²min, strains and neighbour counts; the text dump reader) and reports numba's
per-kernel cache statistics. The test fails when the second process compiled any kernel, when it
used a kernel signature the warm-up did not prepare, or when a kernel of the project (every numba
dispatcher of every module importing numba through orchestrator/jit.py, found automatically) is
neither warmed nor only called from another kernel.

The temporary cache starts as a copy of the project's own cache (valid entries are reused, stale
ones ignored by numba), so the warm-up takes seconds once the project's cache is warm (``.ci/setup``
fills it); the checks use the statistics of each process, not the files, so the copy cannot hide a
kernel the warm-up misses.
"""
from __future__ import annotations

import inspect
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

from numba.core.caching import _CacheLocator

from orchestrator.jit import dispatchers

ROOT = Path(__file__).resolve().parents[1]

#: the second process: public calls as the engine-free tests make them, then the cache statistics
PUBLIC_CALLS = r'''
import json, sys
from pathlib import Path
import numpy as np
from orchestrator.ct import segment, shape, synth
from orchestrator.analysis import d2min, local_strain, neighbor_counts
from engines.lammps_dump import read_dump
from orchestrator.jit import dispatchers

SCHEDULE_MINUTES = 0.13   #: engine-free tests, ~8 s quiet: early in the fast tier (tests/conftest.py schedule_groups)

vs = 1e-5
rng = np.random.default_rng(0)
c = np.array([[8.0, 8.0, 8.0], [17.5, 8.5, 8.0], [8.5, 17.0, 9.0]]) * vs
for dtype in (np.uint16, np.float32):
    scan = synth.render_scan((18, 26, 26), vs, c, np.array([5.0, 4.5, 4.0]) * vs, hollow=np.array([0.5, 0, 0]),
                             noise=0.05, psf_sigma=0.8, drift=0.05, dtype=dtype, seed=1)
    seg = segment.segment(scan)
shape.grain_shapes(seg, degree=3)
seg.contacts()
u, _, _ = shape.fibonacci_directions(20)
shape.radial_profile(seg.solid_fraction(), np.array([8.0, 8.0, 8.0]), u, 6.0)
coefs = synth.random_sh_grains(2, 4 * vs, degree=4, seed=2)
pos = np.array([[[6 * vs] * 3, [13 * vs] * 3]] * 2)
rot = np.array([[np.eye(3), np.eye(3)[[1, 2, 0]]]] * 2)
synth.render_sequence((20, 20, 20), vs, pos, grain_shapes=coefs, rotations=rot)
synth.render_scan((8, 8, 8), vs, [[4 * vs] * 3], 6 * vs)

p = np.stack(np.meshgrid(*[np.arange(5.0)] * 3, indexing="ij"), -1).reshape(-1, 3) * 1e-4
p += rng.normal(scale=5e-6, size=p.shape)
q = p * 1.002
q[3] = np.nan
d2min(p, q, cutoff=1.5e-4)
local_strain(np.eye(3)[None].repeat(4, 0))
neighbor_counts(p, 1.5e-4)

tmp = Path(sys.argv[1])
rows = np.column_stack([np.arange(1, 2001), np.ones(2000), rng.normal(size=(2000, 10))])
body = "\n".join(" ".join("%.6g" % v for v in r) for r in rows)
head = "ITEM: TIMESTEP\n5\nITEM: NUMBER OF ATOMS\n2000\nITEM: BOX BOUNDS ff ff ff\n0 1\n0 1\n0 1\nITEM: ATOMS " + \
       " ".join(f"c{k}" for k in range(12)) + "\n"
for name, end in (("newline.dump", "\n"), ("no-newline.dump", "")):
    (tmp / name).write_text(head + body + end)
    assert read_dump(tmp / name)[2].shape == (2000, 12)

print(json.dumps({k: {"hits": sorted(repr(tuple(s)) for s in d.stats.cache_hits),
                      "misses": sorted(repr(tuple(s)) for s in d.stats.cache_misses)}
                  for k, d in dispatchers().items()}))
'''


def _seed(cache_dir: Path) -> None:
    """Copy the project's current numba cache of every kernel module into ``cache_dir``, laid out as
    numba lays out a ``NUMBA_CACHE_DIR``: only to save the warm-up's compile time."""
    for d in dispatchers().values():
        src = Path(d._cache._cache_path)
        py_file = inspect.getsourcefile(d.py_func)
        dst = cache_dir / _CacheLocator.get_suitable_cache_subpath(py_file)
        dst.mkdir(parents=True, exist_ok=True)
        for f in src.glob(f"{Path(py_file).stem}.{d.py_func.__name__}-*.nb[ic]"):
            shutil.copy2(f, dst / f.name)


def _run(args, cache_dir: Path) -> str:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir))
    r = subprocess.run([sys.executable, *args], cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    return r.stdout


def _called_by_a_kernel(name: str, kernels) -> bool:
    """Whether the source of another kernel calls kernel ``name`` (a callee is compiled and cached with
    its caller, never called from Python)."""
    short = name.rsplit(".", 1)[1]
    call = re.compile(rf"\b{re.escape(short)}\(")
    return any(call.search(inspect.getsource(d.py_func)) for k, d in kernels.items() if k != name)


def test_warm_leaves_nothing_to_compile(tmp_path):
    cache = tmp_path / "numba-cache"
    _seed(cache)
    out = _run(["-m", "orchestrator.jit", "-v"], cache).splitlines()
    assert out[0].startswith("jit: "), out
    warmed = {(name, "(" + sig) for name, sig in (line.strip().split("(", 1) for line in out[1:])}

    stats = json.loads(_run(["-c", PUBLIC_CALLS, str(tmp_path)], cache).splitlines()[-1])
    compiled = {k: v["misses"] for k, v in stats.items() if v["misses"]}
    assert not compiled, f"compiled after the warm-up (not in orchestrator.jit.warm): {compiled}"
    used = {(k, s) for k, v in stats.items() for s in v["hits"]}
    assert used - warmed == set(), "kernel signatures used but not prepared by orchestrator.jit.warm"

    kernels = dispatchers()
    assert set(stats) == set(kernels) and len(kernels) >= 21
    warmed_names = {name for name, _ in warmed}
    missed = [k for k, d in kernels.items()
              if k not in warmed_names and d.targetoptions.get("inline") != "always"
              and not _called_by_a_kernel(k, kernels)]
    assert not missed, f"kernels that orchestrator.jit.warm never calls: {missed}"
