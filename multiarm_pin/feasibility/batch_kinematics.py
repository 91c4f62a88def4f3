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
    # joint-first while building (each joint's (T, 3, 3) block contiguous), returned as a
    # (T, njoints, ...) view
    R = np.empty((model.njoints, T, 3, 3))
    p = np.empty((model.njoints, T, 3))
    R[0], p[0] = np.eye(3), 0.0

    def times(A: np.ndarray, B: np.ndarray) -> np.ndarray:
        """(T, 3, 3) @ a constant (3, 3), as one (3T, 3) @ (3, 3) matrix product."""
        return (A.reshape(-1, 3) @ B).reshape(A.shape)

    for j in range(1, model.njoints):
        joint = model.joints[j]
        kind, axis = _axis(joint)
        parent = model.parents[j]
        M = model.jointPlacements[j]
        Rpar = R[parent]
        t = np.asarray(M.translation)
        pp = p[parent] + Rpar[..., 0] * t[0] + Rpar[..., 1] * t[1] + Rpar[..., 2] * t[2]
        i = joint.idx_q
        if kind in ("R", "RUB"):
            # Rp (I + sin K + (1 - cos) K²), K the axis' cross-product matrix
            cos, sin = ((np.cos(q[:, i]), np.sin(q[:, i])) if kind == "R"
                        else (q[:, i], q[:, i + 1]))
            K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                          [-axis[1], axis[0], 0.0]])
            Rm = np.asarray(M.rotation)
            R[j] = (times(Rpar, Rm) + sin[:, None, None] * times(Rpar, Rm @ K)
                    + (1.0 - cos)[:, None, None] * times(Rpar, Rm @ K @ K))
            p[j] = pp
        elif kind == "P":
            Rp = times(Rpar, np.asarray(M.rotation))
            R[j] = Rp
            p[j] = pp + (Rp[..., 0] * axis[0] + Rp[..., 1] * axis[1]
                         + Rp[..., 2] * axis[2]) * q[:, i, None]
        else:
            Rp = times(Rpar, np.asarray(M.rotation))
            Rj = Rotation.from_quat(q[:, i + 3:i + 7]).as_matrix()
            R[j] = Rp @ Rj
            p[j] = pp + np.einsum("tij,tj->ti", Rp, q[:, i:i + 3])
    return np.moveaxis(R, 0, 1), np.moveaxis(p, 0, 1)


__all__ = ["joint_placements"]
