"""The one rich console every command prints through.

``soft_wrap=True``: rich does not break long lines (a path, an error message) at the terminal's
width, so what a command prints stays one line in a log and greppable; tables still fit the width.
rich is imported on first use, not with the command modules (validate within 2 s, #16).
"""


def console(stderr: bool = False):
    """A ``rich.console.Console`` on stdout (or stderr) that never hard-wraps text."""
    from rich.console import Console
    return Console(stderr=stderr, soft_wrap=True)
