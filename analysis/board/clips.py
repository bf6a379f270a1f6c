"""Which videos a board shows of each system: a few of its test clips, read from the study's stimulus manifest
(CONTRACTS §4) as a user's file, the same items for every system of a task where they have them.

The videos are the blinded files the raters saw (their names the clips' random ids), found through the manifest's
`video` column and refused where a path leads out of the stimulus folder."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from moglow_eval.core import study, user_files

from ..data.load import AnalysisError

MANIFEST = "manifest.csv"
MAX_MANIFEST_BYTES = 64 << 20  # as the app reads it: a row is about 200 bytes, so 300,000 clips
REQUIRED = ("clip_id", "condition", "role", "item", "video")


@dataclass(frozen=True)
class Clip:
    """One video a board copies: its clip id (the file's name there), its item, and the file in the stimuli."""

    clip_id: str
    item: str
    source: Path


def read_manifest(path) -> list[dict]:
    """The test clips of a manifest: {"clip_id", "condition", "item", "video" (resolved), "key" (the order in
    which an item's clips are picked: a matched clip first, then by style, sample and id)}; AnalysisError, one line
    naming the file and line, for a manifest that is not one."""
    path = Path(path)
    base = path.resolve().parent
    out, lines = [], {}
    with user_files.csv_rows(path, MAX_MANIFEST_BYTES, AnalysisError, "manifest") as (header, rows):
        missing = [c for c in REQUIRED if c not in header]
        if missing:
            raise AnalysisError(f"{path}:1: not a stimulus manifest: no column {', '.join(missing)}")
        for line, row in rows:
            if row["role"] != "test":
                continue
            if not study.CLIP_ID.fullmatch(row["clip_id"]):
                raise AnalysisError(f"{path}:{line}: clip_id {row['clip_id'][:40]!r} is not a clip id")
            if row["clip_id"] in lines:  # a clip id names one clip (CONTRACTS §2): which video would be whose?
                raise AnalysisError(f"{path}:{line}: clip_id {row['clip_id']} again (line {lines[row['clip_id']]})")
            lines[row["clip_id"]] = line
            video = (base / row["video"]).resolve()
            if not row["video"] or not video.is_relative_to(base):  # '..', an absolute path or a link leading out
                raise AnalysisError(f"{path}:{line}: video {row['video'][:80]!r} leaves the stimulus folder {base}")
            key = (bool(row.get("motion_item")), row.get("style", ""), row.get("sample", ""), row["clip_id"])
            out.append({**{k: row[k] for k in ("clip_id", "condition", "item")}, "video": video, "key": key})
    return out


def condition_of(systems, rows, manifest, where) -> dict[str, str]:
    """{system: the manifest's condition}: each system by its own name; the reference, which the manifest calls
    NAT and a report may name otherwise (--reference-name, a study's reference), is the one system left over when
    NAT is. AnalysisError naming the system the manifest has no clips of."""
    conditions = {r["condition"] for r in rows}
    out = {s: s for s in systems if s in conditions}
    left = [s for s in systems if s not in conditions]
    if len(left) == 1 and study.NATURAL in conditions and study.NATURAL not in systems:
        out[left[0]] = study.NATURAL
    elif left:
        raise AnalysisError(
            f"{manifest}: no test clips of {left[0]}, a system of {where}: not the stimulus folder of this study"
        )
    return out


def pick_clips(rows, conditions: dict[str, str], n: int) -> dict[str, list[Clip]]:
    """{system: up to `n` of its test clips}, one per item: the first items (in name order) that every system has,
    then its own next ones where it lacks some."""
    by = {s: {} for s in conditions}
    wanted = {c: s for s, c in conditions.items()}
    for r in sorted(rows, key=lambda r: r["key"]):
        system = wanted.get(r["condition"])
        if system is not None:
            by[system].setdefault(r["item"], r)
    common = sorted(set.intersection(*(set(items) for items in by.values()))) if by else []
    out = {}
    for system, items in by.items():
        order = common + sorted(set(items) - set(common))
        out[system] = [Clip(items[i]["clip_id"], i, items[i]["video"]) for i in order[:n]]
    return out
