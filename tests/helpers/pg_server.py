"""The tests' PostgreSQL: the one at 127.0.0.1:5432 (trust auth, database `test`) when it answers, else a throwaway
server of the tests' own, made with initdb in a temporary folder and started with pg_ctl on a free port (as the
`postgres` user when run as root: initdb refuses root), stopped and removed at the end of the run (conftest).
RATING_TEST_PG / E2E_PG, when set, name the server to use instead and nothing is started.

`Cluster` is also the restart test's server (tests/rating_app/test_outage.py), never the shared one."""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import psycopg

from moglow_eval.core.ports import free_port

PG_BIN = Path("/usr/lib/postgresql/15/bin")
DEFAULT_ADMIN = "postgresql://postgres@127.0.0.1:5432/test"


class ServerError(RuntimeError):
    pass


class Cluster:
    """A PostgreSQL cluster of our own in a temporary folder (initdb refuses root: run as the postgres user)."""

    def __init__(self):
        if not (PG_BIN / "initdb").exists():
            raise ServerError(f"PostgreSQL's server binaries are needed in {PG_BIN}: scripts/install-system-deps.sh")
        self.dir = Path(tempfile.mkdtemp(prefix="ra_pg_"))
        self.port = free_port()
        self.as_user = ["runuser", "-u", "postgres", "--"] if os.geteuid() == 0 else []
        if self.as_user:
            shutil.chown(self.dir, "postgres")
        self._run("initdb", "-D", str(self.dir / "data"), "-U", "postgres", "--auth=trust", "-E", "UTF8")
        self.url = f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/postgres"

    def _run(self, tool, *args):
        r = subprocess.run([*self.as_user, str(PG_BIN / tool), *args], capture_output=True, text=True, timeout=120)
        if r.returncode != 0:
            raise ServerError(f"{tool}: {r.stdout[-1500:]} {r.stderr[-1500:]}")

    def start(self):
        opts = f"-p {self.port} -k {self.dir} -c listen_addresses=127.0.0.1 -c fsync=off -c max_connections=300"
        self._run("pg_ctl", "-D", str(self.dir / "data"), "-o", opts, "-l", str(self.dir / "log"), "-w", "start")

    def stop(self, mode="fast"):
        self._run("pg_ctl", "-D", str(self.dir / "data"), "-m", mode, "-w", "stop")

    def remove(self):
        with contextlib.suppress(ServerError):
            self.stop("immediate")
        shutil.rmtree(self.dir, ignore_errors=True)


def answers(url: str) -> bool:
    try:
        with psycopg.connect(url, connect_timeout=3):
            return True
    except psycopg.Error:
        return False


def throwaway_server() -> tuple[Cluster, str]:
    """A started Cluster with a database `test`, and the plain URL of that database."""
    cluster = Cluster()
    try:
        cluster.start()
        admin = f"postgresql://postgres@127.0.0.1:{cluster.port}/test"
        with psycopg.connect(admin.rsplit("/", 1)[0] + "/postgres", autocommit=True) as conn:
            conn.execute("CREATE DATABASE test")
    except BaseException:
        cluster.remove()
        raise
    return cluster, admin


def suite_server(default: str = DEFAULT_ADMIN) -> tuple[Cluster | None, str]:
    """(the throwaway cluster or None, the plain URL of the tests' database `test`), and the environment set so that
    every test and every process they start (the demo, gunicorn) uses it."""
    configured = os.environ.get("E2E_PG")
    if configured or os.environ.get("RATING_TEST_PG"):
        return None, configured or os.environ["RATING_TEST_PG"].replace("postgresql+psycopg://", "postgresql://")
    cluster, admin = (None, default) if answers(default) else throwaway_server()
    os.environ["E2E_PG"] = admin
    os.environ["RATING_TEST_PG"] = admin.replace("postgresql://", "postgresql+psycopg://", 1)
    return cluster, admin


def pg_admin_url() -> str:
    """A plain libpq URL of the tests' server's database `test` (where test databases are created): E2E_PG, which
    the `pg_server` fixture sets to the server at 127.0.0.1:5432 or to the tests' own."""
    return os.environ.get("E2E_PG", DEFAULT_ADMIN)
