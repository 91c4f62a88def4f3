"""Compiled (numba) object-level controller: ``ObjectPD`` on the buffer of the compiled path.

:class:`~multiarm_pin.sim.controllers.ObjectPD` computes, from the blocks of one state, the held
points' desired accelerations, the joint accelerations of their damped least-squares task,
the force distribution and the inverse dynamics of thesis Eq 3.7-3.10. Its numpy version
(``ObjectPD.reference``) is the oracle; :func:`object_pd_torques` computes the same torques
arm by arm from the flat buffer of :mod:`multiarm_pin._compiled.evaluate` (no dense system over
all arms, no SVD: the internal forces come from
:func:`~multiarm_pin._compiled.force_qp.least_norm_forces`, each arm's constraint rows are met
by a Householder QR of ``W_i``), and :func:`solve_with_torques` then solves the forward
dynamics with these torques on the same blocks (one Pinocchio pass and one set of blocks per
evaluation).
With some unilateral contacts separated, :func:`touching_torques` plans on the touching rows
only (or reports :data:`PD_HOLD` when they cannot make every object wrench, and
:func:`hold_still_torques` gives the arms' hold).

Whenever a step is doubtful (an arm's ``W_i`` not of full column rank with margin, the force
QP not converged or degenerate, NaN) the kernels report it and the caller runs the numpy
reference, which decides and raises exactly as documented there. Conventions as in
``docs/ARCHITECTURE.md``: SI units, ``[linear; angular]``, world axes, tool quantities LWA at
the tool origin, object quantities at the COM, ``μ > 0`` pushing. The vectors the kernels
read (object pose ``OX_*``, reference ``REF_*``, gains ``PD_*`` and ``GAIN_*``, parameters
``P_*``, ``dims``) are laid out in :mod:`multiarm_pin._compiled.layout`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from multiarm_pin._compiled.evaluate import (
    _arm_segments,
    _block_segments,
    _solution_segments,
    quaternion_rotation,
)
from multiarm_pin._compiled.force_qp import QP_OK, least_norm_forces
from multiarm_pin._compiled.function_pointers import Compile, bind, compile_of, pointer
from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.layout import (
    DIMS_K,
    DIMS_M,
    DIMS_N,
    GAIN_DAMPING,
    GAIN_HOLD_KD,
    GAIN_HOLD_KP,
    GAIN_MARGIN,
    OX_POSITION,
    OX_ROTATION,
    OX_TWIST,
    P_OBJECT_RCOND_TOL,
    P_RCOND_TOL,
    PD_KD,
    PD_KP,
    REF_ACCELERATION,
    REF_POSITION,
    REF_ROTATION,
    REF_TWIST,
    SEG_H,
    SEG_M,
    X_POSITION,
    X_QUATERNION,
    X_TWIST,
    offsets,
    view2,
    view3,
)
from multiarm_pin._compiled.linalg import (
    cholesky,
    cholesky_solve,
    householder_qr,
    householder_reflect,
    singular_values,
)
from multiarm_pin._compiled.object_first import object_first

PD_OK = 0
"""Status of :func:`object_pd_torques`: torques computed."""
PD_FORCES_FAILED = 1
"""Status: the warm-started force QP failed (the caller solves it cold)."""
PD_ARM_RANK = 2
"""Status: some ``W_i`` is not of full column rank with margin, or the hold task's
``AᵀA + ε I`` of an arm with fewer rows than joints is not positive definite (the caller
uses the reference, whose pseudo-inverse decides)."""
PD_NOT_FINITE = 3
"""Status: NaN or infinity in the result."""
PD_LARGE_ROTATION = 4
"""Status: the object's orientation error is within 1e-3 rad of π (the caller uses the
reference's ``pin.log3``, which handles that case)."""

PD_HOLD = 5
"""Status of :func:`touching_torques`: the touching contacts cannot make every object wrench
(grasp rank < 6): the controller holds the arms still (:func:`hold_still_torques`)."""

GRASP_RANK_TOLERANCE = 1e-9
"""Relative singular value below which the touching contacts' wrench map is rank deficient
(``object_pd.grasp_rank`` and :func:`touching_rank`)."""

NULL_KP = 0
"""``null_gains[NULL_KP]``: ``object_pd``'s joint-space stiffness ``null_kp`` [1/s²]."""
NULL_KD = 1
"""``null_gains[NULL_KD]``: its damping ``null_kd`` [1/s]."""

RANK_MARGIN = 1e-7
"""``W_i`` counts as of full column rank when its smallest QR pivot is above this times the
largest: three orders of magnitude above the reference's singular-value threshold
(``inverse_dynamics.RANK_TOL = 1e-10``), more than the factor between QR pivots and singular
values for the at most 6-7 columns of an arm's rows."""


