"""Back up a running study and restore it (`python -m rating_app backup | restore`).

SQLite: SQLite's online backup API copies a consistent snapshot page by page while the app goes on writing (WAL
readers and writers do not block it), into a temporary file renamed into place at the end. PostgreSQL: `pg_dump
--format=custom` (one transaction, so one consistent snapshot, while the app goes on), restored by `pg_restore`
into an empty database. Either way the restored database is the study as it was at one instant: each answer is
committed before the next trial is served, so a backup never holds half an answer.
"""

from __future__ import annotations

import contextlib
import shutil
import sqlite3
import subprocess
from pathlib import Path

from sqlalchemy import inspect
from sqlalchemy.engine import make_url
from sqlalchemy.exc import SQLAlchemyError

from moglow_eval.core import whole_files

from ..store.db import Clip, Rater, Trial, check_url, make_engine, require_sqlite_file
from ..store.manifest import AppError

SQLITE_MAGIC = b"SQLite format 3\x00"
PG_DUMP_MAGIC = b"PGDMP"


def backup(db_url: str | None, out) -> str:
    """Write a backup of the study database at `db_url` to `out`; return what kind it is ("sqlite" / "pg_dump")."""
    url = make_url(check_url(db_url))
    out = Path(out)
    if out.is_dir():
        raise AppError(f"--out {out}: is a folder; give the backup file's name")
    if url.get_backend_name() == "sqlite":
        db = _sqlite_path(url, must_exist=True)
        _require_study(url, db)
        if out.exists() and out.samefile(db):  # renamed over the live study, a running app would write on unseen
            raise AppError(f"--out {out}: is the study's database itself; write the backup elsewhere")
        with whole_files.writing(out) as tmp:
            _made(tmp, "--out", out)
            _sqlite_copy(_sqlite_path(url), tmp)
        return "sqlite"
    _require_study(url)
    with whole_files.writing(out) as tmp:
        _made(tmp, "--out", out)
        _pg_tool("pg_dump", "--format=custom", "--no-owner", f"--file={tmp}", _libpq(url))
    return "pg_dump"


def restore(backup_file, db_url: str | None) -> str:
    """Restore `backup_file` into the new or empty database at `db_url`; return its kind."""
    url = make_url(check_url(db_url))
    backup_file = Path(backup_file)
    with open(backup_file, "rb") as fh:
        head = fh.read(len(SQLITE_MAGIC))
    if url.get_backend_name() == "sqlite":
        if not head.startswith(SQLITE_MAGIC):
            raise AppError(f"{backup_file}: not an SQLite backup (restore a pg_dump file into PostgreSQL)")
        target = _sqlite_path(url)
        if target.exists() and target.stat().st_size:
            raise AppError(f"--db {target}: exists already; restore into a new file")
        if not target.parent.is_dir():
            raise AppError(f"--db {target}: folder {target.parent} does not exist")
        with whole_files.writing(target) as tmp:  # checked before it is renamed into place: a bad backup leaves none
            _made(tmp, "--db", target)
            _sqlite_copy(backup_file, tmp)
            _check_rating_database(tmp, backup_file)
        return "sqlite"
    if not head.startswith(PG_DUMP_MAGIC):
        raise AppError(f"{backup_file}: not a pg_dump custom-format backup (restore an SQLite backup into SQLite)")
    _require_empty(url)
    _pg_tool(
        "pg_restore",
        "--exit-on-error",
        "--no-owner",
        "--single-transaction",
        f"--dbname={_libpq(url)}",
        str(backup_file),
    )
    return "pg_dump"


def _sqlite_path(url, must_exist=False) -> Path:
    if not url.database or url.database == ":memory:":
        raise AppError(f"--db {url}: an SQLite database in a file is needed")
    path = Path(url.database)
    if must_exist:
        require_sqlite_file(str(path))
    return path


def _made(tmp: Path, flag: str, out: Path) -> None:
    """The temporary file of `out` made empty at once: a folder the command may not write in is named as such, not as
    a database SQLite could not open (the one copied from, by its message)."""
    try:
        tmp.touch(exist_ok=False)
    except OSError as e:
        raise AppError(f"{flag} {out}: cannot be written there ({e.strerror or e})") from None


def _sqlite_copy(source: Path, target: Path) -> None:
    """SQLite's online backup API: a consistent copy of `source` even while others write to it."""
    try:
        with contextlib.closing(sqlite3.connect(source, timeout=30)) as src:
            with contextlib.closing(sqlite3.connect(target)) as dst:
                src.backup(dst, pages=1024)
    except sqlite3.DatabaseError as e:
        raise AppError(f"{source}: cannot copy the database: {e}") from None


def _check_rating_database(copy: Path, backup_file: Path) -> None:
    """AppError unless `copy` (of `backup_file`) is whole and a rating study's: SQLite's integrity check, and the
    app's core tables (an SQLite file of something else would restore, and fail only at the next export)."""
    with contextlib.closing(sqlite3.connect(copy)) as conn:
        ok = conn.execute("PRAGMA integrity_check").fetchone()[0]
        tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    if ok != "ok":
        raise AppError(f"{backup_file}: a damaged database ({ok.splitlines()[0]}); restore an intact backup")
    missing = sorted({Clip.__tablename__, Rater.__tablename__, Trial.__tablename__} - tables)  # any version's
    if missing:
        raise AppError(f"{backup_file}: not a rating study's database (no table {missing[0]})")


def _libpq(url) -> str:
    """The URL as libpq (pg_dump, pg_restore) reads it: no SQLAlchemy driver name; the password, if any, stays in
    the URL here only because the user gave it so (PGPASSWORD and ~/.pgpass work as for psql)."""
    return url.set(drivername="postgresql").render_as_string(hide_password=False)


def _pg_tool(name: str, *args: str) -> None:
    exe = _pg_binary(name)
    r = subprocess.run([exe, *args], capture_output=True, text=True)
    if r.returncode != 0:
        lines = [x for x in r.stderr.strip().splitlines() if x.strip()] or [f"exit code {r.returncode}"]
        raise AppError(f"{name} failed: {lines[0].removeprefix(f'{name}: ')}")


def _pg_binary(name: str) -> str:
    """The newest installed PostgreSQL's `name` (pg_dump must be at least the server's version), else PATH's."""
    found = sorted(Path("/usr/lib/postgresql").glob(f"*/bin/{name}"), key=lambda p: _version(p.parts[-3]))
    exe = str(found[-1]) if found else shutil.which(name)
    if not exe:
        raise AppError(f"{name} not found: install PostgreSQL's client programs (postgresql-client)")
    return exe


def _version(text: str):
    return tuple(int(x) for x in text.split(".") if x.isdigit())


def _tables(url) -> list[str] | None:
    engine = make_engine(url.render_as_string(hide_password=False))
    try:
        return inspect(engine).get_table_names()
    except SQLAlchemyError as e:
        first = str(getattr(e, "orig", None) or e).strip().splitlines()
        where = url.render_as_string(hide_password=True)
        raise AppError(f"cannot open the database {where}: {first[0] if first else e.__class__.__name__}") from None
    finally:
        engine.dispose()


def _require_study(url, path: Path | None = None) -> None:
    if "ratings" not in _tables(url):
        raise AppError(
            f"{path or url.render_as_string(hide_password=True)}: no ratings table (not a rating app database)"
        )


def _require_empty(url) -> None:
    if _tables(url):
        where = url.render_as_string(hide_password=True)
        raise AppError(f"--db {where}: not empty; restore into a new, empty database (createdb NAME)")
