"""Compiled closed loop: ``object_pd`` and the forward dynamics, stage by stage and step by step.

Mirrors :func:`multiarm_pin.sim.closed_loop.closed_loop_evaluation` (one evaluation: blocks at
zero torque, the compiled ``object_pd`` torques, the object-first solution with them) and the
RK4 step of :class:`multiarm_pin.sim.stepper.Stepper` (its ``derivative``, ``advance`` and
``step``), so that a whole run of a system of arms and bilateral (or all-pushing unilateral)
rows under ``object_pd`` is one compiled call per stretch of samples instead of a few dozen
Python calls per evaluation:

- :func:`closed_loop_stage`: one evaluation at a state, its arm terms computed by
  :func:`~multiarm_pin._compiled.rigid_body.rigid_body_pass` or given (Pinocchio's), and its
  tangent;
- :func:`run_rk4`: RK4 steps (or semi-implicit Euler steps, ``Stepper.step``'s other
  branch, when ``params[P_SEMI_IMPLICIT]`` is 1) over a stretch of the time grid, the arm
  terms computed by :func:`~multiarm_pin._compiled.rigid_body.rigid_body_pass`, every sample
  recorded into the run's record arrays.

Whatever these kernels cannot decide exactly as the Python path would, they hand back (a
status and the sample where they stopped, the state left at that sample): a doubtful
controller or solver case (the numpy reference decides), NaN, a unilateral row whose
multiplier is not positive (the mixed LCP decides) or that separates at a sample (the event
machinery of :mod:`multiarm_pin.sim.contact_events` runs). The caller,
:mod:`multiarm_pin.sim.compiled_loop`, then runs that step in Python and resumes.

State vector ``x``: the kernels' (:func:`~multiarm_pin._compiled.layout.state_vector`), object
state, ``q``, ``v`` and ``τ`` (zero here: the blocks are made at zero torque). Tangent ``d``
(2 nv + 13,): ``[q̇; v̇; ṗ; q̇uat; ȧ]`` as ``Stepper.derivative``.

Twins: ``multiarm_pin.sim.closed_loop`` (the same concept, one closed-loop evaluation, at the
sim layer: its ``closed_loop_evaluation`` is the Python evaluation the stepper calls at every
stage, for any controller, which :func:`closed_loop_stage` mirrors for ``object_pd``; these
kernels are driven by :mod:`multiarm_pin.sim.compiled_loop`, not by it).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from multiarm_pin._compiled.controller_kernels import PD_OK, pd_step_compile, solve_compile
from multiarm_pin._compiled.evaluate import evaluate_system, quaternion_rotation, rotation_rows
from multiarm_pin._compiled.function_pointers import (
    Compile,
    bind,
    compile_all,
    compile_of,
    compiled,
    pointer,
    type_key,
)
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
    P_GRAVITY,
    P_INERTIA,
    P_MASS,
    REFERENCE_SIZE,
    ROW_NORMAL,
    ROW_PHI,
    ROW_PHI_DOT,
    ROW_POINT,
    SEG_A_O,
    SEG_MU,
    SEG_QDD,
    SEG_ROWS,
    WE_FROM,
    WE_TO,
    WE_WRENCH,
    X_POSITION,
    X_QUATERNION,
    X_TWIST,
    offsets,
    view1,
    view2,
    view3,
)
from multiarm_pin._compiled.object_first import SOLVE_OK
from multiarm_pin._compiled.rigid_body import difference, integrate, rigid_body_pass
from multiarm_pin._compiled.trajectory import reference_motion

STAGE_OK = 0
"""Status of the kernels: every evaluation decided here."""
STAGE_NOT_FINITE = 1
"""Status: NaN or infinity in a state (the Python path raises, naming the field)."""
STAGE_CONTROLLER = 2
"""Status: the compiled ``object_pd`` reported a doubtful case (its reference decides)."""
STAGE_SOLVE = 3
"""Status: the object-first solve reported a singular or badly conditioned case."""
STAGE_RELEASE = 4
"""Status: a unilateral row's multiplier is not positive (the mixed LCP decides)."""
STAGE_RELEASE_IN_STEP = 6
"""Status: a unilateral row's multiplier is not positive at a later stage of a step (the
stepper takes that step from its start)."""
STAGE_SEPARATION = 5
"""Status: at a sample, a unilateral row's gap or gap rate is past the separation thresholds
of :mod:`multiarm_pin.sim.contact_events` (the event machinery decides)."""

NULL_KP = 0
"""``null_gains[NULL_KP]``: ``object_pd``'s joint-space stiffness ``null_kp`` [1/s²]."""
NULL_KD = 1
"""``null_gains[NULL_KD]``: its damping ``null_kd`` [1/s]."""


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