@kernel
def min_norm_rows(W, ncols, nrows, g, x, Q, beta):  # pragma: no cover - compiled
    """Minimum-norm ``x`` with ``W[:nrows, :ncols]ᵀ x = g`` by Householder QR of ``W``.

    Args:
        W: (k, m) an arm's ``W_i`` (only ``[:nrows, :ncols]`` read).
        ncols: constraint rows ``N_i`` (columns of ``W_i``).
        nrows: joints ``k`` (rows).
        g: (ncols,) right-hand side.
        x: output (nrows,) (also the scratch of the factorisation: nothing is allocated).
        Q: scratch (k, m) (the Householder vectors and ``R`` of
            :func:`~multiarm_pin._compiled.linalg.householder_qr`).
        beta: scratch (m,).

    Returns:
        False if ``W`` is not of full column rank with the margin :data:`RANK_MARGIN`
        (``x`` then meaningless). With ``ncols == nrows`` the solution is the only one,
        ``W⁻ᵀ g``.
    """
    if ncols > nrows:
        return False  # more columns than rows: not of full column rank
    for a in range(nrows):
        for s in range(ncols):
            Q[a, s] = W[a, s]
    householder_qr(Q, nrows, ncols, beta, x)  # R's diagonal in x for now
    rmax = 0.0
    rmin = np.inf
    for j in range(ncols):
        rmax = max(rmax, abs(x[j]))
        rmin = min(rmin, abs(x[j]))
    if not (ncols == 0 or rmin > RANK_MARGIN * rmax):
        return False
    # Wᵀ x = Rᵀ Qᵀ x = g: y = R⁻ᵀ g (forward substitution, y[j] over R[j, j] in x[j]),
    # x = H_0 ... H_{N-1} [y; 0]
    for j in range(ncols):
        acc = g[j]
        for p in range(j):
            acc -= Q[p, j] * x[p]  # R[p, j] (p < j) is stored above the diagonal
        x[j] = acc / x[j]
    for a in range(ncols, nrows):
        x[a] = 0.0
    for j in range(ncols - 1, -1, -1):
        householder_reflect(Q, nrows, j, beta, x)
    return True


@kernel
def _forces_and_torques(M, J, Jdq, tp, tR, ttw, h, W, W_o, c, M_o, h_o, N, nv_arm, unilateral,
                        obj_x, a_d, z, hold_tool, hold_obj, hold_n, gains, active, tau, mu, qdd,
                        a_pts):  # pragma: no cover - compiled
    """:func:`object_pd_torques` on the buffer views.

    An arm whose constraint rows fix its joint accelerations (``N_i = nv_i``: ``W_i`` square)
    skips the hold task (step 2's task rows, step 3): its ``q̈_i = W_i⁻ᵀ (c_i - W_o,iᵀ a_d)``
    whatever ``q̈_des`` is, as the reference's projection of step 4 gives it. Its status then
    depends on ``W_i`` alone (:data:`PD_ARM_RANK` when not of full rank with margin), not on
    the hold task's matrix ``AᵀA + ε I``, which the reference factors but whose solution
    drops out.

    Not inlined (``inline="always"``): numba deep-copies the IR of an inlined function, which
    for this one costs more than compiling it separately.
    """
    n, k, m = W.shape
    # 1. internal forces: the least-norm QP, warm-started
    wrench = np.empty(6)
    for a in range(6):
        acc = -h_o[a]
        for b in range(6):
            acc += M_o[a, b] * a_d[b]
        wrench[a] = acc
    status, _ = least_norm_forces(W_o, N, unilateral, wrench, gains[GAIN_MARGIN], active, mu,
                                  20 + 2 * n * m)
    if status != QP_OK:
        return PD_FORCES_FAILED
    return planned_torques(M, J, Jdq, tp, tR, ttw, h, W, W_o, c, N, nv_arm, obj_x, a_d, z,
                           hold_tool, hold_obj, hold_n, gains, tau, mu, qdd, a_pts)


