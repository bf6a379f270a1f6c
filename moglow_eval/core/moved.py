"""Commands that moved, and the one line their old path answers (CHANGELOG, *Changed*).

A command a user could have typed in a script or a lab notebook (`python -m generation.train`) keeps a file at its
old path whose only statement is `moved.point(...)`: run, it ends with one line naming the new command and exit code
2, instead of Python's bare "No module named"; imported, it raises ModuleNotFoundError with the same line. MOVED is
the one list of those moves; modules that were only ever imported are listed in the CHANGELOG.
"""

import sys
from pathlib import Path

from .cli import EXIT_USAGE

VERSION = "0.2.0"  # the release whose CHANGELOG lists the moves
MOVED = {
    "generation.train": "generation.training.train",
    "generation.prepare_data": "generation.data.prepare",
    "generation.import_motion": "generation.data.import_motion",
    "generation.sample": "generation.sampling.sample",
    "generation.pretrained": "generation.sampling.pretrained",
    "generation.demo_study": "generation.own_study.demo_study",
    "generation.motion_encoder": "generation.metrics.fmd",
}


def message(old: str) -> str:
    """The one line an old command path answers."""
    return f"python -m {old} moved to python -m {MOVED[old]} in {VERSION} (CHANGELOG, Changed): run that instead"


def point(old: str, name: str):
    """What an old path's file does: `point(__spec__.name, __name__)`. Run (`python -m old`), one line on stderr and
    exit code 2; imported, ModuleNotFoundError naming the new module."""
    if name == "__main__":
        print(f"error: {message(old)}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE)
    raise ModuleNotFoundError(message(old), name=old)


def is_pointer(path: Path) -> bool:
    """Whether a file is one of MOVED's pointers (the architecture test counts it as no module of its part)."""
    text = path.read_text(encoding="utf-8")
    return "moved.point(__spec__.name, __name__)" in text and text.count("\n") <= 6
