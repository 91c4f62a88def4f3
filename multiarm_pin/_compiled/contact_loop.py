"""The compiled loop of ``simulate``: RK4 or semi-implicit steps, contact events included.

Every run the compiled path serves, whatever its rows (bilateral, unilateral, supports), is
this loop. Mirrors, for RK4 and semi-implicit Euler, :class:`multiarm_pin.sim.stepper.Stepper`
(``evaluate`` on the active set, ``separations``, ``advance_with_events``, ``_impact``,
``_separate``) and :mod:`multiarm_pin.sim.event_location` (``illinois``, ``release``,
``locate_separation``, ``locate_touchdown``), with the rules and tolerances of
:mod:`multiarm_pin.sim.contact_events` passed in :data:`EVENT_CONSTANTS` order, so that a run
with fingertips or supports, separations, touchdowns and impacts is one compiled call per
stretch of samples instead of thousands of Python evaluations. It takes:

- systems with arms or without (an object on supports), with or without supports, their rows
  bilateral, unilateral or both;
- zero torque, or ``object_pd`` on its compiled path: every contact touching
  (:func:`~multiarm_pin._compiled.controller_kernels.object_pd_step`), some separated
  (:func:`~multiarm_pin._compiled.controller_kernels.touching_torques`), and its hold-still
  fallback when the touching contacts cannot make every object wrench; or ``phased_pd``
  (:func:`~multiarm_pin._compiled.phased.phased_torques`, the supports in its forces);
- an external wrench schedule;
- supports of finite extent while every support point is inside its rectangle at a step's
  start and end (then the rectangles change nothing the stepper decides: no off-edge event,
  no fallen row, every row watched as on a whole plane); a step with some point outside at
  either end is handed back (:data:`STAGE_OFF_RECTANGLE`). A point that leaves its rectangle
  and comes back within one step, or is outside only at an event located inside a step, is
  not seen (the stepper checks the same two ends for off-edge events, but also the state at a
  located touchdown);
- fingertips that start beside their face (``Stepper.beside_start``): kept out of the
  recorded penetration until they are above their face's plane or touch, as the stepper does.

One evaluation (:func:`contact_stage`): the arms' terms
(:func:`~multiarm_pin._compiled.rigid_body.rigid_body_pass`) and blocks at zero torque
(:func:`~multiarm_pin._compiled.evaluate.evaluate_system`), the controller's torques, the
support rows (``constraints/supports.py``), every row stacked as
``MultiArmSystem.contact_blocks`` stacks them (the arms' blocks, then one zero-dof support
block), and the mixed LCP of ``solve_unilateral``: the bilateral object-first solve when every
row is active, there are no supports and every arm has as many joints as rows, accepted when
every unilateral multiplier is ``>= 0``; otherwise the active-set kernel
(:func:`~multiarm_pin._compiled.delassus.contact_kernel`).

The evaluation, the rows alone, the controller's torques, the active-set kernel and the step
with its events are handed to :func:`run_contact_rk4` as function pointers
(:func:`loop_functions`): each is compiled once, on its own, and only the controller a run
uses.

Whatever the kernel cannot decide as the Python path would (a doubtful controller or solver
case, NaN, too many events in one step) it hands back: the status and the sample whose step
the Python stepper must take, with the state, the active set, the events and the
controller's hold state as they were at that sample (the step's partial work is dropped).

Twins: ``multiarm_pin.sim.contact_loop`` (this module's Python driver, the sim layer's side of
the same concept, the contact loop: its ``ContactLoop`` packs the inputs, calls
:func:`run_contact_rk4` and has the stepper take the steps handed back).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from multiarm_pin._compiled.assembly import object_terms
from multiarm_pin._compiled.controller_kernels import (
    NULL_KD,
    NULL_KP,
    PD_FORCES_FAILED,
    PD_HOLD,
    PD_OK,
    hold_still_torques,
    joint_pd,
    pd_step_compile,
    touching_torques,
)
from multiarm_pin._compiled.delassus import contact_kernel
from multiarm_pin._compiled.evaluate import (
    _block_segments,
    evaluate_system,
    quaternion_rotation,
    rotation_rows,
)
from multiarm_pin._compiled.function_pointers import (
    Compile,
    bind,
    compile_all,
    compile_of,
    compiled,
    numba_type,
    pointer,
    type_key,
)
from multiarm_pin._compiled.held import hold
from multiarm_pin._compiled.integrator import advance, advance_semi_implicit, tangent
from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.layout import (
    DIMS_K,
    DIMS_M,
    DIMS_N,
    DIMS_NV,
    EN_KINETIC,
    EN_MOMENTUM,
    EN_POTENTIAL,
    OBJECT_STATE_SIZE,
    P_BAUMGARTE_ALPHA,
    P_BAUMGARTE_BETA,
    P_BAUMGARTE_ON,
    P_GRAVITY,
    P_INERTIA,
    P_MASS,
    P_OBJECT_RCOND_TOL,
    P_RCOND_TOL,
    PLANE_HALF_EXTENT,
    PLANE_POINT,
    PLANE_X_AXIS,
    PLANE_Y_AXIS,
    ROW_NORMAL,
    ROW_PHI,
    ROW_PHI_DOT,
    ROW_POINT,
    SEG_M,
    WE_FROM,
    WE_TO,
    WE_WRENCH,
    X_POSITION,
    X_QUATERNION,
    X_TWIST,
    offsets,
    view3,
)
from multiarm_pin._compiled.linalg import copy1, copy2
from multiarm_pin._compiled.mlcp import OK as LCP_OK
from multiarm_pin._compiled.object_first import SOLVE_OK, object_first
from multiarm_pin._compiled.phased import callee_compiles as phased_callee_compiles
from multiarm_pin._compiled.phased import phased_torques
from multiarm_pin._compiled.rigid_body import difference, rigid_body_pass
from multiarm_pin._compiled.trajectory import reference_motion
from multiarm_pin._compiled.tuple_address import TupleAddress, address, tuple_at

STAGE_OK = 0
"""Status of the kernels: every evaluation decided here."""
STAGE_NOT_FINITE = 1
"""Status: NaN or infinity in a state (the Python path raises, naming the field)."""
STAGE_CONTROLLER = 2
"""Status: the compiled controller reported a doubtful case (its reference decides)."""
STAGE_SOLVE = 3
"""Status: the object-first solve or the active-set kernel reported a singular or badly
conditioned case."""
STAGE_TOO_MANY_EVENTS = 7
"""Status: more contact events in one step than the rules allow (the stepper raises)."""
STAGE_EVENTS_FULL = 8
"""Status: the event table is nearly full; the caller takes the events and calls again (no
step to take in Python)."""
STAGE_OFF_RECTANGLE = 9
"""Status: at this sample some point of a finite support's row is not inside its rectangle
(the stepper takes the step: off-edge events, fallen rows, rows not watched)."""
STAGE_EVENTS_NOT_COMPILED = 10
"""Status: the step needs what the loop was compiled without (:func:`loop_functions` with
``events`` False): a row that may leave or touch down, or the active-set solve. Nothing of
that sample's step is done; the caller makes the loop with its events and calls again from
that sample."""
NOT_COMPILED = -1
"""What the stand-ins of the event machinery return (:func:`_no_active_set`, the active-set
kernel's status; :func:`_no_touching`, ``touching_torques``' status): ``contact_stage`` and
:func:`_torques` then return :data:`STAGE_EVENTS_NOT_COMPILED`."""

CONTROL_NONE = 0
"""``control[CTL_MODE]``: zero torque."""
CONTROL_OBJECT_PD = 1
"""``control[CTL_MODE]``: ``object_pd`` on its compiled path."""
CONTROL_PHASED = 2
"""``control[CTL_MODE]``: ``phased_pd`` (:func:`~multiarm_pin._compiled.phased.phased_torques`)."""
CTL_MODE = 0
"""``control`` (int64 array): the controller mode."""
CTL_HOLDING = 1
"""``control``: 1 while ``object_pd`` holds the arms still (``ObjectPD.holding``)."""
CTL_MARGIN_KEPT = 2
"""``control``: 0 when the last ``object_pd`` call could not keep the margin
(``ObjectPD.margin_kept``)."""

SOLVER_BILATERAL = 0
"""A sample's solver code: the bilateral object-first solve (``"bilateral"``)."""
SOLVER_ACTIVE_SET = 1
"""A sample's solver code: the active-set method (``"active_set"``)."""

EVENT_SEPARATION = 0
"""Event kind code: ``"separation"``."""
EVENT_TOUCHDOWN = 1
"""Event kind code: ``"touchdown"``."""
EVENT_WIDTH = 8
"""Columns of the event table: time [s], kind, block, row, ``φ̇`` before, ``φ̇`` after
[m/s], impulse [N s], rebound (1.0 / 0.0)."""
HOLD_WIDTH = 2
"""Columns of the hold-onset table: time [s], rank of the touching contacts."""

EVENT_CONSTANTS = ("GAP_TOLERANCE", "LOST_GAP", "TIME_TOLERANCE", "LIFT_ACCELERATION",
                   "SEPARATION_TIME_TOLERANCE", "SEPARATION_ACCELERATION", "SEPARATION_GAP",
                   "SEPARATION_SPEED", "REBOUND_SPEED", "RESTING_SPEED",
                   "MAX_EVENTS_PER_STEP", "RESTING_RELEASE", "MAX_ITERATIONS",
                   "DEPENDENCY_RTOL", "VIOLATION_RTOL", "CONSISTENCY_RTOL")
"""The rules the kernel reads, in the order of its ``rules`` vector (the first eleven from
:mod:`multiarm_pin.sim.contact_events`, then :mod:`multiarm_pin.sim.event_location`'s and
the mixed LCP's tolerances)."""
(R_GAP, R_LOST, R_TIME, R_LIFT, R_SEP_TIME, R_SEP_ACC, R_SEP_GAP, R_SEP_SPEED, R_REBOUND,
 R_RESTING, R_MAX_EVENTS, R_RESTING_RELEASE, R_MAX_ITER, R_DEP, R_VIOL, R_CONS) = range(16)


