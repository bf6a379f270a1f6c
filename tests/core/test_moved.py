"""Moved commands are announced (issue 53, item 3): every old command path in moglow_eval.core.moved answers one line
naming its new home, run or imported, and the new home exists; the CHANGELOG names every move."""

import importlib
import importlib.util
import subprocess
import sys

import pytest
from helpers.paths import ROOT

from moglow_eval.core import moved


@pytest.mark.parametrize("old", sorted(moved.MOVED))
def test_an_old_command_path_points_to_the_new_one(old):
    new = moved.MOVED[old]
    assert importlib.util.find_spec(new) is not None, new
    assert moved.is_pointer(ROOT / (old.replace(".", "/") + ".py"))
    run = subprocess.run([sys.executable, "-m", old, "--help"], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert run.returncode == 2
    assert run.stdout == ""
    assert run.stderr.strip().splitlines() == [f"error: {moved.message(old)}"]
    assert f"python -m {new}" in run.stderr
    sys.modules.pop(old, None)
    with pytest.raises(ModuleNotFoundError, match=f"python -m {new}"):
        importlib.import_module(old)


def test_the_changelog_names_every_move():
    changelog = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    missing = [f"{old} -> {new}" for old, new in moved.MOVED.items() if f"`{old}`" not in changelog]
    assert not missing, missing


def test_a_real_module_is_no_pointer():
    assert not moved.is_pointer(ROOT / "generation" / "make_stimuli.py")
