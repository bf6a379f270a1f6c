"""The app's settings table (rating_app/store/settings.py): the flags, the environment variables, the study file's keys,
create_app's arguments and docs/hosting.md's table all come from it, and a flag that is not given leaves the
variable its say."""

import re
import subprocess
import sys

import pytest
from helpers.paths import ROOT

from rating_app import SETTINGS, AppError, create_app
from rating_app.__main__ import build_parser
from rating_app.store.config import environment, known_keys
from rating_app.store.db import Base, app_engine, make_engine
from rating_app.store.settings import ARGS, TABLE

# What the app answered to before the table: every flag, setting name (the study file's key in lower case) and
# default must keep working; the environment variables are the names under the prefix RATING_ (issue 63).
FLAGS = {
    "--config": "RATING_CONFIG",
    "--manifest": "RATING_MANIFEST",
    "--db": "DATABASE_URL",
    "--design": "STUDY_DESIGN",
    "--question": "STUDY_QUESTION",
    "--completion-code": "COMPLETION_CODE",
    "--completion-url": "COMPLETION_URL",
    "--upload-root": "UPLOAD_ROOT",  # added by issue 55
    "--ratings-per-clip": "RATINGS_PER_CLIP",
    "--clips-per-rater": "CLIPS_PER_RATER",
    "--catch-per-rater": "CATCH_PER_RATER",
    "--slot-timeout": "SLOT_TIMEOUT",
    "--min-view": "MIN_VIEW",
    "--sessions-per-client": "SESSIONS_PER_CLIENT",
    "--reasons": "VOTE_REASONS",  # added with the reasons of a pairwise vote
    "--reason-text": "REASON_TEXT",
    "--pairing": "PAIRING",
    "--pairing-random": "PAIRING_RANDOM",
    "--pairing-indifference": "PAIRING_INDIFFERENCE",  # added by issue 55
    "--stop-when": "STOP_WHEN",
    "--stop-level": "STOP_LEVEL",
    "--stop-width": "STOP_WIDTH",
    "--stop-max-votes": "STOP_MAX_VOTES",
}
DEFAULTS = {
    "RATINGS_PER_CLIP": 20,
    "CLIPS_PER_RATER": 0,
    "CATCH_PER_RATER": 4,
    "SLOT_TIMEOUT": 3600.0,
    "MIN_VIEW": 1.0,
    "SESSIONS_PER_CLIENT": 10,
    "PROXY_COUNT": 0,
    "DB_POOL_SIZE": 10,
    "VIDEO_ACCEL": "off",
    "STUDY_DESIGN": "acr",
    "PAIRING": "balanced",
    "PAIRING_RANDOM": 0.1,
    "PAIRING_INDIFFERENCE": 0.0,
    "STOP_WHEN": "never",
    "STOP_LEVEL": 0.95,
    "STOP_WIDTH": 0.0,
    "STOP_MAX_VOTES": 0,
}
ARGUMENTS = {  # create_app's keyword arguments before the table
    "manifest", "db_url", "ratings_per_clip", "clips_per_rater", "catch_per_rater", "admin_token", "slot_timeout_s",
    "completion_code", "completion_url", "secret_key", "min_view", "sessions_per_client", "design", "question",
    "config", "reasons", "reason_text", "pairing", "pairing_random", "stop_when", "stop_level", "stop_width",
    "stop_max_votes", "upload_root", "pairing_indifference",
}  # fmt: skip


def serve_parser():
    sub = next(a for a in build_parser()._actions if a.dest == "cmd")
    return sub.choices["serve"]


def test_every_name_and_default_is_kept():
    assert {s.flag: s.name for s in TABLE if s.flag} == FLAGS
    assert {name: SETTINGS[name].default for name in DEFAULTS} == DEFAULTS
    assert set(ARGS) == ARGUMENTS
    assert len({s.env for s in TABLE}) == len(TABLE) and len(set(known_keys())) == len(known_keys())


def test_every_variable_has_the_one_prefix():
    assert {s.name: s.env for s in TABLE if s.name in ("DATABASE_URL", "RATING_MANIFEST", "RATINGS_PER_CLIP")} == {
        "DATABASE_URL": "RATING_DATABASE_URL",
        "RATING_MANIFEST": "RATING_MANIFEST",
        "RATINGS_PER_CLIP": "RATING_RATINGS_PER_CLIP",
    }
    assert all(s.env.startswith("RATING_") for s in TABLE)
    assert "database_url" in known_keys() and "rating_manifest" in known_keys()  # the study file's keys as before