@kernel(refcounts=False)
def joint_pd(err, x, v_starts, nv_arm, kp, kd, z):  # pragma: no cover - compiled
    """``object_pd``'s joint-space PD ``z = pad(kp err - kd v)`` (n, k) into ``z``.

    Args:
        err: (nv,) ``q_target ⊖ q`` [rad, m].
        x: the state vector (``v`` read).
        v_starts: (n,) int first joint of each arm in ``v``.
        nv_arm: (n,) int joints per arm.
        kp: stiffness [1/s²].
        kd: damping [1/s].
        z: output (n, k), zero on padding.
    """
    nv = err.shape[0]
    v0 = x.shape[0] - 2 * nv
    for i in range(z.shape[0]):
        for a in range(z.shape[1]):
            if a < nv_arm[i]:
                j = v_starts[i] + a
                z[i, a] = kp * err[j] - kd * x[v0 + j]
            else:
                z[i, a] = 0.0


@kernel
def tangent(x, nv, nv_arm, v_starts, qdd, a_o, d):  # pragma: no cover - compiled
    """The tangent ``d`` (2 nv + 13,) ``[q̇; v̇; ṗ; q̇uat; ȧ]`` of ``x`` (``Stepper.derivative``).

    Args:
        x: the state vector.
        nv: joints.
        nv_arm: (n,) int joints per arm.
        v_starts: (n,) int first joint of each arm in ``v``.
        qdd: (n, k) the arms' accelerations, padded.
        a_o: (6,) the object's acceleration.
        d: output.
    """
    v0 = x.shape[0] - 2 * nv
    for j in range(nv):
        d[j] = x[v0 + j]
    for i in range(nv_arm.shape[0]):
        for a in range(nv_arm[i]):
            d[nv + v_starts[i] + a] = qdd[i, a]
    tw = x[X_TWIST:X_TWIST + 6]
    qx, qy, qz, qw = x[X_QUATERNION], x[X_QUATERNION + 1], x[X_QUATERNION + 2], x[X_QUATERNION + 3]
    wx, wy, wz = tw[3], tw[4], tw[5]
    b = 2 * nv
    d[b], d[b + 1], d[b + 2] = tw[0], tw[1], tw[2]
    d[b + 3] = 0.5 * (qw * wx + wy * qz - wz * qy)
    d[b + 4] = 0.5 * (qw * wy + wz * qx - wx * qz)
    d[b + 5] = 0.5 * (qw * wz + wx * qy - wy * qx)
    d[b + 6] = 0.5 * -(wx * qx + wy * qy + wz * qz)
    for a in range(6):
        d[b + 7 + a] = a_o[a]


