"""The docs can't rot: the site builds strictly, every command shown parses, every figure links to its RESULTS entry.

Every line of every bash block in README.md and docs/*.md is checked:
- `python -m MODULE ARGS`, `moglow-eval SUB ARGS` and `torchrun ... -m MODULE ARGS`: ARGS are parsed by that
  module's own argparse parser (`build_parser()`), so a renamed or removed flag fails here;
- `python bench/SCRIPT.py ARGS`: the script exists and defines every flag given;
- `python -m pytest ARGS`: every test file named exists;
- `export NAME=value`: NAME is a setting the rating app reads;
- a path such as `scripts/install-system-deps.sh`: it exists and is executable;
- commands that are not ours are skipped, by name, in NOT_OURS below. Anything else fails.
"""

import importlib
import re
import shlex
import subprocess
import sys

import pytest
from helpers.paths import ROOT

# Other people's tools and shell built-ins: shown in the docs, not ours to check.
NOT_OURS = {
    "cd",
    "curl",
    "dask",  # the cluster's scheduler and workers (docs/hosting.md, Rendering on other machines)
    "git",
    "gunicorn",
    "ln",
    "mkdir",
    "mkdocs",  # its build is run by test_mkdocs_build_strict below
    "openssl",
    "pip",
    "podman",
    "podman-compose",
    "unzip",
}
# `python -m X` for X not ours.
NOT_OUR_MODULES = {"pytest"}
# `python -m X` and `moglow-eval` commands: the module whose build_parser() parses the arguments.
MODULES = {
    "rendering": "rendering.__main__",
    "rating_app": "rating_app.__main__",
}
CONSOLE = {
    "stimuli": ("generation.make_stimuli", []),
    "intake": ("generation.challenge.intake", []),
    **{c: ("rating_app.__main__", [c]) for c in ("serve", "simulate", "export", "backup", "restore")},
    "report": ("analysis.report", []),
    "plan": ("analysis.plan", []),
    "board": ("analysis.board", []),
    "demo": ("analysis.demo", []),
    "challenge-demo": ("analysis.challenge_demo", []),
}
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def bash_lines(path):
    """(line number, command line) of every bash block in a Markdown file, continuation lines joined."""
    out, block, start, pending = [], False, 0, ""
    for n, raw in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        line = raw.strip()
        if line.startswith("```"):
            block = line == "```bash" if not block else False
            continue
        if not block or not line or line.startswith("#"):  # a comment line explains, it runs nothing
            continue
        start = start or n
        if line.endswith("\\"):
            pending += line[:-1] + " "
            continue
        out.append((start, pending + line))
        pending, start = "", 0
    return out


def without_substitutions(line):
    """The line with each $(...) (balanced parentheses) replaced by the word SUBST: what it prints is a value."""
    while "$(" in line:
        start = line.index("$(")
        depth, i = 0, start + 1
        for i in range(start + 1, len(line)):
            depth += {"(": 1, ")": -1}.get(line[i], 0)
            if depth == 0:
                break
        line = line[:start] + "SUBST" + line[i + 1 :]
    return line


def commands(line):
    """The simple commands of a shell line: $(...) replaced by a placeholder, split at && ; |, without leading
    VAR=value assignments or redirections."""
    line = without_substitutions(line)
    tokens = shlex.split(line, comments=True)
    cmds, cur = [], []
    for tok in tokens + ["&&"]:
        if tok in ("&&", ";", "|", "||"):
            cmds.append(cur) if cur else None
            cur = []
        else:
            cur.append(tok)
    result = []
    for cmd in cmds:
        while cmd and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*=.*", cmd[0]):
            cmd = cmd[1:]
        kept, skip = [], False
        for tok in cmd:
            if skip:
                skip = False
            elif tok in (">", ">>", "<", "2>"):
                skip = True
            elif not tok.startswith((">", "<")):
                kept.append(tok)
        if kept:
            result.append(kept)
    return result


def parse_with(module, args):
    """Parse args with the module's real parser; an error is the parser's own one-line message."""
    parser = importlib.import_module(module).build_parser()
    try:
        parser.parse_args(args)
    except SystemExit as e:
        assert e.code == 0, f"{parser.prog} {shlex.join(args)}: the parser refuses it (exit {e.code})"


