"""``object_pd``: object-level computed torque on the inverse dynamics with force distribution.

See :class:`ObjectPD` (the algorithm, step by step) and the package docstring of
:mod:`multiarm_pin.sim.controllers`. Its compiled path is
:mod:`multiarm_pin._compiled.controller_kernels`; :meth:`ObjectPD.reference` is the numpy
reference it mirrors. The module is long because the controller's two paths
(compiled and reference) and its hold-still fallback share its state and belong together.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from multiarm_pin._compiled import controller_kernels, layout
from multiarm_pin._compiled.controller_kernels import GRASP_RANK_TOLERANCE
from multiarm_pin.dynamics.blocks import (
    SystemBlocks,
    expand_rows,
    restrict_rows,
    select_rows,
)
from multiarm_pin.dynamics.force_distribution import distribute_forces
from multiarm_pin.dynamics.force_qp import WarmForceDistribution
from multiarm_pin.dynamics.inverse_dynamics import InverseDynamicsResult, inverse_dynamics
from multiarm_pin.exceptions import DynamicsError, InputError
from multiarm_pin.sim.controllers.base import Controller
from multiarm_pin.sim.controllers.base import gain as _gain
from multiarm_pin.sim.controllers.relative_motion import transported_acceleration
from multiarm_pin.sim.trajectories import MinimumJerkTrajectory, pose_error
from multiarm_pin.spatial import cross
from multiarm_pin.system import Evaluation, MultiArmSystem, SystemState

JACOBIAN_DAMPING = 1e-8
"""Damping ``ε`` of ``object_pd``'s least-squares hold ``(AᵀA + ε I)⁻¹ Aᵀ``, relative to the
mean diagonal of ``AᵀA`` (keeps it finite at singular poses; changes regular arms' solutions
by about ``ε/σ²_min`` relative)."""


def grasp_rank(blocks: SystemBlocks) -> int:
    """Rank of the stacked ``W_o`` of the blocks' rows (the wrenches the contacts can make).

    Decided structurally: the singular values of ``W_o`` with every column scaled to unit
    norm (a contact's unit force and its moment about the COM divided by the object's size
    would change nothing: the columns are ``[n; r × n]``) that exceed
    ``GRASP_RANK_TOLERANCE`` times the largest.

    Args:
        blocks: the system blocks (only ``W_o`` and ``N`` are used).

    Returns:
        The rank, 0..6; 6 means the contacts can produce any object wrench (with forces of
        either sign).
    """
    W_o = blocks.stacked_W_o()
    if W_o.shape[1] == 0:
        return 0
    norms = np.linalg.norm(W_o, axis=0)
    W_o = W_o[:, norms > 0] / norms[norms > 0]
    if W_o.shape[1] == 0:
        return 0
    sv = np.linalg.svd(W_o, compute_uv=False)
    return int((sv > GRASP_RANK_TOLERANCE * sv[0]).sum())
def _rank_reason(rank: int) -> str:
    """The warning's reason when the touching contacts' grasp rank is below 6."""
    return f"the touching contacts cannot make every object wrench (rank {rank} < 6)"


@dataclass(frozen=True)
class ObjectPDPlan:
    """What the compiled :class:`ObjectPD` planned at its last call.

    Attributes:
        tau: (n, nv_max) joint torques [N m] (zero on padding).
        mu: (n, N_max) planned contact multipliers [N] (positive = pushing).
        qdd: (n, nv_max) planned joint accelerations.
        a_o: (6,) desired object acceleration ``[ẍ; ω̇]`` at the COM, world axes.
    """

    tau: np.ndarray
    mu: np.ndarray
    qdd: np.ndarray
    a_o: np.ndarray


class ObjectPD(Controller):
    """Object-level computed torque on the inverse dynamics with force distribution.

    Primary objective: the object follows ``trajectory`` (PD on its pose). Secondary
    objective (the relative motion ``T_i α_i`` of thesis Sec 3.5): every contact's tip centre
    (a point fixed on the tool; for a tip carried by the object, the tool point under it at
    the first call) keeps its place *in the object frame* of the first call, so fingertips
    do not slide along their faces and joints do not drift. Three or more non-collinear
    points per tool (a rigid three-finger gripper, weld, revolute ...) hold the tool's whole
    pose relative to the object; fewer (one or two fingertips) hold only what the grasp
    needs and leave the tool's other motions to the joint PD, instead of dragging the arm
    along the object's rotation into a singularity. Per arm i and held point k (world
    position ``x_ik = p_i + d_ik``, ``r_ik = x_ik - x_o``):

    1. error ``e_ik = x_o + R_o s_ik - x_ik`` (``s_ik`` its object-frame place at the first
       call) and relative velocity ``u_ik = ẋ_ik - ẋ_o - ω_o × r_ik``;
    2. desired relative acceleration ``hold_kp e_ik - hold_kd u_ik`` (a PD on the point's
       coordinates in the object frame);
    3. desired point acceleration ``a_ik``: the linear part of
       :func:`tool_acceleration_from_object` (transport of ``a_d`` to ``r_ik``, plus
       ``2 ω_o × u_ik`` and step 2);
    4. with ``A_i`` the points' stacked Jacobian rows ``J_v + J_ω × d_ik`` and ``b_i`` their
       classical accelerations at ``q̈ = 0``:
       ``q̈_i = z_i + (A_iᵀ A_i + ε I)⁻¹ A_iᵀ (a_i - b_i - A_i z_i)``,
       ``z_i = null_kp (q_ref ⊖ q)_i - null_kd v_i`` (least squares, damped by
       :data:`JACOBIAN_DAMPING`; ``z_i`` survives only on the task's null space);
    5. :func:`~multiarm_pin.dynamics.inverse_dynamics.inverse_dynamics` takes the ``q̈_i``
       closest to these that satisfy the constraint rows, and returns the torques.

    Args:
        system: the system.
        trajectory: desired object pose over time (a :class:`MinimumJerkTrajectory`, or a
            mapping ``{"times", "positions", "quaternions"}``); hold the first call's pose if
            None.
        waypoints: instead of ``trajectory``, the object's COM-frame world poses
            ``[{t, position, quaternion | rpy}, ...]``
            (:meth:`MinimumJerkTrajectory.from_waypoints`; the pose of the first call is
            prepended at t = 0 when the first waypoint is later).
        kp: pose stiffness [1/s²], scalar or (6,) ``[x y z, rx ry rz]``.
        kd: pose damping [1/s], scalar or (6,).
        margin: least push [N] of every unilateral contact.
        null_kp: stiffness [1/s²] of the joint-space PD toward the first call's ``q``, acting
            only on the joint motions that leave the held points in place (redundant arms'
            self-motion, a single fingertip's rotation about its tip; none for a 6-joint arm
            with three fingertips). Before the relative hold existed it acted on all the
            joints' free motions, which let tips slide along the object; that role is now
            ``hold_kp``'s.
        null_kd: its damping [1/s].
        hold_kp: stiffness [1/s²] of the held points' positions relative to the object
            (step 2).
        hold_kd: its damping [1/s].
        compiled: use the compiled kernels on evaluations of the compiled path (default);
            False always runs :meth:`reference` (for tests and benchmarks).

    Attributes:
        last: the plan of the last call: ``tau``, ``mu`` (the planned forces), ``qdd``, ``a_o``
            (an :class:`ObjectPDPlan` from the compiled path, the
            :class:`~multiarm_pin.dynamics.inverse_dynamics.InverseDynamicsResult` of the
            reference).
        hold_mask: (n, m_max) bool, True for real held points (arm i has one per contact
            of its joint), None before the first call.
        hold_points_in_tool: (n, m_max, 3) held points in the tool frame [m].
        hold_points_in_object: (n, m_max, 3) their places in the object frame [m].
        last_point_acceleration: (n, m_max, 3) the desired point accelerations ``a_ik`` of
            the last call, world axes [m/s²] (meaningless on padding).
        margin_kept: False when the last call could not keep every unilateral contact
            pushing with ``margin`` (then it planned the least-norm forces, and the contacts
            that would have to pull separate in the simulation).
        holding: True when the last call held the arms still (see below).
        warnings: one message per onset of holding, with its time (the simulation adds
            them to its result's warnings).

    Touching contacts: when the evaluation carries the active set
    (:attr:`~multiarm_pin.system.Evaluation.active`, set by :func:`simulate`), the forces
    are planned and the inverse dynamics solved on the touching rows only
    (:func:`~multiarm_pin.dynamics.blocks.restrict_rows`); separated contacts get no force.
    When those rows cannot produce every object wrench (:func:`grasp_rank` < 6) or the
    inverse dynamics has no solution, the controller degrades gracefully instead of raising:
    it holds the arms still, ``τ = M (null_kp (q_h ⊖ q) - null_kd v) - h`` (computed-torque
    joint PD toward ``q_h``, the configuration at the onset, with gravity and velocity
    terms compensated and contact forces ignored), and records one warning per onset.
    """

    name = "object_pd"

    def __init__(self, system: MultiArmSystem, trajectory=None, kp=100.0, kd=20.0,
                 margin: float = 1.0, null_kp: float = 25.0, null_kd: float = 10.0,
                 hold_kp: float = 100.0, hold_kd: float = 20.0, compiled: bool = True,
                 waypoints=None):
        super().__init__(system)
        self.waypoints = None
        if waypoints is not None:
            if trajectory is not None:
                raise InputError("object_pd: give either waypoints or trajectory, not both")
            trajectory = MinimumJerkTrajectory.from_waypoints(waypoints)  # checks them
            if trajectory.times[0] > 0:  # starts from the first call's pose
                self.waypoints, trajectory = list(waypoints), None
        if trajectory is not None and not isinstance(trajectory, MinimumJerkTrajectory):
            try:
                trajectory = MinimumJerkTrajectory(**dict(trajectory))
            except TypeError as exc:
                raise InputError(
                    "object_pd trajectory: expected a MinimumJerkTrajectory or a mapping with "
                    f"times, positions and quaternions, got {trajectory!r}"
                ) from exc
        self.trajectory = trajectory
        self.kp = _gain(kp, 6, "object_pd kp")
        self.kd = _gain(kd, 6, "object_pd kd")
        self.null_kp = float(_gain(null_kp, 1, "object_pd null_kp")[0])
        self.null_kd = float(_gain(null_kd, 1, "object_pd null_kd")[0])
        self.hold_kp = float(_gain(hold_kp, 1, "object_pd hold_kp")[0])
        self.hold_kd = float(_gain(hold_kd, 1, "object_pd hold_kd")[0])
        if not (np.isfinite(margin) and margin >= 0):
            raise InputError(f"object_pd margin: expected a force >= 0 [N], got {margin!r}")
        self.margin = float(margin)
        self.q_ref: np.ndarray | None = None
        self.hold_mask: np.ndarray | None = None
        self.hold_points_in_tool: np.ndarray | None = None
        self.hold_points_in_object: np.ndarray | None = None
        self.last: InverseDynamicsResult | ObjectPDPlan | None = None
        self.last_point_acceleration: np.ndarray | None = None
        self.margin_kept = True
        self.holding = False
        self.warnings: list[str] = []
        self._q_hold: np.ndarray | None = None
        self.compiled = bool(compiled)
        self._forces: WarmForceDistribution | None = None
        self._motion_cache: dict = {}
        self._pd_step = None  # object_pd_step's pointer for touching_torques (made once)
        self._null_gains = np.zeros(2)  # kernel_inputs()' (null_kp, null_kd), kept while equal
        self._kernel_inputs: tuple | None = None  # the same tuple while its arrays are

    def _hold_still(self, t: float, state: SystemState, blocks: SystemBlocks,
                    reason: str) -> np.ndarray:
        """(nv,) torques [N m] holding the arms at the onset's configuration (fallback)."""
        s = self.system
        z = self._hold_acceleration(t, state, reason)
        tau = (blocks.M @ z[:, :, None])[:, :, 0] - blocks.h
        return s.unpad(np.where(blocks.dof_mask, tau, 0.0))

    def _hold_acceleration(self, t: float, state: SystemState, reason: str) -> np.ndarray:
        """Start holding (at the onset: ``q_h``, one warning) and return the hold's joint PD.

        Returns:
            (n, nv_max) ``z = null_kp (q_h ⊖ q) - null_kd v`` [rad/s²], zero on padding.
        """
        s = self.system
        if not self.holding:
            self.holding = True
            self._q_hold = np.array(state.q, dtype=float)
            self.warnings.append(f"t = {t:.6g} s: object_pd: {reason}; holding the arms still "
                                 "(gravity compensation and joint PD)")
        err = pin.difference(s.arm_set.model, state.q, self._q_hold)
        return s.pad(self.null_kp * err - self.null_kd * state.v)

    def _start_trajectory(self, o) -> MinimumJerkTrajectory:
        """At the first call: hold the object's pose ``o``, or go through the waypoints from it."""
        if self.waypoints is None:
            return MinimumJerkTrajectory.hold(o.position, o.quaternion)
        return MinimumJerkTrajectory.from_waypoints(self.waypoints, (o.position, o.quaternion))

    def desired_acceleration(self, t: float, state: SystemState) -> np.ndarray:
        """(6,) ``a_d = a_ref + K_d (v_ref - v_o) + K_p e`` [m/s², rad/s²], world at the COM."""
        o = state.obj
        if self.trajectory is None:
            self.trajectory = self._start_trajectory(o)
        ref = self.trajectory(t)
        e = pose_error(ref.position, ref.rotation, o.position, o.rotation)
        return ref.acceleration + self.kd * (ref.twist - o.twist) + self.kp * e

    def _init_hold(self, state: SystemState, evaluation: Evaluation) -> None:
        """Fix the held points: each contact's tip centre, as a tool-fixed point."""
        o = state.obj
        tools = evaluation.arms.tools
        points = []
        for i, joint in enumerate(self.system.joints):
            centres = []
            for c in joint.contacts:  # the tip centre in world, wherever it is carried
                if c.point_on == "tool":
                    centres.append(tools.position[i] + tools.rotation[i] @ c.point)
                else:
                    centres.append(o.position + o.rotation @ c.point)
            points.append(np.array(centres))
        m = max(len(c) for c in points)
        n = len(points)
        self.hold_mask = np.zeros((n, m), dtype=bool)
        self.hold_points_in_tool = np.zeros((n, m, 3))
        self.hold_points_in_object = np.zeros((n, m, 3))
        for i, c in enumerate(points):
            k = len(c)
            self.hold_mask[i, :k] = True
            self.hold_points_in_tool[i, :k] = (c - tools.position[i]) @ tools.rotation[i]
            self.hold_points_in_object[i, :k] = (c - o.position) @ o.rotation

    def hold_error(self, state: SystemState, evaluation: Evaluation
                   ) -> tuple[np.ndarray, np.ndarray]:
        """Held points' position errors and velocities relative to the object (step 1).

        The first call fixes the held points (``hold_points_in_tool``,
        ``hold_points_in_object``, ``hold_mask``).

        Args:
            state: the system state.
            evaluation: its evaluation (tool kinematics from ``evaluation.arms.tools``).

        Returns:
            ``(e, u)``, both (n, m_max, 3) world axes (zero on padding): ``e`` from each
            point to its held place on the object [m], ``u`` its velocity relative to the
            object's material point there, ``ṗ - ẋ_o - ω_o × r`` [m/s].
        """
        if self.hold_mask is None:
            self._init_hold(state, evaluation)
        return self._hold_terms(state, evaluation)[:2]

    def _hold_terms(self, state, evaluation):
        o = state.obj
        tools = evaluation.arms.tools
        d = np.einsum("nij,nmj->nmi", tools.rotation, self.hold_points_in_tool)
        x = tools.position[:, None] + d
        w_t = tools.twist[:, None, 3:]
        r = x - o.position
        u = tools.twist[:, None, :3] + cross(w_t, d) - o.twist[:3] - cross(o.twist[3:], r)
        e = o.position + self.hold_points_in_object @ o.rotation.T - x
        mask = self.hold_mask[:, :, None]
        return np.where(mask, e, 0.0), np.where(mask, u, 0.0), d, r

    def __call__(self, t, state, evaluation) -> np.ndarray:
        """(nv,) torques [N m].

        On an evaluation of the compiled path (:meth:`MultiArmSystem.blocks`) the torques come
        from :func:`~multiarm_pin._compiled.controller_kernels.object_pd_torques` (per-arm blocks,
        the
        force QP warm-started from the previous call's active set; with some contacts
        separated, :func:`~multiarm_pin._compiled.controller_kernels.touching_torques` or the
        hold-still fallback, see :meth:`closed_loop`); otherwise, or when the kernel reports a
        doubtful case, from :meth:`reference`. Both give the same torques (to round-off).
        """
        if self.q_ref is None:
            self.q_ref = np.array(state.q, dtype=float)
        if self.hold_mask is None:
            self._init_hold(state, evaluation)
        out = self.closed_loop(t, state, evaluation, False)
        if out is None:
            return self.reference(t, state, evaluation)
        return out[0]

    def closed_loop(self, t: float, state: SystemState, evaluation: Evaluation, solve: bool
                    ) -> tuple[np.ndarray, int] | None:
        """Torques by one compiled call and, if ``solve``, the forward dynamics they produce.

        :func:`multiarm_pin._compiled.controller_kernels.object_pd_step` on the buffer of a compiled
        evaluation; with ``solve`` the object-first solution of the blocks plus these torques
        is written into the buffer's solution segments (one shared evaluation, see
        :func:`multiarm_pin.sim.closed_loop.closed_loop_evaluation`).

        When the evaluation's active set leaves some contacts out, the torques are planned on
        the touching rows only (:func:`~multiarm_pin._compiled.controller_kernels.
        touching_torques`, as :meth:`reference` does), or, when those rows cannot make every
        object wrench, the arms are held still (the hold's bookkeeping and warning as in
        :meth:`reference`, the torques by :func:`~multiarm_pin._compiled.controller_kernels.
        hold_still_torques`). The forward dynamics is then the stepper's (a mixed LCP): only
        ``solve=False`` is served, ``solve=True`` returns None.

        Args:
            t: time [s].
            state: the state of ``evaluation``.
            evaluation: an evaluation of the compiled path at zero torque.
            solve: also solve the forward dynamics.

        Returns:
            ``(tau (nv,) [N m], solve_status)`` (``solve_status`` of
            :func:`multiarm_pin._compiled.object_first.object_first`, -1 if not solved), or None
            when the compiled path does not apply or reported a doubtful case (then call
            :meth:`reference`).
        """
        buffer = getattr(evaluation, "buffer", None) if self.compiled else None
        if buffer is None:
            return None
        active = getattr(evaluation, "active", None)
        if active is not None and np.all(np.asarray(active)[evaluation.blocks.constraint_mask]):
            active = None  # every contact touches
        if active is not None and solve:
            return None  # the forward dynamics is the stepper's mixed LCP, not object-first
        self.prepare(state, evaluation)
        s = self.system
        path = s.compiled
        o = state.obj
        t = float(t)
        ref = self._motion_cache.get(t)  # RK4 samples t + dt/2 twice, t + dt again next step
        if ref is None or ref[0] is not self.trajectory:
            p_ref, R_ref, v_ref, a_ref = self.trajectory.motion(t)
            ref = (self.trajectory, layout.reference_vector(p_ref, R_ref, v_ref, a_ref))
            if len(self._motion_cache) >= 4:
                self._motion_cache.pop(next(iter(self._motion_cache)))
            self._motion_cache[t] = ref
        err = pin.difference(s.arm_set.model, state.q, self.q_ref)
        z = s.pad(self.null_kp * err - self.null_kd * state.v)
        kshape, mshape = self._shapes
        tau = np.empty(kshape)
        mu = np.empty(mshape)
        qdd = np.empty(kshape)
        a_pts = np.zeros(self.hold_points_in_tool.shape)
        a_d = np.empty(6)
        obj = layout.object_state_vector(o.position, o.quaternion, o.twist)
        if active is not None:  # some contacts are separated: plan on the touching ones
            args = (buffer, path.dims, path.N, path.nv_arm, self._unilateral,
                    np.ascontiguousarray(active, dtype=bool), obj, ref[1], self._pd_gains, z,
                    self.hold_points_in_tool, self.hold_points_in_object, self._hold_n,
                    self._gains, self._touching_active, tau, mu, qdd, a_pts, a_d)
            if self._pd_step is None:
                self._pd_step = controller_kernels.touching_step(*args)
            status, rank = controller_kernels.touching_torques(*args, self._pd_step)
            if status == controller_kernels.PD_HOLD:
                z = self._hold_acceleration(t, state, _rank_reason(rank))
                controller_kernels.hold_still_torques(buffer, path.dims, path.nv_arm, z, tau)
                return s.unpad(tau), -1
            solved = -1
        else:
            status = controller_kernels.object_pd_step(
                buffer, path.dims, path.N, path.nv_arm, self._unilateral, obj, ref[1],
                self._pd_gains, z,
                self.hold_points_in_tool, self.hold_points_in_object, self._hold_n, self._gains,
                self._forces.active, tau, mu, qdd, a_pts, a_d)
            solved = -1
            if status == controller_kernels.PD_OK and solve:
                solved = controller_kernels.solve_with_torques(buffer, path.dims, path.N,
                                                               path.params, tau, np.zeros(6))
        if status != controller_kernels.PD_OK:
            if status == controller_kernels.PD_FORCES_FAILED and active is None:
                self._forces.cold_solves += 1
            return None
        self.last_point_acceleration = a_pts
        self.last = ObjectPDPlan(tau, mu, qdd, a_d)
        self.margin_kept = True  # the compiled QP solved with the margin
        self.holding = False  # the touching contacts make every object wrench again
        return s.unpad(tau), solved

    def prepare(self, state: SystemState, evaluation: Evaluation) -> None:
        """Fix what the first call fixes, without computing torques.

        The reference configuration, the held points (from the tools' placements in
        ``evaluation``, compiled or reference), the trajectory from the first pose when it
        starts from there, the force QP's warm start and the kernels' gain vectors; calls
        after the first change nothing. The compiled loop calls it on a reference
        evaluation of the initial state, so that a run needs no other compiled code.

        Args:
            state: the state of the first call.
            evaluation: its evaluation (only the tools' placements are read).
        """
        if self.q_ref is None:
            self.q_ref = np.array(state.q, dtype=float)
        if self.hold_mask is None:
            self._init_hold(state, evaluation)
        if self.trajectory is None:
            self.trajectory = self._start_trajectory(state.obj)
        if self._forces is None:
            s = self.system
            self._forces = WarmForceDistribution(s.compiled.N, s.unilateral)
            # the warm start of the QP on the touching rows only (its own: rows compacted)
            self._touching_active = np.zeros_like(self._forces.active)
            self._hold_n = self.hold_mask.sum(axis=1).astype(np.int64)
            self._gains = layout.hold_gain_vector(self.hold_kp, self.hold_kd, JACOBIAN_DAMPING,
                                                  self.margin)
            self._pd_gains = layout.pd_gain_vector(self.kp, self.kd)
            self._unilateral = np.ascontiguousarray(s.unilateral)
            self._shapes = ((s.n_arms, s.arm_set.nv_max), (s.n_arms, s.N_max))

    def kernel_inputs(self) -> tuple | None:
        """The controller's inputs of the compiled loop, or None before they exist.

        :func:`multiarm_pin._compiled.contact_loop.run_contact_rk4` runs this controller inside
        its steps on the same state as :meth:`closed_loop` (the same arrays: the force QP's
        warm start it updates is this controller's). They exist once the first call or
        :meth:`prepare` has fixed them (reference configuration, held points, trajectory, warm
        start); never with ``compiled=False``. The arrays are the same objects from call to
        call, in the same tuple, while the controller's values are the same (callers key on the
        tuple's identity).

        Returns:
            ``(trajectory table, pd gains, (null_kp, null_kd), hold_points_in_tool,
            hold_points_in_object, held points per arm, hold gains, warm start, unilateral,
            q_ref)`` (see :func:`~multiarm_pin._compiled.contact_loop.contact_stage`), or
            None.
        """
        if not self.compiled or self._forces is None or self.trajectory is None:
            return None
        null = self._null_gains
        kept = self._kernel_inputs
        if (kept is not None and null[0] == self.null_kp and null[1] == self.null_kd
                and kept[0] is self.trajectory.table() and kept[7] is self._forces.active
                and kept[9] is self.q_ref and kept[3] is self.hold_points_in_tool
                and kept[4] is self.hold_points_in_object):  # (the rest is fixed once)
            return kept
        if null[0] != self.null_kp or null[1] != self.null_kd:  # gains changed: a new array
            self._null_gains = null = np.array([self.null_kp, self.null_kd])
        # here one of the checked arrays is new (or none is kept yet): a new tuple
        self._kernel_inputs = (self.trajectory.table(), self._pd_gains, null,
                               self.hold_points_in_tool, self.hold_points_in_object,
                               self._hold_n, self._gains, self._forces.active,
                               self._unilateral, self.q_ref)
        return self._kernel_inputs

    def reference(self, t: float, state: SystemState, evaluation: Evaluation) -> np.ndarray:
        """(nv,) torques [N m] by the numpy reference (SVD basis, NNLS, batched numpy).

        The oracle of the compiled path of :meth:`__call__`, which falls back to it whenever
        the compiled kernels report a doubtful case; it raises the documented errors.
        """
        s = self.system
        b = evaluation.blocks
        o = state.obj
        if self.q_ref is None:
            self.q_ref = np.array(state.q, dtype=float)
        if self.hold_mask is None:
            self._init_hold(state, evaluation)
        if self.trajectory is None:  # fixed at the first call's pose, holding or not
            self.trajectory = self._start_trajectory(o)
        active = getattr(evaluation, "active", None)
        index = None
        unilateral = s.unilateral
        if active is not None and not np.all(np.asarray(active)[b.constraint_mask]):
            full = b
            b, index = restrict_rows(full, active)
            unilateral = select_rows(s.unilateral, index)
            rank = grasp_rank(b)
            if rank < 6:
                return self._hold_still(t, state, full, _rank_reason(rank))
        a_d = self.desired_acceleration(t, state)  # (not needed to hold the arms still)
        try:
            fd = distribute_forces(b, b.M_o @ a_d - b.h_o, unilateral, self.margin)
            self.margin_kept = True
        except DynamicsError:
            # The grasp cannot keep every unilateral contact pushing with the margin for this
            # load: plan the least-norm forces; a contact that would have to pull then
            # separates in the simulation (complementarity), it is not held by a pull.
            fd = distribute_forces(b, b.M_o @ a_d - b.h_o, np.zeros_like(s.unilateral), 0.0)
            self.margin_kept = False
        if self._forces is not None and index is None:  # next warm start: this active set
            self._forces.seed(fd.mu, self.margin)
        qdd_desired = self.joint_accelerations(state, evaluation, a_d)
        try:
            last = inverse_dynamics(b, a_d, qdd_desired, fd.mu_I, fd.basis)
        except DynamicsError as exc:
            return self._hold_still(t, state, evaluation.blocks,
                                    f"no inverse dynamics on the touching contacts ({exc})")
        if index is not None:  # multipliers back at the rows of the full blocks
            last = InverseDynamicsResult(last.tau, expand_rows(last.mu, index), last.qdd,
                                         last.a_o, last.mu_I, last.basis)
        self.last = last
        self.holding = False
        return s.unpad(last.tau)

    def joint_accelerations(self, state: SystemState, evaluation: Evaluation,
                            a_d: np.ndarray) -> np.ndarray:
        """(n, nv_max) desired joint accelerations of the held points' tasks (steps 1-4).

        Sets :attr:`last_point_acceleration`.

        Args:
            state: the state.
            evaluation: its evaluation (tools' kinematics, Jacobians).
            a_d: (6,) the object's desired acceleration, world axes at the COM.
        """
        s = self.system
        arms = evaluation.arms
        o = state.obj
        b = evaluation.blocks
        e, u, d, r = self._hold_terms(state, evaluation)
        n, m = self.hold_mask.shape
        zero = np.zeros((n * m, 3))
        rel_a = np.concatenate([self.hold_kp * e - self.hold_kd * u, np.zeros_like(e)], axis=2)
        a_pts = transported_acceleration(r.reshape(-1, 3), o.twist, a_d,
                                         np.concatenate([u.reshape(-1, 3), zero], axis=1),
                                         rel_a.reshape(-1, 6))[:, :3].reshape(n, m, 3)
        self.last_point_acceleration = a_pts
        # Task rows of the tool-fixed points: ṗ = v_t + ω_t × d, i.e. A = J_v + J_ω × d;
        # their classical acceleration at q̈ = 0: J̇q̇_v + J̇q̇_ω × d + ω_t × (ω_t × d).
        J = arms.J
        mask = self.hold_mask[:, :, None]
        A = J[:, None, :3, :] + cross(J[:, None, 3:, :].transpose(0, 1, 3, 2),
                                       d[:, :, None, :]).transpose(0, 1, 3, 2)
        A = np.where(mask[..., None], A, 0.0).reshape(n, 3 * m, -1)
        w_t = arms.tools.twist[:, None, 3:]
        Jdq = arms.Jdot_qdot
        a0 = Jdq[:, None, :3] + cross(Jdq[:, None, 3:], d) + cross(w_t, cross(w_t, d))
        rhs = np.where(mask, a_pts - a0, 0.0).reshape(n, 3 * m)
        # q̈ = z + (AᵀA + ε I)⁻¹ Aᵀ (rhs - A z), z the joint-space PD: the least-squares
        # hold, and z on the task's null space (one batched nv_max x nv_max solve).
        err = pin.difference(s.arm_set.model, state.q, self.q_ref)
        z = s.pad(self.null_kp * err - self.null_kd * state.v)
        At = A.transpose(0, 2, 1)
        AtA = At @ A
        scale = np.trace(AtA, axis1=1, axis2=2) / b.nv
        AtA += (JACOBIAN_DAMPING * scale)[:, None, None] * np.eye(AtA.shape[1])
        resid = rhs - (A @ z[:, :, None])[:, :, 0]
        return z + np.linalg.solve(AtA, (At @ resid[:, :, None]))[:, :, 0]


__all__ = ["GRASP_RANK_TOLERANCE", "JACOBIAN_DAMPING", "ObjectPD", "ObjectPDPlan", "grasp_rank"]
