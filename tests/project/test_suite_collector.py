"""The suite's own process: collection runs with the cyclic collector off, and what it left is frozen before the
first test (tests/conftest.py, pytest_collection); the tests then run with the collector on."""

import gc


def test_tests_run_with_the_collector_on_and_collections_leftovers_frozen():
    assert gc.isenabled()
    assert gc.get_freeze_count() > 10_000  # every test module and what it imports; a bare interpreter has none