# ------------------------------------------------------------------ one evaluation
@kernel(refcounts=False)
def wrench_at(t, wrenches, a):  # pragma: no cover - compiled
    """Component ``a`` of the external wrench at ``t`` [s] (``WrenchSchedule.__call__``).

    The sum over the intervals ``from <= t < to`` of the table (``WRENCH_FIELDS``).
    """
    out = 0.0
    for e in range(wrenches.shape[0]):
        if wrenches[e, WE_FROM] <= t < wrenches[e, WE_TO]:
            out = out + wrenches[e, WE_WRENCH + a]
    return out


def arm_compiles(x, model_ints, model_floats, J, dJ, M, nle, H, energy, arm_ints, v_starts,
                 ints, floats, params, dims, buf) -> tuple[Compile, Compile]:
    """The compiles of the rigid-body pass and of the system's evaluation, as the stages call them.

    The stage's rows (:func:`_rows_and_blocks`) and its controllers call
    :func:`~multiarm_pin._compiled.rigid_body.rigid_body_pass` and
    :func:`~multiarm_pin._compiled.evaluate.evaluate_system` through their addresses with
    these arguments (``q`` and ``v`` are parts of the state vector ``x``, (13 + nq + 2 nv,)).
    """
    nv = J.shape[1]
    q = x[OBJECT_STATE_SIZE:x.shape[0] - 2 * nv]
    v = x[x.shape[0] - 2 * nv:x.shape[0] - nv]
    return (compile_of(rigid_body_pass, (model_ints, model_floats, q, v, J, dJ, M, nle, H,
                                         energy), numba.types.none),
            compile_of(evaluate_system, (J, dJ, M, nle, H, x, arm_ints, v_starts, ints, floats,
                                         params, dims, buf), numba.types.boolean))


@kernel(refcounts=False)
def record_state(s, t, x, nq, nv, nv_arm, v_starts, tau, qdd, a_o, wrenches, r_q, r_v, r_p,
                 r_quat, r_tw, r_tau, r_qdd, r_a_o, r_wrench):  # pragma: no cover - compiled
    """Record sample ``s``'s state ``x``, torques, accelerations and external wrench.

    ``tau`` and ``qdd`` are padded per arm, ``(n, k)``; ``a_o`` (6,); the wrench is the one at
    ``t``; the record arrays as :func:`run_contact_rk4`'s ``Rec``.
    """
    q0 = OBJECT_STATE_SIZE
    v0 = q0 + nq
    for j in range(nq):
        r_q[s, j] = x[q0 + j]
    for j in range(nv):
        r_v[s, j] = x[v0 + j]
    for a in range(3):
        r_p[s, a] = x[X_POSITION + a]
    for a in range(4):
        r_quat[s, a] = x[X_QUATERNION + a]
    for a in range(6):
        r_tw[s, a] = x[X_TWIST + a]
        r_a_o[s, a] = a_o[a]
        r_wrench[s, a] = wrench_at(t, wrenches, a)
    for i in range(nv_arm.shape[0]):
        for a in range(nv_arm[i]):
            j = v_starts[i] + a
            r_tau[s, j] = tau[i, a]
            r_qdd[s, j] = qdd[i, a]


@kernel(refcounts=False)
def record_energy(s, x, params, energy, arms, r_kinetic, r_potential, r_momentum
                  ):  # pragma: no cover - compiled
    """Record sample ``s``'s kinetic and potential energy and momentum.

    The object's, plus the arms' ``energy`` (:func:`~.rigid_body.rigid_body_pass`'s) when
    ``arms``. The object's: ``½ m |ẋ|² + ½ ωᵀ I_w ω``, ``-m g·x``, ``[m ẋ; I_w ω + x × m ẋ]``
    (``I_w = R I_c Rᵀ``); the potential is zero at the origin.
    """
    R = rotation_rows(x[X_QUATERNION:X_QUATERNION + 4])
    mass = params[P_MASS]
    w = (x[X_TWIST + 3], x[X_TWIST + 4], x[X_TWIST + 5])
    b = (R[0][0] * w[0] + R[1][0] * w[1] + R[2][0] * w[2],  # Rᵀ ω
         R[0][1] * w[0] + R[1][1] * w[1] + R[2][1] * w[2],
         R[0][2] * w[0] + R[1][2] * w[1] + R[2][2] * w[2])
    i0 = P_INERTIA
    c = (params[i0] * b[0] + params[i0 + 1] * b[1] + params[i0 + 2] * b[2],  # I_c Rᵀ ω
         params[i0 + 3] * b[0] + params[i0 + 4] * b[1] + params[i0 + 5] * b[2],
         params[i0 + 6] * b[0] + params[i0 + 7] * b[1] + params[i0 + 8] * b[2])
    L = (R[0][0] * c[0] + R[0][1] * c[1] + R[0][2] * c[2],  # I_w ω = R I_c Rᵀ ω
         R[1][0] * c[0] + R[1][1] * c[1] + R[1][2] * c[2],
         R[2][0] * c[0] + R[2][1] * c[1] + R[2][2] * c[2])
    p_lin = (mass * x[X_TWIST], mass * x[X_TWIST + 1], mass * x[X_TWIST + 2])
    ke = energy[EN_KINETIC] if arms else 0.0
    pe = energy[EN_POTENTIAL] if arms else 0.0
    for a in range(3):
        ke += 0.5 * (mass * x[X_TWIST + a] * x[X_TWIST + a] + w[a] * L[a])
        pe -= mass * params[P_GRAVITY + a] * x[X_POSITION + a]
    for a in range(3):
        c1, c2 = (a + 1) % 3, (a + 2) % 3
        lin = energy[EN_MOMENTUM + a] if arms else 0.0
        ang = energy[EN_MOMENTUM + 3 + a] if arms else 0.0
        r_momentum[s, a] = lin + p_lin[a]
        r_momentum[s, 3 + a] = (ang + L[a] + x[X_POSITION + c1] * p_lin[c2]
                                - x[X_POSITION + c2] * p_lin[c1])
    r_kinetic[s] = ke
    r_potential[s] = pe


@kernel(refcounts=False)
def _support_rows(x, sp_p, sp_n, sp_a, params, b, rows_phi, rows_phi_dot, pts, nrm, W_o,
                  c):  # pragma: no cover - compiled
    """The support rows of block ``b`` at ``x`` (``SupportSet.evaluate`` and the stacking).

    ``W_o[b, :, r] = [n; r × n]``, ``c[b, r] = -κ - 2α φ̇ - β² φ`` (Baumgarte when on).
    """
    R = rotation_rows(x[X_QUATERNION:X_QUATERNION + 4])
    wx, wy, wz = x[X_TWIST + 3], x[X_TWIST + 4], x[X_TWIST + 5]
    on = params[P_BAUMGARTE_ON] != 0.0
    al, be = params[P_BAUMGARTE_ALPHA], params[P_BAUMGARTE_BETA]
    for j in range(sp_p.shape[0]):
        r0 = R[0][0] * sp_p[j, 0] + R[0][1] * sp_p[j, 1] + R[0][2] * sp_p[j, 2]
        r1 = R[1][0] * sp_p[j, 0] + R[1][1] * sp_p[j, 1] + R[1][2] * sp_p[j, 2]
        r2 = R[2][0] * sp_p[j, 0] + R[2][1] * sp_p[j, 1] + R[2][2] * sp_p[j, 2]
        n0, n1, n2 = sp_n[j, 0], sp_n[j, 1], sp_n[j, 2]
        p0, p1, p2 = x[X_POSITION] + r0, x[X_POSITION + 1] + r1, x[X_POSITION + 2] + r2
        g3 = r1 * n2 - r2 * n1
        g4 = r2 * n0 - r0 * n2
        g5 = r0 * n1 - r1 * n0
        u0 = wy * r2 - wz * r1
        u1 = wz * r0 - wx * r2
        u2 = wx * r1 - wy * r0
        kappa = (n0 * (wy * u2 - wz * u1) + n1 * (wz * u0 - wx * u2)
                 + n2 * (wx * u1 - wy * u0))
        phi = n0 * (p0 - sp_a[j, 0]) + n1 * (p1 - sp_a[j, 1]) + n2 * (p2 - sp_a[j, 2])
        phi_dot = (n0 * x[X_TWIST] + n1 * x[X_TWIST + 1] + n2 * x[X_TWIST + 2]
                   + g3 * wx + g4 * wy + g5 * wz)
        rows_phi[b, j] = phi
        rows_phi_dot[b, j] = phi_dot
        pts[b, j, 0], pts[b, j, 1], pts[b, j, 2] = p0, p1, p2
        nrm[b, j, 0], nrm[b, j, 1], nrm[b, j, 2] = n0, n1, n2
        W_o[b, 0, j], W_o[b, 1, j], W_o[b, 2, j] = n0, n1, n2
        W_o[b, 3, j], W_o[b, 4, j], W_o[b, 5, j] = g3, g4, g5
        cs = -kappa
        if on:
            cs = cs - 2.0 * al * phi_dot - be * be * phi
        c[b, j] = cs


@kernel
def _object_terms(x, params, M_o, h_o):  # pragma: no cover - compiled
    """``M_o``, ``h_o`` of the object alone at ``x`` (:func:`~.assembly.object_terms`)."""
    R = np.empty((3, 3))
    quaternion_rotation(x[X_QUATERNION:X_QUATERNION + 4], R)
    object_terms(params[P_MASS], params[P_INERTIA:P_INERTIA + 9].reshape((3, 3)),
                 params[P_GRAVITY:P_GRAVITY + 3], R, x[X_TWIST:X_TWIST + 6], M_o, h_o)


