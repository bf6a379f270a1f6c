"""Do two checkouts give the same exports and stats.json from the same studies? (A refactor's check: House V.)

    python scripts/compare_outputs.py --old ../old-checkout DEMO_DIR [DEMO_DIR ...]

Each DEMO_DIR is what `python -m analysis.demo --design D --out DEMO_DIR` left: its database and stimuli. Both
checkouts export that database (and, for pairwise, its battles), then report their own export; the exports must be
the same bytes and the two stats.json the same but for `generated_at` and `input` (the run's time and path). One
line per study; exit 1 when any differs.
"""

import argparse
import filecmp
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
RUN_NAMED = ("generated_at", "input")  # what names the run, not the study


def run(checkout: Path, *argv):
    """`python -m ARGV` with `checkout`'s packages first on the path."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("RATING_") and k != "DATABASE_URL"}
    env["PYTHONPATH"] = str(checkout)
    subprocess.run([sys.executable, "-m", *argv], cwd=checkout, env=env, check=True, capture_output=True)


def outputs(checkout: Path, demo: Path, out: Path) -> Path:
    db = f"sqlite:///{demo / 'ratings.sqlite'}"
    out.mkdir(parents=True)
    run(checkout, "rating_app", "export", "--db", db, "--out", str(out / "export.csv"))
    try:
        run(checkout, "rating_app", "export", "--db", db, "--format", "battles", "--out", str(out / "battles.csv"))
    except subprocess.CalledProcessError:
        pass  # a design without battles: both checkouts refuse it
    metrics = demo / "stimuli" / "metrics.csv"
    extra = ["--metrics", str(metrics)] if metrics.exists() else []
    report = ["analysis.report", str(out / "export.csv"), "--out", str(out / "report"), "--n-boot", "200", "--quiet"]
    run(checkout, *report, *extra)
    return out


def same_stats(a: Path, b: Path) -> list[str]:
    docs = [json.loads(p.read_text()) for p in (a, b)]
    for d in docs:
        for key in RUN_NAMED:
            d.pop(key, None)
    return sorted(k for k in set(docs[0]) | set(docs[1]) if docs[0].get(k) != docs[1].get(k))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--old", required=True, type=Path, help="the other checkout (e.g. a git worktree)")
    ap.add_argument("demos", nargs="+", type=Path, help="analysis.demo output folders")
    args = ap.parse_args(argv)
    bad = 0
    with tempfile.TemporaryDirectory() as tmp:
        for demo in args.demos:
            old = outputs(args.old.resolve(), demo.resolve(), Path(tmp) / demo.name / "old")
            new = outputs(HERE, demo.resolve(), Path(tmp) / demo.name / "new")
            notes = [f"export {'same' if filecmp.cmp(old / 'export.csv', new / 'export.csv', False) else 'DIFFERS'}"]
            if (old / "battles.csv").exists() or (new / "battles.csv").exists():
                same = (old / "battles.csv").exists() and filecmp.cmp(old / "battles.csv", new / "battles.csv", False)
                notes.append(f"battles {'same' if same else 'DIFFER'}")
            keys = same_stats(old / "report" / "stats.json", new / "report" / "stats.json")
            notes.append(f"stats.json {'same' if not keys else 'DIFFERS in ' + ', '.join(keys)}")
            bad += any("DIFFER" in n for n in notes)
            print(f"{demo.name}: {'; '.join(notes)}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
