"""The installed package holds every module of parallax/: pyproject.toml lists its packages by
name (conf/ ships as parallax.conf), so a new package must be added there too."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def test_pyproject_lists_every_package_of_the_source_tree():
    tomllib = pytest.importorskip("tomllib")  # Python 3.11 and later
    setuptools = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(setuptools["packages"])
    found = {
        ".".join(init.parent.relative_to(REPO).parts)
        for init in (REPO / "parallax").rglob("__init__.py")
    }
    assert found - listed == set(), "add these to pyproject.toml's [tool.setuptools] packages"
    assert listed - found == set(setuptools["package-dir"])  # only parallax.conf lives elsewhere
