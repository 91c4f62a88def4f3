"""The package's import graph: no cycle, no import back up the layers, a self-contained
compiled layer (docs/ARCHITECTURE.md's table of layers).

Every ``import`` and ``from ... import`` of every module is read with ``ast`` (those inside
functions and under ``if TYPE_CHECKING`` too: they are dependencies of the design even when
deferred). Each failure names the file, the line and the import. The checker is tested on a
planted package first (:func:`test_the_checker_finds_planted_cycles_and_upward_imports`), so
that a clean result means something.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "multiarm_pin"

LAYERS = ("base", "_compiled", "model", "grasp", "constraints", "dynamics", "system", "sim",
          "feasibility", "app", "study", "design", "command line")
"""Bottom to top. A module may import its own layer and the layers below. ``_compiled`` (the
numba kernels) sits right above ``base`` and imports nothing else of the package; the command
line (``app/cli.py``) wires every layer's subcommand and sits on top."""

BASE = {"__init__", "exceptions", "spatial", "yaml_reader", "_registry", "data"}
"""Top-level modules of the base layer (the package's ``__init__`` only names the others'
exports lazily, by string)."""

COMPILED_THIRD_PARTY = {"numpy", "numba"}
"""What the compiled layer may import besides the standard library and the package's base."""


def layer(module: str) -> str:
    """The layer of a dotted module name of the package."""
    parts = module.split(".")
    if module == "multiarm_pin.app.cli":
        return "command line"
    if len(parts) == 1 or parts[1] in BASE:
        return "base"
    return parts[1]


def modules(package: Path) -> dict[str, Path]:
    """Dotted name -> file of every module of ``package`` (a folder named like the package)."""
    out = {}
    for f in sorted(package.rglob("*.py")):
        parts = list(f.relative_to(package.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = f
    return out


def import_edges(package: Path) -> list[tuple[str, str, Path, int, str]]:
    """``(importer, imported, file, line, source text)`` for every import of the package.

    ``imported`` is the module the name resolves to (``from p import m`` gives ``p.m`` when
    that is a module, else ``p``); imports of other packages are left out.
    """
    mods = modules(package)
    root = package.name
    edges, seen = [], set()
    for name, f in mods.items():
        text = f.read_text(encoding="utf-8")
        here = name.split(".") if f.name == "__init__.py" else name.split(".")[:-1]
        for node in ast.walk(ast.parse(text, str(f))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = here[: len(here) - (node.level - 1)]
                    base = ".".join(up + ([node.module] if node.module else []))
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base
                           for a in node.names]
            for target in targets:
                if target.split(".")[0] != root:
                    continue
                while target not in mods and "." in target:
                    target = target.rsplit(".", 1)[0]
                if target != name and (name, target, node.lineno) not in seen:
                    seen.add((name, target, node.lineno))
                    code = " ".join((ast.get_source_segment(text, node) or target).split())
                    edges.append((name, target, f, node.lineno, code))
    return edges


def upward_imports(edges) -> list[str]:
    """One line per import of a higher layer (and per import of the compiled layer beyond
    itself and the base)."""
    bad = []
    for src, dst, f, line, code in edges:
        a, b = layer(src), layer(dst)
        if a == "_compiled" and b not in ("_compiled", "base"):
            bad.append(f"{f}:{line}: `{code}`: the compiled layer imports {dst} ({b})")
        elif LAYERS.index(b) > LAYERS.index(a):
            bad.append(f"{f}:{line}: `{code}`: layer {a} imports {dst} of the higher layer {b}")
    return bad


def cycles(edges) -> list[str]:
    """One line per import cycle (strongly connected component of more than one module),
    naming every import inside it."""
    graph: dict[str, set[str]] = {}
    for src, dst, *_ in edges:
        graph.setdefault(src, set()).add(dst)
        graph.setdefault(dst, set())
    index, low, stack, on, comps = {}, {}, [], set(), []

    def visit(v):  # Tarjan's algorithm
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
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
                comps.append(comp)

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10 * len(graph) + 100))
    try:
        for v in sorted(graph):
            if v not in index:
                visit(v)
    finally:
        sys.setrecursionlimit(limit)
    return [f"cycle of {len(c)} modules {sorted(c)} through: " + "; ".join(
        f"{f}:{line}: `{code}`" for src, dst, f, line, code in edges if src in c and dst in c)
        for c in comps]


