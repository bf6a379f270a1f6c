"""A condition joins a running pairwise study, or is withdrawn from it (CONTRACTS §8, *Rounds*):
`python -m rating_app add-condition` / `withdraw-condition` and the dashboard's forms.

The new condition's clips come from a stimulus folder built the same way as the study's (generation.make_stimuli
with `--system`, or a study of one's own): its manifest is checked as the app checks one at its start, then
against the study: no clip id of the study's, every test item of the study and no other, the same design (style,
sound, frames and fps per item), and videos of the byte size the study's videos of that item have (the one-size
rule of CONTRACTS §4, so that a file's size never tells the new condition apart). Every file of that folder is
read as hostile (submission.py: paths inside it, regular files under a size cap, cells stripped once). Its test
clips get fresh random ids, their videos are encoded again with fresh randomness and checked against the one-size
rule again, and their files land in the study's stimulus folder (where the app, and a proxy's internal location,
serve videos from) with the study's file time; their rows are appended to the study's manifest (and metrics.csv)
and written to the database with the Cover rows of their new pairs, in one transaction that begins the next
round. All or nothing: a refusal is one line and leaves the study folder (files and folders) and the database as
they were; so does any failure on the way.
"""

from __future__ import annotations

import contextlib
import csv
import io
import os
import shutil
import tempfile
from dataclasses import replace
from pathlib import Path

from sqlalchemy import select
from sqlalchemy.orm import Session

from .. import designs
from ..designs import get
from ..pairing.assign import lock_assign
from ..store import rounds
from ..store.db import Clip, Cover, clip_row, study_design, utcnow
from ..store.manifest import AppError, load_manifest, read_rows
from . import submission


def _growing() -> str:
    """The designs that grow round by round (designs/base.py `grows`), for a message."""
    return " or ".join(d.name for d in designs.DESIGNS.values() if d.grows)


def _study(s, study_manifest):
    """(the design, the study's manifest path, {clip id: condition} of the database's clips)."""
    design = study_design(s)
    if not designs.get(design).grows:
        raise AppError(
            f"add-condition: the database holds a {design} study; only a {_growing()} study takes new conditions (its "
            "new pairs leave every stored one as it is)"
        )
    path = study_manifest
    if path is None:
        row = s.get(rounds.StudyManifest, 1)
        if row is None:
            raise AppError("add-condition: the database names no study manifest; start the app once, or pass it")
        path = row.path
    return get(design), Path(path), dict(s.execute(select(Clip.clip_id, Clip.condition)).all())


def _pick(study_clips, db_clips, new_clips, wanted, where) -> list:
    """The new manifest's test clips of the conditions joining; AppError, one line, on any clash."""
    have = {c.condition for c in study_clips if c.role == "test"} | set(db_clips.values())
    offered = sorted({c.condition for c in new_clips if c.role == "test"})
    names = sorted(wanted) if wanted else [c for c in offered if c not in have]
    for n in names:
        if n in have:
            raise AppError(f"{where}: condition {n} is already in the study")
        if n not in offered:
            raise AppError(f"{where}: no test clip of condition {n} (it has {', '.join(offered) or 'none'})")
    if not names:
        raise AppError(f"{where}: every condition it has ({', '.join(offered)}) is already in the study")
    taken = {c.clip_id for c in study_clips} | set(db_clips)
    items = sorted({c.item for c in study_clips if c.role == "test"})
    out = []
    for n in names:
        mine = [c for c in new_clips if c.condition == n and c.role == "test"]
        clash = next((c.clip_id for c in mine if c.clip_id in taken), None)
        if clash:
            raise AppError(f"{where}: clip id {clash} is already in the study")
        got = sorted(c.item for c in mine)
        missing = sorted(set(items) - set(got))
        extra = sorted(set(got) - set(items))
        if missing:
            raise AppError(f"{where}: condition {n} has no test clip of item {missing[0]} (the study has it)")
        if extra:
            raise AppError(f"{where}: item {extra[0]} of condition {n} is not a test item of the study")
        out += mine
    return out


def _check_design(study_clips, added, where) -> None:
    """The same kind of clip as the study's: style, sound, mismatched motion, frames and fps of each item."""
    test = [c for c in study_clips if c.role == "test" and not c.motion_item]
    by_item = {}
    for c in test:
        by_item.setdefault(c.item, []).append(c)
    styles, sound = {c.style for c in test}, any(c.audio for c in study_clips)
    for c in added:
        ref = by_item[c.item][0]
        if c.motion_item:
            raise AppError(f"{where}: clip {c.clip_id} shows another item's motion; a pairwise study has none")
        if c.style not in styles or c.audio != sound:
            what = "style" if c.style not in styles else "sound"
            raise AppError(f"{where}: clip {c.clip_id}'s {what} differs from the study's (a mismatched design)")
        if (c.frames, c.fps) != (ref.frames, ref.fps):
            raise AppError(
                f"{where}: clip {c.clip_id} has {c.frames} frames at {c.fps} fps; the study's clips of item {c.item} "
                f"have {ref.frames} at {ref.fps} (a mismatched design)"
            )


