"""A Pinocchio model as the int and float tables of the compiled rigid-body pass.

:class:`CompiledModel` holds, for the joints of a ``pin.Model`` and a list of its frames (the
tools), the tables read by :func:`multiarm_pin._compiled.rigid_body.rigid_body_pass` and its
``integrate`` / ``difference``; their columns are defined once in
:mod:`multiarm_pin._compiled.layout` (``MODEL_INT_FIELDS``, ``MODEL_FLOAT_FIELDS``,
``JOINT_KINDS``). Supported joints (:data:`SUPPORTED_JOINTS`): revolute about x, y, z or any
axis, prismatic along x, y, z or any axis, continuous revolute about x, y, z or any axis. A
model with another joint (spherical, free-flyer, planar, composite, mimic, helical...) raises
:class:`~multiarm_pin.exceptions.UnsupportedJointError`; :func:`is_supported` tells it in
advance so the caller can keep Pinocchio's path.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from multiarm_pin._compiled.layout import (
    ENERGY_SIZE,
    KIND_FRAME,
    KIND_PRISMATIC,
    KIND_REVOLUTE,
    KIND_REVOLUTE_UNBOUNDED,
    KIND_UNIVERSE,
    MF_ARMATURE,
    MF_AXIS,
    MF_GRAVITY,
    MF_INERTIA,
    MF_LEVER,
    MF_MASS,
    MF_PLACEMENT,
    MI_IDX_Q,
    MI_IDX_V,
    MI_KIND,
    MI_PARENT,
    MODEL_FLOATS,
    MODEL_INTS,
)
from multiarm_pin.exceptions import InputError, UnsupportedJointError

SUPPORTED_JOINTS: dict[str, int] = {
    **{f"JointModelR{a}": KIND_REVOLUTE for a in "XYZ"},
    "JointModelRevoluteUnaligned": KIND_REVOLUTE,
    **{f"JointModelP{a}": KIND_PRISMATIC for a in "XYZ"},
    "JointModelPrismaticUnaligned": KIND_PRISMATIC,
    **{f"JointModelRUB{a}": KIND_REVOLUTE_UNBOUNDED for a in "XYZ"},
    "JointModelRevoluteUnboundedUnaligned": KIND_REVOLUTE_UNBOUNDED,
}
"""Pinocchio joint types (``joint.shortname()``) of the compiled pass, and their kind."""


@dataclass(frozen=True)
class CompiledModel:
    """The tables of a Pinocchio model and its tool frames for the compiled rigid-body pass.

    Rows ``0..njoints-1`` are Pinocchio's joints (row 0 the universe, same indices), then one
    row per tool frame, in the order given to :meth:`build`.

    Attributes:
        ints: (njoints + n_tools, MODEL_INTS) int64, columns ``MI_*`` (read-only).
        floats: (njoints + n_tools, MODEL_FLOATS) float64, columns ``MF_*`` (read-only).
        njoints: Pinocchio's ``model.njoints`` (universe included).
        n_tools: number of tool frames.
        nq: configuration size.
        nv: velocity size.
    """

    ints: np.ndarray
    floats: np.ndarray
    njoints: int
    n_tools: int
    nq: int
    nv: int

    @classmethod
    def build(cls, model: pin.Model, tool_frame_ids) -> CompiledModel:
        """The tables of ``model`` and of its frames ``tool_frame_ids`` (in that order).

        Raises:
            UnsupportedJointError: the model has a joint outside :data:`SUPPORTED_JOINTS`.
            InputError: a tool frame id is not a frame of the model.
        """
        bad = unsupported_joints(model)
        if bad:
            name, kind = bad[0]
            raise UnsupportedJointError(name, kind, [n for n, _ in bad])
        tools = [int(f) for f in tool_frame_ids]
        for f in tools:
            if not 0 <= f < model.nframes:
                raise InputError(f"tool frame id {f}: expected a frame of the model "
                                 f"(0..{model.nframes - 1})")
        nj = model.njoints
        rows = nj + len(tools)
        ints = np.zeros((rows, MODEL_INTS), dtype=np.int64)
        floats = np.zeros((rows, MODEL_FLOATS))
        ints[0, MI_PARENT] = -1
        ints[0, MI_KIND] = KIND_UNIVERSE
        ints[0, MI_IDX_Q] = ints[0, MI_IDX_V] = -1
        _placement(floats[0], pin.SE3.Identity())
        floats[0, MF_GRAVITY:MF_GRAVITY + 6] = model.gravity.vector
        for j in range(1, nj):
            jm = model.joints[j]
            kind = SUPPORTED_JOINTS[jm.shortname()]
            ints[j, MI_PARENT] = model.parents[j]
            ints[j, MI_KIND] = kind
            ints[j, MI_IDX_Q] = jm.idx_q
            ints[j, MI_IDX_V] = jm.idx_v
            _placement(floats[j], model.jointPlacements[j])
            floats[j, MF_AXIS:MF_AXIS + 3] = _axis(jm, kind)
            inertia = model.inertias[j]
            floats[j, MF_MASS] = inertia.mass
            floats[j, MF_LEVER:MF_LEVER + 3] = inertia.lever
            floats[j, MF_INERTIA:MF_INERTIA + 9] = inertia.inertia.ravel()
            floats[j, MF_ARMATURE] = model.armature[jm.idx_v]
        for t, f in enumerate(tools):
            frame = model.frames[f]
            ints[nj + t, MI_PARENT] = frame.parentJoint
            ints[nj + t, MI_KIND] = KIND_FRAME
            ints[nj + t, MI_IDX_Q] = ints[nj + t, MI_IDX_V] = -1
            _placement(floats[nj + t], frame.placement)
        ints.setflags(write=False)
        floats.setflags(write=False)
        return cls(ints, floats, nj, len(tools), model.nq, model.nv)

    def outputs(self) -> tuple[np.ndarray, ...]:
        """Zeroed output arrays ``(J, dJ, M, nle, H, energy)`` of the pass.

        Shapes (6, nv), (6, nv), (nv, nv), (nv,), (n_tools, 4, 4), (ENERGY_SIZE,); ``M`` must
        stay zero where the pass does not write (joints of different arms or branches).
        """
        nv = self.nv
        return (np.zeros((6, nv)), np.zeros((6, nv)), np.zeros((nv, nv)), np.zeros(nv),
                np.zeros((self.n_tools, 4, 4)), np.zeros(ENERGY_SIZE))


def unsupported_joints(model: pin.Model) -> list[tuple[str, str]]:
    """``(name, type)`` of the model's joints that the compiled pass does not support."""
    return [(model.names[j], model.joints[j].shortname()) for j in range(1, model.njoints)
            if model.joints[j].shortname() not in SUPPORTED_JOINTS]


def is_supported(model: pin.Model) -> bool:
    """True when every joint of ``model`` is of a type of :data:`SUPPORTED_JOINTS`."""
    return not unsupported_joints(model)


def _placement(row: np.ndarray, placement: pin.SE3) -> None:
    """Write an SE3 into the placement columns (``[R | t]``, 3x4 row-major) of a table row."""
    row[MF_PLACEMENT:MF_PLACEMENT + 12] = placement.homogeneous[:3].ravel()


def _axis(joint, kind: int) -> np.ndarray:
    """(3,) unit axis of a supported joint in its own frame, read from its motion subspace.

    Pinocchio's Python bindings give no axis for every joint type (none for
    ``JointModelRevoluteUnboundedUnaligned``); the motion subspace ``S`` of any state holds it
    (angular rows for revolute joints, linear rows for prismatic ones).
    """
    data = joint.createData()
    q = np.zeros(joint.idx_q + joint.nq)  # the joint reads its own slice of a model's q
    q[joint.idx_q] = 1.0 if kind == KIND_REVOLUTE_UNBOUNDED else 0.0
    joint.calc(data, q)
    S = np.asarray(data.S).reshape(6)
    return S[:3].copy() if kind == KIND_PRISMATIC else S[3:].copy()
