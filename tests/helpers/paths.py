"""Where the tests find the repository and the real data: ../shared beside the checkout (docs/data.md).

Tests that read ../shared belong to the full tier (conftest marks them `full`); the fast tier reads only what the
repository holds (tests/data/)."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared"
DATA = SHARED / "data"
BANDAI = DATA / "bandai-namco-locomotion"
PFNN = DATA / "pfnn-holden"
ACTIONS = DATA / "bandai-namco-actions"
TEST_DATA = ROOT / "tests" / "data"


def small_take_names(per_category=4):
    """The `per_category` longest Bandai-Namco takes of every locomotion category."""
    from generation.data.prepare import longest_takes

    return longest_takes(BANDAI, per_category)