def check_python(args):
    if args[:1] == ["-m"]:
        module, rest = args[1], args[2:]
        if module in NOT_OUR_MODULES:
            for a in rest:
                if a.startswith("tests/"):
                    assert (ROOT / a).is_file(), f"{a}: no such test file"
            return
        parse_with(MODULES.get(module, module), rest)
        return
    script = ROOT / args[0]
    assert script.suffix == ".py" and script.is_file(), f"{args[0]}: no such script"
    source = script.read_text(encoding="utf-8")
    for flag in (a.split("=")[0] for a in args[1:] if a.startswith("--")):
        assert f'"{flag}"' in source, f"{args[0]}: defines no {flag}"


def app_settings():
    """Every environment variable the rating app reads: its settings' (rating_app.SETTINGS), and libpq's password."""
    from rating_app import SETTINGS

    return {s.env for s in SETTINGS.values()} | {"PGPASSWORD"}


def check_settings(args):
    """`export NAME=value ...` in the docs sets only variables the app reads (a misspelt one is silently ignored)."""
    names = {a.partition("=")[0] for a in args}
    unknown = sorted(names - app_settings())
    assert not unknown, f"export {unknown}: the rating app reads no such setting"


def check(cmd):
    name, args = cmd[0], cmd[1:]
    if name == "export":
        return check_settings(args)
    if name in NOT_OURS:
        return
    if name == "python":
        return check_python(args)
    if name == "torchrun":
        i = args.index("-m")
        return parse_with(args[i + 1], args[i + 2 :])
    if name == "moglow-eval":
        if args == ["--version"]:
            from moglow_eval.console import main

            assert main(["--version"]) == 0
            return
        module, prefix = CONSOLE[args[0]]
        return parse_with(module, prefix + args[1:])
    path = ROOT / name
    assert path.is_file() and path.stat().st_mode & 0o111, f"{name}: not ours and not an executable in the tree"


SHOWN = [(p, n, line) for p in DOCS for n, line in bash_lines(p)]


def test_the_docs_show_commands():
    """The collector finds the commands (an empty list would make the check below pass for nothing)."""
    files = {p.name for p, _, _ in SHOWN}
    assert {"README.md", "moglow-study.md", "models.md", "hosting.md", "data.md"} <= files
    assert len(SHOWN) > 60


@pytest.mark.parametrize("path,n,line", SHOWN, ids=[f"{p.name}:{n}" for p, n, _ in SHOWN])
def test_every_command_shown_parses(path, n, line, capsys):
    cmds = commands(line)
    assert cmds, f"{path.name}:{n}: no command in {line!r}"
    for cmd in cmds:
        check(cmd)


def test_the_checker_catches_a_bad_flag_and_an_unknown_command():
    with pytest.raises(AssertionError, match="refuses"):
        check(["python", "-m", "generation.make_stimuli", "--no-such-flag"])
    with pytest.raises(AssertionError, match="refuses"):
        check(["moglow-eval", "report"])  # the ratings file is required
    with pytest.raises(AssertionError, match="defines no"):
        check(["python", "bench/bench_sampling.py", "--no-such-flag"])
    with pytest.raises(AssertionError, match="reads no such setting"):
        check(["export", "RATINGS_PER_CLIPS=20"])
    with pytest.raises(AssertionError, match="not ours"):
        check(["wget", "http://example.org"])
    assert commands("A=1 python -m x --out y > z && cd d") == [["python", "-m", "x", "--out", "y"], ["cd", "d"]]
    assert commands("export T=$(python -c 'print(f(1))') C=1") == [["export", "T=SUBST", "C=1"]]


# ---------------------------------------------------------------- the site


def nav_pages():
    text = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    return set(re.findall(r":\s*([\w.-]+\.md)\s*$", text, re.M))


def test_every_page_is_in_the_nav():
    pages = {p.name for p in (ROOT / "docs").glob("*.md")}
    assert pages == nav_pages(), (sorted(pages - nav_pages()), sorted(nav_pages() - pages))
    assert {"CONTRACTS.md", "ARCHITECTURE.md"} <= nav_pages()


def test_every_image_exists():
    for path in DOCS:
        for ref in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", path.read_text(encoding="utf-8")):
            assert (path.parent / ref).is_file(), f"{path.name}: {ref} not found"
            assert "docs/img/" in str((path.parent / ref).resolve()), f"{path.name}: {ref}: images live in docs/img/"