@kernel
def planned_torques(M, J, Jdq, tp, tR, ttw, h, W, W_o, c, N, nv_arm, obj_x, a_d, z, hold_tool,
                    hold_obj, hold_n, gains, tau, mu, qdd, a_pts):  # pragma: no cover - compiled
    """Steps 2-5 of :func:`_forces_and_torques` with the multipliers ``mu`` planned already.

    The held points' tasks at the object acceleration ``a_d``, their joint accelerations and
    the inverse dynamics on the rows ``W``, ``W_o``, ``c`` (``N[i]`` per arm) with the
    object's acceleration ``a_d`` and the multipliers ``mu`` (n, m): ``τ_i = M_i q̈_i - h_i -
    W_i μ_i``. Also the torques of ``phased_pd``
    (:func:`multiarm_pin._compiled.phased.phased_torques`), whose forces include the supports'.

    Returns:
        :data:`PD_OK`, :data:`PD_ARM_RANK` or :data:`PD_NOT_FINITE`.
    """
    n, k, m = W.shape
    hold_kp, hold_kd = gains[GAIN_HOLD_KP], gains[GAIN_HOLD_KD]
    damping = gains[GAIN_DAMPING]
    # 2. held points' desired accelerations, per arm (3-vectors as scalars: ``d``, ``r``,
    # ``e``, ``u`` of each point; the object's pose and twist, ``ω̇`` of ``a_d``)
    op0, op1, op2 = obj_x[OX_POSITION], obj_x[OX_POSITION + 1], obj_x[OX_POSITION + 2]
    oR = obj_x[OX_ROTATION:OX_ROTATION + 9]  # row-major
    ov0, ov1, ov2 = obj_x[OX_TWIST], obj_x[OX_TWIST + 1], obj_x[OX_TWIST + 2]
    ow0, ow1, ow2 = obj_x[OX_TWIST + 3], obj_x[OX_TWIST + 4], obj_x[OX_TWIST + 5]
    al0, al1, al2 = a_d[3], a_d[4], a_d[5]
    hmax = hold_tool.shape[1]
    A = np.zeros((3 * hmax, k))
    rhs = np.zeros(3 * hmax)
    K = np.empty((k, k))
    L = np.zeros((k, k))
    sol = np.empty((k, 1))
    QR = np.empty((k, m))
    beta = np.empty(m)
    gap = np.empty(m)
    x = np.empty(k)
    for i in range(n):
        R = tR[i]
        wt0, wt1, wt2 = ttw[i, 3], ttw[i, 4], ttw[i, 5]
        nh = hold_n[i]
        Ni = N[i]
        nvi = nv_arm[i]
        task = Ni != nvi  # else W_i square: the rows alone fix q̈_i (see the docstring)
        for p in range(nh):
            h0, h1, h2 = hold_tool[i, p, 0], hold_tool[i, p, 1], hold_tool[i, p, 2]
            d0 = R[0, 0] * h0 + R[0, 1] * h1 + R[0, 2] * h2
            d1 = R[1, 0] * h0 + R[1, 1] * h1 + R[1, 2] * h2
            d2 = R[2, 0] * h0 + R[2, 1] * h1 + R[2, 2] * h2
            g0, g1, g2 = hold_obj[i, p, 0], hold_obj[i, p, 1], hold_obj[i, p, 2]
            xa = tp[i, 0] + d0
            r0 = xa - op0
            e0 = op0 + oR[0] * g0 + oR[1] * g1 + oR[2] * g2 - xa
            xa = tp[i, 1] + d1
            r1 = xa - op1
            e1 = op1 + oR[3] * g0 + oR[4] * g1 + oR[5] * g2 - xa
            xa = tp[i, 2] + d2
            r2 = xa - op2
            e2 = op2 + oR[6] * g0 + oR[7] * g1 + oR[8] * g2 - xa
            # u = v_t + ω_t × d - ẋ_o - ω_o × r
            u0 = ttw[i, 0] + wt1 * d2 - wt2 * d1 - ov0 - (ow1 * r2 - ow2 * r1)
            u1 = ttw[i, 1] + wt2 * d0 - wt0 * d2 - ov1 - (ow2 * r0 - ow0 * r2)
            u2 = ttw[i, 2] + wt0 * d1 - wt1 * d0 - ov2 - (ow0 * r1 - ow1 * r0)
            # transport: ẍ_o + ω̇_o × r + ω_o × (ω_o × r) + 2 ω_o × u + (kp e - kd u)
            s0 = ow1 * r2 - ow2 * r1
            s1 = ow2 * r0 - ow0 * r2
            s2 = ow0 * r1 - ow1 * r0
            apt0 = (a_d[0] + (al1 * r2 - al2 * r1) + (ow1 * s2 - ow2 * s1)
                    + 2.0 * (ow1 * u2 - ow2 * u1) + hold_kp * e0 - hold_kd * u0)
            apt1 = (a_d[1] + (al2 * r0 - al0 * r2) + (ow2 * s0 - ow0 * s2)
                    + 2.0 * (ow2 * u0 - ow0 * u2) + hold_kp * e1 - hold_kd * u1)
            apt2 = (a_d[2] + (al0 * r1 - al1 * r0) + (ow0 * s1 - ow1 * s0)
                    + 2.0 * (ow0 * u1 - ow1 * u0) + hold_kp * e2 - hold_kd * u2)
            a_pts[i, p, 0] = apt0
            a_pts[i, p, 1] = apt1
            a_pts[i, p, 2] = apt2
            if not task:
                continue
            # task rows A = J_v + J_ω × d; a0 = J̇q̇_v + J̇q̇_ω × d + ω_t × (ω_t × d)
            for j in range(nvi):
                A[3 * p + 0, j] = J[i, 0, j] + J[i, 4, j] * d2 - J[i, 5, j] * d1
                A[3 * p + 1, j] = J[i, 1, j] + J[i, 5, j] * d0 - J[i, 3, j] * d2
                A[3 * p + 2, j] = J[i, 2, j] + J[i, 3, j] * d1 - J[i, 4, j] * d0
            s0 = wt1 * d2 - wt2 * d1
            s1 = wt2 * d0 - wt0 * d2
            s2 = wt0 * d1 - wt1 * d0
            rhs[3 * p + 0] = apt0 - (Jdq[i, 0] + Jdq[i, 4] * d2 - Jdq[i, 5] * d1
                                     + wt1 * s2 - wt2 * s1)
            rhs[3 * p + 1] = apt1 - (Jdq[i, 1] + Jdq[i, 5] * d0 - Jdq[i, 3] * d2
                                     + wt2 * s0 - wt0 * s2)
            rhs[3 * p + 2] = apt2 - (Jdq[i, 2] + Jdq[i, 3] * d1 - Jdq[i, 4] * d0
                                     + wt0 * s1 - wt1 * s0)
        # the right-hand side of the arm's rows W_iᵀ q̈_i = c_i - W_o,iᵀ a_d
        for s in range(Ni):
            acc = c[i, s]
            for a in range(6):
                acc -= W_o[i, a, s] * a_d[a]
            gap[s] = acc
        for j in range(k):
            qdd[i, j] = 0.0
        if task:
            # 3. q̈_des = z + (AᵀA + ε s I)⁻¹ Aᵀ (rhs - A z), s = trace(AᵀA) / nv_i
            nr = 3 * nh
            for p in range(nr):
                acc = rhs[p]
                for j in range(nvi):
                    acc -= A[p, j] * z[i, j]
                rhs[p] = acc
            tr = 0.0
            for a in range(nvi):
                for b in range(a + 1):
                    acc = 0.0
                    for p in range(nr):
                        acc += A[p, a] * A[p, b]
                    K[a, b] = acc
                    K[b, a] = acc
                tr += K[a, a]
                acc = 0.0
                for p in range(nr):
                    acc += A[p, a] * rhs[p]
                sol[a, 0] = acc
            eps = damping * tr / nvi
            for a in range(nvi):
                K[a, a] += eps
            if not cholesky(K, L, nvi):
                return PD_ARM_RANK
            cholesky_solve(L, sol, nvi, np.int64(1))
            for j in range(nvi):
                qdd[i, j] = z[i, j] + sol[j, 0]
            for s in range(Ni):
                acc = gap[s]
                for j in range(nvi):
                    acc -= W[i, j, s] * qdd[i, j]
                gap[s] = acc
        # 4. inverse dynamics: the q̈_i closest to q̈_des (0 for a square W_i: it fixes q̈_i)
        # with W_iᵀ q̈_i = c_i - W_o,iᵀ a_d
        if Ni > nvi or not min_norm_rows(W[i], Ni, nvi, gap, x, QR, beta):
            return PD_ARM_RANK
        for j in range(nvi):
            qdd[i, j] += x[j]
        # 5. τ_i = M_i q̈_i - h_i - W_i μ_i (zero on padding)
        for j in range(k):
            if j >= nvi:
                tau[i, j] = 0.0
                continue
            acc = -h[i, j]
            for b in range(k):
                acc += M[i, j, b] * qdd[i, b]
            for s in range(Ni):
                acc -= W[i, j, s] * mu[i, s]
            tau[i, j] = acc
    total = 0.0
    for i in range(n):
        for j in range(k):
            total += tau[i, j]
    if not math.isfinite(total):
        return PD_NOT_FINITE
    return PD_OK


