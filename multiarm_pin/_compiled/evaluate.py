"""Compiled fused evaluation: arm terms, constraint rows, blocks and solve into one buffer.

Mirrors :meth:`multiarm_pin.system.MultiArmSystem.blocks` with ``reference=True`` followed by
:func:`multiarm_pin.dynamics.object_first.solve_object_first_numpy`: one compiled call runs
:func:`~multiarm_pin._compiled.arm_terms.arm_terms`,
:func:`~multiarm_pin._compiled.constraint_rows.constraint_rows`,
:func:`~multiarm_pin._compiled.assembly.assemble` and (for a step)
:func:`~multiarm_pin._compiled.object_first.object_first`, so that one dynamics step costs a
handful of Python calls whatever the number of arms (the numpy versions spend most of their
time in the overhead of 60-80 small numpy calls).

Everything here takes and returns plain float64 / int64 arrays laid out in
:mod:`multiarm_pin._compiled.layout`: the state vector ``x`` (object state ``X_*``, then
``q``, ``v``, ``τ``), the arm table (``ARM_*``), the contact tables (``CI_*``, ``CF_*``),
the parameter vector (``P_*``), ``dims`` (``DIMS_*``) and the flat output buffer (segments
``SEG_*``). Conventions are those of ``docs/ARCHITECTURE.md``: SI units, spatial vectors
``[linear; angular]``, world axes, tool quantities LOCAL_WORLD_ALIGNED at the tool origin,
object quantities at the COM, ``μ > 0`` pushing.

Compilation is cached on disk (``cache=True``, in ``__pycache__``): the first call in a fresh
checkout compiles every kernel (its time: ``benchmarks/compile_times.py``), later processes
load them. Compile time grows with every
jitted function on a kernel's call path (each is compiled, and its LLVM code optimised again
inside each caller), so the kernels here call the leaf kernels directly, with their views
taken by inlined helpers.
"""

from __future__ import annotations

import math

import numpy as np

from multiarm_pin._compiled.arm_terms import arm_terms
from multiarm_pin._compiled.assembly import assemble
from multiarm_pin._compiled.constraint_rows import constraint_rows
from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.layout import (
    ARM_JOINTS,
    ARM_NV,
    CONTACT_FLOATS,
    CONTACT_INTS,
    DIMS_K,
    DIMS_M,
    DIMS_N,
    DIMS_NV,
    DIMS_SIZE,
    KIND_FRAME,
    KIND_PRISMATIC,
    KIND_REVOLUTE,
    KIND_REVOLUTE_UNBOUNDED,
    MI_IDX_Q,
    MI_KIND,
    MODEL_FLOATS,
    MODEL_INTS,
    OBJECT_STATE_SIZE,
    P_OBJECT_RCOND_TOL,
    P_RCOND_TOL,
    ROW_WIDTH,
    SEG_A_O,
    SEG_C,
    SEG_H,
    SEG_H_O,
    SEG_J,
    SEG_JDOT_QDOT,
    SEG_M,
    SEG_M_O,
    SEG_MU,
    SEG_NLE,
    SEG_POSITION,
    SEG_QDD,
    SEG_ROTATION,
    SEG_ROWS,
    SEG_TWIST,
    SEG_V,
    SEG_W,
    SEG_W_O,
    X_POSITION,
    X_QUATERNION,
    X_TWIST,
    offsets,
    shaped,
    view3,
)
from multiarm_pin._compiled.object_first import SOLVE_OK, object_first
from multiarm_pin._compiled.rigid_body import rigid_body_pass

SOLVE_NOT_FINITE = 3
"""Status of :func:`step_system`: the state or the torques hold NaN or infinity (the other
statuses are those of :func:`~multiarm_pin._compiled.object_first.object_first`)."""

SOLVE_BAD_LENGTH = 4
"""Status of :func:`evaluate_state`: a part of the state or the torques has the wrong length
(nothing computed; the caller's checks then name it)."""


@kernel
def quaternion_rotation(quat, R):  # pragma: no cover - compiled
    """Rotation matrix (3, 3) of a unit quaternion ``[x, y, z, w]`` into ``R``."""
    rows = rotation_rows(quat)
    for a in range(3):
        R[a, 0], R[a, 1], R[a, 2] = rows[a]


