import math

import numpy as np

from multiarm_pin.study.report import largest_passing, summary_by_value, write_report
from multiarm_pin.study.spec import load_study
from multiarm_pin.study.store import rows_to_table
from tests.study.helpers import SCENARIOS, write_study


def _spec(tmp_path):
    return load_study(write_study(tmp_path, {
        "name": "rep", "base": str(SCENARIOS / "two_gripper_form_closure.yaml"),
        "mode": "grasp", "parameters": [{"perturb_contacts": {"sigma": [0.001, 0.01, 0.02]}}],
        "samples": 4, "metrics": ["form_closure", "margin"]}))


def _rows():
    # σ = 1 mm: all closed; 10 mm: 3 of 4 closed; 20 mm: 1 closed, 1 open, 2 errors
    closed = {0.001: [1, 1, 1, 1], 0.01: [1, 1, 0, 1], 0.02: [1, 0, None, None]}
    rows, i = [], 0
    for s, fcs in closed.items():
        for k, fc in enumerate(fcs):
            ok = fc is not None
            rows.append({"case_id": f"case_{i:05d}", "key": "k", "index": i,
                         "perturb_contacts.sigma": s, "sample": k,
                         "form_closure": float(fc) if ok else math.nan,
                         "margin": 0.05 - s if ok else math.nan,
                         "status": "ok" if ok else "error",
                         "error": "" if ok else "ScenarioError: outside the face by 0.003 m"})
            i += 1
    return rows


def test_summary_fractions_count_failures_as_not_holding(tmp_path):
    spec = _spec(tmp_path)
    table = rows_to_table(_rows())
    rows = summary_by_value(table, spec, "perturb_contacts.sigma")
    assert [r["form_closure fraction"] for r in rows] == [1.0, 0.75, 0.25]
    assert [r["failed"] for r in rows] == [0, 0, 2]
    assert np.isclose(rows[2]["margin mean"], 0.03)  # errors excluded from the mean
    assert largest_passing(table, spec, "perturb_contacts.sigma", "form_closure") == \
        (0.001, 0.01)


def test_report_has_tables_plots_and_failures(tmp_path):
    spec = _spec(tmp_path)
    table = rows_to_table(_rows())
    path = write_report(tmp_path / "out", spec, table)
    text = path.read_text()
    assert "cases: 12 (10 ran, 2 failed)" in text
    assert "## Against `perturb_contacts.sigma`" in text and "## All cases" in text
    assert "up to `perturb_contacts.sigma` = 0.001; first value where it fails: 0.01" in text
    assert "2 x ScenarioError: outside the face by # m" in text
    pngs = sorted(p.name for p in (tmp_path / "out" / "plots").glob("*.png"))
    assert pngs == ["form_closure__vs__perturb_contacts.sigma.png",
                    "margin__vs__perturb_contacts.sigma.png"]


def test_report_keeps_error_messages_whole(tmp_path):
    """Issue 25: the report cut messages at 60 characters (tables) and 220 (failure kinds)."""
    spec = _spec(tmp_path)
    rows = _rows()
    long = ("ScenarioError: " + str(spec.base_file) + ": arms[1].joint.contacts[2].point: "
            "contact point [0.41, 0.2, 0.1] is 0.0125 m outside face +x (tolerance 1e-06 m); "
            "expected a point on the face | moved by perturb_contacts.sigma = 0.02 m\n"
            "second line of the message " + "x" * 300 + " END")
    rows[10]["error"] = rows[11]["error"] = long
    text = write_report(tmp_path / "out", spec, rows_to_table(rows)).read_text()
    whole = " ".join(long.replace(str(spec.base_file), "two_gripper_form_closure.yaml").split())
    assert f"- case_00010: {whole}" in text  # First failures, on one line
    assert f"| {whole.replace('|', chr(92) + '|')} |" in text  # the All cases table
    kind = [ln for ln in text.splitlines() if ln.startswith("- 2 x ")]
    assert len(kind) == 1 and kind[0].endswith("x" * 300 + " END (first: case_00010)")
    assert "..." not in text
