"""The stimulus videos, served so that nothing about the response tells one condition from another.

make_stimuli renders conditions one after the other, so file times follow the condition: a Last-Modified header
or an mtime-based ETag would let a rater sort clips by condition. Videos are therefore served with no date at
all and with an ETag that is a keyed hash of the bytes (HMAC with the app's secret key): a plain hash would let
whoever holds a video's bytes, a system's submitter among them, recognise it without downloading it. The bytes
are read once at start-up (up to a cap), so the response time does not depend on the file system's cache either.
Range requests (video seeking) still work.
"""

from __future__ import annotations

import hashlib
import hmac
import io
import os
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote

from flask import abort, current_app, request, send_file

from ..store.manifest import AppError
from ..store.settings import SETTINGS

ACCEL_PREFIX = "/_stimuli/"  # the proxy's internal location of the stimulus folder (deploy/, docs/hosting.md)


@dataclass
class Video:
    path: Path
    etag: str
    data: bytes | None


class VideoStore:
    """clip_id -> Video; each path is checked to lie inside the stimulus folder when it is read. `cache_bytes`: how
    many bytes of videos this worker keeps in memory (RATING_VIDEO_CACHE_MB); the others are read per request."""

    def __init__(self, clips, root: Path, preload: bool = True, key: bytes = b"", cache_bytes: int | None = None):
        self.root = Path(root).resolve()
        self.key = key
        self.cache_bytes = SETTINGS["VIDEO_CACHE_MB"].default * 2**20 if cache_bytes is None else cache_bytes
        self.paths = {c.clip_id: c.video for c in clips}
        self.videos: dict[str, Video] = {}
        self.cached = 0
        if preload:
            for cid in self.paths:
                self._load(cid)

    def _read(self, cid: str) -> bytes:
        path = Path(os.path.realpath(self.paths[cid]))
        if not path.is_relative_to(self.root):  # a symlink swapped after start-up: never served
            raise AppError(f"{self.paths[cid]}: leaves the stimulus folder {self.root}")
        return path.read_bytes()

    def _load(self, cid: str) -> Video:
        data = self._read(cid)
        keep = self.cached + len(data) <= self.cache_bytes
        self.cached += len(data) if keep else 0
        etag = hmac.new(self.key, data, hashlib.sha256).hexdigest()[:32]
        v = Video(self.paths[cid], etag, data if keep else None)
        self.videos[cid] = v
        return v

    def size(self, cid: str) -> int | None:
        """The video's byte size, or None when it cannot be read."""
        v = self.videos.get(cid)
        if v is not None and v.data is not None:
            return len(v.data)
        try:
            return os.stat(os.path.realpath(self.paths[cid])).st_size
        except (OSError, KeyError):
            return None

    def accel(self, cid: str):
        """(a response whose bytes the reverse proxy sends: an empty 200 with `X-Accel-Redirect` to the file under
        ACCEL_PREFIX, which nginx's internal location, or Caddy's handle_response, serves and never shows the
        client; the byte range that response will carry, from the request's Range header). No video is held in
        memory.

        The app records the range before the proxy sends it, and proxies read a Range header each its own way
        (Caddy sends one byte for `bytes=0-0,`, a multipart body for two ranges). So a Range header that is not
        exactly one satisfiable byte range is answered 416 here, with nothing redirected and nothing recorded."""
        try:
            path = Path(os.path.realpath(self.paths[cid]))
            if not path.is_relative_to(self.root):
                raise AppError(f"{self.paths[cid]}: leaves the stimulus folder {self.root}")
            size = path.stat().st_size
        except (OSError, AppError) as e:
            current_app.logger.error("video not served: %s", e)
            abort(404, "unknown video")
        resp = current_app.response_class(status=200, mimetype="video/mp4")
        resp.headers["X-Accel-Redirect"] = ACCEL_PREFIX + quote(path.relative_to(self.root).as_posix())
        resp.headers["Cache-Control"] = "private, max-age=3600"
        wanted = one_range(size)
        if wanted is None:
            resp = current_app.response_class(status=416)
            resp.headers["Content-Range"] = f"bytes */{size}"
            return resp, None
        return resp, (wanted if request.method == "GET" else None)

    def response(self, cid: str):
        """The video as a conditional response (Range, If-None-Match), without any date."""
        try:
            v = self.videos.get(cid) or self._load(cid)
            data = v.data if v.data is not None else self._read(cid)
        except (OSError, AppError) as e:
            current_app.logger.error("video not served: %s", e)
            abort(404, "unknown video")
        resp = send_file(
            io.BytesIO(data), mimetype="video/mp4", conditional=True, etag=v.etag, last_modified=None, max_age=None
        )
        resp.headers["Cache-Control"] = "private, max-age=3600"
        return resp


def one_range(size: int) -> tuple[int, int] | None:
    """[start, stop) of the bytes the request's Range header asks for: the whole file without one; None unless it
    is exactly one byte range that overlaps the file (Werkzeug's parse, which refuses trailing commas, signs,
    parameters and other units, and gives several ranges no single span)."""
    if "Range" not in request.headers:
        return (0, size)
    parsed = request.range
    span = parsed.range_for_length(size) if parsed is not None else None
    return span if span is not None and span[0] < span[1] else None
