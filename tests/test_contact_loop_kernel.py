"""Short runs of the compiled contact loop against the Python stepper, small enough to run
without compilation too (``make test`` runs this file again with ``NUMBA_DISABLE_JIT=1``:
the kernel as Python, bounds-checked)."""

from __future__ import annotations

import numpy as np
import pytest
from closed_loop_cases import RUN_FIELDS, rel_err, run_scenario


@pytest.mark.parametrize(("name", "duration"), [
    ("box_on_table", 0.13),   # the first impact (~0.1 s) and the bounce off the table
    ("grasp_failure", 0.17),  # a fingertip lets go at 0.15 s, planning on the others
])
def test_short_runs_equal_the_python_stepper(name, duration, monkeypatch):
    fast, calls = run_scenario(name, duration, True, monkeypatch)
    ref, _ = run_scenario(name, duration, False, monkeypatch)
    assert calls, "no compiled loop ran"
    assert ref.events, "the run should have contact events"
    assert [(e.kind, e.block, e.row, e.rebound) for e in fast.events] == \
        [(e.kind, e.block, e.row, e.rebound) for e in ref.events]
    for a, b in zip(fast.events, ref.events, strict=True):
        assert abs(a.t - b.t) <= 1e-9
    for field in RUN_FIELDS:
        assert rel_err(getattr(fast, field), getattr(ref, field)) <= 1e-9, field
    np.testing.assert_array_equal(fast.active, ref.active)
    assert list(fast.solver) == list(ref.solver)
