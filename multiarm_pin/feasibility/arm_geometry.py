"""Each arm's collision geometry: its URDF's collision shapes, as hulls, with its allowed pairs.

:func:`arm_collision_geometry` rebuilds an :class:`~multiarm_pin.model.arm.Arm`'s model the
way the arm was loaded (the same URDF, the same locked joints, the same base placement), this
time with the URDF's ``<collision>`` geometry (Pinocchio's ``buildGeomFromUrdf``), and gives:

- ``hull``: every mesh replaced by its convex hull (coal's ``buildConvexHull``; primitives such
  as boxes, cylinders and spheres kept as they are). A hull fills the concave parts of a
  mesh, so its distances are lower bounds of the mesh's; it is what the checks at every
  sample use.
- ``mesh``: the same geometry with the meshes themselves (coal BVH models), for confirming a
  penetration that a hull reports.
- ``self_pairs``: the pairs of geometry objects of the arm that may collide: every pair but
  those on the same joint (rigidly attached to each other), those on adjacent joints (their
  joint keeps them apart; the kinova's SRDF does not list its first two links, whose hulls
  overlap), and those that the robot's SRDF disables (example-robot-data ships one for most
  arms: links that never meet).
- ``carrier``: the geometry objects on the tool's joint and every joint after it (the wrist
  flange, a gripper, its fingertips): the links that carry the grasp's contacts.

The geometry is expressed on the arm's own model (``arm.model``: base placement baked in, the
same joints in the same order), so ``pin.updateGeometryPlacements(arm.model, data, hull, gd,
q)`` places it.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from os.path import join

import pinocchio as pin

from multiarm_pin.exceptions import InputError
from multiarm_pin.model.robots import robot_entry
from multiarm_pin.model.sources import load_example_robot, lock_joints, unique_frame_names


@dataclass(frozen=True)
class ArmGeometry:
    """The collision geometry of one arm on its own model.

    Attributes:
        model: the arm's model rebuilt with its collision geometry (same joints as
            ``arm.model``).
        hull: collision geometry, meshes replaced by their convex hulls.
        mesh: the same geometry objects with the meshes themselves.
        names: (G,) link name of each geometry object (the URDF link it belongs to).
        self_pairs: pairs ``(g1, g2)`` of geometry indices that are checked against each other.
        carrier: indices of the geometry objects on the tool's joint or after it.
        srdf: the SRDF file the disabled pairs came from, or ``""`` (adjacent joints instead).
    """

    model: pin.Model
    hull: pin.GeometryModel
    mesh: pin.GeometryModel
    names: tuple[str, ...]
    self_pairs: tuple[tuple[int, int], ...]
    carrier: frozenset
    srdf: str


def _loader_paths(robot: str) -> tuple[str, str, str]:
    """``(urdf, srdf or "", package dir)`` of a registered robot's example-robot-data files."""
    import example_robot_data as erd
    from example_robot_data import robots_loader

    entry = robot_entry(robot)
    cls = getattr(robots_loader, entry.loader) if entry.loader else robots_loader.ROBOTS[robot]
    rel = join(cls.path, cls.urdf_subpath, cls.urdf_filename)
    root = erd.getModelPath(rel)
    srdf = join(root, cls.path, cls.srdf_subpath, cls.srdf_filename) if cls.srdf_filename \
        else ""
    return join(root, rel), srdf, join(root, "../..")


@functools.cache
def _source_geometry(source: str) -> tuple[pin.Model, pin.GeometryModel, str]:
    """The unreduced model, its collision geometry and SRDF of an arm's source, once a process.

    ``source`` is :attr:`Arm.source`: ``example_robot_data:<name>`` or a URDF path.
    """
    if source.startswith("example_robot_data:"):
        robot = source.split(":", 1)[1]
        model = load_example_robot(robot)[0]
        urdf, srdf, package = _loader_paths(robot)
        dirs = [package]
    else:
        from pathlib import Path

        path = Path(source)
        model = pin.buildModelFromUrdf(str(path))
        urdf, srdf = str(path), ""
        dirs = [str(p) for p in (path.parent, *path.parents[:3])]
    geom = pin.buildGeomFromUrdf(model, urdf, pin.GeometryType.COLLISION, package_dirs=dirs)
    return model, geom, srdf


