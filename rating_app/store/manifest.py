"""Reading the stimulus manifest (CONTRACTS §4); metrics.csv beside it is read by
core.tables.read_metrics."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from moglow_eval.core import colours, study, user_files
from moglow_eval.core.cli import UserError

REQUIRED = ("clip_id", "condition", "role", "item", "video")
MAX_BYTES = 64 << 20  # a manifest row is about 200 bytes: 300,000 clips
MAX_SIDE = 16384  # pixels: more than any video the renderer writes


class AppError(UserError):
    """A user-facing error: printed as one line by the CLI, never with a traceback."""


@dataclass(frozen=True)
class ManifestClip:
    clip_id: str
    condition: str
    role: str
    item: str
    video: Path  # absolute path of the MP4
    frames: int | None
    fps: float | None
    motion_item: str = ""  # appropriateness: the other item whose motion this clip shows (CONTRACTS §10)
    audio: bool = False  # the video carries sound (a study with [audio], CONTRACTS §10)
    style: str = ""  # how the body is drawn (a study with [render] style, CONTRACTS §4): exported, never served
    sample: str = ""  # a stochastic system's sample (CONTRACTS §4): exported, never served
    sample_of: str = ""  # the clip that stands for this clip's samples (pairing/samples.py); "" without samples
    width: int | None = None  # the video's pixels across and down (CONTRACTS §4), for the page to lay it out
    height: int | None = None

    @property
    def duration_ms(self) -> int | None:
        if self.frames and self.fps:
            return int(round(1000.0 * self.frames / self.fps))
        return None


def _number(value: str, kind, where: str, field: str):
    if value is None or value.strip() == "":
        return None
    try:
        x = kind(value)
    except ValueError:
        raise AppError(f"{where}: field '{field}' must be a number, got {value!r}") from None
    if isinstance(x, float) and not math.isfinite(x):
        raise AppError(f"{where}: field '{field}' must be finite, got {value!r}")
    return x


def read_rows(path):
    """``with read_rows(path) as (header, rows)``: a manifest (or metrics.csv beside one) read as a user's file
    (moglow_eval.core.user_files.csv_rows): rows of (line, {column: cell stripped once}), every reader of it then
    using the same stripped cells."""
    return user_files.csv_rows(path, MAX_BYTES, AppError, "manifest")


def load_manifest(path, check_files: bool = True) -> list[ManifestClip]:
    """The clips of manifest.csv; AppError naming the file and line for the first row that breaks CONTRACTS §4.
    `check_files`: also require every video to exist (the server does; the simulated crowd, elsewhere, does not)."""
    path = Path(path)
    if not path.exists():
        raise AppError(f"{path}: manifest not found")
    base = path.resolve().parent
    clips, seen = [], set()
    with read_rows(path) as (header, rows):
        missing = [c for c in REQUIRED if c not in header]
        if missing:
            raise AppError(f"{path}:1: missing column(s) {', '.join(missing)}")
        for line, row in rows:
            clip = clip_from_row(row, f"{path}:{line}", base, check_files)
            if clip.clip_id in seen:
                raise AppError(f"{path}:{line}: duplicate clip_id {clip.clip_id}")
            seen.add(clip.clip_id)
            clips.append(clip)
    if not clips:
        raise AppError(f"{path}: no clips")
    return clips


def clip_from_row(row: dict, where: str, base: Path, check_files: bool) -> ManifestClip:
    """One manifest row, checked; `where` is "file:line" for the error."""
    cid = (row["clip_id"] or "").strip()
    if not study.CLIP_ID.fullmatch(cid):
        raise AppError(f"{where}: clip_id {cid!r} is not an opaque token {study.CLIP_ID.pattern}")
    role = (row["role"] or "").strip()
    if role not in study.ROLES:
        raise AppError(f"{where}: role {role!r} must be one of {', '.join(study.ROLES)}")
    condition = (row["condition"] or "").strip()
    if not condition or len(condition) > 64 or not condition.isprintable():  # it reaches the report's console
        raise AppError(f"{where}: condition must be 1-64 printable characters, got {condition[:64]!r}")
    video = (base / (row["video"] or "").strip()).resolve()
    if not video.is_relative_to(base):  # '..', an absolute path or a symlink leading out
        raise AppError(f"{where}: video {row['video']!r} leaves the stimulus folder {base}")
    if check_files and not video.is_file():
        raise AppError(f"{where}: video {row['video']!r} not found ({video})")
    if check_files:  # else any file in the folder (a CSV, a key) is sent to raters as video
        try:
            mp4 = _is_mp4(video)
        except OSError as e:  # said as what it is: the server could not send it either
            raise AppError(f"{where}: video {row['video']!r} cannot be read ({e.strerror or e}): {video}") from None
        if not mp4:
            raise AppError(f"{where}: video {row['video']!r} is not an MP4 file ({video})")
    sample = (row.get("sample") or "").strip()
    if sample and not study.SAMPLE_NAME.fullmatch(sample):
        raise AppError(f"{where}: sample {sample!r} is not a sample name {study.SAMPLE_NAME.pattern}")
    return ManifestClip(
        clip_id=cid,
        condition=condition,
        role=role,
        item=(row["item"] or "").strip()[:128],
        video=video,
        frames=_positive(row.get("frames"), int, where, "frames"),
        fps=_positive(row.get("fps"), float, where, "fps"),
        motion_item=(row.get("motion_item") or "").strip()[:128],
        audio=(row.get("audio") or "").strip() == "1",
        style=(row.get("style") or "").strip()[:16],
        sample=sample,
        width=_side(row.get("width"), where, "width"),
        height=_side(row.get("height"), where, "height"),
    )


def _positive(value, kind, where, field):
    """A clip's frames or fps: above 0, or None where not given. The viewing rule takes a clip's length from them,
    and a negative one would shorten it (or a pair's), a zero one drop it."""
    x = _number(value, kind, where, field)
    if x is not None and not x > 0:
        raise AppError(f"{where}: field '{field}' must be above 0, got {value!r}")
    return x


def _side(value, where, field):
    """A video's width or height from the manifest: a positive whole number of pixels, or None where not given."""
    x = _number(value, int, where, field)
    if x is not None and not 0 < x <= MAX_SIDE:
        raise AppError(f"{where}: field '{field}' must be 1-{MAX_SIDE} pixels, got {value!r}")
    return x


# The types an MP4 (ISO base media, QuickTime) file's first box has: `ftyp` as ffmpeg writes it, the others as older
# muxers may put them first.
MP4_FIRST_BOXES = (b"ftyp", b"free", b"skip", b"wide", b"moov", b"mdat", b"pnot")


def _is_mp4(path: Path) -> bool:
    """Whether `path` starts as an MP4 file does: a first box of one of MP4_FIRST_BOXES' types (OSError where it cannot
    be read)."""
    with open(path, "rb") as fh:
        head = fh.read(12)
    return len(head) == 12 and head[4:8] in MP4_FIRST_BOXES


def video_size(clips) -> tuple[int, int] | None:
    """(width, height) of a set's videos, as the manifest gives them (every video of a set is one size, §4), for
    the rater's page to lay them out before they load (a two-person study's are wide); None where not given."""
    sizes = {(c.width, c.height) for c in clips if c.width and c.height}
    return sizes.pop() if len(sizes) == 1 else None


def _study_names(manifest) -> tuple[Path, dict | None]:
    """study.json beside the manifest (CONTRACTS §4) as its path and its object, None where there is no such file;
    AppError, one line, on a file that is not one."""
    path = Path(manifest).resolve().parent / study.STUDY_NAMES_FILE
    if not path.exists():
        return path, None
    text = user_files.read_text(path, 4096, AppError, "study names file")  # a few names: larger is not this file
    doc = user_files.json_value(text, f"{path}: not a study names file", AppError)
    if not isinstance(doc, dict) or study.REFERENCE_NAME not in doc:
        raise AppError(f"{path}: not a study names file (no {study.REFERENCE_NAME!r} key)")
    return path, doc


def reference_name(manifest) -> str | None:
    """The reference condition's own name from study.json beside the manifest (a study of your own motion,
    CONTRACTS §4), None where there is no such file or it names NAT; AppError, one line, on a malformed file."""
    path, doc = _study_names(manifest)
    if doc is None:
        return None
    name = doc[study.REFERENCE_NAME]
    if not isinstance(name, str) or not study.CONDITION_NAME.fullmatch(name):
        raise AppError(
            f"{path}: {study.REFERENCE_NAME} must be a condition name (a letter, then letters, digits, _ or -)"
        )
    return None if name == study.NATURAL else name


def interlocutor_colour(manifest) -> str | None:
    """The interlocutor's drawing colour, "#rrggbb", from study.json beside the manifest (a two-person study,
    CONTRACTS §4); None where the file or the key is absent (stimuli made by another tool): the rater's page then
    names no colour. AppError, one line, on a value that is not a colour."""
    path, doc = _study_names(manifest)
    value = None if doc is None else doc.get(study.INTERLOCUTOR_COLOUR)
    if value is None:
        return None
    try:
        return colours.to_hex(colours.from_hex(value))
    except ValueError as e:
        raise AppError(f"{path}: {study.INTERLOCUTOR_COLOUR} {e}") from None
