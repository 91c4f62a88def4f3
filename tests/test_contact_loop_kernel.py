"""Short runs of the compiled contact loop against the Python stepper, small enough to run
without compilation too (``make test`` runs this file again with ``NUMBA_DISABLE_JIT=1``:
the kernel as Python, bounds-checked)."""

from __future__ import annotations

import pytest
from closed_loop_cases import assert_same_contact_run, run_scenario


@pytest.mark.parametrize(("name", "duration", "support_block"), [
    ("box_on_table", 0.13, 0),   # the first impact (~0.1 s) and the bounce off the table
    ("grasp_failure", 0.17, None),  # a fingertip lets go at 0.15 s, planning on the others
])
def test_short_runs_equal_the_python_stepper(name, duration, support_block, monkeypatch):
    """The table's four coplanar rows are redundant: compared by their resultant (see
    ``closed_loop_cases.assert_same_contact_run``), the fingertips row by row."""
    fast, calls = run_scenario(name, duration, True, monkeypatch)
    ref, _ = run_scenario(name, duration, False, monkeypatch)
    assert calls, "no compiled loop ran"
    assert ref.events, "the run should have contact events"
    assert_same_contact_run(fast, ref, 1e-9, support_block=support_block)
