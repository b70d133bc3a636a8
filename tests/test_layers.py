"""The layout's promise, checked on the code itself: data flows one way through the packages, each
importing only those below it, and no module imports itself back through others (an import circle).

Every `import gecgen...` and `from gecgen... import` counts, at the top of a module or inside a
function alike: a function-level import defers the circle, it does not remove it.
"""
from __future__ import annotations

import ast
import re
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


def test_every_command_imports_only_the_packages_of_its_work():
    """docs/reference.md's table "Where each command's work happens" is the rule: a command's module
    imports the packages of its row, the nouns (model), the reports and the API, nothing else; the
    modules not named after a command are the ones several share."""
    from gecgen.cli import COMMANDS

    text = (GECGEN.parent / "docs" / "reference.md").read_text()
    rows = text[text.index("| command | package of its work |"):].split("\n\n")[0].splitlines()[2:]
    allowed = {}
    for row in rows:
        commands, work = row.strip("|").split("|")
        for command in re.findall(r"`([a-z0-9]+)`", commands):
            allowed[command] = set(re.findall(r"`([a-z]+)`", work)) | {"model", "report", "api", "cli", "version"}
    assert set(allowed) == set(COMMANDS), set(allowed) ^ set(COMMANDS)
    graph = _modules()
    for command, (module, _) in COMMANDS.items():
        used = {_layer(m) for m in graph[f"gecgen.cli.{module}"]}
        assert used <= allowed[command], (command, used - allowed[command])
    shared = {m.split(".")[2] for m in graph if m.startswith("gecgen.cli.")} - {m for m, _ in COMMANDS.values()}
    assert shared == {"__main__", "common", "human", "register", "pixels"}, shared