@kernel
def object_pd_torques(buf, dims, N, nv_arm, unilateral, obj_x, a_d, z, hold_tool, hold_obj,
                      hold_n, gains, active, tau, mu, qdd, a_pts):  # pragma: no cover - compiled
    """``ObjectPD`` torques from the flat buffer of the compiled path (see the module docstring).

    Args:
        buf: the flat buffer of :func:`~multiarm_pin._compiled.evaluate.evaluate_system`
            (blocks at zero torque, ``h = -nle``).
        dims: (DIMS_SIZE,) int ``(k, m, nv, n)``.
        N: (n,) int constraint rows per arm.
        nv_arm: (n,) int joints per arm.
        unilateral: (n, m) bool mask of unilateral multipliers.
        obj_x: (OBJECT_POSE_SIZE,) object COM position [m], rotation (9, row-major), twist
            ``[ẋ; ω]`` (``OBJECT_POSE_FIELDS``).
        a_d: (6,) desired object acceleration ``[ẍ; ω̇]`` at the COM [m/s², rad/s²].
        z: (n, k) joint-space PD ``null_kp (q_ref ⊖ q) - null_kd v`` [rad/s²], zero padding.
        hold_tool: (n, h, 3) held points in the tool frame [m].
        hold_obj: (n, h, 3) their places in the object frame [m].
        hold_n: (n,) int held points per arm (the first ``hold_n[i]`` are real).
        gains: (HOLD_GAINS_SIZE,) ``hold_kp`` [1/s²], ``hold_kd`` [1/s], Jacobian damping
            (relative), margin [N] (``HOLD_GAIN_FIELDS``).
        active: (n, m) uint8 active set of the force QP (in: warm start, out: the new one).
        tau: output (n, k) torques [N m] to add to ``h``.
        mu: output (n, m) planned multipliers [N].
        qdd: output (n, k) planned joint accelerations.
        a_pts: output (n, h, 3) desired point accelerations [m/s²] (untouched on padding).

    Returns:
        :data:`PD_OK`, or the reason the caller must use the reference.
    """
    k, m, n = dims[DIMS_K], dims[DIMS_M], dims[DIMS_N]
    off = offsets(dims)
    M, _, J, Jdq, tp, tR, ttw, _ = _arm_segments(buf, off, n, k, m)
    _, h, W, W_o, c, M_o, h_o = _block_segments(buf, off, n, k, m)
    return _forces_and_torques(M, J, Jdq, tp, tR, ttw, h, W, W_o, c, M_o, h_o, N, nv_arm,
                               unilateral, obj_x, a_d, z, hold_tool, hold_obj, hold_n, gains,
                               active, tau, mu, qdd, a_pts)