@kernel
def closed_loop_stage(t, x, arm_pass, model_ints, model_floats, q_ref, err, J, dJ, M, nle, H,
                      energy, arm_ints, v_starts, ints, floats, params, dims, N, nv_arm,
                      unilateral, traj, pd_gains, null_gains, hold_tool, hold_obj, hold_n, gains,
                      active, wrenches, buf, tau, mu, qdd, a_pts, a_d, ref, E, z, d,
                      callees):  # pragma: no cover - compiled
    """One closed-loop evaluation at ``(t, x)`` and its tangent ``d``.

    With ``arm_pass``, first the arms' terms at ``x`` by
    :func:`~multiarm_pin._compiled.rigid_body.rigid_body_pass` (into ``J``, ``dJ``, ``M``,
    ``nle``, ``H``, ``energy``) and ``err = q_ref ⊖ q``; otherwise they are given (e.g.
    Pinocchio's). Then the blocks of the state at zero torque
    (:func:`~.evaluate.evaluate_system`), the reference motion at ``t``, the joint-space PD
    ``z = pad(null_kp (q_ref ⊖ q) - null_kd v)``, then
    :func:`~.controller_kernels.object_pd_step` (the torques), then
    :func:`~.controller_kernels.solve_with_torques` (the forward dynamics on the buffer).

    Args:
        t: time [s].
        x: (13 + nq + 2 nv,) the state vector, ``τ`` part zero.
        arm_pass: compute the arms' terms and ``err`` here.
        model_ints: the arms' model table (read with ``arm_pass``).
        model_floats: its float table.
        q_ref: (nq,) ``object_pd``'s joint-space reference (read with ``arm_pass``).
        err: (nv,) ``q_ref ⊖ q`` (``pin.difference(model, q, q_ref)``), in or out.
        J: (6, nv) world Jacobian columns at the origin (``data.J``).
        dJ: (6, nv) their time derivative (``data.dJ``).
        M: (nv, nv) joint-space mass matrix (``data.M``; arm blocks read).
        nle: (nv,) nonlinear effects [N m].
        H: (n, 4, 4) tool placements.
        energy: (ENERGY_SIZE,) the arms' energies and momentum (out with ``arm_pass``).
        arm_ints: (n, 1 + 2k) the arm table.
        v_starts: (n,) int first joint of each arm in ``v``.
        ints: (K, CONTACT_INTS) contact table.
        floats: (K, CONTACT_FLOATS) contact table.
        params: (N_PARAMS,) parameter vector (Baumgarte as the run uses it).
        dims: (DIMS_SIZE,) ``(k, m, nv, n)``.
        N: (n,) int rows per arm.
        nv_arm: (n,) int joints per arm.
        unilateral: (n, m) bool unilateral rows.
        traj: (K_w, TRAJECTORY_WIDTH) the reference trajectory's table.
        pd_gains: (PD_GAINS_SIZE,) object PD gains.
        null_gains: (2,) ``null_kp``, ``null_kd`` (``NULL_KP``, ``NULL_KD``).
        hold_tool: (n, h, 3) held points in the tool frames [m].
        hold_obj: (n, h, 3) their places in the object frame [m].
        hold_n: (n,) int held points per arm.
        gains: (HOLD_GAINS_SIZE,) held-point gains, damping, margin.
        active: (n, m) uint8 the force QP's warm start (updated).
        wrenches: (K_e, WRENCH_WIDTH) external wrench intervals (:func:`wrench_at`; K_e = 0:
            none), added to ``h_o`` for the forward dynamics only: ``object_pd`` does not
            know them (as ``MultiArmSystem.contact_blocks`` adds them after the controller).
        buf: output, the flat buffer (blocks at zero torque, solution with the torques).
        tau: output (n, k) torques [N m].
        mu: output (n, m) planned multipliers [N].
        qdd: output (n, k) planned joint accelerations.
        a_pts: output (n, h, 3) desired point accelerations.
        a_d: output (6,) desired object acceleration.
        ref: workspace (REFERENCE_SIZE,), the reference at ``t`` on return.
        E: workspace (3, 3).
        z: workspace (n, k).
        d: output (2 nv + 13,) the tangent.
        callees: ``(arm pass, system, controller, solve)``:
            :func:`~multiarm_pin._compiled.rigid_body.rigid_body_pass`,
            :func:`~.evaluate.evaluate_system`,
            :func:`~.controller_kernels.object_pd_step` and
            :func:`~.controller_kernels.solve_with_torques` as :func:`callee_compiles` lists them
            (each compiled once and called through its address), as functions or as
            pointers from Python (:func:`~multiarm_pin._compiled.function_pointers.pointer`),
            or those kernels.

    Returns:
        ``STAGE_OK`` or the reason to hand the evaluation to the Python path.
    """
    k, m, nv, n = dims[DIMS_K], dims[DIMS_M], dims[DIMS_NV], dims[DIMS_N]
    off = offsets(dims)
    fns = bind(callees)
    if arm_pass:
        q0 = OBJECT_STATE_SIZE
        nq = q_ref.shape[0]
        q = x[q0:q0 + nq]
        fns[0](model_ints, model_floats, q, x[q0 + nq:q0 + nq + nv], J, dJ, M, nle, H, energy)
        difference(model_ints, q, q_ref, err)
    if not fns[1](J, dJ, M, nle, H, x, arm_ints, v_starts, ints, floats, params, dims, buf):
        return STAGE_NOT_FINITE
    reference_motion(t, traj, E, ref)
    joint_pd(err, x, v_starts, nv_arm, null_gains[NULL_KP], null_gains[NULL_KD], z)
    w = np.empty(6)
    for a in range(6):
        w[a] = wrench_at(t, wrenches, a)
    if fns[2](buf, dims, N, nv_arm, unilateral, x[:OBJECT_STATE_SIZE], ref, pd_gains, z,
              hold_tool, hold_obj, hold_n, gains, active, tau, mu, qdd, a_pts, a_d) != PD_OK:
        return STAGE_CONTROLLER
    if fns[3](buf, dims, N, params, tau, w) != SOLVE_OK:
        return STAGE_SOLVE
    mu_s = view2(buf, off, SEG_MU, n, k, m)
    for i in range(n):
        for r in range(m):
            if unilateral[i, r] and not mu_s[i, r] > 0.0:
                return STAGE_RELEASE
    qdd_s = view2(buf, off, SEG_QDD, n, k, m)
    a_o = view1(buf, off, SEG_A_O)
    tangent(x, nv, nv_arm, v_starts, qdd_s, a_o, d)
    return STAGE_OK


