"""Architecture figures of the source tree (issue #13), printed as one table.

    python benchmarks/architecture_metrics.py [--repo DIR]

- files outside ``engines/`` whose code (not comments/docstrings) names an engine;
- the five longest functions (lines);
- internal imports (orchestrator.*, engines.*) written inside functions, and all internal imports;
- import cycles: strongly connected components of the module import graph (grimp, the graph
  import-linter uses), listed;
- ``duplicates`` pairs (the count line of the `duplicates` tool, when it is installed).
"""
from __future__ import annotations

import argparse
import ast
import io
import re
import shutil
import subprocess
import sys
import tokenize
from pathlib import Path

ENGINE_NAME = re.compile(r"(?<![a-z])(liggghts|yade|lammps)(?![a-z])", re.I)


IDENT_STRING = re.compile(r"""^[rbuf]*["'](\w*)["']$""", re.I)


def _code_only(src: str) -> str:
    """Names and identifier-like string literals ("liggghts", "yade_gamma": a key or a list entry)
    of the source; comments, docstrings and messages (strings with spaces) do not count."""
    out = []
    try:
        for tok in tokenize.generate_tokens(io.StringIO(src).readline):
            if tok.type == tokenize.NAME:
                out.append(tok.string)
            elif tok.type == tokenize.STRING:
                m = IDENT_STRING.match(tok.string)
                if m:
                    out.append(m.group(1))
    except (tokenize.TokenError, IndentationError):
        return src
    return " ".join(out)


def py_files(repo: Path):
    for top in ("orchestrator", "engines"):
        yield from sorted((repo / top).rglob("*.py"))


def module_name(repo: Path, f: Path) -> str:
    parts = list(f.relative_to(repo).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", default=str(Path(__file__).resolve().parents[1]))
    a = ap.parse_args(argv)
    repo = Path(a.repo)
    named, funcs, inner, total = [], [], 0, 0
    for f in py_files(repo):
        src = f.read_text()
        rel = f.relative_to(repo).as_posix()
        if not rel.startswith("engines/") and ENGINE_NAME.search(_code_only(src)):
            named.append(rel)
        tree = ast.parse(src)
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                funcs.append((node.end_lineno - node.lineno + 1, f"{rel}:{node.lineno} {node.name}"))
        depth_imports = []

        def visit(node, in_func):
            nonlocal inner, total
            for ch in ast.iter_child_nodes(node):
                if isinstance(ch, (ast.Import, ast.ImportFrom)):
                    mods = [n.name for n in ch.names] if isinstance(ch, ast.Import) else [ch.module or ""]
                    internal = (isinstance(ch, ast.ImportFrom) and ch.level > 0) or any(
                        m.split(".")[0] in ("orchestrator", "engines") for m in mods)
                    if internal:
                        total += 1
                        inner += in_func
                visit(ch, in_func or isinstance(ch, (ast.FunctionDef, ast.AsyncFunctionDef)))
        visit(tree, False)
    funcs.sort(reverse=True)
    print(f"files outside engines/ naming an engine in code: {len(named)}")
    for n in named:
        print(f"    {n}")
    print("longest functions: " + "; ".join(f"{n} lines {w}" for n, w in funcs[:5]))
    print(f"internal imports inside functions: {inner} of {total}")
    try:
        import grimp
        sys.path.insert(0, str(repo))
        g = grimp.build_graph("orchestrator", "engines")
        cycles = _sccs(g)
        print(f"import cycles (strongly connected module groups): {len(cycles)}")
        for c in cycles:
            print("    " + " <-> ".join(sorted(c)))
    except ImportError:
        print("import cycles: grimp not installed (pip install import-linter)")
    if shutil.which("duplicates"):
        out = subprocess.run(["duplicates", "--repo", str(repo), "--seconds", "60"], capture_output=True,
                             text=True).stdout
        print("duplicates: " + (out.splitlines()[0] if out else "?"))
    return 0


def _sccs(g) -> list[set]:
    """Tarjan's strongly connected components with more than one module."""
    mods = sorted(g.modules)
    index, low, stack, on, out = {}, {}, [], set(), []
    sys.setrecursionlimit(10000)

    def strong(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in g.find_modules_directly_imported_by(v):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(comp)
    for m in mods:
        if m not in index:
            strong(m)
    return out


if __name__ == "__main__":
    raise SystemExit(main())
