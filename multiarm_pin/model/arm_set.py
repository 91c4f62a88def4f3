"""All arms of a system evaluated together as one combined Pinocchio model.

Per-arm Python calls would dominate the cost of every dynamics evaluation. :class:`ArmSet`
appends every arm's model (base already baked in, names prefixed with ``<arm name>/``) into one
Pinocchio model with ``pin.appendModel``, so each Pinocchio algorithm (CRBA, nonlinear effects,
Jacobians and their time variation) is a single call whatever the number of arms. The per-arm
results are then gathered into stacked, padded arrays with a few numpy operations
(:meth:`ArmSet.evaluate`, the reference) or by the compiled kernels of
:mod:`multiarm_pin._compiled.arm_terms` (the hot path, after :meth:`ArmSet.pinocchio_pass`). Because
Pinocchio's cost per arm and its ``Data`` grow superlinearly in one combined model, the hot
path uses groups of at most :data:`GROUP_SIZE` arms, each with its own combined model.

State layout: ``q`` is the concatenation of the arms' configurations in arm order
(``ArmSet.q_slices``), ``v`` likewise (``ArmSet.v_slices``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from multiarm_pin._compiled.rigid_body import rigid_body_pass
from multiarm_pin.exceptions import InputError, UnsupportedJointError
from multiarm_pin.model.arm import Arm
from multiarm_pin.model.compiled_model import CompiledModel, is_supported, unsupported_joints
from multiarm_pin.model.kinematics import BodyKinematics
from multiarm_pin.spatial import as_array

GROUP_SIZE = 16
"""Most arms in one combined Pinocchio model of the hot path (:meth:`ArmSet.pinocchio_pass`).

