"""Random multi-arm systems under ``object_pd`` for the closed-loop tests (a helper module).

Arms (UR5: 6 joints, Panda: 7, so padding occurs) on a circle around a box, every joint type
of the library plus fingertips, states moving and slightly off the constraint manifold.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pinocchio as pin
from system_builders import BOX_SIZE, JOINT_KINDS, Q_NOMINAL, joint_spec

from multiarm_pin.model.arm import Arm
from multiarm_pin.model.rigid_object import ObjectState, RigidObject
from multiarm_pin.sim.controllers import ObjectPD
from multiarm_pin.sim.trajectories import MinimumJerkTrajectory
from multiarm_pin.system import MultiArmSystem, SystemState


@cache
def arm(robot: str, i: int, n: int) -> Arm:
    """Arm ``i`` of ``n`` on a circle of radius 0.9 m around the origin, facing it."""
    angle = 2 * np.pi * i / n
    base = pin.SE3(pin.rpy.rpyToMatrix(0, 0, angle + np.pi),
                   np.array([0.9 * np.cos(angle), 0.9 * np.sin(angle), 0.0]))
    return Arm.from_robot_name(robot, name=f"{robot}{i}", base_placement=base)


def random_case(seed: int, n_arms: int, kinds=None):
    """``(system, state_at_rest, moving_off_state, trajectory)`` of a random system.

    ``kinds`` defaults to joint types drawn from :data:`JOINT_KINDS`; the object's
    trajectory moves it 5 cm and turns it 0.2 rad over 1 s.
    """
    rng = np.random.default_rng(seed)
    robots = [("ur5", "panda")[int(rng.integers(2))] for _ in range(n_arms)]
    if kinds is None:
        kinds = [JOINT_KINDS[int(rng.integers(len(JOINT_KINDS)))] for _ in range(n_arms)]
    q0 = [Q_NOMINAL[r] + 0.2 * rng.normal(size=len(Q_NOMINAL[r])) for r in robots]
    quat = rng.normal(size=4)
    quat /= np.linalg.norm(quat)
    system, state = MultiArmSystem.from_initial_state(
        [arm(r, i, n_arms) for i, r in enumerate(robots)], RigidObject.box(BOX_SIZE, 5.0),
        [joint_spec(k) for k in kinds], q0, pin.XYZQUATToSE3([0.0, 0.0, 0.3, *quat]),
        (0.3, -1.0, -9.0))
    o = state.obj
    moving = SystemState(state.q, rng.normal(size=system.nv),
                         ObjectState(o.position, o.quaternion, rng.normal(size=6)))
    moving = system.project_velocities(moving)
    off = SystemState(moving.q + 1e-3 * rng.normal(size=system.nq),
                      moving.v + 0.1 * rng.normal(size=system.nv),
                      ObjectState(o.position + 1e-3 * rng.normal(size=3), o.quaternion,
                                  moving.obj.twist))
    end = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, 0.0, 0.2)
                         @ pin.Quaternion(quat).toRotationMatrix()).coeffs()
    trajectory = MinimumJerkTrajectory([0.0, 1.0], [o.position, o.position + [0.05, 0, 0.03]],
                                       [quat, end])
    return system, state, off, trajectory


def object_pd(system, trajectory, **kw) -> ObjectPD:
    """An ``object_pd`` controller with non-zero null-space gains (every term acts)."""
    return ObjectPD(system, trajectory, margin=kw.pop("margin", 0.5), null_kp=25.0,
                    null_kd=10.0, **kw)
