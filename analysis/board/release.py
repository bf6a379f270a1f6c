"""One release of a board, written whole into an empty folder: its data (release.json; per task its table as CSV
and JSON, its export, manifest, stats.json and methods), its videos and its pages.

    release.json          the release's tables, files and videos (docs/CONTRACTS.md, "Board")
    index.html            the results: per task, each system's score, interval and rank interval
    tasks/TASK.html       a task's whole table, what it means, its methods paragraph and its files
    systems/SYSTEM.html   a system's results in each task and a few of its videos
    data.html             the data release: every file with its size and SHA-256
    data/TASK.csv, data/TASK.json                     the task's table
    data/TASK/EXPORT, data/TASK/manifest.csv, data/TASK/stats.json, data/TASK/methods.txt
                          the data release: the export (ratings.csv, pairs.csv) without the raters' ids on the crowd
                          platform, the manifest, the report's stats.json without the organiser's path, its methods
    videos/CLIP.mp4       the blinded clips, copied (their names are the random clip ids the raters saw)

Nothing here reads the clock: a release is a function of its inputs, its number, its date and the tool's version.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import re
from pathlib import Path

from moglow_eval.core import tables, user_files

from ..data.load import AnalysisError
from . import pages
from .clips import MANIFEST, MAX_MANIFEST_BYTES
from .tasks import STATS, Task

FORMAT, FORMAT_VERSION = "moglow-eval board", 1
RELEASE_FILE = "release.json"
TABLE_COLUMNS = ("task", "rank", "rank_low", "rank_high", "group", "system", "score", "low", "high", "n")
MAX_VIDEO_BYTES = 2 << 30  # a stimulus video is a few MB; nothing a study plays is this large
CHUNK = 1 << 20
PLAIN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,99}")
# The crowd platform's participant id (Prolific's PID, CONTRACTS §6): the data release never publishes it.
PRIVATE = ("external_id",)


def copy_file(src: Path, dst: Path, max_bytes: int, what: str) -> dict:
    """`src` copied to `dst` (a regular file, read within `max_bytes`: never a link to it); its size and SHA-256."""
    digest, size = hashlib.sha256(), 0
    with user_files.open_regular(src, max_bytes, AnalysisError, what) as fh, open(dst, "xb") as out:
        while chunk := fh.read(CHUNK):
            size += len(chunk)
            if size > max_bytes:
                raise AnalysisError(f"{src}: grew past the size a {what} can be while it was copied")
            digest.update(chunk)
            out.write(chunk)
    return {"bytes": size, "sha256": digest.hexdigest()}


def copy_export(src: Path, dst: Path) -> dict:
    """The export, streamed row by row, without the PRIVATE columns; its size and SHA-256."""
    with user_files.csv_rows(src, tables.MAX_BYTES, AnalysisError, "export") as (header, rows):
        keep = [c for c in header if c not in PRIVATE]
        with open(dst, "x", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh, lineterminator="\n")
            w.writerow(keep)
            w.writerows([row[c] for c in keep] for _, row in rows)
    digest, size = hashlib.sha256(), 0
    with open(dst, "rb") as fh:
        while chunk := fh.read(CHUNK):
            size += len(chunk)
            digest.update(chunk)
    return {"bytes": size, "sha256": digest.hexdigest()}


def write_text(path: Path, text: str) -> dict:
    data = text.encode("utf-8")
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "xb") as fh:
        fh.write(data)
    return {"bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}


def table_rows(task: Task) -> list[dict]:
    """The task's table as its CSV and JSON hold it: the numbers of stats.json unrounded, best first."""
    return [
        {
            "task": task.name,
            "rank": pages.rank_text(r).replace("–", "-"),
            **{k: r[k] for k in ("rank_low", "rank_high", "group", "system", "score", "low", "high", "n")},
        }
        for r in task.standings.rows
    ]


