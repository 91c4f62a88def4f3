"""Models for the compiled rigid-body pass tests (a helper module, not a test file).

:func:`every_joint_model` builds, from a seeded generator, a Pinocchio model with every joint
type of :data:`multiarm_pin.model.compiled_model.SUPPORTED_JOINTS` (through a URDF, the only
way to get an unaligned continuous joint from Python), two kinematic trees, a branch, tilted
joint placements, off-centre and off-diagonal inertias and armatures. :func:`random_state`
draws a state of any supported model; :func:`pinocchio_pass` is the reference.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

# (name, parent link, URDF type, axis): the tree "a" (a branch at a3) and the tree "b"
_JOINTS = (
    ("a1", "world", "revolute", (1, 0, 0)),  # JointModelRX
    ("a2", "l_a1", "continuous", (0.6, 0.0, 0.8)),  # RevoluteUnboundedUnaligned
    ("a3", "l_a2", "prismatic", (0, 0, 1)),  # JointModelPZ
    ("a4", "l_a3", "revolute", (0.0, 0.8, -0.6)),  # RevoluteUnaligned
    ("a5", "l_a4", "continuous", (0, 1, 0)),  # JointModelRUBY
    ("a6", "l_a3", "prismatic", (0.48, 0.6, 0.64)),  # PrismaticUnaligned (second branch)
    ("a7", "l_a6", "revolute", (0, 1, 0)),  # JointModelRY
    ("b1", "world", "continuous", (1, 0, 0)),  # JointModelRUBX
    ("b2", "l_b1", "revolute", (0, 0, 1)),  # JointModelRZ
    ("b3", "l_b2", "prismatic", (1, 0, 0)),  # JointModelPX
    ("b4", "l_b3", "prismatic", (0, 1, 0)),  # JointModelPY
    ("b5", "l_b4", "continuous", (0, 0, 1)),  # JointModelRUBZ
)
TOOL_LINKS = ("l_a5", "l_a7", "l_b5")
"""Links of the tool frames of :func:`every_joint_model` (one per branch)."""


def _xyz(values) -> str:
    return " ".join(f"{x:.17g}" for x in values)


def _link(name: str, rng: np.random.Generator) -> str:
    """A link with a random mass, COM lever and (positive definite) inertia."""
    A = rng.normal(size=(3, 3))
    inertia = A @ A.T * 0.05 + 0.01 * np.eye(3)
    moments = " ".join(f'{key}="{inertia[r, c]:.17g}"' for key, r, c in (
        ("ixx", 0, 0), ("ixy", 0, 1), ("ixz", 0, 2), ("iyy", 1, 1), ("iyz", 1, 2), ("izz", 2, 2)))
    return (f'<link name="{name}"><inertial><origin xyz="{_xyz(rng.uniform(-0.2, 0.2, 3))}" '
            f'rpy="{_xyz(rng.uniform(-1, 1, 3))}"/><mass value="{rng.uniform(0.5, 3):.17g}"/>'
            f'<inertia {moments}/></inertial></link>')


def every_joint_model(rng: np.random.Generator) -> tuple[pin.Model, list[int]]:
    """The model of every supported joint type and its tool frame ids (:data:`TOOL_LINKS`).

    Two trees on the universe (``a``: 7 joints with a branch; ``b``: 5 joints), gravity
    tilted, armature on every joint.
    """
    parts = ['<robot name="every_joint"><link name="world"/>']
    for name, parent, kind, axis in _JOINTS:
        parts.append(_link(f"l_{name}", rng))
        limit = ('<limit lower="-2.5" upper="2.5" effort="10" velocity="5"/>'
                 if kind != "continuous" else "")
        parts.append(
            f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="l_{name}"/><origin xyz="{_xyz(rng.uniform(-0.4, 0.4, 3))}" '
            f'rpy="{_xyz(rng.uniform(-np.pi, np.pi, 3))}"/><axis xyz="{_xyz(axis)}"/>'
            f'{limit}</joint>')
    parts.append("</robot>")
    model = pin.buildModelFromXML("".join(parts))
    model.gravity = pin.Motion(np.array([0.5, -1.0, -9.7, 0.0, 0.0, 0.0]))
    model.armature = rng.uniform(0.0, 0.3, model.nv)
    return model, [model.getFrameId(link) for link in TOOL_LINKS]


def random_state(model: pin.Model, rng: np.random.Generator, speed: float = 1.0
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``(q, v)``: joints uniform within their limits (±π, ±0.5 m when unlimited), continuous
    joints at a uniform angle, velocities normal with standard deviation ``speed``."""
    q = np.empty(model.nq)
    for j in range(1, model.njoints):
        jm = model.joints[j]
        iq = jm.idx_q
        if jm.nq == 2:
            angle = rng.uniform(-np.pi, np.pi)
            q[iq], q[iq + 1] = np.cos(angle), np.sin(angle)
            continue
        lo, hi = model.lowerPositionLimit[iq], model.upperPositionLimit[iq]
        prismatic = jm.shortname().startswith("JointModelP")
        bound = 0.5 if prismatic else np.pi
        q[iq] = rng.uniform(max(lo, -bound), min(hi, bound))
    return q, speed * rng.normal(size=model.nv)


def pinocchio_pass(model: pin.Model, q: np.ndarray, v: np.ndarray, tool_ids
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The reference ``(J, dJ, M, nle, H)``: the calls of ``ArmSet.pinocchio_pass``, copied."""
    data = model.createData()
    pin.computeJointJacobiansTimeVariation(model, data, q, v)
    pin.crba(model, data, q)
    pin.nonLinearEffects(model, data, q, v)
    H = np.array([pin.updateFramePlacement(model, data, int(f)).np for f in tool_ids])
    return data.J.copy(), data.dJ.copy(), data.M.copy(), data.nle.copy(), H.reshape(-1, 4, 4)


def com_frames(model: pin.Model) -> tuple[pin.Model, list[int]]:
    """A copy of ``model`` with a frame at every body's COM (axes of the joint), and their ids.

    Joint ``j`` (1..njoints-1) gets the frame ``com_<j>``; the ids are in joint order.
    """
    out = pin.Model(model)
    ids = []
    for j in range(1, out.njoints):
        ids.append(out.addFrame(pin.Frame(f"com_{j}", j, 0, pin.SE3(np.eye(3),
                                          out.inertias[j].lever), pin.FrameType.OP_FRAME)))
    return out, ids