def compiled_third_party(package: Path) -> list[str]:
    """Imports of the compiled layer other than numpy, numba, the standard library and the
    package."""
    bad = []
    for name, f in modules(package).items():
        if layer(name) != "_compiled":
            continue
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module] if isinstance(node, ast.ImportFrom) and not node.level
                     else [])
            for n in names:
                top = n.split(".")[0]
                if top not in (COMPILED_THIRD_PARTY | set(sys.stdlib_module_names)
                               | {package.name, "__future__"}):
                    bad.append(f"{f}:{node.lineno}: the compiled layer imports {n}")
    return bad


def test_no_import_runs_up_the_layers():
    edges = import_edges(PACKAGE)
    assert len(edges) > 300  # the reader sees the package's imports
    bad = upward_imports(edges)
    assert not bad, "\n".join(bad)


def test_no_import_cycle():
    bad = cycles(import_edges(PACKAGE))
    assert not bad, "\n".join(bad)


def test_the_compiled_layer_imports_only_numpy_numba_and_itself():
    bad = compiled_third_party(PACKAGE)
    assert not bad, "\n".join(bad)


def test_every_folder_is_a_known_layer():
    unknown = {layer(m) for m in modules(PACKAGE)} - set(LAYERS)
    assert not unknown, unknown


def test_the_checker_finds_planted_cycles_and_upward_imports(tmp_path):
    """A small package with one bad import of each kind (and good ones) is reported exactly."""
    pkg = tmp_path / "multiarm_pin"
    files = {
        "__init__.py": "from multiarm_pin.exceptions import E\n",
        "exceptions.py": "class E(Exception):\n    pass\n",
        "_compiled/__init__.py": "",
        "_compiled/kernel.py": "import numpy\nimport scipy\nfrom . import linalg\n"
                               "def f():\n    from multiarm_pin.sim import stepper\n",
        "_compiled/linalg.py": "from multiarm_pin.exceptions import E\n",
        "dynamics/__init__.py": "",
        "dynamics/a.py": "from multiarm_pin.dynamics.b import x\n",
        "dynamics/b.py": "from typing import TYPE_CHECKING\nx = 1\nif TYPE_CHECKING:\n"
                         "    from multiarm_pin.dynamics import a\n",
        "sim/__init__.py": "",
        "sim/stepper.py": "from multiarm_pin._compiled import kernel\nfrom ..dynamics import a\n",
        "model/__init__.py": "",
        "model/arm.py": "import multiarm_pin.sim.stepper\n",
    }
    for rel, text in files.items():
        (pkg / rel).parent.mkdir(parents=True, exist_ok=True)
        (pkg / rel).write_text(text)
    edges = import_edges(pkg)
    assert ("multiarm_pin.sim.stepper", "multiarm_pin.dynamics.a") in [e[:2] for e in edges]
    up = upward_imports(edges)
    assert len(up) == 2, up
    assert "kernel.py:5: `from multiarm_pin.sim import stepper`: the compiled layer" in up[0] \
        or "kernel.py:5" in up[1]
    assert any("arm.py:1: `import multiarm_pin.sim.stepper`: layer model imports "
               "multiarm_pin.sim.stepper of the higher layer sim" in u for u in up), up
    cyc = cycles(edges)
    assert len(cyc) == 2, cyc  # a <-> b (through a TYPE_CHECKING import), kernel <-> stepper
    assert any("dynamics/b.py:4" in c and "dynamics/a.py:1" in c for c in cyc), cyc
    assert any("_compiled/kernel.py:5" in c and "sim/stepper.py:1" in c for c in cyc), cyc
    third = compiled_third_party(pkg)
    assert len(third) == 1 and "kernel.py:2: the compiled layer imports scipy" in third[0]
