"""The board's folder: what a board holds, what a new build may do to it, and writes that never leave half a site.

    board.json, index.html    the top: the newest release (or a challenge's page before it publishes), every release
    releases/N/               release N, written once (analysis.board.release) and never touched again

A new board is built whole in a hidden folder beside --out and renamed into place. On a board that exists, a release
is built in a hidden folder inside releases/ and renamed to its number; then the top's two files are each replaced
whole. An interrupted build leaves the board as it was, or with one more release that the next build lists.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from moglow_eval.core import user_files

from ..data.load import AnalysisError
from .release import FORMAT, RELEASE_FILE

BOARD_FILE = "board.json"
RELEASES = "releases"
MODES = ("challenge", "leaderboard")
MAX_JSON_BYTES = 64 << 20
MAX_DEPTH = 12


@dataclass(frozen=True)
class Board:
    """A board folder as it stands: its mode, whether it has published, its title, and its releases' heads ({"release",
    "date"}, oldest first)."""

    mode: str
    published: bool
    title: str
    releases: list


def _read_board_json(path: Path, what: str) -> dict:
    doc = user_files.read_json(path, MAX_JSON_BYTES, AnalysisError, what, max_depth=MAX_DEPTH)
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise AnalysisError(f'{path}: not a board\'s {what} (no "format": "{FORMAT}")')
    return doc


def read_releases(out: Path) -> list[dict]:
    """The heads of the board's releases, oldest first; a release folder whose release.json is not its own is an
    error (a hidden folder, an interrupted build's, is left alone)."""
    folder = out / RELEASES
    if not folder.is_dir():
        return []
    heads = []
    for entry in sorted(folder.iterdir(), key=lambda p: (len(p.name), p.name)):
        if entry.name.startswith("."):
            continue
        doc = _read_board_json(entry / RELEASE_FILE, RELEASE_FILE) if entry.name.isdigit() else None
        if doc is None or doc.get("release") != int(entry.name) or not isinstance(doc.get("date"), str):
            raise AnalysisError(f"{entry}: not a release of this board (releases/N/ holds release N's {RELEASE_FILE})")
        heads.append({"release": doc["release"], "date": doc["date"]})
    return heads


def inspect(out: Path) -> Board | None:
    """The board at `out`, or None where there is none yet (no folder, or an empty one); AnalysisError for a file,
    or a folder that holds something else."""
    if not out.exists():
        return None
    if not out.is_dir():
        raise AnalysisError(f"--out {out}: is a file, not a board folder")
    if not (out / BOARD_FILE).exists():
        if any(out.iterdir()):
            raise AnalysisError(f"--out {out}: exists and is not a board (no {BOARD_FILE}); give a new or empty folder")
        return None
    doc = _read_board_json(out / BOARD_FILE, BOARD_FILE)
    if doc.get("mode") not in MODES:
        raise AnalysisError(f"{out / BOARD_FILE}: mode {str(doc.get('mode'))[:20]!r} is none of {', '.join(MODES)}")
    title = doc.get("title") if isinstance(doc.get("title"), str) else ""
    return Board(doc["mode"], doc.get("published") is True, title, read_releases(out))


def _open_up(folder: Path) -> None:
    """A staged folder readable as a web site is (mkdtemp makes it private)."""
    for path in [folder, *(p for p in folder.rglob("*") if p.is_dir())]:
        path.chmod(0o755)


@contextlib.contextmanager
def staged(parent: Path, name: str):
    """A hidden folder in `parent` to build in, removed unless the block renamed it away; AnalysisError naming the
    folder that was asked for (not the hidden one) where it cannot be made."""
    try:
        parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{name}.building-", dir=parent))
    except OSError as exc:
        where = f"{exc.filename}: " if exc.filename and Path(exc.filename).name[:1] != "." else ""
        raise AnalysisError(f"{parent / name}: cannot be made there ({where}{exc.strerror or exc})") from None
    try:
        yield tmp
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def move_into_place(tmp: Path, target: Path) -> None:
    """`tmp`, made readable, renamed to `target` (absent, or an empty folder): the whole of it appears at once."""
    _open_up(tmp)
    try:
        os.rename(tmp, target)
    except OSError as exc:
        raise AnalysisError(f"{target}: could not be put in place ({exc.strerror or exc}); was it written meanwhile?")
