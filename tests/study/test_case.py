"""One study case applies the scenario's ``limits:`` as ``multiarm-pin run`` does."""

from __future__ import annotations

import yaml

from multiarm_pin.study.case import CaseTask, run_case
from multiarm_pin.study.metrics import metric_names

from .helpers import SCENARIOS

BASE = SCENARIOS / "two_ur5_box.yaml"


def _case(overrides: dict) -> dict:
    data = yaml.safe_load(BASE.read_text(encoding="utf-8"))
    names = [a["name"] for a in data["arms"]]
    task = CaseTask(case_id="case_00000", key="k", index=0, params={}, mode="simulate",
                    base_file=str(BASE), base_data=data, overrides=overrides,
                    metrics=metric_names("simulate", names))
    return run_case(task)


def test_a_torque_stop_policy_ends_the_case_at_the_reports_first_violation():
    """A 200 kg box (about 7x the shoulders' effort limit): with ``limits.torque: report``
    the case runs to its end and its report names the first violation; with ``stop`` the
    case ends at that same sample, as an error row that keeps ``feasible = 0`` and the
    torque ratio of the samples simulated."""
    heavy = {"object.mass": 200.0, "simulation.duration": 0.04}
    reported = _case(heavy)
    stopped = _case({**heavy, "limits": {"torque": "stop"}})

    assert reported["row"]["status"] == "ok"
    run = reported["summary"]["run"]
    first = min(v["t_first"] for v in run["violations"] if v["kind"] == "torque")
    assert reported["row"]["feasible"] == 0.0
    assert run["t_end"] > first + 0.02  # the violation is well before the end

    row, summary = stopped["row"], stopped["summary"]
    assert row["status"] == "error"
    assert "limits.torque: stop" in row["error"]
    assert row["feasible"] == 0.0
    ratios = [v for k, v in row.items() if k.startswith("torque_limit_ratio[")]
    assert ratios and max(ratios) > 2.0
    assert summary["run"]["t_end"] == first
    assert summary["run"]["status"] == "failed"