@kernel
def log3(R, out):  # pragma: no cover - compiled
    """Rotation vector ``θ u`` (3,) of a rotation matrix into ``out`` (``pin.log3``).

    ``θ = atan2(|v| / 2, (tr R - 1) / 2)`` with ``v = vee(R - Rᵀ)``, accurate for every angle
    up to near π, where ``v`` vanishes: returns False when ``θ > π - 1e-3``.
    """
    vx = R[2, 1] - R[1, 2]
    vy = R[0, 2] - R[2, 0]
    vz = R[1, 0] - R[0, 1]
    s = 0.5 * math.sqrt(vx * vx + vy * vy + vz * vz)
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    theta = math.atan2(s, c)
    if theta > math.pi - 1e-3:
        return False
    f = 0.5 * theta / s if s > 0.0 else 0.5
    out[0] = f * vx
    out[1] = f * vy
    out[2] = f * vz
    return True


@kernel
def desired_acceleration(obj, ref, pd_gains, obj_x, a_d):  # pragma: no cover - compiled
    """The PD on the object pose, ``a_d = a_ref + K_d (v_ref - v_o) + K_p e``.

    ``e = [p_ref - p; log(R_ref Rᵀ)]``: the part of :func:`object_pd_step` before the
    torques.

    Args:
        obj: (OBJECT_STATE_SIZE,) object position [m], quaternion ``[x, y, z, w]``, twist
            ``[ẋ; ω]`` (``OBJECT_STATE_FIELDS``).
        ref: (REFERENCE_SIZE,) reference position [m], rotation (row-major), twist, classical
            acceleration, world axes at the COM (``REFERENCE_FIELDS``).
        pd_gains: (PD_GAINS_SIZE,) ``K_p`` (6) [1/s²], ``K_d`` (6) [1/s].
        obj_x: output (OX_TWIST + 6,) the object's position, rotation (row-major) and twist
            (``OBJECT_POSE_FIELDS``), as :func:`object_pd_torques` reads them.
        a_d: output (6,) desired object acceleration ``[ẍ; ω̇]`` at the COM [m/s², rad/s²].

    Returns:
        False when the orientation error is within 1e-3 rad of π (``a_d`` then not written:
        the caller reports :data:`PD_LARGE_ROTATION`).
    """
    Ro = np.empty((3, 3))
    quaternion_rotation(obj[X_QUATERNION:X_QUATERNION + 4], Ro)
    for a in range(3):
        obj_x[OX_POSITION + a] = obj[X_POSITION + a]
        for b in range(3):
            obj_x[OX_ROTATION + 3 * a + b] = Ro[a, b]
    for a in range(6):
        obj_x[OX_TWIST + a] = obj[X_TWIST + a]
    # pose error: [p_ref - p; log(R_ref Rᵀ)]
    E = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            acc = 0.0
            for p in range(3):
                acc += ref[REF_ROTATION + 3 * a + p] * Ro[b, p]
            E[a, b] = acc
    rot = np.empty(3)
    if not log3(E, rot):
        return False
    for a in range(6):
        e = ref[REF_POSITION + a] - obj[X_POSITION + a] if a < 3 else rot[a - 3]
        a_d[a] = (ref[REF_ACCELERATION + a]
                  + pd_gains[PD_KD + a] * (ref[REF_TWIST + a] - obj[X_TWIST + a])
                  + pd_gains[PD_KP + a] * e)
    return True


