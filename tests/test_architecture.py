"""The house rules that code review would otherwise have to remember (docs/ARCHITECTURE.md).

Every import in the product, at module level or inside a function, is read from the source: a lazy import
hides a dependency from Python's import order, not from this test.
"""

import ast
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
