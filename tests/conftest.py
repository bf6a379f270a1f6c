"""Shared fixtures, and the two tiers of the suite.

The fast tier, `python -m pytest -m "not full"`, needs nothing beside the checkout: no ../shared, no PostgreSQL,
no browser. The full tier (`python -m pytest`, what CI runs) adds every test that reads the real data in ../shared
(CONTRACTS.md, data/README.md), talks to PostgreSQL, drives a browser, runs a crowd against a served app or
makes a full-size run; those are marked `full` here, from their markers and the fixtures they use, so a new test
lands in the right tier by itself (a long test without such a fixture says `@pytest.mark.full` itself).
Torch and PostgreSQL start only in the fixtures and tests that need them. Shared helpers: tests/helpers/.
"""

import gc
import os
import secrets
import sys

import psycopg
import pytest
from helpers import fast_tier
from helpers.once import built_once
from helpers.paths import BANDAI, PARTS, ROOT, SHARED, small_take_names

from rendering.mesh import set_gl_environment

# Fixtures that need the full machine: ../shared, PostgreSQL, or a real run of the pipeline.
FULL_FIXTURES = {"shared_dir", "small_dataset", "tiny_runs", "quick_stimuli", "pg_server", "pg_database"}
FULL_MARKERS = ("full", "postgres", "browser")
MAX_WORKERS = 4  # cores that `-n auto` counts at most (pytest_xdist_auto_num_workers)


@pytest.fixture(scope="session")
def shared_dir():
    if not SHARED.is_dir():
        pytest.fail(f"../shared is missing beside the checkout ({SHARED}); CI always has it")
    return SHARED


@pytest.fixture(autouse=True)
def _fast_tier_needs_nothing_beside(request):
    # A test in the fast tier must run on a bare machine; one that reads ../shared or starts PostgreSQL or a browser
    # belongs to the full tier (helpers/fast_tier.py says why this is watched rather than trusted).
    if request.node.get_closest_marker("full"):
        yield
        return
    fast_tier.watch()
    yield
    used = fast_tier.stop()
    if used is not None:
        pytest.fail(f"a fast-tier test used {used}: ask for its fixture (shared_dir, pg_server) or mark the test full")


@pytest.fixture(autouse=True)
def _float32_on_gpus():
    # On a GPU, cuDNN runs nn.LSTM and the convolutions in TF32 by default (10-bit mantissa), which moves the
    # models' outputs by ~5e-4: the tests compare float32 maths (MGStream against nn.LSTM, a stream against
    # its own predictions), so they run in full float32. Training keeps the default. No effect on a CPU, and
    # torch is not imported for it: a test that never loads torch never pays for it.
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.backends.cudnn.allow_tf32 = False


def pytest_configure(config):
    # make_stimuli picks MG's sampler precision per CPU (generation.sampling.precision), measuring at first use and
    # caching in the user's cache folder. The suite samples in float32 on every host, as its figures were made, and
    # leaves that cache alone; tests/generation/test_sampler_precision.py tests the pick with measurements it gives it.
    os.environ.setdefault("MOGLOW_SAMPLER_PRECISION", "float32")
    # One thread in each BLAS and OpenMP pool of the processes the suite starts (its workers, set here before xdist
    # starts them, and every command they run): xdist already gives every core a worker (see
    # pytest_xdist_auto_num_workers), so a pool's second thread only waits for a core another worker is using, and
    # costs CPU doing so (bench/RESULTS.md, test-suite). What a command sets itself (--threads, training's free-core
    # rule) it still sets; a user's own setting is kept.
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, "1")
    # The suite's process draws meshes as a command's does, so it sets what a command's main sets before its first GL
    # context (rendering.mesh.GL_ENVIRONMENT: the library sets no environment variable); without it llvmpipe's
    # rasteriser threads, which a forked child does not inherit, would leave tests/rendering/test_mesh_drawing.py's
    # child waiting for ever.
    set_gl_environment()
    fast_tier.install()
    if sys.dont_write_bytecode and not hasattr(config, "workerinput"):
        # Where PYTHONDONTWRITEBYTECODE is set, as on some CI machines, each of the several hundred processes the
        # suite starts (servers and their workers, commands, render workers) would compile the product's modules
        # from source again, a few tenths of a second each. Compiled once here, before xdist's workers start, they
        # are read from __pycache__ (which git ignores), as on a machine without that setting.
        import compileall

        for part in PARTS:
            compileall.compile_dir(ROOT / part, quiet=1)


