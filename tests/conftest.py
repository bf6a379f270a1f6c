"""Shared fixtures. Real data lives in ../shared beside the checkout (CONTRACTS.md, data/README.md)."""
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
DATA = SHARED / "data"
BANDAI = DATA / "bandai-namco-locomotion"
PFNN = DATA / "pfnn-holden"


@pytest.fixture(scope="session")
def shared_dir():
    if not SHARED.is_dir():
        pytest.fail(f"../shared is missing beside the checkout ({SHARED}); CI always has it")
    return SHARED