@kernel(refcounts=False)  # allocates nothing: see multiarm_pin._compiled.jit
def _rows_and_blocks(x, sy, wk, callees):  # pragma: no cover - compiled
    """Every row and the stacked blocks at ``x``, at zero torque (no controller call).

    ``sy``: the system tuple (see :func:`run_contact_rk4`); ``wk``: the workspace tuple;
    ``callees``: as :func:`stage_compiles` makes them (the rigid-body pass and the system's
    evaluation first). Fills the stacked ``M, h, W, W_o, c, M_o, h_o`` (no wrench) and the
    rows; returns False on NaN. For a system with arms; without arms
    :func:`_object_rows_and_blocks` (the loops call the one :func:`stage_compiles` picked,
    through its address: the other is not compiled).
    """
    (model_ints, model_floats, arm_ints, v_starts, ints, floats, params, dims, N, nv_arm,
     sp_p, sp_n, sp_a, uni_c, mask_c, nv_c, N_c, rest_c, wrenches, rules) = tuple_at(sy)
    (J, dJ, Mq, nle, H, energy, buf, Mc, hc, Wc, W_oc, cc, M_o, h_o, phi, phi_dot, pts,
     nrm) = tuple_at(wk)
    k, m, nv, n = dims[DIMS_K], dims[DIMS_M], dims[DIMS_NV], dims[DIMS_N]
    B, kc, R = Wc.shape
    nq = x.shape[0] - OBJECT_STATE_SIZE - 2 * nv
    q0 = OBJECT_STATE_SIZE
    callees[0](model_ints, model_floats, x[q0:q0 + nq], x[q0 + nq:q0 + nq + nv], J, dJ, Mq, nle,
               H, energy)
    if not callees[1](J, dJ, Mq, nle, H, x, arm_ints, v_starts, ints, floats, params, dims, buf):
        return False
    off = offsets(dims)
    Ma = view3(buf, off, SEG_M, n, k, m)
    rows, ha, Wa, W_oa, ca, Mo, ho = _block_segments(buf, off, n, k, m)
    for i in range(n):
        for a in range(k):
            hc[i, a] = ha[i, a]
            for b in range(k):
                Mc[i, a, b] = Ma[i, a, b]
            for r in range(R):
                Wc[i, a, r] = Wa[i, a, r] if r < m else 0.0
        for r in range(R):
            inside = r < m
            for a in range(6):
                W_oc[i, a, r] = W_oa[i, a, r] if inside else 0.0
            cc[i, r] = ca[i, r] if inside else 0.0
            phi[i, r] = rows[i, r, ROW_PHI] if inside else 0.0
            phi_dot[i, r] = rows[i, r, ROW_PHI_DOT] if inside else 0.0
            for a in range(3):
                pts[i, r, a] = rows[i, r, ROW_POINT + a] if inside else 0.0
                nrm[i, r, a] = rows[i, r, ROW_NORMAL + a] if inside else 0.0
    for a in range(6):
        h_o[a] = ho[a]
        for b in range(6):
            M_o[a, b] = Mo[a, b]
    return _supports_and_check(x, sy, wk)


@kernel
def _object_rows_and_blocks(x, sy, wk, callees):  # pragma: no cover - compiled
    """:func:`_rows_and_blocks` of a system without arms: the object's terms and the supports.

    ``callees`` (empty: nothing is called through it) as :func:`_rows_and_blocks`'s.
    """
    _object_terms(x, sy[6], wk[12], wk[13])
    return _supports_and_check(x, sy, wk)


@kernel(refcounts=False)
def _supports_and_check(x, sy, wk):  # pragma: no cover - compiled
    """The supports' block and rows after the arms' (:func:`_rows_and_blocks`); False on NaN."""
    (model_ints, model_floats, arm_ints, v_starts, ints, floats, params, dims, N, nv_arm,
     sp_p, sp_n, sp_a, uni_c, mask_c, nv_c, N_c, rest_c, wrenches, rules) = tuple_at(sy)
    (J, dJ, Mq, nle, H, energy, buf, Mc, hc, Wc, W_oc, cc, M_o, h_o, phi, phi_dot, pts,
     nrm) = tuple_at(wk)
    n = dims[DIMS_N]
    B, kc, R = Wc.shape
    if B > n:  # the supports' zero-dof block: M = I, h = 0, W = 0
        for a in range(kc):
            hc[n, a] = 0.0
            for b in range(kc):
                Mc[n, a, b] = 1.0 if a == b else 0.0
            for r in range(R):
                Wc[n, a, r] = 0.0
        for r in range(R):
            for a in range(6):
                W_oc[n, a, r] = 0.0
            cc[n, r] = 0.0
            phi[n, r] = 0.0
            phi_dot[n, r] = 0.0
            for a in range(3):
                pts[n, r, a] = 0.0
                nrm[n, r, a] = 0.0
        _support_rows(x, sp_p, sp_n, sp_a, params, n, phi, phi_dot, pts, nrm, W_oc, cc)
    for a in range(6):
        if not math.isfinite(h_o[a]):
            return False
    for b in range(B):
        for r in range(R):
            if not math.isfinite(phi[b, r] + phi_dot[b, r] + cc[b, r]):
                return False
    return True


@kernel(refcounts=False)
def _all_touching(active, N):  # pragma: no cover - compiled
    """True when every arm row (``r < N[i]``) is active."""
    for i in range(N.shape[0]):
        for r in range(N[i]):
            if not active[i, r]:
                return False
    return True


@kernel(refcounts=False)  # allocates nothing: see multiarm_pin._compiled.jit
def _torques(t, x, active, sy, ctl, wk, out, callees):  # pragma: no cover - compiled
    """The controller's torques ``out.tau`` (n, k) at ``(t, x)`` on the buffer at zero torque.

    ``object_pd``: :func:`~multiarm_pin._compiled.controller_kernels.object_pd_step` when
    every arm row touches, else :func:`touching_torques` on the touching rows, or, when they
    cannot make every object wrench, the hold-still torques toward ``q_hold`` (set at the
    onset, which is recorded). Those two are ``callees[2]`` and ``callees[3]``
    (:func:`stage_compiles`).
    """
    (model_ints, model_floats, arm_ints, v_starts, ints, floats, params, dims, N, nv_arm,
     sp_p, sp_n, sp_a, uni_c, mask_c, nv_c, N_c, rest_c, wrenches, rules) = tuple_at(sy)
    (control, traj, pd_gains, null_gains, hold_tool, hold_obj, hold_n, gains, qp_active,
     unilateral, q_ref, q_hold, onsets, n_onsets, qp_active_r, touching, no_uni,
     gains_free, _) = tuple_at(ctl)
    buf = wk[6]
    (a_o, qdd_c, mu, phi_dd, Av, tau, err, z, ref, E, mu_p, qdd_p, a_pts, a_d) = tuple_at(out)
    k, n = dims[DIMS_K], dims[DIMS_N]
    for i in range(n):
        for a in range(k):
            tau[i, a] = 0.0
    if control[CTL_MODE] == CONTROL_NONE or n == 0:
        return STAGE_OK
    q0 = OBJECT_STATE_SIZE
    nq = q_ref.shape[0]
    q = x[q0:q0 + nq]
    kp, kd = null_gains[NULL_KP], null_gains[NULL_KD]
    full = _all_touching(active, N)
    touching_rows = 0
    for i in range(n):
        for r in range(touching.shape[1]):
            touching[i, r] = active[i, r]
            if active[i, r] and r < N[i]:
                touching_rows += 1
    # holding, with fewer than 6 touching rows: still rank < 6 by structure (the reference
    # decides the same without its SVD); the rank is only needed at an onset, for its warning
    status = PD_HOLD
    rank = touching_rows
    if full or control[CTL_HOLDING] == 0 or touching_rows >= 6:
        difference(model_ints, q, q_ref, err)
        joint_pd(err, x, v_starts, nv_arm, kp, kd, z)
        reference_motion(t, traj, E, ref)
        for attempt in range(2):
            # attempt 1: the margin cannot be kept; the least-norm forces without it (and no
            # unilateral bound), as ObjectPD.reference falls back
            uni = unilateral if attempt == 0 else no_uni
            g = gains if attempt == 0 else gains_free
            if full:
                status = callees[2](buf, dims, N, nv_arm, uni, x[:OBJECT_STATE_SIZE], ref,
                                    pd_gains, z, hold_tool, hold_obj, hold_n, g,
                                    qp_active if attempt == 0 else qp_active_r, tau, mu_p,
                                    qdd_p, a_pts, a_d)
            else:
                status, rank = callees[3](buf, dims, N, nv_arm, uni, touching,
                                          x[:OBJECT_STATE_SIZE], ref, pd_gains, z, hold_tool,
                                          hold_obj, hold_n, g, qp_active_r, tau, mu_p, qdd_p,
                                          a_pts, a_d, callees[2])
            if status != PD_FORCES_FAILED:
                if status == PD_OK:  # (ObjectPD.margin_kept: set by a plan, not by holding)
                    control[CTL_MARGIN_KEPT] = 1 if attempt == 0 else 0
                break
    if status == PD_OK:
        control[CTL_HOLDING] = 0
        return STAGE_OK
    if status == NOT_COMPILED:
        return STAGE_EVENTS_NOT_COMPILED
    if status != PD_HOLD:
        return STAGE_CONTROLLER
    if control[CTL_HOLDING] == 0:  # the onset: hold the configuration of this state
        control[CTL_HOLDING] = 1
        for a in range(nq):
            q_hold[a] = q[a]
        j = n_onsets[0]
        if j < onsets.shape[0]:
            onsets[j, 0] = t
            onsets[j, 1] = rank
        n_onsets[0] = j + 1
    difference(model_ints, q, q_hold, err)
    joint_pd(err, x, v_starts, nv_arm, kp, kd, z)
    hold_still_torques(buf, dims, nv_arm, z, tau)
    return STAGE_OK


