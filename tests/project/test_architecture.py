"""The house rules that code review would otherwise have to remember (docs/ARCHITECTURE.md).

Every import in the product, at module level or inside a function, is read from the source: a lazy import
hides a dependency from Python's import order, not from this test.
"""

import ast
import functools
import sys

import pytest
from helpers.paths import ROOT
from helpers.rooms import ROOMS

from moglow_eval.core import moved

# Each part may import only the parts listed: core is the floor, rendering draws clips, generation makes them
# (and renders its stimuli), the app and the analysis read only files and core's contracts.
ALLOWED = {
    "moglow_eval.core": set(),
    "rendering": {"moglow_eval.core"},
    "generation": {"moglow_eval.core", "rendering"},
    "rating_app": {"moglow_eval.core"},
    "analysis": {"moglow_eval.core"},
    # the console command `moglow-eval` (pyproject [project.scripts]) dispatches to every part; none imports it
    "moglow_eval": {"moglow_eval.core", "rendering", "generation", "rating_app", "analysis"},
}
PARTS = tuple(ALLOWED)
# The modules a part keeps at its top, beside its rooms (the one-line pointers of moved commands are checked apart).
TOP_MODULES = {
    "generation": ["make_stimuli"],
    "rating_app": ["wsgi"],
    "analysis": ["challenge_demo", "demo", "import_votes", "plan", "report"],
}


def part_of(module):
    """The part a dotted module name belongs to (the longest part name it starts with), or None."""
    hits = [p for p in PARTS if module == p or module.startswith(p + ".")]
    return max(hits, key=len) if hits else None


def part_files(part):
    """The .py files of a part (moglow_eval's own files leave out moglow_eval/core, a part of its own)."""
    folder = ROOT / part.replace(".", "/")
    inner = [ROOT / p.replace(".", "/") for p in PARTS if p.startswith(part + ".")]
    return [p for p in sorted(folder.rglob("*.py")) if not any(p.is_relative_to(i) for i in inner)]


@functools.lru_cache(maxsize=None)
def _import_nodes(text, filename):
    return tuple(n for n in ast.walk(ast.parse(text, filename)) if isinstance(n, (ast.Import, ast.ImportFrom)))


def import_nodes(path):
    """A file's import statements, lazy ones included, in ast.walk's order: parsed once a run for the same text, as
    the checks below read each file's imports many times (every part's edges, every part's modules)."""
    return _import_nodes(path.read_text(encoding="utf-8"), str(path))


def imports_of(path):
    """(line, dotted module) for every absolute import statement in a file; relative imports stay in the part."""
    for node in import_nodes(path):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.lineno, node.module


def part_edges():
    """{(importer part, imported part): first 'file:line' that makes the edge}."""
    edges = {}
    for part in PARTS:
        for path in part_files(part):
            for line, module in imports_of(path):
                top = part_of(module)
                if top is not None and top != part:
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
        for path in part_files(part)
        for line, module in imports_of(path)
        if module.split(".")[0] in ("tests", "conftest", "pytest", "hypothesis", "selenium")
    ]
    assert not bad, bad