@pytest.hookimpl(wrapper=True)
def pytest_collection(session):
    # Collection imports every test module, and through them torch, pandas, SQLAlchemy and the rest: hundreds of
    # thousands of objects that stay for the whole run. The cyclic collector, on, walks them again and again as they
    # pile up (a full collection at each quarter's growth), so it is off until collection is done; then what
    # collection left is frozen out of its reach, and each of its full collections walks only what the tests have made
    # since. The crowds and servers the tests run in-process allocate all the time, and those full collections were a
    # measurable share of a crowd test's CPU (bench/notes/2026-12-02-results-details.md, test-suite).
    gc.disable()
    try:
        return (yield)
    finally:
        gc.collect()
        gc.freeze()
        gc.enable()


def pytest_xdist_auto_num_workers(config):
    """The workers of `-n auto` (pyproject's addopts): one a core for the fast tier, which computes all the time,
    and one more for the full tier, whose browsers, servers, crowds and databases leave a core waiting about a fifth
    of the run; a third worker on 2 cores fills that time, and would only slow the fast tier (bench/RESULTS.md,
    test-suite). At most MAX_WORKERS a core count: each worker's servers, crowds and browsers hold PostgreSQL
    connections and memory, and the suite was measured on 2 cores. Where PYTEST_XDIST_AUTO_NUM_WORKERS is set, this
    answers nothing, and xdist's own hook reads it."""
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return None
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    cores = min(cores, MAX_WORKERS)
    return cores if _fast_tier(config) else cores + 1


@pytest.fixture(scope="session")
def pg_server():
    """The plain URL of the tests' PostgreSQL database `test`: the server at 127.0.0.1:5432 when it answers, else
    a throwaway one of the tests' own, removed at the end of the session (helpers/pg_server.py). Its URLs are
    also set in the environment (E2E_PG, RATING_TEST_PG) for the processes the tests start."""
    from helpers.pg_server import ServerError, suite_server

    try:
        cluster, admin = suite_server()
    except ServerError as e:
        pytest.fail(f"no PostgreSQL for the tests: {e}")
    yield admin
    if cluster is not None:
        cluster.remove()


def needs_full(item):
    """Whether a collected test belongs to the full tier (see the module's docstring)."""
    if any(m in item.keywords for m in FULL_MARKERS) or FULL_FIXTURES & set(item.fixturenames):
        return True
    params = getattr(getattr(item, "callspec", None), "params", {})
    return "postgres" in params.values()


def pytest_collection_modifyitems(config, items):
    # Every collected test runs, in CI too: a long variant of a check is a benchmark or a script (bench/, deploy/),
    # never a test left out.
    full_files = set()
    for item in items:
        if needs_full(item):
            item.add_marker(pytest.mark.full)
            full_files.add(item.path)
    # The files with full-tier tests first: they hold the long ones (whole studies, browsers, servers), and the
    # workers, which take a file at a time in this order (--dist loadfile --no-loadscope-reorder: xdist's own order,
    # by the number of tests in a file, left the README's study, two tests, to the end), then end on the many short
    # files together instead of one finishing a long file while the others wait. A stable sort: each file's tests
    # keep their order, and every worker collects the same order, as xdist requires. The fast tier keeps the files'
    # own order: it has no long files to put first.
    if not _fast_tier(config):
        items.sort(key=lambda item: item.path not in full_files)