@kernel
def _phased_torques(t, x, active, sy, ctl, wk, out, callees):  # pragma: no cover - compiled
    """``phased_pd``'s torques ``out.tau`` (the arguments as :func:`_torques`'s).

    :func:`~multiarm_pin._compiled.phased.phased_torques` on the buffer and the support
    block's rows (``κ`` from ``c = -κ - 2α φ̇ - β² φ``); ``STAGE_CONTROLLER`` when it reports a
    case the reference decides (the stepper then takes the step). Its ``distribute`` and
    ``plan`` are ``callees[2]`` and ``callees[3]`` (:func:`stage_compiles`).
    """
    (model_ints, model_floats, arm_ints, v_starts, ints, floats, params, dims, N, nv_arm,
     sp_p, sp_n, sp_a, uni_c, mask_c, nv_c, N_c, rest_c, wrenches, rules) = tuple_at(sy)
    (control, traj, pd_gains, null_gains, hold_tool, grasp_obj, hold_n, gains, qp_active,
     unilateral, q_ref, q_hold, onsets, n_onsets, qp_active_r, touching, no_uni,
     gains_free, ph) = tuple_at(ctl)
    (phases, press, release, named, offs, margins, offset_start, lam, a_plan) = ph
    buf, W_oc, cc, phi, phi_dot = wk[6], wk[10], wk[11], wk[14], wk[15]
    (a_o, qdd_c, mu, phi_dd, Av, tau, err, z, ref, E, mu_p, qdd_p, a_pts, a_d) = tuple_at(out)
    m, n = dims[DIMS_M], dims[DIMS_N]
    K = sp_p.shape[0]
    q0 = OBJECT_STATE_SIZE
    nq = q_ref.shape[0]
    difference(model_ints, x[q0:q0 + nq], q_ref, err)
    joint_pd(err, x, v_starts, nv_arm, null_gains[NULL_KP], null_gains[NULL_KD], z)
    G = np.empty((K, 6))
    kappa = np.empty(K)
    gaps = np.empty(K)
    on = params[P_BAUMGARTE_ON] != 0.0
    al, be = params[P_BAUMGARTE_ALPHA], params[P_BAUMGARTE_BETA]
    for j in range(K):
        for a in range(6):
            G[j, a] = W_oc[n, a, j]
        gaps[j] = phi[n, j]
        kap = -cc[n, j]
        if on:
            kap = kap - 2.0 * al * phi_dot[n, j] - be * be * phi[n, j]
        kappa[j] = kap
    for i in range(n):
        for r in range(m):
            touching[i, r] = active[i, r]
    status, kept = phased_torques(t, buf, dims, N, nv_arm, unilateral, touching,
                                  x[:OBJECT_STATE_SIZE], G, kappa, gaps, phases, press, release,
                                  named, offs, margins, offset_start, pd_gains, z, hold_tool,
                                  grasp_obj, hold_n, gains, tau, mu_p, lam, qdd_p, a_pts, a_d,
                                  a_plan, callees[2], callees[3])
    if status != PD_OK:
        return STAGE_CONTROLLER
    control[CTL_HOLDING] = 0
    control[CTL_MARGIN_KEPT] = 1 if kept else 0
    return STAGE_OK


@kernel
def off_rectangles(x, sp_p, planes):  # pragma: no cover - compiled
    """True when some support row's point at ``x`` is not inside its support's rectangle.

    ``SupportSet.edge_margins`` ``<= 0`` (``min(lx/2 - |u|, ly/2 - |v|)``, ``(u, v)`` the
    point's in-plane coordinates from the rectangle's centre); rows of whole planes (infinite
    half extents) never are.

    Args:
        x: the state vector.
        sp_p: (K, 3) the rows' object-frame points [m].
        planes: (K, SUPPORT_PLANE_SIZE) their supports' planes (``SUPPORT_PLANE_FIELDS``).
    """
    R = rotation_rows(x[X_QUATERNION:X_QUATERNION + 4])
    for j in range(sp_p.shape[0]):
        hx, hy = planes[j, PLANE_HALF_EXTENT], planes[j, PLANE_HALF_EXTENT + 1]
        if math.isinf(hx) and math.isinf(hy):
            continue
        u = 0.0
        v = 0.0
        for a in range(3):
            p = x[X_POSITION + a] + (R[a][0] * sp_p[j, 0] + R[a][1] * sp_p[j, 1]
                                     + R[a][2] * sp_p[j, 2])
            d = p - planes[j, PLANE_POINT + a]
            u += d * planes[j, PLANE_X_AXIS + a]
            v += d * planes[j, PLANE_Y_AXIS + a]
        if not (min(hx - abs(u), hy - abs(v)) > 0.0):
            return True
    return False


@kernel
def _zero_torques(t, x, active, sy, ctl, wk, out, callees):  # pragma: no cover - compiled
    """No controller: zero torques ``out.tau`` (the arguments as :func:`_torques`'s)."""
    tau = out[5]
    for i in range(tau.shape[0]):
        for a in range(tau.shape[1]):
            tau[i, a] = 0.0
    return STAGE_OK


@kernel
def contact_stage(t, x, active, sy, ctl, wk, out, d, rows, torques, lcp,
                  callees):  # pragma: no cover - compiled
    """One evaluation at ``(t, x)`` on the active set, and its tangent ``d``.

    The rows and blocks (``rows``: :func:`_rows_and_blocks` or :func:`_object_rows_and_blocks`),
    the controller (``torques``:
    :func:`_torques` or :func:`_zero_torques`), the external wrench on ``h_o``, then the
    mixed LCP as ``solve_unilateral`` (see the module docstring; ``lcp``:
    :func:`~multiarm_pin._compiled.delassus.contact_kernel`). Outputs in ``out``: ``a_o``
    (6,), ``qdd_c`` (B, kc), ``mu`` and ``phi_dd`` (B, R), ``tau`` (n, k); the rows in ``wk``.

    Returns:
        ``(status, solver code)``.
    """
    (model_ints, model_floats, arm_ints, v_starts, ints, floats, params, dims, N, nv_arm,
     sp_p, sp_n, sp_a, uni_c, mask_c, nv_c, N_c, rest_c, wrenches, rules) = tuple_at(sy)
    (J, dJ, Mq, nle, H, energy, buf, Mc, hc, Wc, W_oc, cc, M_o, h_o, phi, phi_dot, pts,
     nrm) = tuple_at(wk)
    (a_o, qdd_c, mu, phi_dd, Av, tau, err, z, ref, E, mu_p, qdd_p, a_pts, a_d) = tuple_at(out)
    if not rows(x, sy, wk, callees):
        return STAGE_NOT_FINITE, 0
    st = torques(t, x, active, sy, ctl, wk, out, callees)
    if st != STAGE_OK:
        return st, 0
    k, nv, n = dims[DIMS_K], dims[DIMS_NV], dims[DIMS_N]
    B, kc, R = Wc.shape
    for i in range(n):
        for a in range(k):
            hc[i, a] += tau[i, a]
    hw = np.empty(6)
    for a in range(6):
        hw[a] = h_o[a] + wrench_at(t, wrenches, a)
    solver = SOLVER_ACTIVE_SET
    fast = n > 0 and B == n
    if fast:
        for i in range(n):
            if nv_c[i] < N_c[i]:
                fast = False
        fast = fast and _all_touching(active, N_c)
    done = False
    if fast:
        s = object_first(Mc, hc, Wc, W_oc, cc, M_o, hw, N_c, params[P_RCOND_TOL],
                         params[P_OBJECT_RCOND_TOL], a_o, qdd_c, mu)
        if s != SOLVE_OK:
            return STAGE_SOLVE, 0
        done = True
        for b in range(B):
            for r in range(N_c[b]):
                if uni_c[b, r] and mu[b, r] < 0.0:
                    done = False
        if done:
            solver = SOLVER_BILATERAL
            for b in range(B):
                for r in range(R):
                    if r >= N_c[b]:
                        phi_dd[b, r] = 0.0
                        continue
                    acc = 0.0
                    for a in range(6):
                        acc += W_oc[b, a, r] * a_o[a]
                    for j in range(kc):
                        acc += Wc[b, j, r] * qdd_c[b, j]
                    phi_dd[b, r] = acc - cc[b, r]
    if not done:
        s = lcp(Mc, hc, Wc, W_oc, cc, M_o, hw, nv_c, N_c, uni_c, active, active, False,
                rules[R_DEP], rules[R_VIOL], rules[R_CONS], a_o, qdd_c, mu, Av)[0]
        if s != LCP_OK:
            return (STAGE_EVENTS_NOT_COMPILED if s == NOT_COMPILED else STAGE_SOLVE), 0
        for b in range(B):
            for r in range(R):
                phi_dd[b, r] = Av[b, r] - cc[b, r]
    for a in range(6):
        if not math.isfinite(a_o[a]):
            return STAGE_NOT_FINITE, 0
    tangent(x, nv, nv_arm, v_starts, qdd_c, a_o, d)
    return STAGE_OK, solver


@kernel
def _no_touching(buf, dims, N, nv_arm, unilateral, touching, obj, ref, pd_gains, z, hold_tool,
                 hold_obj, hold_n, gains, active_r, tau, mu, qdd, a_pts, a_d,
                 step):  # pragma: no cover - compiled
    """:func:`touching_torques`' stand-in in a loop made without its events.

    :func:`_torques` calls it only when some row does not touch; it returns
    :data:`NOT_COMPILED`: the loop is then made with its events.
    """
    return NOT_COMPILED, 0


@kernel
def _no_active_set(M, h, W, W_o, c, M_o, h_o, nv, N, uni, act, guess, use_guess, dep_rtol,
                   viol_rtol, cons_rtol, a_o, qdd, mu, Av):  # pragma: no cover - compiled
    """The active-set kernel's stand-in in a loop made without its events.

    :func:`contact_stage` calls it only when its object-first path does not decide (a row not
    active, a unilateral multiplier below zero, supports, an arm with fewer joints than
    rows); it returns :data:`NOT_COMPILED`: the loop is then made with its events.
    """
    return NOT_COMPILED, 0, 0, 0, 0.0