@pytest.mark.parametrize(
    "edges, cycle",
    [
        ({("generation", "rendering"), ("rendering", "generation")}, {"generation", "rendering"}),
        ({("analysis", "rating_app"), ("rating_app", "moglow_eval.core")}, None),
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
    for node in import_nodes(path):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        else:
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
        for name in targets:
            while name and name not in known:  # `import a.b.c` of a name inside c: the module c
                name = name.rpartition(".")[0]
            if name and name != here:
                yield node.lineno, name


def module_edges(part):
    """{(importer module, imported module): first 'file:line'} within one part."""
    files = {module_name(p): p for p in part_files(part)}
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


# ------------------------------------------------------------------------------------------------ rooms
def room_of(module, rooms):
    """`generation.models.fl` (or the room's package, `generation.models`) -> `models`; a part's top-level module
    (the main job, a command) -> None."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in rooms else None


def wrong_way_room_imports(edges, rooms):
    """'file:line: a imports b' for every edge from a room to one above it (or not in the order), or to the part's
    top-level modules."""
    rank = {name: i for i, name in enumerate(rooms)}
    wrong = []
    for (a, b), where in sorted(edges.items()):
        ra, rb = room_of(a, rooms), room_of(b, rooms)
        if rb is None and "." in b and ra is not None:
            wrong.append(f"{where}: {a} imports the top-level {b}")
        elif ra is not None and rb is not None and ra != rb and not rank.get(rb, 99) < rank.get(ra, -1):
            wrong.append(f"{where}: {a} imports {b} ({ra} may import only {list(rooms[: rank.get(ra, 0)])})")
    return wrong


@pytest.mark.parametrize("part", ROOMS)
def test_a_part_is_its_rooms_in_order(part):
    """Every module of generation, rating_app and analysis but the part's commands lives in a room named for its
    concept, and the rooms import only downwards: in generation motion at the floor and a study of your own motion at
    the top; in the app the study's state at the floor and the blueprints above; in the analysis the data, then the
    statistics, the page, and the designs that use all three."""
    folder = ROOT / part
    subs = {p.name for p in folder.iterdir() if (p / "__init__.py").is_file()}
    assert subs == set(ROOMS[part]), f"{part}'s subpackages {sorted(subs)} vs the order {ROOMS[part]}"
    top = sorted(
        p.stem for p in folder.glob("*.py") if p.stem not in ("__init__", "__main__") and not moved.is_pointer(p)
    )
    assert top == TOP_MODULES[part], f"{part}/ holds modules outside a room: {top}"
    wrong = wrong_way_room_imports(module_edges(part), ROOMS[part])
    assert not wrong, "\n".join(wrong)


def test_the_room_guard_sees_an_upward_import():
    """The guard itself can fail: the shape the move removed (sampling reaching into training is fine, a model
    reaching into the stimuli is not, and neither is a room reaching the main job)."""
    edges = {
        ("generation.sampling.sample", "generation.training.train"): "x:1",
        ("generation.models.fl", "generation.stimuli.items"): "y:2",
        ("generation.motion.bvh", "generation.make_stimuli"): "z:3",
        ("generation.make_stimuli", "generation.own_study.builder"): "w:4",
        ("rating_app.store.settings", "rating_app.media.videos"): "v:5",
        ("analysis.designs.base", "analysis.page.report_html"): "u:6",
    }
    wrong = []
    for part, rooms in ROOMS.items():
        wrong += wrong_way_room_imports({k: v for k, v in edges.items() if k[0].startswith(part + ".")}, rooms)
    assert [w.split(":")[0] for w in wrong] == ["y", "z", "v"], wrong


# ------------------------------------------------------------------------------------------------ sizes
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 80


def code_lines(node):
    """A function's lines less its docstring: the API's docstrings (Parameters, Returns, Examples) are reference
    text, not stages of the function."""
    n = node.end_lineno - node.lineno + 1
    first = node.body[0] if node.body else None
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
        n -= first.end_lineno - first.lineno + 1
    return n


def oversized(paths, root=ROOT):
    """'file: N lines' for a module of MAX_MODULE_LINES or more, 'file:line name: N lines' for a function over
    MAX_FUNCTION_LINES: a long module is several concepts, a long function several stages."""
    found = []
    for path in paths:
        text = path.read_text(encoding="utf-8")
        if (n := text.count("\n")) >= MAX_MODULE_LINES:
            found.append(f"{path.relative_to(root)}: {n} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                if (n := code_lines(node)) > MAX_FUNCTION_LINES:
                    found.append(f"{path.relative_to(root)}:{node.lineno} {node.name}: {n} lines")
    return found


def test_no_module_or_function_is_too_long():
    assert not (found := oversized(p for part in PARTS for p in part_files(part))), "\n".join(found)


def test_the_size_guard_sees_a_long_function(tmp_path):
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_FUNCTION_LINES))
    (tmp_path / "long.py").write_text(f"def long():\n{body}")
    (tmp_path / "short.py").write_text('def short():\n    """' + "doc\n" * 100 + '"""\n    return 1\n')
    assert oversized([tmp_path / "long.py", tmp_path / "short.py"], tmp_path) == [
        f"long.py:1 long: {1 + MAX_FUNCTION_LINES} lines"
    ]


# ------------------------------------------------------------------------------- designs as plug-ins
# Where a design may be named: where the names are defined, each part's design modules and their registries.
DESIGN_HOMES = (
    "moglow_eval/core/study.py",
    "rating_app/designs/",
    "analysis/designs/",
    "generation/own_study/designs/",
)
# Modules that are about named designs by purpose, not composites: the demos build a chosen design's study, and the
# importer writes the export of the design a leaderboard's votes become.
NAMES_A_DESIGN = {
    "analysis/demo.py": "runs the demo of the design it is asked for",
    "generation/own_study/demo_dyad.py": "builds the dyadic or semantic demo study",
    "analysis/import_votes.py": "writes a pairwise or appropriateness export from another tool's votes",
    "generation/challenge/demo_inputs.py": "writes the demo challenge's two tasks, each served by a design it names",
}


def design_names_in(paths, root=ROOT):
    """'file:line: name' for each string constant that is a design's name (moglow_eval.core.study.DESIGNS)."""
    from moglow_eval.core import study

    found = []
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in study.DESIGNS:
                found.append(f"{path.relative_to(root)}:{node.lineno}: {node.value!r}")
    return found


def test_no_shared_module_names_a_design():
    """A composite asks the study's design object (its growth rule, its battles, its methods text, its stimuli's
    needs), never its name: a new design then touches only the files ARCHITECTURE's checklist lists."""
    paths = [
        p
        for part in PARTS
        for p in part_files(part)
        if not str(p.relative_to(ROOT)).startswith(DESIGN_HOMES) and str(p.relative_to(ROOT)) not in NAMES_A_DESIGN
    ]
    assert not (found := design_names_in(paths)), "\n".join(found)


def test_the_design_guard_sees_a_name(tmp_path):
    (tmp_path / "shared.py").write_text('def grows(design):\n    return design.name == "pairwise"\n')
    (tmp_path / "fine.py").write_text('def grows(design):\n    return design.grows  # "pairwise" in a comment\n')
    assert design_names_in([tmp_path / "shared.py", tmp_path / "fine.py"], tmp_path) == ["shared.py:2: 'pairwise'"]


def unresolved_imports(paths, root=ROOT):
    """'file:line: module.name' for each `from OUR_MODULE import name` in `paths` that no longer resolves: a
    module or a name that moved (the benches import the product, and nothing else runs them)."""
    import importlib

    found = []
    for path in paths:
        for node in import_nodes(path):
            if not isinstance(node, ast.ImportFrom) or node.level or not node.module:
                continue
            if node.module.split(".")[0] not in {p.split(".")[0] for p in PARTS}:
                continue
            try:
                module = importlib.import_module(node.module)
            except ImportError:
                found.append(f"{path.relative_to(root)}:{node.lineno}: {node.module}")
                continue
            for alias in node.names:
                if not hasattr(module, alias.name):
                    try:
                        importlib.import_module(f"{node.module}.{alias.name}")
                    except ImportError:
                        found.append(f"{path.relative_to(root)}:{node.lineno}: {node.module}.{alias.name}")
    return found


def test_every_bench_imports_what_exists():
    assert not (found := unresolved_imports(sorted((ROOT / "bench").glob("*.py")))), "\n".join(found)


def test_the_import_guard_sees_a_moved_name(tmp_path):
    (tmp_path / "b.py").write_text("from analysis import rating_models\nfrom analysis.stats import anova\n")
    assert unresolved_imports([tmp_path / "b.py"], tmp_path) == ["b.py:1: analysis.rating_models"]


# The suite mirrors the house: a folder of tests per part, one for whole studies across the parts, one for the
# house's own rules; beside them only what the tests share (tests/helpers/, tests/data/, tests/reference/).
TEST_FOLDERS = ("core", "rendering", "generation", "rating_app", "analysis", "end_to_end", "project")
SHARED_FOLDERS = ("helpers", "data", "reference")


def imports_of_test_modules(paths, root=ROOT):
    """'file:line: module' for each import of a test module (one named test_*) in `paths`, at any depth: tests share
    through tests/helpers/ and the conftest.py files, never through another test file, whose tests would then run
    twice or not at all."""
    found = []
    for path in paths:
        for node in sorted(import_nodes(path), key=lambda n: n.lineno):
            if isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            else:  # `import test_x`, and `from . import test_x`, which names the module among the imported names
                names = [alias.name for alias in node.names]
            found += [
                f"{path.relative_to(root)}:{node.lineno}: {name}"
                for name in names
                if any(part.startswith("test_") for part in name.split("."))
            ]
    return found


def test_no_test_file_imports_another():
    found = imports_of_test_modules(sorted((ROOT / "tests").rglob("*.py")))
    assert not found, "\n".join(found)


def test_the_test_import_guard_sees_a_lazy_import(tmp_path):
    (tmp_path / "test_a.py").write_text(
        "from helpers.api_client import TOKEN_HDR\n"
        "NAME = 'test_b'\n"
        "def test_x():\n"
        "    from test_b import post\n"
        "import test_c as c\n"
        "from . import test_d\n"
    )
    assert imports_of_test_modules([tmp_path / "test_a.py"], tmp_path) == [
        "test_a.py:4: test_b",
        "test_a.py:5: test_c",
        "test_a.py:6: test_d",
    ]


def misplaced_tests(tests):
    """What breaks the layout of the folder `tests`: a test file outside the part folders, a folder that is neither
    one of them nor one the tests share, two test files of one name (pytest imports each by its name alone), and an
    __init__.py in a part folder (tests/rendering/ would become a package `rendering`, hiding the part's)."""
    files = sorted(tests.rglob("test_*.py"))
    found = [
        f"{p.relative_to(tests)}: outside {', '.join(TEST_FOLDERS)}"
        for p in files
        if p.parent.parent != tests or p.parent.name not in TEST_FOLDERS
    ]
    found += [
        f"{p.name}/: not a folder of tests/"
        for p in sorted(tests.iterdir())
        if p.is_dir() and p.name not in TEST_FOLDERS + SHARED_FOLDERS and p.name != "__pycache__"
    ]
    names = [p.name for p in files]
    found += [
        f"{name}: {names.count(name)} test files of this name" for name in sorted(set(names)) if names.count(name) > 1
    ]
    found += [
        f"{f}/__init__.py: a part folder is no package" for f in TEST_FOLDERS if (tests / f / "__init__.py").exists()
    ]
    return found


def test_every_test_file_lives_in_its_part_folder():
    found = misplaced_tests(ROOT / "tests")
    assert not found, "\n".join(found)


def test_the_layout_guard_sees_a_stray_test(tmp_path):
    for path in ("test_top.py", "core/test_a.py", "project/test_a.py", "misc/test_b.py", "rendering/__init__.py"):
        (tmp_path / path).parent.mkdir(exist_ok=True)
        (tmp_path / path).write_text("")
    (tmp_path / "helpers").mkdir()
    assert misplaced_tests(tmp_path) == [
        f"misc/test_b.py: outside {', '.join(TEST_FOLDERS)}",
        f"test_top.py: outside {', '.join(TEST_FOLDERS)}",
        "misc/: not a folder of tests/",
        "test_a.py: 2 test files of this name",
        "rendering/__init__.py: a part folder is no package",
    ]
