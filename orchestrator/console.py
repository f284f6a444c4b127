"""The one rich console every command prints through.

``soft_wrap=True``: rich does not break long lines (a path, an error message) at the terminal's
width, so what a command prints stays one line in a log and greppable; tables still fit the width.
"""
from rich.console import Console


def console(stderr: bool = False) -> Console:
    """A console on stdout (or stderr) that never hard-wraps text."""
    return Console(stderr=stderr, soft_wrap=True)
