"""A new system's stimulus folder, as `add-condition` takes it: every file in it is hostile (CONTRACTS §8, *Rounds*).

- Its manifest and metrics.csv are read once, as a user's files (moglow_eval.core.user_files): every cell stripped
  once, and the stripped cells are what every later step checks, copies and writes.
- Every path column (PATH_COLUMNS: `video`, `motion`) of every row resolves inside the new manifest's folder
  (symlinks followed, so a link leading out is refused); a file the study takes is a regular file under its
  column's size cap, opened without following a last swap (moglow_eval.core.user_files.open_regular).
- The clips it takes get fresh random ids (moglow_eval.core.study.new_clip_id) and new file names, so that nothing
  a rater's client sees (the trial's clip ids, the URLs) is a name the submitter chose or knows; their videos are
  encoded again with fresh randomness by `python -m rendering.reencode` (run as a process: the app imports no
  other part), so that no served file is one of the submitted files byte for byte either.
"""

from __future__ import annotations

import os
import re
import shutil
import stat
import subprocess
import sys
from dataclasses import dataclass, replace
from pathlib import Path

from moglow_eval.core import clip, study, user_files

from ..store.manifest import AppError, ManifestClip, clip_from_row, read_rows

PATH_COLUMNS = ("video", "motion")  # the manifest's columns that name a file beside it (CONTRACTS §4)
MAX_BYTES = {"video": 256 << 20, "motion": clip.MAX_NPZ_BYTES}  # a stimulus video is a few MB
METRICS = "metrics.csv"
REENCODE_TIMEOUT_S = 900
_SUFFIX = re.compile(r"(\.[a-z0-9]{1,8}){1,2}")  # `.mp4`, `.npz`, `.bvh.gz`: what a new file's name keeps


@dataclass(frozen=True)
class Taken:
    """One clip the study takes: as the study will know it (a fresh id, its files in the study folder), the
    manifest row it gets, and the submitted files it comes from."""

    clip: ManifestClip
    old_id: str  # the id the submitter gave it: never shown, never stored
    row: dict
    sources: dict  # column -> the submitted file (checked)
    targets: dict  # column -> its path relative to the study folder


@dataclass
class Submission:
    path: Path
    header: list
    rows: dict  # clip id -> (line, stripped row)
    clips: list  # ManifestClip of every row, from the same stripped cells


def read(manifest) -> Submission:
    """The new manifest, read once and checked as the app checks one (every video present) and every path cell
    inside its folder; AppError, one line naming the file, line and column."""
    path = Path(manifest)
    base = path.resolve().parent
    rows, clips = {}, []
    with read_rows(path) as (header, lines):
        for line, row in lines:
            where = f"{path}:{line}"
            c = clip_from_row(row, where, base, check_files=True)
            if c.clip_id in rows:
                raise AppError(f"{where}: duplicate clip_id {c.clip_id}")
            for col in PATH_COLUMNS:
                if row.get(col):
                    inside(base, row[col], f"{where}: {col}")
            rows[c.clip_id] = (line, row)
            clips.append(c)
    if not clips:
        raise AppError(f"{path}: no clips")
    return Submission(path, header, rows, clips)


def inside(base: Path, cell: str, where: str) -> Path:
    """The file a path cell names, resolved (symlinks followed); AppError unless it lies inside `base`."""
    target = Path(os.path.realpath(base / cell))
    if not target.is_relative_to(base):
        raise AppError(f"{where} {cell!r} leaves the new manifest's folder {base}")
    return target


def source(base: Path, cell: str, col: str, where: str) -> Path:
    """A file the study takes: inside `base`, a regular file, at most MAX_BYTES[col]; AppError otherwise."""
    target = inside(base, cell, where)
    try:
        st = os.stat(target)
    except OSError as exc:
        raise AppError(f"{where} {cell!r}: cannot be read ({exc.strerror or exc})") from None
    if not stat.S_ISREG(st.st_mode):
        raise AppError(f"{where} {cell!r} is not a regular file")
    if st.st_size > MAX_BYTES[col]:
        raise AppError(
            f"{where} {cell!r} is {st.st_size >> 20} MB, more than a {col} file may be ({MAX_BYTES[col] >> 20} MB)"
        )
    return target


