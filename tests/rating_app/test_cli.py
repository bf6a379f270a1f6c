"""`python -m rating_app serve | export | simulate`, the manifest reader and the simulated crowd's model."""

import collections
import csv
import json
import os
import subprocess
import sys

import numpy as np
import pytest
import requests
from helpers.paths import ROOT
from helpers.servers import in_thread, wait_for

from moglow_eval.core.ports import free_port
from moglow_eval.core.tables import read_metrics
from rating_app import create_app
from rating_app.simulate.raters import ClipInfo, load_clips, parse_quality, quality_from_metrics
from rating_app.store.manifest import AppError, load_manifest


def cli(*args, timeout=120, **kw):
    return subprocess.run(
        [sys.executable, "-m", "rating_app", *map(str, args)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
        **kw,
    )


@pytest.fixture
def live(app_stimuli, app_db_url):
    # The crowd waits as the server requires: 10% of each clip here, so that the test stays short.
    app = create_app(
        manifest=app_stimuli,
        db_url=app_db_url,
        admin_token="cli-token",
        ratings_per_clip=6,
        min_view=0.1,
        sessions_per_client=0,
    )
    with in_thread(app) as url:
        yield url, app_db_url


@pytest.mark.full  # the full tier: a crowd against a served app
@pytest.mark.parametrize("app_db_url", ["postgres"], indirect=True)  # the database is the app's concern, not the CLI's
def test_simulated_crowd_matches_export(live, app_stimuli, tmp_path):
    url, db = live
    out = tmp_path / "summary.json"
    r = cli(
        "simulate",
        "--url",
        url,
        "--raters",
        8,
        "--seed",
        1,
        "--careless",
        0.5,
        "--manifest",
        app_stimuli,
        "--summary",
        out,
        "--quiet",
        "--concurrency",
        1,
    )
    assert r.returncode == 0, r.stderr
    s = json.loads(out.read_text())
    assert s["errors"] == [] and s["n_raters_completed"] == 6 and s["study_full"] is True  # target 6, all clips
    assert len(s["careless_raters"]) >= 1
    # export through the CLI, compare with what the crowd says it submitted
    csv_path = tmp_path / "ratings.csv"
    r = cli("export", "--db", db, "--out", csv_path)
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(csv_path.open()))
    assert collections.Counter((x["rater_id"], x["clip_id"], int(x["rating"])) for x in rows) == collections.Counter(
        (x["rater_id"], x["clip_id"], x["rating"]) for x in s["ratings"]
    )
    per_rater = collections.Counter(x["rater_id"] for x in rows)
    assert per_rater == {x["rater_id"]: x["n_ratings"] for x in s["raters"] if x["started"]}
    failed = {x["rater_id"] for x in rows if x["role"] == "catch" and int(x["rating"]) >= 3}
    assert failed == set(s["failed_catch_raters"])
    assert failed <= set(s["careless_raters"])  # attentive raters never fail a catch trial
    attentive = [x for x in rows if x["rater_id"] not in s["careless_raters"]]
    mean = {
        c: sum(int(x["rating"]) for x in attentive if x["condition"] == c)
        / max(1, sum(x["condition"] == c for x in attentive))
        for c in ("NAT", "MG", "FL", "BAD")
    }
    # NAT has the best metrics, BAD the worst (finer orderings: test_quality_follows_the_metrics)
    assert mean["NAT"] > mean["MG"] and mean["NAT"] > mean["FL"] and mean["NAT"] > mean["BAD"] + 1
    # the study is full now: another crowd is told so and submits nothing
    r = cli("simulate", "--url", url, "--raters", 2, "--seed", 2, "--manifest", app_stimuli, "--quiet")
    assert r.returncode == 0 and json.loads(r.stdout)["study_full"] is True
    assert json.loads(r.stdout)["n_ratings"] == 0


