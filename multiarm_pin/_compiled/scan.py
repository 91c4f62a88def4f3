"""Compiled parts of the collision scan along a run: placements, path lengths, ground heights.

Mirrors the numpy of :mod:`multiarm_pin.feasibility.scan` and
:mod:`multiarm_pin.feasibility.batch_kinematics` (their references, tested against them and
against Pinocchio): :func:`joint_placements` (every joint's world placement at many samples,
``pin.forwardKinematics``' recursion ``oMi[j] = oMi[parent] · jointPlacement[j] · M_j(q)``),
:func:`path_lengths` (the joint pairs' path lengths ``C`` of the conservative advancement),
:func:`first_exceeding` (the first sample where a pair's ``C`` passes a threshold) and
:func:`ground_heights` (the lowest points of the polytopes above the ground).

All are ``nogil``: the scan runs on a worker thread beside the compiled loop, and holds the
interpreter only between these calls. The model comes as the rigid-body tables of
:class:`~multiarm_pin.model.compiled_model.CompiledModel` (``MI_*``, ``MF_*``, ``KIND_*`` of
:mod:`multiarm_pin._compiled.layout`), plus an optional last free-flyer joint (the object of
a collision scene: parent the universe, placement the identity, ``q`` ``[x, y, z, qx, qy, qz,
qw]`` after the tables' joints). Units SI, world axes.

Twins: ``multiarm_pin.feasibility.scan`` (the same concept, the collision scan along a run, at
the feasibility layer: its ``RunScan`` calls these kernels, and runs numpy references instead
with ``compiled=False``).
"""

from __future__ import annotations

import math

import numpy as np

from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.layout import (
    KIND_PRISMATIC,
    KIND_REVOLUTE_UNBOUNDED,
    MF_AXIS,
    MF_PLACEMENT,
    MI_IDX_Q,
    MI_KIND,
    MI_PARENT,
)


@kernel(nogil=True)
def joint_placements(model_ints, model_floats, q, R, p):  # pragma: no cover - compiled
    """World placements of every joint at ``m`` configurations.

    Args:
        model_ints: (nj, MODEL_INTS) int64 joint rows of the tables (row 0 the universe; the
            joints revolute, prismatic or continuous revolute).
        model_floats: (nj, MODEL_FLOATS) float64.
        q: (m, nq) configurations; with a free flyer, its 7 entries last.
        R: output (m, J, 3, 3) joint axes -> world axes; ``J = nj`` or ``nj + 1`` (then joint
            ``nj`` is the free flyer, its quaternion normalised).
        p: output (m, J, 3) joint origins [m].
    """
    m, J = R.shape[0], R.shape[1]
    nj = model_ints.shape[0]
    L = np.empty((3, 3))  # a joint's local rotation (placement times its motion)
    E = np.empty((3, 3))  # its motion's rotation
    tk = np.empty(3)
    for s in range(m):
        for r in range(3):
            p[s, 0, r] = 0.0
            for c in range(3):
                R[s, 0, r, c] = 1.0 if r == c else 0.0
        for j in range(1, nj):
            par, kind, i = model_ints[j, MI_PARENT], model_ints[j, MI_KIND], model_ints[j, MI_IDX_Q]
            a = model_floats[j, MF_AXIS:MF_AXIS + 3]
            P = model_floats[j, MF_PLACEMENT:MF_PLACEMENT + 12]  # [Rm | t] row-major
            shift = 0.0
            if kind == KIND_PRISMATIC:
                co, si = 1.0, 0.0
                shift = q[s, i]
            elif kind == KIND_REVOLUTE_UNBOUNDED:
                co, si = q[s, i], q[s, i + 1]
            else:
                co, si = math.cos(q[s, i]), math.sin(q[s, i])
            # E = cos I + sin [a]x + (1 - cos) a aᵀ (I for a prismatic joint), L = Rm E
            E[0, 0], E[0, 1], E[0, 2] = co, -si * a[2], si * a[1]
            E[1, 0], E[1, 1], E[1, 2] = si * a[2], co, -si * a[0]
            E[2, 0], E[2, 1], E[2, 2] = -si * a[1], si * a[0], co
            for r in range(3):
                for c in range(3):
                    E[r, c] += (1.0 - co) * a[r] * a[c]
            for r in range(3):
                for c in range(3):
                    L[r, c] = P[4 * r] * E[0, c] + P[4 * r + 1] * E[1, c] + P[4 * r + 2] * E[2, c]
            for k in range(3):  # the origin in the parent's frame: t + L a travel
                tk[k] = P[4 * k + 3] + (L[k, 0] * a[0] + L[k, 1] * a[1] + L[k, 2] * a[2]) * shift
            for r in range(3):
                p[s, j, r] = (p[s, par, r] + R[s, par, r, 0] * tk[0] + R[s, par, r, 1] * tk[1]
                              + R[s, par, r, 2] * tk[2])
                for c in range(3):
                    R[s, j, r, c] = (R[s, par, r, 0] * L[0, c] + R[s, par, r, 1] * L[1, c]
                                     + R[s, par, r, 2] * L[2, c])
        if J > nj:  # the free flyer: [x, y, z, qx, qy, qz, qw]
            i = q.shape[1] - 7
            x, y, z, w = q[s, i + 3], q[s, i + 4], q[s, i + 5], q[s, i + 6]
            n = math.sqrt(x * x + y * y + z * z + w * w)
            x, y, z, w = x / n, y / n, z / n, w / n
            R[s, nj, 0, 0] = 1.0 - 2.0 * (y * y + z * z)
            R[s, nj, 0, 1] = 2.0 * (x * y - z * w)
            R[s, nj, 0, 2] = 2.0 * (x * z + y * w)
            R[s, nj, 1, 0] = 2.0 * (x * y + z * w)
            R[s, nj, 1, 1] = 1.0 - 2.0 * (x * x + z * z)
            R[s, nj, 1, 2] = 2.0 * (y * z - x * w)
            R[s, nj, 2, 0] = 2.0 * (x * z - y * w)
            R[s, nj, 2, 1] = 2.0 * (y * z + x * w)
            R[s, nj, 2, 2] = 1.0 - 2.0 * (x * x + y * y)
            for r in range(3):
                p[s, nj, r] = q[s, i + r]


