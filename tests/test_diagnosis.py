"""Failures name their cause (multiarm_pin.app.diagnosis): a run that fails says whether an arm
went singular, torques went beyond the limits, or dt is too large; an unreachable pose says
when its quaternion looks w-first. Numbers checked against trajectory.npz and Pinocchio."""

from __future__ import annotations

import re

import numpy as np
import pinocchio as pin
import pytest
from hostile_scenarios import STRETCH_WAYPOINTS, two_ur5_welds
from run_helpers import run_cli, write

from multiarm_pin.app.diagnosis import w_first_hint
from multiarm_pin.app.scenario import load_scenario
from multiarm_pin.model.arm import Arm


def _ur5(base_y: float) -> Arm:
    base = pin.SE3(np.eye(3), np.array([0.0, base_y, 0.0]))
    return Arm.from_robot_name("ur5", "tool0", name="x", base_placement=base,
                               load_visuals=False)


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


def test_an_arm_stretched_through_its_singularity_is_named_with_time_and_torques(tmp_path):
    """The box carried out of reach: the left UR5's elbow passes through 0, the run fails;
    the error names the arm, the time and the torques, equal to those recomputed here."""
    scenario = write(tmp_path / "stretch.yaml", two_ur5_welds(
        name="stretch", waypoints=STRETCH_WAYPOINTS, duration=1.5))
    out = tmp_path / "out"
    proc = run_cli("run", scenario, "--out", out, "--quiet", "--no-html")
    assert proc.returncode == 1, proc.stderr
    err = next(line for line in proc.stderr.splitlines() if line.startswith("error:"))
    assert "likely cause: arm 'left' is singular" in err, err
    m = re.search(r"arm 'left' is singular: the smallest singular value of its tool Jacobian "
                  r"falls to (\S+) at t = (\S+) s \((\S+)x its (\S+) at t = 0\)", err)
    assert m, err
    smin, t_min, s0 = float(m[1]), float(m[2]), float(m[4])
    crossing = re.search(r"crosses a singularity \(det J changes sign\) between t = (\S+) s "
                         r"and (\S+) s", err)
    assert crossing, err
    traj = np.load(out / "trajectory.npz")
    t, q = traj["t"], traj["q_left"]
    arm = _ur5(0.55)

    def svd(k: int) -> tuple[np.ndarray, float]:
        J = pin.computeFrameJacobian(arm.model, arm.model.createData(), q[k], arm.tool_frame_id,
                                     pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        return np.linalg.svd(J, compute_uv=False), np.linalg.det(J)

    k = int(np.argmin(np.abs(t - t_min)))
    assert svd(k)[0].min() == pytest.approx(smin, rel=2e-3)
    assert svd(0)[0].min() == pytest.approx(s0, rel=2e-3)
    a, b = (int(np.argmin(np.abs(t - float(x)))) for x in crossing.groups())
    assert b == a + 1 and np.sign(svd(a)[1]) != np.sign(svd(b)[1])
    # the elbow angle passes through 0 there: the UR5's elbow singularity
    assert q[a, 2] * q[b, 2] < 0
    # the torques named are the recorded ones, against the URDF's effort limit
    tau = traj["tau_left"]
    effort = np.array(arm.model.effortLimit)
    named = re.findall(r"arm 'left' joint '(\w+)': (\S+) N m at t = (\S+) s, (\S+)x its "
                       r"effort limit (\S+) N m", err)
    assert named, err
    for joint, value, t_peak, ratio, limit in named:
        c = arm.model.joints[arm.model.getJointId(joint)].idx_v
        k = int(np.argmin(np.abs(t - float(t_peak))))
        assert tau[k, c] == pytest.approx(float(value), rel=1e-4)
        assert float(limit) == effort[c]
        assert float(ratio) == pytest.approx(abs(tau[k, c]) / effort[c], rel=2e-3)
        assert abs(tau[:, c]).max() == pytest.approx(abs(tau[k, c]), rel=1e-12)


def test_w_first_quaternion_of_the_object_is_pointed_out(tmp_path):
    """[1, 0, 0, 0] read as [x, y, z, w] turns the box upside down (out of the left arm's
    reach); reordered to [0, 0, 0, 1] the same pose is reachable: the error says so."""
    scenario = write(tmp_path / "wfirst.yaml", two_ur5_welds(name="wfirst",
                                                             quaternion="[1, 0, 0, 0]"))
    proc = run_cli("run", scenario, "--out", tmp_path / "out", "--quiet", "--no-html")
    assert proc.returncode == 2, proc.stderr
    assert "out of reach" in proc.stderr
    assert ("object.pose.quaternion [1, 0, 0, 0] looks written [w, x, y, z]: quaternions are "
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
