"""Issue 46: `python -m rating_app simulate` says, in one line and with a non-zero exit, when its crowd fell short of
what was asked (raters refused, the study not filled, the time limit passed) and when no server answers."""

import contextlib
import json
import subprocess
import sys

import pytest
from helpers.paths import ROOT

from moglow_eval.core.ports import free_port
from rating_app import create_app

pytestmark = pytest.mark.full  # the full tier: served apps and crowds that fall short


def simulate(*args, timeout=120):
    return subprocess.run(
        [sys.executable, "-m", "rating_app", "simulate", "--quiet", *map(str, args)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@contextlib.contextmanager
def served(stimuli, db, **settings):
    """The app on a real threaded HTTP server on a free port, with `settings`; yields its URL."""
    from helpers.servers import in_thread

    with in_thread(create_app(manifest=stimuli, db_url=db, admin_token="t", **settings)) as url:
        yield url


def one_error_line(r):
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr
    assert lines and lines[-1].startswith("error: "), r.stderr
    return lines[-1]


def test_refused_raters_end_in_one_line_naming_the_setting(app_stimuli, tmp_path):
    db = f"sqlite:///{tmp_path}/r.sqlite"
    with served(app_stimuli, db, ratings_per_clip=50, min_view=0, sessions_per_client=2) as url:
        r = simulate("--url", url, "--raters", 5, "--manifest", app_stimuli, "--concurrency", 1)
    line = one_error_line(r)
    assert "3 of 5 raters refused with 429 after 2 started" in line and "--sessions-per-client" in line, line
    summary = json.loads(r.stdout)  # the summary is still written before the line
    assert summary["n_raters_refused"] == 3 and summary["n_raters_started"] == 2


def test_a_study_left_unfilled_is_a_failure_and_its_report_says_so(app_stimuli, tmp_path):
    db = f"sqlite:///{tmp_path}/r.sqlite"
    with served(app_stimuli, db, ratings_per_clip=50, min_view=0, sessions_per_client=0) as url:
        r = simulate("--url", url, "--raters", 2, "--careless", 0, "--manifest", app_stimuli)
    line = one_error_line(r)
    assert "the study did not fill: all 2 raters took part" in line and "--raters" in line, line
    # The export says how many raters the study needs (every clip 50 times, each rater all of them: 50), and the
    # report notes, in its summary, its page and stats.json, that two raters are far fewer.
    ratings, report = tmp_path / "ratings.csv", tmp_path / "report"
    r = subprocess.run(
        [sys.executable, "-m", "rating_app", "export", "--db", db, "--out", ratings], capture_output=True, cwd=ROOT
    )
    assert r.returncode == 0, r.stderr
    assert ratings.read_text().splitlines()[1].endswith(",50")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "analysis.report",
            ratings,
            "--out",
            report,
            "--quiet",
            "--no-ordinal",
            "--n-boot",
            "50",
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 0, r.stderr
    note = "ratings from 2 raters, fewer than the 50 this study needs to fill"
    stats = json.loads((report / "stats.json").read_text())
    assert stats["target_raters"] == 50 and note in stats["notes"][0]
    assert note in (report / "report.html").read_text()
    r = subprocess.run(
        [sys.executable, "-m", "analysis.report", ratings, "--out", report, "--no-ordinal", "--n-boot", "50"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 0 and note in r.stdout, r.stdout


def test_the_time_limit_is_a_failure_that_names_min_view(app_stimuli, tmp_path):
    db = f"sqlite:///{tmp_path}/r.sqlite"
    # The whole clip must play before an answer (the production default), and each rater thinks a minute on
    # average before answering: two seconds are far too little, and the crowd stops at them, not a minute later.
    with served(app_stimuli, db, ratings_per_clip=50, min_view=1, sessions_per_client=0) as url:
        r = simulate("--url", url, "--raters", 2, "--manifest", app_stimuli, "--timeout", 2, "--think", 60, timeout=40)
    line = one_error_line(r)
    assert "the time limit passed (--timeout 2 s)" in line and "--min-view" in line and "is 1," in line, line
    assert json.loads(r.stdout)["timed_out"] is True


def test_a_time_limit_before_any_session_still_names_the_apps_min_view(app_stimuli, tmp_path):
    """The app's --min-view comes from /healthz, which the crowd reads before any rater starts: a limit that passes
    before the first session reply (a loaded machine, a slow server) still names it."""
    db = f"sqlite:///{tmp_path}/r.sqlite"
    with served(app_stimuli, db, min_view=0.75, sessions_per_client=0) as url:
        r = simulate("--url", url, "--raters", 2, "--manifest", app_stimuli, "--timeout", 0.001, timeout=40)
    line = one_error_line(r)
    assert "with 0 of 2 raters done" in line and "the app's is 0.75," in line, line
    summary = json.loads(r.stdout)
    assert summary["timed_out"] is True and summary["n_raters_started"] == 0


def test_a_full_study_is_a_success(app_stimuli, tmp_path):
    db = f"sqlite:///{tmp_path}/r.sqlite"
    with served(app_stimuli, db, ratings_per_clip=2, min_view=0, sessions_per_client=0) as url:
        r = simulate("--url", url, "--raters", 4, "--manifest", app_stimuli, "--concurrency", 1)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["study_full"] is True


@pytest.mark.parametrize("design", [None, "acr"])
def test_no_server_is_said_within_seconds_not_at_the_time_limit(app_stimuli, design):
    url = f"http://127.0.0.1:{free_port()}"
    extra = ["--design", design] if design else []
    # --timeout is the default 600 s; the subprocess's own limit fails the test long before that.
    r = simulate("--url", url, "--raters", 3, "--manifest", app_stimuli, *extra, timeout=60)
    line = one_error_line(r)
    assert f"{url}: no rating app answers" in line and "rating_app serve" in line, line
    assert r.stdout == ""  # nothing ran, so there is no summary


def test_a_summary_that_cannot_be_written_stops_the_crowd_before_it_answers(app_stimuli, tmp_path):
    import requests

    db = f"sqlite:///{tmp_path}/r.sqlite"
    with served(app_stimuli, db, ratings_per_clip=50, min_view=0, sessions_per_client=0) as url:
        r = simulate("--url", url, "--raters", 2, "--manifest", app_stimuli, "--summary", tmp_path)
        progress = requests.get(f"{url}/admin/progress.json", headers={"Authorization": "Bearer t"}, timeout=30)
    assert "--summary" in one_error_line(r)
    assert progress.json()["raters"] == []  # no rater started: nothing was written to the study first
