"""`python -m analysis.board --task NAME=REPORT ...`: the results of one or more reports published as a static site.

    python -m analysis.board --task NAME=REPORT [--task ...] [--mode challenge|leaderboard] [--publish] [--out board/]
    moglow-eval board ...

The site is HTML with the data beside it.

Each --task is one report folder (`python -m analysis.report --out`): the site shows, per task, each system's score
with its interval, its rank interval and group, and its number of votes or ratings (tables, and the same as CSV and
JSON); the methods paragraph; a page per system with a few of its videos (the blinded clips, copied from the stimulus
folder: `--stimuli NAME=FOLDER`, else `stimuli/` beside the export); and the data release (the export, the
manifest, the report's stats.json), on a Data page. Every page carries the tool's version, the release and its date.

- `--mode challenge` (a new board's default): publishes once. Built without --publish, the board shows the tasks,
  how each is evaluated and the date, and nothing of any system; with --publish it becomes release 1, and later
  builds into it are refused.
- `--mode leaderboard`: every build publishes a release (releases/1/, releases/2/, ...); the top shows the newest and
  lists every release, and no build rewrites an earlier one.

Pages carry no script and no file from elsewhere, and read on a phone. Writes are atomic (analysis.board.folder).
Bad input (a missing report, a stats.json that is not one, a folder that is not a board, ...) is one line, exit 2.
"""

from __future__ import annotations

import argparse
import datetime
import re
import sys
import time
from pathlib import Path

from moglow_eval.core import cli, whole_files

from ..data.load import AnalysisError
from ..page.methods import methods_outline, tool_version
from . import folder, pages
from .release import FORMAT, FORMAT_VERSION, dumps, write_release
from .tasks import TASK_NAME, TaskSpec, read_task

TITLES = {"challenge": "Challenge results", "leaderboard": "Leaderboard"}
DEFAULT_VIDEOS = 3


def _top(release: dict, releases: list[dict]) -> dict:
    """The top's board.json: the newest release (its paths relative to `latest`), and every release."""
    listed = [{**r, "path": f"{folder.RELEASES}/{r['release']}/"} for r in releases]
    head = {k: v for k, v in release.items() if k != "tasks"}
    latest = f"{folder.RELEASES}/{release['release']}/"
    return {**head, "published": True, "latest": latest, "releases": listed, "tasks": release["tasks"]}


def _check_mode(out: Path, board, mode: str) -> None:
    if board is None:
        return
    if board.mode != mode:
        raise AnalysisError(f"--out {out}: a {board.mode} board; it cannot be built as a {mode} (--mode {board.mode})")
    if mode == "challenge" and board.published:
        raise AnalysisError(
            f"--out {out}: a challenge board that has published, and a challenge publishes once; give a new --out "
            "(or --mode leaderboard for a board that publishes again)"
        )


def _preview(out: Path, board, tasks, title: str, date: str) -> dict:
    """A challenge's board before it publishes: the tasks and how each is evaluated, nothing of any system."""
    doc = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "title": title,
        "mode": "challenge",
        "published": False,
        "date": date,
        "tool_version": tool_version(),
        "tasks": [{"task": t.name, "design": t.design.name, "methods": methods_outline(t.design)} for t in tasks],
    }
    files = {folder.BOARD_FILE: dumps(doc), "index.html": pages.preview_page(doc)}
    if board is None:
        with folder.staged(out.parent, out.name) as tmp:
            for name, text in files.items():
                (tmp / name).write_text(text, encoding="utf-8")
            folder.move_into_place(tmp, out)
    else:
        for name, text in files.items():
            whole_files.write_whole(out / name, text)
    return doc


