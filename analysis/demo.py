"""A whole study in one command (MoGlow §5.4–5.5, simulated crowd):

    make_stimuli --quick  →  rating_app serve  →  rating_app simulate (until every test clip has its
    target ratings)  →  /admin/export.csv  →  analysis.report

Every stage is a real process talking through the files and HTTP API of CONTRACTS.md, exactly as a
researcher would run them by hand. Everything started here is stopped at the end, also on Ctrl-C or error.

    python -m analysis.demo [--out demo/] [--db postgresql://127.0.0.1:5432/test] [--raters 60]
                            [--design acr|pairwise|parallel|appropriateness|dyadic|semantic] [--sound]

With another --design the app runs that test design (CONTRACTS §8), the crowd answers it, the export is pairs.csv
(pairwise and the three matched-against-mismatched designs) or the parallel ratings.csv, and the report is that
design's. With --sound (implied by appropriateness) the stimuli are a study of your own motion with speech
(generation.own_study.demo_study: real non-locomotion mocap, two made-up systems, speech synthesised by espeak-ng), the
videos carry it, and every simulated rater passes the sound check first. With dyadic or semantic they are a study of
two people talking (generation.own_study.demo_dyad: two real takes an item, a voice for each, captions; semantic
highlights the answer's keyword).

Each run replaces what an earlier one left in --out (its database would refuse another design, and make_stimuli an
existing set), so the designs can be tried one after the other in the default folder; a folder the demo did not
make (no demo.json in it) is refused, never emptied. --stimuli keeps a set (an earlier run's demo/stimuli too).
"""

from __future__ import annotations

import argparse
import json
import os
import secrets
import shutil
import signal
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

from moglow_eval.core import cli, study
from moglow_eval.core.ports import free_port
from moglow_eval.core.study import DESIGNS


class DemoError(cli.UserError):
    """A stage failed; the message says which and where its log is."""


def _stage(title: str):
    print(f"\n== {title}", flush=True)


class Processes:
    """Children in their own process groups, so that stopping one stops everything it started
    (make_stimuli's render pool, gunicorn's workers)."""

    def __init__(self):
        self.running: list[subprocess.Popen] = []

    def start(self, cmd, **kw) -> subprocess.Popen:
        p = subprocess.Popen(cmd, start_new_session=True, **kw)
        self.running.append(p)
        return p

    def run(self, cmd, what: str, log: Path | None = None, env=None) -> None:
        out = open(log, "w") if log else None
        try:
            p = self.start(cmd, stdout=out, stderr=subprocess.STDOUT if out else None, env=env)
            rc = p.wait()
        finally:
            if out:
                out.close()
        self.running.remove(p)
        if rc != 0:
            where = f"; log: {log}" if log else ""
            raise DemoError(f"{what} failed (exit {rc}){where}")

    def stop_all(self, grace_s: float = 10.0) -> None:
        for p in self.running:
            if p.poll() is None:
                _signal_group(p, signal.SIGTERM)
        deadline = time.monotonic() + grace_s
        for p in self.running:
            try:
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                _signal_group(p, signal.SIGKILL)
                p.wait()
        # Workers that outlive their parent are still in its group: sweep it once more.
        for p in self.running:
            _signal_group(p, signal.SIGKILL)
        self.running.clear()


