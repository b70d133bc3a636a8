"""The layout's promise, checked on the code itself: data flows one way through the packages, each
importing only those below it, and no module imports itself back through others (an import circle).

Every `import gecgen...` and `from gecgen... import` counts, at the top of a module or inside a
function alike: a function-level import defers the circle, it does not remove it.
"""
from __future__ import annotations

import ast
from pathlib import Path

GECGEN = Path(__file__).resolve().parents[1] / "gecgen"
#: the packages from the bottom up (docs/reference.md, "Layout"): each may import those before it
LAYERS = ("version", "model", "symbolic", "emit", "runtime", "fit", "loop", "simulate", "plan", "verify", "deliver", "report",
          "api", "cli")


def _modules() -> dict[str, set[str]]:
    """Module name (gecgen.x.y) -> the gecgen modules it imports (a `from P import name` of a
    submodule counts as importing that submodule)."""
    names = {".".join(p.relative_to(GECGEN.parent).with_suffix("").parts).removesuffix(".__init__"): p
             for p in GECGEN.rglob("*.py")}
    out = {}
    for name, path in names.items():
        found = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                found |= {a.name for a in node.names if a.name.startswith("gecgen")}
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0 and \
                    node.module.startswith("gecgen"):
                found |= {f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in names else node.module
                          for a in node.names}
        out[name] = {m for m in found if m in names and m != name}
    return out


def _layer(module: str) -> str:
    part = module.split(".")[1] if "." in module else "api"  # gecgen itself re-exports the API
    return "api" if part == "__main__" else part


def test_every_package_is_in_a_layer():
    assert {_layer(m) for m in _modules()} <= set(LAYERS)


def test_no_package_imports_one_above_it():
    upward = sorted(f"{m} imports {t}" for m, ts in _modules().items() for t in ts
                    if LAYERS.index(_layer(t)) > LAYERS.index(_layer(m)))
    assert not upward, upward


def test_no_import_circle():
    graph = _modules()
    state: dict[str, int] = {}  # 1 on the path, 2 done
    circles = []

    def visit(m, path):
        state[m] = 1
        for t in sorted(graph[m]):
            if state.get(t) == 1:
                circles.append(" -> ".join(path[path.index(t):] + [t]))
            elif t not in state:
                visit(t, path + [t])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert not circles, circles
