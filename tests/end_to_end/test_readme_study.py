"""Issue 46: the README's "A study in five commands", read from the README (never copied here) and run as a newcomer
runs them, in a fresh folder: the app in one process, the other commands beside it. The crowd must fill the
study and the report must count every rater it brought.

The suite runs all five as written, the stimuli made by the README's first command (half a minute or more). The
one liberty taken: when port 5000, which the README's commands use, is busy on this machine (another test run), the
app gets a free port and the crowd's URL follows. (The commands also inherit the suite's one thread per BLAS and
OpenMP pool, tests/conftest.py, as every process the suite starts does: the checks below count raters and ratings,
which the threads do not change.)
"""

import csv
import json
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from helpers.paths import ROOT
from helpers.servers import wait_for

from moglow_eval.core.ports import free_port

SECTION = "## A study in five commands"


def readme_commands():
    """[(environment assignments, argv)] of the README section's code block, comments dropped."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert SECTION in text, f"README.md: no section {SECTION!r}"
    block = re.search(r"```bash\n(.*?)```", text.split(SECTION, 1)[1], re.S).group(1)
    commands = []
    for line in block.splitlines():
        words = shlex.split(line, comments=True)
        env = {}
        while words and re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S*", words[0]):
            name, value = words.pop(0).split("=", 1)
            env[name] = value
        if words:
            commands.append((env, words))
    return commands


def by_role(commands):
    """{"stimuli" | "serve" | "simulate" | "export" | "report": (env, argv)}, each found once, in that order."""
    roles = {
        "stimuli": ["python", "-m", "generation.make_stimuli"],
        "serve": ["python", "-m", "rating_app", "serve"],
        "simulate": ["python", "-m", "rating_app", "simulate"],
        "export": ["python", "-m", "rating_app", "export"],
        "report": ["python", "-m", "analysis.report"],
    }
    found = {}
    for role, start in roles.items():
        match = [c for c in commands if c[1][: len(start)] == start]
        assert len(match) == 1, f"README {SECTION}: expected one `{' '.join(start)}` command, found {len(match)}"
        found[role] = match[0]
    assert commands == list(found.values()), "README: the five commands, in the pipeline's order"
    return found


def flag(argv, name):
    return argv[argv.index(name) + 1] if name in argv else None


def port_free(port):
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def on_a_free_port(serve, simulate):
    """The serve and simulate argv, moved to a free port only if the README's is taken."""
    url = flag(simulate, "--url")
    port = int(re.fullmatch(r"http://127\.0\.0\.1:(\d+)/?", url).group(1))
    assert int(flag(serve, "--port") or 5000) == port, "README: the crowd's --url is not where the app serves"
    if port_free(port):
        return serve, simulate
    free = free_port()
    simulate = [f"http://127.0.0.1:{free}" if w == url else w for w in simulate]
    return [*serve, "--port", str(free)], simulate


def run(argv, env, cwd, timeout):
    """One README command as typed in a shell there: `python` is this interpreter, the checkout on the path."""
    return subprocess.run(
        [sys.executable, *argv[1:]], env=env, cwd=cwd, capture_output=True, text=True, timeout=timeout
    )


def study_in_five_commands(folder: Path):
    cmds = by_role(readme_commands())
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    env.pop("RATING_DATABASE_URL", None), env.pop("RATING_MANIFEST", None)  # a newcomer's shell sets neither
    stim_env, stim = cmds["stimuli"]
    r = run(stim, {**env, **stim_env}, folder, 900)
    assert r.returncode == 0, r.stderr[-3000:]
    serve_env, serve = cmds["serve"]
    sim_env, simulate = cmds["simulate"]
    serve, simulate = on_a_free_port(serve, simulate)
    url = flag(simulate, "--url")
    log = open(folder / "server.log", "w")
    server = subprocess.Popen(
        [sys.executable, *serve[1:]],
        env={**env, **serve_env},
        cwd=folder,
        stdout=log,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )
    try:
        wait_for(f"{url}/healthz", server, "the README's serve command")
        crowd = run(simulate, {**env, **sim_env}, folder, 600)
        assert crowd.returncode == 0, crowd.stderr[-3000:]
        exp_env, export = cmds["export"]
        r = run(export, {**env, **exp_env}, folder, 120)
        assert r.returncode == 0, r.stderr
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        server.wait(20)
        log.close()
    rep_env, report = cmds["report"]
    r = run(report, {**env, **rep_env}, folder, 600)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(crowd.stdout), flag(export, "--out"), flag(report, "--out"), r.stdout


def check_the_study(folder, summary, ratings, report, console):
    assert summary["study_full"] is True and summary["n_raters_refused"] == 0, summary
    assert summary["errors"] == [] and not summary["timed_out"], summary
    with open(folder / ratings, newline="") as fh:
        rows = list(csv.DictReader(fh))
    raters = {r["rater_id"] for r in rows}
    stats = json.loads((folder / report / "stats.json").read_text())
    assert summary["n_ratings"] == len(rows) == stats["n_ratings_total"]
    # every rater the crowd started is in the export and counted by the report (the app's export names the
    # study's target, and a full study reaches it: the report has nothing to warn of)
    assert len(raters) == summary["n_raters_started"] == stats["n_raters_total"]
    assert "did not fill" not in console and "fewer than the" not in console
    assert (folder / report / "report.html").is_file()


def test_the_readme_names_five_commands_that_parse():
    """What the runs below rely on, checked on its own: five commands, one per stage, each parsed by its parser."""
    cmds = by_role(readme_commands())
    from analysis.report import build_parser as report_parser
    from rating_app.__main__ import build_parser as app_parser

    serve = app_parser().parse_args(cmds["serve"][1][3:])
    # a local trial with the simulated crowd: one address, so no per-address limit, and a short viewing rule;
    # the production defaults (10 sessions an hour per address, the whole clip) stay as they are
    assert serve.sessions_per_client == 0 and serve.min_view < 1
    assert "RATING_ADMIN_TOKEN" in cmds["serve"][0]
    simulate = app_parser().parse_args(cmds["simulate"][1][3:])
    assert simulate.manifest == serve.manifest
    export = app_parser().parse_args(cmds["export"][1][3:])
    assert report_parser().parse_args(cmds["report"][1][3:]).ratings == export.out


@pytest.mark.full  # the README's own study, its five commands as written
def test_the_readmes_five_commands_as_written(tmp_path):
    summary, ratings, report, console = study_in_five_commands(tmp_path)
    check_the_study(tmp_path, summary, ratings, report, console)
