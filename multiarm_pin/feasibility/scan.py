"""Collisions along a run, stretch by stretch: each pair measured only where it may come closer.

:class:`RunScan` takes a run's samples in stretches (:meth:`RunScan.extend`: the whole run at
once after it, or each stretch the simulation records while it runs, for a ``stop`` policy)
and finds every sample where a pair of :class:`~multiarm_pin.feasibility.CollisionScene`'s
bodies interpenetrates, and the clearance of each category over the samples
(:meth:`RunScan.result`).

Conservative advancement at sample resolution, along the path: for each pair of joints
``(a, b)`` that carry a pair's bodies, the path length of ``a``'s placement seen from ``b``,
``C(s) = Σ_{t < s} |Δp_t| + ρ ‖ΔR_t‖_2`` (``Δ`` between consecutive samples, ``ρ`` bounding
the distance of the first body's points to its joint), bounds how far any point of the first
body has moved relative to the second between two samples: a pair measured at sample ``s``
(distance ``d``) is at least ``d - (C(s') - C(s))`` apart at any ``s'`` (and at any earlier
sample, from a later measurement). It is measured again at the first sample where that bound
falls to :data:`ADVANCE_FRACTION` of ``d`` (to ``-PENETRATION_TOLERANCE`` for a grasp pair or a
touching one, which matter only once they may penetrate; at every sample while it penetrates),
found by a binary search of the monotone ``C``. A pair that stays far is measured once.
Ground pairs: the lowest point of a round shape exactly, of a hull bounded by the lowest
corner of its box and measured from its vertices (exact for a half-space). A hull
penetration is checked on the meshes (:meth:`CollisionScene.mesh_penetration`); a carrying
link within the grasp zone of its arm's contact points is skipped at those samples (the
grasp, not a collision).

Clearances (:meth:`RunScan.result`): per category, branch and bound over each pair's samples,
from the bounds above (and the gap of the pair's bounding spheres); a measurement also bounds
its pair at the other samples by the gap of the two bodies along the measured closest axis,
carried with the second body (a separating-axis bound from their support functions), which
holds a pair at nearly constant distance (two links turning about each other) with a few
measurements.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from multiarm_pin.feasibility.batch_kinematics import joint_placements

CATEGORIES = ("arm_self", "arm_arm", "arm_object", "arm_support", "arm_ground")
"""Pair categories, in the order of the codes of
:attr:`~multiarm_pin.feasibility.collisions.CollisionScene.category`."""

JOINT_ZONE_RADIUS = 0.05
"""Radius [m] around each contact point of an arm's grasp inside which its carrying links
may touch or enter the object (the grasp, not a collision)."""

PENETRATION_TOLERANCE = 1e-6
"""Depth [m] beyond which a penetration counts (round-off of touching surfaces)."""

ADVANCE_FRACTION = 0.5
"""A measured pair is measured again where its bound falls below this fraction of the distance
measured."""

ADVANCE_STRIDE = 16
"""A pair due at a later sample is measured at the last multiple of this many samples before
it, so that pairs share their samples (one placement update for all of them)."""

CLEARANCE_TOLERANCE = 1e-10
"""How far [m] above the exact minimum over the samples a reported clearance may be (a pair
whose bound is within it of the smallest distance found is not measured again)."""

KEPT_PLACEMENTS = 1_000_000
"""Largest samples x joints whose placements a scan keeps (96 bytes each)."""

PATH_BLOCK = 128
"""Samples per block of the path lengths' computation (its arrays stay in the CPU cache)."""


@dataclass(frozen=True)
class ScanResult:
    """What :class:`RunScan` found along a run.

    Attributes:
        clearance: per category of :data:`CATEGORIES`,
            the smallest hull distance over the run [m] (grasp pairs left out), or None when
            the category has no pair.
        hits: per pair index, its collisions ``(sample, distance [m] on the meshes, point
            (3,) on the first body)`` in time order.
        measured: number of (sample, pair) distances computed exactly.
    """

    clearance: dict
    hits: dict
    measured: int


