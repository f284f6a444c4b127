"""Jinja rendering shared by the adapters: strict undefined variables, exact numbers."""
from __future__ import annotations

import functools
import hashlib
from pathlib import Path

import jinja2

from .base import TEMPLATES


def _num(x) -> str:
    """A number written with full precision (repr of a float), never rounded by the template."""
    if isinstance(x, bool):
        return "True" if x else "False"
    if isinstance(x, int):
        return str(x)
    return repr(float(x))


@functools.lru_cache(maxsize=1)
def environment() -> jinja2.Environment:
    """One Jinja environment per process (it caches compiled templates)."""
    return _environment()


def _environment() -> jinja2.Environment:
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)), undefined=jinja2.StrictUndefined,
                             keep_trailing_newline=True, trim_blocks=False, lstrip_blocks=False)
    env.filters["num"] = _num
    env.filters["pylist"] = lambda xs: "[" + ", ".join(_num(x) for x in xs) + "]"
    return env


def render_template(name: str, context: dict, out: Path) -> Path:
    from orchestrator import __version__
    from orchestrator.atomic import write_text
    ctx = {"version": __version__, "case_source": getattr(context.get("case"), "source", ""), **context}
    try:
        text = environment().get_template(name).render(**ctx)
    except jinja2.TemplateNotFound as exc:
        raise FileNotFoundError(f"no template {TEMPLATES / exc.name} (needed by {name}): this engine has no "
                                "deck for this scene yet") from None
    return write_text(out, text)


def templates_hash(engine: str, scene: str) -> str:
    """Hash of every template an engine may use (its folder), for run directories."""
    h = hashlib.sha256()
    for f in sorted((TEMPLATES / engine).rglob("*")):
        if f.is_file():
            h.update(f.relative_to(TEMPLATES).as_posix().encode())
            h.update(f.read_bytes())
    return h.hexdigest()