def stage_compiles(x, active, sy, ctl, wk, out, d, events: bool = True) -> tuple:
    """The compiles of the ``fn`` argument of :func:`run_contact_rk4`, for these arguments' types.

    ``(contact_stage, rows, torques, lcp, callees)``, each a
    :class:`~multiarm_pin._compiled.function_pointers.Compile`: the rows and blocks
    (:func:`_rows_and_blocks`, or :func:`_object_rows_and_blocks` for a system without arms),
    the controller's torques (:func:`_torques` for ``object_pd``, :func:`_phased_torques` for
    ``phased_pd``, :func:`_zero_torques` without a controller: only the ones a run uses are
    compiled), the active-set kernel (:func:`~multiarm_pin._compiled.delassus.contact_kernel`)
    and what the first two call: with arms, the rigid-body pass and the system's evaluation
    (:func:`~multiarm_pin._compiled.rigid_body.rigid_body_pass`,
    :func:`~multiarm_pin._compiled.evaluate.evaluate_system`), then for ``object_pd``
    :func:`~multiarm_pin._compiled.controller_kernels.object_pd_step` and
    :func:`~multiarm_pin._compiled.controller_kernels.touching_torques`. Each is compiled once
    and called through its address (:mod:`~multiarm_pin._compiled.function_pointers`): the
    loop's module, and the stage's, do not compile them again. ``events`` False: stand-ins of
    the same types take the places of the active-set kernel and ``touching_torques``
    (:func:`_no_active_set`, :func:`_no_touching`), which only a step with events needs.
    """
    mode = int(ctl[0][CTL_MODE])
    arms = int(sy[7][DIMS_N]) > 0
    int64 = numba.types.int64
    pair = numba.types.UniTuple(int64, 2)
    rules = sy[19]
    callees = ()
    if arms:
        (model_ints, model_floats, arm_ints, v_starts, ints, floats, params, dims, N, nv_arm,
         *_) = sy
        J, dJ, Mq, nle, H, energy, buf = wk[:7]
        callees = arm_compiles(x, model_ints, model_floats, J, dJ, Mq, nle, H, energy, arm_ints,
                               v_starts, ints, floats, params, dims, buf)
        if mode == CONTROL_OBJECT_PD:
            (_, _, pd_gains, _, hold_tool, hold_obj, hold_n, gains, qp_active, unilateral, _,
             _, _, _, qp_active_r, touching, _, _, _) = ctl
            (_, _, _, _, _, tau, _, z, ref, _, mu_p, qdd_p, a_pts, a_d) = out
            obj = x[:OBJECT_STATE_SIZE]
            step = pd_step_compile(buf, dims, N, nv_arm, unilateral, obj, ref, pd_gains, z,
                                   hold_tool, hold_obj, hold_n, gains, qp_active, tau, mu_p,
                                   qdd_p, a_pts, a_d)
            callees += (step, compile_of(
                touching_torques if events else _no_touching,
                (buf, dims, N, nv_arm, unilateral, touching, obj, ref,
                                   pd_gains, z, hold_tool, hold_obj, hold_n, gains, qp_active_r,
                                   tau, mu_p, qdd_p, a_pts, a_d, step.function_type), pair))
        elif mode == CONTROL_PHASED:
            (_, _, _, _, hold_tool, _, hold_n, gains, *_, ph) = ctl
            (_, _, _, _, _, tau, _, z, _, _, _, qdd_p, a_pts, a_d) = out
            callees += phased_callee_compiles(buf, nv_arm, z, hold_tool, hold_n, gains, tau,
                                              qdd_p, a_pts, a_d, ph[8])
    callee_types = tuple(c.function_type for c in callees)
    torque_kernel = (_torques if mode == CONTROL_OBJECT_PD
                     else _phased_torques if mode == CONTROL_PHASED else _zero_torques)
    # the stages take the loop's tuples by their addresses (run_contact_rk4)
    sy_at, ctl_at, wk_at, out_at = (TupleAddress(numba_type(t)) for t in (sy, ctl, wk, out))
    torques = compile_of(torque_kernel, (0.0, x, active, sy_at, ctl_at, wk_at, out_at,
                                         callee_types), int64)
    a_o, qdd_c, mu, Av = out[0], out[1], out[2], out[4]
    lcp = compile_of(contact_kernel if events else _no_active_set,
                     (wk[7], wk[8], wk[9], wk[10], wk[11], wk[12], a_o, sy[15], sy[16], sy[13],
                      active, active, False, rules[R_DEP], rules[R_VIOL], rules[R_CONS], a_o,
                      qdd_c, mu, Av),
                     numba.types.Tuple((int64, int64, int64, int64, numba.types.float64)))
    rows = compile_of(_rows_and_blocks if arms else _object_rows_and_blocks,
                      (x, sy_at, wk_at, callee_types), numba.types.boolean)
    stage = compile_of(contact_stage, (0.0, x, active, sy_at, ctl_at, wk_at, out_at, d,
                                       rows.function_type, torques.function_type,
                                       lcp.function_type, callee_types), pair)
    return stage, rows, torques, lcp, callees


def _each(fn: tuple, f) -> tuple:
    """``f`` of every compile of :func:`stage_compiles`' tuple ``fn``, nested as ``fn``."""
    stage, rows, torques, lcp, callees = fn
    return (f(stage), f(rows), f(torques), f(lcp), tuple(f(c) for c in callees))


def loop_functions(head: tuple, events: bool = True) -> tuple:
    """``(run_contact_rk4's entry point, fn, advance)`` for its arguments before ``fn``.

    ``fn`` is :func:`stage_compiles`' tuple compiled; ``advance`` is
    :func:`_advance_with_events`, compiled once for the types of ``head``'s arrays and ``fn``
    and called through its address. ``events`` False: the loop without its event machinery,
    for the stretches where every row is active: :func:`_advance_touching` and the stand-ins
    of :func:`stage_compiles`, which hand back :data:`STAGE_EVENTS_NOT_COMPILED` at the first
    step that needs more; the loop, its stage, its rows and its controller are the same
    compiles in both (the stand-ins have the types of what they stand for), so the events
    add only their own three compiles. The loop, the advance, the stages and their callees are
    independent compiles (a caller needs only the type of a function it calls through its
    address): :func:`~multiarm_pin._compiled.function_pointers.compile_all` runs them at once.
    Made once per process for the types of ``head``.
    """
    (_, _, _, x, active, sy, ctl, wk, out, rk, st0, loc, imp, ev, n_ev, _, _) = head
    mode = int(ctl[0][CTL_MODE])
    key = (mode, int(sy[7][DIMS_N]) > 0, events, type_key(head))
    found = _loops.get(key)  # compile_of types every argument: once per types
    if found is not None:
        return found
    fn = stage_compiles(x, active, sy, ctl, wk, out, rk[0], events)
    stage, rows, torques, lcp, callees = fn
    at = tuple(TupleAddress(numba_type(t)) for t in (sy, ctl, wk, out, rk, st0, loc, imp))
    advance = compile_of(_advance_with_events if events else _advance_touching,
                         (0.0, x, 0.0, active, *at, ev, n_ev, _each(fn, lambda c: c.function_type)),
                         numba.types.int64)
    loop = compile_of(run_contact_rk4,
                      (*head, _each(fn, lambda c: c.pointer_type), advance.pointer_type))
    # the larger first (by the code each compiles): the active-set kernel before the
    # controller's callees, which a run whose events come later compiles with it, so that the
    # two processes finish together; the controller's callees share no code (touching_torques
    # calls object_pd_step through its address)
    groups = [[advance], [loop], [lcp], *[[c] for c in callees[2:]], [torques],
              [*callees[1:2]], [rows], [stage], [*callees[:1]]]
    compile_all([g for g in groups if g])
    found = _loops[key] = (compiled(loop), _each(fn, pointer), pointer(advance))
    return found


_loops: dict = {}  # (controller mode, arms?, events?, type_key of the head) -> the tuple


@kernel
def evaluate_once(t, x, active, held, d, fn):  # pragma: no cover - compiled
    """One evaluation at ``(t, x)`` on the active set, as the loop makes it (no event, no record).

    :func:`contact_stage` through ``fn`` (:func:`stage_compiles`' tuple, as pointers), with
    the loop's tuples (:func:`run_contact_rk4`'s ``sy``, ``ctl``, ``wk``, ``out``) held in
    ``held`` (:func:`~multiarm_pin._compiled.held.hold`: a call from Python unboxes one
    pointer for them); the tangent into ``d``, the rest into ``wk`` and ``out``. For an
    evaluation on its own from Python
    (:meth:`multiarm_pin.sim.contact_loop.ContactLoop.evaluate`).

    Returns:
        ``(status, solver code)``.
    """
    sy, ctl, wk, out = address(held.sy), address(held.ctl), address(held.wk), address(held.out)
    fns = bind(fn)
    return fns[0](t, x, active, sy, ctl, wk, out, d, fns[1], fns[2], fns[3], fns[4])


def evaluate_functions(args: tuple, events: bool = True) -> tuple:
    """``(evaluate_once's entry point, held, fn)`` for the loop's arguments ``args``.

    ``args``: ``(t, x, active, sy, ctl, wk, out, d)``; the entry point is called as
    ``entry(t, x, active, held, d, fn)``. The stages as :func:`loop_functions` makes them for
    the same types (the same compiles).
    """
    (t, x, active, sy, ctl, wk, out, d) = args
    fn = stage_compiles(x, active, sy, ctl, wk, out, d, events)
    held = hold(sy, ctl, wk, out)
    entry = compile_of(evaluate_once, (t, x, active, held, d,
                                       _each(fn, lambda c: c.pointer_type)))
    compile_all([[c] for c in (entry, *fn[:4], *fn[4])])
    return compiled(entry), held, _each(fn, pointer)


