"""numba, imported once for the project's compiled kernels (``from orchestrator.jit import numba``),
and :func:`warm`, which fills numba's on-disk cache with every kernel the project calls.

numba caches compiled kernels (``cache=True``) in a ``__pycache__`` beside each module; when the
installed package is read-only (a system or shared install), the cache goes to
``$TMPDIR/orchestrator-numba-<uid>`` instead, set here before numba is first imported (numba reads
``NUMBA_CACHE_DIR`` at import). A ``NUMBA_CACHE_DIR`` the user has set is kept.

Why :func:`warm`: numba compiles a kernel on its first call in a process whose cache does not hold
it yet. On a fresh install every pytest-xdist worker compiled its own copy of the ~20 kernels
(~48 s CPU of a 72 s first run of the engine-free tests, 39 s once cached). ``python -m
orchestrator.jit`` (run by ``.ci/setup``) compiles them once, by calling the public functions that
use them on tiny inputs: the argument types are the ones the project's code passes, by construction.
Later processes load the kernels from the cache; with the cache already warm it takes seconds.
"""
from __future__ import annotations

import importlib
import os
import re
import sys
import tempfile
import time

_PACKAGES = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))   # orchestrator/ and engines/

if "NUMBA_CACHE_DIR" not in os.environ and not os.access(os.path.join(_PACKAGES, "orchestrator"), os.W_OK):
    os.environ["NUMBA_CACHE_DIR"] = os.path.join(tempfile.gettempdir(), f"orchestrator-numba-{os.getuid()}")

import numba  # noqa: E402  (after NUMBA_CACHE_DIR)
import numpy as np  # noqa: E402
from numba.core.dispatcher import Dispatcher  # noqa: E402

__all__ = ["numba", "warm", "kernel_modules", "dispatchers", "touched"]

#: the packages whose modules may hold kernels
_KERNEL_PACKAGES = ("orchestrator", "engines")
#: a module may hold kernels when it imports numba, through this module (the project's convention)
#: or directly
_USES_NUMBA = re.compile(r"^\s*(?:from\s+(?:orchestrator|\.+)\.?jit\s+import\s+numba\b|import\s+numba\b|from\s+numba\b)",
                         re.M)


def kernel_modules() -> list[str]:
    """Dotted names of the project's modules that import numba, through this module or directly (found
    by reading the sources of orchestrator/ and engines/, so a new kernel module is found without a
    list)."""
    names = []
    for pkg in _KERNEL_PACKAGES:
        for root, dirs, files in os.walk(os.path.join(_PACKAGES, pkg)):
            dirs[:] = sorted(d for d in dirs if d != "__pycache__" and not d.startswith("."))
            for f in sorted(files):
                path = os.path.join(root, f)
                if not f.endswith(".py") or os.path.samefile(path, __file__):
                    continue
                with open(path, encoding="utf-8") as fh:
                    if _USES_NUMBA.search(fh.read()):
                        rel = os.path.relpath(path, _PACKAGES)[:-3]
                        names.append(rel.replace(os.sep, ".").removesuffix(".__init__"))
    return names


def dispatchers() -> dict[str, Dispatcher]:
    """Every numba kernel defined in :func:`kernel_modules`, by ``module.name`` (imports them)."""
    out = {}
    for name in kernel_modules():
        mod = importlib.import_module(name)
        for attr, obj in sorted(vars(mod).items()):
            if isinstance(obj, Dispatcher) and obj.py_func.__module__ == name:
                out[f"{name}.{attr}"] = obj
    return out


def _modules(*names: str) -> list:
    """The modules ``names``, imported by name at run time. This module is a core module that every
    kernel module imports (pyproject.toml [tool.importlinter]: no import cycle with orchestrator.ct
    and orchestrator.analysis, no import of engines), so the public functions that the warm-up calls
    are joined here at run time, as the registries join scenes and engines."""
    return [importlib.import_module(n) for n in names]


