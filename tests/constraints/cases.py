"""Random joints of every type, with tool and object trajectories starting assembled."""

from __future__ import annotations

import pinocchio as pin

from multiarm_pin.constraints import JOINT_TYPES, custom, fingertips_from_placements, make_joint
from multiarm_pin.model.polyhedron import box

from .trajectories import RigidTrajectory, random_rotation

FRAMED_KINDS = sorted(k for k, e in JOINT_TYPES.items() if e.placeable and not e.from_contacts)
"""Joint types placed by a joint frame, built from the initial state (weld, revolute, ...)."""
KINDS = FRAMED_KINDS + ["fingertips", "custom_sockets"]


def random_placement(rng, scale=0.3) -> pin.SE3:
    return pin.SE3(random_rotation(rng), rng.normal(size=3) * scale)


def random_joint(kind: str, rng, points_on: str = "tool"):
    """A joint of ``kind`` and the object's and tool's world placements at t = 0."""
    oMo = random_placement(rng)
    if kind == "fingertips":
        shape = box([0.4, 0.3, 0.2])
        contacts = [("+x", [0.2, 0.05, 0.03]), ("-x", [-0.2, -0.1, 0.0]),
                    ("+z", [0.1, 0.1, 0.1]), ("+z", [-0.1, 0.05, 0.1]), ("+y", [0.0, 0.15, -0.05]),
                    ("-y", [0.1, -0.15, 0.0]), ("-z", [0.0, 0.0, -0.1])]
        oMt = oMo * random_placement(rng, 0.1)
        joint = fingertips_from_placements(shape, contacts, 0.01, oMt, oMo)
        return joint, oMt, oMo
    J_in_object = random_placement(rng, 0.2)
    J_in_tool = random_placement(rng, 0.1)
    if kind == "custom_sockets":
        # a ball on the tool inside a socket and a shaft inside a bore, sphere-tipped,
        # some tips carried by the object
        contacts = [
            {"point": [0.1, 0, 0], "surface": {"type": "sphere", "center": [0, 0, 0],
                                               "radius": 0.1, "inside": True},
             "tip_radius": 0.01, "points_on": "object"},
            {"point": [0, 0.1, 0], "surface": {"type": "sphere", "center": [0, 0, 0],
                                               "radius": 0.1, "inside": True}},
            {"point": [0.05, 0.2, 0.3], "surface": {"type": "cylinder", "center": [0, 0.2, 0],
                                                    "axis": [0, 0, 1], "radius": 0.05,
                                                    "inside": True},
             "tip_radius": 0.005},
            {"point": [0.05, -0.05, 0.05], "surface": {"type": "plane", "point": [0, 0, 0.05],
                                                   "normal": [1, 1, 0]},
             "points_on": "object", "tip_radius": 0.02},
        ]
        joint = custom(contacts, J_in_object, J_in_tool)
    else:
        params = {"joint_in_object": J_in_object, "joint_in_tool": J_in_tool, "size": 0.08}
        if kind != "corner_gripper":
            params["points_on"] = points_on
            params["tip_radius"] = 0.01
        joint = make_joint(kind, **params)
    oMt = oMo * joint.tool_in_object
    return joint, oMt, oMo


def trajectories(rng, oMt, oMo, speed=0.2, spin=0.8):
    tool = RigidTrajectory(rng, oMt.translation, oMt.rotation, speed, spin)
    obj = RigidTrajectory(rng, oMo.translation, oMo.rotation, speed, spin)
    return tool, obj