@kernel(nogil=True)
def path_lengths(R, p, R_last, p_last, ua, ub, base_shift, base_turn, shift,
                 turn):  # pragma: no cover - compiled
    """The joint pairs' path lengths at ``m`` consecutive samples (``RunScan._block_paths``).

    From each joint's world increment ``A = R(t) R(t-1)ᵀ``: pair ``(a, b)``'s relative
    placement turns by ``‖A_a - A_b‖_F / √2`` (the spectral norm of the change) and its
    origin moves by ``|w(t) - A_b w(t-1)|`` (``w = p_a - p_b``); both summed from the bases.

    Args:
        R: (m, J, 3, 3) the joints' rotations at the samples.
        p: (m, J, 3) their origins [m].
        R_last: (J, 3, 3) the rotations at the sample before the first (the first's own at
            the run's start).
        p_last: (J, 3) the origins there [m].
        ua: (U,) int64 the pairs' first joints.
        ub: (U,) int64 their second joints.
        base_shift: (U,) ``Σ |Δp|`` at the sample before the first [m].
        base_turn: (U,) ``Σ ‖ΔR‖_2`` there.
        shift: output (m, U) ``Σ |Δp|`` up to each sample [m].
        turn: output (m, U) ``Σ ‖ΔR‖_2`` up to each sample.
    """
    m, J = R.shape[0], R.shape[1]
    U = ua.shape[0]
    A = np.empty((J, 3, 3))
    e = np.empty(3)
    for s in range(m):
        Rp = R_last if s == 0 else R[s - 1]
        pp = p_last if s == 0 else p[s - 1]
        for j in range(J):
            for r in range(3):
                for c in range(3):
                    A[j, r, c] = (R[s, j, r, 0] * Rp[j, c, 0] + R[s, j, r, 1] * Rp[j, c, 1]
                                  + R[s, j, r, 2] * Rp[j, c, 2])
        for u in range(U):
            a, b = ua[u], ub[u]
            d2 = 0.0
            for r in range(3):
                for c in range(3):
                    d = A[a, r, c] - A[b, r, c]
                    d2 += d * d
            for r in range(3):
                e[r] = (p[s, a, r] - p[s, b, r]) - (
                    A[b, r, 0] * (pp[a, 0] - pp[b, 0]) + A[b, r, 1] * (pp[a, 1] - pp[b, 1])
                    + A[b, r, 2] * (pp[a, 2] - pp[b, 2]))
            prev_s = base_shift[u] if s == 0 else shift[s - 1, u]
            prev_t = base_turn[u] if s == 0 else turn[s - 1, u]
            shift[s, u] = prev_s + math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
            turn[s, u] = prev_t + math.sqrt(0.5 * d2)