def arm_compiles(x, model_ints, model_floats, J, dJ, M, nle, H, energy, arm_ints, v_starts,
                 ints, floats, params, dims, buf) -> tuple[Compile, Compile]:
    """The compiles of the rigid-body pass and of the system's evaluation, as the stages call them.

    Both loops' stages call :func:`~multiarm_pin._compiled.rigid_body.rigid_body_pass` and
    :func:`~multiarm_pin._compiled.evaluate.evaluate_system` through their addresses with
    these arguments (``q`` and ``v`` are parts of the state vector ``x``, (13 + nq + 2 nv,)):
    one compiled function each for both loops.
    """
    nv = J.shape[1]
    q = x[OBJECT_STATE_SIZE:x.shape[0] - 2 * nv]
    v = x[x.shape[0] - 2 * nv:x.shape[0] - nv]
    return (compile_of(rigid_body_pass, (model_ints, model_floats, q, v, J, dJ, M, nle, H,
                                         energy), numba.types.none),
            compile_of(evaluate_system, (J, dJ, M, nle, H, x, arm_ints, v_starts, ints, floats,
                                         params, dims, buf), numba.types.boolean))


def callee_compiles(stage_args: tuple) -> tuple[Compile, Compile, Compile, Compile]:
    """The compiles of the ``callees`` of :func:`closed_loop_stage`, for its other arguments.

    ``stage_args``: every argument of :func:`closed_loop_stage` before ``callees``, in its
    order (their types are what count). The rigid-body pass, the system's evaluation and the
    controller, each compiled once, on its own, for the types the stage passes them
    (:mod:`~multiarm_pin._compiled.function_pointers`): the stage's module holds only the
    stage's own code.
    """
    (_, x, _, model_ints, model_floats, _, _, J, dJ, M, nle, H, energy, arm_ints, v_starts,
     ints, floats, params, dims, N, nv_arm, unilateral, _, pd_gains, _, hold_tool, hold_obj,
     hold_n, gains, active, _, buf, tau, mu, qdd, a_pts, a_d, ref, _, z, _) = stage_args
    return (*arm_compiles(x, model_ints, model_floats, J, dJ, M, nle, H, energy, arm_ints,
                          v_starts, ints, floats, params, dims, buf),
            pd_step_compile(buf, dims, N, nv_arm, unilateral, x[:OBJECT_STATE_SIZE], ref,
                            pd_gains, z, hold_tool, hold_obj, hold_n, gains, active, tau, mu, qdd,
                            a_pts, a_d),
            solve_compile(buf, dims, N, params, tau))


def stage_entry(stage_args: tuple) -> tuple:
    """``(entry point of closed_loop_stage, its callees' pointers)`` for its other arguments.

    ``stage_args`` as for :func:`callee_compiles`. The stage, compiled for the types of its
    callees, and the callees are independent compiles:
    :func:`~multiarm_pin._compiled.function_pointers.compile_all` runs them at once.
    """
    arm_pass, system, controller, solve = callees = callee_compiles(stage_args)
    stage = compile_of(closed_loop_stage,
                       (*stage_args, tuple(c.pointer_type for c in callees)))
    compile_all([[controller], [system], [solve], [stage], [arm_pass]])  # the larger first
    return compiled(stage), tuple(pointer(c) for c in callees)


def loop_functions(head: tuple, x, model_ints, model_floats, q_ref, arm_ints, v_starts, ints,
                   floats, params, dims, N, nv_arm, unilateral, traj, pd_gains, null_gains,
                   hold_tool, hold_obj, hold_n, gains, active, wrenches, work_J, work_dJ,
                   work_M, work_nle, work_H, work_energy, buf, tau, mu, qdd, a_pts, a_d):
    """``(run_rk4's entry point, evaluate, callees)`` for these arguments of :func:`run_rk4`.

    ``head``: every argument of :func:`run_rk4` before ``evaluate`` (the others are among
    them: they are given again by name for the stage's example arguments).
    :func:`closed_loop_stage` compiled once for the types :func:`run_rk4` passes it and
    called through its address (:mod:`~multiarm_pin._compiled.function_pointers`), and its
    callees (:func:`callee_compiles`): the loop's module does not compile the stage again, nor
    the stage's module its callees. The loop, the stage and each callee are independent
    compiles (a caller needs only the type of a function it calls through its address):
    :func:`~multiarm_pin._compiled.function_pointers.compile_all` runs them at once.
    Made once per process for the types of ``head`` (which holds every other argument).
    """
    key = type_key(head)
    found = _loops.get(key)  # compile_of types every argument: once per types
    if found is not None:
        return found
    n, k = tau.shape
    nd = 2 * q_ref.shape[0] + OBJECT_STATE_SIZE  # any size: only the types count
    example = (0.0, x, True, model_ints, model_floats, q_ref, np.empty(work_J.shape[1]), work_J,
               work_dJ, work_M, work_nle, work_H, work_energy, arm_ints, v_starts, ints, floats,
               params, dims, N, nv_arm, unilateral, traj, pd_gains, null_gains, hold_tool,
               hold_obj, hold_n, gains, active, wrenches, buf, tau, mu, qdd, a_pts, a_d,
               np.empty(REFERENCE_SIZE), np.empty((3, 3)), np.empty((n, k)), np.empty(nd))
    arm_pass, system, controller, solve = callees = callee_compiles(example)
    callee_types = tuple(c.function_type for c in callees)
    stage = compile_of(closed_loop_stage, (*example, callee_types), numba.types.int64)
    loop = compile_of(run_rk4, (*head, stage.pointer_type,
                                tuple(c.pointer_type for c in callees)))
    # one group each, the larger first (by the code each compiles)
    compile_all([[controller], [loop], [system], [solve], [stage], [arm_pass]])
    found = _loops[key] = (compiled(loop), pointer(stage), tuple(pointer(c) for c in callees))
    return found