class _ScanGeometry:
    """What a scan needs of a scene that does not depend on the run (built once per scene)."""

    def __init__(self, scene):
        hull = scene.hull
        G = hull.ngeoms
        centre, radius = np.zeros((G, 3)), np.zeros(G)
        for g in range(G):
            if g == scene.ground_index:
                continue
            o = hull.geometryObjects[g]
            shape = o.geometry
            shape.computeLocalAABB()
            centre[g] = o.placement.act(np.array(shape.aabb_center))  # in its joint's frame
            radius[g] = float(shape.aabb_radius)
        self.joint = np.array([o.parentJoint for o in hull.geometryObjects], dtype=int)
        self.centre, self.radius = centre, radius
        reach = np.linalg.norm(centre, axis=1) + radius  # any point's distance to its joint
        pairs = scene.pairs
        P = len(pairs)
        ja, jb = self.joint[pairs[:, 0]], self.joint[pairs[:, 1]]
        key = ja * scene.model.njoints + jb
        uniq, self.joint_pair = np.unique(key, return_inverse=True)
        self.ua, self.ub = uniq // scene.model.njoints, uniq % scene.model.njoints
        self.rho = reach[pairs[:, 0]]
        # each body's support function in its joint's frame (None: a shape without one)
        self.hull_vertices = []  # hulls' and boxes' vertices (V, 3), in the joint frame
        self.round = []  # spheres, cylinders, capsules: (R, t, radius, half length, kind)
        for g in range(G):
            o = hull.geometryObjects[g]
            shape = o.geometry
            M = o.placement
            pts, rnd = None, None
            if hasattr(shape, "points"):
                pts = np.asarray(shape.points(), float)
            elif hasattr(shape, "halfSide"):
                h = np.array(shape.halfSide)
                pts = np.array([[x, y, z] for x in (-h[0], h[0]) for y in (-h[1], h[1])
                                for z in (-h[2], h[2])])
            elif type(shape).__name__ in ("Sphere", "Cylinder", "Capsule"):
                kind = type(shape).__name__
                rnd = (np.array(M.rotation), np.array(M.translation), float(shape.radius),
                       float(getattr(shape, "halfLength", 0.0)), kind)
            self.hull_vertices.append(None if pts is None else pts @ M.rotation.T
                                      + M.translation)
            self.round.append(rnd)
        # ground pairs with a support function: the lowest point, exactly (others: coal)
        self.vertices = {}  # ground pair of a polytope -> box corners (8, 3) in joint
        self.ground = np.zeros(P, dtype=bool)
        for k in (np.flatnonzero(pairs[:, 1] == scene.ground_index)
                  if scene.ground_index is not None else ()):
            a = int(pairs[k, 0])
            local = self.hull_vertices[a]
            if local is not None:
                lo, hi = local.min(axis=0), local.max(axis=0)
                self.vertices[int(k)] = np.array([[x, y, z] for x in (lo[0], hi[0])
                                                  for y in (lo[1], hi[1])
                                                  for z in (lo[2], hi[2])])
            elif self.round[a] is None:
                continue
            self.ground[k] = True

    def support(self, g: int, u: np.ndarray) -> np.ndarray | None:
        """``max u·x`` over geometry ``g`` (x in its joint's frame) for directions u (m, 3).

        A polytope's vertices; a sphere, cylinder (axis z of its frame) or capsule in closed
        form. None for another shape.
        """
        V = self.hull_vertices[g]
        if V is not None:  # sums of products, not a BLAS call (an inner dimension of 3)
            return (u[:, 0, None] * V[:, 0] + u[:, 1, None] * V[:, 1]
                    + u[:, 2, None] * V[:, 2]).max(axis=1)
        rnd = self.round[g]
        if rnd is None:
            return None
        R, t, r, h, kind = rnd
        ug = u @ R  # the directions in the shape's frame
        out = u @ t + h * np.abs(ug[:, 2])
        if kind == "Cylinder":
            return out + r * np.hypot(ug[:, 0], ug[:, 1])
        return out + r * np.linalg.norm(u, axis=1)


