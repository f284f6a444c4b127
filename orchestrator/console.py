"""The one rich console every command prints through.

``soft_wrap=True``: rich does not break long lines (a path, an error message) at the terminal's
width, so what a command prints stays one line in a log and greppable; tables still fit the width.
Printed into a file or a pipe (a ladder's log under nohup), the width is 200 columns rather than
rich's 80, which cut a sweep's table of fourteen columns to a letter or two each.
rich is imported on first use, not with the command modules (validate within 2 s, #16).
"""
import os
import sys

#: columns of a table printed into a file or a pipe (no terminal to fit)
LOG_WIDTH = 200


def console(stderr: bool = False):
    """A ``rich.console.Console`` on stdout (or stderr) that never hard-wraps text."""
    from rich.console import Console
    stream = sys.stderr if stderr else sys.stdout
    tty = hasattr(stream, "isatty") and stream.isatty()
    width = None if tty or os.environ.get("COLUMNS") else LOG_WIDTH
    return Console(stderr=stderr, soft_wrap=True, width=width)