def _publish(out: Path, board, tasks, head: dict) -> dict:
    """A new release: into a board made whole beside `out`, or into releases/N of the board there."""
    earlier = board.releases if board is not None else []
    number = 1 + max((r["release"] for r in earlier), default=0)
    head = {**head, "release": number}
    releases = [*earlier, {"release": number, "date": head["date"]}]
    if board is None:
        with folder.staged(out.parent, out.name) as tmp:
            target = tmp / folder.RELEASES / str(number)
            target.mkdir(parents=True)
            release = write_release(target, tasks, head)
            top = _top(release, releases)
            (tmp / folder.BOARD_FILE).write_text(dumps(top), encoding="utf-8")
            (tmp / "index.html").write_text(pages.results_page(release, f"releases/{number}/", "", releases), "utf-8")
            folder.move_into_place(tmp, out)
        return top
    with folder.staged(out / folder.RELEASES, "release") as tmp:
        release = write_release(tmp, tasks, head)
        folder.move_into_place(tmp, out / folder.RELEASES / str(number))
    top = _top(release, releases)
    whole_files.write_whole(out / folder.BOARD_FILE, dumps(top))
    whole_files.write_whole(out / "index.html", pages.results_page(release, f"releases/{number}/", "", releases))
    return top


def build_board(specs, out="board", mode=None, publish=False, date=None, title=None, n_videos=DEFAULT_VIDEOS) -> dict:
    """Build the board of `specs` (analysis.board.tasks.TaskSpec, one per task) into `out`.

    `mode`: "challenge" or "leaderboard" (None: the board's own, else challenge). `publish`: a challenge publishes
    (a leaderboard publishes every build). `date`: YYYY-MM-DD (None: today, UTC). `title`: the board's (None: its
    own, else per mode). `n_videos`: videos per system and task. Returns the top's board.json document. Raises
    AnalysisError, one line, for bad input; every input is checked before anything is written.
    """
    if not str(out).strip():  # Path("") is the current folder, which a build cannot move into place
        raise AnalysisError("--out: empty; give the board's folder")
    out = Path(out)
    board = folder.inspect(out)
    mode = mode or (board.mode if board is not None else "challenge")
    if mode not in folder.MODES:
        raise AnalysisError(f"--mode {mode!r}: none of {', '.join(folder.MODES)}")
    _check_mode(out, board, mode)
    tasks = [read_task(s, n_videos) for s in specs]
    date = date or time.strftime("%Y-%m-%d", time.gmtime())
    last = max(board.releases, key=lambda r: r["date"], default=None) if board is not None else None
    if last is not None and date < last["date"]:  # YYYY-MM-DD, as --date takes and a release writes: strings in order
        raise AnalysisError(
            f"--date {date}: before release {last['release']}'s date {last['date']}; a board's releases go forward"
        )
    title = title or (board.title if board is not None and board.title else TITLES[mode])
    if mode == "challenge" and not publish:
        return _preview(out, board, tasks, title, date)
    head = {"title": title, "mode": mode, "date": date, "tool_version": tool_version()}
    return _publish(out, board, tasks, head)


# ------------------------------------------------------------------------------------------------ command line
def _pair(what: str, name_pattern: re.Pattern):
    """An argparse type: NAME=PATH, NAME a task's name."""

    def parse(text):
        name, sep, path = text.partition("=")
        if not sep or not path or not name_pattern.fullmatch(name):
            raise argparse.ArgumentTypeError(
                f"expected NAME={what} with NAME letters, digits, _ or - (at most 40), got {text[:80]!r}"
            )
        return name, Path(path)

    return parse


