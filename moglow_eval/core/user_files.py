"""Files a command reads from a user, read as hostile: every reader of a user's CSV or JSON goes through here.

- Only a regular file is read: a FIFO, a device (`/dev/zero`), a folder or a socket is refused before a byte is
  read (it is opened without blocking, and checked on the open descriptor, so a swap after a check gains nothing).
- A size cap, checked before reading and enforced while reading (a file that grows is cut off with an error).
- Lines are read one at a time with a cap on each, and decoded on their own (a UTF-8 sequence never holds a
  newline byte): memory stays flat whatever the file's size, and a bad line stops the reading there.
- JSON is parsed only when its nesting is shallow (`json_value`, `read_json`; `too_deep` is the one scan, which
  the app's request bodies go through too): deep brackets would reach Python's recursion limit, and a cell of them
  is refused with one line; so is TOML that nests too deep (`read_toml`).
- A text cell written back out to a CSV that a spreadsheet may open is defused (`defuse`): the app's exports and
  the importers write the same way.

Every problem is one `UserError` (or the caller's subclass) naming the file and the line.
"""

from __future__ import annotations

import contextlib
import csv
import json
import os
import re
import stat
import tomllib
import unicodedata
from collections.abc import Iterator
from pathlib import Path

from .cli import UserError

READ_CHUNK = 16 << 20  # bytes a whole-file read asks for at a time
MAX_LINE = 1 << 20  # bytes in one line of a user's CSV: a vote or a clip is a few hundred
MAX_CELL = 64 * 1024  # characters in one cell, below csv's own limit (128 KB), so this message comes first
MAX_JSON_DEPTH = 8  # a list of reason ids is depth 1; nothing a user gives us nests deeper than a few levels
# A spreadsheet evaluates a cell that starts with one of these; such a cell is written with a leading apostrophe.
FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def defuse(value):
    """A CSV cell that no spreadsheet evaluates: text starting with FORMULA_START gets a leading apostrophe."""
    if isinstance(value, str) and value.startswith(FORMULA_START):
        return "'" + value
    return value


# A terminal's escape sequence (ESC [ ... letter, or ESC and one character): cut whole, not left as "[31m".
_ESCAPE = re.compile(r"\x1b(\[[0-?]*[ -/]*[@-~]|[@-_])")


def shown_text(value: str) -> str:
    """A user's text as it may be drawn or shown (a caption's word, a keyword): escape sequences cut, every control,
    format, surrogate, private or unassigned character removed (a NUL stops the text layout with a traceback, a
    bidirectional override reorders what is drawn), and runs of white space one space."""
    value = _ESCAPE.sub("", value)
    kept = "".join(" " if ch.isspace() else ch for ch in value if ch.isspace() or unicodedata.category(ch)[0] != "C")
    return " ".join(kept.split())


