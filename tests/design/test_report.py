"""The results folder of a design: scenarios `run` accepts, pictures, report, the best run."""

import json

import pytest
import yaml

from multiarm_pin.app.cli import main
from multiarm_pin.app.scenario import build_scenario, load_scenario
from tests.design.design_cases import spec_data


@pytest.fixture(scope="module")
def designed(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("design")
    d = spec_data()
    d["search"] = {"candidates": 12, "refine": 1, "polish": 1, "seed": 0}
    d["top"] = 2
    spec = tmp / "spec.yaml"
    spec.write_text(yaml.safe_dump(d), encoding="utf-8")
    out = tmp / "out"
    code = main(["design", str(spec), "--out", str(out), "--workers", "1", "--quiet"])
    return code, out


def test_the_folder_holds_designs_report_and_the_best_run(designed):
    code, out = designed
    assert code == 0
    for k in (1, 2):
        assert (out / f"designs/design_{k}.png").stat().st_size > 10_000
        sc = load_scenario(out / f"designs/design_{k}.yaml")  # a scenario as it is
        built = build_scenario(sc, load_visuals=False)
        assert all(a.q0 is not None for a in sc.arms)
        assert all(ik is None for ik in built.ik)  # q0 given: no IK needed
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "| rank | candidate | objective | torque_ratio | clearance | manipulability |" \
        in report
    assert "## Pareto front" in report and "best_run/replay.html" in report
    info = json.loads((out / "design.json").read_text(encoding="utf-8"))
    assert [d["rank"] for d in info["designs"]] == [1, 2]
    summary = json.loads((out / "best_run/summary.json").read_text(encoding="utf-8"))
    assert summary["status"] == "complete" and summary["feasible"] is True
    assert info["best_run"]["feasible"] is True
    assert (out / "best_run/replay.html").is_file()


def test_a_design_runs_unchanged(designed, tmp_path):
    _, out = designed
    code = main(["run", str(out / "designs/design_2.yaml"), "--out", str(tmp_path / "run"),
                 "--quiet", "--duration", "0.2"])
    assert code == 0