def test_simulate_arg_errors(app_stimuli, tmp_path, command_fails):
    """The crowd's bad flags, each refused before it reaches the URL (nothing answers there)."""
    url = "http://127.0.0.1:9"
    bad_metrics = tmp_path / "stimuli"
    bad_metrics.mkdir()
    (bad_metrics / "manifest.csv").write_text(app_stimuli.read_text())
    (bad_metrics / "metrics.csv").write_text("clip_id,jerk\nabcdefabcdef12,fast\n")
    for args, needle in (
        (("--raters", 0, "--manifest", app_stimuli), "--raters"),
        (("--raters", 2, "--careless", 1.5, "--manifest", app_stimuli), "--careless"),
        (("--raters", 2, "--quality", "NAT=9", "--manifest", app_stimuli), "--quality"),
        (("--raters", 2), "--manifest"),  # the crowd learns the clips' conditions from the manifest only
        (("--raters", 2, "--manifest", tmp_path / "none.csv"), "none.csv"),
        (("--raters", 2, "--manifest", bad_metrics / "manifest.csv"), "metrics.csv:2: jerk 'fast' is not a number"),
    ):
        command_fails("simulate", "--url", url, *args, needle=needle)
    # an address that is none (it was tried for 5 s), and ids the app would refuse for every rater
    for url_, args, needle in (
        ("127.0.0.1:5000", (), "--url: expected the app's address, http://HOST:PORT or https://HOST"),
        ("ftp://127.0.0.1", (), "--url: expected the app's address"),
        (url, ("--prefix", "lab/run1"), "--prefix: expected 1-120 letters, digits and _.:@-"),
        (url, ("--prefix", "x" * 121), "--prefix: expected 1-120"),
    ):
        command_fails("simulate", "--url", url_, "--raters", 2, "--manifest", app_stimuli, *args, needle=needle)


def test_export_cli_errors(tmp_path):
    r = cli("export", "--db", f"sqlite:///{tmp_path}/missing.sqlite", "--out", tmp_path / "x.csv")
    assert r.returncode == 2 and r.stderr.startswith("error:") and "missing.sqlite" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    r = cli("export", "--db", "postgresql://postgres@127.0.0.1:5432/no_such_db_here", "--out", tmp_path / "x.csv")
    assert r.returncode == 2 and r.stderr.startswith("error:") and "Traceback" not in r.stderr
    for command in (("export",), ("serve", "--manifest", tmp_path / "m.csv")):  # "$DATABASE_URL", unset
        r = cli(*command, "--db", "")
        assert r.returncode == 2 and "argument --db: empty; give a value, or leave" in r.stderr, r.stderr
    r = cli("export", "--db", "sqlite://", "--out", tmp_path / "x.csv")  # in memory: no study to export
    assert (
        r.returncode == 2
        and r.stderr == "error: --db: an SQLite database in a file is needed (sqlite:///FILE), not one in memory\n"
    )
    # the --out before the database: "" (a traceback) or a folder (its hidden temporary file was named)
    db = tmp_path / "study.sqlite"
    db.write_bytes(b"")  # the study's own file as --out: its export would have replaced it
    for out, says in (
        ("", "error: python -m rating_app export: argument --out: empty"),
        (tmp_path, f"error: --out {tmp_path}: a folder"),
        (db, f"error: --out {db}: is the file --db names"),
    ):
        r = cli("export", "--db", f"sqlite:///{db}", "--out", out)
        assert r.returncode == 2 and r.stderr.startswith(says) and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_serve_cli(app_stimuli, tmp_path):
    r = cli("serve", "--manifest", tmp_path / "nope.csv")
    assert r.returncode == 2 and "nope.csv" in r.stderr and "Traceback" not in r.stderr
    port = free_port()
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "rating_app",
            "serve",
            "--manifest",
            str(app_stimuli),
            "--db",
            f"sqlite:///{tmp_path}/r.sqlite",
            "--port",
            str(port),
        ],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        wait_for(f"http://127.0.0.1:{port}/healthz", proc, "rating_app serve")
        r = requests.post(f"http://127.0.0.1:{port}/api/sessions", json={}, timeout=5)
        assert r.status_code == 201 and r.json()["n_trials"] == 17
    finally:
        proc.terminate()
        proc.wait(10)
    journal = (tmp_path / "r.sqlite-wal").exists() or (tmp_path / "r.sqlite").exists()
    assert journal


