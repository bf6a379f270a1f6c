"""Abuse limits shared by the rater API and the admin pages: who the client is, cross-site requests, JSON shape.

Limits are counted in the database, not in memory, so that they hold across gunicorn workers and restarts.
"""

from __future__ import annotations

import hashlib
import hmac
from urllib.parse import urlsplit

from flask import abort, current_app, request

# The API's bodies are flat objects; deep nesting only serves to exhaust the parser. The bound and the scan are
# every user JSON's (moglow_eval.core.user_files).
from moglow_eval.core.user_files import MAX_JSON_DEPTH, too_deep


def client_key() -> str:
    """A keyed hash of the client's address (after PROXY_COUNT trusted proxies): countable, not stored raw."""
    addr = (request.remote_addr or "?").encode()
    return hmac.new(current_app.config["SECRET_KEY"].encode(), addr, hashlib.sha256).hexdigest()[:32]


def same_site_only() -> None:
    """Refuse a request a browser sends on behalf of another site (a form or fetch from elsewhere).

    Browsers send Sec-Fetch-Site and, on POST, Origin; scripts and the simulated crowd send neither."""
    site = request.headers.get("Sec-Fetch-Site")
    if site is not None and site not in ("same-origin", "none"):
        abort(403, "cross-site request refused")
    origin = request.headers.get("Origin")
    if origin is not None:
        o, here = urlsplit(origin), urlsplit(request.host_url)
        if (o.scheme, o.netloc) != (here.scheme, here.netloc):
            abort(403, "cross-site request refused")


def check_depth(raw: bytes, limit: int = MAX_JSON_DEPTH) -> None:
    """400 for JSON nested deeper than `limit`, found by one scan of the bytes before any parser recurses."""
    if too_deep(raw, limit):
        abort(400, f"JSON nested deeper than {limit} levels")


def escape_text(text: str) -> str:
    """One line, printable: control characters (newlines included) become escapes, so a client cannot forge
    log lines or break a table."""
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)