# ------------------------------------------------------------------ steps and events
@kernel
def _illinois(theta, value, lo, f_lo, hi, f_hi, side):  # pragma: no cover - compiled
    """One update of ``event_location.illinois``'s bracket with the iterate ``(θ, value)``.

    Returns:
        ``(lo, f_lo, hi, f_hi, side)``; ``side`` is -1 when ``θ`` became the upper end.
    """
    if value > 0.0:
        if side == 1:
            f_hi *= 0.5
        return theta, value, hi, f_hi, 1
    if side == -1:
        f_lo *= 0.5
    return lo, f_lo, theta, value, -1


@kernel(refcounts=False)
def _any_push(active, uni_c, mu0):  # pragma: no cover - compiled
    """True if an active unilateral row pushed at a step's start (``mu0 > 0``)."""
    for b in range(active.shape[0]):
        for r in range(active.shape[1]):
            if active[b, r] and uni_c[b, r] and mu0[b, r] > 0.0:
                return True
    return False


@kernel(refcounts=False)
def _leaves(active, uni_c, mu_end, phi_dd_end, sep_acc, b, r):  # pragma: no cover - compiled
    """True if row ``(b, r)`` leaves at a step's end (``locate_separation``'s rows).

    Active, unilateral, ``μ <= 0`` and ``φ̈ > sep_acc`` there.
    """
    return (active[b, r] and uni_c[b, r] and mu_end[b, r] <= 0.0
            and phi_dd_end[b, r] > sep_acc)


@kernel(refcounts=False)  # allocates nothing: one twin for every advance
def _step(t, x, d1, h, active, sy, ctl, wk, out, rk, x_new, fn,
          rot):  # pragma: no cover - compiled
    """One step ``h`` [s] from ``x`` (tangent ``d1`` there) into ``x_new`` (``Stepper.step``).

    RK4, or semi-implicit Euler (the step from ``d1`` alone:
    :func:`~multiarm_pin._compiled.integrator.advance_semi_implicit`) when ``rot`` (``rk``'s
    last element: its (3, 3) workspace, ``None`` in RK4 runs) is given. numba drops the branch
    of the other integrator when it compiles the step for ``rot``'s type: a run compiles its
    own integrator only.
    """
    model_ints = sy[0]
    d2, d3, d4, hd, xs, dsum, _ = tuple_at(rk)
    if rot is not None:
        advance_semi_implicit(model_ints, x, d1, h, hd[:sy[7][DIMS_NV]], rot, x_new)
        return STAGE_OK
    for stage in range(3):  # one call site of the stage: t + h/2, t + h/2, t + h
        hs = h if stage == 2 else 0.5 * h
        advance(model_ints, x, d1 if stage == 0 else (d2 if stage == 1 else d3), hs, hd, xs)
        st = fn[0](t + hs, xs, active, sy, ctl, wk, out,
                   d2 if stage == 0 else (d3 if stage == 1 else d4), fn[1], fn[2], fn[3],
                   fn[4])[0]
        if st != STAGE_OK:
            return st
    for a in range(d1.shape[0]):  # (d1 + 2 d2 + 2 d3 + d4) / 6, numpy's order of operations
        dsum[a] = (((d1[a] + 2.0 * d2[a]) + 2.0 * d3[a]) + d4[a]) / 6.0
    advance(model_ints, x, dsum, h, hd, x_new)
    return STAGE_OK


@kernel
def _min_gap(x, watch, sy, wk, fn):  # pragma: no cover - compiled
    """The smallest gap [m] of the ``watch`` rows at ``x`` (``Stepper.gaps``), NaN if not finite."""
    if not fn[1](x, sy, wk, fn[4]):
        return np.nan
    phi = wk[14]
    g = np.inf
    for b in range(watch.shape[0]):
        for r in range(watch.shape[1]):
            if watch[b, r] and phi[b, r] < g:
                g = phi[b, r]
    return g


@kernel
def _release(mu, phi_dd, rows, rules):  # pragma: no cover - compiled
    """``event_location.release``: ``-max φ̈`` of the force-free lifting rows, else Σ μ."""
    lift = False
    top = -np.inf
    total = 0.0
    for b in range(rows.shape[0]):
        for r in range(rows.shape[1]):
            if not rows[b, r]:
                continue
            total += mu[b, r]
            if mu[b, r] <= 0.0 and phi_dd[b, r] > rules[R_LIFT]:
                lift = True
                top = max(top, phi_dd[b, r])
    if lift:
        return -top
    return max(total, rules[R_RESTING_RELEASE])


@kernel
def _event(ev, n_ev, t, kind, b, r, before, after, impulse, rebound):  # pragma: no cover
    """Append one event to the table (``Stepper._event``)."""
    j = n_ev[0]
    ev[j, 0] = t
    ev[j, 1] = kind
    ev[j, 2] = b
    ev[j, 3] = r
    ev[j, 4] = before
    ev[j, 5] = after
    ev[j, 6] = impulse
    ev[j, 7] = 1.0 if rebound else 0.0
    n_ev[0] = j + 1


@kernel
def _separations(t, active, mu, phi_dd, phi, phi_dot, keep, use_keep, uni_c, rules, ev,
                 n_ev):  # pragma: no cover - compiled
    """``Stepper.separations``: drop active unilateral rows that let go; True if any did."""
    out = False
    for b in range(active.shape[0]):
        for r in range(active.shape[1]):
            if not (active[b, r] and uni_c[b, r]) or (use_keep and keep[b, r]):
                continue
            if ((mu[b, r] <= 0.0 and phi_dd[b, r] > rules[R_SEP_ACC])
                    or phi[b, r] > rules[R_SEP_GAP] or phi_dot[b, r] > rules[R_SEP_SPEED]):
                _event(ev, n_ev, t, EVENT_SEPARATION, b, r, phi_dot[b, r], phi_dot[b, r], 0.0,
                       False)
                active[b, r] = False
                out = True
    return out


@kernel
def _evaluate_start(t, x, active, sy, ctl, wk, out, st0, keep, use_keep, ev, n_ev, reuse, fn
                    ):  # pragma: no cover - compiled
    """Evaluate at ``(t, x)``, drop separating rows and re-evaluate (``Stepper`` after an event).

    Its callers pass ``use_keep`` and ``reuse`` as ``np.bool_`` values, not literals: numba
    compiles a function once per literal argument value.

    The start of the next step is kept in ``st0``: ``d1``, ``mu0``, ``phi_dd0``, ``phi0`` (its
    gaps). With ``reuse`` the evaluation at ``(t, x)`` is the one in ``wk``, ``out`` and
    ``loc[10]`` (the previous step's end, the solver code in ``st0[4][1]``): as the stepper's
    cache, no second controller call.
    """
    rules = sy[19]
    uni_c = sy[13]
    d1, mu0, phi_dd0, phi0, memo = tuple_at(st0)
    solver = memo[1]
    for attempt in range(2):  # one call site of the stage
        if attempt > 0 or not reuse:
            st, solver = fn[0](t, x, active, sy, ctl, wk, out, d1, fn[1], fn[2], fn[3], fn[4])
            if st != STAGE_OK:
                return st, solver
        if attempt == 1 or not _separations(t, active, out[2], out[3], wk[14], wk[15], keep,
                                            use_keep, uni_c, rules, ev, n_ev):
            break
    copy2(phi0, wk[14])
    copy2(mu0, out[2])
    copy2(phi_dd0, out[3])
    return STAGE_OK, solver


@kernel
def _impact(t, x, watch, active, sy, wk, imp, ev, n_ev, joined, fn):  # pragma: no cover - compiled
    """``Stepper._impact``: the impact law at a touchdown, into ``x``; the active set updated."""
    (model_ints, model_floats, arm_ints, v_starts, ints, floats, params, dims, N, nv_arm,
     sp_p, sp_n, sp_a, uni_c, mask_c, nv_c, N_c, rest_c, wrenches, rules) = tuple_at(sy)
    (J, dJ, Mq, nle, H, energy, buf, Mc, hc, Wc, W_oc, cc, M_o, h_o, phi, phi_dot, pts,
     nrm) = tuple_at(wk)
    touching, cand, uni, rhs, dv_o, dqd, P, Av, zero_h, zero6 = tuple_at(imp)
    if not fn[1](x, sy, wk, fn[4]):
        return STAGE_NOT_FINITE
    B, R = phi.shape
    for b in range(B):
        for r in range(R):
            touching[b, r] = watch[b, r] and phi[b, r] <= rules[R_GAP]
            cand[b, r] = active[b, r] or touching[b, r]
            uni[b, r] = uni_c[b, r]
    for attempt in range(4):
        for b in range(B):
            for r in range(R):
                if r >= N_c[b]:
                    rhs[b, r] = 0.0
                    continue
                vm = phi_dot[b, r]
                e = 0.0 if abs(vm) < rules[R_RESTING] else rest_c[b, r]
                rhs[b, r] = -((1.0 + e) * vm) if uni[b, r] else -vm
        s = fn[3](Mc, zero_h, Wc, W_oc, rhs, M_o, zero6, nv_c, N_c, uni, cand, cand, False,
                  rules[R_DEP], rules[R_VIOL], rules[R_CONS], dv_o, dqd, P, Av)[0]
        if s != LCP_OK:
            return STAGE_SOLVE
        for b in range(B):
            for r in range(R):
                Av[b, r] += phi_dot[b, r] if r < N_c[b] else 0.0  # φ̇⁺
        if attempt == 3:
            break
        slow = False
        for b in range(B):
            for r in range(R):
                if (cand[b, r] and uni[b, r] and Av[b, r] > rules[R_REBOUND]
                        and Av[b, r] <= rules[R_RESTING]):
                    uni[b, r] = False  # held at φ̇⁺ = 0 by this impact
                    slow = True
        if not slow:
            break
    dims = sy[7]
    nv, n = dims[DIMS_NV], dims[DIMS_N]
    nq = x.shape[0] - OBJECT_STATE_SIZE - 2 * nv
    v0 = OBJECT_STATE_SIZE + nq
    for i in range(n):
        for a in range(nv_arm[i]):
            x[v0 + v_starts[i] + a] += dqd[i, a]
    for a in range(6):
        x[X_TWIST + a] += dv_o[a]
    for b in range(B):  # touchdowns, then the active rows the impact sends off
        for r in range(R):
            if touching[b, r]:
                leave = uni_c[b, r] and Av[b, r] > rules[R_REBOUND]
                _event(ev, n_ev, t, EVENT_TOUCHDOWN, b, r, phi_dot[b, r], Av[b, r], P[b, r],
                       leave)
    for b in range(B):
        for r in range(R):
            leave = cand[b, r] and uni_c[b, r] and Av[b, r] > rules[R_REBOUND]
            if active[b, r] and leave:
                _event(ev, n_ev, t, EVENT_SEPARATION, b, r, phi_dot[b, r], Av[b, r], P[b, r],
                       False)
    for b in range(B):
        for r in range(R):
            leave = cand[b, r] and uni_c[b, r] and Av[b, r] > rules[R_REBOUND]
            joined[b, r] = touching[b, r] and not leave
            active[b, r] = cand[b, r] and not leave
    return STAGE_OK