def test_only_the_tables_variables_are_read():
    environ = {"RATING_PAIRING": "active", "RATING_PAIRINGS": "x", "RATING_TEST_PG": "postgresql://x", "HOME": "/h"}
    assert environment(environ=environ) == {"PAIRING": "active"}
    assert environment(environ={"DATABASE_URL": "", "RATING_MIN_VIEW": ""}) == {}  # empty: unset
    with pytest.raises(AppError, match="^DATABASE_URL is set, but the app reads RATING_DATABASE_URL now: rename"):
        environment(environ={"DATABASE_URL": "sqlite:///x.sqlite", "RATING_DATABASE_URL": "sqlite:///y.sqlite"})


def test_the_pool_size_is_bounded_where_the_engine_is_made():
    url = "postgresql://nobody@127.0.0.1:1/none"  # never connected to: the pool is made before any connection
    assert make_engine(url).pool.size() == SETTINGS["DB_POOL_SIZE"].default == 10
    assert make_engine(url, pool_size=3).pool.size() == 3
    for bad in (0, 1001, -1):
        with pytest.raises(AppError, match=f"pool_size: must be >= 1 and <= 1000, got '{bad}'"):
            make_engine(url, pool_size=bad)


def test_the_video_cache_is_a_setting(make_app, monkeypatch):
    """The bytes of videos a worker keeps come from RATING_VIDEO_CACHE_MB, read with the other settings (a bad value
    is one line: test_cli), not from the environment at import."""
    assert make_app().extensions["rating_app"]["videos"].cache_bytes == 512 * 2**20
    monkeypatch.setenv("RATING_VIDEO_CACHE_MB", "0")
    videos = make_app().extensions["rating_app"]["videos"]
    assert videos.cache_bytes == 0 and videos.cached == 0 and all(v.data is None for v in videos.videos.values())


def test_the_schema_is_whole_after_importing_only_the_store(tmp_path):
    """Every table is defined in store/db.py: init_db in a fresh process that imported nothing else of the app
    creates the tables the whole app knows."""
    code = (
        "import sys; from sqlalchemy import inspect; from rating_app.store import db; "
        "e = db.make_engine('sqlite:///' + sys.argv[1]); db.init_db(e); "
        "assert 'rating_app.store.rounds' not in sys.modules, 'rounds was imported'; "
        "print(' '.join(sorted(inspect(e).get_table_names())))"
    )
    db = str(tmp_path / "s.sqlite")
    r = subprocess.run([sys.executable, "-c", code, db], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    import rating_app.store.rounds  # noqa: F401  (here: the module that once held two of the tables)

    assert r.stdout.split() == sorted(Base.metadata.tables)
    assert {"study_conditions", "study_manifest"} <= set(r.stdout.split())


def test_the_help_shows_each_flags_variable_and_default():
    text = re.sub(r"\s+", " ", serve_parser().format_help())
    for s in TABLE:
        if s.flag:
            shown = f"default {s.default}; ${s.env})" if s.default is not None else f"(${s.env})"
            assert shown in text, (s.flag, shown)


def test_a_flag_not_given_leaves_the_variable_its_say(app_stimuli, app_db_url, monkeypatch):
    """The parser's defaults are the table's (for the help), but only the flags given reach create_app: the
    environment still overrides the default, and a flag overrides the environment."""
    monkeypatch.setenv("RATING_RATINGS_PER_CLIP", "7")
    monkeypatch.setenv("RATING_SLOT_TIMEOUT", "60")
    base = ["serve", "--manifest", str(app_stimuli), "--db", app_db_url]
    plain = build_parser().parse_args(base)
    assert plain.ratings_per_clip == 20 and set(plain.given) == {"manifest", "db_url"}
    flagged = build_parser().parse_args([*base, "--ratings-per-clip", "9"])
    assert flagged.given["ratings_per_clip"] == 9
    apps = [create_app(**a.given) for a in (plain, flagged)]
    try:
        assert [a.config["RATINGS_PER_CLIP"] for a in apps] == [7, 9]
        assert [a.config["SLOT_TIMEOUT_S"] for a in apps] == [60.0, 60.0]
        assert apps[0].config["CATCH_PER_RATER"] == 4 and apps[0].config["STUDY_DESIGN"] == "acr"  # defaults
    finally:
        for a in apps:
            app_engine(a).dispose()


def test_an_unknown_argument_is_refused():
    with pytest.raises(TypeError, match="unexpected keyword argument 'ratings_per_klip'"):
        create_app(manifest="x.csv", ratings_per_klip=3)


def test_the_docs_table_is_the_settings_table():
    text = (ROOT / "docs" / "hosting.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| `([A-Z_]+)` \| (?:`(--[a-z-]+)`)? \| (?:`([^`]*)`)? \|", text, flags=re.M)
    documented = {env: (flag or None, default or None) for env, flag, default in rows}
    expected = {s.env: (s.flag, None if s.default is None else str(s.default)) for s in TABLE}
    assert documented == expected