@kernel
def object_pd_step(buf, dims, N, nv_arm, unilateral, obj, ref, pd_gains, z, hold_tool,
                   hold_obj, hold_n, gains, active, tau, mu, qdd, a_pts,
                   a_d):  # pragma: no cover - compiled
    """``ObjectPD``'s torques on the buffer: the desired acceleration, then the plan.

    One compiled call per evaluation: the PD on the object pose
    ``a_d = a_ref + K_d (v_ref - v_o) + K_p [p_ref - p; log(R_ref Rᵀ)]``, then
    :func:`object_pd_torques`. The forward dynamics with these torques is
    :func:`solve_with_torques`, a separate compile (the compiled loop and
    :func:`touching_torques` never ask for it).

    Args:
        buf: the flat buffer (blocks at zero torque; read only).
        dims: (DIMS_SIZE,) int ``(k, m, nv, n)``.
        N: (n,) int constraint rows per arm.
        nv_arm: (n,) int joints per arm.
        unilateral: (n, m) bool.
        obj: (OBJECT_STATE_SIZE,) object position [m], quaternion ``[x, y, z, w]``, twist
            ``[ẋ; ω]`` (``OBJECT_STATE_FIELDS``).
        ref: (REFERENCE_SIZE,) reference position [m], rotation (row-major), twist, classical
            acceleration, world axes at the COM (``REFERENCE_FIELDS``).
        pd_gains: (PD_GAINS_SIZE,) ``K_p`` (6) [1/s²], ``K_d`` (6) [1/s] (``PD_GAIN_FIELDS``).
        z: (n, k) joint-space PD (see :func:`object_pd_torques`).
        hold_tool: (n, h, 3).
        hold_obj: (n, h, 3).
        hold_n: (n,) int.
        gains: (HOLD_GAINS_SIZE,) ``hold_kp``, ``hold_kd``, Jacobian damping, margin.
        active: (n, m) uint8 warm start of the force QP (updated).
        tau: output (n, k) torques [N m].
        mu: output (n, m) planned multipliers [N].
        qdd: output (n, k) planned joint accelerations.
        a_pts: output (n, h, 3) desired point accelerations [m/s²].
        a_d: output (6,) desired object acceleration.

    Returns:
        :data:`PD_OK` or the reason to use the reference.
    """
    obj_x = np.empty(OX_TWIST + 6)
    if not desired_acceleration(obj, ref, pd_gains, obj_x, a_d):
        return PD_LARGE_ROTATION
    k, m, n = dims[DIMS_K], dims[DIMS_M], dims[DIMS_N]
    off = offsets(dims)
    M, _, J, Jdq, tp, tR, ttw, _ = _arm_segments(buf, off, n, k, m)
    _, h, W, W_o, c, M_o, h_o = _block_segments(buf, off, n, k, m)
    return _forces_and_torques(M, J, Jdq, tp, tR, ttw, h, W, W_o, c, M_o, h_o, N, nv_arm,
                               unilateral, obj_x, a_d, z, hold_tool, hold_obj, hold_n, gains,
                               active, tau, mu, qdd, a_pts)


@kernel
def touching_rank(W_o, N):  # pragma: no cover - compiled
    """Rank of the stacked ``W_o`` of the first ``N[i]`` rows of each arm (``grasp_rank``).

    The singular values of ``[W_o,1[:, :N_1] ... W_o,n[:, :N_n]]`` with every column scaled
    to unit norm (zero columns dropped) above :data:`GRASP_RANK_TOLERANCE` times the
    largest, as ``multiarm_pin.sim.controllers.object_pd.grasp_rank`` decides it.

    Args:
        W_o: (n, 6, m) the arms' object wrench columns (padding after ``N[i]``).
        N: (n,) int rows per arm.

    Returns:
        The rank, 0..6.
    """
    n = W_o.shape[0]
    A = np.empty((6, n * W_o.shape[2]))  # the unit columns, the first ``cols`` of them
    cols = 0
    for i in range(n):
        for s in range(N[i]):
            acc = 0.0
            for a in range(6):
                acc += W_o[i, a, s] * W_o[i, a, s]
            if acc > 0.0:
                norm = math.sqrt(acc)
                for a in range(6):
                    A[a, cols] = W_o[i, a, s] / norm
                cols += 1
    if cols == 0:
        return 0
    A = np.ascontiguousarray(A[:, :cols])
    sv = np.empty(cols)
    singular_values(A, sv)  # (one-sided Jacobi: no LAPACK call)
    top = 0.0
    for a in range(cols):
        top = max(top, sv[a])
    rank = 0
    for a in range(cols):
        if sv[a] > GRASP_RANK_TOLERANCE * top:
            rank += 1
    return min(rank, 6)