def test_mkdocs_build_strict(tmp_path):
    pytest.importorskip("mkdocs", reason="mkdocs is not installed: pip install -e '.[dev]'")
    pytest.importorskip("material", reason="mkdocs-material is not installed: pip install -e '.[dev]'")
    pytest.importorskip("mkdocstrings", reason="mkdocstrings is not installed: pip install -e '.[dev]'")
    r = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    page = (tmp_path / "site" / "moglow-study" / "index.html").read_text(encoding="utf-8")
    assert 'src="../img/sheet_nat.png"' in page and (tmp_path / "site" / "img" / "sheet_nat.png").is_file()
    results = (tmp_path / "site" / "results" / "index.html").read_text(encoding="utf-8")
    assert all(f'id="{e}"' in results for e in results_entries())
    api = (tmp_path / "site" / "api" / "index.html").read_text(encoding="utf-8")
    names = re.findall(r"^::: ([\w.]+)\s*$", (ROOT / "docs" / "api.md").read_text(encoding="utf-8"), re.M)
    assert names and all(f'id="{n}"' in api for n in names)  # mkdocstrings rendered each function named


# ---------------------------------------------------------------- figures and their RESULTS entries

FIELDS = ("- Command:", "- Machine:", "- Same-run baseline:", "- Date:")


def results_entries():
    """{id: text} of bench/RESULTS.md's entries: one `### id` heading each."""
    text = (ROOT / "bench" / "RESULTS.md").read_text(encoding="utf-8")
    parts = re.split(r"^### ([a-z0-9-]+)\s*$", text, flags=re.M)
    return {parts[i]: parts[i + 1].split("\n## ")[0] for i in range(1, len(parts), 2)}


def test_every_results_entry_has_its_command_machine_baseline_and_date():
    entries = results_entries()
    assert len(entries) >= 15
    for name, text in entries.items():
        missing = [f for f in FIELDS if f not in text]
        assert not missing, f"bench/RESULTS.md ### {name}: add {missing}"
        assert re.search(r"- Date: .*\d{4}-\d\d-\d\d", text), name


def results_links(path):
    text = path.read_text(encoding="utf-8")
    return re.findall(r"\]\(([^)]*(?:RESULTS\.md|results\.md)[^)]*)\)", text)


def test_every_link_to_a_figure_names_an_existing_entry():
    entries = results_entries()
    linked = set()
    for path in DOCS:
        for link in results_links(path):
            target, _, anchor = link.partition("#")
            expected = "bench/RESULTS.md" if path.name == "README.md" else "results.md"
            assert target == expected, f"{path.name}: link {link}: use {expected}#ENTRY"
            if anchor:  # a link without an anchor is navigation to the whole page, not a figure's source
                assert anchor in entries, f"{path.name}: link {link}: no entry '{anchor}' in bench/RESULTS.md"
                linked.add(anchor)
    unlinked = sorted(set(entries) - linked)
    assert len(unlinked) <= len(entries) // 2, f"most entries should be quoted somewhere; unlinked: {unlinked}"


def test_figures_quoted_beside_a_results_mention_link_to_an_entry():
    """A sentence that cites RESULTS for a figure does so with a link to the entry, not the bare file name."""
    for path in DOCS:
        if path.name in ("CONTRACTS.md", "ARCHITECTURE.md"):
            continue  # CONTRACTS.md and ARCHITECTURE.md quote no figures; ARCHITECTURE.md is edited elsewhere
        text = path.read_text(encoding="utf-8")
        bare = re.findall(r"(?<!\])\((?:bench/)?RESULTS(?:\.md)?[^)#]*\)", text)
        assert not bare, f"{path.name}: {bare}: link to the entry instead"


# ---------------------------------------------------------------- release files


def test_citation_cites_the_tool_and_the_moglow_paper():
    yaml = pytest.importorskip("yaml", reason="pyyaml is not installed: pip install -e '.[dev]'")
    import tomllib

    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert cff["type"] == "software" and cff["version"] == project["version"]
    assert cff["license"] == "MIT" and "MIT" in (ROOT / "LICENSE").read_text().splitlines()[0]
    assert "preferred-citation" not in cff  # it would replace the tool in "cite this repository"
    paper = cff["references"][0]
    assert paper["title"].startswith("MoGlow: Probabilistic and controllable motion synthesis")
    assert [a["family-names"] for a in paper["authors"]] == ["Henter", "Alexanderson", "Beskow"]
    assert (paper["journal"], paper["volume"], paper["issue"], paper["year"]) == (
        "ACM Transactions on Graphics",
        39,
        6,
        2020,
    )