@pytest.mark.parametrize(
    "edit,needle",
    [
        (lambda rows: rows[1].__setitem__("clip_id", "NAT_clip_1"), ":3: clip_id"),
        (lambda rows: rows[2].__setitem__("clip_id", rows[1]["clip_id"]), ":4: duplicate clip_id"),
        (lambda rows: rows[1].__setitem__("role", "bonus"), ":3: role"),
        (lambda rows: rows[1].__setitem__("condition", "MG\x1b[2J"), ":3: condition must be 1-64 printable"),
        (lambda rows: rows[1].__setitem__("video", "videos/none.mp4"), ":3: video"),
        (lambda rows: rows[1].__setitem__("fps", "fast"), ":3: field 'fps'"),
        (lambda rows: rows[1].__setitem__("fps", "-20"), ":3: field 'fps' must be above 0"),  # the viewing rule's
        (lambda rows: rows[2].__setitem__("frames", "0"), ":4: field 'frames' must be above 0"),
        (lambda rows: [r.pop("condition") for r in rows], ":1: missing column(s) condition"),
    ],
)
def test_manifest_errors_name_file_and_line(app_stimuli, tmp_path, edit, needle):
    rows = list(csv.DictReader(open(app_stimuli, encoding="utf-8")))
    edit(rows)
    bad = app_stimuli.parent / f"bad_{tmp_path.name}.csv"
    try:
        with open(bad, "w", newline="", encoding="utf-8") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
        with pytest.raises(AppError) as e:
            load_manifest(bad)
        assert str(bad) in str(e.value) and needle in str(e.value)
    finally:
        bad.unlink()


def test_quality_follows_the_metrics(app_stimuli):
    clips = load_clips(app_stimuli)
    q = quality_from_metrics(clips)
    assert q["NAT"] > q["MG"] > q["FL"] > q["BAD"]
    assert q["NAT"] == pytest.approx(4.3) and q["BAD"] == pytest.approx(1.3)
    # metrics decide: if the 'MG' clips had FL's metrics (farther from the reference's) they would be below FL
    flipped = {
        k: ClipInfo(k, {"MG": "FL", "FL": "MG"}.get(c.condition, c.condition), c.role, metrics=c.metrics)
        for k, c in clips.items()
    }
    q2 = quality_from_metrics(flipped)
    assert q2["NAT"] > q2["FL"] > q2["MG"] > q2["BAD"]
    assert parse_quality("NAT=4.5, MG=3") == {"NAT": 4.5, "MG": 3.0}
    for bad in ("NAT", "NAT=x", "=3", "NAT=0.5"):
        with pytest.raises(AppError):
            parse_quality(bad)


def test_a_smoothed_system_is_rated_below_the_reference_not_above_it():
    """The simulated crowd scores a system by how far its motion statistics are from the reference's: a system
    whose jerk and acceleration are a tenth of the real motion's (heavily smoothed) is not better than it."""
    from rating_app.simulate.raters import make_raters

    rng = np.random.default_rng(0)
    clips = {}
    for i in range(12):
        for cond, jerk, acc in (("NAT", 30.0, 6.0), ("SMOOTH", 3.0, 0.6), ("SYS", 36.0, 7.0)):
            cid = f"{cond.lower()}{i:02d}"
            m = {"foot_skating": 0.05, "bone_length_std": 0.0, "jerk": jerk, "acceleration": acc}
            clips[cid] = ClipInfo(cid, cond, "test", metrics={k: v * rng.uniform(0.9, 1.1) for k, v in m.items()})
    q = quality_from_metrics(clips)
    assert q["NAT"] > q["SYS"] > q["SMOOTH"]
    raters = [r for r in make_raters(40, seed=1, careless=0.0, prefix="sim") if not r.careless]
    mean = {
        cond: np.mean([r.rate(c)[0] for r in raters for c in clips.values() if c.condition == cond])
        for cond in ("NAT", "SMOOTH")
    }
    assert mean["SMOOTH"] < mean["NAT"] - 1