def _fast_tier(config):
    """Whether this run is the fast tier (`-m "not full"`)."""
    return "not full" in (config.option.markexpr or "")


# --- data ---
@pytest.fixture(scope="session")
def small_dataset(tmp_path_factory):
    """Path of a dataset.npz prepared from 4 real takes of every Bandai-Namco category (about a second)."""
    from generation.data.prepare import prepare

    def build(folder):
        prepare(BANDAI, folder / "dataset.npz", takes=small_take_names(), workers=1, progress=False)

    return built_once(tmp_path_factory, "small_dataset", build) / "dataset.npz"


# --- models ---
@pytest.fixture(scope="session")
def tiny_runs(small_dataset, tmp_path_factory):
    """{'mg': run_dir, 'fl': run_dir}: mg_tiny and fl_tiny trained 150 steps on `small_dataset` (seconds)."""
    from generation.training.train import train

    def build(root):  # train restores torch's thread count on return (threads.torch_threads)
        for kind in ("mg", "fl"):
            train(kind, "tiny", small_dataset, root / kind, steps=150, seed=0, progress=False, threads=1)

    root = built_once(tmp_path_factory, "tiny_runs", build)
    return {kind: root / kind for kind in ("mg", "fl")}


# --- rating app: one small real stimulus folder; every app test runs on SQLite and PostgreSQL ---
APP_ADMIN_TOKEN = "test-admin-token"


@pytest.fixture(scope="session")
def app_stimuli(tmp_path_factory):
    from helpers.fake_stimuli import write_fake_stimuli

    return write_fake_stimuli(tmp_path_factory.mktemp("app_stimuli"))


@pytest.fixture(params=["sqlite", "postgres"])
def app_db_url(request, tmp_path):
    if request.param == "sqlite":
        yield f"sqlite:///{tmp_path}/ratings.sqlite"
    else:
        from helpers.fake_stimuli import pg_schema

        request.getfixturevalue("pg_server")
        with pg_schema() as url:  # a fresh schema per test, dropped afterwards (never skipped)
            yield url


@pytest.fixture
def app(app_stimuli, app_db_url):
    """The app with target 3 and MIN_VIEW 0 (answers need no wait; tests of the viewing rule use `make_app`)."""
    from rating_app import create_app
    from rating_app.store.db import app_engine

    app = create_app(
        manifest=app_stimuli, db_url=app_db_url, admin_token=APP_ADMIN_TOKEN, ratings_per_clip=3, min_view=0
    )
    app.config["TESTING"] = True
    yield app
    app_engine(app).dispose()


@pytest.fixture
def client(app):
    return app.test_client()


@pytest.fixture
def make_app(app_stimuli, app_db_url):
    """make_app(**settings) -> an app on this test's database; every engine is disposed at the end."""
    from rating_app import create_app
    from rating_app.store.db import app_engine

    made = []

    def make(**kw):
        kw = {"manifest": app_stimuli, "db_url": app_db_url, "admin_token": APP_ADMIN_TOKEN, **kw}
        made.append(create_app(**kw))
        made[-1].config["TESTING"] = True
        return made[-1]

    yield make
    for a in made:
        app_engine(a).dispose()


# --- stimuli: one real `make_stimuli --quick` run per session ---
@pytest.fixture(scope="session")
def quick_stimuli(tmp_path_factory):
    """Path of the stimulus folder written by one `python -m generation.make_stimuli --quick` run (prepared
    data subset and tiny models trained in the run). Its dataset cache and checkpoints are in the sibling
    folder `runs/` (`runs/dataset_quick.npz`, `runs/{mg,fl}_tiny/checkpoints/`)."""
    import subprocess
    import sys

    def build(root):
        r = subprocess.run(
            [
                sys.executable,
                "-m",
                "generation.make_stimuli",
                "--quick",
                "--out",
                str(root / "stimuli"),
                "--runs",
                str(root / "runs"),
            ],
            capture_output=True,
            text=True,
            cwd=ROOT,
            timeout=900,
        )
        if r.returncode != 0:
            pytest.fail(f"make_stimuli --quick failed ({r.returncode}): {r.stderr[-3000:]}")
        (root / "make_stimuli.log").write_text(r.stdout + r.stderr)

    return built_once(tmp_path_factory, "quick_stimuli", build) / "stimuli"