@contextlib.contextmanager
def open_regular(path, max_bytes: int, error=UserError, what: str = "file"):
    """A binary file object of `path`, a regular file of at most `max_bytes`; `error` (one line) otherwise."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise error(f"{path}: no such {what}") from None
    except OSError as exc:
        raise error(f"{path}: cannot be read ({exc.strerror or exc})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise error(f"{path}: not a regular {what} (a device, a pipe or a folder is never read)")
        if st.st_size > max_bytes:
            raise error(f"{path}: {_size(st.st_size)} is larger than a {what} can be ({_size(max_bytes)})")
        os.set_blocking(fd, True)
        fh = os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
    with fh:
        yield fh


def _size(n: int) -> str:
    if n >= 2**20:
        return f"{n / 2**20:.1f} MB"
    return f"{n >> 10} KB" if n >= 1024 and not n % 1024 else f"{n} bytes"


def lines(fh, path, max_bytes: int, error=UserError, max_line: int = MAX_LINE) -> Iterator[str]:
    """The decoded lines of binary file object `fh` (a BOM at the start dropped), one at a time; `error` names
    the line that is too long or not UTF-8, or the byte where the file passed `max_bytes`."""
    read, number = 0, 0
    while True:
        raw = fh.readline(max_line + 1)
        if not raw:
            return
        number += 1
        read += len(raw)
        if read > max_bytes:
            raise error(f"{path}:{number}: the file grew past {_size(max_bytes)} while it was read")
        if len(raw) > max_line and not raw.endswith(b"\n"):
            raise error(f"{path}:{number}: line longer than {_size(max_line)}")
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise error(f"{path}:{number}: not UTF-8 text ({exc.reason} at byte {exc.start} of the line)") from None
        yield text.removeprefix("\ufeff") if number == 1 else text


@contextlib.contextmanager
def csv_rows(path, max_bytes: int, error=UserError, what: str = "CSV file", max_cell: int = MAX_CELL):
    """``with csv_rows(...) as (header, rows)``: a user's CSV file read in a stream, `rows` an iterator of
    (line, {column: cell stripped of blanks}), blank lines skipped, short rows filled with "". `error`, one line
    naming the file and line, for a file that is not a regular file, too large, not UTF-8, not CSV, or has a cell
    over `max_cell` characters or more cells than its header."""
    path = Path(path)
    with open_regular(path, max_bytes, error, what) as fh:
        reader = csv.reader(lines(fh, path, max_bytes, error))

        def next_row():
            try:
                row = next(reader, None)
            except csv.Error as exc:
                raise error(f"{path}:{reader.line_num}: not CSV ({exc})") from None
            long = next((c for c in row or () if len(c) > max_cell), None)
            if long is not None:
                raise error(f"{path}:{reader.line_num}: a cell of {len(long)} characters (at most {max_cell})")
            return row

        head = next_row()
        if head is None:
            raise error(f"{path}: empty (expected a CSV header and rows)")
        header = [h.strip() for h in head]

        def rows():
            while (row := next_row()) is not None:
                if not any(c.strip() for c in row):
                    continue  # a blank line is layout
                if len(row) > len(header):
                    raise error(f"{path}:{reader.line_num}: {len(row)} cells, the header has {len(header)}")
                cells = [c.strip() for c in row] + [""] * (len(header) - len(row))
                yield reader.line_num, dict(zip(header, cells))

        yield header, rows()


def too_deep(text: str | bytes, max_depth: int = MAX_JSON_DEPTH) -> bool:
    """Whether JSON `text` nests its brackets deeper than `max_depth`, found by one scan before any parser recurses
    (brackets inside strings do not count). Bytes are scanned as Latin-1: every byte one character, and UTF-8 never
    puts a quote, a backslash or a bracket inside a longer sequence, so the bytes nest as their text does."""
    if isinstance(text, bytes):
        text = text.decode("latin-1")
    depth, in_string, escaped = 0, False, False
    for ch in text:
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            if depth > max_depth:
                return True
        elif ch in "]}":
            depth -= 1
    return False


def json_value(text: str, where: str, error=UserError, max_depth: int = MAX_JSON_DEPTH, file: bool = False):
    """`text` parsed as JSON when its brackets nest at most `max_depth` deep; `error` naming `where` (and, for a
    whole `file`, the line) for text that is not JSON or nests deeper (checked on the text before parsing, so
    no recursion)."""
    if too_deep(text, max_depth):
        raise error(f"{where}: JSON nested deeper than {max_depth} levels")
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        message = f"{where}:{exc.lineno}: invalid JSON ({exc.msg})" if file else f"{where}: not JSON ({exc})"
        raise error(message) from None


def read_at_most(fh, n: int, into: bytearray | None = None) -> bytearray:
    """`into` (a new bytearray where None) with up to `n` more bytes of `fh` appended, to its end: read in chunks, as
    one read of `n` asks the allocator for all `n` at once (a cap of hundreds of MB for a file of a few KB)."""
    out = bytearray() if into is None else into
    stop = len(out) + n
    while len(out) < stop:
        chunk = fh.read(min(READ_CHUNK, stop - len(out)))
        if not chunk:
            break
        out += chunk
    return out


def read_text(path, max_bytes: int, error=UserError, what: str = "file") -> str:
    """The whole of a small user's file as UTF-8 text (open_regular's checks); `error`, one line, otherwise."""
    with open_regular(path, max_bytes, error, what) as fh:
        data = read_at_most(fh, max_bytes + 1)
    if len(data) > max_bytes:
        raise error(f"{path}: grew past {_size(max_bytes)} while it was read")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None


def read_json(path, max_bytes: int, error=UserError, what: str = "JSON file", max_depth: int = MAX_JSON_DEPTH):
    """A user's JSON file (read_text, then json_value); `error`, one line naming the file, otherwise."""
    return json_value(read_text(path, max_bytes, error, what), str(path), error, max_depth, file=True)


def read_toml(path, max_bytes: int, error=UserError, what: str = "TOML file") -> dict:
    """A user's TOML file (read_text); `error`, one line naming the file, for TOML that is invalid or nests so
    deep that the parser's recursion gives up (its length is capped, so that depth is bounded too)."""
    text = read_text(path, max_bytes, error, what)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not a TOML file: {exc}") from None
    except RecursionError:
        raise error(f"{path}: not a TOML file: nested too deep") from None
