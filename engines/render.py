"""Jinja rendering shared by the adapters: strict undefined variables, exact numbers."""
from __future__ import annotations

import functools
import hashlib
from pathlib import Path

from orchestrator import __version__
from orchestrator.atomic import write_text

from .base import TEMPLATES


def _num(x) -> str:
    """A number written with full precision (repr of a float), never rounded by the template."""
    if isinstance(x, bool):
        return "True" if x else "False"
    if isinstance(x, int):
        return str(x)
    return repr(float(x))


@functools.lru_cache(maxsize=1)
def environment():
    """One Jinja environment per process (it caches compiled templates)."""
    return _environment()


def _environment():
    import jinja2            # here: jinja2 costs ~0.15 s to import, which validate does not need (#16)
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)), undefined=jinja2.StrictUndefined,
                             keep_trailing_newline=True, trim_blocks=False, lstrip_blocks=False)
    env.filters["num"] = _num
    env.filters["pylist"] = lambda xs: "[" + ", ".join(_num(x) for x in xs) + "]"
    return env


def render_template(name: str, context: dict, out: Path) -> Path:
    ctx = {"version": __version__, "case_source": getattr(context.get("case"), "source", ""), **context}
    import jinja2
    try:
        text = environment().get_template(name).render(**ctx)
    except jinja2.TemplateNotFound as exc:
        raise FileNotFoundError(f"no template {TEMPLATES / exc.name} (needed by {name}): this engine has no "
                                "deck for this scene yet") from None
    return write_text(out, text)


def scene_templates(engine: str, scene: str) -> list[str] | None:
    """The templates a scene's deck is rendered from: its main template and, recursively, every
    template it includes or imports (jinja2.meta). None when a reference is computed at render
    time (then every template of the engine counts) or the scene has no template."""
    from jinja2 import meta
    env = environment()
    mains = [f"{engine}/{scene}{ext}" for ext in (".in.j2", ".py.j2") if (TEMPLATES / engine / f"{scene}{ext}").is_file()]
    if not mains:
        return None
    seen, todo = set(), list(mains)
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        source = (TEMPLATES / name).read_text()
        for ref in meta.find_referenced_templates(env.parse(source)):
            if ref is None:
                return None
            todo.append(ref)
    return sorted(seen)


#: where the engines' runtime packages live (engines/<engine>_runtime/, beside this module)
RUNTIMES = Path(__file__).resolve().parent


def templates_hash(engine: str, scene: str) -> str:
    """Hash of the templates a scene's deck uses (:func:`scene_templates`; all of the engine's
    when that cannot be told), for run directories: editing another scene's deck leaves this
    scene's runs reusable."""
    names = scene_templates(engine, scene)
    if names is None:
        names = sorted(f.relative_to(TEMPLATES).as_posix() for f in (TEMPLATES / engine).rglob("*") if f.is_file())
    h = hashlib.sha256()
    for name in names:
        h.update(name.encode())
        h.update((TEMPLATES / name).read_bytes())
    # the Python an engine copies beside its deck (engines/<engine>_runtime/) is part of the deck
    runtime = RUNTIMES / f"{engine}_runtime"
    for f in sorted(runtime.rglob("*.py")):
        h.update(f.relative_to(runtime).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()
