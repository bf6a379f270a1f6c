"""A pip-installed (non-editable) package holds every file the parts read at run time: pyproject's package-data
globs cover every file in the folders they name (a design's page template in templates/designs/ was once left
out of the wheel, which an editable install does not show)."""

import tomllib

import pytest
from helpers.paths import ROOT

PACKAGE_DATA = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]


@pytest.mark.parametrize("package", sorted(PACKAGE_DATA))
def test_package_data_covers_every_data_file(package):
    base = ROOT / package
    covered = {p for pattern in PACKAGE_DATA[package] for p in base.glob(pattern) if p.is_file()}
    folders = {(base / pattern).parent for pattern in PACKAGE_DATA[package]}
    tops = {f for f in folders if not any(g in f.parents for g in folders)}
    data = {p for top in tops for p in top.rglob("*") if p.is_file() and "__pycache__" not in p.parts}
    missing = sorted(str(p.relative_to(ROOT)) for p in data - covered)
    assert not missing, f"pyproject [tool.setuptools.package-data] {package}: add a pattern for {missing}"
