"""Smoke test of the benchmark program: ``--quick`` writes its three files with finite numbers."""

import csv
import math
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "solver_vs_kkt.py"
TIMES = ("t_coeff_s", "t_object_first_s", "t_dense_kkt_s", "t_full_step_s")


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--out", str(out)],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


def test_quick_run_writes_csv_report_and_plot(quick_run):
    for name in ("solver_vs_kkt.csv", "solver_vs_kkt.md", "solver_vs_kkt.png",
                 "solver_vs_kkt_unilateral.csv"):
        f = quick_run / name
        assert f.is_file() and f.stat().st_size > 0, name
    assert (quick_run / "solver_vs_kkt.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    report = (quick_run / "solver_vs_kkt.md").read_text()
    for heading in ("## Environment", "## Method", "Table 4.4", "pin.constraintDynamics",
                    "## Where the time of one full step goes", "## Targets",
                    "## Unilateral contacts (issue 12)"):
        assert heading in report, heading


def test_quick_run_numbers_are_finite_and_answers_agree(quick_run):
    with (quick_run / "solver_vs_kkt.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert {"case", "n_arms", "t_pinocchio_s", *TIMES} <= set(rows[0])
    cases = {(r["case"], int(r["n_arms"])) for r in rows}
    assert {("revolute", 2), ("revolute", 3), ("weld", 2)} <= cases
    for r in rows:
        for col in TIMES:
            t = float(r[col])
            assert math.isfinite(t) and t > 0, (r["case"], r["n_arms"], col, t)
        # the two solvers (and Pinocchio, for welds) must give the same motion
        assert float(r["max_rel_diff_kkt"]) < 1e-8
        if r["case"] == "weld":
            assert math.isfinite(float(r["t_pinocchio_s"])) and float(r["t_pinocchio_s"]) > 0
            assert float(r["max_rel_diff_pinocchio"]) < 1e-8
        else:
            assert math.isnan(float(r["t_pinocchio_s"]))


def test_quick_run_unilateral_rows(quick_run):
    """Issue 12's row: both torque families, finite times, exact complementarity, and the
    motion of the bilateral solve on the rows that do not separate, at every state."""
    with (quick_run / "solver_vs_kkt_unilateral.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert [r["family"] for r in rows] == ["random", "squeeze"]
    for r in rows:
        assert int(r["n_rows"]) == 11
        for col in ("t_bilateral_s", "t_unilateral_s", "t_bilateral_fingertips_s",
                    "t_unilateral_guess_s", "ratio"):
            t = float(r[col])
            assert math.isfinite(t) and t > 0, (r["family"], col, t)
        assert float(r["max_complementarity"]) < 1e-10
        # every state is compared (on its rows that do not separate): never zero cases
        assert int(r["states_compared"]) == int(r["n_states"]) >= 1
        assert float(r["max_rel_diff_bilateral"]) < 1e-10


def test_bad_arguments_are_rejected():
    proc = subprocess.run([sys.executable, str(SCRIPT), "--arms", "2,x"],
                          capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert proc.returncode == 2 and "comma-separated integers" in proc.stderr