def test_unmeasured_metrics_are_skipped(app_stimuli, tmp_path):
    """A metric that could not be measured ('nan' or empty, e.g. foot skating without contacts) is missing for
    that clip, not an error, and the quality still follows the metrics that were measured."""
    folder = tmp_path / "stimuli"
    folder.mkdir()
    (folder / "manifest.csv").write_text(app_stimuli.read_text())
    text = app_stimuli.with_name("metrics.csv").read_text().splitlines()
    head, first, second = text[0].split(","), text[1].split(","), text[2].split(",")
    first[head.index("foot_skating")] = "nan"
    second[head.index("jerk")] = ""
    (folder / "metrics.csv").write_text("\n".join([text[0], ",".join(first), ",".join(second)] + text[3:]) + "\n")
    table = read_metrics(folder / "metrics.csv")
    assert np.isnan(table.at[first[0], "foot_skating"]) and table.at[first[0], "jerk"] > 0
    assert np.isnan(table.at[second[0], "jerk"]) and table.at[second[0], "foot_skating"] > 0
    clips = load_clips(folder / "manifest.csv")
    assert np.isnan(clips[first[0]].metrics["foot_skating"]) and clips[first[0]].metrics["jerk"] > 0
    q = quality_from_metrics(clips)
    assert q["NAT"] > q["MG"] > q["FL"] > q["BAD"]


@pytest.mark.parametrize(
    "db,needle",
    [
        ("notaurl", "not a database URL"),
        ("mysql://u@127.0.0.1/x", "unsupported database 'mysql'"),
        ("TEXTFILE", "not an SQLite database"),
        ("postgresql://postgres@127.0.0.1:1/test", "cannot"),
    ],
)
def test_bad_database_is_one_line(app_stimuli, tmp_path, db, needle, command_fails):
    if db == "TEXTFILE":
        (tmp_path / "notes.txt").write_text("not a database\n")
        db = f"sqlite:///{tmp_path / 'notes.txt'}"
    command_fails("serve", "--manifest", app_stimuli, "--db", db, "--port", free_port(), needle=needle)
    command_fails("export", "--db", db, "--out", tmp_path / "x.csv", needle=needle)


def test_an_empty_database_file_is_refused_and_left_empty(app_stimuli, tmp_path, command_fails):
    """A command that reads a study, given an empty file (a `touch`ed name, a failed copy), says so and leaves it
    empty: opening it as SQLite wrote a database header into the user's file before the refusal."""
    empty = tmp_path / "ratings.sqlite"
    empty.touch()
    db = f"sqlite:///{empty}"
    needle = f"{empty}: an empty file, not a rating app database"
    command_fails("export", "--db", db, "--out", tmp_path / "x.csv", needle=needle)
    command_fails("backup", "--db", db, "--out", tmp_path / "copy.sqlite", needle=needle)
    command_fails("add-condition", "--db", db, "--manifest", app_stimuli, needle=needle)
    assert empty.stat().st_size == 0
    assert not (tmp_path / "x.csv").exists() and not (tmp_path / "copy.sqlite").exists()


