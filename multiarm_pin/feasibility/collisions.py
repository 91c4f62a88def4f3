"""Collisions of a system's bodies: arms, object, supports and ground, with Pinocchio and coal.

:class:`CollisionScene` puts every body of a :class:`~multiarm_pin.system.MultiArmSystem` into
one Pinocchio model and one geometry model: each arm's collision geometry
(:mod:`multiarm_pin.feasibility.arm_geometry`, names prefixed ``<arm>/``), the object's convex
polyhedron on a free-flyer joint (so that a sample's configuration is ``[q; x_o; quat_o]``,
the quaternion ``[x, y, z, w]``), each support as a slab under its plane, and a ground
half-space ``z <= height``. Its pairs, each in one category:

- ``arm_self``: two links of one arm (the pairs of :class:`ArmGeometry.self_pairs`);
- ``arm_arm``: a link of one arm and a link of another;
- ``arm_object``: a link and the object. The links that carry the arm's grasp (on the tool's
  joint or after it) may touch the object at the grasp: a penetration of theirs whose point
  on the object lies within :data:`JOINT_ZONE_RADIUS` of one of the arm's contact points is
  the grasp itself, not a collision (and these pairs are left out of the clearance);
- ``arm_support``: a link and a support's slab;
- ``arm_ground``: a link and the ground. An arm whose base stands on the ground (base
  origin within :data:`MOUNT_TOLERANCE` of it, z axis up) rests its base links (the
  geometry fixed to the world) on it: those pairs are left out.

Distances are coal's (``pin.computeDistances``, signed: negative = penetration depth [m]) on
the convex hulls of the meshes, which are lower bounds of the meshes' distances. A pair
whose hull penetrates is checked again on the meshes themselves (coal BVH models); only a
mesh collision is a collision (its depth: :meth:`CollisionScene.mesh_penetration`).

Slabs: a support is an infinite plane in the dynamics; its slab is a box of thickness
:data:`SLAB_THICKNESS` under the plane, the rectangle that bounds the object's support points
at the scene's reference state (x axis: the world x axis projected on the plane), widened by
:data:`SLAB_MARGIN` on each side.
"""

from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from multiarm_pin.feasibility.arm_geometry import ArmGeometry, arm_collision_geometry
from multiarm_pin.feasibility.batch_kinematics import joint_placements

CATEGORIES = ("arm_self", "arm_arm", "arm_object", "arm_support", "arm_ground")
"""Pair categories, in the order of :attr:`CollisionScene.category` codes."""

JOINT_ZONE_RADIUS = 0.05
"""Radius [m] around each contact point of an arm's grasp inside which its carrying links
may touch or enter the object (the grasp, not a collision)."""

MOUNT_TOLERANCE = 0.01
"""Largest distance [m] between an arm's base origin and the ground for it to stand on it."""

SLAB_THICKNESS = 0.05
"""Thickness [m] of a support's slab (under its plane)."""

SLAB_MARGIN = 0.0
"""Margin [m] of a support's slab beyond the object's support points (none: a support is
where the object's support points rest, as a stand under some points of a face)."""

GJK_TOLERANCE = 1e-11
"""Tolerance of coal's GJK on the hulls' distances [m] (its default, 1e-6, leaves the
distance of two hulls uncertain by about 1e-7 m)."""

CLEARANCE_TOLERANCE = 1e-10
"""How far [m] above the exact minimum over the samples a reported clearance may be (a pair
whose bound is within it of the smallest distance found is not measured again)."""

ADVANCE_FRACTION = 0.5
"""A measured pair is measured again where its bound falls below this fraction of the distance
measured (:meth:`CollisionScene.scan`)."""

ADVANCE_WINDOW = 64
"""Samples ahead over which a measured pair's distance is bounded before it is measured again
(:meth:`CollisionScene.scan`)."""

ADVANCE_STRIDE = 16
"""A pair due at a later sample is measured at the last multiple of this many samples before
it, so that pairs share their samples (one placement update for all of them)."""

PENETRATION_TOLERANCE = 1e-6
"""Depth [m] beyond which a penetration counts (round-off of touching surfaces)."""


