"""Joint placements of a Pinocchio model at many configurations at once, vectorised in numpy.

The collision checks along a run need every link's placement at every recorded sample;
one ``pin.forwardKinematics`` call per sample, with each placement read back through the
Python bindings, costs more than the checks themselves. :func:`joint_placements` runs the
same recursion (``oMi[j] = oMi[parent] · jointPlacement[j] · M_j(q)``) on all samples at
once for the joint types of the arms (revolute and prismatic about x, y, z or any axis,
continuous revolute ``(cos θ, sin θ)``, and the free-flyer ``[x, y, z, qx, qy, qz, qw]``).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from multiarm_pin.exceptions import UnsupportedJointError

_AXES = {"X": np.array([1.0, 0.0, 0.0]), "Y": np.array([0.0, 1.0, 0.0]),
         "Z": np.array([0.0, 0.0, 1.0])}


def _axis(joint) -> tuple[str, np.ndarray]:
    """``("R" | "P" | "RUB" | "FF", axis (3,))`` of a joint model."""
    name = joint.shortname()[len("JointModel"):]
    if name == "FreeFlyer":
        return "FF", np.zeros(3)
    for kind in ("RUB", "R", "P"):
        rest = name[len(kind):]
        if name.startswith(kind) and rest in _AXES:
            return kind, _AXES[rest]
    if name in ("RevoluteUnaligned", "PrismaticUnaligned", "RevoluteUnboundedUnaligned"):
        kind = {"RevoluteUnaligned": "R", "PrismaticUnaligned": "P"}.get(name, "RUB")
        return kind, np.asarray(joint.extract().axis, float)
    raise UnsupportedJointError(joint.shortname(), joint.shortname())


def _rotations(axis: np.ndarray, cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations about a unit ``axis`` by angles of cosine ``cos``, sine ``sin``."""
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                  [-axis[1], axis[0], 0.0]])
    return (np.eye(3) + sin[:, None, None] * K
            + (1.0 - cos)[:, None, None] * (K @ K))


def joint_placements(model: pin.Model, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World placements of every joint of ``model`` at T configurations.

    Args:
        model: a Pinocchio model of the supported joint types.
        q: (T, nq) configurations.

    Returns:
        ``(R (T, njoints, 3, 3), p (T, njoints, 3))``: joint axes -> world axes and joint
        origins [m]; joint 0 is the world.

    Raises:
        UnsupportedJointError: a joint type outside those above.
    """
    q = np.asarray(q, float)
    T = len(q)
    R = np.empty((T, model.njoints, 3, 3))
    p = np.empty((T, model.njoints, 3))
    R[:, 0], p[:, 0] = np.eye(3), 0.0
    for j in range(1, model.njoints):
        joint = model.joints[j]
        kind, axis = _axis(joint)
        parent = model.parents[j]
        M = model.jointPlacements[j]
        Rp = R[:, parent] @ M.rotation
        pp = p[:, parent] + R[:, parent] @ M.translation
        i = joint.idx_q
        if kind == "R":
            Rj, tj = _rotations(axis, np.cos(q[:, i]), np.sin(q[:, i])), None
        elif kind == "RUB":
            Rj, tj = _rotations(axis, q[:, i], q[:, i + 1]), None
        elif kind == "P":
            Rj, tj = None, q[:, i, None] * axis
        else:
            Rj = Rotation.from_quat(q[:, i + 3:i + 7]).as_matrix()
            tj = q[:, i:i + 3]
        R[:, j] = Rp if Rj is None else Rp @ Rj
        p[:, j] = pp if tj is None else pp + np.einsum("tij,tj->ti", Rp, tj)
    return R, p


__all__ = ["joint_placements"]