@pytest.mark.parametrize(
    "args,env,needle",
    [
        (("--slot-timeout", "-5"), {}, "--slot-timeout"),
        (("--port", "99999"), {}, "--port"),
        (("--min-view", "2"), {}, "--min-view"),
        ((), {"RATING_SLOT_TIMEOUT": "nan"}, "RATING_SLOT_TIMEOUT"),
        ((), {"RATING_RATINGS_PER_CLIP": "0"}, "RATING_RATINGS_PER_CLIP"),
        (("--catch-per-rater", "-1"), {}, "--catch-per-rater"),
        ((), {"RATING_CATCH_PER_RATER": "two"}, "RATING_CATCH_PER_RATER"),
        ((), {"RATING_VIDEO_CACHE_MB": "lots"}, "RATING_VIDEO_CACHE_MB: expected an integer"),
        ((), {"RATING_VIDEO_CACHE_MB": "-1"}, "RATING_VIDEO_CACHE_MB"),
        ((), {"RATING_DB_POOL_SIZE": "0"}, "RATING_DB_POOL_SIZE"),
        # A variable from before the prefix is refused with its new name, not dropped (nor obeyed).
        ((), {"PAIRING": "active"}, "PAIRING is set, but the app reads RATING_PAIRING now"),
    ],
)
def test_bad_settings_stop_the_start(app_stimuli, tmp_path, args, env, needle, command_fails, monkeypatch):
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    command_fails("serve", "--manifest", app_stimuli, "--db", f"sqlite:///{tmp_path}/r.sqlite", *args, needle=needle)


@pytest.mark.parametrize(
    "env,needle,preload",
    [
        ({"RATING_MANIFEST": ""}, "no stimulus manifest", False),
        ({"RATING_SLOT_TIMEOUT": "nan"}, "RATING_SLOT_TIMEOUT", False),
        (
            {"ADMIN_TOKEN": "x", "SECRET_KEY": "y"},
            "ADMIN_TOKEN, SECRET_KEY are set, but the app reads RATING_ADMIN_TOKEN",
            False,
        ),
        ({"RATING_SLOT_TIMEOUT": "nan"}, "RATING_SLOT_TIMEOUT", True),  # the master builds the app (docs/hosting.md)
    ],
)
def test_gunicorn_with_a_bad_environment_stops(app_stimuli, tmp_path, env, needle, preload):
    base = dict(os.environ, RATING_MANIFEST=str(app_stimuli), RATING_DATABASE_URL=f"sqlite:///{tmp_path}/r.sqlite")
    # Without --preload, one worker: with two, gunicorn halting on the first one's load error may interrupt the
    # second one's import, and that interrupted import's traceback is gunicorn's shutdown, not our error line. With
    # it, the master builds the app before any worker starts: four workers, as the docs start it.
    workers = ["-w", "4", "--preload"] if preload else ["-w", "1"]
    r = subprocess.run(
        [sys.executable, "-m", "gunicorn", *workers, "-b", f"127.0.0.1:{free_port()}", "rating_app.wsgi:app"],
        cwd=ROOT,
        env=dict(base, **env),
        capture_output=True,
        text=True,
        timeout=60,
    )  # respawning forever would run into the timeout
    assert r.returncode != 0 and f"error: {needle}" in r.stderr and needle in r.stderr
    assert "Traceback" not in r.stderr
    if preload:  # the master stops with gunicorn's "app failed to load" code, and our line is all it says
        assert r.returncode == 4 and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_a_stale_database_variable_is_refused_by_the_commands_that_default_to_it(tmp_path, command_fails, monkeypatch):
    """export, backup and the rounds' commands take RATING_DATABASE_URL for want of --db: an old DATABASE_URL stops
    them with one line naming the new variable, instead of their reading the default SQLite file."""
    monkeypatch.delenv("RATING_DATABASE_URL", raising=False)
    monkeypatch.setenv("DATABASE_URL", f"sqlite:///{tmp_path / 'study.sqlite'}")
    for args in (("export", "--out", tmp_path / "x.csv"), ("withdraw-condition", "--condition", "MG")):
        command_fails(*args, needle="DATABASE_URL is set, but the app reads RATING_DATABASE_URL now")


def test_an_app_worker_starts_without_scipy_pandas_or_torch():
    """A gunicorn worker imports the app (rating_app.wsgi's create_app): scipy, pandas and torch stay out of it,
    each a fraction of a second more for every worker's start. Active pairing loads scipy when it first fits."""
    r = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys, rating_app; print(sorted({'scipy', 'pandas', 'torch'} & set(sys.modules)))",
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 0 and r.stdout.strip() == "[]", r.stdout + r.stderr[-500:]