@kernel
def touching_torques(buf, dims, N, nv_arm, unilateral, touching, obj, ref, pd_gains, z,
                     hold_tool, hold_obj, hold_n, gains, active_r, tau, mu, qdd, a_pts, a_d,
                     pd_step):  # pragma: no cover - compiled
    """``ObjectPD`` torques planned on the touching contacts only (some have separated).

    What ``ObjectPD.reference`` computes on an evaluation whose active set leaves some
    unilateral contacts out: each arm's touching rows are compacted to the front of a copy
    of the buffer (kept rows in order, zero padding, as
    :func:`multiarm_pin.dynamics.blocks.restrict_rows` does; ``M``, ``J``, ``J̇q̇``, tools,
    ``h``, ``M_o``, ``h_o`` unchanged); the grasp rank of those rows is decided first
    (:func:`touching_rank`; :data:`PD_HOLD` below 6: the caller holds the arms still,
    :func:`hold_still_torques`); then ``pd_step`` (:func:`object_pd_step`) plans on the
    copy, and the planned multipliers are put back at their full rows (zero on separated
    rows).

    ``object_pd_step`` is called through its address, not compiled into this kernel: the
    plan's code (force QP, task, torques) is compiled once, in ``object_pd_step``.

    The reference's fallbacks are not here: a force QP that fails (for instance a margin that
    no internal force keeps: the reference then plans least-norm forces), an arm whose rows
    or task are rank deficient, NaN, a large rotation error all return their status, and the
    caller runs the reference, which decides.

    Args:
        buf: the flat buffer (blocks at zero torque; read only).
        dims: (DIMS_SIZE,) int ``(k, m, nv, n)``.
        N: (n,) int constraint rows per arm (all of them, touching or not).
        nv_arm: (n,) int joints per arm.
        unilateral: (n, m) bool mask of the unilateral rows (all of them).
        touching: (n, m) bool, True on the rows that touch (padding ignored).
        obj: (OBJECT_STATE_SIZE,) object position, quaternion, twist (as
            :func:`object_pd_step`).
        ref: (REFERENCE_SIZE,) the reference (as :func:`object_pd_step`).
        pd_gains: (PD_GAINS_SIZE,) ``K_p``, ``K_d``.
        z: (n, k) joint-space PD (see :func:`object_pd_torques`).
        hold_tool: (n, h, 3) held points in the tool frame [m].
        hold_obj: (n, h, 3) their places in the object frame [m].
        hold_n: (n,) int held points per arm.
        gains: (HOLD_GAINS_SIZE,) ``hold_kp``, ``hold_kd``, Jacobian damping, margin.
        active_r: (n, m) uint8 warm start of the force QP on the restricted rows (in and
            out; its own array, not the full rows' one: a warm start only, the QP's answer
            does not depend on it).
        tau: output (n, k) torques [N m] to add to ``h`` (zero on padding).
        mu: output (n, m) planned multipliers of the full rows [N] (zero on separated rows).
        qdd: output (n, k) planned joint accelerations.
        a_pts: output (n, h, 3) desired point accelerations [m/s²].
        a_d: output (6,) desired object acceleration [m/s², rad/s²].
        pd_step: :func:`object_pd_step` for these arguments' types, as a first-class function
            or its :func:`~multiarm_pin._compiled.function_pointers.pointer` (the function
            itself without the JIT).

    Returns:
        ``(status, rank)``: :data:`PD_OK`, :data:`PD_HOLD` or the reason the caller must use
        the reference (outputs then meaningless); the grasp rank of the touching rows (0..6).
    """
    k, m, n = dims[DIMS_K], dims[DIMS_M], dims[DIMS_N]
    off = offsets(dims)
    restricted = buf.copy()
    _, _, W, W_o, c, _, _ = _block_segments(buf, off, n, k, m)
    _, _, W_r, W_o_r, c_r, _, _ = _block_segments(restricted, off, n, k, m)
    unilateral_r = np.zeros((n, m), dtype=np.bool_)
    N_r = np.zeros(n, dtype=np.int64)
    index = np.empty((n, m), dtype=np.int64)
    W_r[:] = 0.0
    W_o_r[:] = 0.0
    c_r[:] = 0.0
    for i in range(n):
        p = 0
        for s in range(N[i]):
            if not touching[i, s]:
                continue
            for j in range(k):
                W_r[i, j, p] = W[i, j, s]
            for a in range(6):
                W_o_r[i, a, p] = W_o[i, a, s]
            c_r[i, p] = c[i, s]
            unilateral_r[i, p] = unilateral[i, s]
            index[i, p] = s
            p += 1
        N_r[i] = p
    rank = touching_rank(W_o_r, N_r)
    if rank < 6:
        return PD_HOLD, rank
    mu_r = np.zeros((n, m))
    status = bind(pd_step)(restricted, dims, N_r, nv_arm, unilateral_r, obj, ref, pd_gains, z,
                           hold_tool, hold_obj, hold_n, gains, active_r, tau, mu_r, qdd, a_pts,
                           a_d)
    if status != PD_OK:
        return status, rank
    for i in range(n):
        for s in range(m):
            mu[i, s] = 0.0
        for p in range(N_r[i]):
            mu[i, index[i, p]] = mu_r[i, p]
    return PD_OK, rank


