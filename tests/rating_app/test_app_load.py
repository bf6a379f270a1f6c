"""Bounded load test on loopback: 40 concurrent simulated raters complete sessions against gunicorn; the server
is killed with SIGKILL mid-run and restarted; no acknowledged rating is missing and none is counted twice. In every
design on PostgreSQL, and acr on SQLite too."""

import collections
import threading
import time

import pytest
from helpers.concurrent_raters import cover_mismatches
from helpers.crowd_records import DESIGNS
from helpers.fake_stimuli import write_fake_stimuli
from helpers.servers import crowd_env, kill9, start_gunicorn, stop, warm_up

from moglow_eval.core import study
from moglow_eval.core.ports import free_port
from rating_app.simulate import run_simulation
from rating_app.store.db import make_engine

pytestmark = pytest.mark.full  # the full tier: crowds against real servers


@pytest.fixture(scope="module")
def design_stimuli(tmp_path_factory):
    return write_fake_stimuli(tmp_path_factory.mktemp("load_stimuli"), catch_nat=True, mismatched=True)


# Every design on PostgreSQL, and acr on SQLite too: which database holds the answers is the app's concern.
DESIGN_DATABASES = [(d, "postgres") for d in study.DESIGNS] + [("acr", "sqlite")]


# every design: DESIGNS[design] fails for one crowd_records lacks
@pytest.mark.parametrize("design, app_db_url", DESIGN_DATABASES, indirect=["app_db_url"])
def test_raters_with_a_server_crash(app_stimuli, design_stimuli, app_db_url, tmp_path, design):
    """40 raters at once, the server killed a third of the way through (bench/bench_app.py runs crowds of
    hundreds): enough that answers are in flight when it dies, in every design."""
    raters = 40
    key, rows_of, per_rater, unit = DESIGNS[design]
    stimuli = app_stimuli if design == "acr" else design_stimuli
    port = free_port()
    env = crowd_env(stimuli, app_db_url, "load-token", STUDY_DESIGN=design)
    log = open(tmp_path / "gunicorn.log", "w")
    acks, killed = [0], threading.Event()
    kill_at = raters * per_rater // 3  # a third of the way through
    procs = [start_gunicorn(port, env, log)]

    def on_ack(rec):
        acks[0] += 1

    summary = {}

    def crowd():
        try:
            summary.update(
                run_simulation(
                    f"http://127.0.0.1:{port}",
                    raters,
                    seed=3,
                    careless=0.1,
                    manifest=stimuli,
                    concurrency=raters,
                    timeout_s=150,
                    progress=False,
                    on_ack=on_ack,
                )
            )
        except Exception as e:  # said in the assertion below, not lost in the thread
            summary["crashed"] = repr(e)

    # Every worker answers before the crowd comes: on a cold machine a worker still importing the app would take
    # the first connections late, and the crowd's first third could pass before the kill is armed.
    warm_up(f"http://127.0.0.1:{port}", 3 * 16)
    sim = threading.Thread(target=crowd)
    try:
        sim.start()
        while acks[0] < kill_at and sim.is_alive():
            time.sleep(0.01)
        acked_before = acks[0]
        assert acked_before, f"the crowd ended before its first answer: {summary}"
        kill9(procs[-1])
        killed.set()
        time.sleep(0.5)
        procs.append(start_gunicorn(port, env, log))
        sim.join(180)
        assert not sim.is_alive(), "simulation did not finish in time"
    finally:
        stop(procs)
        log.close()

    assert killed.is_set() and 0 < acked_before < summary["n_ratings"]
    assert summary["errors"] == [], summary["errors"][:3]
    assert summary["n_raters_completed"] == raters
    acked = collections.Counter(tuple(r[k] for k in key) for r in summary["ratings"])
    assert max(acked.values()) == 1 and len(acked) == raters * per_rater

    engine = make_engine(app_db_url)
    try:
        from sqlalchemy.orm import Session

        with Session(engine) as s:
            rows = list(rows_of(s))
        assert cover_mismatches(engine) == {}  # the kill -9 left no running count off
    finally:
        engine.dispose()
    stored = collections.Counter(tuple(r[k] for k in key) for r in rows)
    assert max(stored.values()) == 1  # never double-counted
    assert stored == acked  # nothing acknowledged is missing, nothing extra
    # the balanced assignment spread the 2 test slots per rater evenly over the test units
    per_unit = collections.Counter(unit(r) for r in rows if r["role"] == "test" and unit(r) is not None)
    assert max(per_unit.values()) - min(per_unit.values()) <= 3


def test_apps_starting_at_once_on_a_fresh_database_all_start(app_stimuli, pg_server, monkeypatch):
    """gunicorn's workers each open the study as they boot. On a fresh PostgreSQL database they raced to record the
    manifest's row: a worker that lost failed to boot, and gunicorn shut the whole server down ("Worker failed to
    boot"), seen once in this file's crowds. Here two apps start in threads, each held before recording its start
    until the other is there too (or 3 s have passed: under the lock that now orders them, the first waits alone)."""
    import secrets

    import psycopg

    from rating_app import create_app
    from rating_app.store import rounds

    record, meet = rounds.record_start, threading.Barrier(2, timeout=3)

    def together(*args):
        try:
            meet.wait()
        except threading.BrokenBarrierError:
            pass
        return record(*args)

    monkeypatch.setattr(rounds, "record_start", together)
    for _ in range(2):
        name = f"start_{secrets.token_hex(4)}"
        with psycopg.connect(pg_server, autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        url = pg_server.rsplit("/", 1)[0] + f"/{name}"
        errors, apps = [], []

        def start():
            try:
                apps.append(create_app(manifest=app_stimuli, db_url=url, admin_token="start-token"))
            except Exception as e:  # said in the assertion below
                errors.append(repr(e))

        meet.reset()
        threads = [threading.Thread(target=start) for _ in range(2)]
        try:
            for t in threads:
                t.start()
            for t in threads:
                t.join(120)
            assert errors == [] and len(apps) == 2, errors
        finally:
            for app in apps:
                app.extensions["rating_app"]["engine"].dispose()
            with psycopg.connect(pg_server, autocommit=True) as conn:
                conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')
