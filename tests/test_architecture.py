"""The house rules that code review would otherwise have to remember (docs/ARCHITECTURE.md).

Every import in the product, at module level or inside a function, is read from the source: a lazy import
hides a dependency from Python's import order, not from this test.
"""

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# Each part may import only the parts listed: core is the floor, rendering draws clips, generation makes them
# (and renders its stimuli), the app and the analysis read only files and core's contracts.
ALLOWED = {
    "core": set(),
    "rendering": {"core"},
    "generation": {"core", "rendering"},
    "rating_app": {"core"},
    "analysis": {"core"},
    # the console command `moglow-eval` (pyproject [project.scripts]) dispatches to every part; none imports it
    "moglow_eval": {"core", "rendering", "generation", "rating_app", "analysis"},
}
PARTS = tuple(ALLOWED)


def imports_of(path):
    """(line, top-level module) for every import statement in a file; relative imports stay in the part."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.lineno, node.module.split(".")[0]


def part_edges():
    """{(importer part, imported part): first 'file:line' that makes the edge}."""
    edges = {}
    for part in PARTS:
        for path in sorted((ROOT / part).rglob("*.py")):
            for line, top in imports_of(path):
                if top in PARTS and top != part:
                    edges.setdefault((part, top), f"{path.relative_to(ROOT)}:{line}")
    return edges


def find_cycle(edges):
    """One cycle among the parts as a list of part names, or None (depth-first search)."""
    graph = {p: sorted(b for a, b in edges if a == p) for p in PARTS}
    state = {}

    def visit(node, stack):
        state[node] = "open"
        for nxt in graph[node]:
            if state.get(nxt) == "open":
                return stack[stack.index(nxt) :] + [nxt]
            if nxt not in state and (cycle := visit(nxt, stack + [nxt])):
                return cycle
        state[node] = "done"
        return None

    for start in PARTS:
        if start not in state and (cycle := visit(start, [start])):
            return cycle
    return None


def test_no_cycle_between_the_parts():
    edges = part_edges()
    cycle = find_cycle(edges)
    assert cycle is None, " -> ".join(cycle) + " (" + ", ".join(edges[(a, b)] for a, b in zip(cycle, cycle[1:])) + ")"


def test_every_import_points_down():
    wrong = [f"{where}: {a} imports {b}" for (a, b), where in part_edges().items() if b not in ALLOWED[a]]
    assert not wrong, "\n".join(wrong)


def test_the_product_never_imports_test_code():
    bad = [
        f"{path.relative_to(ROOT)}:{line}"
        for part in PARTS
        for path in (ROOT / part).rglob("*.py")
        for line, top in imports_of(path)
        if top in ("tests", "conftest", "pytest", "hypothesis", "selenium")
    ]
    assert not bad, bad


@pytest.mark.parametrize(
    "edges, cycle",
    [
        ({("generation", "rendering"), ("rendering", "generation")}, {"generation", "rendering"}),
        ({("analysis", "rating_app"), ("rating_app", "core")}, None),
        ({("a", "b"), ("b", "c"), ("c", "a")}, None),  # not parts: ignored
    ],
)
def test_the_cycle_finder_finds_cycles(edges, cycle):
    """The guard itself can fail: the cycle this issue removed (rendering <-> generation) is found."""
    found = find_cycle({e: "x" for e in edges if set(e) <= set(PARTS)})
    assert found == cycle if cycle is None else (set(found) == cycle and found[0] == found[-1])


# ------------------------------------------------------------------------------------------- modules in a part
def module_name(path):
    """`rating_app/designs/acr.py` -> `rating_app.designs.acr`; a package's `__init__.py` is the package."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def module_imports(path, known):
    """(line, module) for every import of a module of ours in a file, lazy ones included, relative ones resolved:
    the deepest module the statement names (`from . import x` names module x when x is one, else the package).
    A parent package run on the way (`a.b` before `a.b.c`) is not an edge: a registry that imports its kinds,
    each importing their base, is no cycle."""
    here = module_name(path)
    package = here if path.name == "__init__.py" else here.rpartition(".")[0]
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
        else:
            continue
        for name in targets:
            while name and name not in known:  # `import a.b.c` of a name inside c: the module c
                name = name.rpartition(".")[0]
            if name and name != here:
                yield node.lineno, name


def module_edges(part):
    """{(importer module, imported module): first 'file:line'} within one part."""
    files = {module_name(p): p for p in sorted((ROOT / part).rglob("*.py"))}
    edges = {}
    for name, path in files.items():
        for line, target in module_imports(path, files):
            edges.setdefault((name, target), f"{path.relative_to(ROOT)}:{line}")
    return edges


def find_module_cycle(edges):
    """One cycle among modules as a list of names (first == last), or None."""
    graph = {}
    for a, b in edges:
        graph.setdefault(a, []).append(b)
        graph.setdefault(b, [])
    state = {}

    def visit(node, stack):
        state[node] = "open"
        for nxt in sorted(graph[node]):
            if state.get(nxt) == "open":
                return stack[stack.index(nxt) :] + [nxt]
            if nxt not in state and (cycle := visit(nxt, stack + [nxt])):
                return cycle
        state[node] = "done"
        return None

    for start in sorted(graph):
        if start not in state and (cycle := visit(start, [start])):
            return cycle
    return None


@pytest.mark.parametrize("part", PARTS)
def test_no_cycle_between_the_modules_of_a_part(part):
    """A module pair that imports each other (even lazily, inside a function) is one concept in two files, or a
    shared piece that belongs below both."""
    edges = module_edges(part)
    cycle = find_module_cycle(edges)
    assert cycle is None, " -> ".join(cycle) + " (" + ", ".join(edges[(a, b)] for a, b in zip(cycle, cycle[1:])) + ")"


def test_the_module_cycle_finder_sees_lazy_and_relative_imports(tmp_path, monkeypatch):
    """The guard itself can fail: a lazy relative import back (the shape of report <-> design_report) is a cycle,
    a registry importing its kinds, which import their base, is not."""
    pkg = tmp_path / "demo_part"
    (pkg / "kinds").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "report.py").write_text("def build():\n    from .other import x\n")
    (pkg / "other.py").write_text("from . import report\nx = 1\n")
    (pkg / "kinds" / "__init__.py").write_text("from .a import A\nfrom .base import Base\n")
    (pkg / "kinds" / "base.py").write_text("class Base: ...\n")
    (pkg / "kinds" / "a.py").write_text("from .base import Base\nfrom ..other import x\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    edges = module_edges("demo_part")
    assert set(find_module_cycle(edges)) == {"demo_part.report", "demo_part.other"}
    (pkg / "other.py").write_text("x = 1\n")
    assert find_module_cycle(module_edges("demo_part")) is None
    assert ("demo_part.kinds.a", "demo_part.kinds.base") in module_edges("demo_part")