@kernel(nogil=True)
def first_exceeding(shift, turn, u, rho, thr, lo, hi, at):  # pragma: no cover - compiled
    """First sample in ``[lo, hi)`` where ``shift[s, u_k] + rho_k turn[s, u_k] > thr_k``.

    ``shift``, ``turn`` (T, U) non-decreasing along the samples; ``u`` (K,) int64, ``rho``,
    ``thr`` (K,); ``at`` output (K,) int64, ``hi`` where no sample of the range exceeds.
    A binary search per pair.
    """
    for k in range(u.shape[0]):
        a, b = lo, hi
        uk, rk, tk = u[k], rho[k], thr[k]
        while a < b:
            mid = (a + b) >> 1
            if shift[mid, uk] + rk * turn[mid, uk] > tk:
                b = mid
            else:
                a = mid + 1
        at[k] = a


@kernel(nogil=True)
def _write_height(d, row, col, slot, low, exact, best):  # pragma: no cover - compiled
    """An exact height ``d`` [m] into ``low[row, slot]`` and ``exact[row, col]``; the new best.

    The tail of :func:`ground_heights` and :func:`round_heights`: ``d`` is the body's origin
    height minus its support function along ``-z`` minus the ground's height; returns
    ``min(best, d)``.
    """
    low[row, slot] = d
    exact[row, col] = d
    return min(best, d)


@kernel(nogil=True)
def stable_order(a):  # pragma: no cover - compiled
    """The indices that sort ``a`` (n,) ascending: ``np.argsort(a, kind="stable")``.

    Equal values keep their order, NaN last. By insertion: ``n`` is a scene's body count, and
    numba's mergesort compiles for seconds.
    """
    order = np.arange(a.shape[0])
    for i in range(1, a.shape[0]):
        k = order[i]
        j = i - 1
        while j >= 0 and (a[order[j]] > a[k]
                          or (math.isnan(a[order[j]]) and not math.isnan(a[k]))):
            order[j + 1] = order[j]
            j -= 1
        order[j + 1] = k
    return order


@kernel(nogil=True)
def ground_heights(R, p, joints, corners, vertices, starts, height, best, tol, n0, pairs,
                   slots, low, exact):  # pragma: no cover - compiled
    """The polytopes' ground pairs at ``m`` samples: bounds, and exact where they matter.

    Each body's lowest box corner bounds its height above the ground ``z = height`` from
    below; the pairs are taken by their smallest bound, and at the samples where the bound
    is below ``max(best, tol)`` the height of the body's lowest vertex is computed
    (``best``: the smallest exact height so far, lowered as they come).

    Args:
        R: (m, J, 3, 3) the joints' rotations at the samples.
        p: (m, J, 3) their origins [m].
        joints: (K,) int64 each body's joint.
        corners: (K, 8, 3) its box's corners in its joint's frame [m].
        vertices: (V, 3) the bodies' vertices in their joints' frames, body ``k``'s rows
            ``starts[k] .. starts[k + 1] - 1``.
        starts: (K + 1,) int64.
        height: the ground's height [m].
        best: the smallest height found so far [m].
        tol: the penetration tolerance [m].
        n0: the run index of the first sample.
        pairs: (K,) int64 the pairs' columns of ``exact``.
        slots: (K,) int64 their columns of ``low``.
        low: (T, Pg) the ground pairs' lower bounds: rows ``n0 .. n0 + m - 1`` written.
        exact: (T, P) exact heights: written where computed.

    Returns:
        The new ``best``.
    """
    m, K = R.shape[0], joints.shape[0]
    lowest = np.empty(K)
    for k in range(K):
        j, slot = joints[k], slots[k]
        lk = np.inf
        for s in range(m):
            z = np.inf
            for v in range(8):
                zv = (corners[k, v, 0] * R[s, j, 2, 0] + corners[k, v, 1] * R[s, j, 2, 1]
                      + corners[k, v, 2] * R[s, j, 2, 2])
                z = min(z, zv)
            low[n0 + s, slot] = z + p[s, j, 2] - height
            lk = min(lk, low[n0 + s, slot])
        lowest[k] = lk
    for k in stable_order(lowest):
        limit = max(best, tol)
        if lowest[k] >= limit:
            break  # and every later pair's bound is at least as large
        j, slot = joints[k], slots[k]
        for s in range(m):
            if low[n0 + s, slot] >= limit:
                continue
            top = -np.inf  # the support function along -z: max of -z over the vertices
            for v in range(starts[k], starts[k + 1]):
                top = max(top, -R[s, j, 2, 0] * vertices[v, 0] - R[s, j, 2, 1] * vertices[v, 1]
                          - R[s, j, 2, 2] * vertices[v, 2])
            best = _write_height(p[s, j, 2] - top - height, n0 + s, pairs[k], slot, low, exact,
                                 best)
    return best