def take(sub: Submission, picked, study_header, study_rows, root: Path, taken_ids: set) -> list[Taken]:
    """The picked clips as the study takes them: a fresh id each, their files named by it in the folders where
    the study keeps each column's files, and their checked sources."""
    base = sub.path.resolve().parent
    out = []
    for c in picked:
        line, row = sub.rows[c.clip_id]
        new_id = study.new_clip_id(taken_ids)
        new_row = {**row, "clip_id": new_id}
        sources, targets = {}, {}
        for col in PATH_COLUMNS:
            if col not in study_header or not row.get(col):
                new_row[col] = ""  # a column the study does not keep: nothing of it is taken
                continue
            where = f"{sub.path}:{line}: {col}"
            sources[col] = source(base, row[col], col, where)
            suffix = "".join(Path(row[col].lower()).suffixes[-2:])
            if not _SUFFIX.fullmatch(suffix) or (col == "video" and suffix != ".mp4"):
                raise AppError(
                    f"{where} {row[col]!r}: a {col} file must end in {'.mp4' if col == 'video' else 'a suffix'}"
                )
            targets[col] = f"{_folder(study_rows, col)}{new_id}{suffix}"
            new_row[col] = targets[col]
        clip_as_study = replace(c, clip_id=new_id, video=root / targets["video"])
        out.append(Taken(clip_as_study, c.clip_id, new_row, sources, targets))
    return out


def _folder(study_rows, col: str) -> str:
    """Where the study keeps `col`'s files, relative to its manifest ("videos/"), from its first row that has one."""
    for _, row in study_rows:
        if row.get(col):
            parent = Path(row[col]).parent.as_posix()
            return "" if parent == "." else parent + "/"
    return f"{col}s/"


def metrics_rows(sub: Submission, taken: list[Taken], study_header) -> list[dict]:
    """The rows of the new folder's metrics.csv for the clips taken, under their new ids and the study's keys
    (condition, role, item as the study takes them), every metric a number or `nan`; AppError, one line."""
    path = sub.path.resolve().parent / METRICS
    by_old = {t.old_id: t for t in taken}
    out = []
    with read_rows(path) as (header, lines):
        if "clip_id" not in header:
            raise AppError(f"{path}:1: no clip_id column")
        for line, row in lines:
            t = by_old.get(row["clip_id"])
            if t is None:
                continue
            for col in study_header:
                if col not in study.METRIC_KEYS and row.get(col, "") not in ("", "nan") and not _number(row[col]):
                    raise AppError(f"{path}:{line}: {col} {row[col][:40]!r} is not a number")
            c = t.clip
            keys = {"clip_id": c.clip_id, "condition": c.condition, "role": c.role, "item": c.item}
            out.append({**{k: row.get(k) or "nan" for k in study_header}, **keys})
    return out


def _number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def copy_file(src: Path, dst: Path, col: str) -> None:
    """Copy a submitted file, opened as a regular file under its cap (a swap after the checks gains nothing)."""
    with user_files.open_regular(src, MAX_BYTES[col], AppError, f"{col} file") as fh, open(dst, "xb") as out:
        shutil.copyfileobj(fh, out, 1 << 20)


def reencode(src: Path, dst: Path, like: Path) -> None:
    """The submitted video `src` encoded again into `dst` by `python -m rendering.reencode`, as large, as fast and
    as long as the study's video `like`; AppError with its one line when it refuses or fails."""
    cmd = [sys.executable, "-m", "rendering.reencode", str(src), str(dst), "--like", str(like)]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=REENCODE_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise AppError(f"{src}: encoding it again took over {REENCODE_TIMEOUT_S} s") from None
    if out.returncode != 0:
        last = (out.stderr.strip().splitlines() or ["no message"])[-1]
        raise AppError(f"{src}: not taken: {last.removeprefix('error: ')}")
