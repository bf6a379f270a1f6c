"""What a rater's request brings, checked before anything is read: the JSON body, its fields, the session token.

Every check answers one line (400, 404, 415) naming the field; the API's endpoints and the designs' answer
parsers (designs/) share them.
"""

from __future__ import annotations

import math
import re

from flask import abort, request

from .limits import check_depth, escape_text

TOKEN = re.compile(r"[A-Za-z0-9_-]{16,64}")  # always fullmatch: '$' would let a trailing newline in
EXTERNAL = re.compile(r"[A-Za-z0-9_.:@-]{1,128}")


def json_body(allowed: tuple[str, ...], required: tuple[str, ...] = ()) -> dict:
    if not request.is_json:
        abort(415, "expected a JSON body (Content-Type: application/json)")
    check_depth(request.get_data(cache=True))
    body = request.get_json(silent=True)
    if not isinstance(body, dict):
        abort(400, "body must be a JSON object")
    unknown = sorted(set(body) - set(allowed))
    if unknown:
        abort(400, f"unknown field '{escape_text(unknown[0])[:64]}'")
    for k in required:
        if k not in body:
            abort(400, f"missing field '{k}'")
    return body


def int_field(body, name, lo, hi, nullable=False):
    """An integer in lo..hi (a float with an integer value counts); 400 otherwise."""
    v = body.get(name)
    if v is None and nullable:
        return None
    if (
        isinstance(v, bool)
        or not isinstance(v, (int, float))
        or (isinstance(v, float) and not (math.isfinite(v) and v.is_integer()))
    ):
        abort(400, f"field '{name}' must be an integer")
    v = int(v)
    if not lo <= v <= hi:
        abort(400, f"field '{name}' must be between {lo} and {hi}")
    return v


def ext_field(body, name):
    v = body.get(name)
    if v is None:
        return None
    if not isinstance(v, str) or not EXTERNAL.fullmatch(v):
        abort(400, f"field '{name}' must be 1-128 characters of letters, digits and _.:@-")
    return v


def check_token(token: str) -> None:
    """404 for a string that cannot be a session token, before it reaches the database."""
    if not TOKEN.fullmatch(token):
        abort(404, "unknown session")
