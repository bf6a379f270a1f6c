"""The schema's life beyond its tables (db.py): the lock that serialises its creation between processes starting at
once, and the columns added since the first schema, given to a database made before them."""

from __future__ import annotations

import contextlib
import fcntl
from pathlib import Path

from sqlalchemy import inspect, text
from sqlalchemy.engine import Engine, make_url


@contextlib.contextmanager
def init_lock(engine: Engine):
    """Serialise schema creation between processes starting at once (gunicorn workers)."""
    if engine.dialect.name == "sqlite":
        db = make_url(str(engine.url)).database
        if not db or db == ":memory:":
            yield
            return
        with open(str(Path(db)) + ".init-lock", "w") as fh:
            fcntl.flock(fh, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(fh, fcntl.LOCK_UN)
    else:
        with engine.connect() as conn:
            conn.execute(text("SELECT pg_advisory_lock(715517)"))
            try:
                yield
            finally:
                conn.execute(text("SELECT pg_advisory_unlock(715517)"))
                conn.commit()


# Columns added since the first schema: (table, column, type); a database made before them gets them, NULL.
ADDED_COLUMNS = (
    ("trials", "unit", "VARCHAR(400)"),  # the designs: NULL, as for every acr trial
    ("trials", "video_ranges", "VARCHAR(400)"),  # bytes sent (CONTRACTS §5); NULL = none recorded
    ("trial_clips", "video_ranges", "VARCHAR(400)"),
    ("clips", "motion_item", "VARCHAR(128)"),  # appropriateness: NULL for every clip of an older study
    ("clips", "style", "VARCHAR(16)"),  # the manifest's style: NULL for every clip of an older study
    ("clips", "sample", "VARCHAR(64)"),  # a stochastic system's sample: NULL for every clip of an older study
    ("clips", "sample_of", "VARCHAR(64)"),
    ("trials", "sample_clip", "VARCHAR(64)"),  # the sample an acr trial shows: NULL where it is its clip
    ("raters", "audio_sample", "VARCHAR(64)"),  # the sound check
    ("raters", "audio_tries", "INTEGER"),
    ("raters", "audio_passed_at", "TIMESTAMP"),
    ("preferences", "round", "INTEGER"),  # votes stored before rounds: NULL, exported as round 1
    ("preferences", "reasons", "VARCHAR(500)"),
    ("preferences", "reason_text", "TEXT"),
)


def add_missing_columns(engine: Engine) -> None:
    """Add the ADDED_COLUMNS a database made before them lacks."""
    insp = inspect(engine)
    have = {t: {c["name"] for c in insp.get_columns(t)} for t in {t for t, _, _ in ADDED_COLUMNS}}
    for table, column, kind in ADDED_COLUMNS:
        if column not in have[table]:
            with engine.begin() as conn:
                conn.execute(text(f"ALTER TABLE {table} ADD COLUMN {column} {kind}"))