_loops: dict = {}  # type_key of run_rk4's head -> loop_functions' tuple


@kernel(refcounts=False)
def _advance(model_ints, x, d, h, hd, out):  # pragma: no cover - compiled
    """The state ``h`` [s] along the tangent ``d`` into ``out`` (``Stepper.advance``)."""
    nv = (d.shape[0] - OBJECT_STATE_SIZE) // 2
    nq = x.shape[0] - OBJECT_STATE_SIZE - 2 * nv
    for a in range(d.shape[0]):
        hd[a] = h * d[a]
    q0 = OBJECT_STATE_SIZE
    integrate(model_ints, x[q0:q0 + nq], hd[:nv], out[q0:q0 + nq])
    v0 = q0 + nq
    for j in range(nv):
        out[v0 + j] = x[v0 + j] + hd[nv + j]
        out[v0 + nv + j] = 0.0  # τ
    b = 2 * nv
    for a in range(3):
        out[a] = x[a] + hd[b + a]
    s = 0.0
    for a in range(4):
        out[X_QUATERNION + a] = x[X_QUATERNION + a] + hd[b + 3 + a]
    for a in range(4):
        s += out[X_QUATERNION + a] * out[X_QUATERNION + a]
    s = math.sqrt(s)
    for a in range(4):
        out[X_QUATERNION + a] /= s
    for a in range(6):
        out[X_TWIST + a] = x[X_TWIST + a] + hd[b + 7 + a]


@kernel
def _advance_semi_implicit(model_ints, x, d, h, v_new, R, out):  # pragma: no cover - compiled
    """One semi-implicit Euler step ``h`` [s] of ``x`` with the tangent ``d`` into ``out``.

    ``Stepper.step``'s semi-implicit branch: velocities first (``v + h q̈``, twist ``+ h a``),
    then the configuration with the new velocities (the arms' by ``integrate``, the position
    ``+ h ẋ``, the orientation by the exact exponential of ``h ω``:
    :func:`~multiarm_pin.spatial.integrate_quaternion`, its Rodrigues formula and Eigen's
    rotation-to-quaternion conversion, ``w >= 0``). ``v_new`` (nv,) and ``R`` (3, 3) are
    workspaces.
    """
    nv = v_new.shape[0]
    nq = x.shape[0] - OBJECT_STATE_SIZE - 2 * nv
    q0 = OBJECT_STATE_SIZE
    v0 = q0 + nq
    b = 2 * nv
    for j in range(nv):
        v_new[j] = x[v0 + j] + h * d[nv + j]
        out[v0 + nv + j] = 0.0  # τ
    for a in range(6):
        out[X_TWIST + a] = x[X_TWIST + a] + h * d[b + 7 + a]
    for j in range(nv):
        out[v0 + j] = v_new[j]
        v_new[j] = h * v_new[j]
    integrate(model_ints, x[q0:q0 + nq], v_new, out[q0:q0 + nq])
    for a in range(3):
        out[X_POSITION + a] = x[X_POSITION + a] + h * out[X_TWIST + a]
    # dR = exp3(h ω) (Rodrigues; its Taylor series near zero), then dR R(quat)
    wx, wy, wz = out[X_TWIST + 3] * h, out[X_TWIST + 4] * h, out[X_TWIST + 5] * h
    t2 = wx * wx + wy * wy + wz * wz
    if t2 > 1e-8:
        t = math.sqrt(t2)
        ct, st = math.cos(t), math.sin(t)
        a_vx, a_vxvx = st / t, (1.0 - ct) / t2
    else:
        ct = 1.0 - t2 / 2.0
        a_vx, a_vxvx = 1.0 - t2 / 6.0, 0.5 - t2 / 24.0
    dR00, dR11, dR22 = ct + a_vxvx * wx * wx, ct + a_vxvx * wy * wy, ct + a_vxvx * wz * wz
    dR01, dR10 = a_vxvx * wx * wy - a_vx * wz, a_vxvx * wx * wy + a_vx * wz
    dR02, dR20 = a_vxvx * wx * wz + a_vx * wy, a_vxvx * wx * wz - a_vx * wy
    dR12, dR21 = a_vxvx * wy * wz - a_vx * wx, a_vxvx * wy * wz + a_vx * wx
    quaternion_rotation(x[X_QUATERNION:X_QUATERNION + 4], R)
    m = R  # dR R, column by column in place (each column of the product needs its own)
    for c in range(3):
        r0, r1, r2 = R[0, c], R[1, c], R[2, c]
        m[0, c] = dR00 * r0 + dR01 * r1 + dR02 * r2
        m[1, c] = dR10 * r0 + dR11 * r1 + dR12 * r2
        m[2, c] = dR20 * r0 + dR21 * r1 + dR22 * r2
    o = X_QUATERNION  # Eigen's Quaternion(Matrix3) (as pin.Quaternion), then w >= 0
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0.0:
        t = math.sqrt(tr + 1.0)
        out[o + 3] = 0.5 * t
        t = 0.5 / t
        out[o] = (m[2, 1] - m[1, 2]) * t
        out[o + 1] = (m[0, 2] - m[2, 0]) * t
        out[o + 2] = (m[1, 0] - m[0, 1]) * t
    else:
        i = 0
        if m[1, 1] > m[0, 0]:
            i = 1
        if m[2, 2] > m[i, i]:
            i = 2
        j = (i + 1) % 3
        k = (j + 1) % 3
        t = math.sqrt(m[i, i] - m[j, j] - m[k, k] + 1.0)
        out[o + i] = 0.5 * t
        t = 0.5 / t
        out[o + 3] = (m[k, j] - m[j, k]) * t
        out[o + j] = (m[j, i] + m[i, j]) * t
        out[o + k] = (m[k, i] + m[i, k]) * t
    if out[o + 3] < 0.0:
        for a in range(4):
            out[o + a] = -out[o + a]


