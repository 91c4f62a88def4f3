"""Every name exported in an ``__all__`` must exist (a stale export is a defect)."""

import importlib

import pytest

PACKAGES = [
    "multiarm_pin",
    "multiarm_pin.constraints",
    "multiarm_pin.dynamics",
    "multiarm_pin.grasp",
    "multiarm_pin.study",
    "multiarm_pin.study.spec",
    "multiarm_pin.study.metrics",
    "multiarm_pin.study.case",
    "multiarm_pin.study.execution",
    "multiarm_pin.study.store",
    "multiarm_pin.study.report",
]


@pytest.mark.parametrize("name", PACKAGES)
def test_all_names_exist(name):
    module = importlib.import_module(name)
    assert module.__all__, f"{name} exports nothing"
    missing = [n for n in module.__all__ if not hasattr(module, n)]
    assert not missing, f"{name}.__all__ names missing attributes: {missing}"


def test_version_matches_package_metadata():
    from importlib.metadata import version

    import multiarm_pin

    assert multiarm_pin.__version__ == version("multiarm_pin")
