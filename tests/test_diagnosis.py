"""Failures name their cause (multiarm_pin.app.diagnosis): a run that fails says whether an arm
went singular, torques went beyond the limits, or dt is too large; an unreachable pose says
when its quaternion looks w-first. Numbers checked against trajectory.npz and Pinocchio."""

from __future__ import annotations

import re

import numpy as np
import pinocchio as pin
import pytest
from hostile_scenarios import GRIPPERS_STRETCHED, two_ur5_welds
from run_helpers import run_cli, write

from multiarm_pin.app.diagnosis import w_first_hint
from multiarm_pin.app.scenario import load_scenario
from multiarm_pin.model.arm import Arm

THREE_DIGITS = 6e-3  # relative tolerance of a number printed with 3 significant digits


def test_dt_too_large_for_the_controller_is_named_before_and_after(tmp_path):
    """dt = 0.5 s with object_pd kp = 100, kd = 20 (double pole at -10 1/s): dt · rate = 5,
    beyond rk4's 2.785; the run fails (a failed solve) and the error names dt."""
    scenario = write(tmp_path / "dt.yaml", two_ur5_welds(name="dt", dt=0.5))
    proc = run_cli("run", scenario, "--out", tmp_path / "out", "--quiet", "--no-html")
    assert proc.returncode == 1, proc.stderr
    warn = next(line for line in proc.stderr.splitlines() if line.startswith("warning:")
                and "simulation.dt" in line)
    assert "rate 10 1/s" in warn and "dt · rate = 5," in warn and "rk4" in warn
    err = next(line for line in proc.stderr.splitlines() if line.startswith("error:"))
    assert "simulation failed" in err
    assert "likely cause: dt = 0.5 s is too large for the controller gains" in err


