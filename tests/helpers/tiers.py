"""Which tests run: the suite keeps short variants, and --run-slow (or RUN_SLOW=1) runs everything."""

import os

import pytest


def run_slow(config) -> bool:
    """Whether this run includes the tests marked slow and the long parametrisations."""
    return bool(config.getoption("--run-slow") or os.environ.get("RUN_SLOW") == "1")


def only_when_slow(request, why):
    """Skip this parametrisation unless slow tests run: the suite keeps one short variant of a check that every
    parametrisation repeats (e.g. one database of two), and --run-slow runs them all."""
    if not run_slow(request.config):
        pytest.skip(f"slow: {why} (--run-slow runs it)")
