"""A whole challenge in one command, from the released inputs to the board (docs/challenge.md):

    generation.challenge.demo_inputs (three made-up teams)  →  intake (team B refused)  →  team B resubmits  →
    intake (every team accepted)  →  make_stimuli, one study per task  →  serve, a simulated crowd, export and
    report per task (analysis.demo)  →  analysis.board

    python -m analysis.challenge_demo [--out challenge-demo/] [--items 6] [--raters 40] [--ratings-per-clip 20]
                                      [--seed 0]
    moglow-eval challenge-demo ...

Team A is a deterministic system, team B first submits a broken folder (a missing item, a wrong frame rate, NaN
frames) and then a fixed one, and team C is stochastic, with five samples per item. The two tasks are realism (acr,
each rater shown a sample of team C's drawn for them) and speech (appropriateness, one sample drawn per item). Every
stage is a real process, as an organiser would run it; the logs are in OUT/logs. A folder the demo did not make (no
challenge-demo.json in it) is refused, never emptied; one it made is replaced.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path

from moglow_eval.core import cli

from .demo import DemoError, Processes, interrupted, run_demo

MARK = "challenge-demo.json"
SAMPLES = 5  # the rules: five samples per item from a stochastic system, one file from a deterministic one


def _stage(n: int, title: str) -> None:
    print(f"\n== {n}/6 {title}", flush=True)


def _fresh(out: Path) -> None:
    if out.is_dir() and any(out.iterdir()):
        if not (out / MARK).is_file():
            raise DemoError(f"--out {out}: holds files the challenge demo did not make (no {MARK}); give another --out")
        shutil.rmtree(out)
    (out / "logs").mkdir(parents=True)


def _intake(procs: Processes, data: Path, out: Path, log: Path) -> dict:
    """One intake round over every team; {team: verdict} from its table (exit 1, a refused team, is expected)."""
    cmd = [sys.executable, "-m", "generation.challenge.intake", "--inputs", str(data / "inputs" / "speech")]
    cmd += ["--fps", "30", "--samples", str(SAMPLES), "--or-one", "--teams", str(data / "submissions")]
    cmd += ["--out", str(out), "--quiet"]
    try:
        procs.run(cmd, "intake", log)
    except DemoError:
        if not (out / "teams.csv").is_file():
            raise
    rows = (out / "teams.csv").read_text().splitlines()[1:]
    verdicts = {r.split(",")[0]: r.split(",")[1] for r in rows}
    for line in log.read_text().splitlines():
        print(f"  {line}", flush=True)
    return verdicts


def run_challenge(
    out: Path, n_items: int = 6, raters: int = 40, seed: int = 0, db: str | None = None, ratings_per_clip: int = 20
) -> dict:
    """Run the demo challenge into `out`; returns the paths of its board and its reports. `ratings_per_clip`: each
    task's target, answers a clip (or a pair), as analysis.demo's."""
    out = Path(out)
    _fresh(out)
    (out / MARK).write_text(json.dumps({"items": n_items, "seed": seed}) + "\n")
    t0, procs, py = time.monotonic(), Processes(), sys.executable
    data, logs = out / "data", out / "logs"
    try:
        _stage(1, f"the released inputs and three teams' submissions → {data}")
        cmd = [py, "-m", "generation.challenge.demo_inputs", "--out", str(data), "--items", str(n_items)]
        procs.run([*cmd, "--seed", str(seed)], "generation.challenge.demo_inputs", logs / "inputs.log")

        _stage(2, "intake: every team's folder checked against the inputs")
        first = _intake(procs, data, out / "intake" / "1", logs / "intake-1.log")
        refused = sorted(t for t, v in first.items() if v != "accepted")
        print(f"  refused: {', '.join(refused) or 'none'}; each team's page: {out / 'intake' / '1'}/TEAM/intake.html")

        _stage(3, f"{', '.join(refused)} resubmit{'s' if len(refused) == 1 else ''}; intake again")
        for team in refused:
            shutil.rmtree(data / "submissions" / team)
            shutil.copytree(data / "resubmissions" / team, data / "submissions" / team)
        second = _intake(procs, data, out / "intake" / "2", logs / "intake-2.log")
        if any(v != "accepted" for v in second.values()):
            raise DemoError(f"intake: a team is still refused after resubmitting; see {out / 'intake' / '2'}")

        _stage(4, "the studies: one per task, every accepted team a condition")
        tasks = json.loads((data / "tasks.json").read_text())  # {task: the design that serves it}
        for task in tasks:
            cmd = [py, "-m", "generation.make_stimuli", "--study", str(data / f"{task}.toml")]
            cmd += ["--out", str(out / "stimuli" / task), "--size", "160", "--quiet"]
            procs.run(cmd, f"make_stimuli ({task})", logs / f"stimuli-{task}.log")
            print(f"  {task}: {out / 'stimuli' / task}", flush=True)

        _stage(5, "each task served, rated by a simulated crowd, exported and reported")
        reports = {}
        for task, design in tasks.items():
            print(f"\n-- {task} ({design})", flush=True)
            url = None if db is None else db
            stimuli = out / "stimuli" / task
            run_demo(out / task, db=url, raters=raters, seed=seed, design=design, stimuli=stimuli,
                     ratings_per_clip=ratings_per_clip)  # fmt: skip
            reports[task] = out / task / "report"

        _stage(6, f"the board → {out / 'board'}")
        cmd = [py, "-m", "analysis.board", "--out", str(out / "board"), "--mode", "challenge", "--publish"]
        for task in reports:
            cmd += ["--task", f"{task}={reports[task]}", "--stimuli", f"{task}={out / 'stimuli' / task}"]
        procs.run(cmd, "analysis.board", logs / "board.log")
    finally:
        procs.stop_all()
    board = out / "board" / "index.html"
    print(f"\nDone in {time.monotonic() - t0:.0f} s. The board: {board.resolve()}", flush=True)
    return {"board": out / "board", "reports": reports, "intake": out / "intake"}


def build_parser():
    """The command's argument parser (also read by tests/project/test_docs.py to check the docs' commands)."""
    p = cli.ArgumentParser(
        prog="python -m analysis.challenge_demo",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--out", default="challenge-demo", help="folder for everything it makes (default challenge-demo/)")
    p.add_argument("--items", type=cli.number(int, 4, 40), default=6, help="test items per task (default 6)")
    p.add_argument("--raters", type=cli.number(int, 1, 10_000), default=40, help="most simulated raters per task")
    p.add_argument(
        "--ratings-per-clip",
        type=cli.number(int, 1, 10_000),
        default=20,
        help="answers each clip (or pair) of a task gets before its crowd stops (default 20)",
    )
    p.add_argument("--seed", type=cli.number(int, 0), default=0)
    p.add_argument("--db", default=None, help="database URL (default an SQLite file per task)")
    return p


def _main(argv) -> int:
    a = build_parser().parse_args(argv)
    cli.folder_to_write(a.out, "the demo's folder")
    try:
        run_challenge(Path(a.out), a.items, a.raters, a.seed, a.db, a.ratings_per_clip)
    except KeyboardInterrupt:
        return interrupted()
    return 0


def main(argv=None) -> int:
    return cli.run(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
