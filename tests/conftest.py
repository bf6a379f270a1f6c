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


def pytest_addoption(parser):
    parser.addoption("--run-slow", action="store_true", help="also run tests marked slow (full-size end-to-end runs)")


def pytest_collection_modifyitems(config, items):
    import os
    if config.getoption("--run-slow") or os.environ.get("RUN_SLOW") == "1":
        return
    skip = pytest.mark.skip(reason="slow: run with --run-slow (CI runs the short variant)")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