@kernel(nogil=True, loop=True)  # monitors check beside it
def run_rk4(k0, k1, times, x, model_ints, model_floats, q_ref, arm_ints, v_starts, ints,
            floats, params, dims, N, nv_arm, unilateral, traj, pd_gains, null_gains, hold_tool,
            hold_obj, hold_n, gains, active, wrenches, separation, work_J, work_dJ, work_M,
            work_nle, work_H, work_energy, buf, tau, mu, qdd, a_pts, a_d, r_q, r_v, r_p, r_quat,
            r_tw, r_tau, r_mu, r_phi, r_phi_dot, r_points, r_normals, r_a_o, r_qdd, r_violation,
            r_wrench, r_kinetic, r_potential, r_momentum, semi, evaluate,
            callees):  # pragma: no cover - compiled
    """RK4 (or semi-implicit Euler) steps from sample ``k0``, recording samples ``k0 .. k1 - 1``.

    Sample ``k`` is evaluated (stage 1), recorded, and unless it is the grid's last, the state
    advances to sample ``k + 1`` by RK4 with ``h = times[k + 1] - times[k]`` (stages at
    ``t + h/2``, ``t + h/2``, ``t + h``), exactly as ``Stepper.step``; when ``semi`` is given
    (the run's ``params[P_SEMI_IMPLICIT]`` is then 1), by one semi-implicit Euler step from that
    evaluation alone (:func:`_advance_semi_implicit`, ``Stepper.step``'s other branch).

    Args:
        k0: first sample.
        k1: one past the last sample to record (at most ``len(times)``).
        times: (T,) the time grid [s].
        x: (13 + nq + 2 nv,) the state vector at sample ``k0`` (``τ`` part zero); on return,
            the state at the sample returned.
        model_ints: the arms' model table (:mod:`multiarm_pin.model.compiled_model`).
        model_floats: its float table.
        q_ref: (nq,) ``object_pd``'s joint-space reference.
        arm_ints: (n, 1 + 2k) the arm table.
        v_starts: (n,) int first joint of each arm in ``v``.
        ints: (K, CONTACT_INTS) contact table.
        floats: (K, CONTACT_FLOATS) contact table.
        params: (N_PARAMS,) parameter vector.
        dims: (DIMS_SIZE,) ``(k, m, nv, n)``.
        N: (n,) int rows per arm.
        nv_arm: (n,) int joints per arm.
        unilateral: (n, m) bool unilateral rows.
        traj: (K_w, TRAJECTORY_WIDTH) the reference trajectory's table.
        pd_gains: (PD_GAINS_SIZE,) object PD gains.
        null_gains: (2,) ``null_kp``, ``null_kd``.
        hold_tool: (n, h, 3) held points in the tool frames [m].
        hold_obj: (n, h, 3) their places in the object frame [m].
        hold_n: (n,) int held points per arm.
        gains: (HOLD_GAINS_SIZE,) held-point gains, damping, margin.
        active: (n, m) uint8 the force QP's warm start (updated).
        wrenches: (K_e, WRENCH_WIDTH) external wrench intervals (see
            :func:`closed_loop_stage`).
        separation: (2,) the separation gap [m] and gap rate [m/s] of unilateral rows.
        work_J: (6, nv) workspace.
        work_dJ: (6, nv) workspace.
        work_M: (nv, nv) workspace, zero off the arms' blocks.
        work_nle: (nv,) workspace.
        work_H: (n, 4, 4) workspace.
        work_energy: (ENERGY_SIZE,) workspace.
        buf: (buffer size,) workspace, the last evaluation's buffer on return.
        tau: (n, k) the last evaluation's torques [N m].
        mu: (n, m) its planned multipliers [N].
        qdd: (n, k) its planned joint accelerations.
        a_pts: (n, h, 3) its desired point accelerations [m/s²].
        a_d: (6,) its desired object acceleration.
        r_q: (T, nq) record of ``q``.
        r_v: (T, nv) record of ``v``.
        r_p: (T, 3) object position [m].
        r_quat: (T, 4) object quaternion ``[x, y, z, w]``.
        r_tw: (T, 6) object twist.
        r_tau: (T, nv) torques [N m].
        r_mu: (T, n, m) multipliers of the solution [N].
        r_phi: (T, n, m) gaps [m].
        r_phi_dot: (T, n, m) gap rates [m/s].
        r_points: (T, n, m, 3) contact points [m].
        r_normals: (T, n, m, 3) push directions.
        r_a_o: (T, 6) object acceleration.
        r_qdd: (T, nv) joint accelerations.
        r_violation: (T,) ``max |φ|`` of the real rows [m].
        r_wrench: (T, 6) the external wrench [N, N m].
        r_kinetic: (T,) kinetic energy of arms and object [J].
        r_potential: (T,) their potential energy ``-Σ m g·c`` [J] (zero at the origin).
        r_momentum: (T, 6) their total momentum ``[linear; angular about the world
            origin]`` [kg m/s, kg m²/s].
        semi: (nv,) workspace of the semi-implicit step, or ``None`` for RK4. numba drops the
            branch of the other integrator when it compiles the loop for its type: a run
            compiles its own integrator only.
        evaluate: :func:`closed_loop_stage`, as :func:`loop_functions` makes it (compiled
            once, called through its address: its pointer,
            :func:`~multiarm_pin._compiled.function_pointers.pointer`) or the kernel itself.
        callees: the stage's ``callees`` (:func:`callee_compiles`), likewise.

    Returns:
        ``(status, k)``: ``STAGE_OK`` and ``k1`` when every sample was done, else the reason
        and the sample ``k`` whose step the Python path must take (``x`` is that sample's
        state; it may already be recorded). ``STAGE_RELEASE`` (at a sample's own
        evaluation) means the row let go inside the step that led there: the caller retakes
        that step if the kernel took it; ``STAGE_RELEASE_IN_STEP``, at a later stage of the
        step from ``k``.
    """
    k, nv, n = dims[DIMS_K], dims[DIMS_NV], dims[DIMS_N]
    nq = q_ref.shape[0]
    nx = x.shape[0]
    nd = 2 * nv + OBJECT_STATE_SIZE
    d1, d2, d3, d4 = np.empty(nd), np.empty(nd), np.empty(nd), np.empty(nd)
    hd = np.empty(nd)
    xs = np.empty(nx)
    stage_fn = bind(evaluate)
    fns = bind(callees)
    err = np.empty(nv)
    ref = np.empty(REFERENCE_SIZE)
    E = np.empty((3, 3))
    z = np.empty((n, k))
    ds = (d1, d2, d3, d4)
    stages = 1 if semi is not None else 4
    for s in range(k0, k1):
        t = times[s]
        h = times[s + 1] - t if s + 1 < times.shape[0] else 0.0
        for stage in range(stages):
            if stage == 0:
                ts, xe = t, x
            else:  # RK4: from x along the previous stage's tangent, h/2, h/2, h
                ts = t + h if stage == 3 else t + 0.5 * h
                _advance(model_ints, x, ds[stage - 1], h if stage == 3 else 0.5 * h, hd, xs)
                xe = xs
            st = stage_fn(
                ts, xe, True, model_ints, model_floats, q_ref, err, work_J, work_dJ, work_M,
                work_nle, work_H, work_energy, arm_ints, v_starts, ints, floats, params, dims,
                N, nv_arm, unilateral, traj, pd_gains, null_gains, hold_tool, hold_obj, hold_n,
                gains, active, wrenches, buf, tau, mu, qdd, a_pts, a_d, ref, E, z, ds[stage],
                fns)
            if st == STAGE_RELEASE and stage > 0:
                return STAGE_RELEASE_IN_STEP, s
            if st != STAGE_OK:
                return st, s
            if stage > 0:
                continue
            if not _record(s, t, x, nq, nv, N, nv_arm, v_starts, unilateral, wrenches,
                           separation, params, dims, buf, tau, work_energy, r_q, r_v, r_p, r_quat,
                           r_tw, r_tau, r_mu, r_phi, r_phi_dot, r_points, r_normals, r_a_o,
                           r_qdd, r_violation, r_wrench, r_kinetic, r_potential, r_momentum):
                return STAGE_SEPARATION, s
            if s == times.shape[0] - 1:
                return STAGE_OK, s + 1
        if semi is not None:
            _advance_semi_implicit(model_ints, x, d1, h, semi, E, xs)
            for a in range(nx):
                x[a] = xs[a]
            continue
        for a in range(nd):  # (d1 + 2 d2 + 2 d3 + d4) / 6, numpy's order of operations
            d1[a] = (((d1[a] + 2.0 * d2[a]) + 2.0 * d3[a]) + d4[a]) / 6.0
        _advance(model_ints, x, d1, h, hd, xs)
        for a in range(nx):
            x[a] = xs[a]
    return STAGE_OK, k1


