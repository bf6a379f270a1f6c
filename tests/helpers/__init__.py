"""What the tests share besides fixtures: where the real data is, stimulus folders made for the app's tests, the
tests' PostgreSQL, servers and proxies started as processes, and crowds of concurrent raters.

The tests import these as `helpers.NAME` (pytest puts tests/ on sys.path); fixtures stay in conftest.py.
"""