@kernel(nogil=True)
def grasp_openings(centres, bodies, radius, points, zone, n0, columns,
                   opens):  # pragma: no cover - compiled
    """From each sample on, the first where an arm's carrying link may collide with the object.

    A carrying link whose bounding sphere lies within ``zone`` of one of its arm's contact
    points touches the object (if at all) at the grasp: such samples are skipped.

    Args:
        centres: (m, G, 3) the bodies' bounding-sphere centres at the samples [m].
        bodies: (K,) int64 the carrying links' geometry indices.
        radius: (K,) their spheres' radii [m].
        points: (m, N, 3) the arm's contact points [m].
        zone: the grasp zone's radius [m].
        n0: the run index of the first sample (``n0 + m``: none in the stretch).
        columns: (K,) int64 the pairs' columns of ``opens``.
        opens: (m + 1, P) run indices, written in the pairs' columns (rows ``0 .. m - 1``).
    """
    m, N = points.shape[0], points.shape[1]
    for k in range(bodies.shape[0]):
        g, col = bodies[k], columns[k]
        nxt = n0 + m
        for s in range(m - 1, -1, -1):
            near = np.inf
            for i in range(N):
                d0 = points[s, i, 0] - centres[s, g, 0]
                d1 = points[s, i, 1] - centres[s, g, 1]
                d2 = points[s, i, 2] - centres[s, g, 2]
                near = min(near, math.sqrt(d0 * d0 + d1 * d1 + d2 * d2))
            if not near + radius[k] <= zone:
                nxt = n0 + s
            opens[s, col] = nxt


@kernel(nogil=True)
def pair_bounds(exact, shift, turn, ks, u, rho, centres, a, b, ra, rb, spheres, slots,
                ground_lower, out):  # pragma: no cover - compiled
    """Lower bounds of pairs' hull distances at every sample scanned (``column_bounds``).

    The measured distance where measured; elsewhere the best of the path bounds from the
    measurements before and after (``d - |C(s') - C(s)|``, ``C = shift + ρ turn``) and the gap
    of the pair's bounding spheres; a ground pair's own bound.

    Args:
        exact: (T, P) measured distances, NaN where not measured [m].
        shift: (T, U) the joint pairs' ``Σ |Δp|`` [m].
        turn: (T, U) their ``Σ ‖ΔR‖_2``.
        ks: (K,) int64 the pairs.
        u: (K,) int64 their joint pairs.
        rho: (K,) their first bodies' reach [m].
        centres: (T, G, 3) the bodies' bounding-sphere centres [m] (read where ``spheres``).
        a: (K,) int64 the pairs' first bodies.
        b: (K,) int64 their second bodies.
        ra: (K,) the first bodies' sphere radii [m].
        rb: (K,) the second bodies' [m].
        spheres: (K,) bool: the spheres' gap bounds the pair.
        slots: (K,) int64 a ground pair's column of ``ground_lower`` (its bound there), -1 for
            another pair.
        ground_lower: (T, Pg) the ground pairs' bounds [m].
        out: output (n, K) the bounds at samples ``0 .. n - 1`` [m].
    """
    n = out.shape[0]
    for k in range(ks.shape[0]):
        col, uk, rk = ks[k], u[k], rho[k]
        if slots[k] >= 0:
            for s in range(n):
                out[s, k] = ground_lower[s, slots[k]]
            continue
        best = -np.inf  # max over measured s' <= s of d + C(s')
        for s in range(n):
            C = shift[s, uk] + rk * turn[s, uk]
            d = exact[s, col]
            if not math.isnan(d):
                best = max(best, d + C)
            out[s, k] = best - C
        best = -np.inf  # max over measured s' >= s of d - C(s')
        for s in range(n - 1, -1, -1):
            C = shift[s, uk] + rk * turn[s, uk]
            d = exact[s, col]
            if not math.isnan(d):
                best = max(best, d - C)
                out[s, k] = d
                continue
            bound = max(out[s, k], best + C)
            if spheres[k]:
                g0 = centres[s, a[k], 0] - centres[s, b[k], 0]
                g1 = centres[s, a[k], 1] - centres[s, b[k], 1]
                g2 = centres[s, a[k], 2] - centres[s, b[k], 2]
                bound = max(bound, math.sqrt(g0 * g0 + g1 * g1 + g2 * g2) - ra[k] - rb[k])
            out[s, k] = bound


