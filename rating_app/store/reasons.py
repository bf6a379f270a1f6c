"""The reasons a rater may give with a pairwise vote (CONTRACTS §8): tick boxes from a configured list and an
optional free text, checked here before anything is stored.

The list is the `VOTE_REASONS` setting: `ID=Label` entries joined by commas (`none`: no boxes; unset: the
design's own list, GENEA's four realism reasons for pairwise, moglow_eval.core.votes). The free text is the
`REASON_TEXT` setting: its most characters (0: no text box; unset: core.votes.FREE_TEXT_MAX for pairwise). A text
over the limit is refused with a 400, never cut, so what is stored is exactly what the rater typed.
"""

from __future__ import annotations

import re
import unicodedata

from flask import abort, current_app
from sqlalchemy import select

from moglow_eval.core import votes

from .manifest import AppError

REASON_ID = re.compile(rf"[A-Za-z][A-Za-z0-9_]{{0,{votes.REASON_ID_MAX - 1}}}")  # always fullmatch
MAX_REASONS = 12  # boxes on one page; their ids joined by ';' fit preferences.reasons
LABEL_MAX = 80
NONE = "none"


def parse_list(raw: str | None, default) -> tuple[tuple[str, str], ...]:
    """((id, label), ...) from the setting's text (None: `default`); AppError naming the entry that is not one."""
    if raw is None:
        return tuple(default)
    raw = raw.strip()
    if raw.lower() in (NONE, ""):
        return ()
    out, seen = [], set()
    for entry in raw.split(","):
        rid, _, label = (x.strip() for x in entry.partition("="))
        label = label or rid
        if not REASON_ID.fullmatch(rid):
            raise AppError(
                f"reasons: {rid!r} is not a reason id (a letter, then letters, digits or _; at most "
                f"{votes.REASON_ID_MAX} characters)"
            )
        if rid in seen:
            raise AppError(f"reasons: {rid} is listed twice")
        if len(label) > LABEL_MAX or not label.isprintable():
            raise AppError(f"reasons: the label of {rid} must be at most {LABEL_MAX} printable characters")
        seen.add(rid)
        out.append((rid, label))
    if len(out) > MAX_REASONS:
        raise AppError(f"reasons: at most {MAX_REASONS} boxes, got {len(out)}")
    return tuple(out)


def configure(design, reasons_raw: str | None, text_max: int | None, takers=()) -> dict:
    """app.config entries VOTE_REASONS and REASON_TEXT for `design`; AppError when a design without reasons is
    given some. `takers`: the names of the designs that take reasons, for that message (the registry knows them)."""
    reasons = parse_list(reasons_raw, design.default_reasons)
    text = design.default_reason_text if text_max is None else text_max
    if (reasons or text) and not design.takes_reasons:
        raise AppError(f"reasons: a {design.name} study asks for no reasons ({', '.join(takers)} do)")
    return {"VOTE_REASONS": reasons, "REASON_TEXT": text}


def _free_text(value, limit: int) -> str:
    """The free text as typed, or a 400: a string, at most `limit` characters, no control characters other
    than a line break or a tab (a NUL cannot be stored in PostgreSQL, and the others are never typed)."""
    if not isinstance(value, str):
        abort(400, "field 'reason_text' must be a string")
    if value and not limit:
        abort(400, "field 'reason_text': this study takes no free text")
    if len(value) > limit:
        abort(400, f"field 'reason_text' must be at most {limit} characters (got {len(value)})")
    if any(unicodedata.category(ch) in ("Cc", "Cs") and ch not in "\n\t" for ch in value):
        abort(400, "field 'reason_text' must not hold control characters")
    return value


def parse_answer(body: dict, training: bool) -> tuple[str, str]:
    """(the ticked reason ids joined by ';' in the configured order, the free text) of an answer's body; both
    optional; a familiarisation trial's must be empty. 400 for an unknown or repeated id, or a bad text."""
    ids, text = body.get("reasons"), body.get("reason_text")
    if ids is None:
        ids = []
    if not isinstance(ids, list) or not all(isinstance(x, str) for x in ids):
        abort(400, "field 'reasons' must be a list of reason ids")
    text = "" if text is None else _free_text(text, current_app.config["REASON_TEXT"])
    if training and (ids or text):
        abort(400, "a familiarisation trial takes no reasons")
    known = [rid for rid, _ in current_app.config["VOTE_REASONS"]]
    for x in ids:
        if x not in known:
            shown = x[:40] if REASON_ID.fullmatch(x[:40]) else "?"
            abort(400, f"field 'reasons': unknown reason {shown!r} (this study's: {', '.join(known) or 'none'})")
    if len(set(ids)) != len(ids):
        abort(400, "field 'reasons': a reason is given twice")
    return ";".join(rid for rid in known if rid in ids), text


def latest_texts(conn, n: int = 20) -> list[dict]:
    """The latest `n` free texts given with votes, newest first, for the dashboard (which escapes them)."""
    from .db import Preference, Rater

    rows = conn.execute(
        select(Rater.rater_id, Preference.submitted_at, Preference.reasons, Preference.reason_text)
        .join(Rater, Rater.id == Preference.rater_pk)
        .where(Preference.reason_text.is_not(None), Preference.reason_text != "")
        .order_by(Preference.submitted_at.desc(), Preference.id.desc())
        .limit(n)
    ).all()
    return [{"rater_id": r, "at": at, "reasons": (ids or "").replace(";", ", "), "text": t} for r, at, ids, t in rows]
