"""A board's tasks: each one report folder (what `python -m analysis.report` writes), read with the export it was
made from and the stimulus folder its clips came from. Every file is read as a user's file and checked here, before
the board writes a byte; each problem is one line naming the file and the flag that fixes it.

- The results: the report's stats.json, read through its design's plug-in (analysis.designs.base.Design.standings):
  the board names no design.
- The export (the data release): the file stats.json's `input` names, taken as it was given to the report (relative
  to the folder the board is built from, else to the report folder's parent), or `--export TASK=FILE`. Its rows must
  be as many as the report counted, so that a board never publishes another study's answers beside these results.
- The stimuli (the videos, the manifest): `--stimuli TASK=FOLDER`, else the `stimuli/` folder beside the export, as
  `make_stimuli --out stimuli/` and the demo leave it. Every test clip the export shows must be in its manifest, of
  the same condition.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from moglow_eval.core import study, tables, user_files

from ..data.load import AnalysisError
from ..designs import DESIGNS
from ..designs.base import Design, Standings
from . import clips

TASK_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,39}")  # a task's name is a file name on the board
STATS = "stats.json"
STATS_MAX_BYTES = 256 << 20  # a report of a huge acr study lists every clip's mean: tens of MB
STATS_MAX_DEPTH = 16  # stats.json nests six or seven deep (without_exclusion, style, mixed_model, ...)
STIMULI = "stimuli"  # the default stimulus folder, beside the export


@dataclass(frozen=True)
class TaskSpec:
    """A task as the command line gives it: its name, its report folder, and where its export and stimuli are."""

    name: str
    report: Path
    stimuli: Path | None = None
    export: Path | None = None


@dataclass
class Task:
    """A task read and checked: its design, its stats.json and standings, its export, manifest and videos."""

    name: str
    report: Path
    design: Design
    doc: dict
    standings: Standings
    export: Path
    manifest: Path
    videos: dict[str, list[clips.Clip]] = field(default_factory=dict)

    @property
    def methods(self) -> str:
        return self.doc["methods"]


def read_stats(spec: TaskSpec) -> tuple[Path, dict, Design]:
    """(its path, the stats.json of the task's report, its design); AnalysisError, one line, otherwise."""
    if not spec.report.is_dir():
        raise AnalysisError(
            f"--task {spec.name}: {spec.report}: no such report folder (python -m analysis.report --out)"
        )
    path = spec.report / STATS
    doc = user_files.read_json(path, STATS_MAX_BYTES, AnalysisError, "stats.json", max_depth=STATS_MAX_DEPTH)
    if not isinstance(doc, dict) or not isinstance(doc.get("methods"), str):
        raise AnalysisError(f"{path}: not a report's stats.json (no methods paragraph; python -m analysis.report)")
    name = doc.get("design", study.DEFAULT_DESIGN)  # an acr stats.json names no design (CONTRACTS §8)
    if name not in DESIGNS:
        raise AnalysisError(f"{path}: design {str(name)[:40]!r} is none of {', '.join(DESIGNS)}")
    n, given = doc.get("n_ratings_total"), doc.get("input")
    if not isinstance(n, int) or isinstance(n, bool) or not isinstance(given, str) or not given:
        raise AnalysisError(f"{path}: not a report's stats.json (no n_ratings_total or input)")
    return path, doc, DESIGNS[name]


def _number(x) -> bool:
    return x is None or (isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x))


def standings_of(path, doc, design) -> Standings:
    """The design's standings of `doc`, each row checked; AnalysisError naming the file otherwise."""
    try:
        st = design.standings(doc)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        why = f"no {exc}" if isinstance(exc, KeyError) else str(exc)[:80]
        raise AnalysisError(f"{path}: not a {design.name} report's stats.json ({why})") from None
    for r in st.rows:
        if not isinstance(r["system"], str) or not study.CONDITION_NAME.fullmatch(r["system"]):
            raise AnalysisError(f"{path}: {str(r['system'])[:40]!r} is not a condition name")
        if not all(_number(r[k]) for k in ("score", "low", "high")) or not isinstance(r["n"], int):
            raise AnalysisError(f"{path}: {r['system']}: its score, interval or count is not a number")
    names = [r["system"] for r in st.rows]
    if not names or len(set(names)) != len(names):
        raise AnalysisError(f"{path}: {'no systems' if not names else 'a system named twice'}")
    return st


