"""The app as a real server for the tests: served over HTTP from a thread of the test's own process; gunicorn
started and waited for, killed without a clean shutdown; and the settings of a crowd run (tests/rating_app/
test_app_load.py, test_hosts.py, test_outage.py, test_proxy.py, test_accel.py)."""

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import requests

ROOT = Path(__file__).resolve().parents[2]


@contextlib.contextmanager
def in_thread(app):
    """`app` on werkzeug's threaded HTTP server on a free port of 127.0.0.1, served from a daemon thread; yields its
    URL, and stops the server and closes the app's database connections on leaving."""
    import threading

    from werkzeug.serving import make_server

    from rating_app.store.db import app_engine

    server = make_server("127.0.0.1", 0, app, threaded=True)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_port}"
    finally:
        server.shutdown()
        thread.join(5)
        app_engine(app).dispose()


def wait_for(url, proc, what, timeout_s=120.0):
    """Return once `url` answers 200; AssertionError (naming `what`) if `proc` exits or `timeout_s` passes first.
    A deadline, not a wait: generous, as a server's start (its imports, its workers' imports beside the rest of the
    suite) can take tens of seconds on a slow, loaded 2-core machine."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise AssertionError(f"{what} exited with {proc.returncode}")
        with contextlib.suppress(requests.RequestException):
            if requests.get(url, timeout=1).status_code == 200:
                return
        time.sleep(0.1)
    raise AssertionError(f"{what} did not come up")


def start_gunicorn(port, env, log, workers=3, threads=16, preload=True):
    """gunicorn serving rating_app.wsgi:app on 127.0.0.1:port in a process group of its own (see kill9), once its
    /healthz answers; its output goes to the open file `log`. `preload`: with `--preload`, as docs/hosting.md
    starts it (the app built once in the master, the workers forked from it)."""
    cmd = [sys.executable, "-m", "gunicorn", "-w", str(workers), "-k", "gthread", "--threads", str(threads)]
    cmd += ["--preload"] if preload else []
    cmd += ["--backlog", "2048", "-b", f"127.0.0.1:{port}", "rating_app.wsgi:app"]
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    wait_for(f"http://127.0.0.1:{port}/healthz", proc, f"gunicorn (see {log.name})")
    return proc


def warm_up(url, n):
    """`n` concurrent requests to `url`/healthz, each answered: every worker of a server started moments ago has
    imported the app and answers before a crowd arrives."""
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(n) as pool:
        codes = list(pool.map(lambda _: requests.get(url + "/healthz", timeout=60).status_code, range(n)))
    assert codes == [200] * n, codes


def kill9(proc):
    os.killpg(proc.pid, signal.SIGKILL)  # master and workers at once, no clean shutdown
    proc.wait(10)


def stop(procs):
    """Stop the gunicorn processes of `procs` that still run (a killed one has been reaped already)."""
    for p in procs:
        if p.poll() is None:
            p.terminate()
            p.wait(10)


def crowd_env(stimuli, database_url, token, **settings):
    """The environment of an app under a simulated crowd: targets that never fill, two test trials a rater, no
    viewing time, no per-client session limit (every rater is on loopback), and `settings` on top, by their names
    (STUDY_DESIGN="pairwise": the variable RATING_STUDY_DESIGN)."""
    return dict(
        os.environ,
        RATING_MANIFEST=str(stimuli),
        RATING_DATABASE_URL=database_url,
        RATING_ADMIN_TOKEN=token,
        RATING_RATINGS_PER_CLIP="1000",
        RATING_CLIPS_PER_RATER="2",
        RATING_MIN_VIEW="0",
        RATING_SESSIONS_PER_CLIENT="0",
        **{"RATING_" + name: value for name, value in settings.items()},
    )