@kernel(refcounts=False)  # allocates nothing: see multiarm_pin._compiled.jit
def _advance_with_events(t, x, t_end, active, sy, ctl, wk, out, rk, st0, loc, imp, ev, n_ev, fn
                         ):  # pragma: no cover - compiled
    """``Stepper.advance_with_events``: ``x`` to ``t_end`` with its events, in place.

    ``st0`` holds the start of the step (``d1``, ``mu0``, ``phi_dd0`` of the evaluation at
    ``(t, x)``), ``loc`` the location workspace.
    """
    rules = sy[19]
    uni_c, mask_c = sy[13], sy[14]
    d1, mu0, phi_dd0, phi0, memo = tuple_at(st0)
    (new, s_e, s_hi, mu_end, phi_dd_end, mu_hi, rows_sep, leaving, watch, joined, dtmp, _,
     _, _) = tuple_at(loc)
    memo[0] = 0
    B, R = active.shape
    tol = rules[R_GAP]
    max_events = int(rules[R_MAX_EVENTS])
    for _ in range(max_events):
        h = t_end - t
        st = _step(t, x, d1, h, active, sy, ctl, wk, out, rk, new, fn, rk[-1])
        if st != STAGE_OK:
            return st
        # locate_separation
        sep = False
        end_eval = False  # wk and out hold the evaluation at (t_end, new)
        if _any_push(active, uni_c, mu0):
            st, memo[1] = fn[0](t_end, new, active, sy, ctl, wk, out, dtmp, fn[1], fn[2],
                                fn[3], fn[4])
            if st != STAGE_OK:
                return st
            end_eval = True
            copy2(mu_end, out[2])
            copy2(phi_dd_end, out[3])
            both = False
            for b in range(B):
                for r in range(R):
                    rows_sep[b, r] = _leaves(active, uni_c, mu_end, phi_dd_end,
                                             rules[R_SEP_ACC], b, r)
                    if rows_sep[b, r] and mu0[b, r] > 0.0:
                        both = True
            if both:
                f_lo = _release(mu0, phi_dd0, rows_sep, rules)
                f_hi = _release(mu_end, phi_dd_end, rows_sep, rules)
                if f_lo > 0.0 > f_hi:
                    end_eval = False  # new moves to the separation
                    # illinois(band=None, bisect_every=3) from [0, 1], payload (state, μ)
                    lo, hi = 0.0, 1.0
                    copy1(s_hi, new)
                    copy2(mu_hi, mu_end)
                    side = 0
                    for it in range(int(rules[R_MAX_ITER])):
                        if (hi - lo) * h < rules[R_SEP_TIME]:
                            break
                        theta = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
                        if it % 3 == 2 or not (lo < theta < hi):
                            theta = 0.5 * (lo + hi)
                        st = _step(t, x, d1, theta * h, active, sy, ctl, wk, out, rk, s_e,
                                   fn, rk[-1])
                        if st != STAGE_OK:
                            return st
                        st = fn[0](t + theta * h, s_e, active, sy, ctl, wk, out, dtmp, fn[1],
                                   fn[2], fn[3], fn[4])[0]
                        if st != STAGE_OK:
                            return st
                        value = _release(out[2], out[3], rows_sep, rules)
                        lo, f_lo, hi, f_hi, side = _illinois(theta, value, lo, f_lo, hi, f_hi,
                                                             side)
                        if side == -1:  # the iterate is the new upper end: its payload
                            copy1(s_hi, s_e)
                            copy2(mu_hi, out[2])
                    for b in range(B):
                        for r in range(R):
                            leaving[b, r] = rows_sep[b, r] and mu_hi[b, r] <= 0.0
                    copy1(new, s_hi)
                    h = hi * h
                    sep = True
        # touchdowns: watched rows (not far below the band at the step's start)
        any_watch = False
        for b in range(B):
            for r in range(R):
                watch[b, r] = mask_c[b, r] and uni_c[b, r] and not active[b, r]
                any_watch = any_watch or watch[b, r]
        g_hi = 0.0
        if any_watch:
            any_watch = False
            for b in range(B):
                for r in range(R):  # phi0: the gaps at the step's start (x)
                    watch[b, r] = watch[b, r] and phi0[b, r] >= -rules[R_LOST]
                    any_watch = any_watch or watch[b, r]
            if any_watch:
                if end_eval:  # new's rows are known
                    g_hi = np.inf
                    for b in range(B):
                        for r in range(R):
                            if watch[b, r]:
                                g_hi = min(g_hi, wk[14][b, r])
                else:
                    g_hi = _min_gap(new, watch, sy, wk, fn)
                if not math.isfinite(g_hi):
                    return STAGE_NOT_FINITE
        if g_hi >= -tol:
            if not sep:
                copy1(x, new)
                # the end's evaluation is the next sample's (the stepper's cache)
                memo[0] = 1 if end_eval else 0
                return STAGE_OK
            t = t + h
            copy1(x, new)
            # Stepper._separate: the leaving rows' events with their rates at (t, x)
            if not fn[1](x, sy, wk, fn[4]):
                return STAGE_NOT_FINITE
            phi_dot = wk[15]
            for b in range(B):
                for r in range(R):
                    if leaving[b, r] and active[b, r]:
                        _event(ev, n_ev, t, EVENT_SEPARATION, b, r, phi_dot[b, r],
                               phi_dot[b, r], 0.0, False)
                        active[b, r] = False
            st = _evaluate_start(t, x, active, sy, ctl, wk, out, st0, joined, np.bool_(False),
                                 ev, n_ev, np.bool_(False), fn)[0]
            if st != STAGE_OK:
                return st
            if t_end - t <= rules[R_TIME]:
                return STAGE_OK
            continue
        st, theta = _locate_touchdown(t, x, d1, h, watch, g_hi, active, sy, ctl, wk, out, rk, loc,
                                      fn)
        if st != STAGE_OK:
            return st
        t = t + theta * h
        if theta > 0.0:
            copy1(x, s_e)
        st = _impact(t, x, watch, active, sy, wk, imp, ev, n_ev, joined, fn)
        if st != STAGE_OK:
            return st
        st = _evaluate_start(t, x, active, sy, ctl, wk, out, st0, joined, np.bool_(True), ev,
                             n_ev, np.bool_(False), fn)[0]
        if st != STAGE_OK:
            return st
        if t_end - t <= rules[R_TIME]:
            return STAGE_OK
    return STAGE_TOO_MANY_EVENTS


@kernel
def _advance_touching(t, x, t_end, active, sy, ctl, wk, out, rk, st0, loc, imp, ev, n_ev, fn
                      ):  # pragma: no cover - compiled
    """:func:`_advance_with_events` for a step from a state where every row is active.

    The step and, when a unilateral row pushes, the evaluation at its end: the same
    operations as :func:`_advance_with_events` while no row leaves in the step (the end's
    evaluation kept for the next sample likewise). Returns :data:`STAGE_EVENTS_NOT_COMPILED`,
    with nothing done, when some row is not active at the start (a touchdown may come) or a
    row would leave in the step (a separation to locate): :func:`_advance_with_events` takes
    those steps.
    """
    rules = sy[19]
    uni_c, mask_c = sy[13], sy[14]
    d1, mu0, phi_dd0, _, memo = tuple_at(st0)
    new, dtmp = loc[0], loc[10]
    B, R = active.shape
    for b in range(B):
        for r in range(R):
            if mask_c[b, r] and not active[b, r]:
                return STAGE_EVENTS_NOT_COMPILED
    memo[0] = 0
    st = _step(t, x, d1, t_end - t, active, sy, ctl, wk, out, rk, new, fn, rk[-1])
    if st != STAGE_OK:
        return st
    any_push = _any_push(active, uni_c, mu0)
    if any_push:
        st, memo[1] = fn[0](t_end, new, active, sy, ctl, wk, out, dtmp, fn[1], fn[2], fn[3],
                            fn[4])
        if st != STAGE_OK:
            return st
        mu_end, phi_dd_end = out[2], out[3]
        for b in range(B):
            for r in range(R):
                if (_leaves(active, uni_c, mu_end, phi_dd_end, rules[R_SEP_ACC], b, r)
                        and mu0[b, r] > 0.0):
                    return STAGE_EVENTS_NOT_COMPILED
    copy1(x, new)
    memo[0] = 1 if any_push else 0
    return STAGE_OK


