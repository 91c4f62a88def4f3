"""Constraint layer: frictionless point contacts, joints built from them, and their library.

Pure rigid-body kinematics between each arm's tool and the object (thesis ch. 3); signs and
frames follow docs/ARCHITECTURE.md. The hot path is :class:`ConstraintSet.evaluate`.
"""

from multiarm_pin.constraints.constraint_set import ConstraintSet, ConstraintTerms
from multiarm_pin.constraints.contact import Contact, ContactState
from multiarm_pin.constraints.fingertips import fingertips_from_placements, fingertips_on_faces
from multiarm_pin.constraints.joint import TWIST_NAMES, Joint, JointTerms
from multiarm_pin.constraints.joint_types import (
    JOINT_TYPES,
    JointType,
    joint_type,
    make_joint,
    make_joint_from_placements,
)
from multiarm_pin.constraints.library import (
    as_placement,
    corner_gripper,
    custom,
    cylindrical,
    prismatic,
    relative_placement,
    revolute,
    spherical,
    universal,
    weld,
    weld_from_placements,
)
from multiarm_pin.constraints.supports import Support, SupportSet, SupportTerms
from multiarm_pin.constraints.surfaces import Cylinder, Plane, Sphere, Surface, make_surface

__all__ = [
    "JOINT_TYPES",
    "TWIST_NAMES",
    "ConstraintSet",
    "ConstraintTerms",
    "Contact",
    "ContactState",
    "Cylinder",
    "Joint",
    "JointTerms",
    "JointType",
    "Plane",
    "Sphere",
    "Support",
    "SupportSet",
    "SupportTerms",
    "Surface",
    "as_placement",
    "corner_gripper",
    "custom",
    "cylindrical",
    "fingertips_from_placements",
    "fingertips_on_faces",
    "joint_type",
    "make_joint",
    "make_joint_from_placements",
    "make_surface",
    "prismatic",
    "relative_placement",
    "revolute",
    "spherical",
    "universal",
    "weld",
    "weld_from_placements",
]