def table_csv(rows: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=TABLE_COLUMNS, lineterminator="\n")
    w.writeheader()
    w.writerows({k: ("" if v is None else v) for k, v in r.items()} for r in rows)  # repr of a float: exact
    return buf.getvalue()


def export_name(task: Task) -> str:
    """The export's name on the board: its own (ratings.csv, pairs.csv) where that is a plain file name."""
    name = task.export.name
    return name if PLAIN.fullmatch(name) and name not in (MANIFEST, STATS, "methods.txt") else "export.csv"


def _data_files(folder: Path, task: Task, rows: list[dict]) -> list[dict]:
    """The task's files, written under data/: [{"what", "path" (from the release's folder), "bytes", "sha256"}]."""
    st = task.standings
    table = {"task": task.name, "design": task.design.name, "score": st.score, "about": st.about, "count": st.count}
    own = f"data/{task.name}/"
    (folder / own).mkdir(parents=True)
    export, manifest = own + export_name(task), own + MANIFEST
    # The report's stats.json as it is, but for the path of the export on the organiser's machine.
    stats = json.dumps({**task.doc, "input": export_name(task)}, indent=1)
    files = [
        ("the table, CSV", f"data/{task.name}.csv", lambda p: write_text(p, table_csv(rows))),
        ("the table, JSON", f"data/{task.name}.json", lambda p: write_text(p, dumps({**table, "systems": rows}))),
        ("the raters' answers", export, lambda p: copy_export(task.export, p)),
        ("the stimulus manifest", manifest, lambda p: copy_file(task.manifest, p, MAX_MANIFEST_BYTES, "manifest")),
        ("the report's statistics", own + STATS, lambda p: write_text(p, stats)),
        ("the methods paragraph", own + "methods.txt", lambda p: write_text(p, task.methods + "\n")),
    ]
    return [{"what": what, "path": path, **write(folder / path)} for what, path, write in files]


def _videos(folder: Path, task: Task, copied: set[str]) -> dict[str, list[dict]]:
    """{system: [{"clip_id", "item", "video"}]}: its clips copied to videos/ (each clip once per release)."""
    out = {}
    for system, clips in task.videos.items():
        out[system] = []
        for clip in clips:
            path = f"videos/{clip.clip_id}.mp4"
            if clip.clip_id not in copied:
                copy_file(clip.source, folder / path, MAX_VIDEO_BYTES, "video")
                copied.add(clip.clip_id)
            out[system].append({"clip_id": clip.clip_id, "item": clip.item, "video": path})
    return out


def dumps(doc) -> str:
    return json.dumps(doc, indent=1, ensure_ascii=False, allow_nan=False) + "\n"


def write_release(folder: Path, tasks: list[Task], head: dict) -> dict:
    """Write the release of `tasks` into the empty `folder`; `head` is {"title", "mode", "release", "date",
    "tool_version"}. Returns its release.json document."""
    (folder / "videos").mkdir()
    copied: set[str] = set()
    entries = []
    for task in tasks:
        rows = table_rows(task)
        entries.append(
            {
                "task": task.name,
                "design": task.design.name,
                "score": task.standings.score,
                "about": task.standings.about,
                "count": task.standings.count,
                "methods": task.methods,
                "systems": rows,
                "files": _data_files(folder, task, rows),
                "videos": _videos(folder, task, copied),
            }
        )
    release = {"format": FORMAT, "format_version": FORMAT_VERSION, **head, "tasks": entries}
    write_text(folder / "index.html", pages.results_page(release, "", "../../"))
    for task in release["tasks"]:
        write_text(folder / "tasks" / f"{task['task']}.html", pages.task_page(release, task))
    systems = dict.fromkeys(r["system"] for task in release["tasks"] for r in task["systems"])
    for system in systems:
        write_text(folder / "systems" / f"{system}.html", pages.system_page(release, system))
    write_text(folder / "data.html", pages.data_page(release))
    write_text(folder / RELEASE_FILE, dumps(release))
    return release
