"""Fixtures of the study tests."""

import pytest

from multiarm_pin.study import Study
from tests.study.helpers import tiny_simulation_study


@pytest.fixture(scope="session")
def warm_kernels(tmp_path_factory):
    """Run one tiny simulate case in this process first, so that the compiled kernels are in
    numba's disk cache before any Dask worker starts: workers then load them instead of each
    compiling them at once (minutes on a loaded 2-core machine in a fresh checkout)."""
    folder = tmp_path_factory.mktemp("warm")
    table = Study.from_file(tiny_simulation_study(folder, masses=(2.0,), samples=1)).run_loop()
    assert table.column("status").to_pylist() == ["ok"], table.column("error").to_pylist()