def scan_geometry(scene) -> _ScanGeometry:
    """The scene's run-independent scan data (built at the first scan, then kept)."""
    geo = getattr(scene, "_scan_geometry", None)
    if geo is None:
        geo = scene._scan_geometry = _ScanGeometry(scene)
    return geo


class RunScan:
    """Collisions and clearances of a run whose samples come in stretches (module docstring).

    Args:
        scene: the :class:`~multiarm_pin.feasibility.CollisionScene` of the run's system.
        capacity: the run's number of samples T (at most this many are extended).

    Attributes:
        n: samples scanned so far.
        hits: per pair index, its collisions ``(sample, depth [m], point (3,))``.
    """

    def __init__(self, scene, capacity: int):
        self.scene = scene
        self.geo = scan_geometry(scene)
        self.tol = PENETRATION_TOLERANCE
        T, P, U = int(capacity), len(scene.pairs), len(self.geo.ua)
        self.T = T
        self.n = 0
        self.configs = np.zeros((T, scene.model.nq))
        self.path_shift = np.zeros((T, U))  # Σ |Δp| of each joint pair's relative placement
        self.path_turn = np.zeros((T, U))  # Σ ‖ΔR‖_2
        self.exact = np.full((T, P), np.nan)
        self.ground_lower = np.full((T, P), -np.inf)  # ground pairs' bounds (exact if measured)
        self.ground_best = np.inf
        never = T  # a sample index no stretch reaches
        self.due = np.where(self.geo.ground, never, 0)
        self.pending = np.zeros(P, dtype=bool)  # its bound holds over every sample so far
        self.last = np.full(P, -1)
        self.budget = np.zeros(P)
        self.hits: dict[int, list] = {}
        self._last_rel = None  # joints' (R (J, 3, 3), p (J, 3)) at sample n - 1
        J = scene.model.njoints
        # every joint's placement at every sample, for the clearances' separating-axis
        # bounds; recomputed where needed instead when a run is too long to keep them
        kept = T * J <= KEPT_PLACEMENTS
        self._R = np.empty((T, J, 3, 3)) if kept else None
        self._p = np.empty((T, J, 3)) if kept else None

    # ------------------------------------------------------------------ stretches
    def extend(self, q: np.ndarray, object_position: np.ndarray, object_quaternion: np.ndarray,
               contact_points: list[np.ndarray] | None = None) -> int | None:
        """Scan the next samples of the run.

        Args:
            q: (m, nq) arms' configurations of samples ``n .. n + m - 1``.
            object_position: (m, 3) [m].
            object_quaternion: (m, 4) ``[x, y, z, w]``.
            contact_points: per arm, (m, N_i, 3) its grasp's contact points [m] (None: no
                grasp exception).

        Returns:
            The first sample (run index) of these with a collision, or None.
        """
        n0, m = self.n, len(q)
        n1 = n0 + m
        if n1 > self.T:
            raise ValueError(f"RunScan: {n1} samples exceed its capacity {self.T}")
        if not m:
            return None
        scene = self.scene
        configs = self.configs
        configs[n0:n1] = np.concatenate([q, object_position, object_quaternion], axis=1)
        R, p = joint_placements(scene.model, configs[n0:n1])
        if self._R is not None:
            self._R[n0:n1], self._p[n0:n1] = R, p
        self._paths(R, p, n0, n1)
        opens = self._openings(R, p, contact_points, n0, n1)
        self._ground(R, p, n0, n1)
        # pairs whose bound held to the last stretch's end: where does it fail in this one?
        waiting = np.flatnonzero(self.pending)
        if len(waiting):
            s2, found = self._first_exceeding(waiting, n0, n1)
            self.pending[waiting[found]] = False
            self.due[waiting[found]] = np.maximum(n0, s2[found] // ADVANCE_STRIDE
                                                  * ADVANCE_STRIDE)
        live = (self.due >= n0) & (self.due < n1)
        self.due[live] = opens[self.due[live] - n0, np.flatnonzero(live)]
        self._advance(opens, n0, n1)
        self.n = n1
        return self._check_hits(contact_points, n0, n1)

    def _paths(self, R, p, n0: int, n1: int) -> None:
        """:meth:`_block_paths` in blocks of :data:`PATH_BLOCK` samples (in cache)."""
        for b0 in range(n0, n1, PATH_BLOCK):
            b1 = min(n1, b0 + PATH_BLOCK)
            self._block_paths(R[b0 - n0:b1 - n0], p[b0 - n0:b1 - n0], b0, b1)

    def _block_paths(self, R, p, n0: int, n1: int) -> None:
        """The joint pairs' path lengths ``C`` at samples ``n0 .. n1 - 1``.

        From each joint's world increment between consecutive samples, ``A = R(t) R(t-1)ᵀ``:
        the relative placement ``(R_bᵀ R_a, R_bᵀ w)`` (``w = p_a - p_b``) of a joint pair
        changes by ``‖ΔR_rel‖_F = ‖A_a - A_b‖_F`` (its spectral norm, which bounds how far a
        point moves per metre from the joint, is that over √2) and
        ``|Δp_rel| = |w(t) - A_b w(t-1)|`` (both exact and without cancellation).
        """
        ua, ub = self.geo.ua, self.geo.ub
        m = n1 - n0
        if self._last_rel is None:
            R_prev = np.concatenate([R[:1], R[:-1]])
            p_prev = np.concatenate([p[:1], p[:-1]])
        else:
            R_prev = np.concatenate([self._last_rel[0][None], R[:-1]])
            p_prev = np.concatenate([self._last_rel[1][None], p[:-1]])
        # joint-first layouts (J, ..., m): gathering by joint copies contiguous blocks
        A = np.ascontiguousarray(np.moveaxis(R @ np.swapaxes(R_prev, -1, -2), 0, -1)
                                 ).reshape(-1, 9, m)  # (J, 9, m)
        pc = np.ascontiguousarray(np.moveaxis(p, 0, -1))  # (J, 3, m)
        qc = np.ascontiguousarray(np.moveaxis(p_prev, 0, -1))
        Ab = A[ub]  # (U, 9, m)
        D = A[ua] - Ab
        # ‖ΔR‖_2 = ‖ΔR‖_F / √2 for a difference of rotations (R1 - R2 = R1 (I - Q), Q a
        # rotation by θ: singular values 2 sin(θ/2) twice and 0): a point at ρ from the
        # joint moves by at most ρ ‖ΔR‖_2
        turn = np.sqrt(0.5 * np.einsum("uim,uim->um", D, D)).T  # (m, U)
        w = pc[ua] - pc[ub]  # (U, 3, m)
        w0 = qc[ua] - qc[ub]
        shift2 = np.zeros((len(ua), m))
        for i in range(3):
            e = w[:, i] - (Ab[:, 3 * i] * w0[:, 0] + Ab[:, 3 * i + 1] * w0[:, 1]
                           + Ab[:, 3 * i + 2] * w0[:, 2])
            shift2 += e * e
        shift = np.sqrt(shift2).T
        base_s = self.path_shift[n0 - 1] if n0 else 0.0
        base_t = self.path_turn[n0 - 1] if n0 else 0.0
        self.path_shift[n0:n1] = base_s + np.cumsum(shift, axis=0)
        self.path_turn[n0:n1] = base_t + np.cumsum(turn, axis=0)
        self._last_rel = (R[-1].copy(), p[-1].copy())

    def _path(self, s: np.ndarray, k: np.ndarray) -> np.ndarray:
        """``C`` of pairs ``k`` at samples ``s`` (same shapes) [m]."""
        u = self.geo.joint_pair[k]
        return self.path_shift[s, u] + self.geo.rho[k] * self.path_turn[s, u]

    def _first_exceeding(self, ks: np.ndarray, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
        """First sample in ``[lo, hi)`` where each pair's bound falls to its target.

        That is where ``C(s) - C(last) > budget`` (``C`` is non-decreasing: a binary search,
        all pairs at once, on the flat arrays).

        Returns:
            ``(samples (K,), found (K,) bool)``.
        """
        U = self.path_shift.shape[1]
        shift, turn = self.path_shift.reshape(-1), self.path_turn.reshape(-1)
        u = self.geo.joint_pair[ks]
        rho = self.geo.rho[ks]
        at = self.last[ks] * U + u
        thr = shift.take(at) + rho * turn.take(at) + self.budget[ks]
        a = np.full(len(ks), lo)
        b = np.full(len(ks), hi)
        for _ in range(max(1, int(hi - lo).bit_length())):
            mid = (a + b) >> 1
            at = np.minimum(mid, hi - 1) * U + u
            over = shift.take(at) + rho * turn.take(at) > thr
            b = np.where(over, mid, b)
            a = np.where(over | (a >= b), a, mid + 1)
        return a, a < hi

    def _openings(self, R, p, contact_points, n0: int, n1: int) -> np.ndarray:
        """(m + 1, P) from each sample of the stretch on, the first where a pair can collide.

        Run indices; ``n1``: none in the stretch.

        A carrying link whose bounding sphere lies, at a sample, within
        :data:`JOINT_ZONE_RADIUS` of one of its arm's
        contact points touches the object (if at all) at the grasp: such samples are skipped.
        Every other pair may collide at every sample (its own index).
        """
        scene, geo = self.scene, self.geo
        m, P = n1 - n0, len(scene.pairs)
        opens = np.broadcast_to(np.arange(n0, n1 + 1)[:, None], (m + 1, P)).copy()
        if contact_points is None:
            return opens
        for k in np.flatnonzero(scene.grasp_pair):
            g = int(scene.pairs[k, 0])
            cps = np.asarray(contact_points[scene.arm_of_pair[k]]).reshape(m, -1, 3)
            if not cps.shape[1]:
                continue
            j = geo.joint[g]
            c = np.einsum("tij,j->ti", R[:, j], geo.centre[g]) + p[:, j]
            near = np.min(np.linalg.norm(cps - c[:, None], axis=2), axis=1) + geo.radius[g]
            nxt = np.where(near <= JOINT_ZONE_RADIUS, n1, np.arange(n0, n1))
            opens[:m, k] = np.minimum.accumulate(nxt[::-1])[::-1]
        return opens

    def _ground(self, R, p, n0: int, n1: int) -> None:
        """The ground pairs at samples ``n0 .. n1 - 1``: bounds, and exact where they matter.

        The distance of a convex body to the half-space ``z <= h`` is the height of its
        lowest point above ``h`` (its support function along ``-z``): exact for the round
        shapes at once; a polytope's is bounded from below by the lowest corner of its box
        (in its joint frame) first, and computed from its vertices only where that bound is
        below the smallest distance found so far (or below the penetration tolerance).
        """
        geo, joint = self.geo, self.geo.joint
        ks = np.flatnonzero(geo.ground)
        if not len(ks):
            return
        pairs = self.scene.pairs
        low = self.ground_lower[n0:n1]

        def lowest(k, rows):  # exact heights above the ground at rows of the stretch
            g = int(pairs[k, 0])
            j = joint[g]
            return p[rows, j, 2] - geo.support(g, -R[rows, j, 2, :]) - self.scene.ground

        every = np.arange(n1 - n0)
        for k in ks:
            if k in geo.vertices:
                j = joint[int(pairs[k, 0])]
                low[:, k] = self._lowest(geo.vertices[k], R[:, j, 2, :], p[:, j, 2])
            else:
                self.exact[n0:n1, k] = low[:, k] = lowest(k, every)
                self.ground_best = min(self.ground_best, float(low[:, k].min()))
        for k in sorted(geo.vertices, key=lambda k: float(low[:, k].min())):
            rows = np.flatnonzero(low[:, k] < max(self.ground_best, self.tol))
            if not len(rows):
                continue
            d = lowest(k, rows)
            self.exact[n0 + rows, k] = low[rows, k] = d
            self.ground_best = min(self.ground_best, float(d.min()))

    def _lowest(self, local: np.ndarray, Rz: np.ndarray, pz: np.ndarray) -> np.ndarray:
        """(m,) height above the ground [m] of the lowest of ``local`` (V, 3) points.

        ``Rz`` (m, 3): the joint's third rotation row; ``pz`` (m,): its origin's height.
        Sums of products, not a BLAS call (small operands).
        """
        z = (local[:, 0, None] * Rz[None, :, 0] + local[:, 1, None] * Rz[None, :, 1]
             + local[:, 2, None] * Rz[None, :, 2])
        return z.min(axis=0) + pz - self.scene.ground

    def _advance(self, opens: np.ndarray, n0: int, n1: int) -> None:
        """Measure every pair due in the stretch, and find when each is due again."""
        scene, due, tol = self.scene, self.due, self.tol
        model, data, hull, hd = scene.model, scene.data, scene.hull, scene.hull_data
        while True:
            s = int(due.min())
            if s >= n1:
                break
            ks = np.flatnonzero(due == s)
            pin.updateGeometryPlacements(model, data, hull, hd, self.configs[s])
            d = np.array([pin.computeDistance(hull, hd, int(k)).min_distance for k in ks])
            self.exact[s, ks] = d
            self.last[ks] = s
            near = d < -tol  # penetrating: every sample (its hits)
            due[ks[near]] = opens[s + 1 - n0, ks[near]]
            far, dfar = ks[~near], d[~near]
            if not len(far):
                continue
            # grasp pairs and touching pairs matter only once they may penetrate
            target = np.where(scene.grasp_pair[far] | (dfar <= tol), -tol,
                              ADVANCE_FRACTION * dfar)
            self.budget[far] = dfar - target
            s2, found = self._first_exceeding(far, s + 1, n1)
            self.pending[far[~found]] = True
            due[far[~found]] = self.T
            hit, at = far[found], s2[found]
            # measured earlier than needed at a multiple of ADVANCE_STRIDE: pairs share samples
            at = np.maximum(s + 1, at // ADVANCE_STRIDE * ADVANCE_STRIDE)
            due[hit] = opens[at - n0, hit]

    def _check_hits(self, contact_points, n0: int, n1: int) -> int | None:
        """The hull penetrations of the stretch checked on the meshes; the first hit's sample."""
        scene = self.scene
        first = None
        rows, cols = np.nonzero(self.exact[n0:n1] < -self.tol)
        for i, k in sorted(zip(rows.tolist(), cols.tolist(), strict=True)):
            s = n0 + i
            hit = scene.mesh_penetration(self.configs[s], k)
            if hit is None:
                continue
            if scene.grasp_pair[k] and contact_points is not None:
                cps = [np.asarray(c)[i] for c in contact_points]
                if scene.at_grasp(k, hit[1], cps):
                    continue
            self.hits.setdefault(int(k), []).append((s, hit[0], hit[1]))
            first = s if first is None else min(first, s)
        return first

    # ------------------------------------------------------------------ the whole run
    def _column_path(self, k: int) -> np.ndarray:
        """(n,) ``C`` of pair ``k`` at the samples scanned [m]."""
        u = self.geo.joint_pair[k]
        return self.path_shift[:self.n, u] + self.geo.rho[k] * self.path_turn[:self.n, u]

    def column_bound(self, k: int) -> np.ndarray:
        """(n,) lower bounds of pair ``k``'s hull distance at the samples scanned [m].

        The measured value where measured; elsewhere the best of the bounds from the
        measurements before and after (``d - |C(s') - C(s)|``); a ground pair's own.
        """
        n = self.n
        if self.geo.ground[k]:
            return self.ground_lower[:n, k].copy()
        d = self.exact[:n, k]
        C = self._column_path(k)
        missing = np.isnan(d)
        ahead = np.maximum.accumulate(np.where(missing, -np.inf, d + C)) - C
        behind = np.maximum.accumulate(np.where(missing, -np.inf, d - C)[::-1])[::-1] + C
        bound = np.maximum(ahead, behind)
        spheres = self._sphere_bound(k)
        if spheres is not None:
            bound = np.maximum(bound, spheres)
        return np.where(missing, bound, d)

    def _sphere_bound(self, k: int) -> np.ndarray | None:
        """(n,) the gap between pair ``k``'s bounding spheres at every sample [m].

        A lower bound of the hulls' distance; None without the placements kept, for a
        ground pair, or a body without a sphere.
        """
        geo = self.geo
        a, b = (int(g) for g in self.scene.pairs[k])
        if self._R is None or geo.ground[k] or not (geo.radius[a] and geo.radius[b]):
            return None
        n = self.n
        ja, jb = geo.joint[a], geo.joint[b]
        R, p = self._R[:n], self._p[:n]
        ea, eb = geo.centre[a], geo.centre[b]
        gap = p[:, ja] - p[:, jb]  # (n, 3): sums of products on strided views, no matmul
        for i in range(3):
            gap += R[:, ja, :, i] * ea[i] - R[:, jb, :, i] * eb[i]
        return np.sqrt(np.einsum("ni,ni->n", gap, gap)) - geo.radius[a] - geo.radius[b]

    def _column_minima(self) -> np.ndarray:
        """(P,) lower bounds of each pair's smallest hull distance over the samples [m].

        From its measurements alone: between two consecutive ones ``(d_a, C_a)``,
        ``(d_b, C_b)`` the bounds are at least ``(d_a + d_b - (C_b - C_a)) / 2``; before the
        first and after the last, ``d - |C - C(end)|``. ``-inf`` for a pair never measured.
        """
        n, P = self.n, len(self.scene.pairs)
        geo = self.geo
        out = np.full(P, -np.inf)
        k, s = np.nonzero(~np.isnan(self.exact[:n].T))  # by pair, then by sample
        if len(k):
            d = self.exact[s, k]
            u, rho = geo.joint_pair[k], geo.rho[k]
            C = self.path_shift[s, u] + rho * self.path_turn[s, u]
            C0 = self.path_shift[0, u] + rho * self.path_turn[0, u]
            Cn = self.path_shift[n - 1, u] + rho * self.path_turn[n - 1, u]
            new = np.concatenate([[True], k[1:] != k[:-1]])
            end = np.concatenate([k[1:] != k[:-1], [True]])
            val = np.where(new, d - (C - C0), np.inf)
            val = np.minimum(val, np.where(end, d - (Cn - C), np.inf))
            seg = np.full(len(k), np.inf)
            seg[:-1] = 0.5 * (d[:-1] + d[1:] - (C[1:] - C[:-1]))
            val = np.minimum(val, np.where(end, np.inf, seg))
            starts = np.flatnonzero(new)
            out[k[starts]] = np.minimum.reduceat(val, starts)
        g = np.flatnonzero(geo.ground)
        out[g] = self.ground_lower[:n, g].min(axis=0)
        return out

    def result(self) -> ScanResult:
        """Clearances of the samples scanned, and the hits (branch and bound per category).

        Each category's clearance is the exact minimum over the samples on the hulls: the
        samples whose bound is below the smallest measured distance are measured until none
        is (within :data:`CLEARANCE_TOLERANCE`).
        """
        scene = self.scene
        minima = self._column_minima() if self.n else None
        clearance = {}
        for ci, name in enumerate(CATEGORIES):
            cols = np.flatnonzero((scene.category == ci) & ~scene.grasp_pair)
            clearance[name] = (self._category_minimum(cols, minima) if len(cols) and self.n
                               else None)
        measured = int(np.count_nonzero(~np.isnan(self.exact[:self.n])))
        return ScanResult(clearance, {k: list(v) for k, v in self.hits.items()}, measured)

    def _placements(self, samples: np.ndarray, joints) -> tuple[np.ndarray, np.ndarray]:
        """``(R (m, j, 3, 3), p (m, j, 3))`` of some joints at some scanned samples."""
        joints = np.asarray(joints)
        if self._R is not None:
            return (self._R[samples[:, None], joints[None, :]],
                    self._p[samples[:, None], joints[None, :]])
        R, p = joint_placements(self.scene.model, self.configs[samples])
        return R[:, joints], p[:, joints]

    def _separation(self, k: int, normal: np.ndarray, s: int, samples: np.ndarray
                    ) -> np.ndarray | None:
        """Lower bounds [m] of pair ``k``'s hull distance at ``samples``, along one axis.

        The gap of the two hulls along ``normal`` (world, from the first body to the
        second, at sample ``s``) carried with the second body: ``min n·y - max n·x`` from
        their support functions, a lower bound of their distance at any placement
        (projection on a unit vector shortens distances). None if a body has none.
        """
        geo, scene = self.geo, self.scene
        a, b = (int(g) for g in scene.pairs[k])
        if geo.support(a, np.zeros((1, 3))) is None or geo.support(b, np.zeros((1, 3))) is None:
            return None
        R, p = self._placements(np.concatenate([[s], samples]), [geo.joint[a], geo.joint[b]])
        n_b = R[0, 1].T @ normal  # the axis in the second body's joint frame
        low_b = -float(geo.support(b, -n_b[None])[0])  # min n·y over the second body
        nw = R[1:, 1] @ n_b  # (m, 3) the axis at each sample, world
        u = np.einsum("mji,mj->mi", R[1:, 0], nw)  # in the first body's joint frame
        high_a = geo.support(a, u)
        return low_b + np.einsum("mi,mi->m", nw, p[1:, 1] - p[1:, 0]) - high_a

    def _category_minimum(self, cols: np.ndarray, minima: np.ndarray) -> float:
        """The smallest hull distance over the samples and the pairs ``cols`` [m].

        Branch and bound, pair by pair (the pair of the smallest bound first, only those
        whose bound (``minima``, :meth:`_column_minima`) is below the smallest distance
        measured, less :data:`CLEARANCE_TOLERANCE`): the sample of the pair's smallest
        bound (:meth:`column_bound`) below it is measured, and the measurement raises the
        pair's bounds at the other samples: ``d - |C(s') - C(s)|`` where that is above them,
        and the gap along the measured closest direction (:meth:`_separation`) at the
        samples still below; until none is below.
        """
        scene = self.scene
        model, data, hull, hd = scene.model, scene.data, scene.hull, scene.hull_data
        n = self.n
        sub = self.exact[:n, cols]
        best = float(np.nanmin(sub)) if np.any(~np.isnan(sub)) else np.inf
        self.visits = 0
        configs = self.configs
        for j in np.argsort(minima[cols], kind="stable"):
            k = int(cols[j])
            if minima[k] >= best - CLEARANCE_TOLERANCE:
                break  # and every later pair's bound is at least as large
            bound = self.column_bound(k)
            bound[~np.isnan(self.exact[:n, k])] = np.inf  # measured: not again
            if bound.min() >= best - CLEARANCE_TOLERANCE:
                continue
            C = None
            while True:
                below = np.flatnonzero(bound < best - CLEARANCE_TOLERANCE)
                if not len(below):
                    break
                s = int(below[np.argmin(bound[below])])
                if C is None:
                    C = self._column_path(k)
                pin.updateGeometryPlacements(model, data, hull, hd, configs[s])
                r = pin.computeDistance(hull, hd, k)
                d = r.min_distance
                self.visits += 1
                self.exact[s, k] = d
                best = min(best, d)
                bound[s] = np.inf
                reach = d - best + CLEARANCE_TOLERANCE  # where the path bound is of use
                lo = int(np.searchsorted(C, C[s] - reach, side="left"))
                hi = int(np.searchsorted(C, C[s] + reach, side="right"))
                np.maximum(bound[lo:hi], d - np.abs(C[lo:hi] - C[s]), out=bound[lo:hi])
                if d <= self.tol:
                    continue  # touching or penetrating: no separating axis
                rest = below[bound[below] < best - CLEARANCE_TOLERANCE]
                if len(rest):
                    axis = np.asarray(r.getNearestPoint2()) - np.asarray(r.getNearestPoint1())
                    norm = float(np.linalg.norm(axis))
                    gap = self._separation(k, axis / norm, s, rest) if norm > 0 else None
                    if gap is not None:
                        bound[rest] = np.fmax(bound[rest], gap)  # NaN: no bound
        return best


__all__ = ["ADVANCE_FRACTION", "ADVANCE_STRIDE", "CATEGORIES", "CLEARANCE_TOLERANCE",
           "JOINT_ZONE_RADIUS", "KEPT_PLACEMENTS", "PENETRATION_TOLERANCE", "RunScan", "ScanResult",
           "scan_geometry"]
