"""Where the tests find the repository and the real data: ../shared beside the checkout (docs/data.md).

Tests that read ../shared belong to the full tier (conftest marks them `full`); the fast tier reads only what the
repository holds (tests/data/)."""

import csv
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PARTS = ("moglow_eval", "generation", "rendering", "rating_app", "analysis")  # the product's packages
SHARED = ROOT.parent / "shared"
DATA = SHARED / "data"
BANDAI = DATA / "bandai-namco-locomotion"
PFNN = DATA / "pfnn-holden"
ACTIONS = DATA / "bandai-namco-actions"
LEADERBOARD = DATA / "genea-leaderboard-votes"  # another lab's released pairwise votes
TEST_DATA = ROOT / "tests" / "data"


def small_take_names(per_category=4):
    """The `per_category` longest Bandai-Namco takes of every locomotion category."""
    from generation.data.prepare import longest_takes

    return longest_takes(BANDAI, per_category)


def takes(category, n, min_seconds=5.0):
    """The first `n` Bandai-Namco takes (by path) of locomotion `category` lasting `min_seconds` or more, from
    ../shared's MANIFEST.csv."""
    with open(DATA / "MANIFEST.csv", newline="") as f:
        rows = [
            r
            for r in csv.DictReader(f)
            if r["locomotion"] == category and float(r["seconds"]) >= min_seconds and r["path"].startswith("bandai")
        ]
    return [DATA / r["path"] for r in sorted(rows, key=lambda r: r["path"])[:n]]