@kernel
def _record(s, t, x, nq, nv, N, nv_arm, v_starts, unilateral, wrenches, separation, params,
            dims, buf, tau, energy, r_q, r_v, r_p, r_quat, r_tw, r_tau, r_mu, r_phi, r_phi_dot,
            r_points, r_normals, r_a_o, r_qdd, r_violation, r_wrench, r_kinetic, r_potential,
            r_momentum):  # pragma: no cover - compiled
    """Record sample ``s`` from its evaluation (arguments as :func:`run_rk4`'s).

    Returns False, recording nothing, if a unilateral row's gap or gap rate is past
    ``separation`` (the event machinery decides that sample).
    """
    k, m, n = dims[DIMS_K], dims[DIMS_M], dims[DIMS_N]
    off = offsets(dims)
    rows = view3(buf, off, SEG_ROWS, n, k, m)
    mu_s = view2(buf, off, SEG_MU, n, k, m)
    qdd_s = view2(buf, off, SEG_QDD, n, k, m)
    a_o = view1(buf, off, SEG_A_O)
    viol = 0.0
    for i in range(n):
        for r in range(N[i]):
            ph = rows[i, r, ROW_PHI]
            viol = max(viol, abs(ph))
            if unilateral[i, r] and (ph > separation[0] or rows[i, r, ROW_PHI_DOT] > separation[1]):
                return False
    record_state(s, t, x, nq, nv, nv_arm, v_starts, tau, qdd_s, a_o, wrenches, r_q, r_v, r_p,
                 r_quat, r_tw, r_tau, r_qdd, r_a_o, r_wrench)
    for i in range(n):
        for r in range(m):
            r_mu[s, i, r] = mu_s[i, r]
            r_phi[s, i, r] = rows[i, r, ROW_PHI]
            r_phi_dot[s, i, r] = rows[i, r, ROW_PHI_DOT]
            for a in range(3):
                r_points[s, i, r, a] = rows[i, r, ROW_POINT + a]
                r_normals[s, i, r, a] = rows[i, r, ROW_NORMAL + a]
    r_violation[s] = viol
    record_energy(s, x, params, energy, True, r_kinetic, r_potential, r_momentum)
    return True


@kernel(refcounts=False)
def record_state(s, t, x, nq, nv, nv_arm, v_starts, tau, qdd, a_o, wrenches, r_q, r_v, r_p,
                 r_quat, r_tw, r_tau, r_qdd, r_a_o, r_wrench):  # pragma: no cover - compiled
    """Record sample ``s``'s state ``x``, torques, accelerations and external wrench.

    ``tau`` and ``qdd`` are padded per arm, ``(n, k)``; ``a_o`` (6,); the wrench is the one at
    ``t``; the record arrays as :func:`run_rk4`'s.
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


__all__ = ["NULL_KD", "NULL_KP", "STAGE_CONTROLLER", "STAGE_NOT_FINITE", "STAGE_OK",
           "STAGE_RELEASE", "STAGE_RELEASE_IN_STEP", "STAGE_SEPARATION", "STAGE_SOLVE",
           "arm_compiles", "callee_compiles", "closed_loop_stage", "joint_pd", "loop_functions",
           "record_energy", "record_state", "run_rk4", "stage_entry", "tangent"]
