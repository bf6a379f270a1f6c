"""Reading the stimulus manifest (CONTRACTS §4) and the metrics.csv written beside it."""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass
from pathlib import Path

from core.cli import UserError

CLIP_ID = re.compile(r"[a-z0-9]{12,64}")  # always fullmatch
ROLES = ("test", "catch", "training")
REQUIRED = ("clip_id", "condition", "role", "item", "video")
METRIC_COLUMNS = ("foot_skating", "bone_length_std", "jerk", "control_error")


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

    @property
    def duration_ms(self) -> int | None:
        if self.frames and self.fps:
            return int(round(1000.0 * self.frames / self.fps))
        return None


def _number(value: str, kind, where: str, field: str, allow_nan=False):
    if value is None or value.strip() == "" or (allow_nan and value.strip().lower() in ("nan", "na")):
        return None
    try:
        x = kind(value)
    except ValueError:
        raise AppError(f"{where}: field '{field}' must be a number, got {value!r}") from None
    if isinstance(x, float) and not math.isfinite(x):
        raise AppError(f"{where}: field '{field}' must be finite, got {value!r}")
    return x


def load_manifest(path, check_files: bool = True) -> list[ManifestClip]:
    path = Path(path)
    if not path.is_file():
        raise AppError(f"{path}: manifest not found")
    base = path.resolve().parent
    clips, seen = [], set()
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            missing = [c for c in REQUIRED if c not in (reader.fieldnames or [])]
            if missing:
                raise AppError(f"{path}:1: missing column(s) {', '.join(missing)}")
            for line, row in enumerate(reader, start=2):
                where = f"{path}:{line}"
                cid = (row["clip_id"] or "").strip()
                if not CLIP_ID.fullmatch(cid):
                    raise AppError(f"{where}: clip_id {cid!r} is not an opaque token [a-z0-9]{{12,64}}")
                if cid in seen:
                    raise AppError(f"{where}: duplicate clip_id {cid}")
                seen.add(cid)
                role = (row["role"] or "").strip()
                if role not in ROLES:
                    raise AppError(f"{where}: role {role!r} must be one of {', '.join(ROLES)}")
                condition = (row["condition"] or "").strip()
                if not condition or len(condition) > 64:
                    raise AppError(f"{where}: condition must be 1-64 characters")
                video = (base / (row["video"] or "").strip()).resolve()
                if not video.is_relative_to(base):  # '..', an absolute path or a symlink leading out
                    raise AppError(f"{where}: video {row['video']!r} leaves the stimulus folder {base}")
                if check_files and not video.is_file():
                    raise AppError(f"{where}: video {row['video']!r} not found ({video})")
                clips.append(
                    ManifestClip(
                        clip_id=cid,
                        condition=condition,
                        role=role,
                        item=(row["item"] or "").strip()[:128],
                        video=video,
                        frames=_number(row.get("frames"), int, where, "frames"),
                        fps=_number(row.get("fps"), float, where, "fps"),
                    )
                )
    except UnicodeDecodeError as e:
        raise AppError(f"{path}: not UTF-8 ({e.reason})") from None
    except csv.Error as e:
        raise AppError(f"{path}: bad CSV ({e})") from None
    if not clips:
        raise AppError(f"{path}: no clips")
    return clips


def load_metrics(path) -> dict[str, dict]:
    """metrics.csv -> {clip_id: {condition, role, item, foot_skating, ...}} (metric values as floats)."""
    path = Path(path)
    out = {}
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        if "clip_id" not in (reader.fieldnames or []):
            raise AppError(f"{path}:1: missing column clip_id")
        for line, row in enumerate(reader, start=2):
            rec = {k: row.get(k, "") for k in ("condition", "role", "item")}
            for m in METRIC_COLUMNS:
                if m in row:
                    rec[m] = _number(row[m], float, f"{path}:{line}", m, allow_nan=True)  # nan: not measured
            out[row["clip_id"].strip()] = rec
    return out
