from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest
import yaml

from multiarm_pin.grasp.contacts import Grasp, contact_on_face
from multiarm_pin.grasp.form_closure import ferrari_canny_epsilon, lp_margin
from multiarm_pin.grasp.report import analyse, load_grasp_file
from multiarm_pin.model.polyhedron import box
from multiarm_pin.sim.trajectories import MinimumJerkTrajectory
from multiarm_pin.study.case import CaseTask, grasp_of, run_case
from multiarm_pin.study.metrics import (
    count_separations,
    grasp_metrics,
    torque_limit_ratio,
    tracking_errors,
)
from tests.study.helpers import SCENARIOS


def _arm(limits):
    model = SimpleNamespace(effortLimit=np.asarray(limits, dtype=float))
    return SimpleNamespace(model=model, nv=len(limits))


def test_torque_limit_ratio_closed_form():
    built = SimpleNamespace(arms=[_arm([10.0, 20.0]), _arm([5.0])])
    tau = np.abs(np.array([[1.0, -30.0, 2.0], [-9.0, 4.0, -4.9]]))
    # column maxima 9, 30, 4.9 over limits 10, 20, 5 -> 0.9, 1.5, 0.98
    assert torque_limit_ratio(built, tau) == pytest.approx(1.5, abs=0)
    no_limits = SimpleNamespace(arms=[_arm([0.0, 0.0]), _arm([0.0])])
    assert np.isnan(torque_limit_ratio(no_limits, tau))


def test_separations_from_events_or_from_pulling_contacts():
    events = [{"kind": "separation"}, {"kind": "touchdown"}, {"kind": "separation"}]
    assert count_separations({"events": events}, np.zeros((3, 2))) == 2
    mu = np.array([[1.0, 2.0, 3.0], [-0.1, 2.0, 0.5], [-0.2, 1.0, -1e-9]])
    assert count_separations({}, mu) == 2  # contacts 0 and 2 pulled at some time
    assert count_separations({}, np.zeros((4, 0))) == 0


def test_tracking_errors_of_a_known_offset():
    traj = MinimumJerkTrajectory.hold(np.array([0.1, 0.2, 0.3]), np.array([0, 0, 0, 1.0]))
    controller = SimpleNamespace(trajectory=traj)
    t = np.linspace(0, 1, 5)
    d = np.array([0.003, -0.004, 0.0])  # 5 mm off
    theta = 0.02  # rad about z
    q = pin.Quaternion(pin.AngleAxis(theta, np.array([0, 0, 1.0]))).coeffs()
    result = SimpleNamespace(t=t, object_position=np.tile([0.1, 0.2, 0.3] + d, (5, 1)),
                             object_quaternion=np.tile(q, (5, 1)))
    pos, rot = tracking_errors(controller, result)
    assert pos == pytest.approx(0.005, rel=1e-12) and rot == pytest.approx(theta, rel=1e-9)
    assert np.isnan(tracking_errors(None, result)[0])


def test_grasp_metrics_agree_with_the_grasp_report():
    gf = load_grasp_file(SCENARIOS / "grasps" / "box_form_closure.yaml")
    rep, _ = analyse(gf)
    m = grasp_metrics(gf.grasp, gf.length_scale)
    assert m["form_closure"] == 1.0 and rep["form_closure"] is True
    assert m["margin"] == pytest.approx(rep["margin"], abs=1e-12)
    assert m["epsilon"] == pytest.approx(rep["ferrari_canny"], abs=1e-12)
    # and with the LP and the hull computed here from the wrench matrix
    W = gf.grasp.wrenches(None, gf.length_scale)
    assert m["margin"] == pytest.approx(lp_margin(W)[0], abs=1e-12)
    assert m["epsilon"] == pytest.approx(ferrari_canny_epsilon(W), abs=1e-12)


def test_grasp_of_a_scenario_is_its_fingertip_contacts():
    f = SCENARIOS / "two_gripper_form_closure.yaml"
    data = yaml.safe_load(f.read_text())
    grasp, L = grasp_of(data, str(f))
    poly = box(data["object"]["shape"]["size"])
    expected = [contact_on_face(poly, c["face"], c["point"])
                for a in data["arms"] for c in a["joint"]["contacts"]]
    assert L == 1.0 and len(grasp) == 7
    for got, exp in zip(grasp.contacts, expected, strict=True):
        assert np.array_equal(got.point, exp.point) and np.array_equal(got.normal, exp.normal)
    m = grasp_metrics(Grasp(tuple(expected), poly))
    assert m["form_closure"] == 1.0 and m["margin"] > 0.03  # issue 6's worked example


def test_run_case_turns_every_failure_into_a_row():
    f = SCENARIOS / "two_gripper_form_closure.yaml"
    data = yaml.safe_load(f.read_text())
    task = CaseTask("case_00000", "k", 0, {"p": 1.0}, "grasp", str(f), data,
                    {"arms[0].joint.contacts[0].point": [0.4, 0.9, 0.15]}, ("form_closure",))
    out = run_case(task)
    row = out["row"]
    assert row["status"] == "error" and "outside the face" in row["error"]
    assert "arms[0].joint.contacts[0]" in row["error"] and np.isnan(row["form_closure"])
    assert row["p"] == 1.0 and out["summary"]["status"] == "error"
    bad_mass = CaseTask("case_00001", "k", 1, {}, "simulate", str(f), data,
                        {"object.mass": -2.0}, ("max_constraint_violation",))
    row = run_case(bad_mass)["row"]
    assert row["status"] == "error" and "object.mass" in row["error"]


def test_feasibility_metrics_of_a_case_match_its_run_and_the_urdf():
    """``feasible``, ``min_clearance`` and each arm's ``torque_limit_ratio[<arm>]`` of the
    demo's case: the per-arm ratios recomputed here from the case's recorded torques would
    need the record; instead they are checked against the summary's per-joint peaks (the
    feasibility report) and their maximum against ``torque_limit_ratio`` (computed from the
    torques and the models' effort limits by another function)."""
    from multiarm_pin.study.metrics import arm_metric, metric_names

    f = SCENARIOS / "two_ur5_box.yaml"
    data = yaml.safe_load(f.read_text())
    names = metric_names("simulate", ["left", "right"])
    assert names[-2:] == (arm_metric("left"), arm_metric("right"))
    task = CaseTask("case_00000", "k", 0, {}, "simulate", str(f), data,
                    {"simulation.duration": 0.1}, names)
    out = run_case(task)
    row, run = out["row"], out["summary"]["run"]
    assert row["status"] == "ok", row["error"]
    assert row["feasible"] == 1.0 and run["feasible"] is True
    gaps = [v for v in run["clearance"].values() if v is not None]
    assert row["min_clearance"] == min(gaps) and 0.0 < row["min_clearance"] < 0.1
    per_arm = [row[arm_metric(a)] for a in ("left", "right")]
    for a, r in zip(("left", "right"), per_arm, strict=True):
        peaks = [j["peak_torque_ratio"] for j in run["limits"][a].values()]
        assert r == max(peaks) and 0.05 < r < 1.0
    assert max(per_arm) == pytest.approx(row["torque_limit_ratio"], rel=1e-12)