@kernel
def _locate_touchdown(t, x, d1, h, watch, g_hi, active, sy, ctl, wk, out, rk, loc, fn
                      ):  # pragma: no cover - compiled
    """``event_location.locate_touchdown``: ``(status, θ)``, the state at ``θ`` in ``loc[1]``.

    (θ = 0: the state is ``x`` itself, ``loc[1]`` untouched.)
    """
    rules = sy[19]
    s_e = loc[1]
    tol = rules[R_GAP]
    target = -0.5 * tol
    lo, hi = 0.0, 1.0
    if not fn[1](x, sy, wk, fn[4]):
        return STAGE_NOT_FINITE, 0.0
    phi, phi_dot = wk[14], wk[15]
    g0 = np.inf
    closing = False
    for b in range(watch.shape[0]):
        for r in range(watch.shape[1]):
            if watch[b, r]:
                g0 = min(g0, phi[b, r])
                if phi[b, r] <= 0.0 and phi_dot[b, r] < -rules[R_REBOUND]:
                    closing = True
    f_lo, f_hi = g0 - target, g_hi - target
    if f_lo <= 0.5 * tol:  # a watched row starts within (or below) the band
        if closing:
            return STAGE_OK, 0.0
        theta = 1.0
        while True:
            theta *= 0.5
            if theta * h < rules[R_TIME]:
                return STAGE_OK, 0.0
            st = _step(t, x, d1, theta * h, active, sy, ctl, wk, out, rk, s_e, fn, rk[-1])
            if st != STAGE_OK:
                return st, 0.0
            f = _min_gap(s_e, watch, sy, wk, fn) - target
            if not math.isfinite(f):
                return STAGE_NOT_FINITE, 0.0
            if f > 0.5 * tol:
                lo, f_lo = theta, f
                break
            hi, f_hi = theta, f
    # illinois(band=0.5 tol): the last iterate, as soon as |value| <= band or the bracket
    # was narrow
    side = 0
    theta = hi
    for _ in range(int(rules[R_MAX_ITER])):
        short = (hi - lo) * h < rules[R_TIME]
        theta = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        if not (lo < theta < hi):
            theta = 0.5 * (lo + hi)
        st = _step(t, x, d1, theta * h, active, sy, ctl, wk, out, rk, s_e, fn, rk[-1])
        if st != STAGE_OK:
            return st, 0.0
        value = _min_gap(s_e, watch, sy, wk, fn) - target
        if not math.isfinite(value):
            return STAGE_NOT_FINITE, 0.0
        if abs(value) <= 0.5 * tol or short:
            return STAGE_OK, theta
        lo, f_lo, hi, f_hi, side = _illinois(theta, value, lo, f_lo, hi, f_hi, side)
    return STAGE_OK, theta


@kernel
def _record_sample(s, t, x, active, sy, wk, out, solver, Rec):  # pragma: no cover - compiled
    """Record sample ``s`` from its evaluation (``Recorder.record``)."""
    (model_ints, model_floats, arm_ints, v_starts, ints, floats, params, dims, N, nv_arm,
     sp_p, sp_n, sp_a, uni_c, mask_c, nv_c, N_c, rest_c, wrenches, rules) = tuple_at(sy)
    energy, phi, phi_dot, pts, nrm = wk[5], wk[14], wk[15], wk[16], wk[17]
    a_o, qdd_c, mu, tau = out[0], out[1], out[2], out[5]
    (r_q, r_v, r_p, r_quat, r_tw, r_tau, r_mu, r_phi, r_phi_dot, r_points, r_normals, r_a_o,
     r_qdd, r_violation, r_wrench, r_kinetic, r_potential, r_momentum, r_active,
     r_solver, beside) = Rec
    tol = rules[R_GAP]
    nv, n = dims[DIMS_NV], dims[DIMS_N]
    nq = x.shape[0] - OBJECT_STATE_SIZE - 2 * nv
    record_state(s, t, x, nq, nv, nv_arm, v_starts, tau, qdd_c, a_o, wrenches, r_q, r_v, r_p,
                 r_quat, r_tw, r_tau, r_qdd, r_a_o, r_wrench)
    viol = 0.0
    B, R = phi.shape
    for b in range(B):
        for r in range(R):
            r_mu[s, b, r] = mu[b, r]
            r_phi[s, b, r] = phi[b, r]
            r_phi_dot[s, b, r] = phi_dot[b, r]
            r_active[s, b, r] = active[b, r]
            for a in range(3):
                r_points[s, b, r, a] = pts[b, r, a]
                r_normals[s, b, r, a] = nrm[b, r, a]
            # a fingertip that started beside its face: out of the penetration until it is
            # above its face's plane or touches (``Stepper.update_beside_start``)
            if beside[b, r] and not (phi[b, r] < -tol and not active[b, r]):
                beside[b, r] = False
            if not mask_c[b, r]:
                continue
            if active[b, r] or not uni_c[b, r]:
                viol = max(viol, abs(phi[b, r]))
            elif not beside[b, r]:
                viol = max(viol, -phi[b, r])
    r_violation[s] = viol
    r_solver[s] = solver
    record_energy(s, x, params, energy, n > 0, r_kinetic, r_potential, r_momentum)


@kernel(nogil=True, refcounts=False, loop=True)  # monitors check beside it; allocates nothing
def run_contact_rk4(k0, k1, times, x, active, sy, ctl, wk, out, rk, st0, loc, imp, ev, n_ev,
                    reserve, Rec, fn, advance):  # pragma: no cover - compiled
    """RK4 with contact events from sample ``k0``, recording samples ``k0 .. k1 - 1``.

    As :func:`~multiarm_pin.sim.simulation.simulate` with the stepper: at each sample the
    evaluation on the active set, the separations there (and a new evaluation), the record,
    then :func:`_advance_with_events` to the next sample.

    Args:
        k0: first sample.
        k1: one past the last sample to record.
        times: (T,) the time grid [s].
        x: the state vector at sample ``k0`` (in and out).
        active: (B, R) bool, the active set (in and out).
        sy: the system tuple (model, arm and contact tables, parameters, dimensions, support
            tables, the rows' masks, joints, rows and restitution, wrenches, rules).
        ctl: the controller tuple (mode and hold flags, ``object_pd``'s inputs, the hold
            configuration and onsets, scratch).
        wk: the workspace of one evaluation (arm terms, buffer, stacked blocks, rows).
        out: the outputs of one evaluation (solution, torques, plan).
        rk: the step's workspace (RK4 stages, the semi-implicit step's rotation).
        st0: the start of a step (tangent, multipliers, rates, gaps, reuse memo).
        loc: the event-location workspace, then the copies of ``x``, ``active`` and the hold
            configuration that a failed step restores.
        imp: the impact workspace.
        (:class:`multiarm_pin.sim.contact_loop.ContactLoop` builds them.)
        ev: (E, EVENT_WIDTH) the event table (appended to).
        n_ev: (1,) int the events in it.
        reserve: rows of ``ev`` to keep free before a step (more than one step can add).
        Rec: the record arrays (``Recorder``'s, and the active set and solver codes), then
            the (B, R) bool rows kept out of the recorded penetration (``beside_start``: in
            and out).
        fn: ``(contact_stage, rows, torques, lcp, callees)`` as :func:`stage_compiles`
            makes them (compiled once, called through their addresses), as pointers from
            Python (:func:`~multiarm_pin._compiled.function_pointers.pointer`) or functions.
        advance: :func:`_advance_with_events`, likewise (:func:`loop_functions`).

    Returns:
        ``(status, k)``: ``STAGE_OK`` and ``k1``, or the reason and the sample whose step the
        Python stepper takes (``x``, ``active``, the events and the controller's hold state
        are as they were right after that sample's separations; the sample is recorded when
        the step failed, not when its evaluation did). ``STAGE_EVENTS_FULL``: take the events
        and call again from ``k``. ``STAGE_OFF_RECTANGLE``: sample ``k`` or the step's end
        has a support point off its rectangle (at the sample: checked before its
        evaluation, nothing of it done).
    """
    # every call below takes these tuples by their addresses (tuple_address)
    sy, ctl, wk, out, rk, st0, loc, imp = (address(sy), address(ctl), address(wk), address(out),
                                           address(rk), address(st0), address(loc),
                                           address(imp))
    control, q_hold, n_onsets = ctl[0], ctl[11], ctl[13]
    fns = bind(fn)
    advance_fn = bind(advance)
    x0, active0, q_hold0 = loc[11], loc[12], loc[13]
    for s in range(k0, k1):
        if n_ev[0] + reserve > ev.shape[0]:
            return STAGE_EVENTS_FULL, s
        if off_rectangles(x, sy[10], sy[12]):
            st0[4][0] = 0  # the stepper takes this sample: nothing of it to reuse
            return STAGE_OFF_RECTANGLE, s
        t = times[s]
        reuse = st0[4][0] == 1 and s > k0
        if reuse:
            copy1(st0[0], loc[10])  # the end's tangent
        st, solver = _evaluate_start(t, x, active, sy, ctl, wk, out, st0, loc[9],
                                     np.bool_(False), ev, n_ev, reuse, fns)
        if st != STAGE_OK:
            return st, s
        _record_sample(s, t, x, active, sy, wk, out, solver, Rec)
        if s == times.shape[0] - 1:
            return STAGE_OK, s + 1
        copy1(x0, x)
        copy2(active0, active)
        copy1(q_hold0, q_hold)
        n0, holding0, onsets0 = n_ev[0], control[CTL_HOLDING], n_onsets[0]
        st = advance_fn(t, x, times[s + 1], active, sy, ctl, wk, out, rk, st0, loc, imp, ev,
                        n_ev, fns)
        if st == STAGE_OK and off_rectangles(x, sy[10], sy[12]):
            st = STAGE_OFF_RECTANGLE  # the step ends off a rectangle: the stepper's (off edge)
        if st != STAGE_OK:
            copy1(x, x0)
            copy2(active, active0)
            copy1(q_hold, q_hold0)
            n_ev[0], control[CTL_HOLDING], n_onsets[0] = n0, holding0, onsets0
            return st, s
    return STAGE_OK, k1
