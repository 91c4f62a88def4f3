"""Joint placements of a Pinocchio model at many configurations at once, vectorised in numpy.

The collision checks along a run need every link's placement at every recorded sample;
one ``pin.forwardKinematics`` call per sample, with each placement read back through the
Python bindings, costs more than the checks themselves. :func:`joint_placements` runs the
same recursion (``oMi[j] = oMi[parent] · jointPlacement[j] · M_j(q)``) on all samples at
once for the joint types of the arms (revolute and prismatic about x, y, z or any axis,
continuous revolute ``(cos θ, sin θ)``, and the free-flyer ``[x, y, z, qx, qy, qz, qw]``).

A model whose joints are those of the compiled rigid-body tables
(:class:`~multiarm_pin.model.compiled_model.CompiledModel`), and at most a last free flyer on
the universe at the identity (a collision scene's object), is placed by the compiled kernel
:func:`multiarm_pin._compiled.scan.joint_placements` instead (``nogil``: the collision scan
runs beside the simulation's loop); any other by the numpy recursion (decided by joint type,
:func:`placement_plan`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from multiarm_pin._compiled import scan as kernels
from multiarm_pin.exceptions import UnsupportedJointError
from multiarm_pin.model.compiled_model import CompiledModel, is_supported

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


@dataclass(frozen=True)
class PlacementPlan:
    """What :func:`joint_placements` needs of a model, read once (:func:`placement_plan`).

    Attributes:
        steps: per joint ``1 .. njoints - 1``: ``(kind, parent, idx_q, translation (3,), B,
            axis (3,))``, ``kind`` one of ``"R"``, ``"RUB"``, ``"P"``, ``"FF"`` and ``B`` its
            placement's rotation ``Rm`` (3, 3), for a revolute joint ``[Rm, Rm K, Rm K²]``
            (3, 9) (``K`` the axis' cross-product matrix): the numpy recursion's.
        tables: ``(ints, floats)`` the compiled kernel's joint rows (the model's joints but
            a last free flyer), or None: the kernel does not handle the model.
    """

    steps: tuple
    tables: tuple | None


def _compiled_tables(model: pin.Model) -> tuple | None:
    """The kernel's tables of ``model``, or None if it does not handle it (by joint type).

    Handled: joints of :class:`CompiledModel`'s kinds, and at most one free flyer, the last
    joint, on the universe at the identity and last in ``q``.
    """
    last = model.njoints - 1
    arms = model
    if last >= 1 and model.joints[last].shortname() == "JointModelFreeFlyer":
        if (model.parents[last] != 0 or not model.jointPlacements[last].isIdentity()
                or model.joints[last].idx_q != model.nq - 7):
            return None
        arms = pin.Model()  # the joints before it, rebuilt (their placements only)
        for j in range(1, last):
            arms.addJoint(int(model.parents[j]), model.joints[j], model.jointPlacements[j],
                          model.names[j])
    if not is_supported(arms):
        return None
    tables = CompiledModel.build(arms, [])
    return tables.ints, tables.floats


def placement_plan(model: pin.Model) -> PlacementPlan:
    """What :func:`joint_placements` needs of ``model``, read once (:class:`PlacementPlan`).

    Raises:
        UnsupportedJointError: a joint type outside those of :func:`joint_placements`.
    """
    plan = []
    for j in range(1, model.njoints):
        joint = model.joints[j]
        kind, axis = _axis(joint)
        M = model.jointPlacements[j]
        Rm = np.array(M.rotation)
        if kind in ("R", "RUB"):
            K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                          [-axis[1], axis[0], 0.0]])
            B = np.concatenate([Rm, Rm @ K, Rm @ K @ K], axis=1)
        else:
            B = Rm
        plan.append((kind, int(model.parents[j]), int(joint.idx_q),
                     np.array(M.translation), B, axis))
    return PlacementPlan(tuple(plan), _compiled_tables(model))


def joint_placements(model: pin.Model, q: np.ndarray, plan: PlacementPlan | None = None,
                     compiled: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """World placements of every joint of ``model`` at T configurations.

    Args:
        model: a Pinocchio model of the supported joint types.
        q: (T, nq) configurations.
        plan: ``placement_plan(model)``, if kept (read here otherwise).
        compiled: place with the compiled kernel when it handles the model (False: the
            numpy recursion, its reference).

    Returns:
        ``(R (T, njoints, 3, 3), p (T, njoints, 3))``: joint axes -> world axes and joint
        origins [m]; joint 0 is the world.

    Raises:
        UnsupportedJointError: a joint type outside those above.
    """
    q = np.asarray(q, float)
    T = len(q)
    if plan is None:
        plan = placement_plan(model)
    if compiled and plan.tables is not None:
        R = np.empty((T, model.njoints, 3, 3))
        p = np.empty((T, model.njoints, 3))
        kernels.joint_placements(plan.tables[0], plan.tables[1], np.ascontiguousarray(q), R, p)
        return R, p
    # joint-first while building (each joint's (T, 3, 3) block contiguous), returned as a
    # (T, njoints, ...) view
    R = np.empty((model.njoints, T, 3, 3))
    p = np.empty((model.njoints, T, 3))
    R[0], p[0] = np.eye(3), 0.0
    for j, (kind, parent, i, t, B, axis) in enumerate(plan.steps, start=1):
        Rpar = R[parent]
        pp = p[parent] + Rpar[..., 0] * t[0] + Rpar[..., 1] * t[1] + Rpar[..., 2] * t[2]
        # Rpar times a constant (3, 3) or (3, 9), as one (3T, 3) @ (3, k) matrix product
        RB = (Rpar.reshape(-1, 3) @ B).reshape(T, 3, -1)
        if kind in ("R", "RUB"):
            # Rp (I + sin K + (1 - cos) K²)
            cos, sin = ((np.cos(q[:, i]), np.sin(q[:, i])) if kind == "R"
                        else (q[:, i], q[:, i + 1]))
            R[j] = (RB[..., :3] + sin[:, None, None] * RB[..., 3:6]
                    + (1.0 - cos)[:, None, None] * RB[..., 6:])
            p[j] = pp
        elif kind == "P":
            R[j] = RB
            p[j] = pp + (RB[..., 0] * axis[0] + RB[..., 1] * axis[1]
                         + RB[..., 2] * axis[2]) * q[:, i, None]
        else:
            Rj = Rotation.from_quat(q[:, i + 3:i + 7]).as_matrix()
            R[j] = RB @ Rj
            p[j] = pp + np.einsum("tij,tj->ti", RB, q[:, i:i + 3])
    return np.moveaxis(R, 0, 1), np.moveaxis(p, 0, 1)


__all__ = ["PlacementPlan", "joint_placements", "placement_plan"]