def _signal_group(p: subprocess.Popen, sig) -> None:
    try:
        os.killpg(p.pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def _wait_until_up(url: str, server: subprocess.Popen, log: Path, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if server.poll() is not None:
            raise DemoError(f"the rating app exited (code {server.returncode}){_last_error(log)}; log: {log}")
        try:
            with urllib.request.urlopen(url, timeout=2) as r:
                if r.status == 200:
                    return
        except (urllib.error.URLError, ConnectionError, OSError):
            pass
        time.sleep(0.3)
    raise DemoError(f"the rating app did not answer at {url} within {timeout_s:.0f} s; log: {log}")


def _last_error(log: Path) -> str:
    """': ' and the app's own error line (e.g. a database that holds another design's study), or ''."""
    lines = [x for x in log.read_text(errors="replace").splitlines() if x.startswith("error: ")]
    return f": {lines[-1][len('error: ') :]}" if lines else ""


def _export(url: str, token: str, folder: Path) -> Path:
    """The app's export, saved in `folder` under the name the app gives it (ratings.csv or pairs.csv: the design
    decides, CONTRACTS §8); returns its path."""
    req = urllib.request.Request(f"{url}/admin/export.csv", headers={"Authorization": f"Bearer {token}"})
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            name = Path(r.headers.get_filename() or "ratings.csv").name
            out = folder / name
            out.write_bytes(r.read())
    except urllib.error.URLError as e:
        raise DemoError(f"export from {url}/admin/export.csv failed: {e}") from None
    return out


MARK = "demo.json"  # written first by every run: what tells a demo's folder from anyone else's
# What a run writes into --out beside its stimuli; a new run replaces them (the database would refuse another design,
# make_stimuli an existing set), so each design can be demonstrated after another in the default folder.
RUN_OUTPUTS = ("logs", "report", "ratings.csv", "pairs.csv", "crowd_summary.json", MARK)
STIMULI_OUTPUTS = ("stimuli", "study")  # made anew unless --stimuli is given (runs/ keeps the tiny models: reused)
DB_NAME = "ratings.sqlite"
# The app's variable of each serve setting: RATING_ and its name in upper case, or this (rating_app/store/settings.py).
ENV_NAMES = {"design": "RATING_STUDY_DESIGN"}


def clear_earlier_run(out: Path, new_stimuli: bool) -> None:
    """Remove what an earlier demo run left in `out`; DemoError when `out` holds files the demo did not make (it
    writes MARK first), rather than deleting anyone's work."""
    if not out.is_dir() or not any(out.iterdir()):
        return
    if not (out / MARK).is_file():
        raise DemoError(f"--out {out}: holds files the demo did not make (no {MARK}); give another --out")
    names = RUN_OUTPUTS + (STIMULI_OUTPUTS if new_stimuli else ())
    for path in [out / n for n in names] + sorted(out.glob(DB_NAME + "*")):
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()


def speech_items(design: str) -> tuple[tuple[int, int], str]:
    """The bounds of --items for the study with speech the demo makes for `design`, and who talks in it."""
    if design in study.TWO_PERSON_DEMO_DESIGNS:
        return study.TWO_PERSON_DEMO_ITEMS, "two people talking"
    return study.SPEECH_DEMO_ITEMS, "one person talking"


def make_stimuli(procs: "Processes", out: Path, s: dict) -> Path:
    """Stage 1: a stimulus set in out/stimuli, a study of speech and motion with `sound`, else make_stimuli
    --quick (its tiny models in `runs`, default out/runs, trained once and reused by later runs)."""
    seed, design, sound = s["seed"], s["design"], s["sound"]
    py, stimuli = sys.executable, out / "stimuli"
    if design in study.TWO_PERSON_DEMO_DESIGNS:
        _stage(f"1/5 a study of two people talking (generation.own_study.demo_dyad) → {stimuli}")
        cmd = ["--out", str(out / "study"), "--seed", str(seed), "--design", design]
        cmd += ["--items", str(s["items"])] if s["items"] else []
        procs.run([py, "-m", "generation.own_study.demo_dyad", *cmd], "generation.own_study.demo_dyad")
        cmd = ["--study", str(out / "study" / "study.toml")]
    elif sound:
        _stage(f"1/5 a study with sound (generation.own_study.demo_study) → {stimuli}")
        procs.run(
            [py, "-m", "generation.own_study.demo_study", "--out", str(out / "study"), "--seed", str(seed)]
            + (["--appropriateness"] if design == "appropriateness" else [])
            + (["--items", str(s["items"])] if s["items"] else []),
            "generation.own_study.demo_study",
        )
        cmd = ["--study", str(out / "study" / "study.toml")]
    else:
        _stage(f"1/5 make stimuli (--quick) → {stimuli}")
        cmd = ["--quick", "--runs", str(s["runs"] or out / "runs"), "--seed", str(seed)]
        cmd += ["--n-items", str(s["items"])] if s["items"] else []
    cmd += ["--size", str(s["size"])]
    procs.run([py, "-m", "generation.make_stimuli", *cmd, "--out", str(stimuli), "--force"], "make_stimuli")
    return stimuli


def serve_command(manifest: Path, db: str, port: int, opts: dict, gunicorn: bool, env: dict) -> list[str]:
    """The app's command line (or gunicorn's, with the settings in `env`) for the settings `opts`."""
    py = sys.executable
    if gunicorn:
        env.update(RATING_MANIFEST=str(manifest), RATING_DATABASE_URL=db)
        env.update({ENV_NAMES.get(k, "RATING_" + k.upper()): str(v) for k, v in opts.items()})
        return [py, "-m", "gunicorn", "-w", "2", "--threads", "4", "-b", f"127.0.0.1:{port}", "rating_app.wsgi:app"]
    flags = [x for k, v in opts.items() for x in (f"--{k.replace('_', '-')}", str(v))]
    return [py, "-m", "rating_app", "serve", "--manifest", str(manifest), "--db", db, "--port", str(port), *flags]


def start_app(procs: "Processes", out: Path, manifest: Path, db: str, s: dict) -> tuple[str, dict]:
    """Stage 2: the app on a free port, once it answers; returns its URL and the environment holding its admin
    token."""
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    env = dict(os.environ, RATING_ADMIN_TOKEN=secrets.token_hex(16))
    _stage(f"2/5 rating app at {url} (database {db.split('@')[-1]})")
    # The crowd runs on loopback (one address) and should not take 4 s per clip: lift the per-address session
    # limit and lower the minimum viewing time (the dashboard says so); the crowd still waits as required.
    opts = dict(ratings_per_clip=s["ratings_per_clip"], min_view=s["min_view"], sessions_per_client=0)
    opts["design"] = s["design"]
    if s["clips_per_rater"]:
        opts["clips_per_rater"] = s["clips_per_rater"]
    cmd = serve_command(manifest, db, port, opts, s["gunicorn"], env)
    log = out / "logs" / "server.log"
    with open(log, "w") as fh:
        server = procs.start(cmd, stdout=fh, stderr=subprocess.STDOUT, env=env)
    _wait_until_up(f"{url}/", server, log)
    return url, env


def run_crowd(procs: "Processes", out: Path, url: str, env: dict, manifest: Path, s: dict, time_left: float) -> dict:
    """Stage 3: the simulated crowd until every test unit has its target answers; returns its summary."""
    raters, rpc = s["raters"], s["ratings_per_clip"]
    _stage(
        f"3/5 simulated crowd: up to {raters} raters, {s['careless']:.0%} careless, until every test clip has "
        f"{rpc} ratings"
    )
    summary_path = out / "crowd_summary.json"
    cmd = [sys.executable, "-m", "rating_app", "simulate", "--url", url, "--manifest", str(manifest)]
    cmd += ["--raters", str(raters), "--seed", str(s["seed"]), "--careless", str(s["careless"])]
    cmd += ["--summary", str(summary_path), "--design", s["design"], "--timeout", str(max(60.0, time_left))]
    try:
        procs.run(cmd, "the simulated crowd", env=env)
    except DemoError:
        if not summary_path.is_file():
            raise
    summary = json.loads(summary_path.read_text())
    if not summary.get("study_full"):  # the crowd's own line above says why; this one says what to change here
        raise DemoError(f"the crowd of {raters} raters did not fill every clip's {rpc} ratings; raise --raters")
    return summary


def report(procs: "Processes", out: Path, ratings: Path, stimuli: Path) -> None:
    """Stage 5: the report of the export, with the stimuli's metrics where there are some."""
    _stage(f"5/5 report → {out / 'report'}")
    metrics = Path(stimuli) / "metrics.csv"
    cmd = [sys.executable, "-m", "analysis.report", str(ratings), "--out", str(out / "report")]
    if metrics.is_file():  # a design whose statistics have no use for the metrics leaves them aside
        cmd += ["--metrics", str(metrics)]
    procs.run(cmd, "analysis.report")


def run_demo(
    out: Path,
    db: str | None = None,
    raters: int = 200,
    seed: int = 0,
    careless: float = 0.1,
    ratings_per_clip: int = 20,
    clips_per_rater: int | None = 30,
    gunicorn: bool = False,
    stimuli: Path | None = None,
    timeout_s: float = 1800.0,
    min_view: float = 0.01,
    design: str = "acr",
    sound: bool = False,
    runs: Path | None = None,
    size: int = 320,
    items: int | None = None,
) -> dict:
    """Run the study; returns paths and the crowd's summary. `stimuli` reuses an existing folder. What an earlier
    run left in `out` is replaced (clear_earlier_run). `items`: test items of the set it makes (None: the paper's 30
    for the built-in set, the demo study's own number for a study with speech)."""
    out = Path(out)
    sound = sound or design in study.MISMATCH_COLUMN  # the matched-against-mismatched designs are about speech
    # Checked before anything in `out` is replaced: a refused run leaves an earlier one as it was.
    if items is not None and stimuli is not None:
        raise DemoError("--items: a set given with --stimuli is used as it is; leave out one of the two")
    if items is not None and sound:
        (low, high), who = speech_items(design)
        if not low <= items <= high:
            raise DemoError(f"--items: a study of {who} has {low} to {high} items, not {items}")
    settings = dict(locals())
    clear_earlier_run(out, stimuli is None)
    (out / "logs").mkdir(parents=True, exist_ok=True)
    (out / MARK).write_text(json.dumps({"design": design, "seed": seed, "sound": sound}) + "\n")
    procs = Processes()
    t0 = time.monotonic()
    try:
        if stimuli is None:
            stimuli = make_stimuli(procs, out, settings)
        else:
            _stage(f"1/5 stimuli: using {stimuli}")
        manifest = Path(stimuli) / "manifest.csv"
        if not manifest.is_file():
            raise DemoError(f"{manifest}: no manifest (make_stimuli did not write one)")
        db = db or f"sqlite:///{(out / DB_NAME).resolve()}"
        url, env = start_app(procs, out, manifest, db, settings)
        summary = run_crowd(procs, out, url, env, manifest, settings, timeout_s - (time.monotonic() - t0))
        _stage("4/5 export")
        ratings = _export(url, env["RATING_ADMIN_TOKEN"], out)
        print(f"  {ratings}", flush=True)
        procs.stop_all()
        report(procs, out, ratings, stimuli)
    finally:
        procs.stop_all()
    print(f"\nDone in {time.monotonic() - t0:.0f} s. Report: {(out / 'report' / 'report.html').resolve()}", flush=True)
    return {"stimuli": Path(stimuli), "ratings": ratings, "report": out / "report", "summary": summary}


def build_parser():
    """The command's argument parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    p = cli.ArgumentParser(
        prog="python -m analysis.demo", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--out", default="demo", help="folder for everything the demo makes (default demo/)")
    p.add_argument(
        "--db",
        default=None,
        help="database URL (default an SQLite file in --out), e.g. postgresql://127.0.0.1:5432/test",
    )
    p.add_argument(
        "--raters",
        type=cli.number(int, 1, 100_000),
        default=200,
        help="most simulated raters (stops when the study is full)",
    )
    p.add_argument(
        "--careless", type=cli.number(float, 0, 1), default=0.1, help="share of careless raters (default 0.1)"
    )
    p.add_argument("--ratings-per-clip", type=cli.number(int, 1, 10_000), default=20)
    p.add_argument(
        "--clips-per-rater", type=cli.number(int, 0, 100_000), default=30, help="test clips per rater (0: all)"
    )
    p.add_argument("--seed", type=cli.number(int, 0), default=0)
    p.add_argument("--stimuli", default=None, help="reuse this stimulus folder instead of making one")
    p.add_argument(
        "--size",
        type=cli.number(int, 1),
        default=320,
        help="make_stimuli --size: the videos' height in pixels, even (default 320; two people are filmed wide)",
    )
    p.add_argument(
        "--items",
        type=cli.number(int, 2, 10_000),
        default=None,
        help="test items of the set it makes, for a quicker try: the built-in set's (make_stimuli --n-items; default "
        "the paper's 30) or the study with speech's (one person talking {}-{}, two people {}-{}; default the "
        "study's own)".format(*study.SPEECH_DEMO_ITEMS, *study.TWO_PERSON_DEMO_ITEMS),
    )
    p.add_argument(
        "--runs",
        default=None,
        help="where make_stimuli --quick keeps its tiny models and data, reused when there (default OUT/runs)",
    )
    p.add_argument("--gunicorn", action="store_true", help="serve with gunicorn (2 workers) instead of Flask's server")
    p.add_argument(
        "--min-view",
        type=cli.number(float, 0, 1),
        default=0.01,
        help="the app's RATING_MIN_VIEW: share of each clip the crowd must wait before answering (default 0.01)",
    )
    p.add_argument(
        "--design",
        choices=DESIGNS,
        default="acr",
        help="test design: acr (one clip, 1-5; default), pairwise (two clips, a preference), parallel "
        "(every condition of an item on one page, 0-100), appropriateness (a system's motion for the speech heard "
        "against its motion for other speech), dyadic (two people talking: the agent's motion for this interlocutor "
        "against its motion for another) or semantic (the motion for this utterance against another's, the keyword "
        "highlighted); targets count pairs or pages",
    )
    p.add_argument(
        "--sound",
        action="store_true",
        help="a study with speech in every video (implied by appropriateness, dyadic and semantic): see above",
    )
    return p


def _main(argv) -> int:
    a = build_parser().parse_args(argv)
    cli.folder_to_write(a.out, "the demo's folder")
    try:
        run_demo(
            Path(a.out),
            db=a.db,
            raters=a.raters,
            seed=a.seed,
            careless=a.careless,
            ratings_per_clip=a.ratings_per_clip,
            clips_per_rater=a.clips_per_rater or None,
            gunicorn=a.gunicorn,
            stimuli=Path(a.stimuli) if a.stimuli else None,
            min_view=a.min_view,
            design=a.design,
            sound=a.sound,
            runs=Path(a.runs) if a.runs else None,
            size=a.size,
            items=a.items,
        )
    except KeyboardInterrupt:
        return interrupted()
    return 0


def interrupted() -> int:
    """What a demo's command says and returns when Ctrl-C stopped it (Processes stopped everything it started)."""
    print("interrupted: everything the demo started has been stopped", file=sys.stderr)
    return 130


def main(argv=None) -> int:
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
