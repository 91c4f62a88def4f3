"""Real multi-arm systems for the system-level tests (a helper module, not a test file).

UR5 and Panda arms (Panda fingers locked) from example-robot-data on a circle around a box,
joints of every library type plus fingertips, held where the tools are at t = 0.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pinocchio as pin

from multiarm_pin.constraints import JOINT_TYPES
from multiarm_pin.model.arm import Arm, load_arm
from multiarm_pin.model.rigid_object import ObjectState, RigidObject
from multiarm_pin.model.robots import ROBOTS
from multiarm_pin.model.sources import load_example_robot
from multiarm_pin.system import MultiArmSystem, SystemState

Q_NOMINAL = {
    "ur5": np.array([0.0, -1.2, 1.5, -1.9, -1.57, 0.0]),
    "panda": np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]),
}
BOX_SIZE = (0.4, 0.3, 0.2)
FINGERTIP_CONTACTS = [("+x", [0.2, 0.05, 0.03]), ("-x", [-0.2, -0.1, 0.0]), ("+z", [0.1, 0.1, 0.1])]
JOINT_KINDS = sorted(k for k, e in JOINT_TYPES.items() if e.placeable and not e.from_contacts) + [
    "fingertips"]
"""Placeable joint types, framed ones sorted then fingertips (the order seeded draws use)."""


@cache
def make_arm(robot: str, name: str, angle: float, radius: float = 0.9) -> Arm:
    """An arm on a circle of ``radius`` around the origin, facing it (the public loader)."""
    base = pin.SE3(pin.rpy.rpyToMatrix(0, 0, angle + np.pi),
                   np.array([radius * np.cos(angle), radius * np.sin(angle), 0.0]))
    return load_arm(robot, name=name, base=base, load_visuals=False)


def joint_spec(kind: str):
    """A joint spec of the library (or fingertips) of size 8 cm."""
    if kind == "fingertips":
        return {"type": "fingertips", "contacts": FINGERTIP_CONTACTS, "radius": 0.01}
    if kind == "corner_gripper":
        return {"type": kind, "size": 0.08}
    return {"type": kind, "size": 0.08, "tip_radius": 0.01}


def build_system(robots, kinds, rng=None, gravity=(0.0, 0.0, -9.81), mass=5.0, spread=0.2,
                 object_position=(0.0, 0.0, 0.3), object_quaternion=(0, 0, 0, 1)):
    """Arms around the object, joints holding each tool where it is at t = 0 (at rest)."""
    n = len(robots)
    arms = [make_arm(r, f"{r}{i}", 2 * np.pi * i / n) for i, r in enumerate(robots)]
    q0 = [Q_NOMINAL[r] + (spread * rng.normal(size=len(Q_NOMINAL[r])) if rng is not None else 0)
          for r in robots]
    obj = RigidObject.box(BOX_SIZE, mass)
    specs = [joint_spec(k) if isinstance(k, str) else k for k in kinds]
    placement = pin.XYZQUATToSE3(np.concatenate([object_position, object_quaternion]))
    return MultiArmSystem.from_initial_state(arms, obj, specs, q0, placement, gravity)


def random_quaternion(rng):
    """A uniformly random unit quaternion [x, y, z, w]."""
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def moving_state(system, state, rng, speed=1.0):
    """``state`` with random velocities projected onto the constraints."""
    o = state.obj
    s = SystemState(state.q, speed * rng.normal(size=system.nv),
                    ObjectState(o.position, o.quaternion, speed * rng.normal(size=6)))
    return system.project_velocities(s)


def random_mixed_system(rng, n_arms, gravity=(0.0, 0.0, -9.81)):
    """UR5s and Pandas alternating, random joint types, a random object orientation."""
    robots = [("ur5", "panda")[i % 2] for i in range(n_arms)]
    kinds = [JOINT_KINDS[k] for k in rng.integers(len(JOINT_KINDS), size=n_arms)]
    return build_system(robots, kinds, rng, gravity, object_quaternion=random_quaternion(rng))


def one_dof_arm(name: str, angle: float) -> Arm:
    """A UR5 with all joints but the shoulder pan locked: one joint for six constraints."""
    # the registry's raw model (loaded once): the joints are locked at Q_NOMINAL, not neutral
    model, tool = load_example_robot("ur5")[0], ROBOTS["ur5"].tool_frame
    lock = [model.getJointId(j) for j in model.names[2:]]
    reduced = pin.buildReducedModel(model, lock, Q_NOMINAL["ur5"])
    base = pin.SE3(pin.rpy.rpyToMatrix(0, 0, angle + np.pi),
                   np.array([0.9 * np.cos(angle), 0.9 * np.sin(angle), 0.0]))
    return Arm.from_model(reduced, tool, name=name, base_placement=base)


def two_gripper_system():
    """The two-gripper 7-contact form-closure grasp at rest ``(system, state)``.

    ``scenarios/two_gripper_form_closure.yaml``: an MP6 with a four-finger gripper (arm 0,
    fingertip rows 0-3) and one with a three-finger gripper (arm 1, rows 0-2) on a 4 kg box.
    """
    from pathlib import Path

    import yaml

    from multiarm_pin.app.scenario import build_scenario, parse_scenario

    path = Path(__file__).resolve().parents[1] / "scenarios" / "two_gripper_form_closure.yaml"
    built = build_scenario(parse_scenario(yaml.safe_load(path.read_text()), str(path)))
    return built.system, built.initial_state