def pd_step_compile(buf, dims, N, nv_arm, unilateral, obj, ref, pd_gains, z, hold_tool,
                    hold_obj, hold_n, gains, active, tau, mu, qdd, a_pts, a_d) -> Compile:
    """The compile of :func:`object_pd_step` as a first-class function, for these arguments.

    ``N`` and ``unilateral`` are typed read-only, whatever the examples are: the kernel only
    reads them, and a read-only type takes both the system's arrays (read-only in the loops)
    and the rows :func:`touching_torques` compacts (new arrays), so that the loop and
    ``ObjectPD``'s Python path share one compile.

    Returns:
        A :class:`~multiarm_pin._compiled.function_pointers.Compile` returning the status.
    """
    return compile_of(object_pd_step, (
        buf, dims, numba.typeof(N).copy(readonly=True), nv_arm,
        numba.typeof(unilateral).copy(readonly=True), obj, ref, pd_gains, z, hold_tool,
        hold_obj, hold_n, gains, active, tau, mu, qdd, a_pts, a_d), numba.types.int64)


def touching_step(buf, dims, N, nv_arm, unilateral, touching, obj, ref, pd_gains, z,
                  hold_tool, hold_obj, hold_n, gains, active_r, tau, mu, qdd, a_pts, a_d):
    """:func:`touching_torques`' last argument, from Python, for a call on these arguments.

    The :func:`~multiarm_pin._compiled.function_pointers.pointer` of
    :func:`pd_step_compile`'s compile (the loops' own, for the same arrays).
    Depends only on the arguments' types: make it once per caller.
    """
    return pointer(pd_step_compile(buf, dims, N, nv_arm, unilateral, obj, ref, pd_gains, z,
                                   hold_tool, hold_obj, hold_n, gains, active_r, tau, mu, qdd,
                                   a_pts, a_d))


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
def hold_still_torques(buf, dims, nv_arm, z, tau):  # pragma: no cover - compiled
    """Torques holding the arms still: ``τ_i = M_i z_i - h_i`` (``ObjectPD._hold_still``).

    Computed-torque joint PD with the contact forces ignored; the caller computes
    ``z = null_kp (q_hold ⊖ q) - null_kd v``.

    Args:
        buf: the flat buffer (blocks at zero torque, ``h = -nle``).
        dims: (DIMS_SIZE,) int ``(k, m, nv, n)``.
        nv_arm: (n,) int joints per arm.
        z: (n, k) desired joint accelerations [rad/s²], zero on padding.
        tau: output (n, k) torques [N m], zero on padding.
    """
    k, m, n = dims[DIMS_K], dims[DIMS_M], dims[DIMS_N]
    off = offsets(dims)
    M = view3(buf, off, SEG_M, n, k, m)
    h = view2(buf, off, SEG_H, n, k, m)
    for i in range(n):
        nvi = nv_arm[i]
        for j in range(k):
            if j >= nvi:
                tau[i, j] = 0.0
                continue
            acc = 0.0
            for b in range(nvi):
                acc += M[i, j, b] * z[i, b]
            tau[i, j] = acc - h[i, j]


@kernel
def solve_with_torques(buf, dims, N, params, tau, wrench):  # pragma: no cover - compiled
    """Object-first forward dynamics of the buffer's blocks with torques ``tau`` added to ``h``.

    The solution goes to the buffer's ``a_o``, ``qdd``, ``mu`` segments; its ``h`` segment
    is left at zero torque.

    Args:
        buf: the flat buffer (blocks at zero torque).
        dims: (DIMS_SIZE,) int ``(k, m, nv, n)``.
        N: (n,) int constraint rows per arm.
        params: (N_PARAMS,) the parameter vector (the solver thresholds are read).
        tau: (n, k) joint torques [N m], zero on padding.
        wrench: (6,) external wrench ``[f; m]`` at the COM, world axes [N, N m], added to
            ``h_o`` (the controller does not know it; zeros for none: a writable array, as
            every caller passes, so that one specialisation serves them all).

    Returns:
        The status of :func:`multiarm_pin._compiled.object_first.object_first`.
    """
    k, m, n = dims[DIMS_K], dims[DIMS_M], dims[DIMS_N]
    off = offsets(dims)
    M = view3(buf, off, SEG_M, n, k, m)
    _, h, W, W_o, c, M_o, h_o = _block_segments(buf, off, n, k, m)
    a_o, qdd, mu = _solution_segments(buf, off, n, k, m)
    return object_first(M, h + tau, W, W_o, c, M_o, h_o + wrench, N, params[P_RCOND_TOL],
                        params[P_OBJECT_RCOND_TOL], a_o, qdd, mu)


__all__ = ["GRASP_RANK_TOLERANCE", "NULL_KD", "NULL_KP", "PD_ARM_RANK", "PD_FORCES_FAILED",
           "PD_HOLD", "PD_LARGE_ROTATION", "PD_NOT_FINITE", "PD_OK", "desired_acceleration",
           "hold_still_torques", "joint_pd", "log3", "min_norm_rows", "object_pd_step",
           "object_pd_torques", "pd_step_compile", "planned_torques", "solve_with_torques",
           "touching_rank", "touching_step", "touching_torques"]