def _check_sizes(study_clips, added, where) -> None:
    """Every video of an item one byte size (CONTRACTS §4), the new ones included."""
    sizes = {}
    for c in study_clips:
        if c.role == "test" and not c.motion_item:
            sizes.setdefault(c.item, set()).add(c.video.stat().st_size)
    for c in added:
        have, size = sizes[c.item], c.video.stat().st_size
        if len(have) != 1:
            raise AppError(
                f"the study's videos of item {c.item} are not one size ({len(have)} sizes): re-render the study "
                "before adding to it (CONTRACTS §4)"
            )
        if size not in have:
            raise AppError(
                f"{where}: video of clip {c.clip_id} is {size} bytes, the study's videos of item {c.item} are "
                f"{next(iter(have))}; every video must be one size (CONTRACTS §4: re-render it with rendering.encode)"
            )


def _new_units(design, study_clips, added) -> dict:
    """{key: Unit} of the pairs the added clips make; AppError if a unit the study serves would change."""
    before = design.build_units(design.serving_clips(study_clips))
    after = design.build_units(design.serving_clips([*study_clips, *added]))
    changed = next((k for k, u in before.items() if after.get(k) != u), None)
    if changed:
        raise AppError(f"add-condition: the study's unit {changed} would change; a stored vote must keep its meaning")
    return {k: u for k, u in after.items() if k not in before}


class _Files:
    """The study folder's side of an add, all or nothing: every new file is made in a staging folder first, then
    moved into place with the folders it needs; the manifest and metrics.csv are replaced whole. `undo` puts back
    every file, removes every folder made, and the staging folder."""

    def __init__(self, root: Path, mtime: float):
        self.root, self.mtime = root, mtime
        self.staging = Path(tempfile.mkdtemp(prefix=".adding-", dir=root))
        self.placed, self.folders, self.saved = [], [], {}

    def staged(self, rel: str) -> Path:
        return self.staging / rel.replace("/", "__")

    def place(self, rel: str) -> None:
        dst = (self.root / rel).resolve()
        if not dst.is_relative_to(self.root):
            raise AppError(f"{rel}: leaves the study folder {self.root}")
        if dst.exists():
            raise AppError(f"{dst}: already exists in the study folder; it is never replaced")
        missing = [p for p in reversed(dst.parents) if p.is_relative_to(self.root) and not p.exists()]
        for folder in missing:
            folder.mkdir()
            self.folders.append(folder)
        os.replace(self.staged(rel), dst)
        self.placed.append(dst)
        os.utime(dst, (self.mtime, self.mtime))  # the set's one file time (CONTRACTS §4)

    def rewrite(self, path: Path, header, rows, fill="") -> None:
        """`path` (a CSV) with `rows` appended under its `header`: a new file renamed over it."""
        old = self.saved.setdefault(path, path.read_bytes())
        buf = io.StringIO()
        csv.DictWriter(buf, fieldnames=header, extrasaction="ignore", restval=fill, lineterminator="\n").writerows(rows)
        tmp = self.staging / (path.name + ".new")
        tmp.write_bytes(old + (b"" if old.endswith(b"\n") else b"\n") + buf.getvalue().encode("utf-8"))
        shutil.copymode(path, tmp)
        os.replace(tmp, path)

    def done(self) -> None:
        shutil.rmtree(self.staging, ignore_errors=True)

    def undo(self) -> None:
        for path, data in self.saved.items():
            path.write_bytes(data)
        for p in self.placed:
            p.unlink(missing_ok=True)
        for folder in reversed(self.folders):
            with contextlib.suppress(OSError):
                folder.rmdir()
        self.done()


def _stage(files: _Files, taken, study_clips) -> None:
    """Every taken clip's files, made in the staging folder: its video encoded again like the study's videos of
    its item (submission.reencode), its other files copied; then the one-size rule checked on what was made."""
    like = {c.item: c.video for c in study_clips if c.role == "test" and not c.motion_item}
    for t in taken:
        for col, rel in t.targets.items():
            if col == "video":
                submission.reencode(t.sources[col], files.staged(rel), like[t.clip.item])
            else:
                submission.copy_file(t.sources[col], files.staged(rel), col)
    _check_sizes(study_clips, [replace(t.clip, video=files.staged(t.targets["video"])) for t in taken], "encoded again")


