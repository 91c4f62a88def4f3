"""Compiled (numba) kernels of the per-step hot path: arm terms, constraint rows, assembly, solve.

The numpy implementations (:meth:`multiarm_pin.model.arm_set.ArmSet.evaluate`,
:meth:`multiarm_pin.constraints.ConstraintSet.evaluate`, ``MultiArmSystem._blocks_reference``
and :func:`multiarm_pin.dynamics.object_first.solve_object_first_numpy`) are the references;
these kernels compute the same quantities with plain loops over arms and contacts, so that one
dynamics step costs a handful of Python calls whatever the number of arms (the numpy versions
spend most of their time in the overhead of 60-80 small numpy calls).

Everything here takes and returns plain float64 / int64 arrays; no Python object enters a
kernel. Conventions are those of ``docs/ARCHITECTURE.md``: SI units, spatial vectors
``[linear; angular]``, world axes, tool quantities LOCAL_WORLD_ALIGNED at the tool origin,
object quantities at the COM, ``μ > 0`` pushing.

Layout of the output buffer of :func:`evaluate_system` (one flat float64 array, one segment per
quantity, each C-contiguous; offsets from :func:`buffer_layout`): the arms' ``M (n, k, k)``,
``nle (n, k)``, ``J (n, 6, k)``, ``Jdot_qdot (n, 6)``, tool ``position (n, 3)``, ``rotation
(n, 3, 3)``, ``twist (n, 6)``, padded ``v (n, k)``; the constraint rows packed as ``(n, m, 21)``
(``φ, φ̇, κ, G_tool (6), G_object (6), contact point (3), normal (3)``, the layout of
:meth:`ConstraintSet.evaluate`); the blocks ``h (n, k)``, ``W (n, k, m)``, ``W_o (n, 6, m)``,
``c (n, m)``, ``M_o (6, 6)``, ``h_o (6,)``; the solution of :func:`step_system` ``a_o (6,)``,
``qdd (n, k)``, ``mu (n, m)``. ``k = nv_max``, ``m = N_max``.

Compilation is cached on disk (``cache=True``, in ``__pycache__``): the first call in a fresh
checkout compiles every kernel (a few seconds), later processes load them.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# ------------------------------------------------------------------ buffer layout
SEGMENTS = ("M", "nle", "J", "Jdot_qdot", "position", "rotation", "twist", "v",
            "rows", "h", "W", "W_o", "c", "M_o", "h_o", "a_o", "qdd", "mu")
"""Names of the segments of the flat output buffer of :func:`evaluate_system`, in order."""

ROW_WIDTH = 21
"""Values per constraint row in the packed ``rows`` segment (see the module docstring)."""

# indices into the per-contact tables of :func:`contact_tables`
_I_CARRIER, _I_SURFACE, _I_SLOT, _I_TOOL_CARRIES = 0, 1, 2, 3
_F_TIP, _F_TIP_RADIUS, _F_DIR, _F_POINT = 0, 3, 4, 7
_F_CURV_RADIUS, _F_CURV_SIGN, _F_IS_PLANE, _F_PUSH_SIGN = 10, 11, 12, 13
CONTACT_FLOATS = 14
"""Columns of the float contact table (tip (3), tip radius, surface direction (3), surface
point (3), curvature radius, curvature sign, is-plane flag, push sign)."""


def segment_shapes(n: int, k: int, m: int) -> dict[str, tuple[int, ...]]:
    """Shapes of the buffer segments for n arms, ``k = nv_max`` joints, ``m = N_max`` rows."""
    return {
        "M": (n, k, k), "nle": (n, k), "J": (n, 6, k), "Jdot_qdot": (n, 6),
        "position": (n, 3), "rotation": (n, 3, 3), "twist": (n, 6), "v": (n, k),
        "rows": (n, m, ROW_WIDTH), "h": (n, k), "W": (n, k, m), "W_o": (n, 6, m), "c": (n, m),
        "M_o": (6, 6), "h_o": (6,), "a_o": (6,), "qdd": (n, k), "mu": (n, m),
    }


def buffer_layout(n: int, k: int, m: int) -> tuple[np.ndarray, int]:
    """Start offsets (len(SEGMENTS) + 1,) int64 of every segment, and the total size."""
    shapes = segment_shapes(n, k, m)
    off = [0]
    for name in SEGMENTS:
        off.append(off[-1] + int(np.prod(shapes[name])))
    return np.array(off, dtype=np.int64), off[-1]


def contact_tables(constraint_set) -> tuple[np.ndarray, np.ndarray]:
    """Per-contact tables of a :class:`~multiarm_pin.constraints.ConstraintSet` for the kernels.

    Built from the geometry arrays the set already stores (flattened kept contacts of every
    joint, in arm order).

    Args:
        constraint_set: the system's constraint set.

    Returns:
        ``ints (K, 4)`` int64: carrier body, surface body (``0..n-1`` = tools, ``n`` = object),
        flat slot ``arm * N_max + row``, 1 if the tool is the carrier;
        ``floats (K, 14)``: tip point in the carrier frame (3) [m], tip radius [m], surface
        direction (3) and point (3) in the surface body's frame (plane: normal and point;
        sphere: 0 and centre; cylinder: axis and a point of it), curvature radius [m],
        curvature sign (+1 outside, -1 inside), 1.0 for planes, push sign (-1 if the tip is on
        the tool).
    """
    cs = constraint_set
    K = cs._K
    ints = np.zeros((K, 4), dtype=np.int64)
    ints[:, _I_CARRIER] = cs._bodies[0]
    ints[:, _I_SURFACE] = cs._bodies[1]
    ints[:, _I_SLOT] = cs._flat
    ints[:, _I_TOOL_CARRIES] = cs._tool_first[0] == 0
    floats = np.zeros((K, CONTACT_FLOATS))
    floats[:, _F_TIP:_F_TIP + 3] = cs._tip.T
    floats[:, _F_TIP_RADIUS] = cs._radius
    floats[:, _F_DIR:_F_DIR + 3] = cs._surface_local[:, 0, :].T
    floats[:, _F_POINT:_F_POINT + 3] = cs._surface_local[:, 1, :].T
    floats[:, _F_CURV_RADIUS] = cs._curv_radius
    floats[:, _F_CURV_SIGN] = cs._curv_sign
    floats[:, _F_IS_PLANE] = cs._is_plane
    floats[:, _F_PUSH_SIGN] = cs._push_sign
    return ints, floats


SOLVE_OK = 0
"""Status of :func:`object_first`: solved."""
SOLVE_ARM_SINGULAR = 1
"""Status: some ``M_i`` or ``S_i`` failed to factor, or ``S_i`` is badly conditioned."""
SOLVE_OBJECT_SINGULAR = 2
"""Status: the reduced object matrix is badly conditioned or the result is not finite."""
SOLVE_NOT_FINITE = 3
"""Status of :func:`step_system`: the state or the torques hold NaN or infinity."""


# ------------------------------------------------------------------ small dense linear algebra
@njit(cache=True, error_model="numpy")
def cholesky(A, L, size):  # pragma: no cover - compiled
    """Lower Cholesky factor of the leading ``size`` x ``size`` block of ``A`` into ``L``.

    Returns False (``L`` partly written) if a pivot is not positive or not finite.
    """
    for j in range(size):
        s = A[j, j]
        for p in range(j):
            s -= L[j, p] * L[j, p]
        if not (s > 0.0 and s < np.inf):
            return False
        d = math.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, size):
            t = A[i, j]
            for p in range(j):
                t -= L[i, p] * L[j, p]
            L[i, j] = t / d
    return True


@njit(cache=True, error_model="numpy")
def cholesky_solve(L, B, size, ncols):  # pragma: no cover - compiled
    """``B[:size, :ncols] ← A⁻¹ B`` in place, ``A = L Lᵀ`` (L from :func:`cholesky`).

    Row-oriented: the innermost loops run along the right-hand sides, independent of each
    other (no dependency chain; the compiler vectorises them).
    """
    for i in range(size):
        for p in range(i):
            lip = L[i, p]
            for col in range(ncols):
                B[i, col] -= lip * B[p, col]
        d = 1.0 / L[i, i]
        for col in range(ncols):
            B[i, col] *= d
    for i in range(size - 1, -1, -1):
        for p in range(i + 1, size):
            lpi = L[p, i]
            for col in range(ncols):
                B[i, col] -= lpi * B[p, col]
        d = 1.0 / L[i, i]
        for col in range(ncols):
            B[i, col] *= d


@njit(cache=True, error_model="numpy")
def inverse_diagonal(L, size, out, col):  # pragma: no cover - compiled
    """``out[j] = (A⁻¹)_jj`` for ``A = L Lᵀ``: squared column norms of ``L⁻¹``.

    ``col`` is scratch of length ``size``.
    """
    for j in range(size):
        for i in range(size):
            col[i] = 0.0
        col[j] = 1.0 / L[j, j]
        acc = col[j] * col[j]
        for i in range(j + 1, size):
            t = 0.0
            for p in range(j, i):
                t -= L[i, p] * col[p]
            col[i] = t / L[i, i]
            acc += col[i] * col[i]
        out[j] = acc


# ------------------------------------------------------------------ 1. arm terms
@njit(cache=True, error_model="numpy")
def arm_terms(J_world, dJ_world, M_full, nle_full, v, H, idx, nv_arm, support,
              M, nle, J, Jdq, p, R, twist, vp):  # pragma: no cover - compiled
    """Stacked, padded arm terms from the combined Pinocchio model's arrays (``ArmSet.evaluate``).

    Args:
        J_world: (6, nv) ``data.J`` after ``computeJointJacobiansTimeVariation``: world
            Jacobian columns at the world origin.
        dJ_world: (6, nv) ``data.dJ``, their time derivative (same frame).
        M_full: (nv, nv) ``data.M`` after ``crba`` (full symmetric) [kg m², kg].
        nle_full: (nv,) ``data.nle`` [N m or N].
        v: (nv,) combined joint velocity [rad/s or m/s].
        H: (n, 4, 4) world placements of the n tool frames [m].
        idx: (n, k) int, index of each arm's joint in the combined vector (padded with 0).
        nv_arm: (n,) int, joints per arm.
        support: (n, k) int, 1 where the joint moves the arm's tool.
        M: output (n, k, k) mass matrices, identity on padded dofs.
        nle: output (n, k) nonlinear effects, zero on padding.
        J: output (n, 6, k) LWA tool Jacobians (zero columns on padding and on joints that
            do not move the tool).
        Jdq: output (n, 6) classical tool accelerations at q̈ = 0 (world axes) [m/s², rad/s²].
        p: output (n, 3) tool positions [m].
        R: output (n, 3, 3) tool rotations (tool axes -> world).
        twist: output (n, 6) LWA tool twists [m/s, rad/s].
        vp: output (n, k) padded joint velocities.
    """
    n, k = idx.shape
    acc = np.empty(6)
    tw = np.empty(6)
    for i in range(n):
        nvi = nv_arm[i]
        px, py, pz = H[i, 0, 3], H[i, 1, 3], H[i, 2, 3]
        p[i, 0], p[i, 1], p[i, 2] = px, py, pz
        for a in range(3):
            for b in range(3):
                R[i, a, b] = H[i, a, b]
        for r in range(6):
            acc[r] = 0.0
            tw[r] = 0.0
        for a in range(k):
            if a < nvi:
                ia = idx[i, a]
                va = v[ia]
                vp[i, a] = va
                nle[i, a] = nle_full[ia]
                for b in range(k):
                    M[i, a, b] = M_full[ia, idx[i, b]] if b < nvi else 0.0
            else:
                va = 0.0
                vp[i, a] = 0.0
                nle[i, a] = 0.0
                for b in range(k):
                    M[i, a, b] = 1.0 if b == a else 0.0
            if a < nvi and support[i, a] != 0:
                ia = idx[i, a]
                wx, wy, wz = J_world[3, ia], J_world[4, ia], J_world[5, ia]
                # LWA column at the tool point: linear + ω × p
                J[i, 0, a] = J_world[0, ia] - (py * wz - pz * wy)
                J[i, 1, a] = J_world[1, ia] - (pz * wx - px * wz)
                J[i, 2, a] = J_world[2, ia] - (px * wy - py * wx)
                J[i, 3, a] = wx
                J[i, 4, a] = wy
                J[i, 5, a] = wz
                for r in range(6):
                    tw[r] += J[i, r, a] * va
                    acc[r] += dJ_world[r, ia] * va
            else:
                for r in range(6):
                    J[i, r, a] = 0.0
        for r in range(6):
            twist[i, r] = tw[r]
        # classical acceleration of the tool point: a_O + α × p + ω × v_p
        ax, ay, az = acc[3], acc[4], acc[5]
        ox, oy, oz = tw[3], tw[4], tw[5]
        Jdq[i, 0] = acc[0] + (ay * pz - az * py) + (oy * tw[2] - oz * tw[1])
        Jdq[i, 1] = acc[1] + (az * px - ax * pz) + (oz * tw[0] - ox * tw[2])
        Jdq[i, 2] = acc[2] + (ax * py - ay * px) + (ox * tw[1] - oy * tw[0])
        Jdq[i, 3], Jdq[i, 4], Jdq[i, 5] = ax, ay, az


# ------------------------------------------------------------------ 2. constraint rows
@njit(cache=True, error_model="numpy")
def constraint_rows(tool_p, tool_R, tool_twist, obj_p, obj_R, obj_twist, ints, floats,
                    rows):  # pragma: no cover - compiled
    """Every contact's row (``ConstraintSet.evaluate``), packed into ``rows`` (n, m, 21).

    Args:
        tool_p: (n, 3) tool positions [m].
        tool_R: (n, 3, 3) tool rotations (tool axes -> world).
        tool_twist: (n, 6) LWA tool twists [m/s, rad/s].
        obj_p: (3,) object COM position [m].
        obj_R: (3, 3) object rotation.
        obj_twist: (6,) object twist ``[ẋ; ω]``, world axes.
        ints: (K, 4) int contact table of :func:`contact_tables`.
        floats: (K, 14) float contact table of :func:`contact_tables`.
        rows: output (n, m, 21) packed rows (see the module docstring); padded slots zeroed.
    """
    n, m, width = rows.shape
    for i in range(n):
        for s in range(m):
            for f in range(width):
                rows[i, s, f] = 0.0
    X = np.empty((2, 3))
    Rb = np.empty((2, 3, 3))
    V = np.empty((2, 6))
    r = np.empty((2, 3))
    wr = np.empty((2, 3))
    c = np.empty(3)
    u = np.empty(3)
    d = np.empty(3)
    y = np.empty(3)
    nu = np.empty(3)
    yp = np.empty(3)
    for q in range(ints.shape[0]):
        for side in range(2):
            body = ints[q, side]
            if body < n:
                for a in range(3):
                    X[side, a] = tool_p[body, a]
                    for b in range(3):
                        Rb[side, a, b] = tool_R[body, a, b]
                for a in range(6):
                    V[side, a] = tool_twist[body, a]
            else:
                for a in range(3):
                    X[side, a] = obj_p[a]
                    for b in range(3):
                        Rb[side, a, b] = obj_R[a, b]
                for a in range(6):
                    V[side, a] = obj_twist[a]
        # tip centre c (world), lever arms from both bodies' origins, material velocities
        for a in range(3):
            c[a] = X[0, a] + (Rb[0, a, 0] * floats[q, 0] + Rb[0, a, 1] * floats[q, 1]
                              + Rb[0, a, 2] * floats[q, 2])
        for side in range(2):
            for a in range(3):
                r[side, a] = c[a] - X[side, a]
            wx, wy, wz = V[side, 3], V[side, 4], V[side, 5]
            wr[side, 0] = wy * r[side, 2] - wz * r[side, 1]
            wr[side, 1] = wz * r[side, 0] - wx * r[side, 2]
            wr[side, 2] = wx * r[side, 1] - wy * r[side, 0]
        for a in range(3):
            u[a] = (V[0, a] + wr[0, a]) - (V[1, a] + wr[1, a])
        # surface in world axes: direction d, point s (surface body = side 1)
        for a in range(3):
            d[a] = (Rb[1, a, 0] * floats[q, 4] + Rb[1, a, 1] * floats[q, 5]
                    + Rb[1, a, 2] * floats[q, 6])
            sp = (Rb[1, a, 0] * floats[q, 7] + Rb[1, a, 1] * floats[q, 8]
                  + Rb[1, a, 2] * floats[q, 9])
            y[a] = c[a] - X[1, a] - sp
        dy = d[0] * y[0] + d[1] * y[1] + d[2] * y[2]
        if floats[q, _F_IS_PLANE] != 0.0:
            for a in range(3):
                nu[a] = d[a]
            g = dy
            quad = 0.0
        else:
            for a in range(3):
                yp[a] = y[a] - dy * d[a]
            rho = max(math.sqrt(yp[0] * yp[0] + yp[1] * yp[1] + yp[2] * yp[2]), 1e-300)
            sgn = floats[q, _F_CURV_SIGN]
            du = 0.0
            eu = 0.0
            uu = 0.0
            for a in range(3):
                e = yp[a] / rho
                nu[a] = sgn * e
                du += d[a] * u[a]
                eu += e * u[a]
                uu += u[a] * u[a]
            g = sgn * (rho - floats[q, _F_CURV_RADIUS])
            quad = sgn * (uu - du * du - eu * eu) / rho
        # κ = uᵀHu + ν·(ω_C × (ω_C × r_C) - ω_S × (ω_S × r_S + 2u))
        kappa = quad
        for side in range(2):
            bx, by, bz = wr[side, 0], wr[side, 1], wr[side, 2]
            if side == 1:
                bx += 2.0 * u[0]
                by += 2.0 * u[1]
                bz += 2.0 * u[2]
            wx, wy, wz = V[side, 3], V[side, 4], V[side, 5]
            t0 = wy * bz - wz * by
            t1 = wz * bx - wx * bz
            t2 = wx * by - wy * bx
            sg = 1.0 if side == 0 else -1.0
            kappa += sg * (nu[0] * t0 + nu[1] * t1 + nu[2] * t2)
        slot = ints[q, _I_SLOT]
        i = slot // m
        s = slot - i * m
        rows[i, s, 0] = g - floats[q, _F_TIP_RADIUS]
        rows[i, s, 1] = nu[0] * u[0] + nu[1] * u[1] + nu[2] * u[2]
        rows[i, s, 2] = kappa
        tool_side = 0 if ints[q, _I_TOOL_CARRIES] != 0 else 1
        for side in range(2):
            base = 3 if side == tool_side else 9  # G_tool at 3..8, G_object at 9..14
            sg = 1.0 if side == 0 else -1.0  # +1 carrier, -1 surface body
            rx, ry, rz = r[side, 0], r[side, 1], r[side, 2]
            rows[i, s, base + 0] = sg * nu[0]
            rows[i, s, base + 1] = sg * nu[1]
            rows[i, s, base + 2] = sg * nu[2]
            rows[i, s, base + 3] = sg * (ry * nu[2] - rz * nu[1])
            rows[i, s, base + 4] = sg * (rz * nu[0] - rx * nu[2])
            rows[i, s, base + 5] = sg * (rx * nu[1] - ry * nu[0])
        push = floats[q, _F_PUSH_SIGN]
        for a in range(3):
            rows[i, s, 15 + a] = c[a] - g * nu[a]
            rows[i, s, 18 + a] = push * nu[a]


# ------------------------------------------------------------------ 3. assembly
@njit(cache=True, error_model="numpy")
def assemble(J, Jdq, nle, tau_padded, rows, baumgarte, obj_R, mass, inertia_body, gravity,
             obj_twist, h, W, W_o, c, M_o, h_o):  # pragma: no cover - compiled
    """The padded blocks (``MultiArmSystem.blocks``) from arm terms and constraint rows.

    ``W_i = J_iᵀ G_tool,iᵀ``, ``W_o,i = G_object,iᵀ``, ``c_i = -G_tool,i J̇q̇_i - κ_i``
    (minus ``2α φ̇ + β² φ`` when ``baumgarte[2] != 0``), ``h_i = τ_i - nle_i``,
    ``M_o = diag(m I, R I_c Rᵀ)``, ``h_o = [m g; -ω × (R I_c Rᵀ ω)]``.

    Args:
        J: (n, 6, k) LWA tool Jacobians (:func:`arm_terms`).
        Jdq: (n, 6) classical tool accelerations at q̈ = 0.
        nle: (n, k) nonlinear effects [N m].
        tau_padded: (n, k) joint torques [N m], zero on padding.
        rows: (n, m, 21) packed constraint rows of :func:`constraint_rows`.
        baumgarte: (3,) ``(α, β, on)`` [1/s, 1/s, flag].
        obj_R: (3, 3) object rotation.
        mass: object mass [kg].
        inertia_body: (3, 3) inertia about the COM in object axes [kg m²].
        gravity: (3,) [m/s²], world.
        obj_twist: (6,) object twist ``[ẋ; ω]``, world axes.
        h: output (n, k) ``τ - nle``.
        W: output (n, k, m) ``J_iᵀ G_tool,iᵀ``.
        W_o: output (n, 6, m) ``G_object,iᵀ``.
        c: output (n, m) constraint right-hand sides.
        M_o: output (6, 6) object inertia at the COM, world axes.
        h_o: output (6,) object bias wrench [N, N m].
    """
    n, k = nle.shape
    m = rows.shape[1]
    alpha, beta, on = baumgarte[0], baumgarte[1], baumgarte[2]
    for i in range(n):
        for a in range(k):
            h[i, a] = tau_padded[i, a] - nle[i, a]
        for s in range(m):
            for a in range(k):
                acc = 0.0
                for r in range(6):
                    acc += J[i, r, a] * rows[i, s, 3 + r]
                W[i, a, s] = acc
            gj = 0.0
            for r in range(6):
                W_o[i, r, s] = rows[i, s, 9 + r]
                gj += rows[i, s, 3 + r] * Jdq[i, r]
            cs = -gj - rows[i, s, 2]
            if on != 0.0:
                cs -= 2.0 * alpha * rows[i, s, 1] + beta * beta * rows[i, s, 0]
            c[i, s] = cs
    # object: M_o = diag(m I, R I_c Rᵀ), h_o = [m g; -ω × I_w ω]
    Iw = np.zeros((3, 3))
    for a in range(3):
        for b in range(3):
            t = 0.0
            for p in range(3):
                for q in range(3):
                    t += obj_R[a, p] * inertia_body[p, q] * obj_R[b, q]
            Iw[a, b] = t
    for a in range(6):
        for b in range(6):
            M_o[a, b] = 0.0
    for a in range(3):
        M_o[a, a] = mass
        for b in range(3):
            M_o[3 + a, 3 + b] = Iw[a, b]
    wx, wy, wz = obj_twist[3], obj_twist[4], obj_twist[5]
    Lx = Iw[0, 0] * wx + Iw[0, 1] * wy + Iw[0, 2] * wz
    Ly = Iw[1, 0] * wx + Iw[1, 1] * wy + Iw[1, 2] * wz
    Lz = Iw[2, 0] * wx + Iw[2, 1] * wy + Iw[2, 2] * wz
    for a in range(3):
        h_o[a] = mass * gravity[a]
    h_o[3] = wz * Ly - wy * Lz
    h_o[4] = wx * Lz - wz * Lx
    h_o[5] = wy * Lx - wx * Ly


# ------------------------------------------------------------------ fused evaluation
@njit(cache=True, error_model="numpy")
def quaternion_rotation(quat, R):  # pragma: no cover - compiled
    """Rotation matrix (3, 3) of a unit quaternion ``[x, y, z, w]`` into ``R``."""
    x, y, z, w = quat[0], quat[1], quat[2], quat[3]
    R[0, 0] = 1 - 2 * (y * y + z * z)
    R[0, 1] = 2 * (x * y - z * w)
    R[0, 2] = 2 * (x * z + y * w)
    R[1, 0] = 2 * (x * y + z * w)
    R[1, 1] = 1 - 2 * (x * x + z * z)
    R[1, 2] = 2 * (y * z - x * w)
    R[2, 0] = 2 * (x * z - y * w)
    R[2, 1] = 2 * (y * z + x * w)
    R[2, 2] = 1 - 2 * (x * x + y * y)


@njit(cache=True, error_model="numpy")
def _offsets(n, k, m):  # pragma: no cover - compiled
    """Start offsets of the segments of :data:`SEGMENTS` (and the total size)."""
    sizes = (n * k * k, n * k, n * 6 * k, n * 6, n * 3, n * 9, n * 6, n * k,
             n * m * ROW_WIDTH, n * k, n * k * m, n * 6 * m, n * m, 36, 6, 6, n * k, n * m)
    off = np.empty(len(sizes) + 1, dtype=np.int64)
    off[0] = 0
    for j in range(len(sizes)):
        off[j + 1] = off[j] + sizes[j]
    return off


@njit(cache=True, error_model="numpy")
def _arm_views(buf, off, n, k):  # pragma: no cover - compiled
    """Views of the arm segments: M, nle, J, Jdot_qdot, position, rotation, twist, v."""
    return (buf[off[0]:off[1]].reshape((n, k, k)), buf[off[1]:off[2]].reshape((n, k)),
            buf[off[2]:off[3]].reshape((n, 6, k)), buf[off[3]:off[4]].reshape((n, 6)),
            buf[off[4]:off[5]].reshape((n, 3)), buf[off[5]:off[6]].reshape((n, 3, 3)),
            buf[off[6]:off[7]].reshape((n, 6)), buf[off[7]:off[8]].reshape((n, k)))


@njit(cache=True, error_model="numpy")
def _block_views(buf, off, n, k, m):  # pragma: no cover - compiled
    """Views of the constraint rows and block segments: rows, h, W, W_o, c, M_o, h_o."""
    return (buf[off[8]:off[9]].reshape((n, m, ROW_WIDTH)), buf[off[9]:off[10]].reshape((n, k)),
            buf[off[10]:off[11]].reshape((n, k, m)), buf[off[11]:off[12]].reshape((n, 6, m)),
            buf[off[12]:off[13]].reshape((n, m)), buf[off[13]:off[14]].reshape((6, 6)),
            buf[off[14]:off[15]])


@njit(cache=True, error_model="numpy")
def _solution_views(buf, off, n, k, m):  # pragma: no cover - compiled
    """Views of the solution segments: a_o, qdd, mu."""
    return (buf[off[15]:off[16]], buf[off[16]:off[17]].reshape((n, k)),
            buf[off[17]:off[18]].reshape((n, m)))


@njit(cache=True, error_model="numpy")
def _group_arms(J_world, dJ_world, M_full, nle_full, H, x, arm_ints, nv, v_offset, lo, arms
                ):  # pragma: no cover - compiled
    """:func:`arm_terms` of the group of arms ``lo..lo + len(H)`` into the arm views."""
    M, nle, J, Jdq, p, R, tw, vp = arms
    k = M.shape[1]
    hi = lo + H.shape[0]
    start = x.shape[0] - 2 * nv + v_offset
    v = x[start:start + M_full.shape[0]]
    arm_terms(J_world, dJ_world, M_full, nle_full, v, H, arm_ints[:, 1:1 + k],
              arm_ints[:, 0], arm_ints[:, 1 + k:1 + 2 * k], M[lo:hi], nle[lo:hi], J[lo:hi],
              Jdq[lo:hi], p[lo:hi], R[lo:hi], tw[lo:hi], vp[lo:hi])


@njit(cache=True, error_model="numpy")
def _finish(x, arm_ints, v_starts, ints, floats, params, nv, arms,
            blocks):  # pragma: no cover - compiled
    """Constraint rows and blocks from the arm views; False if ``x`` is not finite."""
    for a in range(x.shape[0]):
        if not math.isfinite(x[a]):
            return False
    M, nle, J, Jdq, p, R, tw, vp = arms
    rows, h, W, W_o, c, M_o, h_o = blocks
    n, k = nle.shape
    obj_R = np.empty((3, 3))
    quaternion_rotation(x[3:7], obj_R)
    obj_tw = x[7:13]
    constraint_rows(p, R, tw, x[0:3], obj_R, obj_tw, ints, floats, rows)
    tau = x[x.shape[0] - nv:]
    tau_p = np.zeros((n, k))
    for i in range(n):
        for a in range(arm_ints[i, 0]):
            tau_p[i, a] = tau[v_starts[i] + a]
    assemble(J, Jdq, nle, tau_p, rows, params[13:16], obj_R, params[0],
             params[1:10].reshape((3, 3)), params[10:13], obj_tw, h, W, W_o, c, M_o, h_o)
    return True


@njit(cache=True, error_model="numpy")
def _solve(N, params, M, blocks, solution):  # pragma: no cover - compiled
    """:func:`object_first` on the block views into the solution views."""
    rows, h, W, W_o, c, M_o, h_o = blocks
    a_o, qdd, mu = solution
    return object_first(M, h, W, W_o, c, M_o, h_o, N, params[16], params[17], a_o, qdd, mu)


@njit(cache=True, error_model="numpy")
def group_arm_terms(J_world, dJ_world, M_full, nle_full, H, x, arm_ints, dims, v_offset,
                    first_arm, buf):  # pragma: no cover - compiled
    """:func:`arm_terms` of one group of consecutive arms into their rows of the buffer.

    Args:
        J_world: (6, nv_g) ``data.J`` of the group's combined Pinocchio model.
        dJ_world: (6, nv_g) ``data.dJ``.
        M_full: (nv_g, nv_g) ``data.M``.
        nle_full: (nv_g,) ``data.nle``.
        H: (n_g, 4, 4) the group's tool placements.
        x: (13 + nq + 2 nv,) the concatenated state and torques (see :func:`evaluate_system`).
        arm_ints: (n_g, 1 + 2k) the group's rows of the arm table, joint indices relative
            to the group's velocity vector.
        dims: (4,) int ``(k, m, nv, n)``: nv_max, N_max, total joints and arms.
        v_offset: index of the group's first joint in the combined velocity.
        first_arm: index of the group's first arm.
        buf: the flat output buffer.
    """
    k, m, nv, n = dims[0], dims[1], dims[2], dims[3]
    arms = _arm_views(buf, _offsets(n, k, m), n, k)
    _group_arms(J_world, dJ_world, M_full, nle_full, H, x, arm_ints, nv, v_offset, first_arm,
                arms)


@njit(cache=True, error_model="numpy")
def finish_system(x, arm_ints, v_starts, ints, floats, params, dims,
                  buf):  # pragma: no cover - compiled
    """Constraint rows and blocks from the arm terms already in ``buf``.

    Args:
        x: (13 + nq + 2 nv,) the concatenated state and torques (see :func:`evaluate_system`).
        arm_ints: (n, 1 + 2k) the arm table (see :func:`evaluate_system`).
        v_starts: (n,) int index of each arm's first joint in the combined velocity (joint
            indices of ``arm_ints`` may be relative to a group).
        ints: (K, 4) int contact table (:func:`contact_tables`).
        floats: (K, 14) float contact table.
        params: (18,) object and Baumgarte parameters (see :func:`evaluate_system`).
        dims: (4,) int ``(k, m, nv, n)``.
        buf: the flat buffer (arm segments read, the others written).

    Returns:
        False (and nothing computed) if some entry of ``x`` is NaN or infinite.
    """
    k, m, nv, n = dims[0], dims[1], dims[2], dims[3]
    off = _offsets(n, k, m)
    return _finish(x, arm_ints, v_starts, ints, floats, params, nv, _arm_views(buf, off, n, k),
                   _block_views(buf, off, n, k, m))


@njit(cache=True, error_model="numpy")
def solve_buffer(N, params, dims, buf):  # pragma: no cover - compiled
    """:func:`object_first` on the blocks of the buffer, solution into its last segments.

    Args:
        N: (n,) int constraint rows per arm.
        params: (18,), the last two entries the solver thresholds.
        dims: (4,) int ``(k, m, nv, n)``.
        buf: the flat buffer.

    Returns:
        The status of :func:`object_first`.
    """
    k, m, n = dims[0], dims[1], dims[3]
    off = _offsets(n, k, m)
    return _solve(N, params, buf[off[0]:off[1]].reshape((n, k, k)),
                  _block_views(buf, off, n, k, m), _solution_views(buf, off, n, k, m))


@njit(cache=True, error_model="numpy")
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
        x: (13 + nq + 2 nv,) object position (3) [m], quaternion ``[x, y, z, w]`` (4), twist
            ``[ẋ; ω]`` (6), then the arms' ``q`` (not read), ``v`` and joint torques ``τ``
            [N m] (zeros for none): one array so that one finiteness test covers all.
        arm_ints: (n, 1 + 2k) int: joints per arm, then joint indices (see ``idx`` of
            :func:`arm_terms`), then the tool-support mask.
        v_starts: (n,) int index of each arm's first joint in the combined velocity.
        ints: (K, 4) int contact table (:func:`contact_tables`).
        floats: (K, 14) float contact table.
        params: (18,) object mass [kg], inertia about the COM in object axes (9, row-major)
            [kg m²], gravity (3) [m/s²], Baumgarte ``(α, β, on)``, then the solver thresholds
            ``rcond_tol``, ``object_rcond_tol`` (read by :func:`solve_buffer` only).
        dims: (4,) int ``(k, m, nv, n) = (nv_max, N_max, total joints, arms)``.
        buf: output, the flat buffer (segments :data:`SEGMENTS`, see the module docstring).

    Returns:
        False (and the buffer meaningless) if some entry of ``x`` is NaN or infinite.
    """
    k, m, nv, n = dims[0], dims[1], dims[2], dims[3]
    off = _offsets(n, k, m)
    arms = _arm_views(buf, off, n, k)
    _group_arms(J_world, dJ_world, M_full, nle_full, H, x, arm_ints, nv, 0, 0, arms)
    return _finish(x, arm_ints, v_starts, ints, floats, params, nv, arms,
                   _block_views(buf, off, n, k, m))


