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
mesh collision is a collision (its depth: :meth:`CollisionScene.mesh_penetration`). A pair of
two of coal's convex shapes (:data:`CONVEX_SHAPES`: primitives of a URDF, the object, slabs,
the ground) is its own hull: its hull penetration is the collision.

Slabs: a support's slab is a box of thickness :data:`SLAB_THICKNESS` under its plane, its
sides along the support's axes (``x_axis``, ``n × x_axis``: the frame the dynamics measures
a finite support's ``extent`` in, :class:`~multiarm_pin.constraints.supports.Support`). A
finite support (an ``extent``) is exactly its rectangle about its ``point``: the whole table
top, so a link over the table beside the object collides with it. An infinite plane (no
``extent``) is the rectangle that bounds the object's support points at the scene's
reference state, widened by :data:`SLAB_MARGIN` on each side (a stand under those points).
"""

from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from multiarm_pin.feasibility.arm_geometry import ArmGeometry, arm_collision_geometry
from multiarm_pin.feasibility.scan import (
    CATEGORIES,
    CLEARANCE_TOLERANCE,
    JOINT_ZONE_RADIUS,
    PENETRATION_TOLERANCE,
    RunScan,
    ScanResult,
)

CONVEX_SHAPES = (coal.Box, coal.Sphere, coal.Capsule, coal.Cone, coal.Cylinder, coal.Ellipsoid,
                 coal.ConvexBase, coal.Halfspace)
"""coal's solid convex shapes: a pair of two of them is its own hull (its penetration is
measured once, :meth:`CollisionScene.mesh_penetration`)."""

MOUNT_TOLERANCE = 0.01
"""Largest distance [m] between an arm's base origin and the ground for it to stand on it."""

SLAB_THICKNESS = 0.05
"""Thickness [m] of a support's slab (under its plane)."""

SLAB_MARGIN = 0.0
"""Margin [m] of an infinite support's slab beyond the object's support points (none: such a
support is where the object's support points rest, as a stand under some points of a face;
a finite support's slab is its ``extent``)."""

GJK_TOLERANCE = 1e-11
"""Tolerance of coal's GJK on the hulls' distances [m] (its default, 1e-6, leaves the
distance of two hulls uncertain by about 1e-7 m)."""


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
        state: the reference state (the slabs of infinite supports are sized around the
            object's support points there); None: the object at the origin.
        ground: height [m] of the ground plane ``z = ground``, or None for no ground.

    Attributes:
        pairs: (P, 2) geometry indices of each checked pair (hull and mesh models alike).
        category: (P,) index into :data:`CATEGORIES`.
        arm_of_pair: (P,) index of the pair's (first) arm.
        grasp_pair: (P,) True for a carrying link against the object.
        convex_pair: (P,) True for two bodies of :data:`CONVEX_SHAPES` (no mesh): a pair
            that is its own hull.
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
        for k in np.flatnonzero(self.convex_pair):  # measured as on the hulls
            self.mesh_data.distanceRequests[int(k)].gjk_tolerance = GJK_TOLERANCE

    # ------------------------------------------------------------------ construction
    def _slabs(self, state) -> list[tuple[np.ndarray, pin.SE3]]:
        """Half sides (2,) [m] and placement of each support's slab (module docstring).

        The slab's axes are the support's own (``x_axis``, ``y_axis = n × x_axis``, ``n``:
        :class:`~multiarm_pin.constraints.supports.Support`, the frame the dynamics measures
        its ``extent`` in); its top face is the support's plane.
        """
        out = []
        pos = np.zeros(3) if state is None else np.asarray(state.obj.position)
        R_o = np.eye(3) if state is None else state.obj.rotation
        for sp in self.system.supports.supports:
            n = np.asarray(sp.normal, float)
            R = np.column_stack([sp.x_axis, sp.y_axis, n])
            if sp.finite:  # the table top itself: its rectangle about its point
                centre, half = np.asarray(sp.point, float), 0.5 * np.asarray(sp.extent)
            else:  # an infinite plane: the rectangle under the object's support points
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
        # two convex bodies (no mesh, no height field among them): the pair is its own hull
        convex = [isinstance(o.geometry, CONVEX_SHAPES) for o in self.mesh.geometryObjects]
        self.convex_pair = np.array([convex[a] and convex[b] for a, b in self.pairs],
                                    dtype=bool)

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
        meshes, whose distance coal reports as 0 once they overlap). A pair of two convex
        bodies (:attr:`convex_pair`: primitives, the object, slabs, the ground) is its own
        hull: its signed distance and nearest point on the first body, as on the hulls (the
        same shapes and distance request).
        """
        return self.mesh_penetrations(q_scene, [k])[0]

    def mesh_penetrations(self, q_scene: np.ndarray, ks) -> list:
        """:meth:`mesh_penetration` of the pairs ``ks`` at one configuration (placed once)."""
        pin.updateGeometryPlacements(self.model, self.data, self.mesh, self.mesh_data, q_scene)
        return [self._placed_mesh_penetration(int(k)) for k in ks]

    def _placed_mesh_penetration(self, k: int):
        """:meth:`mesh_penetration` with the meshes already placed."""
        if self.convex_pair[k]:
            r = pin.computeDistance(self.mesh, self.mesh_data, int(k))
            depth = float(r.min_distance)
            if depth >= -PENETRATION_TOLERANCE:
                return None
            return depth, np.array(r.getNearestPoint1())
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
            if self.grasp_pair[k] and contact_points is not None and self.at_grasp(
                    k, hit[1], contact_points):
                continue
            arm, link, other = self.pair_names(k)
            out.append(Collision(CATEGORIES[self.category[k]], arm, link, other, hit[0],
                                 hit[1]))
        return out

    # ------------------------------------------------------------------ along a run
    def scan(self, q: np.ndarray, object_position: np.ndarray, object_quaternion: np.ndarray,
             contact_points: list[np.ndarray] | None = None) -> ScanResult:
        """Collisions and clearances at every sample of a run (:class:`~.scan.RunScan`).

        Each pair is measured on the hulls where it may come closer and bounded from below
        elsewhere (conservative advancement along the path); a pair whose hulls penetrate
        is measured on the meshes. Each category's clearance is the exact minimum over the
        samples, on the hulls.

        Args:
            q: (T, nq) arms' configurations.
            object_position: (T, 3) [m].
            object_quaternion: (T, 4) ``[x, y, z, w]``.
            contact_points: per arm, (T, N_i, 3) its grasp's contact points [m] (None: no
                grasp exception).

        Returns:
            :class:`ScanResult`.
        """
        run = RunScan(self, len(q))
        run.extend(q, object_position, object_quaternion, contact_points)
        return run.result()

    def at_grasp(self, k: int, point_on_object: np.ndarray, contact_points) -> bool:
        """True if a point of pair ``k`` on the object lies in its arm's grasp zone.

        ``contact_points``: per arm, (N_i, 3) its contact points in the world [m].
        """
        pts = np.asarray(contact_points[self.arm_of_pair[k]]).reshape(-1, 3)
        if not len(pts):
            return False
        return float(np.min(np.linalg.norm(pts - point_on_object, axis=1))) <= JOINT_ZONE_RADIUS


__all__ = [
    "CATEGORIES",
    "CLEARANCE_TOLERANCE",
    "CONVEX_SHAPES",
    "JOINT_ZONE_RADIUS",
    "MOUNT_TOLERANCE",
    "PENETRATION_TOLERANCE",
    "SLAB_MARGIN",
    "SLAB_THICKNESS",
    "Collision",
    "CollisionScene",
    "ScanResult",
]
