"""A study that grows round by round (CONTRACTS §8, *Rounds*): which conditions it has, since which round, which
are withdrawn, and how every worker of a running app learns of a change.

The start is round 1. `add-condition` (operations/conditions.py) adds a condition's clips and begins the next round;
`withdraw-condition` stops serving the pairs of a condition. Each of them bumps the study's `revision` (a
StudySetting); a worker compares it with the one it loaded before it hands out a unit, starts a session or meets a
clip it does not know, and reloads the study's manifest (to which add-condition appended the new clips) when it
changed. Nothing already stored changes: a vote keeps the round it was stored in (`preferences.round`), and a
withdrawn condition's votes stay in the export.
"""

from __future__ import annotations

import threading

from flask import current_app
from sqlalchemy import select

from . import samples

# Its tables are db.py's, with the rest of the schema, so that the schema never depends on which modules were imported.
from .db import StudyCondition, StudyManifest, StudySetting, study_setting
from .manifest import AppError, load_manifest

ROUND = "round"  # StudySetting: the study's round now (absent: 1); designs/pairwise.py reads it with each vote
REVISION = "revision"  # StudySetting: bumped by every add and withdrawal, so that workers reload
_reload_lock = threading.Lock()


def current_round(conn) -> int:
    return int(study_setting(conn, ROUND) or 1)


def revision(conn) -> str:
    return study_setting(conn, REVISION) or "0"


def bump(session, new_round: int | None = None) -> None:
    """Begin round `new_round` (if given) and tell the workers to reload (in the caller's transaction)."""
    if new_round is not None:
        session.merge(StudySetting(name=ROUND, value=str(new_round)))
    session.merge(StudySetting(name=REVISION, value=str(int(revision(session.connection())) + 1)))


def withdrawn(conn) -> set[str]:
    return set(conn.execute(select(StudyCondition.name).where(StudyCondition.withdrawn_at.is_not(None))).scalars())


def record_start(session, manifest, clips, now) -> None:
    """At every start: where the manifest lies, and a row for each test condition that has none (the start's
    conditions, round 1; a condition that appeared in the manifest by other means, the round now)."""
    session.merge(StudyManifest(id=1, path=str(manifest)))
    have = set(session.scalars(select(StudyCondition.name)))
    rnd = current_round(session.connection())
    for name in sorted({c.condition for c in clips if c.role == "test"} - have):
        session.add(StudyCondition(name=name, round=rnd, added_at=now))


def active_units(units, clips, gone: set[str]) -> dict:
    """`units` less the test units showing a withdrawn condition (catch units stay: they test the rater)."""
    if not gone:
        return units
    return {k: u for k, u in units.items() if u.role != "test" or not any(clips[c].condition in gone for c in u.clips)}


def load(ext: dict, conn, manifest) -> None:
    """The study's clips, units and videos into a worker's state `ext`, from the manifest and the database's
    withdrawals, as of the database's revision."""
    rev = revision(conn)
    design = ext["design"]
    every, ext["samples"] = samples.group(design.serving_clips(load_manifest(manifest, check_files=True)))
    units = design.build_units(samples.standing(every))
    by_id = {c.clip_id: c for c in every}
    ext["videos"].paths.update({c.clip_id: c.video for c in every})  # the new videos, read when first asked for
    ext["clips"] = by_id
    ext["units"] = active_units(units, by_id, withdrawn(conn))
    ext["revision"] = rev


def refresh(conn, app=None, seen: str | None = None) -> dict:
    """The app's state (`extensions["rating_app"]`), reloaded first when the study changed since it was loaded.
    `seen`: the revision as a statement of the caller's already read it (None: read it here); a design that
    cannot grow never reads it."""
    app = app or current_app
    ext = app.extensions["rating_app"]
    if not ext["design"].grows:  # its units never change after the start (designs/base.py)
        return ext
    if (seen or revision(conn)) != ext.get("revision"):
        with _reload_lock:
            if revision(conn) != ext.get("revision"):
                try:
                    load(ext, conn, ext["manifest"])
                except AppError as e:  # keep serving what was loaded; the next request tries again
                    app.logger.error("the study changed but cannot be reloaded: %s", e)
    return ext


def current_units(conn, seen: str | None = None) -> dict:
    """The units this worker serves now; `seen` as for `refresh` (GET next reads it with the current trial)."""
    return refresh(conn, seen=seen)["units"]


def know_clips(conn, clip_ids) -> dict:
    """The app's clips, refreshed when one of `clip_ids` is unknown to this worker (another one served it since a
    change)."""
    ext = current_app.extensions["rating_app"]
    if any(c and c not in ext["clips"] for c in clip_ids):
        ext = refresh(conn)
    return ext["clips"]
