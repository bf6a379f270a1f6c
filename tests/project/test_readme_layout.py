"""The README's Layout is one short line per top-level part and points to docs/ARCHITECTURE.md; ARCHITECTURE names
every room of every part and every module in it, and names nothing that is not there (issue 53, item 4)."""

import re

import pytest
from helpers.paths import ROOT
from helpers.rooms import ROOMS

ARCHITECTURE = ROOT / "docs" / "ARCHITECTURE.md"
ROW_CHARS = 150  # one line of the README's table: what a part holds, not its modules


def table_rows(text, heading):
    """{first cell without backticks: the rest of the row} of the table under `heading` (up to the next heading)."""
    section = text.split(heading, 1)[1].split("\n#", 1)[0]
    return {m[1]: m[2] for m in re.finditer(r"^\| `([\w./ ()]+?)/?` \| (.*) \|$", section, re.M)}


def layout_rows():
    return table_rows((ROOT / "README.md").read_text(encoding="utf-8"), "## Layout")


def modules(folder):
    """Module names of a folder (its .py files less __init__/__main__), and its subpackages as `name/`."""
    names = {p.stem for p in folder.glob("*.py") if p.stem not in ("__init__", "__main__")}
    return names | {f"{p.name}/" for p in folder.iterdir() if p.is_dir() and (p / "__init__.py").is_file()}


def room_rows():
    """(part, room, the row's text, the room's folder) for every room in ARCHITECTURE, and for moglow_eval.core and
    rendering, whose rows in the parts table list their modules."""
    text = ARCHITECTURE.read_text(encoding="utf-8")
    parts = table_rows(text, "An arrow between boxes")
    # the parts table: | part | may import | holds |; a room's table: | room | holds | may import |
    rows = [("moglow_eval.core", "", parts["moglow_eval.core"].split(" | ")[-1], ROOT / "moglow_eval/core")]
    rows.append(("rendering", "", parts["rendering"].split(" | ")[-1], ROOT / "rendering"))
    for part in ROOMS:
        rooms = table_rows(text, f"### {part}'s rooms")
        assert set(rooms) == set(ROOMS[part]), f"ARCHITECTURE, {part}'s rooms: {sorted(rooms)} vs {ROOMS[part]}"
        rows += [(part, room, rooms[room].split(" | ")[0], ROOT / part / room) for room in ROOMS[part]]
    return rows


def test_readme_layout_is_a_short_line_per_top_level_part():
    rows = layout_rows()
    tracked = {"moglow_eval/core", "moglow_eval", "generation", "rendering", "rating_app", "analysis", "bench", "docs"}
    tracked |= {"tests", "scripts"}
    assert all((ROOT / f).is_dir() for f in tracked)
    assert set(rows) == tracked, sorted(set(rows) ^ tracked)
    long = {folder: len(row) for folder, row in rows.items() if len(row) > ROW_CHARS}
    assert not long, f"README Layout: one short line per part ({ROW_CHARS} characters), not module lists: {long}"
    section = (ROOT / "README.md").read_text(encoding="utf-8").split("## Layout", 1)[1].split("\n## ", 1)[0]
    assert "docs/ARCHITECTURE.md" in section


@pytest.mark.parametrize("part", ["moglow_eval.core", "rendering", *ROOMS])
def test_architecture_names_every_module_of_every_room(part):
    missing = []
    for _, room, row, folder in (r for r in room_rows() if r[0] == part):
        for name in modules(folder):
            if name.endswith("/"):  # a design's folder: its modules named in the row too
                missing += [f"{room}/{name}{m}" for m in modules(folder / name) if f"`{m}`" not in row]
                name = name.rstrip("/")
            if f"`{name}`" not in row and f"`{name}/`" not in row:
                missing.append(f"{room}/{name}")
    assert not missing, f"docs/ARCHITECTURE.md, {part}: add {missing}"


@pytest.mark.parametrize("part", ["moglow_eval.core", "rendering", *ROOMS])
def test_architecture_names_only_what_exists(part):
    gone = []
    for _, room, row, folder in (r for r in room_rows() if r[0] == part):
        for name in re.findall(r"`([a-z_]+/?)`", row):
            found = any(folder.rglob(f"{name.rstrip('/')}.py")) or (folder / name.rstrip("/")).is_dir()
            if not found and not (ROOT / part.replace(".", "/") / f"{name}.py").exists():
                gone.append(f"{room}: {name}")
    known = {"create_app", "run"}  # names of functions, not files
    gone = [g for g in gone if g.split(": ")[1].rstrip("/") not in known]
    assert not gone, f"docs/ARCHITECTURE.md, {part}: {gone} not in the tree"


def test_ci_runs_the_readmes_two_commands():
    """A fresh machine needs the README's install and test commands only, and CI runs exactly those."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = text.split("## Set up a fresh machine", 1)[1].split("```bash\n", 1)[1].split("```", 1)[0]
    commands = [line.split("  #")[0].strip() for line in block.splitlines() if line.strip()]
    assert len(commands) == 2 and commands[1] == "python -m pytest -q"
    ci = [line.strip() for line in (ROOT / ".ci/run").read_text().splitlines()]
    assert [c for c in ci if c in commands] == commands
    assert [c for c in ci if not c.startswith("#") and c][-3:] == ["ruff check .", "ruff format --check .", commands[1]]