def _date(text):
    try:
        if not re.fullmatch(r"\d{4}-\d{2}-\d{2}", text):
            raise ValueError
        datetime.date.fromisoformat(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a date YYYY-MM-DD, got {text[:40]!r}") from None
    return text


def _title(text):
    if not text.strip() or len(text) > 200:
        raise argparse.ArgumentTypeError("expected a title of 1-200 characters")
    odd = next((c for c in text.strip() if not c.isprintable()), None)
    if odd is not None:  # a terminal's escape or a bell would reach every visitor's page and the board's file
        raise argparse.ArgumentTypeError(
            f"expected one line of printable text, got the control character U+{ord(odd):04X}"
        )
    return text.strip()


def build_parser():
    """The command's argument parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    ap = cli.ArgumentParser(prog="python -m analysis.board", description=__doc__.splitlines()[0])
    ap.add_argument("--task", action="append", required=True, type=_pair("REPORT", TASK_NAME), metavar="NAME=REPORT",
                    help="a task: its name on the board and its report folder (python -m analysis.report --out); "
                    "repeat for each task, in the order the board shows them")  # fmt: skip
    ap.add_argument("--stimuli", action="append", default=[], type=_pair("FOLDER", TASK_NAME), metavar="NAME=FOLDER",
                    help="the task's stimulus folder (its manifest.csv and videos; default: stimuli/ beside the "
                    "export)")  # fmt: skip
    ap.add_argument("--export", action="append", default=[], type=_pair("FILE", TASK_NAME), metavar="NAME=FILE",
                    help="the task's export (ratings.csv, pairs.csv; default: the file its stats.json names as "
                    "input)")  # fmt: skip
    ap.add_argument("--mode", choices=folder.MODES, help="challenge (publishes once) or leaderboard (publishes "
                    "every build, keeping every release); default: the board's own, else challenge")  # fmt: skip
    ap.add_argument("--publish", action="store_true", help="challenge: publish the results (without it the board "
                    "shows nothing of any system); a leaderboard publishes every build")  # fmt: skip
    ap.add_argument(
        "--date", type=_date, metavar="YYYY-MM-DD", help="the release's date, YYYY-MM-DD (default: today, UTC)"
    )
    ap.add_argument("--title", type=_title, metavar="TEXT",
                    help="the board's title (default: its own, else 'Challenge results' or 'Leaderboard')")  # fmt: skip
    ap.add_argument("--videos", type=cli.number(int, 0, 20), default=DEFAULT_VIDEOS, metavar="N",
                    help=f"videos per system and task (0-20; default {DEFAULT_VIDEOS})")  # fmt: skip
    ap.add_argument("--out", default="board", help="the board's folder (default: board/)")
    ap.add_argument("--quiet", action="store_true", help="print nothing")
    return ap


def specs_of(args) -> list[TaskSpec]:
    """The tasks of the command line, each with its --stimuli and --export; one line for a name given twice or a
    --stimuli or --export of no task."""
    names = [name for name, _ in args.task]
    if len(set(names)) != len(names):
        twice = next(n for n in names if names.count(n) > 1)
        raise AnalysisError(f"--task {twice}: given twice")
    extra = {}
    for flag, pairs in (("stimuli", args.stimuli), ("export", args.export)):
        for name, path in pairs:
            if name not in names:
                raise AnalysisError(f"--{flag} {name}={path}: no --task {name}")
            if (flag, name) in extra:
                raise AnalysisError(f"--{flag} {name}: given twice")
            extra[(flag, name)] = path
    return [TaskSpec(n, p, extra.get(("stimuli", n)), extra.get(("export", n))) for n, p in args.task]


def _main(argv):
    args = build_parser().parse_args(argv)
    doc = build_board(specs_of(args), args.out, args.mode, args.publish, args.date, args.title, args.videos)
    if not args.quiet:
        index = Path(args.out) / "index.html"
        if doc["published"]:
            systems = {r["system"] for t in doc["tasks"] for r in t["systems"]}
            tasks, n = len(doc["tasks"]), len(systems)
            print(f"Board: {index} (release {doc['release']} of {doc['date']}: {tasks} task{'s' * (tasks != 1)}, "
                  f"{n} system{'s' * (n != 1)})")  # fmt: skip
        else:
            print(f"Board: {index} (not yet published: no system is shown; --publish publishes it)")
    return 0


def main(argv=None):
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