Pinocchio 4.1's algorithms slow down per arm, and its ``Data`` grows superlinearly, with the
number of arms in one combined model; so larger systems are split into groups of at most 16
consecutive arms, each with its own combined model and ``Data``."""


@dataclass(frozen=True)
class ArmGroup:
    """Consecutive arms evaluated together in one combined Pinocchio model (hot path).

    Attributes:
        model: the group's combined model (the arms' bases baked in, names prefixed).
        data: its ``Data`` (written by :meth:`ArmSet.pinocchio_pass`).
        arms: slice of the group's arms in the arm order.
        q: slice of the group's configuration in the combined ``q``.
        v: slice of the group's velocity in the combined ``v``.
        tool_ids: frame ids of the group's tools in ``model``.
        views: ``(data.J, data.dJ, data.M, data.nle)`` numpy views, made once (Pinocchio
            writes these in place).
    """

    model: pin.Model
    data: pin.Data
    arms: slice
    q: slice
    v: slice
    tool_ids: list
    views: tuple


@dataclass(frozen=True)
class ArmSetTerms:
    """Stacked terms of n arms at one state; padded to ``nv_max`` degrees of freedom.

    Padded entries are zero, except ``M`` which has ones on its padded diagonal so that every
    block stays invertible.

    Attributes:
        M: (n, nv_max, nv_max) joint-space mass matrices [kg m^2].
        nle: (n, nv_max) nonlinear effects ``C v + g`` [N m].
        J: (n, 6, nv_max) tool Jacobians, LOCAL_WORLD_ALIGNED.
        Jdot_qdot: (n, 6) classical tool accelerations at zero joint acceleration, world axes.
        tools: :class:`BodyKinematics` of the n tool frames (world placements, LWA twists).
        v: (n, nv_max) joint velocities, padded.
    """

    M: np.ndarray
    nle: np.ndarray
    J: np.ndarray
    Jdot_qdot: np.ndarray
    tools: BodyKinematics
    v: np.ndarray


class ArmSet:
    """The arms of one system as a single combined Pinocchio model.

    Args:
        arms: the arms; their names must be unique.
        group_size: most arms per combined Pinocchio model of the hot path (None:
            :data:`GROUP_SIZE`); with more arms, :meth:`pinocchio_pass` runs on groups.
        gravity: (3,) gravity [m/s²] of every model and of the compiled tables (None: the
            first arm's model's).

    Attributes:
        model: the combined model of all arms.
        data: its ``Data``, created on first use when the arms are grouped (it grows
            superlinearly with the number of arms); :meth:`evaluate` and the energy/momentum helpers
            of the system use it, the hot path uses the groups'.
        groups: the :class:`ArmGroup` list (one group, sharing ``model`` and ``data``, when
            ``n <= group_size``).
        compiled_model: the tables of ``model`` and the n tool frames for the compiled
            rigid-body pass (:meth:`compiled_pass`), or None when a joint type is not
            supported there (then only Pinocchio's path is available).
    """

    def __init__(self, arms: list[Arm], group_size: int | None = None,
                 gravity: np.ndarray | None = None):
        if not arms:
            raise InputError("an ArmSet needs at least one arm")
        names = [a.name for a in arms]
        if len(set(names)) != len(names):
            raise InputError(f"arm names must be unique, got {names}")
        group_size = GROUP_SIZE if group_size is None else group_size
        if not (isinstance(group_size, int | np.integer) and group_size >= 1):
            raise InputError(f"group_size: expected a positive integer, got {group_size!r}")
        self.arms = list(arms)
        model = _combined(self.arms)
        self.model = model
        self._data = None
        self.n = len(arms)
        self.nq = model.nq
        self.nv = model.nv
        self.tool_frame_ids = np.array(
            [model.getFrameId(f"{a.name}/{a.model.frames[a.tool_frame_id].name}") for a in arms]
        )
        q_starts, v_starts, q0, v0 = [], [], 0, 0
        for a in arms:
            q_starts.append(q0)
            v_starts.append(v0)
            q0 += a.nq
            v0 += a.nv
        self.q_slices = [slice(s, s + a.nq) for s, a in zip(q_starts, arms, strict=True)]
        self.v_slices = [slice(s, s + a.nv) for s, a in zip(v_starts, arms, strict=True)]
        self.nv_arm = np.array([a.nv for a in arms])
        self.nv_max = int(self.nv_arm.max())
        # gather indices into the combined velocity vector, padded with index 0 and masked
        idx = np.zeros((self.n, self.nv_max), dtype=int)
        mask = np.zeros((self.n, self.nv_max), dtype=bool)
        support = np.zeros((self.n, self.nv_max), dtype=bool)
        for i, a in enumerate(arms):
            idx[i, : a.nv] = np.arange(v_starts[i], v_starts[i] + a.nv)
            mask[i, : a.nv] = True
            parent = model.frames[int(self.tool_frame_ids[i])].parentJoint
            for j in model.supports[parent]:
                if j == 0:
                    continue
                jm = model.joints[j]
                support[i, jm.idx_v - v_starts[i] : jm.idx_v - v_starts[i] + jm.nv] = True
        self._idx = idx
        self.dof_mask = mask
        self._support = support.astype(float)
        self._eye_pad = np.zeros((self.n, self.nv_max, self.nv_max))
        for i in range(self.n):
            pad = ~mask[i]
            self._eye_pad[i, pad, pad] = 1.0
        self._mask2 = (mask[:, :, None] & mask[:, None, :]).astype(float)
        self._mask_f = mask.astype(float)
        # fast path: every arm has nv_max joints and all of them move its tool, so the
        # stacked blocks are plain reshapes of Pinocchio's (column-major) matrices
        self._uniform = bool(mask.all() and support.all())
        k = self.nv_max
        self._block_rows = idx[:, :, None]
        self._block_cols = idx[:, None, :]
        self._diag_blocks = (np.arange(self.n)[:, None, None] * k + np.arange(k)[None, :, None],
                             np.arange(self.n)[:, None, None] * k + np.arange(k)[None, None, :])
        self._tool_ids = [int(f) for f in self.tool_frame_ids]
        self._views_of = None
        self._views: tuple = ()
        self.groups: list[ArmGroup] = []
        for a0 in range(0, self.n, int(group_size)):
            a1 = min(self.n, a0 + int(group_size))
            qs = slice(q_starts[a0], q_starts[a0] + sum(a.nq for a in arms[a0:a1]))
            vs = slice(v_starts[a0], v_starts[a0] + sum(a.nv for a in arms[a0:a1]))
            if a1 - a0 == self.n:
                gm, gd, ids = model, self.data, self._tool_ids
            else:
                gm = _combined(self.arms[a0:a1])
                gd = gm.createData()
                ids = [gm.getFrameId(f"{a.name}/{a.model.frames[a.tool_frame_id].name}")
                       for a in arms[a0:a1]]
            self.groups.append(ArmGroup(gm, gd, slice(a0, a1), qs, vs, ids,
                                        (gd.J, gd.dJ, gd.M, gd.nle)))
        self.v_starts = np.array(v_starts, dtype=np.int64)
        if gravity is not None:  # before the compiled tables, whose universe row carries it
            g = pin.Motion(as_array(gravity, (3,), "gravity [m/s^2]"), np.zeros(3))
            for m in {id(m): m for m in [model] + [gr.model for gr in self.groups]}.values():
                m.gravity = g
        self.compiled_model = (CompiledModel.build(model, self._tool_ids) if is_supported(model)
                               else None)
        self._compiled_out: tuple = ()

    @property
    def data(self) -> pin.Data:
        """``Data`` of the combined model of all arms (created on first use if grouped)."""
        if self._data is None:
            self._data = self.model.createData()
        return self._data

    @data.setter
    def data(self, value: pin.Data) -> None:
        self._data = value

    # ------------------------------------------------------------------ state helpers
    def neutral(self) -> np.ndarray:
        """(nq,) neutral configuration of all arms."""
        return pin.neutral(self.model)

    def stack_q(self, qs: list) -> np.ndarray:
        """Concatenate per-arm configurations into the combined ``q`` (nq,)."""
        if len(qs) != self.n:
            raise InputError(f"expected {self.n} configurations, got {len(qs)}")
        return np.concatenate(
            [as_array(q, (a.nq,), f"{a.name}: q") for q, a in zip(qs, self.arms, strict=True)]
        )

    def stack_v(self, vs: list) -> np.ndarray:
        """Concatenate per-arm velocities into the combined ``v`` (nv,)."""
        if len(vs) != self.n:
            raise InputError(f"expected {self.n} velocity vectors, got {len(vs)}")
        return np.concatenate(
            [as_array(v, (a.nv,), f"{a.name}: v") for v, a in zip(vs, self.arms, strict=True)]
        )

    def pad_v(self, v: np.ndarray) -> np.ndarray:
        """Combined (nv,) vector -> stacked, zero-padded (n, nv_max)."""
        return v[self._idx] * self._mask_f

    def unpad_v(self, x: np.ndarray) -> np.ndarray:
        """Stacked (n, nv_max) -> combined (nv,) (padding dropped)."""
        return x[self.dof_mask]

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, q: np.ndarray, v: np.ndarray) -> ArmSetTerms:
        """All arms' dynamic terms at the combined state ``(q, v)`` in one Pinocchio pass.

        Three Pinocchio calls on the combined model (Jacobians and their time variation, CRBA,
        nonlinear effects) whatever the number of arms, then a fixed number of numpy
        operations on stacked arrays. The only per-arm Python is reading the n tool frames'
        placements (Pinocchio exposes frame placements one at a time).

        Args:
            q: (nq,) combined configuration.
            v: (nv,) combined velocity.

        Returns:
            :class:`ArmSetTerms`, world frame, tool quantities LOCAL_WORLD_ALIGNED.
        """
        H = self._full_pass(q, v)
        data = self.data
        p = H[:, :3, 3]
        n, k = self.n, self.nv_max
        if self._uniform:
            # data.J, data.dJ are (6, nv) column-major: their transposes reshape for free
            Jw = data.J.T.reshape(n, k, 6).transpose(0, 2, 1)  # (n, 6, k) world, at origin
            dJw = data.dJ.T.reshape(n, k, 6).transpose(0, 2, 1)
            vp = v.reshape(n, k).copy()
            M = data.M[self._diag_blocks]
            nle = data.nle.reshape(n, k).copy()
        else:
            idx, sup = self._idx, self._support[:, None, :]
            Jw = data.J[:, idx].transpose(1, 0, 2) * sup  # (n, 6, nv_max) world, at origin
            dJw = data.dJ[:, idx].transpose(1, 0, 2) * sup
            vp = v[idx] * self._mask_f
            M = data.M[self._block_rows, self._block_cols] * self._mask2 + self._eye_pad
            nle = data.nle[idx] * self._mask_f
        # LWA Jacobian of the tool point: linear rows + (angular rows) × p, i.e. - p× ω-rows
        J = Jw.copy()
        J[:, :3] -= np.einsum("abc,nb,ncj->naj", _EPS, p, Jw[:, 3:])
        vcol = vp[:, :, None]
        twist = np.matmul(J, vcol)[:, :, 0]  # (n, 6) LWA tool twists
        acc = np.matmul(dJw, vcol)[:, :, 0]  # spatial acceleration at the world origin, q̈ = 0
        # classical acceleration of the tool point: a_O + α × p + ω × v_p
        acc[:, :3] += np.einsum("abc,nb,nc->na", _EPS, acc[:, 3:], p) + np.einsum(
            "abc,nb,nc->na", _EPS, twist[:, 3:], twist[:, :3])
        return ArmSetTerms(
            M=M,
            nle=nle,
            J=J,
            Jdot_qdot=acc,
            tools=BodyKinematics(p, H[:, :3, :3], twist),
            v=vp,
        )

    def pinocchio_pass(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The three Pinocchio calls of an evaluation, and the tools' world placements.

        Per group of arms (:attr:`groups`; one group for ``n <= GROUP_SIZE``), runs
        ``computeJointJacobiansTimeVariation`` (forward kinematics, ``data.J``,
        ``data.dJ``: world Jacobian columns at the world origin), ``crba`` (``data.M``, full
        symmetric) and ``nonLinearEffects`` (``data.nle``) on the group's combined model; the
        results stay in each group's ``data`` (``self.data`` for one group; read by
        :meth:`evaluate` and the compiled kernels of :mod:`multiarm_pin._compiled.arm_terms`).

        Tool placements: one ``pin.updateFramePlacement`` per tool, which updates the tools'
        frames only (``pin.updateFramePlacements`` updates every frame; composing
        ``data.oMi`` with the frame placements would be Python work per arm).

        Args:
            q: (nq,) combined configuration.
            v: (nv,) combined velocity.

        Returns:
            (n, 4, 4) homogeneous world placements of the n tool frames [m].
        """
        if len(self.groups) == 1:
            return self._full_pass(q, v)
        upd = pin.updateFramePlacement
        H = []
        for g in self.groups:  # results stay in each group's data
            model, data = g.model, g.data
            qg, vg = q[g.q], v[g.v]
            pin.computeJointJacobiansTimeVariation(model, data, qg, vg)
            pin.crba(model, data, qg)
            pin.nonLinearEffects(model, data, qg, vg)
            H.extend([upd(model, data, f).np for f in g.tool_ids])
        return np.array(H)

    def compiled_pass(self, q: np.ndarray, v: np.ndarray
                      ) -> tuple[np.ndarray, ...]:
        """The compiled equivalent of :meth:`pinocchio_pass` followed by :meth:`data_arrays`.

        One call of :func:`multiarm_pin._compiled.rigid_body.rigid_body_pass` on the combined
        model of all arms (no grouping: its cost is linear in the number of joints), into
        arrays owned by the ArmSet and overwritten by the next call.

        Args:
            q: (nq,) combined configuration.
            v: (nv,) combined velocity.

        Returns:
            ``(J, dJ, M, nle, H, energy)``: (6, nv) world Jacobian columns at the world
            origin and (6, nv) their time derivative (as ``data.J``, ``data.dJ``), (nv, nv)
            mass matrix (full symmetric, zero between arms), (nv,) nonlinear effects,
            (n, 4, 4) world placements of the n tool frames, the arms' kinetic and potential
            energy [J] and momentum (``ENERGY_FIELDS`` of :mod:`multiarm_pin._compiled.layout`).

        Raises:
            UnsupportedJointError: :attr:`compiled_model` is None (a joint type the compiled
                pass does not support).
        """
        cm = self.compiled_model
        if cm is None:
            name, kind = unsupported_joints(self.model)[0]
            raise UnsupportedJointError(name, kind)
        if not self._compiled_out:
            self._compiled_out = cm.outputs()
        rigid_body_pass(cm.ints, cm.floats, np.ascontiguousarray(q, dtype=float),
                        np.ascontiguousarray(v, dtype=float), *self._compiled_out)
        return self._compiled_out

    def _full_pass(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """:meth:`pinocchio_pass` on the model of all arms (``self.data``), ungrouped."""
        model, data = self.model, self.data
        pin.computeJointJacobiansTimeVariation(model, data, q, v)  # FK, J and dJ (world)
        pin.crba(model, data, q)
        pin.nonLinearEffects(model, data, q, v)
        upd = pin.updateFramePlacement
        return np.array([upd(model, data, f).np for f in self._tool_ids])  # (n, 4, 4)

    @property
    def joint_index(self) -> np.ndarray:
        """(n, nv_max) int: index of arm i's joint a in the combined velocity (0 on padding)."""
        return self._idx

    @property
    def tool_support(self) -> np.ndarray:
        """(n, nv_max) 1.0 where arm i's joint a moves its tool, 0.0 elsewhere and on padding."""
        return self._support

    def data_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Views of ``data.J`` (6, nv), ``data.dJ`` (6, nv), ``data.M`` (nv, nv), ``data.nle``.

        Pinocchio writes these in place (fixed sizes), so the views are made once per
        ``Data`` object (each attribute read of the bindings makes a new view) and remade if
        ``self.data`` is replaced. Valid while ``self.data`` is alive; read them after
        :meth:`pinocchio_pass`.
        """
        if self._views_of is not self.data:
            d = self.data
            self._views = (d.J, d.dJ, d.M, d.nle)
            self._views_of = d
        return self._views

    def gravity(self, q: np.ndarray) -> np.ndarray:
        """(n, nv_max) gravity torques of all arms at the combined configuration ``q`` [N m]."""
        return self.gravity_combined(q)[self._idx] * self._mask_f

    def gravity_combined(self, q: np.ndarray) -> np.ndarray:
        """(nv,) gravity torques of all arms at ``q`` [N m], computed per group."""
        if len(self.groups) == 1:
            return pin.computeGeneralizedGravity(self.model, self.data, q).copy()
        return np.concatenate([pin.computeGeneralizedGravity(g.model, g.data, q[g.q])
                               for g in self.groups])

    def tool_kinematics(self, q: np.ndarray, v: np.ndarray | None = None) -> BodyKinematics:
        """World placements and LWA twists of the n tools at ``(q, v)``."""
        v = np.zeros(self.nv) if v is None else v
        LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        p, R, tw = [], [], []
        for g in self.groups:
            pin.forwardKinematics(g.model, g.data, q[g.q], v[g.v])
            for f in g.tool_ids:
                m = pin.updateFramePlacement(g.model, g.data, int(f))
                p.append(m.translation.copy())
                R.append(m.rotation.copy())
                tw.append(pin.getFrameVelocity(g.model, g.data, int(f), LWA).vector.copy())
        return BodyKinematics(np.array(p), np.array(R), np.array(tw))


_EPS = np.zeros((3, 3, 3))
_EPS[0, 1, 2] = _EPS[1, 2, 0] = _EPS[2, 0, 1] = 1.0
_EPS[0, 2, 1] = _EPS[2, 1, 0] = _EPS[1, 0, 2] = -1.0
"""Levi-Civita symbol: ``(a × b)_i = ε_ijk a_j b_k`` (one einsum instead of ``np.cross``)."""


def _combined(arms: list[Arm]) -> pin.Model:
    """One Pinocchio model of the arms (names prefixed ``<arm name>/``), first arm's gravity."""
    model = pin.Model()
    model.gravity = arms[0].model.gravity
    for arm in arms:
        model = pin.appendModel(model, _prefixed(arm.model, f"{arm.name}/"), 0,
                                pin.SE3.Identity())
    return model


def _prefixed(model: pin.Model, prefix: str) -> pin.Model:
    """Copy of ``model`` with every joint and frame name (but the universe) prefixed."""
    out = pin.Model(model)
    for j in range(1, out.njoints):
        out.names[j] = prefix + out.names[j]
    for k in range(out.nframes):
        f = out.frames[k]
        if f.name == "universe":
            continue
        f.name = prefix + f.name
        out.frames[k] = f
    return out