@dataclass(frozen=True)
class Collision:
    """One pair of bodies in collision at one state.

    Attributes:
        category: one of :data:`CATEGORIES`.
        arm: the (first) arm's name.
        link: its link's name.
        other: the other body (``"<arm>/<link>"``, ``"object"``, the support's name or
            ``"ground"``).
        distance: signed distance [m] (negative: penetration depth), on the meshes
            (:meth:`CollisionScene.mesh_penetration`).
        point: (3,) world point of the penetration [m].
    """

    category: str
    arm: str
    link: str
    other: str
    distance: float
    point: np.ndarray

    def describe(self) -> str:
        """One line: both bodies and the depth."""
        return (f"{self.arm}/{self.link} and {self.other} interpenetrate by "
                f"{-self.distance * 1e3:.3g} mm at {np.round(self.point, 4).tolist()} m")


@dataclass(frozen=True)
class ScanResult:
    """What :meth:`CollisionScene.scan` found along a run.

    Attributes:
        clearance: per category of :data:`CATEGORIES`, the smallest hull distance over the run
            [m] (grasp pairs left out), or None when the category has no pair.
        hits: per pair index, its collisions ``(sample, distance [m] on the meshes, point
            (3,) on the first body)`` in time order.
        measured: number of (sample, pair) distances computed exactly.
    """

    clearance: dict
    hits: dict
    measured: int


def _prefixed(model: pin.Model, geom: pin.GeometryModel, prefix: str):
    """Copies of a model and its geometry with every name (but the universe) prefixed."""
    out = pin.Model(model)
    for j in range(1, out.njoints):
        out.names[j] = prefix + out.names[j]
    for k in range(out.nframes):
        f = out.frames[k]
        if f.name != "universe":
            f.name = prefix + f.name
            out.frames[k] = f
    g = geom.copy()
    g.removeAllCollisionPairs()
    for k in range(g.ngeoms):
        o = g.geometryObjects[k]
        o.name = prefix + o.name
        g.geometryObjects[k] = o
    return out, g


def _object_convex(shape) -> coal.Convex:
    """The object's polyhedron as a coal convex (its vertices; coal takes their hull)."""
    pts = coal.StdVec_Vec3s()
    for p in np.asarray(shape.vertices, float):
        pts.append(p)
    return coal.Convex.convexHull(pts, False, "")


