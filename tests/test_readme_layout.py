"""The README's Layout section names every module of the product, and names nothing that is not there."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("moglow_eval/core", "rendering", "rating_app", "analysis")


def layout_rows():
    """{folder: the text of its row} from the README's Layout table."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## Layout", 1)[1].split("\n## ", 1)[0]
    return {m[1]: m[2] for m in re.finditer(r"^\| `([\w/]+)/` \| (.*) \|$", section, re.M)}


def modules(package):
    """Module and subpackage names of a package, as the README names them (`simulate/` for a subpackage)."""
    folder = ROOT / package
    names = {p.stem for p in folder.glob("*.py") if p.stem not in ("__init__", "__main__")}
    names |= {f"{p.name}/" for p in folder.iterdir() if p.is_dir() and (p / "__init__.py").is_file()}
    return names


@pytest.mark.parametrize("package", PACKAGES)
def test_layout_names_every_module(package):
    row = layout_rows()[package]
    missing = sorted(m for m in modules(package) if f"`{m}`" not in row and f"`{m.rstrip('/')}`" not in row)
    assert not missing, f"README Layout, {package}/: add {missing}"


@pytest.mark.parametrize("package", PACKAGES)
def test_layout_names_only_what_exists(package):
    folder = ROOT / package
    named = re.findall(r"`([\w.]+/?)`", layout_rows()[package])
    gone = [n for n in named if not any(folder.rglob(f"{n}.py")) and not (folder / n.rstrip("/")).exists()]
    gone = [n for n in gone if n not in ("create_app", "metrics.csv", "dataset.npz")]  # names of things, not files
    assert not gone, f"README Layout, {package}/: {gone} not in the tree"


def test_layout_gives_generation_a_row_per_subpackage():
    """generation/ is read by concept: a row of its own for each subpackage (what it holds, not its 30 modules),
    and the generation/ row names what sits outside them."""
    rows = layout_rows()
    folder = ROOT / "generation"
    subs = sorted(p.name for p in folder.iterdir() if (p / "__init__.py").is_file())
    assert subs and all(f"generation/{s}" in rows for s in subs), [s for s in subs if f"generation/{s}" not in rows]
    named = {r.removeprefix("generation/") for r in rows if r.startswith("generation/")}
    assert named <= set(subs), sorted(named - set(subs))
    top = [p.stem for p in folder.glob("*.py") if p.stem != "__init__"] + ["configs", "pretrained"]
    assert all(f"`{m}" in rows["generation"] for m in top), top


def test_layout_lists_every_tracked_folder():
    """Every top-level folder of the repository has its row (local outputs such as runs/ are not tracked)."""
    tracked = {"moglow_eval/core", "generation", "rendering", "rating_app", "analysis", "bench", "docs", "tests"}
    assert all((ROOT / f).is_dir() for f in tracked)
    assert tracked <= set(layout_rows()), sorted(tracked - set(layout_rows()))


def test_ci_runs_the_readmes_two_commands():
    """A fresh machine needs the README's install and test commands only, and CI runs exactly those."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    block = text.split("## Set up a fresh machine", 1)[1].split("```bash\n", 1)[1].split("```", 1)[0]
    commands = [line.split("  #")[0].strip() for line in block.splitlines() if line.strip()]
    assert len(commands) == 2 and commands[1] == "python -m pytest -q"
    ci = [line.strip() for line in (ROOT / ".ci/run").read_text().splitlines()]
    assert [c for c in ci if c in commands] == commands
    assert [c for c in ci if not c.startswith("#") and c][-3:] == ["ruff check .", "ruff format --check .", commands[1]]