@njit(cache=True, error_model="numpy")
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
        ints: (K, 4).
        floats: (K, 14).
        params: (18,), the last two entries the solver thresholds.
        dims: (4,).
        N: (n,) int constraint rows per arm.
        buf: output buffer; the segments ``a_o``, ``qdd``, ``mu`` receive the solution.

    Returns:
        The status of :func:`object_first`, or ``SOLVE_NOT_FINITE`` if ``x`` holds NaN or
        infinity (nothing computed then).
    """
    k, m, nv, n = dims[0], dims[1], dims[2], dims[3]
    off = _offsets(n, k, m)
    arms = _arm_views(buf, off, n, k)
    blocks = _block_views(buf, off, n, k, m)
    _group_arms(J_world, dJ_world, M_full, nle_full, H, x, arm_ints, nv, 0, 0, arms)
    if not _finish(x, arm_ints, v_starts, ints, floats, params, nv, arms, blocks):
        return SOLVE_NOT_FINITE
    return _solve(N, params, arms[0], blocks, _solution_views(buf, off, n, k, m))


# ------------------------------------------------------------------ 4. object-first solve
@njit(cache=True, error_model="numpy")
def object_first(M, h, W, W_o, c, M_o, h_o, N, rcond_tol, object_rcond_tol,
                 a_o, qdd, mu):  # pragma: no cover - compiled
    """Object-first forward dynamics (``solve_object_first_numpy``) with per-arm Cholesky.

    Per arm: ``X = M_i⁻¹ [W_i h_i]``, ``S_i = W_iᵀ X_W`` (padded diagonal set to the arm's
    largest ``S_jj``, or 1), ``r_i = c_i - W_iᵀ M_i⁻¹ h_i``, the condition estimate
    ``max_j S_jj · max_j (S⁻¹)_jj`` against ``1 / rcond_tol``, ``Z = S_i⁻¹ [W_o,iᵀ r_i]``;
    then ``(M_o + Σ W_o,i Z_W) a_o = h_o + Σ W_o,i Z_r`` by Cholesky, with the reciprocal
    condition number ``1 / (trace(A) ‖A⁻¹‖₁)`` (exact ``‖A⁻¹‖₁``, the quantity LAPACK
    ``dpocon`` estimates from below) checked against ``object_rcond_tol``; finally
    ``μ_i = Z_r - Z_W a_o`` and ``q̈_i = X_h + X_W μ_i``.

    Args:
        M: (n, k, k) mass matrices (identity on padding).
        h: (n, k) ``τ - nle``.
        W: (n, k, m) ``J_iᵀ G_tool,iᵀ``.
        W_o: (n, 6, m) ``G_object,iᵀ``.
        c: (n, m) constraint right-hand sides.
        M_o: (6, 6) object inertia.
        h_o: (6,) object bias wrench.
        N: (n,) int constraint rows per arm.
        rcond_tol: threshold on each ``S_i`` (``DEFAULT_RCOND_TOL``).
        object_rcond_tol: threshold on the reduced object matrix (``OBJECT_RCOND_TOL``).
        a_o: output (6,) object acceleration ``[ẍ; ω̇]`` at the COM, world axes.
        qdd: output (n, k) joint accelerations.
        mu: output (n, m) multipliers (positive = pushing) [N].

    Returns:
        ``SOLVE_OK``, ``SOLVE_ARM_SINGULAR`` or ``SOLVE_OBJECT_SINGULAR`` (outputs meaningless
        unless OK).
    """
    n, k, m = W.shape
    X = np.empty((n, k, m + 1))
    Z = np.empty((n, m, 7))
    L = np.zeros((k, k))
    S = np.empty((m, m))
    WX = np.empty((m, m + 1))
    LS = np.zeros((m, m))
    dinv = np.empty(m)
    col = np.empty(m)
    A = np.empty((6, 6))
    rhs = np.empty(6)
    for a in range(6):
        rhs[a] = h_o[a]
        for b in range(6):
            A[a, b] = M_o[a, b]
    has_padding = False
    for i in range(n):
        if N[i] < m:
            has_padding = True
    for i in range(n):
        if not cholesky(M[i], L, k):
            return SOLVE_ARM_SINGULAR
        Xi = X[i]
        for a in range(k):
            for s in range(m):
                Xi[a, s] = W[i, a, s]
            Xi[a, m] = h[i, a]
        cholesky_solve(L, Xi, k, m + 1)
        Zi = Z[i]
        for s in range(m):  # [S  Wᵀ M⁻¹ h] = Wᵀ X, inner loop along X's rows
            for t in range(m + 1):
                WX[s, t] = 0.0
            for a in range(k):
                w = W[i, a, s]
                for t in range(m + 1):
                    WX[s, t] += w * Xi[a, t]
        smax = -np.inf
        for s in range(m):
            for t in range(m):
                S[s, t] = WX[s, t]
            Zi[s, 6] = c[i, s] - WX[s, m]  # r_i
            if S[s, s] > smax:
                smax = S[s, s]
        if has_padding:
            if not smax > 0.0:
                smax = 1.0
            for s in range(N[i], m):
                S[s, s] += smax
        if not cholesky(S, LS, m):
            return SOLVE_ARM_SINGULAR
        inverse_diagonal(LS, m, dinv, col)
        worst = 0.0
        for s in range(m):
            if dinv[s] > worst:
                worst = dinv[s]
        if not (smax * worst * rcond_tol <= 1.0):
            return SOLVE_ARM_SINGULAR
        for s in range(m):
            for r in range(6):
                Zi[s, r] = W_o[i, r, s]
        cholesky_solve(LS, Zi, m, 7)
        for a in range(6):
            for s in range(m):
                w = W_o[i, a, s]
                for b in range(6):
                    A[a, b] += w * Zi[s, b]
                rhs[a] += w * Zi[s, 6]
    LA = np.zeros((6, 6))
    if not cholesky(A, LA, 6):
        return SOLVE_OBJECT_SINGULAR
    inv = np.zeros((6, 6))
    for a in range(6):
        inv[a, a] = 1.0
    cholesky_solve(LA, inv, 6, 6)
    norm1 = 0.0
    trace = 0.0
    for b in range(6):
        trace += A[b, b]
        colsum = 0.0
        for a in range(6):
            colsum += abs(inv[a, b])
        if colsum > norm1:
            norm1 = colsum
    if not (trace * norm1 * object_rcond_tol <= 1.0):
        return SOLVE_OBJECT_SINGULAR
    total = 0.0
    sol = rhs.reshape((6, 1)).copy()
    cholesky_solve(LA, sol, 6, 1)
    for a in range(6):
        a_o[a] = sol[a, 0]
        total += sol[a, 0]
    for i in range(n):
        Zi = Z[i]
        Xi = X[i]
        for s in range(m):
            acc = Zi[s, 6]
            for b in range(6):
                acc -= Zi[s, b] * a_o[b]
            mu[i, s] = acc
            total += acc
        for a in range(k):
            acc = Xi[a, m]
            for s in range(m):
                acc += Xi[a, s] * mu[i, s]
            qdd[i, a] = acc
            total += acc
    if not math.isfinite(total):
        return SOLVE_OBJECT_SINGULAR
    return SOLVE_OK