def _hulls(geom: pin.GeometryModel) -> pin.GeometryModel:
    """A copy of ``geom`` with every BVH mesh replaced by its convex hull."""
    out = geom.copy()
    for k in range(out.ngeoms):
        g = out.geometryObjects[k]
        shape = g.geometry
        if type(shape).__name__.startswith("BVHModel"):
            shape = shape.clone()
            shape.buildConvexHull(True, "Qt")
            g.geometry = shape.convex
            out.geometryObjects[k] = g
    return out


def _descendants(model: pin.Model, joint: int) -> set[int]:
    """``joint`` and every joint after it in the kinematic tree."""
    out = {joint}
    for j in range(joint + 1, model.njoints):
        if model.parents[j] in out:
            out.add(j)
    return out


def arm_collision_geometry(arm) -> ArmGeometry:
    """The collision geometry of ``arm`` (see the module docstring), built once per arm kind.

    Args:
        arm: an :class:`~multiarm_pin.model.arm.Arm` loaded by name or from a URDF.

    Raises:
        InputError: the arm's source cannot be rebuilt (an arm made from a bare model), or
            the rebuilt model's joints differ from the arm's.
    """
    if not arm.source:
        raise InputError(f"arm {arm.name!r}: no URDF or robot name to read its collision "
                         "geometry from (an arm built from a bare model)")
    base = arm.base_placement
    key = (tuple(base.rotation.ravel().tolist()), tuple(base.translation.tolist()))
    tool_joint = int(arm.model.frames[arm.tool_frame_id].parentJoint)
    return _arm_geometry(arm.source, tuple(arm.model.names), key, tool_joint)


@functools.lru_cache(maxsize=16)
def _unplaced(source: str, names: tuple) -> tuple:
    """The arm's model, geometry, its hulls and SRDF, before placing its base (per kind).

    The hulls are in the links' own frames, so placing the base does not change them: they
    are built once per arm kind, not once per base placement.
    """
    model, geom, srdf = _source_geometry(source)
    have = set(names)
    locked = tuple(n for n in list(model.names)[1:] if n not in have)
    if locked:
        model, geom = lock_joints(model, geom.copy(), locked, source)
    model = unique_frame_names(model)
    return model, geom, _hulls(geom), srdf


@functools.lru_cache(maxsize=64)
def _arm_geometry(source: str, names: tuple, base_key: tuple, tool_joint: int) -> ArmGeometry:
    """:func:`arm_collision_geometry` for hashable arguments (the base as two tuples)."""
    import numpy as np

    base = pin.SE3(np.array(base_key[0]).reshape(3, 3), np.array(base_key[1]))
    model, geom, hull_geom, srdf = _unplaced(source, names)
    world = pin.Model()
    world.gravity = model.gravity
    placed, placed_geom = pin.appendModel(world, model, pin.GeometryModel(), geom, 0, base)
    if tuple(placed.names) != names:
        raise InputError(f"{source}: the collision model's joints {list(placed.names)} differ "
                         f"from the arm's {list(names)}")
    _, hull = pin.appendModel(world, model, pin.GeometryModel(), hull_geom, 0, base)
    link_names = tuple(placed.frames[g.parentFrame].name for g in placed_geom.geometryObjects)
    pairs_model = hull.copy()
    pairs_model.addAllCollisionPairs()
    if srdf:
        pin.removeCollisionPairs(placed, pairs_model, srdf)
    joints = [g.parentJoint for g in placed_geom.geometryObjects]
    pairs = []
    for cp in pairs_model.collisionPairs:
        a, b = int(cp.first), int(cp.second)
        ja, jb = joints[a], joints[b]
        if ja == jb:
            continue  # rigidly attached to each other
        if placed.parents[ja] == jb or placed.parents[jb] == ja:
            continue  # adjacent links: their joint keeps them apart (an SRDF may omit them)
        pairs.append((a, b))
    carrier_joints = _descendants(placed, tool_joint)
    carrier = frozenset(k for k, j in enumerate(joints) if j in carrier_joints)
    return ArmGeometry(placed, hull, placed_geom, link_names, tuple(pairs), carrier, srdf)


__all__ = ["ArmGeometry", "arm_collision_geometry"]
