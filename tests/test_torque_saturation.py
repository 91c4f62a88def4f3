"""Actuator saturation inside the dynamics: ``simulate(torque_limit=...)``.

Two welded UR5s hold an 80 kg box still under ``object_pd``: the shoulder needs 1.8 times its
URDF effort limit (150 N m), so the case is far from the threshold. References: the URDF's
limits, and the same run with the clipping done by a controller wrapper (the user's way),
which must give the same motion.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import multiarm_pin as mp
from multiarm_pin.exceptions import InputError

DURATION, DT = 0.3, 0.002


@pytest.fixture(scope="module")
def heavy():
    arms = [mp.load_arm("ur5", name="left", base=pin.SE3(np.eye(3), np.array([0.0, 0.55, 0.0])),
                        load_visuals=False),
            mp.load_arm("ur5", name="right",
                        base=pin.SE3(np.eye(3), np.array([0.0, -0.55, 0.0])), load_visuals=False)]
    box = mp.RigidObject.box(size=[0.8, 0.4, 0.3], mass=80.0)
    start = pin.SE3(np.eye(3), np.array([0.5, 0.0, 0.35]))
    grasp = [pin.SE3(pin.rpy.rpyToMatrix(np.pi / 2, 0, 0), np.array([0.0, 0.2, 0.0])),
             pin.SE3(pin.rpy.rpyToMatrix(-np.pi / 2, 0, 0), np.array([0.0, -0.2, 0.0]))]
    seed = [0.0, -1.2, 1.6, -0.4, 1.57, 0.0]
    q0 = [mp.ik_tool_placement(arm, start * g, seed).q for arm, g in zip(arms, grasp, strict=True)]
    system, state = mp.MultiArmSystem.from_initial_state(arms, box, ["weld", "weld"], q0, start)
    limit = np.concatenate([np.asarray(a.model.effortLimit, dtype=float)[: a.nv] for a in arms])
    return system, state, start, limit


def hold(system, start):
    still = mp.MinimumJerkTrajectory.through([0.0, DURATION], [start, start])
    return mp.make_controller("object_pd", system, trajectory=still)


class Clipped:
    """The user's way: a controller whose output is clipped (the independent reference)."""

    def __init__(self, inner, limit):
        self.inner, self.limit = inner, limit

    def __call__(self, t, state, evaluation):
        return np.clip(self.inner(t, state, evaluation), -self.limit, self.limit)


def test_saturated_torques_stay_within_the_urdf_limits_and_the_box_sags(heavy):
    system, state, start, limit = heavy
    assert limit.tolist() == [150.0, 150.0, 150.0, 28.0, 28.0, 28.0] * 2  # UR5's URDF
    free = mp.simulate(system, state, hold(system, start), DURATION, DT)
    sat = mp.simulate(system, state, hold(system, start), DURATION, DT, torque_limit=limit)
    # without saturation the box is held, far beyond the shoulder's limit
    assert np.abs(free.object_position - start.translation).max() < 1e-3
    assert (np.abs(free.tau) / limit).max() > 1.5
    assert free.torque_limit is None and np.array_equal(free.tau_commanded, free.tau)
    # with it, no applied torque exceeds its limit, the commanded ones do, and the box sags
    assert (np.abs(sat.tau) <= limit * (1.0 + 1e-12)).all()
    assert (np.abs(sat.tau_commanded) / limit).max() > 1.5
    assert np.array_equal(sat.tau, np.clip(sat.tau_commanded, -limit, limit))
    assert sat.object_position[-1, 2] < start.translation[2] - 0.01
    assert np.array_equal(sat.torque_limit, limit)
    assert any("torque saturation" in w for w in sat.warnings)


def test_saturation_inside_the_dynamics_equals_a_clipping_controller(heavy):
    system, state, start, limit = heavy
    sat = mp.simulate(system, state, hold(system, start), DURATION, DT, torque_limit=limit)
    user = mp.simulate(system, state, Clipped(hold(system, start), limit), DURATION, DT)
    scale = np.abs(user.q).max()
    assert np.abs(sat.q - user.q).max() < 1e-8 * scale
    assert np.abs(sat.object_position - user.object_position).max() < 1e-9
    assert np.abs(sat.tau - user.tau).max() < 1e-7 * limit.max()


def test_limits_without_effect_change_nothing(heavy):
    system, state, start, limit = heavy
    ref = mp.simulate(system, state, hold(system, start), 0.05, DT)
    wide = mp.simulate(system, state, hold(system, start), 0.05, DT,
                       torque_limit=np.full(system.nv, np.inf))
    assert np.abs(wide.q - ref.q).max() < 1e-9
    assert np.array_equal(wide.tau, wide.tau_commanded)


@pytest.mark.parametrize("bad", [np.zeros(12), -np.ones(12), np.ones(5), np.full(12, np.nan)])
def test_bad_limits_are_refused(heavy, bad):
    system, state, start, _ = heavy
    with pytest.raises(InputError, match="torque_limit"):
        mp.simulate(system, state, None, 0.01, DT, torque_limit=bad)


def test_a_scenario_saturates_with_limits_torque_saturate(tmp_path):
    """Through the command line: ``limits: {torque: saturate}`` on one UR5 holding 60 kg with
    ``object_pd`` (it needs more than twice its limits): the applied torques stay within the
    URDF efforts, the commanded ones are recorded beside them and exceed them."""
    import json

    from run_helpers import one_arm_scenario, run_cli, write

    sc = write(tmp_path / "s.yaml", one_arm_scenario(
        mass=60.0, duration=0.02, controller="{type: object_pd}",
        extra="limits: {torque: saturate}\n"))
    p = run_cli("run", sc, "--out", tmp_path / "out", "--no-html", "--quiet")
    assert p.returncode == 0, p.stderr
    with np.load(tmp_path / "out" / "trajectory.npz") as z:
        tau, cmd, lim = z["tau_a"], z["tau_commanded_a"], z["tau_limit_a"]
    assert lim.tolist() == [150.0, 150.0, 150.0, 28.0, 28.0, 28.0]
    assert (np.abs(tau) <= lim * (1.0 + 1e-12)).all()
    assert (np.abs(cmd) / lim).max() > 1.5
    assert np.array_equal(tau, np.clip(cmd, -lim, lim))
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert any("torque saturation" in w for w in s["warnings"])
    assert not any(v["kind"] == "torque" for v in s["violations"])  # applied: within


def test_saturate_is_only_a_torque_policy(tmp_path):
    from run_helpers import one_arm_scenario, run_cli, write

    sc = write(tmp_path / "s.yaml", one_arm_scenario(extra="limits: {velocity: saturate}\n"))
    p = run_cli("run", sc, "--out", tmp_path / "out", "--no-html", "--quiet")
    assert p.returncode == 2 and "limits.velocity" in p.stderr and "Traceback" not in p.stderr