def _warm_ct() -> None:
    """The CT kernels (_render, _kernels): render, segment and measure tiny synthetic scans.

    One scan per grey-value dtype that :func:`orchestrator.ct.segment.segment` meets in practice
    (``region_sums`` is compiled per dtype: uint8, uint16 as rendered and as read from most
    scanners' TIFFs, float32 as reconstructed). The grains: one inside the volume (its voxel box is a
    strided view) and one filling the volume's width (a contiguous view), both layouts of
    ``coverage_into``; a hollow grain whose closed cavity is filled (``table_mask`` with a base)."""
    segment, shape, synth = _modules("orchestrator.ct.segment", "orchestrator.ct.shape", "orchestrator.ct.synth")
    vs = 1e-5
    centres = np.array([[6.5, 6.5, 6.5], [14.0, 6.5, 6.5]]) * vs
    radii = np.array([4.5, 4.8]) * vs
    for dtype in (np.uint16, np.uint8, np.float32):
        scan = synth.render_scan((13, 13, 21), vs, centres, radii, hollow=np.array([0.0, 0.5]), noise=0.02,
                                 psf_sigma=0.6, dtype=dtype, supersample=2)
        seg = segment.segment(scan)
    synth.render_scan((6, 6, 6), vs, [[3 * vs, 3 * vs, 3 * vs]], 5 * vs, supersample=2)     # the wide grain
    shape.grain_shapes(seg, degree=2, n_rays=40)      # ray directions read-only (a cached design)
    u, _, _ = shape.fibonacci_directions(8)            # writable, as a caller of radial_profile has them
    shape.radial_profile(seg.solid_fraction(), np.array([6.0, 6.0, 6.0]), u, 5.0)
    seg.contacts()


def _warm_analysis() -> None:
    """The cell-list kernels (analysis/_cells): D²min with its strains, and neighbour counts, of a
    few particles on a jittered grid."""
    analysis, = _modules("orchestrator.analysis")
    rng = np.random.default_rng(0)
    g = np.stack(np.meshgrid(*[np.arange(3.0)] * 3, indexing="ij"), -1).reshape(-1, 3)
    ref = g + rng.normal(scale=0.05, size=g.shape)
    analysis.d2min(ref, ref * 1.01, cutoff=1.5)
    analysis.neighbor_counts(ref, 1.5)


def _warm_textparse() -> None:
    """The dump text parser (engines/_textparse) as ``read_dump`` calls it: on the read-only bytes of
    a file, and on a writable copy when the file lacks a trailing newline."""
    _textparse, = _modules("engines._textparse")
    body = b"1 2.5 -3e-4\n"
    _textparse.parse(memoryview(body), 3)
    _textparse.parse(body[:-1], 3)


def touched(kernels: dict[str, Dispatcher] | None = None) -> dict[str, list[str]]:
    """The kernel signatures this process has compiled or loaded from the cache so far, by kernel
    (``module.name``; ``repr`` of the argument types), of ``kernels`` (default :func:`dispatchers`).
    A kernel compiled only as the callee of another one is listed when it was compiled here, not when
    its caller was loaded."""
    out = {}
    for name, d in (dispatchers() if kernels is None else kernels).items():
        sigs = set(d.stats.cache_hits) | set(d.stats.cache_misses)
        if sigs:
            out[name] = sorted(repr(tuple(s)) for s in sigs)
    return out


def warm() -> tuple[dict[str, list[str]], int, float]:
    """Compile every kernel of the project into numba's on-disk cache, or load it from there, for
    the argument types that the project's public functions pass (by calling them on tiny inputs).
    Returns (:func:`touched`, signatures compiled in this call, seconds)."""
    t0 = time.perf_counter()
    _warm_ct()
    _warm_analysis()
    _warm_textparse()
    kernels = dispatchers()
    compiled = sum(len(d.stats.cache_misses) for d in kernels.values())
    return touched(kernels), compiled, time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    """``python -m orchestrator.jit [-v]``: :func:`warm`, then one line with what it did (``-v``:
    then one line per kernel signature)."""
    verbose = "-v" in (sys.argv[1:] if argv is None else argv)
    sigs, compiled, seconds = warm()
    n = sum(len(v) for v in sigs.values())
    where = numba.config.CACHE_DIR or "beside the kernel modules"
    print(f"jit: {len(sigs)} numba kernels, {n} signatures ready in {seconds:.1f} s "
          f"({compiled} compiled, {n - compiled} loaded from the cache, {where})")
    if verbose:
        for name, v in sigs.items():
            for sig in v:
                print(f"  {name}{sig}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
