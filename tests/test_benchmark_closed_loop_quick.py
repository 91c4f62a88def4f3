"""Smoke test of ``benchmarks/closed_loop.py --quick``: its three files, finite numbers."""

import csv
import math
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "closed_loop.py"


def test_quick_closed_loop_benchmark(tmp_path):
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    for name in ("closed_loop.csv", "closed_loop.md", "closed_loop.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    assert (tmp_path / "closed_loop.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    report = (tmp_path / "closed_loop.md").read_text()
    for heading in ("## Environment", "git commit", "## Method", "## n UR5s welded",
                    "## Shipped scenarios", "## Feasibility checks", "## Cold start",
                    "## Targets"):
        assert heading in report, heading
    with (tmp_path / "closed_loop.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert {(r["case"], int(r["n_arms"])) for r in rows} == {
        ("weld_ur5", 2), ("weld_ur5", 4), ("two_ur5_box", 2)}
    for r in rows:
        for key in ("t_closed_s", "t_open_s", "t_closed_ref_s", "rtf"):
            assert math.isfinite(float(r[key])) and float(r[key]) > 0, (r["case"], key)
        if r["case"] == "weld_ur5":
            assert math.isfinite(float(r["t_pin_s"])) and float(r["t_pin_s"]) > 0
