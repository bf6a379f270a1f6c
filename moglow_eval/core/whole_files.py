"""Files written whole or not at all.

Every output a command makes or replaces in place (a report, a table, an export, a backup, a board page, a prepared
dataset) is written to a temporary file beside it and renamed over it once complete: a kill, a full disk or a refusal
half-way leaves the old file, or none, never part of a new one (the rename is atomic within a folder). The temporary
file is hidden (a leading dot, as the board's readers and a web server's listing pass such files by), its name is
drawn fresh (two writers never share one), and it is removed when the writing fails.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def writing(path, suffix: str = "") -> Iterator[Path]:
    """A temporary path beside `path` to write; renamed over `path` when the block ends, removed when it raises.

    `suffix` ends the temporary name, for a writer that would add its own (numpy's savez appends ".npz" to a name
    without it). A new file gets the permissions any new file gets (the umask), not a temporary file's owner-only ones.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.partial{suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)  # nothing there once renamed


def write_whole(path, data: str | bytes) -> None:
    """`data` (text as UTF-8, exactly as given: no newline translation) written to `path` whole or not at all."""
    blob = data.encode("utf-8") if isinstance(data, str) else data
    with writing(path) as tmp, open(tmp, "xb") as fh:
        fh.write(blob)