def test_a_gripper_stretched_through_its_singularity_is_named_with_time_and_torques(tmp_path):
    """The issue's case: a gripper stretched into its elbow singularity ends in an event
    storm; the error names the arm, the time and the torques, equal to those recomputed here
    from trajectory.npz, Pinocchio and the URDF."""
    scenario = write(tmp_path / "stretch.yaml", GRIPPERS_STRETCHED)
    out = tmp_path / "out"
    proc = run_cli("run", scenario, "--out", out, "--quiet", "--no-html")
    assert proc.returncode == 1, proc.stderr
    err = next(line for line in proc.stderr.splitlines() if line.startswith("error:"))
    assert "more than 50 contact events in one step" in err
    assert "likely cause: arm 'four_finger' is singular" in err, err
    m = re.search(r"arm 'four_finger' is singular: the smallest singular value of its tool "
                  r"Jacobian falls to (\S+) at t = (\S+) s \((\S+)x its (\S+) at t = 0\)", err)
    assert m, err
    smin, t_min, s0 = float(m[1]), float(m[2]), float(m[4])
    crossing = re.search(r"crosses a singularity \(det J changes sign\) between t = (\S+) s "
                         r"and (\S+) s", err)
    assert crossing, err
    traj = np.load(out / "trajectory.npz")
    t, q = traj["t"], traj["q_four_finger"]
    sc = load_scenario(scenario)
    arm = Arm.from_urdf(sc.arms[0].urdf, "tool0", name="x", base_placement=sc.arms[0].base,
                        load_visuals=False)

    def svd(k: int) -> tuple[np.ndarray, float]:
        J = pin.computeFrameJacobian(arm.model, arm.model.createData(), q[k], arm.tool_frame_id,
                                     pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        return np.linalg.svd(J, compute_uv=False), np.linalg.det(J)

    k = int(np.argmin(np.abs(t - t_min)))
    assert svd(k)[0].min() == pytest.approx(smin, rel=THREE_DIGITS)
    assert svd(0)[0].min() == pytest.approx(s0, rel=THREE_DIGITS)
    assert smin < 0.1 * s0
    a, b = (int(np.argmin(np.abs(t - float(x)))) for x in crossing.groups())
    assert b == a + 1 and np.sign(svd(a)[1]) != np.sign(svd(b)[1])
    assert q[a, 2] * q[b, 2] < 0  # the elbow angle passes through 0: the elbow singularity
    # the torques named are the recorded ones, against the URDF's effort limits
    tau = traj["tau_four_finger"]
    effort = np.array(arm.model.effortLimit)
    named = re.findall(r"arm 'four_finger' joint '(\w+)': (\S+) N m at t = (\S+) s, (\S+)x "
                       r"its effort limit (\S+) N m", err)
    assert named and named[0][0] == "shoulder_lift_joint", err
    assert float(named[0][3]) > 5  # far over the 200 N m limit
    for joint, value, t_peak, ratio, limit in named:
        c = arm.model.joints[arm.model.getJointId(joint)].idx_v
        k = int(np.argmin(np.abs(t - float(t_peak))))
        assert tau[k, c] == pytest.approx(float(value), rel=1e-4)
        assert float(limit) == effort[c]
        assert float(ratio) == pytest.approx(abs(tau[k, c]) / effort[c], rel=THREE_DIGITS)
        assert abs(tau[:, c]).max() == pytest.approx(abs(tau[k, c]), rel=1e-12)


def test_w_first_quaternion_of_the_object_is_pointed_out(tmp_path):
    """[1, 0, 0, 0] read as [x, y, z, w] turns the box upside down (out of the left arm's
    reach); reordered to [0, 0, 0, 1] the same pose is reachable: the error says so."""
    scenario = write(tmp_path / "wfirst.yaml", two_ur5_welds(name="wfirst",
                                                             quaternion="[1, 0, 0, 0]"))
    proc = run_cli("run", scenario, "--out", tmp_path / "out", "--quiet", "--no-html")
    assert proc.returncode == 2, proc.stderr
    assert "out of reach" in proc.stderr
    assert ("object.pose.quaternion [1, 0, 0, 0] may be written [w, x, y, z]: quaternions are "
            "[x, y, z, w], and reordered so, [0, 0, 0, 1], arm 'left' reaches its pose"
            in proc.stderr), proc.stderr


def test_w_first_look_is_pointed_out_even_when_reordering_does_not_help(tmp_path):
    sc = load_scenario(write(tmp_path / "w.yaml", two_ur5_welds(quaternion="[1, 0, 0, 0]")))
    hint = w_first_hint(sc, sc.arms[0], lambda spec, oMo: False)
    assert "object.pose.quaternion [1, 0, 0, 0] looks written [w, x, y, z] (first" in hint
    assert "did you mean [0, 0, 0, 1]?" in hint


def test_no_w_first_hint_for_an_xyzw_quaternion(tmp_path):
    """A quaternion that does not look w-first and is not rescued by reordering: no hint."""
    sc = load_scenario(write(tmp_path / "w.yaml", two_ur5_welds(
        quaternion="[0, 0, 0.3826834323650898, 0.9238795325112867]")))
    assert w_first_hint(sc, sc.arms[0], lambda spec, oMo: False) == ""


def test_an_identity_quaternion_is_never_retried_reordered(tmp_path):
    """[0, 0, 0, 1] is the identity as written: not blamed even if reordering would reach."""
    sc = load_scenario(write(tmp_path / "w.yaml", two_ur5_welds(quaternion="[0, 0, 0, 1]")))
    assert w_first_hint(sc, sc.arms[0], lambda spec, oMo: True) == ""


def test_a_w_first_joint_placement_is_retried_reordered(tmp_path):
    """The retried spec holds the written numbers read as (w, x, y, z) (Pinocchio's
    4-number constructor order), the object placement unchanged."""
    w, x = float(np.cos(0.4)), float(np.sin(0.4))  # 0.8 rad about x, written w-first
    text = two_ur5_welds().replace(
        "placement_in_object: {position: [0.0, 0.2, 0.0], rpy: [1.5707963267948966, 0, 0]}",
        f"placement_in_object: {{position: [0.0, 0.2, 0.0], quaternion: [{w!r}, {x!r}, 0, 0]}}")
    sc = load_scenario(write(tmp_path / "w.yaml", text))
    seen = []

    def reachable(spec, oMo):
        seen.append((spec, oMo))
        return True

    hint = w_first_hint(sc, sc.arms[0], reachable)
    assert "arms[0].joint.placement_in_object.quaternion" in hint and "reaches its pose" in hint
    (spec, oMo), = seen
    expected = pin.Quaternion(w, x, 0.0, 0.0).toRotationMatrix()
    np.testing.assert_allclose(spec.joint.placement_in_object.rotation, expected, atol=1e-12)
    np.testing.assert_allclose(spec.joint.placement_in_object.translation, [0, 0.2, 0])
    assert oMo.isApprox(sc.object.placement)