@kernel(nogil=True)
def round_heights(R, p, joints, rotations, offsets, sizes, cylinder, height, n0, pairs, slots,
                  low, exact):  # pragma: no cover - compiled
    """Heights above the ground ``z = height`` of round bodies' lowest points, exactly.

    Spheres, capsules (``sizes[k] = (radius, half length)``, a sphere's half length 0) and
    cylinders (axis z of the shape's frame); the support function along ``-z``.

    Args:
        R: (m, J, 3, 3) the joints' rotations at the samples.
        p: (m, J, 3) their origins [m].
        joints: (K,) int64 each body's joint.
        rotations: (K, 3, 3) each shape's frame in its joint's frame.
        offsets: (K, 3) its origin there [m].
        sizes: (K, 2) radius and half length [m].
        cylinder: (K,) bool: a cylinder (else a sphere or capsule).
        height: the ground's height [m].
        n0: the run index of the first sample.
        pairs: (K,) int64 the pairs' columns of ``exact``.
        slots: (K,) int64 their columns of ``low``.
        low: (T, Pg) the ground pairs' bounds: rows ``n0 .. n0 + m - 1`` written.
        exact: (T, P) exact heights: the same rows written.

    Returns:
        The smallest height written [m] (inf if none).
    """
    best = np.inf
    for k in range(joints.shape[0]):
        j = joints[k]
        for s in range(R.shape[0]):
            u0, u1, u2 = -R[s, j, 2, 0], -R[s, j, 2, 1], -R[s, j, 2, 2]
            g0 = u0 * rotations[k, 0, 0] + u1 * rotations[k, 1, 0] + u2 * rotations[k, 2, 0]
            g1 = u0 * rotations[k, 0, 1] + u1 * rotations[k, 1, 1] + u2 * rotations[k, 2, 1]
            g2 = u0 * rotations[k, 0, 2] + u1 * rotations[k, 1, 2] + u2 * rotations[k, 2, 2]
            radial = (math.sqrt(g0 * g0 + g1 * g1) if cylinder[k]
                      else math.sqrt(u0 * u0 + u1 * u1 + u2 * u2))
            top = (u0 * offsets[k, 0] + u1 * offsets[k, 1] + u2 * offsets[k, 2]
                   + sizes[k, 1] * abs(g2) + sizes[k, 0] * radial)
            best = _write_height(p[s, j, 2] - top - height, n0 + s, pairs[k], slots[k], low,
                                 exact, best)
    return best


@kernel(nogil=True)
def support_max(u, vertices, out):  # pragma: no cover - compiled
    """A polytope's support function ``max_v u·v`` along ``m`` directions.

    Args:
        u: (m, 3) directions.
        vertices: (V, 3) the polytope's vertices (same frame).
        out: output (m,).
    """
    for i in range(u.shape[0]):
        top = -np.inf
        for v in range(vertices.shape[0]):
            top = max(top, u[i, 0] * vertices[v, 0] + u[i, 1] * vertices[v, 1]
                      + u[i, 2] * vertices[v, 2])
        out[i] = top


__all__ = ["first_exceeding", "grasp_openings", "ground_heights", "joint_placements",
           "pair_bounds", "path_lengths", "round_heights", "stable_order", "support_max"]
