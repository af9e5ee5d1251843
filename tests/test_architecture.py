"""The package's structure, read from the source. Imports (every ``import`` statement counts:
module level, inside functions and under ``TYPE_CHECKING``):

- no import cycle among ``calib`` modules;
- no module imports a ``_private`` name from another module;
- no module re-exports a name it imports from another ``calib`` module (a "shim": the name is
  imported and never used, or listed in ``__all__``) — except a package's ``__init__``, whose
  imports are the package's public face.

Sizes: at most a dozen modules at the top level, no module over 400 lines, no function over 60
lines without its docstring.

Edges are explicit imports only: importing ``calib.a.b`` runs ``calib/a/__init__.py`` first, but
that implicit edge is not a dependency the module states.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _modules(root: Path) -> dict[str, Path]:
    out = {}
    for p in sorted((root / "calib").rglob("*.py")):
        name = ".".join(p.relative_to(root).with_suffix("").parts)
        out[name[:-len(".__init__")] if name.endswith(".__init__") else name] = p
    return out


def _resolve(name: str, modules) -> str:
    """The module a dotted import name lands in (``calib.a.b.func`` -> ``calib.a.b``); "" outside calib."""
    while name and name not in modules:
        name = name.rsplit(".", 1)[0] if "." in name else ""
    return name


def _imports(tree: ast.AST):
    """(module imported from, name or None) of every import statement in ``tree``."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, None
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            for a in node.names:
                yield node.module, a.name


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Module -> the calib modules it imports (a ``from m import sub`` of a submodule goes to ``sub``)."""
    modules = _modules(root)
    graph = {m: set() for m in modules}
    for m, p in modules.items():
        for module, name in _imports(ast.parse(p.read_text())):
            target = f"{module}.{name}" if name and f"{module}.{name}" in modules else _resolve(module, modules)
            if target and target != m:
                graph[m].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter[0]
        counter[0] += 1
        stack.append(start)
        on.add(start)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def private_imports(root: Path = ROOT) -> list[str]:
    """``module: from other import _name`` for every private name imported across modules."""
    found = []
    for m, p in _modules(root).items():
        for module, name in _imports(ast.parse(p.read_text())):
            if module.startswith("calib") and name and name.startswith("_") and not name.startswith("__"):
                found.append(f"{m}: from {module} import {name}")
    return found


def _names_used(tree: ast.AST) -> set[str]:
    """Names read anywhere in ``tree``, those in quoted annotations (``-> "Measurements"``) included."""
    used = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
    for node in ast.walk(tree):
        notes = []
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            notes = [a.annotation for a in node.args.args + node.args.kwonlyargs + node.args.posonlyargs] + [node.returns]
        elif isinstance(node, ast.AnnAssign):
            notes = [node.annotation]
        for note in notes:
            for c in ast.walk(note) if note is not None else ():
                if isinstance(c, ast.Constant) and isinstance(c.value, str):
                    used |= {n.id for n in ast.walk(ast.parse(c.value, mode="eval")) if isinstance(n, ast.Name)}
    return used


def reexports(root: Path = ROOT) -> list[str]:
    """``module: name (from other)`` for every calib name a non-package module imports and never uses."""
    found = []
    for m, p in _modules(root).items():
        if p.name == "__init__.py":
            continue
        tree = ast.parse(p.read_text())
        used = _names_used(tree)
        listed = set()
        for node in tree.body:
            if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets):
                listed = {e.value for e in ast.walk(node.value) if isinstance(e, ast.Constant)}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("calib"):
                for a in node.names:
                    local = a.asname or a.name
                    if local not in used or local in listed:
                        found.append(f"{m}: {local} (from {node.module})")
    return found


def test_no_import_cycle_among_calib_modules():
    graph = import_graph()
    assert len(graph) > 100 and sum(len(v) for v in graph.values()) > 300     # the scan sees the package
    assert cycles(graph) == []


def test_no_private_name_is_imported_across_modules():
    assert private_imports() == []


def test_no_module_reexports_what_it_imports():
    assert reexports() == []


def test_the_checks_see_a_cycle_a_private_import_and_a_shim(tmp_path):
    pkg = tmp_path / "calib"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("from calib.sub.b import thing\n")      # a package face: allowed
    (pkg / "a.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from calib.sub.b import B\n")
    (pkg / "sub" / "b.py").write_text("def f():\n    from calib.a import _helper\n    return _helper\n"
                                      "from calib.c import shown  # noqa: F401\nthing = 1\nclass B: ...\n")
    (pkg / "c.py").write_text("shown = 1\n")
    assert cycles(import_graph(tmp_path)) == [["calib.a", "calib.sub.b"]]
    assert private_imports(tmp_path) == ["calib.sub.b: from calib.a import _helper"]
    assert reexports(tmp_path) == ["calib.a: B (from calib.sub.b)", "calib.sub.b: shown (from calib.c)"]


MAX_TOP_LEVEL_MODULES = 12
MAX_MODULE_LINES = 400
MAX_FUNCTION_LINES = 60        # without its docstring


def test_a_handful_of_modules_at_the_top_level_and_none_too_long():
    top = sorted(p.name for p in (ROOT / "calib").glob("*.py"))
    assert len(top) <= MAX_TOP_LEVEL_MODULES, top
    long = {str(p.relative_to(ROOT)): n for p in (ROOT / "calib").rglob("*.py")
            if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES}
    assert long == {}


def _code_lines(fn: ast.AST) -> int:
    """Lines of a function without its docstring."""
    body = fn.body
    doc = body[0] if body and isinstance(body[0], ast.Expr) and isinstance(getattr(body[0], "value", None), ast.Constant) \
        and isinstance(body[0].value.value, str) else None
    return fn.end_lineno - fn.lineno + 1 - (doc.end_lineno - doc.lineno + 1 if doc else 0)


def test_no_function_longer_than_a_screen():
    long = [f"{p.relative_to(ROOT)}:{n.lineno} {n.name} ({_code_lines(n)} lines)"
            for p in (ROOT / "calib").rglob("*.py") for n in ast.walk(ast.parse(p.read_text()))
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and _code_lines(n) > MAX_FUNCTION_LINES]
    assert long == []


@pytest.mark.parametrize("doc", ["docs/layout.md"])
def test_the_layout_page_names_every_package(doc):
    text = (ROOT / doc).read_text()
    packages = sorted(p.parent.relative_to(ROOT).as_posix() for p in (ROOT / "calib").rglob("__init__.py"))
    missing = [p for p in packages if f"{p}/" not in text and f"`{p}`" not in text]
    assert missing == []
