"""Layering of ``src/``: imports only go down, no import circles, estimators never import the plant.

The order (docs/ARCHITECTURE.md, "Layers"), lowest first::

    hd_bag  <  hd_ros  <  hd_twin  <  hd_onboard  <  hd_prognostic  <  hd_ground  <  hdphm
    hd_bag  <  hd_sim (the plant: a side branch, imported only by hdphm, tests, bench)

A package may import only packages below it. ``hd_ros`` (ROS plumbing: topics, QoS, contexts,
conversion, managed node base, replay and record runtimes) imports only ``hd_bag``. ``hd_sim``
imports only ``hd_bag`` (not ``hd_ros``); of the packages
in ``src/`` only ``hdphm`` (CLI, demo, scoring harness) may import ``hd_sim``, and the estimator
packages (hd_twin, hd_onboard, hd_prognostic, hd_ground) never do: that rule has no exceptions.

Every import counts: module level, inside functions, under ``if TYPE_CHECKING`` or ``__main__``.
Imports are read with :mod:`ast` (nothing is imported), relative imports are resolved, and
``from pkg import mod`` counts as an import of the module ``pkg.mod``.

``ALLOWED_UPWARD`` / ``ALLOWED_CYCLES`` listed the violations the code had when this test was
written, each with the requirement of issue 16 that removed it; both are empty now. The test fails
on any violation not in them and on any entry that is no longer needed: the lists can only shrink.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

SRC = Path(__file__).resolve().parent.parent / "src"

#: estimator / CBM stack, lowest first (a package may import those before it)
ORDER = ("hd_bag", "hd_ros", "hd_twin", "hd_onboard", "hd_prognostic", "hd_ground", "hdphm")
#: the plant: imports hd_bag only, imported (inside src/) by hdphm only
PLANT = "hd_sim"
ESTIMATORS = ("hd_twin", "hd_onboard", "hd_prognostic", "hd_ground")


def allowed_packages(pkg: str) -> set[str]:
    """Packages ``pkg`` may import (besides itself)."""
    if pkg == PLANT:
        return {"hd_bag"}
    lower = set(ORDER[:ORDER.index(pkg)])
    return lower | {PLANT} if pkg == "hdphm" else lower


# Upward imports still allowed, (importing module, imported module). Empty: issue 16 removed every
# one the code had (R1: the ROS plumbing, rosutil/managed/replay/record, moved down to hd_ros and the
# stack to hdphm/stack.py; `python -m hd_sim.cli` builds its own parser. R2: node shells import
# downwards only, twin-state records and merging live in hd_twin, node helpers in hd_ros. R3: the
# onboard evaluation takes the ground's calibration as an argument, calibrate=, as it takes the
# plant's simulate=). The test fails on any new upward import.
ALLOWED_UPWARD: set[tuple[str, str]] = set()

# Existing import circles between modules of one package (strongly connected sets of modules).
#   R4 = requirement 4 (hd_twin/modeldir.py: model format, save/load and config reader in one place).
ALLOWED_CYCLES: set[frozenset[str]] = set()  # R4 done: hd_twin/modeldir.py broke train <-> export/plots


def _modules() -> dict[str, Path]:
    mods = {}
    for f in sorted(SRC.rglob("*.py")):
        parts = f.relative_to(SRC).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = f
    return mods


def _resolve(mods: dict[str, Path], name: str) -> str | None:
    """The longest module of ``src`` that ``name`` lies in (None: outside ``src``)."""
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        cand = ".".join(parts[:k])
        if cand in mods:
            return cand
    return None


def import_graph() -> dict[str, dict[str, list[int]]]:
    """{importing module: {imported module of src: [line numbers]}} over every import of ``src``."""
    mods = _modules()
    graph: dict[str, dict[str, list[int]]] = defaultdict(lambda: defaultdict(list))
    for mod, f in mods.items():
        package = mod.split(".") if f.name == "__init__.py" else mod.split(".")[:-1]
        tree = ast.parse(f.read_text(encoding="utf-8"), filename=str(f))
        for node in ast.walk(tree):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package[:len(package) - (node.level - 1)]
                    root = ".".join(base + ([node.module] if node.module else []))
                else:
                    root = node.module or ""
                # `from pkg import mod` imports the module pkg.mod; `from mod import name` imports mod
                targets = [f"{root}.{a.name}" if f"{root}.{a.name}" in mods else root for a in node.names]
            for t in targets:
                r = _resolve(mods, t)
                if r is not None and r != mod:
                    graph[mod][r].append(node.lineno)
    return graph


def _top(mod: str) -> str:
    return mod.split(".")[0]


def _sccs(graph: dict[str, dict[str, list[int]]]) -> list[frozenset[str]]:
    """Strongly connected sets of more than one node (Tarjan, iterative)."""
    nodes = set(graph) | {b for a in graph for b in graph[a]}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out = []
    counter = 0
    for root in sorted(nodes):
        if root in index:
            continue
        work = [(root, iter(sorted(graph.get(root, {}))))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph.get(w, {})))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = set()
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.add(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(frozenset(comp))
    return out


def _fmt(graph, a, b) -> str:
    f = SRC / (a.replace(".", "/") + ".py")
    f = f if f.exists() else SRC / a.replace(".", "/") / "__init__.py"
    return f"{a} -> {b} ({f.relative_to(SRC.parent)} line {', '.join(map(str, sorted(set(graph[a][b]))))})"


def test_every_package_has_a_layer():
    pkgs = {p.name for p in SRC.iterdir() if (p / "__init__.py").exists()}
    assert pkgs == set(ORDER) | {PLANT}, (
        f"packages {sorted(pkgs ^ (set(ORDER) | {PLANT}))}: place each in ORDER (tests/test_layering.py) "
        "and in docs/ARCHITECTURE.md, or remove it from the order")


def test_estimators_never_import_the_plant():
    graph = import_graph()
    bad = [_fmt(graph, a, b) for a in graph for b in graph[a] if _top(a) in ESTIMATORS and _top(b) == PLANT]
    assert not bad, "estimators import the plant (hd_sim): " + "; ".join(bad)


def test_imports_only_go_down():
    graph = import_graph()
    up = {(a, b) for a in graph for b in graph[a] if _top(b) != _top(a) and _top(b) not in allowed_packages(_top(a))}
    new = sorted(up - ALLOWED_UPWARD)
    assert not new, "imports from a lower layer to a higher one: " + "; ".join(_fmt(graph, a, b) for a, b in new)
    gone = sorted(ALLOWED_UPWARD - up)
    assert not gone, f"ALLOWED_UPWARD entries no longer needed, delete them from tests/test_layering.py: {gone}"


def test_no_import_circles():
    graph = import_graph()
    pkg_graph: dict[str, dict[str, list[int]]] = defaultdict(dict)
    for a in graph:
        for b in graph[a]:
            if _top(a) != _top(b) and (a, b) not in ALLOWED_UPWARD:
                pkg_graph[_top(a)][_top(b)] = graph[a][b]
    assert not _sccs(pkg_graph), f"import circles between packages: {_sccs(pkg_graph)}"
    # module circles, leaving out the allowed upward imports (test_imports_only_go_down covers them)
    down = {a: {b: v for b, v in graph[a].items() if (a, b) not in ALLOWED_UPWARD} for a in graph}
    cycles = set(_sccs(down))
    new = sorted(sorted(c) for c in cycles - ALLOWED_CYCLES)
    assert not new, f"import circles between modules: {new}"
    gone = sorted(sorted(c) for c in ALLOWED_CYCLES - cycles)
    assert not gone, f"ALLOWED_CYCLES entries no longer (exactly) circles, update tests/test_layering.py: {gone}"


def test_graph_is_read():
    """The parser sees real edges (guards the tests above against an empty graph)."""
    graph = import_graph()
    assert "hd_bag.mission" in graph["hd_twin.data"]
    assert graph["hd_onboard.core"], "hd_onboard.core imports nothing of src?"


if __name__ == "__main__":  # print today's graph between packages
    g = import_graph()
    for a in sorted(g):
        for b in sorted(g[a]):
            if _top(a) != _top(b):
                print(_fmt(g, a, b))
    print("module circles:", [sorted(c) for c in _sccs(g)])
