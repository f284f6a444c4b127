"""numba, imported once for the project's compiled kernels (``from orchestrator.jit import numba``).

numba caches compiled kernels (``cache=True``) in a ``__pycache__`` beside each module; when the
installed package is read-only (a system or shared install), the cache goes to
``$TMPDIR/orchestrator-numba-<uid>`` instead, set here before numba is first imported (numba reads
``NUMBA_CACHE_DIR`` at import). A ``NUMBA_CACHE_DIR`` the user has set is kept.
"""
from __future__ import annotations

import os
import tempfile

_PACKAGES = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))   # orchestrator/ and engines/

if "NUMBA_CACHE_DIR" not in os.environ and not os.access(os.path.join(_PACKAGES, "orchestrator"), os.W_OK):
    os.environ["NUMBA_CACHE_DIR"] = os.path.join(tempfile.gettempdir(), f"orchestrator-numba-{os.getuid()}")

import numba  # noqa: E402  (after NUMBA_CACHE_DIR)

__all__ = ["numba"]