def _metrics(study_path: Path, sub, taken):
    """(the study's metrics.csv, its header, the rows the taken clips add) when both folders have one, else None;
    read before any file is made, so that a bad metrics.csv refuses the add at once."""
    study_metrics = study_path.parent / submission.METRICS
    if not (study_metrics.is_file() and (sub.path.resolve().parent / submission.METRICS).is_file()):
        return None
    with read_rows(study_metrics) as (header, _):
        pass
    return study_metrics, header, submission.metrics_rows(sub, taken, header)


def _write(files: _Files, study_path: Path, header, taken, metrics) -> None:
    """The staged files moved into the study folder, and the taken clips' rows appended to its manifest and its
    metrics.csv (`metrics`, from _metrics)."""
    for t in taken:
        for rel in t.targets.values():
            files.place(rel)
    files.rewrite(study_path, header, [t.row for t in taken])
    if metrics is not None:
        files.rewrite(*metrics, fill="nan")


def add_condition(engine, new_manifest, conditions=(), study_manifest=None) -> dict:
    """Add the test clips of `conditions` (default: every condition of `new_manifest` the study lacks) to the
    running study in `engine`'s database; {"round", "conditions", "clips", "pairs"}. AppError, one line, and
    nothing changed (no file, no folder, no row), on a clash or a file it will not take."""
    with Session(engine) as s:
        design, study_path, db_clips = _study(s, study_manifest)
    where = str(new_manifest)
    study_clips = load_manifest(study_path, check_files=True)
    sub = submission.read(new_manifest)
    picked = _pick(study_clips, db_clips, sub.clips, set(conditions), where)
    _check_design(study_clips, picked, where)
    _check_sizes(study_clips, picked, where)
    root = study_path.resolve().parent
    with read_rows(study_path) as (header, rows):
        study_rows = list(rows)
    taken_ids = {c.clip_id for c in study_clips} | set(db_clips) | {c.clip_id for c in sub.clips}
    taken = submission.take(sub, picked, header, study_rows, root, taken_ids)
    added = [t.clip for t in taken]
    units = _new_units(design, study_clips, added)
    metrics = _metrics(study_path, sub, taken)
    files = _Files(root, study_clips[0].video.stat().st_mtime)
    try:
        _stage(files, taken, study_clips)
        _write(files, study_path, header, taken, metrics)
        new_round = _store(engine, added, units, sorted({c.condition for c in added}))
    except BaseException:
        files.undo()
        raise
    files.done()
    return {
        "round": new_round,
        "conditions": sorted({c.condition for c in added}),
        "clips": len(added),
        "pairs": len(units),
    }


def _store(engine, added, units, names) -> int:
    """The database's half, in one transaction under the assignment lock; the new round."""
    now = utcnow()
    with Session(engine) as s, s.begin():
        lock_assign(s.connection())
        if s.scalars(select(Clip.clip_id).where(Clip.clip_id.in_([c.clip_id for c in added]))).first():
            raise AppError("add-condition: a clip of it is already in the database (added meanwhile?)")
        if s.scalars(select(rounds.StudyCondition.name).where(rounds.StudyCondition.name.in_(names))).first():
            raise AppError(f"add-condition: {', '.join(names)} joined the study meanwhile")
        new_round = rounds.current_round(s.connection()) + 1
        s.add_all(clip_row(c) for c in added)
        s.add_all(Cover(key=k, answered=0, held=0) for k in units)
        s.add_all(rounds.StudyCondition(name=n, round=new_round, added_at=now) for n in names)
        rounds.bump(s, new_round)
    return new_round


def withdraw_condition(engine, name: str) -> dict:
    """Stop serving the pairs of condition `name` (its votes stay); {"condition", "round", "served"}."""
    with Session(engine) as s, s.begin():
        design = study_design(s)
        if not designs.get(design).grows:
            raise AppError(
                f"withdraw-condition: the database holds a {design} study; only a {_growing()} one has rounds"
            )
        lock_assign(s.connection())
        rows = {r.name: r for r in s.scalars(select(rounds.StudyCondition))}
        row = rows.get(name)
        if row is None:
            raise AppError(f"withdraw-condition: no condition {name!r} in the study (it has {', '.join(sorted(rows))})")
        if row.withdrawn_at is not None:
            raise AppError(f"withdraw-condition: {name} was withdrawn already")
        served = sorted(n for n, r in rows.items() if r.withdrawn_at is None and n != name)
        if len(served) < 2:
            raise AppError(f"withdraw-condition: {name} is one of the last two conditions; pairs need two")
        row.withdrawn_at = utcnow()
        rounds.bump(s)
        return {"condition": name, "round": row.round, "served": served}


def conditions_table(conn) -> list[dict]:
    """The study's conditions for the dashboard: name, round, added, withdrawn."""
    t = rounds.StudyCondition
    rows = conn.execute(select(t.name, t.round, t.added_at, t.withdrawn_at).order_by(t.round, t.name)).all()
    return [{"name": n, "round": r, "added_at": a, "withdrawn_at": w} for n, r, a, w in rows]