def find_export(spec: TaskSpec, doc: dict, stats: Path) -> Path:
    """The export the report was made from (see the module's docstring)."""
    if spec.export is not None:
        if not spec.export.is_file():
            raise AnalysisError(f"--export {spec.name}={spec.export}: no such file")
        return spec.export
    given = Path(doc["input"])
    here = spec.report.parent
    for path in (given, here / given, spec.report / given.name, here / given.name):
        if path.is_file():
            return path
    raise AnalysisError(
        f"{stats}: the export it was made from, {str(given)[:200]}, is not found; give --export {spec.name}=FILE"
    )


# An export's columns that name a clip shown and its condition, in every design (CONTRACTS §7, §8).
EXPORT_CLIPS = (("clip_id", "condition"), ("clip_a", "condition_a"), ("clip_b", "condition_b"))


def check_export(path: Path, doc: dict, stats: Path, task: str) -> dict[str, str]:
    """The export holds the rows the report counted (CONTRACTS §7 n_ratings_total), read as a user's CSV; returns
    {clip_id: condition} of the test clips its rows show."""
    shown, n = {}, 0
    with user_files.csv_rows(path, tables.MAX_BYTES, AnalysisError, "export") as (header, rows):
        pairs = [(clip, cond) for clip, cond in EXPORT_CLIPS if clip in header and cond in header]
        for _, row in rows:
            n += 1
            if row.get("role", "test") == "test":
                shown.update((row[clip], row[cond]) for clip, cond in pairs if row[clip])
    if n != doc["n_ratings_total"]:
        raise AnalysisError(
            f"{path}: {n} rows, but {stats} counts {doc['n_ratings_total']}: not the export this report was made "
            f"from (--export {task}=FILE)"
        )
    return shown


def check_stimuli(shown: dict, rows: list[dict], manifest: Path, export: Path, task: str) -> None:
    """Every test clip the export shows is in the manifest, of the same condition: a stimulus folder of another
    study (another task's, whose clip ids a seed can share) would publish its videos as this task's."""
    theirs = {r["clip_id"]: r["condition"] for r in rows}
    for clip, condition in shown.items():
        if theirs.get(clip) != condition:
            where = "not there" if clip not in theirs else f"of {theirs[clip]} there"
            raise AnalysisError(
                f"{manifest}: not the stimuli of {export}: its clip {clip} of {condition} is {where} "
                f"(--stimuli {task}=FOLDER, the study's stimulus folder)"
            )


def find_manifest(spec: TaskSpec, export: Path) -> Path:
    folder = spec.stimuli if spec.stimuli is not None else export.parent / STIMULI
    manifest = folder / clips.MANIFEST
    if not manifest.is_file():
        how = "" if spec.stimuli is not None else f" (the default, beside the export {export})"
        raise AnalysisError(
            f"{manifest}: no stimulus manifest{how}; give --stimuli {spec.name}=FOLDER, the study's stimulus folder"
        )
    return manifest


def read_task(spec: TaskSpec, n_videos: int) -> Task:
    """The task of `spec`, every file checked (see the module's docstring); AnalysisError, one line, otherwise."""
    stats, doc, design = read_stats(spec)
    standings = standings_of(stats, doc, design)
    export = find_export(spec, doc, stats)
    shown = check_export(export, doc, stats, spec.name)
    manifest = find_manifest(spec, export)
    rows = clips.read_manifest(manifest)
    systems = [r["system"] for r in standings.rows]
    conditions = clips.condition_of(systems, rows, manifest, stats)
    check_stimuli(shown, rows, manifest, export, spec.name)
    videos = clips.pick_clips(rows, conditions, n_videos)
    for clip in (c for picked in videos.values() for c in picked):
        if not clip.source.is_file():
            raise AnalysisError(f"{manifest}: the video of clip {clip.clip_id}, {clip.source}, is not a file")
    return Task(spec.name, spec.report, design, doc, standings, export, manifest, videos)