class CollisionScene:
    """Every body of a system in one Pinocchio geometry model (see the module docstring).

    Args:
        system: the :class:`~multiarm_pin.system.MultiArmSystem`.
        state: the reference state (the slabs are sized around the object's support points
            there); None: the object at the origin.
        ground: height [m] of the ground plane ``z = ground``, or None for no ground.

    Attributes:
        pairs: (P, 2) geometry indices of each checked pair (hull and mesh models alike).
        category: (P,) index into :data:`CATEGORIES`.
        arm_of_pair: (P,) index of the pair's (first) arm.
        grasp_pair: (P,) True for a carrying link against the object.
        names: name of each geometry object (``"<arm>/<link>"``, ``"object"``, ...).
    """

    def __init__(self, system, state=None, ground: float | None = 0.0):
        self.system = system
        self.ground = None if ground is None else float(ground)
        model = pin.Model()
        hull, mesh = pin.GeometryModel(), pin.GeometryModel()
        names, owner, link = [], [], []
        geoms: list[ArmGeometry] = []
        offsets = []
        for arm in system.arms:
            ag = arm_collision_geometry(arm)
            geoms.append(ag)
            m_h, g_h = _prefixed(ag.model, ag.hull, f"{arm.name}/")
            _, g_m = _prefixed(ag.model, ag.mesh, f"{arm.name}/")
            model_h, hull = pin.appendModel(model, m_h, hull, g_h, 0, pin.SE3.Identity())
            _, mesh = pin.appendModel(model, m_h, mesh, g_m, 0, pin.SE3.Identity())
            model = model_h
        # pin.appendModel may order the geometry objects its own way: find them by name
        for arm, ag in zip(system.arms, geoms, strict=True):
            ids = np.array([hull.getGeometryId(f"{arm.name}/{o.name}")
                            for o in ag.hull.geometryObjects], dtype=int)
            if not np.array_equal(ids, [mesh.getGeometryId(f"{arm.name}/{o.name}")
                                        for o in ag.hull.geometryObjects]):
                raise RuntimeError("hull and mesh geometry models ordered their objects "
                                   "differently")
            offsets.append(ids)
        names, owner, link = [""] * hull.ngeoms, [-1] * hull.ngeoms, [""] * hull.ngeoms
        for i, (arm, ag) in enumerate(zip(system.arms, geoms, strict=True)):
            for a, g in enumerate(offsets[i]):
                names[g], owner[g], link[g] = f"{arm.name}/{ag.names[a]}", i, ag.names[a]
        self.nq_arms = model.nq
        jid = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "object")
        fid = model.addFrame(pin.Frame("object", jid, 0, pin.SE3.Identity(),
                                       pin.FrameType.BODY))
        convex = _object_convex(system.obj.shape)
        self.object_index = hull.ngeoms
        for g in (hull, mesh):
            g.addGeometryObject(pin.GeometryObject("object", jid, fid, pin.SE3.Identity(),
                                                   convex))
        names.append("object")
        owner.append(-1)
        link.append("object")
        self.support_index = []
        for sp, (half, placement) in zip(system.supports.supports, self._slabs(state),
                                         strict=True):
            box = coal.Box(2 * half[0], 2 * half[1], SLAB_THICKNESS)
            self.support_index.append(hull.ngeoms)
            for g in (hull, mesh):
                g.addGeometryObject(pin.GeometryObject(sp.name, 0, 0, placement, box))
            names.append(sp.name)
            owner.append(-1)
            link.append(sp.name)
        self.ground_index = None
        if self.ground is not None:
            self.ground_index = hull.ngeoms
            half_space = coal.Halfspace(np.array([0.0, 0.0, 1.0]), self.ground)
            for g in (hull, mesh):
                g.addGeometryObject(pin.GeometryObject("ground", 0, 0, pin.SE3.Identity(),
                                                       half_space))
            names.append("ground")
            owner.append(-1)
            link.append("ground")
        for g in (hull, mesh):  # pin.appendModel pairs the geometry it appends: ours instead
            g.removeAllCollisionPairs()
        self.model, self.hull, self.mesh = model, hull, mesh
        self.names, self.owner, self.link = names, owner, link
        self.arm_geometry = geoms
        self._pairs(system, geoms, offsets)
        self.data = model.createData()
        self.hull_data = pin.GeometryData(hull)
        self.mesh_data = pin.GeometryData(mesh)
        for req in self.hull_data.distanceRequests:
            req.gjk_tolerance = GJK_TOLERANCE
        for req in self.mesh_data.collisionRequests:  # triangle contacts: depth and point
            req.enable_contact = True
            req.num_max_contacts = 64

    # ------------------------------------------------------------------ construction
    def _slabs(self, state) -> list[tuple[np.ndarray, pin.SE3]]:
        """Half sides (2,) [m] and placement of each support's slab (module docstring)."""
        out = []
        pos = np.zeros(3) if state is None else np.asarray(state.obj.position)
        R_o = np.eye(3) if state is None else state.obj.rotation
        for sp in self.system.supports.supports:
            n = np.asarray(sp.normal, float)
            x = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
            x = np.cross(x, n)
            x /= np.linalg.norm(x)
            R = np.column_stack([x, np.cross(n, x), n])
            pts = pos + np.asarray(sp.points) @ R_o.T
            uv = (pts - sp.point) @ R[:, :2]
            lo, hi = uv.min(axis=0), uv.max(axis=0)
            centre = sp.point + R[:, :2] @ (0.5 * (lo + hi))
            half = 0.5 * (hi - lo) + SLAB_MARGIN
            out.append((half, pin.SE3(R, centre - 0.5 * SLAB_THICKNESS * n)))
        return out

    def _pairs(self, system, geoms: list[ArmGeometry], offsets: list[int]) -> None:
        pairs, cat, arm_of, grasp = [], [], [], []

        def add(a, b, c, i, g=False):
            pairs.append((a, b))
            cat.append(CATEGORIES.index(c))
            arm_of.append(i)
            grasp.append(g)

        mounted = [self._stands_on_ground(arm) for arm in system.arms]
        for i, (ag, off) in enumerate(zip(geoms, offsets, strict=True)):
            for a, b in ag.self_pairs:
                add(int(off[a]), int(off[b]), "arm_self", i)
            for j in range(i + 1, len(geoms)):
                for a in range(len(ag.names)):
                    for b in range(len(geoms[j].names)):
                        add(int(off[a]), int(offsets[j][b]), "arm_arm", i)
            joints = [g.parentJoint for g in ag.hull.geometryObjects]
            for a in range(len(ag.names)):
                add(int(off[a]), self.object_index, "arm_object", i, a in ag.carrier)
                for s in self.support_index:
                    add(int(off[a]), s, "arm_support", i)
                if self.ground_index is not None and not (mounted[i] and joints[a] == 0):
                    add(int(off[a]), self.ground_index, "arm_ground", i)
        meta = {}
        for (a, b), c, i, g in zip(pairs, cat, arm_of, grasp, strict=True):
            meta[(min(a, b), max(a, b))] = (c, i, g)
            self.hull.addCollisionPair(pin.CollisionPair(a, b))
            self.mesh.addCollisionPair(pin.CollisionPair(a, b))
        # the geometry model keeps its pairs in its own order: read them back
        order = [(min(int(cp.first), int(cp.second)), max(int(cp.first), int(cp.second)))
                 for cp in self.hull.collisionPairs]
        if [(int(cp.first), int(cp.second)) for cp in self.hull.collisionPairs] != \
                [(int(cp.first), int(cp.second)) for cp in self.mesh.collisionPairs]:
            raise RuntimeError("hull and mesh geometry models ordered their pairs differently")
        self.pairs = np.array([(int(cp.first), int(cp.second))
                               for cp in self.hull.collisionPairs], dtype=int).reshape(-1, 2)
        self.category = np.array([meta[o][0] for o in order], dtype=int)
        self.arm_of_pair = np.array([meta[o][1] for o in order], dtype=int)
        self.grasp_pair = np.array([meta[o][2] for o in order], dtype=bool)

    def _stands_on_ground(self, arm) -> bool:
        """True if the arm's base origin is on the ground with its z axis up."""
        if self.ground is None:
            return False
        b = arm.base_placement
        return (abs(float(b.translation[2]) - self.ground) <= MOUNT_TOLERANCE
                and float(b.rotation[2, 2]) > 1.0 - 1e-6)

    # ------------------------------------------------------------------ queries
    def configuration(self, q: np.ndarray, position: np.ndarray,
                      quaternion: np.ndarray) -> np.ndarray:
        """The scene model's configuration ``[q; x_o; quat_o]`` (nq + 7,)."""
        return np.concatenate([q, position, quaternion])

    def hull_distances(self, q_scene: np.ndarray) -> np.ndarray:
        """(P,) signed distances [m] of every pair on the hulls at a configuration."""
        pin.computeDistances(self.model, self.data, self.hull, self.hull_data, q_scene)
        return np.array([r.min_distance for r in self.hull_data.distanceResults])

    def mesh_distance(self, q_scene: np.ndarray, k: int) -> tuple[float, np.ndarray,
                                                                   np.ndarray]:
        """Signed distance [m] of pair ``k`` on the meshes, and its two nearest points (3,).

        The placements are those of the last :meth:`hull_distances` call when ``q_scene``
        is the same; they are recomputed here anyway (one pair: cheap).
        """
        pin.updateGeometryPlacements(self.model, self.data, self.mesh, self.mesh_data, q_scene)
        r = pin.computeDistance(self.mesh, self.mesh_data, int(k))
        return float(r.min_distance), np.array(r.getNearestPoint1()), \
            np.array(r.getNearestPoint2())

    def mesh_penetration(self, q_scene: np.ndarray, k: int):
        """Pair ``k`` on the meshes: None if apart, else ``(depth, point on the first body)``.

        ``depth`` [m] is negative: coal's signed distance where it gives one (a mesh against
        a convex shape), else the deepest of the triangle contacts' penetration depths (two
        meshes, whose distance coal reports as 0 once they overlap).
        """
        pin.updateGeometryPlacements(self.model, self.data, self.mesh, self.mesh_data, q_scene)
        if not pin.computeCollision(self.mesh, self.mesh_data, int(k)):
            return None
        res = self.mesh_data.collisionResults[int(k)]
        contacts = [res.getContact(i) for i in range(res.numContacts())]
        r = pin.computeDistance(self.mesh, self.mesh_data, int(k))
        depth, point = float(r.min_distance), np.array(r.getNearestPoint1())
        if contacts:
            c = min(contacts, key=lambda c: c.penetration_depth)
            if c.penetration_depth < depth:
                depth, point = float(c.penetration_depth), np.array(c.pos)
        if depth >= -PENETRATION_TOLERANCE:
            return None
        return depth, point

    def hull_points(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The nearest points (3,) of pair ``k`` on the hulls, from the last distances."""
        r = self.hull_data.distanceResults[int(k)]
        return np.array(r.getNearestPoint1()), np.array(r.getNearestPoint2())

    def pair_names(self, k: int) -> tuple[str, str, str]:
        """``(arm, link, other body)`` of pair ``k``."""
        a, b = self.pairs[k]
        arm = self.system.arms[self.owner[a]].name
        return arm, self.link[a], self.names[b]

    def collisions(self, q_scene: np.ndarray, contact_points: list[np.ndarray] | None = None,
                   distances: np.ndarray | None = None) -> list[Collision]:
        """The pairs in collision at a configuration (on the meshes; grasps excepted).

        Args:
            q_scene: (nq + 7,) from :meth:`configuration`.
            contact_points: per arm, (N_i, 3) its grasp's contact points in the world [m]
                (None: no grasp exception, every carrying link's penetration counts).
            distances: the hull distances at ``q_scene`` if already computed.
        """
        d = self.hull_distances(q_scene) if distances is None else distances
        out = []
        for k in np.flatnonzero(d < -PENETRATION_TOLERANCE):
            hit = self.mesh_penetration(q_scene, k)
            if hit is None:
                continue
            if self.grasp_pair[k] and contact_points is not None and self._at_grasp(
                    k, hit[1], contact_points):
                continue
            arm, link, other = self.pair_names(k)
            out.append(Collision(CATEGORIES[self.category[k]], arm, link, other, hit[0],
                                 hit[1]))
        return out

    # ------------------------------------------------------------------ along a run
    def _spheres(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Bounding sphere of every geometry.

        Returns:
            centres (G, 3) in the frame of the geometry's joint [m], radii (G,) [m], and
            whether each moves (G,) bool (on a joint, not the world).
        """
        G = self.hull.ngeoms
        c, r, moving = np.zeros((G, 3)), np.zeros(G), np.zeros(G, dtype=bool)
        for g in range(G):
            o = self.hull.geometryObjects[g]
            moving[g] = o.parentJoint != 0
            if g == self.ground_index:
                continue
            shape = o.geometry
            shape.computeLocalAABB()
            c[g] = o.placement.act(np.array(shape.aabb_center))
            r[g] = float(shape.aabb_radius)
        return c, r, moving

    def scan(self, q: np.ndarray, object_position: np.ndarray, object_quaternion: np.ndarray,
             contact_points: list[np.ndarray] | None = None) -> ScanResult:
        """Collisions and clearances at every sample of a run.

        Each pair is measured on the hulls where it may come closer and bounded from below
        elsewhere (:meth:`_advance`, conservative advancement); a pair whose hulls penetrate
        is measured on the meshes. Each category's clearance is then the exact minimum over
        the samples, on the hulls: the samples whose bound is below the smallest measured
        distance are measured until none is (:meth:`_category_minimum`).

        Args:
            q: (T, nq) arms' configurations.
            object_position: (T, 3) [m].
            object_quaternion: (T, 4) ``[x, y, z, w]``.
            contact_points: per arm, (T, N_i, 3) its grasp's contact points [m] (None: no
                grasp exception).

        Returns:
            :class:`ScanResult`.
        """
        T = len(q)
        P = len(self.pairs)
        c_local, radius, _ = self._spheres()
        G = len(radius)
        configs = np.concatenate([q, object_position, object_quaternion], axis=1)
        R, p = joint_placements(self.model, configs)
        joint = np.array([o.parentJoint for o in self.hull.geometryObjects], dtype=int)
        in_joint = c_local.reshape(G, 3)  # _spheres gives the centres in the joints' frames
        reach = np.linalg.norm(in_joint, axis=1) + radius  # any point's distance to its joint
        exact = np.full((T, P), np.nan)
        skip, ground = self._ground_distances(R, p, joint, exact)
        opens = self._grasp_openings(R, p, joint, in_joint, radius, contact_points, T)
        lower = self._advance(configs, R, p, joint, reach, exact, skip, ground, opens)
        clearance = {}
        for ci, name in enumerate(CATEGORIES):
            cols = np.flatnonzero((self.category == ci) & ~self.grasp_pair)
            if not len(cols):
                clearance[name] = None
                continue
            clearance[name] = self._category_minimum(configs, exact, lower, cols)
        hits: dict[int, list] = {}
        for s, k in zip(*np.nonzero(exact < -PENETRATION_TOLERANCE), strict=True):
            hit = self.mesh_penetration(configs[s], k)
            if hit is None:
                continue
            if self.grasp_pair[k] and contact_points is not None:
                cps = [np.asarray(c)[s] for c in contact_points]
                if self._at_grasp(k, hit[1], cps):
                    continue
            hits.setdefault(int(k), []).append((int(s), hit[0], hit[1]))
        return ScanResult(clearance, hits, int(np.count_nonzero(~np.isnan(exact))))

    def _ground_distances(self, R, p, joint, exact) -> tuple[np.ndarray, np.ndarray]:
        """The ground pairs' distances from the hulls' vertices, where they matter.

        The distance of a convex hull (or a box) to the half-space ``z <= h`` is its lowest
        vertex's height above ``h``; the lowest corner of the hull's bounding box (in its
        joint frame) bounds it from below. The bound of every pair comes first; the exact
        distance (into ``exact``) only where the bound is below the smallest exact distance
        found (or below the penetration tolerance), the pair of the lowest bound first.

        Returns:
            ``(done (P,) bool, lower (T, P))``: the ground pairs handled here and their
            lower bounds (the exact distance where computed).
        """
        T, P = exact.shape
        done = np.zeros(P, dtype=bool)
        lower = np.full((T, P), -np.inf)
        if self.ground_index is None:
            return done, lower
        points = {}
        for k in np.flatnonzero(self.pairs[:, 1] == self.ground_index):
            g = int(self.pairs[k, 0])
            o = self.hull.geometryObjects[g]
            shape = o.geometry
            if hasattr(shape, "points"):
                pts = np.asarray(shape.points(), float)
            elif hasattr(shape, "halfSide"):
                h = np.array(shape.halfSide)
                pts = np.array([[x, y, z] for x in (-h[0], h[0]) for y in (-h[1], h[1])
                                for z in (-h[2], h[2])])
            else:
                continue
            local = pts @ o.placement.rotation.T + o.placement.translation
            lo, hi = local.min(axis=0), local.max(axis=0)
            corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                for z in (lo[2], hi[2])])
            points[k] = local
            lower[:, k] = self._lowest(corners, R[:, joint[g], 2, :], p[:, joint[g], 2])
            done[k] = True
        best = np.inf
        for k in sorted(points, key=lambda k: float(lower[:, k].min())):
            rows = np.flatnonzero(lower[:, k] < max(best, PENETRATION_TOLERANCE))
            if not len(rows):
                continue
            g = int(self.pairs[k, 0])
            d = self._lowest(points[k], R[rows, joint[g], 2, :], p[rows, joint[g], 2])
            exact[rows, k] = lower[rows, k] = d
            best = min(best, float(d.min()))
        return done, lower

    def _lowest(self, local: np.ndarray, Rz: np.ndarray, pz: np.ndarray) -> np.ndarray:
        """(T,) height above the ground [m] of the lowest of ``local`` (V, 3) points.

        ``Rz`` (T, 3): the joint's third rotation row; ``pz`` (T,): its origin's height.
        Sums of products, not a BLAS call (small operands).
        """
        z = (local[:, 0, None] * Rz[None, :, 0] + local[:, 1, None] * Rz[None, :, 1]
             + local[:, 2, None] * Rz[None, :, 2])
        return z.min(axis=0) + pz - self.ground

    def _grasp_openings(self, R, p, joint, in_joint, radius, contact_points, T):
        """(T + 1, P) the first sample from each sample on where a pair can collide.

        A carrying link whose bounding sphere lies, at a sample, within
        :data:`JOINT_ZONE_RADIUS` of one of its arm's contact points touches the object
        (if at all) at the grasp: no collision there, and it is left out of the
        clearances; such samples are skipped (a fingertip on its face, every sample).
        Every other pair may collide at every sample (its own index).
        """
        P = len(self.pairs)
        opens = np.broadcast_to(np.arange(T + 1)[:, None], (T + 1, P)).copy()
        if contact_points is None:
            return opens
        for k in np.flatnonzero(self.grasp_pair):
            g = int(self.pairs[k, 0])
            cps = np.asarray(contact_points[self.arm_of_pair[k]]).reshape(T, -1, 3)
            if not cps.shape[1]:
                continue
            c = np.einsum("tij,j->ti", R[:, joint[g]], in_joint[g]) + p[:, joint[g]]
            near = np.min(np.linalg.norm(cps - c[:, None], axis=2), axis=1) + radius[g]
            inside = near <= JOINT_ZONE_RADIUS
            nxt = np.where(inside, T, np.arange(T))
            opens[:T, k] = np.minimum.accumulate(nxt[::-1])[::-1]
        return opens

    def _advance(self, configs, R, p, joint, reach, exact, skip, bounds,
                 opens) -> np.ndarray:
        """Measure every pair at the samples where it may come closer; bound it elsewhere.

        Conservative advancement at sample resolution: after measuring pair ``(a, b)`` at
        sample ``s`` (distance ``d``), its distance at a later sample ``s'`` is at least
        ``d - (|Δp| + ‖ΔR‖_F ρ_a)``, where ``Δp``, ``ΔR`` are the change of ``a``'s joint
        placement seen from ``b``'s joint between ``s`` and ``s'`` and ``ρ_a`` bounds the
        distance of ``a``'s points to its joint (any point of ``a`` moves relative to ``b``
        by at most that much). The pair is measured again at the first sample of the next
        :data:`ADVANCE_WINDOW` where that bound falls to :data:`ADVANCE_FRACTION` of ``d``
        (to ``-PENETRATION_TOLERANCE`` for a grasp pair or a touching one: they matter only
        once they may penetrate; at the next sample while it penetrates).

        Args:
            configs: (T, nq + 7) the scene's configurations.
            R: (T, njoints, 3, 3) joint axes -> world axes.
            p: (T, njoints, 3) joint origins [m].
            joint: (G,) each geometry's joint.
            reach: (G,) ``ρ`` [m].
            exact: (T, P) filled with the measured hull distances (NaN elsewhere).
            skip: (P,) pairs already handled (bounded at every sample, measured where needed).
            bounds: (T, P) their lower bounds.
            opens: (T + 1, P) from :meth:`_grasp_openings` (samples a pair skips).

        Returns:
            (T, P) lower bounds of the distances [m] (the measured value where measured).
        """
        T, P = exact.shape
        lower = np.full((T, P), -np.inf)
        ja, jb = joint[self.pairs[:, 0]], joint[self.pairs[:, 1]]
        rho = reach[self.pairs[:, 0]]
        due = np.where(skip, T, opens[0])
        lower[:, skip] = bounds[:, skip]
        model, data, hull, hd = self.model, self.data, self.hull, self.hull_data
        W = ADVANCE_WINDOW
        self.visits = 0
        while True:
            s = int(due.min())
            if s >= T:
                break
            ks = np.flatnonzero(due == s)
            self.visits += 1
            pin.updateGeometryPlacements(model, data, hull, hd, configs[s])
            d = np.array([pin.computeDistance(hull, hd, int(k)).min_distance for k in ks])
            exact[s, ks] = d
            lower[s, ks] = d
            near = d < -PENETRATION_TOLERANCE  # penetrating: every sample (its hits)
            due[ks[near]] = opens[s + 1, ks[near]]
            far, dfar = ks[~near], d[~near]
            end = min(T, s + 1 + W)
            if not len(far) or end <= s + 1:
                due[far] = opens[s + 1, far]
                continue
            # a's joint seen from b's joint at s .. end - 1, once per pair of joints
            key = ja[far] * R.shape[1] + jb[far]
            uniq, inv = np.unique(key, return_inverse=True)
            ua, ub = uniq // R.shape[1], uniq % R.shape[1]
            Rw, pw = R[s:end], p[s:end]
            Rbt = np.swapaxes(Rw[:, ub], -1, -2)
            rel_R = Rbt @ Rw[:, ua]
            rel_p = (Rbt @ (pw[:, ua] - pw[:, ub])[..., None])[..., 0]
            dR, dp = rel_R[1:] - rel_R[0], rel_p[1:] - rel_p[0]
            shift = np.sqrt(np.einsum("tki,tki->tk", dp, dp))[:, inv]
            turn = np.sqrt(np.einsum("tkij,tkij->tk", dR, dR))[:, inv]
            move = shift + turn * rho[far]
            bound = dfar - move  # (window, k)
            lower[s + 1:end, far] = np.maximum(lower[s + 1:end, far], bound)
            # grasp pairs and touching pairs matter only once they may penetrate
            target = np.where(self.grasp_pair[far] | (dfar <= PENETRATION_TOLERANCE),
                              -PENETRATION_TOLERANCE, ADVANCE_FRACTION * dfar)
            weak = bound <= target
            first = np.where(weak.any(axis=0), weak.argmax(axis=0), end - s - 1)
            # measured earlier than needed at a multiple of ADVANCE_STRIDE: pairs share samples
            due[far] = opens[np.maximum(s + 1, (s + 1 + first) // ADVANCE_STRIDE
                                        * ADVANCE_STRIDE), far]
        return lower

    def _category_minimum(self, configs, exact, lower, cols) -> float:
        """The smallest hull distance over samples and the pairs ``cols`` (branch and bound).

        Samples in increasing order of their smallest bound; at each, the pairs whose bound
        is below the smallest distance measured so far (less :data:`CLEARANCE_TOLERANCE`)
        are measured; it stops at the first sample whose smallest bound is not below it. The
        result is within :data:`CLEARANCE_TOLERANCE` above the exact minimum.
        """
        model, data, hull, hd = self.model, self.data, self.hull, self.hull_data
        sub = exact[:, cols]
        best = float(np.nanmin(sub)) if np.any(~np.isnan(sub)) else np.inf
        lb = np.where(np.isnan(sub), lower[:, cols], np.inf)
        row = lb.min(axis=1)
        for s in np.argsort(row, kind="stable"):
            if row[s] >= best - CLEARANCE_TOLERANCE:
                break
            pin.updateGeometryPlacements(model, data, hull, hd, configs[s])
            for j in np.flatnonzero(lb[s] < best - CLEARANCE_TOLERANCE):
                k = int(cols[j])
                exact[s, k] = pin.computeDistance(hull, hd, k).min_distance
                best = min(best, float(exact[s, k]))
        return best

    def _at_grasp(self, k: int, point_on_object: np.ndarray, contact_points) -> bool:
        pts = np.asarray(contact_points[self.arm_of_pair[k]]).reshape(-1, 3)
        if not len(pts):
            return False
        return float(np.min(np.linalg.norm(pts - point_on_object, axis=1))) <= JOINT_ZONE_RADIUS


__all__ = [
    "CATEGORIES",
    "CLEARANCE_TOLERANCE",
    "JOINT_ZONE_RADIUS",
    "MOUNT_TOLERANCE",
    "PENETRATION_TOLERANCE",
    "SLAB_MARGIN",
    "SLAB_THICKNESS",
    "Collision",
    "CollisionScene",
    "ScanResult",
]
