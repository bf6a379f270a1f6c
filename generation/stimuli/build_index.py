"""Clips built once: a study's clip ids drawn from its secret seed, every video keyed by what decides
its bytes, and the index of finished clips that lets a rebuild reuse them and a killed build resume.

- `keyed_id`: a clip's id is an HMAC-SHA-256 of what the clip is (its condition, item, role, style, sample, the
  motion it shows) under the study's seed: two builds of one study with one seed give every clip the same id, a
  condition that joins leaves the others' ids as they were, and without the seed no id can be told from another.
- `job_key`: the SHA-256 of everything that decides a video's bytes: the motion file, the sound, the captions, the
  other person, the mesh's files, the render settings and the renderer's own source (its version).
- `BuildIndex`: `.build.csv` in the stimulus folder, a line `key,clip_id` appended (and flushed to disk) as each
  video is finished, after its files took their names. A build killed at any moment leaves every finished clip
  listed and no listed clip broken; the next build of the same folder renders only what is not listed.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import hmac
import os
from pathlib import Path

import numpy as np

from moglow_eval.core import study, whole_files

INDEX = ".build.csv"
KEY_LENGTH = 64  # hex digits of a SHA-256


def keyed_id(seed: int, identity: str, taken: set, forbidden=study.RESERVED) -> str:
    """A CLIP_ID_LENGTH-character id of the alphabet, drawn by an HMAC of `identity` under the study's seed; drawn
    again (a counter appended) while it is in `taken` or spells a name in `forbidden`. Joins `taken`."""
    forbidden = [f.lower() for f in forbidden]
    key = f"moglow-eval clip id\0{seed}".encode()
    for attempt in range(1000):
        digest = hmac.new(key, f"{identity}\0{attempt}".encode(), hashlib.sha256).digest()
        n = int.from_bytes(digest, "big")
        chars = []
        for _ in range(study.CLIP_ID_LENGTH):
            n, r = divmod(n, len(study.CLIP_ID_ALPHABET))
            chars.append(study.CLIP_ID_ALPHABET[r])
        cid = "".join(chars)
        if cid not in taken and not any(f in cid for f in forbidden):
            taken.add(cid)
            return cid
    raise RuntimeError(f"no free clip id for {identity!r}")  # 36**16 ids: never reached


@functools.lru_cache(maxsize=1)
def renderer_version() -> str:
    """The SHA-256 of the rendering package's source files: a change to how anything is drawn or encoded changes
    every key, so no video drawn by older code is reused."""
    import rendering

    h = hashlib.sha256()
    for path in sorted(Path(rendering.__file__).parent.glob("*.py")):
        h.update(path.name.encode() + b"\0" + path.read_bytes())
    return h.hexdigest()


@functools.lru_cache(maxsize=4096)
def _file_digest(path: str, size: int, mtime_ns: int) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _feed(h, value) -> None:
    """Feed `value` to the hash `h` in one canonical form: an absolute path to a file counts by its bytes."""
    if isinstance(value, np.ndarray):
        h.update(f"A{value.dtype.str}{value.shape}".encode())
        h.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, (str, Path)):
        s = str(value)
        if os.path.isabs(s) and os.path.isfile(s):
            st = os.stat(s)
            h.update(b"F" + _file_digest(s, st.st_size, st.st_mtime_ns).encode())
        else:
            h.update(b"S" + s.encode() + b"\0")
    elif value is None or isinstance(value, (bool, int, float, np.generic)):
        h.update(f"V{type(value).__name__}:{value!r}\0".encode())
    elif dataclasses.is_dataclass(value):
        h.update(f"D{type(value).__name__}".encode())
        for f in dataclasses.fields(value):
            h.update(f.name.encode() + b"=")
            _feed(h, getattr(value, f.name))
    elif isinstance(value, dict):
        h.update(b"{")
        for k in sorted(value, key=str):
            _feed(h, str(k))
            _feed(h, value[k])
        h.update(b"}")
    elif isinstance(value, (list, tuple)):
        h.update(b"[")
        for v in value:
            _feed(h, v)
        h.update(b"]")
    else:
        raise TypeError(f"a render job holds a {type(value).__name__}, which has no key")


def job_key(job) -> str:
    """The key of a render job (generation.stimuli.render_pool): its motion file's bytes, its size, preset and
    keywords (files among them by their bytes), and the renderer's version; not its output paths."""
    motion, _video, sheet, size, preset, *keywords = job
    h = hashlib.sha256(renderer_version().encode())
    _feed(h, [str(Path(motion).resolve()), bool(sheet), size, preset, keywords[0] if keywords else {}])
    return h.hexdigest()


class BuildIndex:
    """The finished clips of a stimulus folder: {key: clip_id}, read from `.build.csv` (a torn last line, from a
    build killed while writing it, is ignored) and appended to as clips finish."""

    def __init__(self, out):
        self.path = Path(out) / INDEX
        self.done: dict[str, str] = {}
        if self.path.is_file():
            for line in self.path.read_text(encoding="ascii", errors="replace").splitlines():
                key, _, cid = line.partition(",")
                if len(key) == KEY_LENGTH and study.CLIP_ID.fullmatch(cid):
                    self.done[key] = cid

    def add(self, key: str, cid: str) -> None:
        """Record a finished clip, on disk before this returns."""
        with open(self.path, "a", encoding="ascii") as f:
            f.write(f"{key},{cid}\n")
            f.flush()
            os.fsync(f.fileno())
        self.done[key] = cid

    def keep_only(self, live: dict[str, str]) -> None:
        """Rewrite the index as `live` {key: clip_id} (atomically: a new file renamed over the old)."""
        whole_files.write_whole(self.path, "".join(f"{k},{c}\n" for k, c in sorted(live.items())).encode("ascii"))
        self.done = dict(live)