@kernel(refcounts=False)
def rotation_rows(quat):  # pragma: no cover - compiled
    """Rotation matrix of a unit quaternion ``[x, y, z, w]`` as three row tuples ``R[a][c]``.

    No array: :func:`quaternion_rotation` writes it into one.
    """
    x, y, z, w = quat[0], quat[1], quat[2], quat[3]
    return ((1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
            (2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
            (2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)))


# The segment views are taken by the three inlined helpers below, with the shapes of
# SEGMENT_TABLE written out (tests/test_kernels.py checks them against it): every other
# compiled function, or a call to a jitted helper, on the path of a kernel is one more
# numba compile and one more LLVM optimisation of everything it calls (issue 14), so the
# kernels take their views and call the leaf kernels themselves, with no glue in between.
@kernel(inline="always")
def _arm_segments(buf, off, n, k, m):  # pragma: no cover - compiled
    """Views of the arm segments (inlined): M, nle, J, Jdot_qdot, position, rotation, twist, v."""
    three, six = np.int64(3), np.int64(6)
    return (shaped(buf, off[SEG_M], (n, k, k)),
            shaped(buf, off[SEG_NLE], (n, k)),
            shaped(buf, off[SEG_J], (n, six, k)),
            shaped(buf, off[SEG_JDOT_QDOT], (n, six)),
            shaped(buf, off[SEG_POSITION], (n, three)),
            shaped(buf, off[SEG_ROTATION], (n, three, three)),
            shaped(buf, off[SEG_TWIST], (n, six)),
            shaped(buf, off[SEG_V], (n, k)))


@kernel(inline="always")
def _block_segments(buf, off, n, k, m):  # pragma: no cover - compiled
    """Views of the rows and block segments (inlined): rows, h, W, W_o, c, M_o, h_o."""
    six = np.int64(6)
    return (shaped(buf, off[SEG_ROWS], (n, m, np.int64(ROW_WIDTH))),
            shaped(buf, off[SEG_H], (n, k)),
            shaped(buf, off[SEG_W], (n, k, m)),
            shaped(buf, off[SEG_W_O], (n, six, m)),
            shaped(buf, off[SEG_C], (n, m)),
            shaped(buf, off[SEG_M_O], (six, six)),
            shaped(buf, off[SEG_H_O], (off[SEG_H_O + 1] - off[SEG_H_O],)))


@kernel(inline="always")
def _solution_segments(buf, off, n, k, m):  # pragma: no cover - compiled
    """Views of the solution segments (inlined): a_o, qdd, mu."""
    return (shaped(buf, off[SEG_A_O], (off[SEG_A_O + 1] - off[SEG_A_O],)),
            shaped(buf, off[SEG_QDD], (n, k)),
            shaped(buf, off[SEG_MU], (n, m)))


@kernel
def arm_views(buf, off, n, k, m):  # pragma: no cover - compiled
    """Views of the arm segments: M, nle, J, Jdot_qdot, position, rotation, twist, v."""
    return _arm_segments(buf, off, n, k, m)


@kernel
def block_views(buf, off, n, k, m):  # pragma: no cover - compiled
    """Views of the constraint rows and block segments: rows, h, W, W_o, c, M_o, h_o."""
    return _block_segments(buf, off, n, k, m)


@kernel
def solution_views(buf, off, n, k, m):  # pragma: no cover - compiled
    """Views of the solution segments: a_o, qdd, mu."""
    return _solution_segments(buf, off, n, k, m)


@kernel(inline="always")
def _group_arms_into(J_world, dJ_world, M_full, nle_full, H, x, arm_ints, nv, v_offset, lo,
                     M, nle, J, Jdq, p, R, tw, vp):  # pragma: no cover - compiled
    """:func:`arm_terms` of the group of arms ``lo..lo + len(H)`` into the arm views (inlined)."""
    k = M.shape[1]
    hi = lo + H.shape[0]
    start = x.shape[0] - 2 * nv + v_offset
    v = x[start:start + M_full.shape[0]]
    arm_terms(J_world, dJ_world, M_full, nle_full, v, H, arm_ints[:, ARM_JOINTS:ARM_JOINTS + k],
              arm_ints[:, ARM_NV], arm_ints[:, ARM_JOINTS + k:ARM_JOINTS + 2 * k], M[lo:hi],
              nle[lo:hi], J[lo:hi], Jdq[lo:hi], p[lo:hi], R[lo:hi], tw[lo:hi], vp[lo:hi])


@kernel(inline="always")
def _finish_into(x, arm_ints, v_starts, ints, floats, params, nv, nle, J, Jdq, p, R, tw,
                 rows, h, W, W_o, c, M_o, h_o):  # pragma: no cover - compiled
    """:func:`_finish` on the views themselves (inlined)."""
    for a in range(x.shape[0]):
        if not math.isfinite(x[a]):
            return False
    n, k = nle.shape
    obj_R = np.empty((3, 3))
    quaternion_rotation(x[X_QUATERNION:X_QUATERNION + 4], obj_R)
    obj_tw = x[X_TWIST:X_TWIST + 6]
    constraint_rows(p, R, tw, x[X_POSITION:X_POSITION + 3], obj_R, obj_tw, ints, floats, rows)
    tau = x[x.shape[0] - nv:]
    tau_p = np.zeros((n, k))
    for i in range(n):
        for a in range(arm_ints[i, ARM_NV]):
            tau_p[i, a] = tau[v_starts[i] + a]
    assemble(J, Jdq, nle, tau_p, rows, params, obj_R, obj_tw, h, W, W_o, c, M_o, h_o)
    return True


@kernel
def _finish(x, arm_ints, v_starts, ints, floats, params, nv, arms,
            blocks):  # pragma: no cover - compiled
    """Constraint rows and blocks from the arm views; False if ``x`` is not finite."""
    _, nle, J, Jdq, p, R, tw, _ = arms
    rows, h, W, W_o, c, M_o, h_o = blocks
    return _finish_into(x, arm_ints, v_starts, ints, floats, params, nv, nle, J, Jdq, p, R, tw,
                        rows, h, W, W_o, c, M_o, h_o)


@kernel
def solve_views(N, params, M, h, blocks, solution):  # pragma: no cover - compiled
    """:func:`object_first` on ``M``, ``h`` and the other block views into the solution views."""
    rows, _, W, W_o, c, M_o, h_o = blocks
    a_o, qdd, mu = solution
    return object_first(M, h, W, W_o, c, M_o, h_o, N, params[P_RCOND_TOL],
                        params[P_OBJECT_RCOND_TOL], a_o, qdd, mu)


@kernel
def group_arm_terms(J_world, dJ_world, M_full, nle_full, H, x, arm_ints, dims, v_offset,
                    first_arm, buf):  # pragma: no cover - compiled
    """:func:`arm_terms` of one group of consecutive arms into their rows of the buffer.

    Args:
        J_world: (6, nv_g) ``data.J`` of the group's combined Pinocchio model.
        dJ_world: (6, nv_g) ``data.dJ``.
        M_full: (nv_g, nv_g) ``data.M``.
        nle_full: (nv_g,) ``data.nle``.
        H: (n_g, 4, 4) the group's tool placements.
        x: (13 + nq + 2 nv,) the state vector (see :func:`evaluate_system`).
        arm_ints: (n_g, 1 + 2k) the group's rows of the arm table, joint indices relative
            to the group's velocity vector.
        dims: (DIMS_SIZE,) int ``(k, m, nv, n)``: nv_max, N_max, total joints and arms.
        v_offset: index of the group's first joint in the combined velocity.
        first_arm: index of the group's first arm.
        buf: the flat output buffer.
    """
    k, m, nv, n = dims[DIMS_K], dims[DIMS_M], dims[DIMS_NV], dims[DIMS_N]
    M, nle, J, Jdq, p, R, tw, vp = _arm_segments(buf, offsets(dims), n, k, m)
    _group_arms_into(J_world, dJ_world, M_full, nle_full, H, x, arm_ints, nv, v_offset,
                     first_arm, M, nle, J, Jdq, p, R, tw, vp)


@kernel
def finish_system(x, arm_ints, v_starts, ints, floats, params, dims,
                  buf):  # pragma: no cover - compiled
    """Constraint rows and blocks from the arm terms already in ``buf``.

    Args:
        x: (13 + nq + 2 nv,) the state vector (see :func:`evaluate_system`).
        arm_ints: (n, 1 + 2k) the arm table (see :func:`evaluate_system`).
        v_starts: (n,) int index of each arm's first joint in the combined velocity (joint
            indices of ``arm_ints`` may be relative to a group).
        ints: (K, CONTACT_INTS) int contact table.
        floats: (K, CONTACT_FLOATS) float contact table.
        params: (N_PARAMS,) the parameter vector.
        dims: (DIMS_SIZE,) int ``(k, m, nv, n)``.
        buf: the flat buffer (arm segments read, the others written).

    Returns:
        False (and nothing computed) if some entry of ``x`` is NaN or infinite.
    """
    k, m, nv, n = dims[DIMS_K], dims[DIMS_M], dims[DIMS_NV], dims[DIMS_N]
    off = offsets(dims)
    _, nle, J, Jdq, p, R, tw, _ = _arm_segments(buf, off, n, k, m)
    rows, h, W, W_o, c, M_o, h_o = _block_segments(buf, off, n, k, m)
    return _finish_into(x, arm_ints, v_starts, ints, floats, params, nv, nle, J, Jdq, p, R, tw,
                        rows, h, W, W_o, c, M_o, h_o)


@kernel
def solve_buffer(N, params, dims, buf):  # pragma: no cover - compiled
    """:func:`object_first` on the blocks of the buffer, solution into its last segments.

    Args:
        N: (n,) int constraint rows per arm.
        params: (N_PARAMS,) the parameter vector (the solver thresholds are read).
        dims: (DIMS_SIZE,) int ``(k, m, nv, n)``.
        buf: the flat buffer.

    Returns:
        The status of :func:`object_first`.
    """
    k, m, n = dims[DIMS_K], dims[DIMS_M], dims[DIMS_N]
    off = offsets(dims)
    M = view3(buf, off, SEG_M, n, k, m)
    _, h, W, W_o, c, M_o, h_o = _block_segments(buf, off, n, k, m)
    a_o, qdd, mu = _solution_segments(buf, off, n, k, m)
    return object_first(M, h, W, W_o, c, M_o, h_o, N, params[P_RCOND_TOL],
                        params[P_OBJECT_RCOND_TOL], a_o, qdd, mu)


@kernel
def evaluate_system(J_world, dJ_world, M_full, nle_full, H, x, arm_ints, v_starts, ints,
                    floats, params, dims, buf):  # pragma: no cover - compiled
    """Arm terms, constraint rows and blocks of one state into the flat buffer ``buf``.

    All arms in one combined Pinocchio model (one group); see :func:`group_arm_terms` and
    :func:`finish_system` for several.

    Args:
        J_world: (6, nv) ``data.J`` (see :func:`arm_terms`).
        dJ_world: (6, nv) ``data.dJ``.
        M_full: (nv, nv) ``data.M``.
        nle_full: (nv,) ``data.nle``.
        H: (n, 4, 4) tool placements.
        x: (13 + nq + 2 nv,) the state vector: the object state (``OBJECT_STATE_FIELDS``:
            position [m], quaternion ``[x, y, z, w]``, twist ``[ẋ; ω]``), then the arms'
            ``q`` (not read), ``v`` and joint torques ``τ`` [N m] (zeros for none): one array
            so that one finiteness test covers all.
        arm_ints: (n, 1 + 2k) int, the arm table (``ARM_*``: joints per arm, joint indices
            (see ``idx`` of :func:`arm_terms`), tool-support mask).
        v_starts: (n,) int index of each arm's first joint in the combined velocity.
        ints: (K, CONTACT_INTS) int contact table (:class:`~.layout.ContactTables`).
        floats: (K, CONTACT_FLOATS) float contact table.
        params: (N_PARAMS,) the parameter vector (``PARAM_FIELDS``: object mass [kg],
            inertia about the COM in object axes [kg m²], gravity [m/s²], Baumgarte
            ``(α, β, on)``, the solver thresholds, read by :func:`solve_buffer` only).
        dims: (DIMS_SIZE,) int ``(k, m, nv, n) = (nv_max, N_max, total joints, arms)``.
        buf: output, the flat buffer (segments of :data:`~.layout.SEGMENT_TABLE`).

    Returns:
        False (and the buffer meaningless) if some entry of ``x`` is NaN or infinite.
    """
    k, m, nv, n = dims[DIMS_K], dims[DIMS_M], dims[DIMS_NV], dims[DIMS_N]
    off = offsets(dims)
    M, nle, J, Jdq, p, R, tw, vp = _arm_segments(buf, off, n, k, m)
    rows, h, W, W_o, c, M_o, h_o = _block_segments(buf, off, n, k, m)
    _group_arms_into(J_world, dJ_world, M_full, nle_full, H, x, arm_ints, nv, 0, 0,
                     M, nle, J, Jdq, p, R, tw, vp)
    return _finish_into(x, arm_ints, v_starts, ints, floats, params, nv, nle, J, Jdq, p, R, tw,
                        rows, h, W, W_o, c, M_o, h_o)


@kernel
def step_system(J_world, dJ_world, M_full, nle_full, H, x, arm_ints, v_starts, ints, floats,
                params, dims, N, buf):  # pragma: no cover - compiled
    """:func:`evaluate_system` then :func:`object_first` on the buffer (one full step).

    Args:
        J_world: see :func:`evaluate_system` (likewise every argument but ``N``).
        dJ_world: (6, nv).
        M_full: (nv, nv).
        nle_full: (nv,).
        H: (n, 4, 4).
        x: (13 + nq + 2 nv,).
        arm_ints: (n, 1 + 2k).
        v_starts: (n,).
        ints: (K, CONTACT_INTS).
        floats: (K, CONTACT_FLOATS).
        params: (N_PARAMS,), the solver thresholds included.
        dims: (DIMS_SIZE,).
        N: (n,) int constraint rows per arm.
        buf: output buffer; the segments ``a_o``, ``qdd``, ``mu`` receive the solution.

    Returns:
        The status of :func:`object_first`, or ``SOLVE_NOT_FINITE`` if ``x`` holds NaN or
        infinity (nothing computed then).
    """
    if not evaluate_system(J_world, dJ_world, M_full, nle_full, H, x, arm_ints, v_starts, ints,
                           floats, params, dims, buf):  # called, not inlined: compiled once
        return SOLVE_NOT_FINITE
    k, m, n = dims[DIMS_K], dims[DIMS_M], dims[DIMS_N]
    off = offsets(dims)
    M = view3(buf, off, SEG_M, n, k, m)
    rows, h, W, W_o, c, M_o, h_o = _block_segments(buf, off, n, k, m)
    a_o, qdd, mu = _solution_segments(buf, off, n, k, m)
    return object_first(M, h, W, W_o, c, M_o, h_o, N, params[P_RCOND_TOL],
                        params[P_OBJECT_RCOND_TOL], a_o, qdd, mu)


def state_tables(model_ints, model_floats, arm_ints, v_starts, ints, floats, dims, N
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The constant inputs of :func:`evaluate_state` packed in three flat arrays.

    Each array argument of a kernel adds to its dispatch at every call (issue 14): eight
    tables become three, grouped so that each unpacked table keeps its type (read-only or
    writable) and the kernels called with them compile no other specialisation.

    Args:
        model_ints: (rows, MODEL_INTS) the arms' model table (read-only).
        model_floats: (rows, MODEL_FLOATS) its float table (read-only).
        arm_ints: (n, 1 + 2k) the arm table.
        v_starts: (n,) int first joint of each arm in ``v``.
        ints: (K, CONTACT_INTS) contact table (read-only).
        floats: (K, CONTACT_FLOATS) contact table (read-only).
        dims: (DIMS_SIZE,) ``(k, m, nv, n)``.
        N: (n,) int constraint rows per arm.

    Returns:
        ``(tables_ro, tables, floats_ro)``: read-only int64 ``[model_ints, ints, N]``,
        writable int64 ``[rows, K, dims, v_starts, arm_ints]``, read-only float64
        ``[model_floats, floats]`` (each flattened, C order).
    """
    ro = np.concatenate((np.ravel(model_ints), np.ravel(ints), np.ravel(N))).astype(np.int64)
    rw = np.concatenate(([len(model_ints), len(ints)], np.ravel(dims), np.ravel(v_starts),
                         np.ravel(arm_ints))).astype(np.int64)
    fl = np.concatenate((np.ravel(model_floats), np.ravel(floats))).astype(np.float64)
    ro.setflags(write=False)
    fl.setflags(write=False)
    return ro, rw, fl


@kernel
def evaluate_state(tables_ro, tables, floats_ro, M_full, position, quaternion, twist, q, v,
                   tau, params, step, buf):  # pragma: no cover - compiled
    """:func:`evaluate_system` (``step``: :func:`step_system`) with the arm terms computed here.

    Unpacks the constant tables (:func:`state_tables`), packs the state vector ``x`` (see
    :func:`evaluate_system`) from its parts, checking their lengths (in the kernel: one
    Python-side check or ``np.concatenate`` per part cost more than the rest of the call's
    Python, issue 14), then :func:`~multiarm_pin._compiled.rigid_body.rigid_body_pass`
    (Pinocchio's algorithms, on the arms' model tables) fills ``M_full`` (arm blocks only:
    keep it zero elsewhere) and its other outputs, allocated here (an allocation costs less
    than an array argument's dispatch), at ``q``, ``v``, without the energies; then the blocks
    (and the solve) as there. One compiled call for the whole evaluation.

    Args:
        tables_ro: the read-only int tables of :func:`state_tables` (model table, contact
            table, constraint rows per arm).
        tables: its writable int tables (sizes, ``dims``, ``v_starts``, arm table).
        floats_ro: its read-only float tables (model and contact tables).
        M_full: workspace (nv, nv), the mass matrix (arm blocks; zero elsewhere).
        position: (3,) the object's COM position [m].
        quaternion: (4,) its orientation ``[x, y, z, w]``.
        twist: (6,) its twist ``[ẋ; ω]`` (world axes).
        q: (nq,) the arms' configuration; ``nq`` is the length ``rigid_body_pass`` reads
            from the model table.
        v: (nv,) the arms' velocity.
        tau: (nv,) joint torques [N m].
        params: (N_PARAMS,) the parameter vector.
        step: also solve (object-first) into the buffer.
        buf: output, the flat buffer.

    Returns:
        The status of :func:`object_first` (``SOLVE_OK`` when not solving),
        ``SOLVE_NOT_FINITE`` if the state or the torques hold NaN or infinity, or
        ``SOLVE_BAD_LENGTH`` if a part has the wrong length (nothing computed for either).
    """
    rows, K = tables[0], tables[1]
    at = 2 + DIMS_SIZE
    dims = tables[2:at]
    k, nv, n = dims[DIMS_K], dims[DIMS_NV], dims[DIMS_N]
    v_starts = tables[at:at + n]
    width = ARM_JOINTS + 2 * k
    arm_ints = tables[at + n:at + n + n * width].reshape((n, width))
    at = rows * MODEL_INTS
    model_ints = tables_ro[:at].reshape((rows, MODEL_INTS))
    ints = tables_ro[at:at + K * CONTACT_INTS].reshape((K, CONTACT_INTS))
    N = tables_ro[at + K * CONTACT_INTS:at + K * CONTACT_INTS + n]
    at = rows * MODEL_FLOATS
    model_floats = floats_ro[:at].reshape((rows, MODEL_FLOATS))
    floats = floats_ro[at:at + K * CONTACT_FLOATS].reshape((K, CONTACT_FLOATS))
    nq = 0
    n_tools = 0
    for i in range(rows):  # the configuration's length and the tool frames
        kind = model_ints[i, MI_KIND]
        if kind == KIND_REVOLUTE or kind == KIND_PRISMATIC:
            nq = max(nq, model_ints[i, MI_IDX_Q] + 1)
        elif kind == KIND_REVOLUTE_UNBOUNDED:
            nq = max(nq, model_ints[i, MI_IDX_Q] + 2)
        elif kind == KIND_FRAME:
            n_tools += 1
    if (position.shape[0] != 3 or quaternion.shape[0] != 4 or twist.shape[0] != 6
            or q.shape[0] != nq or v.shape[0] != nv or tau.shape[0] != nv):
        return SOLVE_BAD_LENGTH
    q0 = OBJECT_STATE_SIZE
    x = np.empty(q0 + nq + 2 * nv)
    x[X_POSITION:X_POSITION + 3] = position
    x[X_QUATERNION:X_QUATERNION + 4] = quaternion
    x[X_TWIST:X_TWIST + 6] = twist
    x[q0:q0 + nq] = q
    x[q0 + nq:q0 + nq + nv] = v
    x[q0 + nq + nv:] = tau
    J_world = np.empty((6, nv))
    dJ_world = np.empty((6, nv))
    nle_full = np.empty(nv)
    H = np.empty((n_tools, 4, 4))
    rigid_body_pass(model_ints, model_floats, x[q0:q0 + nq], x[q0 + nq:q0 + nq + nv], J_world,
                    dJ_world, M_full, nle_full, H, np.empty(0))
    if step:
        return step_system(J_world, dJ_world, M_full, nle_full, H, x, arm_ints, v_starts, ints,
                           floats, params, dims, N, buf)
    if evaluate_system(J_world, dJ_world, M_full, nle_full, H, x, arm_ints, v_starts, ints,
                       floats, params, dims, buf):
        return SOLVE_OK
    return SOLVE_NOT_FINITE


__all__ = ["SOLVE_BAD_LENGTH", "SOLVE_NOT_FINITE", "arm_views", "block_views", "evaluate_state",
           "evaluate_system", "finish_system", "group_arm_terms", "quaternion_rotation",
           "solution_views", "solve_buffer", "solve_views", "state_tables", "step_system"]
