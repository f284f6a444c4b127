"""``orchestrator ARGS`` run by :func:`orchestrator.cli.main` inside the test process: the package and
its analysis stack are imported once per test worker instead of once a call (~1.5 s a call on the
2-core machine). Tests of the entry point itself (``python -m orchestrator``: help, a missing file,
an unprivileged user) start a subprocess instead."""
from __future__ import annotations

import contextlib
import io
import subprocess

from orchestrator.cli import main


def main_here(*args) -> subprocess.CompletedProcess:
    """Exit status, stdout and stderr of ``orchestrator ARGS``, as ``subprocess.run`` reports them."""
    args = [str(a) for a in args]
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(args)
        except SystemExit as exc:          # argparse's own errors
            code = exc.code
    return subprocess.CompletedProcess(args, code, out.getvalue(), err.getvalue())
