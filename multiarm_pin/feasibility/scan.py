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
penetration is checked on the meshes (:meth:`CollisionScene.mesh_penetration`), but for a pair
of two convex shapes, whose hull measurement is its hit (``convex_pair``); a carrying
link within the grasp zone of its arm's contact points is skipped at those samples (the
grasp, not a collision).

Clearances (:meth:`RunScan.result`): per category, branch and bound over each pair's samples,
from the bounds above (and the gap of the pair's bounding spheres); a measurement also bounds
its pair at the other samples by the gap of the two bodies along the measured closest axis,
carried with the second body (a separating-axis bound from their support functions), which
holds a pair at nearly constant distance (two links turning about each other) with a few
measurements.

The numeric work of a stretch (joint placements, path lengths, the searches for the next
sample due, the ground heights, the grasp zones, and the clearances' per-sample bounds and
support functions) runs in the ``nogil`` kernels of :mod:`multiarm_pin._compiled.scan`, so
that the scan's worker thread holds the interpreter only for coal's distances and the
bookkeeping between them; ``RunScan(..., compiled=False)`` runs the numpy references
instead (the same samples measured, the same report).

Twins: ``multiarm_pin._compiled.scan`` (the same concept, the collision scan along a run, at the
compiled layer: that module holds the ``nogil`` kernels; this one is their Python driver,
:class:`RunScan`, with the numpy references).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from multiarm_pin._compiled import scan as kernels
from multiarm_pin.feasibility.batch_kinematics import joint_placements, placement_plan

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
it (if that multiple is still ahead; else when due), so that pairs share their samples (one
placement update for all of them)."""

CLEARANCE_TOLERANCE = 1e-10
"""How far [m] above the exact minimum over the samples a reported clearance may be (a pair
whose bound is within it of the smallest distance found is not measured again)."""

KEPT_PLACEMENTS = 1_000_000
"""Largest samples x joints whose placements a scan keeps (96 bytes each)."""

BOUND_BLOCK = 262_144
"""Largest samples x pairs whose bounds a clearance's branch and bound computes at once."""

FIRST_BLOCK = 4096
"""Samples x pairs whose path lengths a search for the first sample beyond a bound compares
at once, before it searches the rest of the stretch."""

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
        self.plan = placement_plan(scene.model)
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
        self.boxed_ground = np.array(sorted(self.vertices), dtype=int)
        self.ground_columns = np.flatnonzero(self.ground)
        # each ground pair's column of a scan's ground bounds (RunScan.ground_lower), -1 else
        self.ground_slot = np.full(P, -1, dtype=np.int64)
        self.ground_slot[self.ground_columns] = np.arange(len(self.ground_columns))
        self.corners = (np.array([self.vertices[k] for k in self.boxed_ground])
                        if self.vertices else np.zeros((0, 8, 3)))
        # the same bodies' vertices, one array for the compiled ground heights
        boxed_vertices = [self.hull_vertices[int(pairs[k, 0])] for k in self.boxed_ground]
        self.boxed_starts = np.cumsum([0] + [len(v) for v in boxed_vertices]).astype(np.int64)
        self.boxed_vertices = (np.ascontiguousarray(np.concatenate(boxed_vertices))
                               if boxed_vertices else np.zeros((0, 3)))
        self.boxed_joints = self.joint[pairs[self.boxed_ground, 0]].astype(np.int64)
        # the round shapes' ground pairs, all at once: joint, shape placement, sizes, kind
        rk = [k for k in np.flatnonzero(self.ground) if int(k) not in self.vertices]
        rnd = [self.round[int(pairs[k, 0])] for k in rk]
        self.round_ground = np.array(rk, dtype=int)
        self.round_joints = self.joint[pairs[self.round_ground, 0]].astype(np.int64)
        self.round_R = np.array([r[0] for r in rnd]).reshape(-1, 3, 3)
        self.round_t = np.array([r[1] for r in rnd]).reshape(-1, 3)
        self.round_size = np.array([(r[2], r[3]) for r in rnd]).reshape(-1, 2)
        self.round_cylinder = np.array([r[4] == "Cylinder" for r in rnd], dtype=bool)

    def support(self, g: int, u: np.ndarray, compiled: bool = False) -> np.ndarray | None:
        """``max u·x`` over geometry ``g`` (x in its joint's frame) for directions u (m, 3).

        A polytope's vertices (``compiled``: by :func:`multiarm_pin._compiled.scan.support_max`);
        a sphere, cylinder (axis z of its frame) or capsule in closed form. None for another
        shape.
        """
        V = self.hull_vertices[g]
        if V is not None and compiled:
            out = np.empty(len(u))
            kernels.support_max(np.ascontiguousarray(u, dtype=float), V, out)
            return out
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


def _shared_sample(due: np.ndarray, after: int) -> np.ndarray:
    """The samples at which pairs due at samples ``due`` are measured.

    At the last multiple of :data:`ADVANCE_STRIDE` before each if that is later than
    ``after``, else when due.
    """
    shared = due // ADVANCE_STRIDE * ADVANCE_STRIDE
    return np.where(shared > after, shared, due)


def _unlogged(log: list[tuple[int, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """``(samples (K,), pairs (K,))`` of a log of ``(sample, pairs)`` (its order kept)."""
    if not log:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return (np.concatenate([np.full(len(ks), s) for s, ks in log]),
            np.concatenate([ks for _, ks in log]))


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
        compiled: the placements, path lengths, searches and ground heights of each stretch
            by the ``nogil`` kernels of :mod:`multiarm_pin._compiled.scan` (False: by their
            numpy references here; the placements stay numpy for a model the kernel does not
            handle, :func:`~.batch_kinematics.placement_plan`).

    Attributes:
        n: samples scanned so far.
        hits: per pair index, its collisions ``(sample, depth [m], point (3,))``.
    """

    def __init__(self, scene, capacity: int, compiled: bool = True):
        self.scene = scene
        self.compiled = bool(compiled)
        self.geo = scan_geometry(scene)
        self.tol = PENETRATION_TOLERANCE
        T, P, U = int(capacity), len(scene.pairs), len(self.geo.ua)
        self.T = T
        self.n = 0
        self.configs = np.zeros((T, scene.model.nq))
        self.path_shift = np.zeros((T, U))  # Σ |Δp| of each joint pair's relative placement
        self.path_turn = np.zeros((T, U))  # Σ ‖ΔR‖_2
        self.exact = np.full((T, P), np.nan)
        # the ground pairs' bounds (exact where measured), column geo.ground_slot[pair]
        self.ground_lower = np.full((T, len(self.geo.ground_columns)), -np.inf)
        self.ground_best = np.inf
        never = T  # a sample index no stretch reaches
        self.due = np.where(self.geo.ground, never, 0)
        self.pending = np.zeros(P, dtype=bool)  # its bound holds over every sample so far
        self.last = np.full(P, -1)
        self.budget = np.zeros(P)
        self.hits: dict[int, list] = {}
        # (sample, pair) -> (depth, point) of a convex pair's hull penetration: its hit
        # (:meth:`CollisionScene.mesh_penetration`), not measured again
        self._hull_hits: dict[tuple[int, int], tuple] = {}
        # the measurements of the pairs apart from the ground since the last
        # :meth:`_sum_measurements`, in sample order: (sample, pairs (K,)); and the
        # penetrating ones of the stretch under way, for :meth:`_check_hits`
        self._measured: list[tuple[int, np.ndarray]] = []
        self._penetrating: list[tuple[int, np.ndarray]] = []
        self._last_rel = None  # joints' (R (J, 3, 3), p (J, 3)) at sample n - 1
        J = scene.model.njoints
        # every joint's placement at every sample, for the clearances' separating-axis
        # bounds; recomputed where needed instead when a run is too long to keep them
        kept = T * J <= KEPT_PLACEMENTS
        self._R = np.empty((T, J, 3, 3)) if kept else None
        self._p = np.empty((T, J, 3)) if kept else None
        # the bodies' bounding-sphere centres (world) at every sample, for the same bounds
        G = len(self.geo.joint)
        self._centres = np.empty((T, G, 3)) if kept else None
        # each pair's measurements so far, summed up for the clearances' bounds
        # (:meth:`_column_minima`): its last one (distance, path length C), the smallest
        # bound of the segments between consecutive ones, the bound before its first one
        self._last_d = np.full(P, np.nan)
        self._last_C = np.zeros(P)
        self._segment_min = np.full(P, np.inf)
        self._before_first = np.full(P, np.inf)
        self._smallest = np.full(P, np.inf)  # its smallest distance measured
        self._summed = 0  # samples whose measurements are summed up

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
        R, p = joint_placements(scene.model, configs[n0:n1], self.geo.plan, self.compiled)
        geo = self.geo
        centres = p[:, geo.joint].copy()  # (m, G, 3) bounding spheres': sums of products
        Rg = R[:, geo.joint]
        for i in range(3):
            centres += Rg[..., i] * geo.centre[:, i, None]
        if self._R is not None:
            self._R[n0:n1], self._p[n0:n1] = R, p
            self._centres[n0:n1] = centres
        self._paths(R, p, n0, n1)
        opens = self._openings(centres, contact_points, n0, n1)
        self._ground(R, p, n0, n1)
        # pairs whose bound held to the last stretch's end: where does it fail in this one?
        waiting = np.flatnonzero(self.pending)
        if len(waiting):
            s2, found = self._first_exceeding(waiting, n0, n1)
            self.pending[waiting[found]] = False
            self.due[waiting[found]] = _shared_sample(s2[found], n0 - 1)
        live = (self.due >= n0) & (self.due < n1)
        self.due[live] = opens[self.due[live] - n0, np.flatnonzero(live)]
        self._advance(opens, n0, n1)
        self.n = n1
        self._sum_measurements()
        return self._check_hits(contact_points, n0, n1)

    def _paths(self, R, p, n0: int, n1: int) -> None:
        """:meth:`_block_paths` in blocks of :data:`PATH_BLOCK` samples (in cache).

        Compiled: :func:`multiarm_pin._compiled.scan.path_lengths` on the whole stretch.
        """
        if self.compiled:
            R, p = np.ascontiguousarray(R), np.ascontiguousarray(p)
            last_R, last_p = self._last_rel if self._last_rel is not None else (R[0], p[0])
            zero = np.zeros(len(self.geo.ua))
            kernels.path_lengths(R, p, np.ascontiguousarray(last_R), np.ascontiguousarray(last_p),
                                 self.geo.ua, self.geo.ub,
                                 self.path_shift[n0 - 1] if n0 else zero,
                                 self.path_turn[n0 - 1] if n0 else zero,
                                 self.path_shift[n0:n1], self.path_turn[n0:n1])
            self._last_rel = (R[-1].copy(), p[-1].copy())
            return
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
        Rj = np.ascontiguousarray(np.moveaxis(R, 0, -1))  # (J, 3, 3, m)
        Pj = np.ascontiguousarray(np.moveaxis(R_prev, 0, -1))
        # A[r, c] = Σ_k R[r, k] R_prev[c, k]: products summed, not 3x3 matrix products
        A = (Rj[:, :, None] * Pj[:, None]).sum(axis=3).reshape(-1, 9, m)  # (J, 9, m)
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

    def _first_exceeding(self, ks: np.ndarray, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
        """First sample in ``[lo, hi)`` where each pair's bound falls to its target.

        That is where ``C(s) - C(last) > budget``: ``C`` compared at every sample of a first
        block of samples, all pairs at once (most pairs due are due there), then a binary
        search (``C`` is non-decreasing) for the others.

        Returns:
            ``(samples (K,), found (K,) bool)``.
        """
        if lo >= hi:
            return np.full(len(ks), hi), np.zeros(len(ks), dtype=bool)
        geo = self.geo
        u, rho = geo.joint_pair[ks], geo.rho[ks]
        last = self.last[ks]
        thr = self.path_shift[last, u] + rho * self.path_turn[last, u] + self.budget[ks]
        if self.compiled:
            at = np.empty(len(ks), dtype=np.int64)
            kernels.first_exceeding(self.path_shift, self.path_turn, u, rho, thr, lo, hi, at)
            return at, at < hi
        b1 = min(hi, lo + max(8, FIRST_BLOCK // max(len(ks), 1)))
        over = (self.path_shift[lo:b1, u] + rho * self.path_turn[lo:b1, u] > thr)  # (b, K)
        hit = over.any(axis=0)
        at = np.where(hit, lo + over.argmax(axis=0), hi)
        todo = np.flatnonzero(~hit)
        if len(todo) and b1 < hi:
            U = self.path_shift.shape[1]
            shift, turn = self.path_shift.reshape(-1), self.path_turn.reshape(-1)
            ut, rt, tt = u[todo], rho[todo], thr[todo]
            a = np.full(len(todo), b1)
            b = np.full(len(todo), hi)
            for _ in range(max(1, int(hi - b1).bit_length())):
                mid = (a + b) >> 1
                flat = np.minimum(mid, hi - 1) * U + ut
                beyond = shift.take(flat) + rt * turn.take(flat) > tt
                b = np.where(beyond, mid, b)
                a = np.where(beyond | (a >= b), a, mid + 1)
            at[todo] = a
        return at, at < hi

    def _openings(self, centres, contact_points, n0: int, n1: int) -> np.ndarray:
        """(m + 1, P) from each sample of the stretch on, the first where a pair can collide.

        Run indices; ``n1``: none in the stretch. ``centres`` (m, G, 3): the bodies'
        bounding-sphere centres at the stretch's samples [m].

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
        grasp = np.flatnonzero(scene.grasp_pair)
        for arm in np.unique(scene.arm_of_pair[grasp]):  # each arm's carrying links at once
            ks = grasp[scene.arm_of_pair[grasp] == arm]
            cps = np.asarray(contact_points[arm]).reshape(m, -1, 3)
            if not cps.shape[1]:
                continue
            g = scene.pairs[ks, 0]
            if self.compiled:
                kernels.grasp_openings(np.ascontiguousarray(centres), g, geo.radius[g],
                                       np.ascontiguousarray(cps, dtype=float),
                                       JOINT_ZONE_RADIUS, n0, ks, opens)
                continue
            gap = cps[:, None] - centres[:, g, None]  # (m, K, N, 3)
            near = np.sqrt(np.einsum("mkni,mkni->mkn", gap, gap)).min(axis=2) + geo.radius[g]
            nxt = np.where(near <= JOINT_ZONE_RADIUS, n1, np.arange(n0, n1)[:, None])
            opens[:m, ks] = np.minimum.accumulate(nxt[::-1], axis=0)[::-1]
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
        low, slot = self.ground_lower[n0:n1], geo.ground_slot

        def lowest(k, rows):  # exact heights above the ground at rows of the stretch
            g = int(pairs[k, 0])
            j = joint[g]
            return p[rows, j, 2] - geo.support(g, -R[rows, j, 2, :]) - self.scene.ground

        every = np.arange(n1 - n0)
        if self.compiled and len(geo.round_ground):  # the round shapes, exactly
            R, p = np.ascontiguousarray(R), np.ascontiguousarray(p)
            self.ground_best = min(self.ground_best, kernels.round_heights(
                R, p, geo.round_joints, geo.round_R, geo.round_t, geo.round_size,
                geo.round_cylinder, self.scene.ground, n0, geo.round_ground,
                slot[geo.round_ground], self.ground_lower, self.exact))
        for k in ks if not self.compiled else ():
            if k not in geo.vertices:
                self.exact[n0:n1, k] = low[:, slot[k]] = lowest(k, every)
                self.ground_best = min(self.ground_best, float(low[:, slot[k]].min()))
        boxed = geo.boxed_ground  # the polytopes' pairs, all at once
        if len(boxed) and self.compiled:
            self.ground_best = kernels.ground_heights(
                np.ascontiguousarray(R), np.ascontiguousarray(p), geo.boxed_joints, geo.corners,
                geo.boxed_vertices, geo.boxed_starts, self.scene.ground, self.ground_best,
                self.tol, n0, boxed, slot[boxed], self.ground_lower, self.exact)
            return
        if len(boxed):
            j = joint[pairs[boxed, 0]]
            low[:, slot[boxed]] = self._lowest(geo.corners, R[:, j, 2, :], p[:, j, 2])
        lowest_bound = low[:, slot[boxed]].min(axis=0)
        for i in np.argsort(lowest_bound, kind="stable"):
            if lowest_bound[i] >= max(self.ground_best, self.tol):
                break  # and every later pair's bound is at least as large
            k = int(boxed[i])
            rows = np.flatnonzero(low[:, slot[k]] < max(self.ground_best, self.tol))
            if not len(rows):
                continue
            d = lowest(k, rows)
            self.exact[n0 + rows, k] = low[rows, slot[k]] = d
            self.ground_best = min(self.ground_best, float(d.min()))

    def _lowest(self, corners: np.ndarray, Rz: np.ndarray, pz: np.ndarray) -> np.ndarray:
        """(m, K) height above the ground [m] of the lowest of each body's ``corners``.

        ``corners`` (K, V, 3) in each body's joint frame; ``Rz`` (m, K, 3): the joints'
        third rotation rows; ``pz`` (m, K): their origins' heights. Sums of products, not a
        BLAS call (small operands).
        """
        z = (corners[None, :, :, 0] * Rz[:, :, None, 0] + corners[None, :, :, 1]
             * Rz[:, :, None, 1] + corners[None, :, :, 2] * Rz[:, :, None, 2])
        return z.min(axis=2) + pz - self.scene.ground

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
            d = np.array([pin.computeDistance(hull, hd, k).min_distance for k in ks.tolist()])
            self.exact[s, ks] = d
            self.last[ks] = s
            self._measured.append((s, ks))
            near = d < -tol  # penetrating: every sample (its hits)
            if near.any():
                self._penetrating.append((s, ks[near]))
            for j in np.flatnonzero(near & scene.convex_pair[ks]).tolist():  # its own hull
                k = int(ks[j])
                self._hull_hits[s, k] = (float(d[j]),
                                         np.array(hd.distanceResults[k].getNearestPoint1()))
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
            due[hit] = opens[_shared_sample(at, s) - n0, hit]  # pairs share samples

    def _check_hits(self, contact_points, n0: int, n1: int) -> int | None:
        """The hull penetrations of the stretch checked on the meshes; the first hit's sample."""
        scene = self.scene
        first = None
        g = self.geo.ground_columns  # the ground's pairs: from their heights (_ground)
        rows, cols = np.nonzero(self.exact[n0:n1, g] < -self.tol)
        pen, self._penetrating = self._penetrating, []  # the others: from _advance
        at, ks = _unlogged(pen)
        rows, cols = np.concatenate([rows, at - n0]), np.concatenate([g[cols], ks])
        order = np.lexsort((cols, rows))  # by sample, then by pair
        rows, cols = rows[order], cols[order]
        edges = np.flatnonzero(np.diff(rows)) + 1
        hits = []  # the meshes placed once per sample for all its pairs
        for a, b in zip([0, *edges.tolist()], [*edges.tolist(), len(rows)], strict=True):
            if a == b:
                continue
            i, ks = int(rows[a]), cols[a:b].tolist()
            own = [self._hull_hits.pop((n0 + i, k), None) for k in ks]
            mesh = [k for k, h in zip(ks, own, strict=True) if h is None]
            found = iter(scene.mesh_penetrations(self.configs[n0 + i], mesh) if mesh else ())
            hits += [(i, k, next(found) if h is None else h)
                     for k, h in zip(ks, own, strict=True)]
        for i, k, hit in hits:
            s = n0 + i
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
        measurements before and after (``d - |C(s') - C(s)|``), and the gap of the pair's
        bounding spheres; a ground pair's own.
        """
        return self.column_bounds(np.array([k]))[:, 0]

    def column_bounds(self, ks: np.ndarray) -> np.ndarray:
        """(n, K) :meth:`column_bound` of the pairs ``ks`` (K,), all at once [m]."""
        n, geo = self.n, self.geo
        ks = np.asarray(ks, dtype=int)
        if self.compiled:
            a, b = self.scene.pairs[ks, 0], self.scene.pairs[ks, 1]
            ground = geo.ground[ks]
            kept = self._centres is not None
            spheres = kept & ~ground & (geo.radius[a] != 0) & (geo.radius[b] != 0)
            out = np.empty((n, len(ks)))
            kernels.pair_bounds(self.exact, self.path_shift, self.path_turn, ks,
                                geo.joint_pair[ks], geo.rho[ks],
                                self._centres if kept else np.zeros((1, 1, 3)), a, b,
                                geo.radius[a], geo.radius[b], spheres, geo.ground_slot[ks],
                                self.ground_lower, out)
            return out
        d = self.exact[:n, ks]
        u, rho = geo.joint_pair[ks], geo.rho[ks]
        C = self.path_shift[:n, u] + rho * self.path_turn[:n, u]
        missing = np.isnan(d)
        ahead = np.maximum.accumulate(np.where(missing, -np.inf, d + C), axis=0) - C
        behind = np.maximum.accumulate(np.where(missing, -np.inf, d - C)[::-1],
                                       axis=0)[::-1] + C
        bound = np.maximum(ahead, behind)
        spheres = self._sphere_bounds(ks)
        if spheres is not None:
            bound = np.maximum(bound, spheres)
        bound = np.where(missing, bound, d)
        ground = geo.ground[ks]
        if ground.any():
            bound[:, ground] = self.ground_lower[:n, geo.ground_slot[ks[ground]]]
        return bound

    def _sphere_bounds(self, ks: np.ndarray) -> np.ndarray | None:
        """(n, K) the gap between pairs ``ks``' bounding spheres at every sample [m].

        A lower bound of the hulls' distance; ``-inf`` for a ground pair or a body without a
        sphere; None without the placements kept.
        """
        geo = self.geo
        if self._centres is None:
            return None
        a, b = self.scene.pairs[ks, 0], self.scene.pairs[ks, 1]
        gap = self._centres[:self.n, a] - self._centres[:self.n, b]  # (n, K, 3)
        out = np.sqrt(np.einsum("nki,nki->nk", gap, gap)) - geo.radius[a] - geo.radius[b]
        out[:, geo.ground[ks] | (geo.radius[a] == 0) | (geo.radius[b] == 0)] = -np.inf
        return out

    def _sum_measurements(self) -> None:
        """Sum up the measurements at the samples scanned since the last call (by pair).

        For :meth:`_column_minima`: between two consecutive measurements ``(d_a, C_a)``,
        ``(d_b, C_b)`` of a pair its bounds are at least ``(d_a + d_b - (C_b - C_a)) / 2``;
        before the first, ``d - (C - C(0))``.
        """
        n0, n = self._summed, self.n
        if n0 >= n:
            return
        geo = self.geo
        g = geo.ground_columns  # their smallest only: their bounds are ground_lower's
        if len(g):
            block = self.exact[n0:n, g]
            near = np.where(np.isnan(block), np.inf, block).min(axis=0)
            self._smallest[g] = np.minimum(self._smallest[g], near)
        log, self._measured = self._measured, []  # the others' (_advance's), by sample
        self._summed = n
        if not log:
            return
        s, k = _unlogged(log)
        by_pair = np.argsort(k, kind="stable")  # by pair, then by sample
        k, s = k[by_pair], s[by_pair]
        d = self.exact[s, k]
        u, rho = geo.joint_pair[k], geo.rho[k]
        C = self.path_shift[s, u] + rho * self.path_turn[s, u]
        new = np.concatenate([[True], k[1:] != k[:-1]])  # a pair's first here
        end = np.concatenate([k[1:] != k[:-1], [True]])  # its last here
        # each pair's previous measurement: the last before these, or the one before it here
        d_prev = np.where(new, self._last_d[k], np.concatenate([[np.nan], d[:-1]]))
        C_prev = np.where(new, self._last_C[k], np.concatenate([[0.0], C[:-1]]))
        seg = np.where(np.isnan(d_prev), np.inf, 0.5 * (d_prev + d - (C - C_prev)))
        starts = np.flatnonzero(new)
        ks = k[starts]
        self._segment_min[ks] = np.minimum(self._segment_min[ks],
                                           np.minimum.reduceat(seg, starts))
        self._smallest[ks] = np.minimum(self._smallest[ks], np.minimum.reduceat(d, starts))
        first = new & np.isnan(self._last_d[k])  # a pair's first measurement of the run
        C0 = self.path_shift[0, u] + rho * self.path_turn[0, u]
        self._before_first[k[first]] = (d - (C - C0))[first]
        self._last_d[k[end]], self._last_C[k[end]] = d[end], C[end]

    def _column_minima(self) -> np.ndarray:
        """(P,) lower bounds of each pair's smallest hull distance over the samples [m].

        From its measurements alone (:meth:`_sum_measurements`): the smallest bound between
        two consecutive ones, before the first (``d - (C - C(0))``) and after the last
        (``d - (C(end) - C)``). ``-inf`` for a pair never measured.
        """
        self._sum_measurements()
        n, geo = self.n, self.geo
        u, rho = geo.joint_pair, geo.rho
        Cn = self.path_shift[n - 1, u] + rho * self.path_turn[n - 1, u]
        after = self._last_d - (Cn - self._last_C)
        out = np.minimum(np.minimum(self._segment_min, self._before_first), after)
        out[np.isnan(self._last_d)] = -np.inf
        g = np.flatnonzero(geo.ground)
        out[g] = self.ground_lower[:n, geo.ground_slot[g]].min(axis=0)
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
        R, p = joint_placements(self.scene.model, self.configs[samples], self.geo.plan,
                                self.compiled)
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
        high_a = geo.support(a, u, self.compiled)
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
        best = float(self._smallest[cols].min())  # measured while scanning
        self.visits = 0
        configs = self.configs
        order = cols[np.argsort(minima[cols], kind="stable")]
        order = order[minima[order] < best - CLEARANCE_TOLERANCE]
        block = max(1, BOUND_BLOCK // max(n, 1))
        bounds, first = None, 0
        for j, k in enumerate(order.tolist()):
            if minima[k] >= best - CLEARANCE_TOLERANCE:
                break  # and every later pair's bound is at least as large
            if bounds is None or j - first >= bounds.shape[1]:
                # a pair's bounds change only where it is measured, which is below: the
                # bounds of the next pairs are computed together (one pass for a block)
                first = j
                ks = order[j:j + block]
                bounds = self.column_bounds(ks)
                bounds[~np.isnan(self.exact[:n, ks])] = np.inf  # measured: not again
                lowest = bounds.min(axis=0)
            if lowest[j - first] >= best - CLEARANCE_TOLERANCE:
                continue
            bound = bounds[:, j - first]
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


__all__ = ["ADVANCE_FRACTION", "ADVANCE_STRIDE", "BOUND_BLOCK", "CATEGORIES",
           "CLEARANCE_TOLERANCE", "FIRST_BLOCK", "JOINT_ZONE_RADIUS", "KEPT_PLACEMENTS",
           "PATH_BLOCK", "PENETRATION_TOLERANCE", "RunScan", "ScanResult",
           "scan_geometry"]