def _two_person_set(tmp_path_factory, design):
    """(stimulus folder, manifest rows, {item: sources.csv row}) of the shared `design` set, made once a run."""
    import csv

    from helpers.seamless_fixtures import build_two_person_set

    root = built_once(tmp_path_factory, f"{design}_set", lambda f: build_two_person_set(f, design))
    with open(root / "out" / "manifest.csv", newline="") as f:
        manifest = list(csv.DictReader(f))
    with open(root / "items" / "sources.csv", newline="") as f:
        sources = {r["item"]: r for r in csv.DictReader(f)}
    return root / "out", manifest, sources


@pytest.fixture(scope="session")
def dyadic_set(tmp_path_factory):
    """A dyadic study built from two synthetic Seamless conversations (helpers.seamless_fixtures), read-only."""
    return _two_person_set(tmp_path_factory, "dyadic")


@pytest.fixture(scope="session")
def semantic_set(tmp_path_factory):
    """The semantic study of the same conversations, stereo, read-only."""
    return _two_person_set(tmp_path_factory, "semantic")


@pytest.fixture
def torch_one_thread():
    """Tiny models: one thread is as fast and immune to other jobs on a shared 2-core machine."""
    import torch

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture
def pg_database(pg_server):
    """A fresh PostgreSQL database for one run, dropped afterwards."""
    name = f"e2e_{secrets.token_hex(4)}"
    admin = pg_server
    with psycopg.connect(admin, autocommit=True) as conn:
        conn.execute(f'CREATE DATABASE "{name}"')
    try:
        yield admin.rsplit("/", 1)[0] + f"/{name}"
    finally:
        with psycopg.connect(admin, autocommit=True) as conn:
            conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


@pytest.fixture
def make(app_db_url):
    """build(manifest, design, **settings): create_app on the test database with test defaults (admin token, no
    viewing wait, no session limit); every app's engine is disposed afterwards."""
    from rating_app import create_app
    from rating_app.store.db import app_engine

    made = []

    def build(manifest, design, **kw):
        kw = {"admin_token": "test-admin-token", "min_view": 0, "sessions_per_client": 0, **kw}
        made.append(create_app(manifest=manifest, db_url=app_db_url, design=design, **kw))
        made[-1].config["TESTING"] = True
        return made[-1]

    yield build
    for a in made:
        app_engine(a).dispose()


# --- a real browser, and the app served to it over HTTP ---
@pytest.fixture
def live_server(app_stimuli, app_db_url):
    """The URL of the app serving `app_stimuli` over HTTP (a module may give its own `app_stimuli`);
    helpers.browser.live_server_manifest holds its manifest and app meanwhile."""
    from helpers.browser import live_server_manifest
    from helpers.servers import in_thread

    from rating_app import create_app

    manifest = os.environ.get("SCREENSHOT_MANIFEST") or app_stimuli
    app = create_app(
        manifest=manifest, db_url=app_db_url, admin_token="browser-token", ratings_per_clip=5, clips_per_rater=3
    )
    live_server_manifest[:] = [manifest, app]
    with in_thread(app) as url:
        yield url


@pytest.fixture
def browser(tmp_path):
    """Debian's chromium, headless, phone-sized (helpers/browser.py), quit at the end."""
    from helpers.browser import chrome

    driver = chrome(tmp_path)
    yield driver
    driver.quit()
