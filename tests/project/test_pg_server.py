"""The tests' own PostgreSQL: where none answers at 127.0.0.1:5432, the suite starts a throwaway
server from the installed binaries, points every test's URL at it, and removes it at the end."""

import os

import psycopg
from helpers.pg_server import answers, suite_server

from moglow_eval.core.ports import free_port


def test_the_suite_has_a_postgresql_and_every_url_points_at_it(pg_server):
    from helpers import fake_stimuli
    from helpers.pg_server import pg_admin_url

    assert answers(pg_admin_url()) and pg_admin_url() == pg_server
    assert fake_stimuli.pg_base() == pg_admin_url().replace("postgresql://", "postgresql+psycopg://", 1)
    assert os.environ["E2E_PG"] == pg_admin_url()  # what the demo and gunicorn, started by tests, are given


def test_without_a_server_a_throwaway_one_is_started_and_removed(pg_server, monkeypatch):
    monkeypatch.delenv("E2E_PG")
    monkeypatch.delenv("RATING_TEST_PG")
    nobody = f"postgresql://postgres@127.0.0.1:{free_port()}/test"  # no server listens there
    cluster, admin = suite_server(default=nobody)
    try:
        assert cluster is not None and admin != nobody and os.environ["E2E_PG"] == admin
        with psycopg.connect(admin, autocommit=True) as conn:
            assert conn.execute("SELECT current_database()").fetchone() == ("test",)
            conn.execute("CREATE TABLE t (x int)")  # a working database, as the tests need it
    finally:
        cluster.remove()
    assert not answers(admin) and not cluster.dir.exists()
