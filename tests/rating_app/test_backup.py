"""Backing up a running study and restoring it (issue 33, item 6), on SQLite and PostgreSQL: a backup taken while a
simulated crowd answers restores into a fresh database whose export holds only answers the live study holds; with
the crowd stopped, the export from the restored database is the live export, byte for byte."""

import contextlib
import csv
import secrets
import sqlite3
import subprocess
import sys
import threading

import psycopg
import pytest
from helpers.fake_stimuli import write_fake_stimuli
from helpers.paths import ROOT
from helpers.pg_server import pg_admin_url
from helpers.servers import in_thread

from rating_app import create_app
from rating_app.simulate import run_simulation
from rating_app.store.db import app_engine


def cli(*args):
    r = subprocess.run(
        [sys.executable, "-m", "rating_app", *map(str, args)], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    return r


@contextlib.contextmanager
def pg_databases(n):
    """`n` fresh PostgreSQL databases, dropped afterwards (a backup holds the whole database, so not a schema)."""
    admin = pg_admin_url()
    names = [f"bk_{secrets.token_hex(4)}" for _ in range(n)]
    with psycopg.connect(admin, autocommit=True) as conn:
        for name in names:
            conn.execute(f'CREATE DATABASE "{name}"')
    try:
        yield [admin.rsplit("/", 1)[0] + f"/{name}" for name in names]
    finally:
        with psycopg.connect(admin, autocommit=True) as conn:
            for name in names:
                conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


@pytest.fixture(params=["sqlite", "postgres"])
def databases(request, tmp_path):
    """(live, restored at mid-crowd, restored at the end): the live study's URL and two new ones to restore into."""
    if request.param == "sqlite":
        yield [f"sqlite:///{tmp_path}/{name}.sqlite" for name in ("live", "mid", "end")]
    else:
        request.getfixturevalue("pg_server")
        with pg_databases(3) as urls:
            yield urls


def export(url, out):
    r = cli("export", "--db", url, "--out", out)
    assert r.returncode == 0, r.stderr
    return out.read_bytes()


@pytest.mark.full  # the full tier: a crowd while the study is backed up
def test_a_backup_of_a_running_study_restores_to_the_same_export(databases, tmp_path):
    live, mid, end = databases
    manifest = write_fake_stimuli(tmp_path / "stimuli", n_items=6)
    app = create_app(manifest=manifest, db_url=live, ratings_per_clip=4, min_view=0.1, sessions_per_client=0)
    acked, halfway, backed_up = [], threading.Event(), threading.Event()

    def on_ack(record):
        acked.append(record)
        if len(acked) >= 15:
            halfway.set()
        if len(acked) >= 30:  # the crowd answers on while the backup runs, and outlasts it however slow its start
            backed_up.wait(120)

    summary = {}
    with in_thread(app) as url:
        crowd = threading.Thread(
            target=lambda: summary.update(
                run_simulation(
                    url,
                    12,
                    manifest=manifest,
                    seed=3,
                    concurrency=3,
                    think_s=0.05,
                    progress=False,
                    on_ack=on_ack,
                )
            )
        )
        try:
            crowd.start()
            assert halfway.wait(120), "the crowd did not get going"
            r = cli("backup", "--db", live, "--out", tmp_path / "mid.bak")  # while the crowd answers
            assert r.returncode == 0, r.stderr
            assert crowd.is_alive()
            backed_up.set()
            crowd.join(300)
            assert not crowd.is_alive() and summary["errors"] == []

            r = cli("restore", tmp_path / "mid.bak", "--db", mid)
            assert r.returncode == 0, r.stderr
            mid_rows = {answer(x) for x in csv.DictReader(_export_text(mid, tmp_path / "mid.csv"))}
            live_rows = {answer(x) for x in csv.DictReader(_export_text(live, tmp_path / "live_now.csv"))}
            acked_early = {(r["rater_id"], r["clip_id"], str(r["rating"])) for r in acked[:15]}
            assert acked_early <= mid_rows  # acked = committed
            assert mid_rows < live_rows  # a snapshot of the live study, without the answers that came later

            # the crowd has stopped: back up, restore, and the two exports are the same bytes
            r = cli("backup", "--db", live, "--out", tmp_path / "end.bak")
            assert r.returncode == 0, r.stderr
            r = cli("restore", tmp_path / "end.bak", "--db", end)
            assert r.returncode == 0, r.stderr
            want = export(live, tmp_path / "live.csv")
            assert want.count(b"\n") == len(summary["ratings"]) + 1
            assert export(end, tmp_path / "end.csv") == want
        finally:
            backed_up.set()


def answer(row):
    return row["rater_id"], row["clip_id"], row["rating"]


def _export_text(url, out):
    export(url, out)
    return out.read_text().splitlines()


def test_backup_and_restore_refuse_bad_input_with_one_line(tmp_path, app_stimuli, pg_server, command_fails):
    """The refusals in-process (the conftest's command_fails); the backups and restores that succeed, as processes."""
    live = f"sqlite:///{tmp_path}/live.sqlite"
    app_engine(create_app(manifest=app_stimuli, db_url=live)).dispose()
    live_file = (tmp_path / "live.sqlite").stat()
    (tmp_path / "not_a_backup").write_text("hello")
    assert cli("backup", "--db", live, "--out", tmp_path / "ok.bak").returncode == 0
    (tmp_path / "cut.bak").write_bytes((tmp_path / "ok.bak").read_bytes()[:20000])  # a copy cut short
    with contextlib.closing(sqlite3.connect(tmp_path / "other.sqlite")) as other:
        other.execute("CREATE TABLE foo (x)")
    with pg_databases(1) as (pg,):
        cases = [
            (("backup", "--db", f"sqlite:///{tmp_path}/none.sqlite", "--out", tmp_path / "x"), "none.sqlite: no such"),
            (("backup", "--db", live, "--out", tmp_path), "is a folder"),
            (("backup", "--db", live, "--out", tmp_path / "live.sqlite"), "is the study's database itself"),
            (("backup", "--db", pg, "--out", tmp_path / "x"), "no ratings table (not a rating app database)"),
            (("restore", tmp_path / "ok.bak", "--db", live), "exists already; restore into a new file"),
            (("restore", tmp_path / "not_a_backup", "--db", f"sqlite:///{tmp_path}/n.sqlite"), "not an SQLite backup"),
            (("restore", tmp_path / "ok.bak", "--db", pg), "not a pg_dump custom-format backup"),
            (("restore", tmp_path / "missing.bak", "--db", pg), "missing.bak: No such file"),
            (("restore", tmp_path / "cut.bak", "--db", f"sqlite:///{tmp_path}/cut.sqlite"), "cut.bak: "),
            (("restore", tmp_path / "other.sqlite", "--db", f"sqlite:///{tmp_path}/o.sqlite"), "not a rating study"),
            (("restore", tmp_path / "ok.bak", "--db", f"sqlite:///{tmp_path}/no/r.sqlite"), "folder"),
        ]
        for args, message in cases:
            command_fails(*args, needle=message)
        assert (tmp_path / "live.sqlite").stat().st_ino == live_file.st_ino  # not renamed over by its own backup
        # a refused restore leaves no database behind, so the next one, of a good backup, is not refused as existing
        assert not (tmp_path / "cut.sqlite").exists() and not (tmp_path / "o.sqlite").exists()
        # a non-empty PostgreSQL database is refused, never merged into
        assert cli("restore", tmp_path / "ok.bak", "--db", f"sqlite:///{tmp_path}/copy.sqlite").returncode == 0
        app_engine(create_app(manifest=app_stimuli, db_url=pg)).dispose()
        assert cli("backup", "--db", pg, "--out", tmp_path / "pg.bak").returncode == 0
        not_empty = "not empty; restore into a new, empty database"
        command_fails("restore", tmp_path / "pg.bak", "--db", pg, needle=not_empty)


def test_a_folder_the_command_may_not_write_in_is_named(tmp_path, app_stimuli):
    """A backup into a folder the user may not write in, or a restore there, named the database it copies from as
    one SQLite could not open; now the flag and the file it could not write (run without root's rights to write
    anywhere: helpers.cli.as_a_plain_user)."""
    from helpers.cli import as_a_plain_user

    live = f"sqlite:///{tmp_path}/live.sqlite"
    app_engine(create_app(manifest=app_stimuli, db_url=live)).dispose()
    assert cli("backup", "--db", live, "--out", tmp_path / "ok.bak").returncode == 0
    shut = tmp_path / "shut"
    shut.mkdir(mode=0o555)
    cases = [
        (("backup", "--db", live, "--out", shut / "b.bak"), f"--out {shut / 'b.bak'}: cannot be written there"),
        (("restore", tmp_path / "ok.bak", "--db", f"sqlite:///{shut}/r.sqlite"), f"--db {shut}/r.sqlite: cannot be"),
    ]
    for args, needle in cases:
        cmd = [sys.executable, "-m", "rating_app", *map(str, args)]
        r = subprocess.run(as_a_plain_user(cmd), cwd=ROOT, capture_output=True, text=True, timeout=300)
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(lines) == 1 and needle in lines[0] and "(Permission denied)" in lines[0], lines
    assert list(shut.iterdir()) == []
