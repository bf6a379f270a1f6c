"""A condition joins a running pairwise study, or is withdrawn from it (CONTRACTS §8, *Rounds*):
`python -m rating_app add-condition` / `withdraw-condition` and the dashboard's forms.

The new condition's clips come from a stimulus folder built the same way as the study's (generation.make_stimuli
with `--system`, or a study of one's own): its manifest is checked as the app checks one at its start, then
against the study: no clip id of the study's, every test item of the study and no other, the same design (style,
sound, frames and fps per item), and videos of the byte size the study's videos of that item have (the one-size
rule of CONTRACTS §4, so that a file's size never tells the new condition apart). Its test clips are then copied
into the study's stimulus folder (where the app, and a proxy's internal location, serve videos from) with the
study's file time, appended to the study's manifest (and metrics.csv), and written to the database with the
Cover rows of their new pairs, in one transaction that begins the next round. A refusal is one line and leaves
the study folder and the database as they were; so does any failure on the way.
"""

from __future__ import annotations

import csv
import io
import os
import shutil
from dataclasses import replace
from pathlib import Path

from sqlalchemy import select
from sqlalchemy.orm import Session

from ..designs import get
from ..pairing.assign import lock_assign
from ..store import rounds
from ..store.db import Clip, Cover, clip_row, study_design, utcnow
from ..store.manifest import AppError, load_manifest


def _study(s, study_manifest):
    """(the design, the study's manifest path, {clip id: condition} of the database's clips)."""
    design = study_design(s)
    if design not in rounds.GROWS:
        raise AppError(
            f"add-condition: the database holds a {design} study; only a {' or '.join(rounds.GROWS)} study takes new "
            "conditions (its new pairs leave every stored one as it is)"
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


def _read_table(path: Path):
    """(the header, the rows as dicts, the file's bytes) of a CSV file."""
    data = path.read_bytes()
    reader = csv.DictReader(io.StringIO(data.decode("utf-8")))
    rows = list(reader)
    return list(reader.fieldnames or []), rows, data


def _append_rows(path: Path, header, rows, fill="") -> None:
    """Append `rows` (dicts) to the CSV `path` under its `header`, atomically (a new file renamed over it)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=header, extrasaction="ignore", restval=fill, lineterminator="\n")
    w.writerows(rows)
    old = path.read_bytes()
    tmp = path.with_name(path.name + ".adding")
    sep = b"" if old.endswith(b"\n") else b"\n"
    tmp.write_bytes(old + sep + buf.getvalue().encode("utf-8"))
    shutil.copymode(path, tmp)
    os.replace(tmp, path)


class _Files:
    """The study folder's changes, undone by `undo` when the database refuses them."""

    def __init__(self, root: Path):
        self.root, self.made, self.saved = root, [], {}

    def copy(self, src: Path, rel: str, mtime: float) -> Path:
        dst = (self.root / rel).resolve()
        if not dst.is_relative_to(self.root):
            raise AppError(f"{rel}: leaves the study folder {self.root}")
        if dst.exists():
            raise AppError(f"{dst}: already exists in the study folder; it is never replaced")
        dst.parent.mkdir(parents=True, exist_ok=True)
        self.made.append(dst)
        shutil.copyfile(src, dst)
        os.utime(dst, (mtime, mtime))  # the set's one file time (CONTRACTS §4)
        return dst

    def append(self, path: Path, header, rows, fill="") -> None:
        self.saved.setdefault(path, path.read_bytes())
        _append_rows(path, header, rows, fill)

    def undo(self) -> None:
        for path, data in self.saved.items():
            path.write_bytes(data)
        for p in self.made:
            p.unlink(missing_ok=True)


def _write_files(files: _Files, study_path: Path, new_path: Path, added) -> None:
    """Copy the added clips' videos (and motion files) into the study folder; append their manifest and metrics
    rows."""
    ids = {c.clip_id for c in added}
    header, study_rows, _ = _read_table(study_path)
    _, new_rows, _ = _read_table(new_path)
    rows = [r for r in new_rows if (r.get("clip_id") or "").strip() in ids]
    mtime = Path(study_path.parent / study_rows[0]["video"]).stat().st_mtime if study_rows else None
    for r in rows:
        for col in ("video", "motion"):
            src = (new_path.parent / (r.get(col) or "")).resolve()
            if col in header and r.get(col) and src.is_file():
                files.copy(src, r[col].strip(), mtime or src.stat().st_mtime)
    files.append(study_path, header, rows)
    study_metrics, new_metrics = study_path.parent / "metrics.csv", new_path.parent / "metrics.csv"
    if study_metrics.is_file() and new_metrics.is_file():
        m_header, _, _ = _read_table(study_metrics)
        _, m_rows, _ = _read_table(new_metrics)
        files.append(study_metrics, m_header, [r for r in m_rows if r.get("clip_id") in ids], fill="nan")


def add_condition(engine, new_manifest, conditions=(), study_manifest=None) -> dict:
    """Add the test clips of `conditions` (default: every condition of `new_manifest` the study lacks) to the
    running study in `engine`'s database; {"round", "conditions", "clips", "pairs"}. AppError, one line, and
    nothing changed, on a clash."""
    with Session(engine) as s:
        design, study_path, db_clips = _study(s, study_manifest)
    where = str(new_manifest)
    study_clips = load_manifest(study_path, check_files=True)
    new_clips = load_manifest(new_manifest, check_files=True)
    picked = _pick(study_clips, db_clips, new_clips, set(conditions), where)
    _check_design(study_clips, picked, where)
    _check_sizes(study_clips, picked, where)
    root = study_path.resolve().parent
    # As the study's manifest will name them: the same relative path, in the study folder.
    added = [replace(c, video=root / c.video.relative_to(Path(new_manifest).resolve().parent)) for c in picked]
    units = _new_units(design, study_clips, added)
    files = _Files(root)
    try:
        _write_files(files, study_path, Path(new_manifest), picked)
        new_round = _store(engine, added, units, sorted({c.condition for c in added}))
    except BaseException:
        files.undo()
        raise
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
        if design not in rounds.GROWS:
            raise AppError(f"withdraw-condition: the database holds a {design} study; only a pairwise one has rounds")
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
