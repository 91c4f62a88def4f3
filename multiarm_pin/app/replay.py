"""Meshcat replay of a simulation: an offline HTML page or a live viewer.

The scene has three parts, all animated on one Meshcat timeline:

- ``arms/<name>/visuals/<geometry>``: each arm's visual geometry (real meshes from its
  URDF, sent as binary arrays in their materials' colours by
  :mod:`multiarm_pin.app.replay_meshes`; primitives through
  :class:`pinocchio.visualize.MeshcatVisualizer`), placed at
  ``base_placement * oMg(q)`` for every frame;
- ``object``: the manipulated object's polyhedron, a semi-transparent triangle mesh posed
  by its COM position and quaternion ``[x, y, z, w]``;
- ``contacts/point_<k>`` and ``contacts/force_<k>``: a small sphere at each contact point
  and a tapered rod for the force on the object, whose tip touches the contact point and
  whose length is ``force_scale * |f|``. When the contacts' states are given
  (``ReplayContacts.touching``), a touching contact's sphere is yellow and a separated
  one's is grey (``contacts/free_<k>``; the other sphere is scaled to nothing); a support's
  point (labelled ``"<support>[j]"``: the object's point that rests on it) is a cube
  (``SUPPORT_MARKER_SIZE``) in the same colours, so which support points touch stands out;
- ``supports/<name>``: a thin slab on each support plane (``ReplayContacts.supports``),
  its top face on the plane, under the support's contact points (a support with an
  ``extent``: its rectangle), in the support's colour (``SUPPORT_COLORS`` in turn; the page's
  legend names them).

Samples are subsampled to ``fps`` frames per second (nearest sample in time), so a page's
size grows with the duration, not with the integrator step. Each animation track is sent as
float32 arrays (:class:`CompactTrack`), without the keys inside a run of equal values (the
viewer interpolates between keys, so a constant stretch plays the same from its two ends).
The page (:func:`write_replay_html`) holds each distinct mesh once and shows the simulated
time, a legend and the contacts' timeline (:mod:`multiarm_pin.app.replay_overlay`), and,
for a phased task (:class:`ReplayPhase` s), the current phase and the phases' table and row.
All positions are in the world frame [m]; forces [N]. The inputs (:class:`ReplayArm`,
:class:`ReplayObject`, :class:`ReplaySupport`, :class:`ReplayContacts` with its contact labels
and :class:`ReplayEvent` s) are defined and checked in :mod:`multiarm_pin.app.replay_scene`,
a phased task's :class:`ReplayPhase` s in :mod:`multiarm_pin.app.replay_phases`, and
re-exported here.
"""

from __future__ import annotations

import contextlib
import io
import math
import webbrowser
from collections.abc import Sequence
from pathlib import Path

import meshcat
import meshcat.animation
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
import umsgpack

from multiarm_pin.app.replay_meshes import lambert_material, mesh_object, visual_mesh
from multiarm_pin.app.replay_overlay import overlay_data
from multiarm_pin.app.replay_page import page_visualizer
from multiarm_pin.app.replay_phases import ReplayPhase, check_phases
from multiarm_pin.app.replay_scene import (
    ReplayArm,
    ReplayContacts,
    ReplayEvent,
    ReplayObject,
    ReplaySupport,
    check_replay_inputs,
    frame_indices,
    polyhedron_triangles,
)
from multiarm_pin.exceptions import InputError
from multiarm_pin.spatial import as_array, quaternion_to_rotation

OBJECT_COLOR = 0xE63946
"""Colour of the object (RGB as an int): a red that stays distinct from Meshcat's blue sky."""
OBJECT_OPACITY = 0.6
CONTACT_COLOR = 0xFFD60A
"""Colour of contact-point spheres: yellow."""
FORCE_COLOR = 0x2DC653
"""Colour of force arrows: green."""
SEPARATED_COLOR = 0x8D99AE
"""Colour of the sphere of a separated (not touching) contact: grey."""
COLLIDING_COLOR = (1.0, 0.0, 0.0, 1.0)
"""Colour (RGBA) of a link while it collides: red, opaque (the object is a lighter red,
semi-transparent)."""
SUPPORT_COLORS = (0x6C584C, 0x3D5A80, 0xA47148, 0x5E548E, 0x4A7C59, 0x9A8C98)
"""Colours of the support slabs, in turn (brown first); the page's legend names each."""
SUPPORT_COLOR = SUPPORT_COLORS[0]
"""Colour of the first support's slab: brown."""
SUPPORT_THICKNESS = 0.01
"""Thickness [m] of the slab drawn under a support plane."""
CONTACT_RADIUS = 0.012
"""Radius [m] of the contact-point spheres."""
SUPPORT_MARKER_SIZE = 0.04
"""Edge [m] of the cube drawn at each support point (``"<support>[j]"``) instead of a sphere."""
FORCE_RADIUS = 0.01
"""Base radius [m] of the tapered force rods."""
AUTO_FORCE_LENGTH = 0.25
"""Length [m] of the longest force arrow when ``force_scale`` is chosen automatically."""
CAMERA_FOV_DEG = 75.0
"""Meshcat's default vertical field of view [deg], used to frame the scene."""
CAMERA_DIRECTION = np.array([1.0, -1.6, 0.9])
"""Direction from the scene centre to the camera (world axes), normalised when used."""
_MIN_SCALE = 1e-6  # a zero-length arrow would make a singular transform
# Meshcat's viewer turns its z-up world into three.js's y-up one with this rotation of the
# scene root (Rx(-pi/2), `create_default_scene` in meshcat's viewer/src/index.js).
_SCENE_ROOT_ROTATION = np.array([[1.0, 0.0, 0.0, 0.0],
                                 [0.0, 0.0, 1.0, 0.0],
                                 [0.0, -1.0, 0.0, 0.0],
                                 [0.0, 0.0, 0.0, 1.0]])


_Y_TO_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
"""Rotation taking local z to local y (so ``_rotation_y_to(n) @ _Y_TO_Z`` maps z to n)."""


class CompactTrack(meshcat.animation.AnimationTrack):
    """An animation track lowered as float32 arrays, without the inner keys of constant runs.

    ``frames`` (F,) and ``values`` (F, n) hold every frame, as meshcat's own track does; the
    viewer gets ``times`` and ``values`` as ``Float32Array`` s (three.js's
    ``KeyframeTrack.parse`` reads them instead of ``keys``), keeping frame ``i`` unless its
    float32 value equals both neighbours' (the viewer's interpolation between the kept ends
    of such a run gives the same values).
    """

    __slots__ = ()

    def kept(self) -> np.ndarray:
        """(F,) bool: the frames sent to the viewer."""
        v = np.asarray(self.values, dtype=np.float32).reshape(len(self.frames), -1)
        keep = np.ones(len(v), dtype=bool)
        if len(v) > 2:
            same = np.all(v[1:] == v[:-1], axis=1)
            keep[1:-1] = ~(same[:-1] & same[1:])
        return keep

    def lower(self):
        """The three.js track JSON: ``name``, ``type``, ``times`` and ``values`` (float32)."""
        keep = self.kept()
        v = np.asarray(self.values, dtype=np.float32).reshape(len(self.frames), -1)[keep]
        times = np.asarray(self.frames, dtype=np.float32)[keep]
        return {"name": "." + str(self.name), "type": str(self.jstype),
                "times": umsgpack.Ext(0x17, times.tobytes()),
                "values": umsgpack.Ext(0x17, np.ascontiguousarray(v).tobytes())}


def _rgb_int(rgba) -> int:
    """0xRRGGBB of an RGBA in [0, 1]."""
    r, g, b = (round(255 * float(c)) for c in rgba[:3])
    return (r << 16) | (g << 8) | b


def _pose(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p
    return T


def _rotation_y_to(direction: np.ndarray) -> np.ndarray:
    """A rotation (3, 3) whose y axis is the unit vector ``direction``."""
    y = direction
    helper = np.array([1.0, 0.0, 0.0]) if abs(y[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    x = np.cross(y, helper)
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    return np.column_stack([x, y, z])


def _norms(vectors: np.ndarray) -> np.ndarray:
    """(N,) ``np.linalg.norm`` of each row of ``vectors`` (N, 3), the same bits as row by row.

    (A batched norm sums the squares in another order than the 1-D norm's dot product, which
    can change the last bit; N is a few hundred here, so the rows are taken one by one.)
    """
    return np.array([np.linalg.norm(v) for v in vectors]).reshape(len(vectors))


def _rotations_y_to(directions: np.ndarray) -> np.ndarray:
    """(N, 3, 3) :func:`_rotation_y_to` of each unit row of ``directions`` (N, 3), batched."""
    y = directions
    helper = np.where((np.abs(y[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    x = np.cross(y, helper)
    x /= _norms(x)[:, None]
    z = np.cross(x, y)
    return np.stack([x, y, z], axis=2)


def _js_quaternions(R: np.ndarray) -> np.ndarray:
    """(N, 4) ``[x, y, z, w]`` of rotations (N, 3, 3) as Meshcat's animation stores them.

    ``meshcat.animation.js_quaternion`` (``transformations.quaternion_from_matrix`` with
    ``isprecise=False``) batched: the eigenvector of the largest eigenvalue of Bar-Itzhack's
    symmetric matrix K, sign chosen so that w >= 0, reordered from ``[w, x, y, z]``. The same
    arithmetic on each matrix, so the same values as the per-matrix call.
    """
    m00, m01, m02 = R[:, 0, 0], R[:, 0, 1], R[:, 0, 2]
    m10, m11, m12 = R[:, 1, 0], R[:, 1, 1], R[:, 1, 2]
    m20, m21, m22 = R[:, 2, 0], R[:, 2, 1], R[:, 2, 2]
    K = np.zeros((len(R), 4, 4))
    K[:, 0, 0] = m00 - m11 - m22
    K[:, 1, 0], K[:, 1, 1] = m01 + m10, m11 - m00 - m22
    K[:, 2, 0], K[:, 2, 1], K[:, 2, 2] = m02 + m20, m12 + m21, m22 - m00 - m11
    K[:, 3, 0], K[:, 3, 1], K[:, 3, 2] = m21 - m12, m02 - m20, m10 - m01
    K[:, 3, 3] = m00 + m11 + m22
    K /= 3.0
    w, V = np.linalg.eigh(K)
    q = V[np.arange(len(R)), :, np.argmax(w, axis=1)][:, [3, 0, 1, 2]]  # [w, x, y, z]
    q[q[:, 0] < 0.0] *= -1.0
    return q[:, [1, 2, 3, 0]]


class _ArmDrawer:
    """Loads one arm's geometry into Meshcat and computes its node poses for a q."""

    def __init__(self, vis: meshcat.Visualizer, arm: ReplayArm, mesh_cache: dict):
        self.arm = arm
        self.root = f"arms/{arm.name}"
        self.data = arm.model.createData()
        self.base = arm.base_placement.homogeneous
        if arm.visual_model is not None:
            self.geom = arm.visual_model
            self.geom_data = pin.GeometryData(self.geom)
            viz = None  # Pinocchio's MeshcatVisualizer: imported only for a primitive
            self.nodes = []
            self.scales = []
            self.links = [arm.model.frames[g.parentFrame].name
                          for g in self.geom.geometryObjects]
            for g in self.geom.geometryObjects:
                # the node MeshcatVisualizer.getViewerNodeName gives a VISUAL geometry
                node = f"{self.root}/visuals/{g.name}"
                mesh = visual_mesh(g, arm.color, mesh_cache)
                if mesh is not None:  # scale already applied to the vertices
                    vis[node].set_object(mesh_object(mesh))
                    self.scales.append(np.ones(3))
                else:  # primitives and other formats: Pinocchio's own loader
                    viz = viz or self._pinocchio_visualizer(vis)
                    viz.loadViewerGeometryObject(g, pin.GeometryType.VISUAL, arm.color)
                    self.scales.append(np.asarray(g.meshScale, dtype=float))
                self.nodes.append(node)
        else:
            self.geom = None
            self.nodes = [f"{self.root}/joints/{arm.model.names[j]}"
                          for j in range(1, arm.model.njoints)]
            self.links = [None] * len(self.nodes)  # a sphere per joint: its body's link
            for f in arm.model.frames:
                if f.type == pin.FrameType.BODY and f.parentJoint > 0:
                    self.links[f.parentJoint - 1] = self.links[f.parentJoint - 1] or f.name
            self.scales = [np.ones(3)] * len(self.nodes)
            rgba = arm.color if arm.color is not None else (0.55, 0.55, 0.55, 1.0)
            for node in self.nodes:
                vis[node].set_object(mg.Sphere(0.04), lambert_material(rgba))

    def load_colliding(self, vis: meshcat.Visualizer, mesh_cache: dict
                       ) -> dict[int, tuple[str, np.ndarray]]:
        """Red copies of the nodes of the arm's colliding links.

        Returns:
            node index -> (the red copy's path, (T,) bool: the samples it is shown).
        """
        out = {}
        for g, (node, link) in enumerate(zip(self.nodes, self.links, strict=True)):
            mask = self.arm.colliding.get(link)
            if mask is None or not mask.any():
                continue
            red = node.replace(f"{self.root}/", f"{self.root}/colliding/", 1)
            if self.geom is None:
                vis[red].set_object(mg.Sphere(0.04), lambert_material(COLLIDING_COLOR))
            else:
                obj = self.geom.geometryObjects[g]
                mesh = visual_mesh(obj, COLLIDING_COLOR, mesh_cache)
                if mesh is not None:
                    vis[red].set_object(mesh_object(mesh))
                else:  # a primitive: Pinocchio's loader, into the copies' group
                    viz = self._pinocchio_visualizer(vis)
                    viz.viewerVisualGroupName = f"{self.root}/colliding/visuals"
                    viz.loadViewerGeometryObject(obj, pin.GeometryType.VISUAL,
                                                 np.array(COLLIDING_COLOR))
            out[g] = (red, mask)
        return out

    def _pinocchio_visualizer(self, vis: meshcat.Visualizer):
        from pinocchio.visualize import MeshcatVisualizer

        viz = MeshcatVisualizer(self.arm.model, None, self.geom)
        viz.initViewer(viewer=vis)
        viz.viewerRootNodeName = self.root
        viz.viewerVisualGroupName = f"{self.root}/visuals"
        return viz

    def _placements(self, q: np.ndarray):
        """The nodes' placements relative to the arm's base at ``q`` (``pin.SE3`` each)."""
        model = self.arm.model
        pin.forwardKinematics(model, self.data, q)
        if self.geom is None:
            return [self.data.oMi[j] for j in range(1, model.njoints)]
        pin.updateGeometryPlacements(model, self.data, self.geom, self.geom_data)
        return self.geom_data.oMg

    def poses(self, q: np.ndarray) -> list[np.ndarray]:
        """World poses (4, 4), pure rotation + translation, of this arm's nodes at ``q``."""
        return [self.base @ M.homogeneous for M in self._placements(q)]

    def pose_stack(self, qs: np.ndarray) -> np.ndarray:
        """(F, nodes, 4, 4) world poses of the nodes at each row of ``qs`` (F, nq).

        Equal to :meth:`poses` row by row (one Pinocchio pass per row, one batched product
        with the base placement).
        """
        H = np.empty((len(qs), len(self.nodes), 4, 4))
        for f, q in enumerate(qs):
            for g, M in enumerate(self._placements(q)):
                H[f, g] = M.homogeneous
        return np.matmul(self.base, H)


def _scaled(T: np.ndarray, scale: np.ndarray) -> np.ndarray:
    out = T.copy()
    out[:3, :3] = T[:3, :3] * scale[None, :]
    return out


def _scene_points(drawers, obj, contacts, index0) -> np.ndarray:
    """(P, 3) world points [m] that the camera frames, at sample ``index0``.

    Arm nodes and bases, object vertices and contact points; the world origin only for an
    empty scene (framing it too would push content far from the origin off-centre).
    """
    pts = []
    for d in drawers:
        pts.append(np.array([T[:3, 3] for T in d.poses(d.arm.q[index0])]).reshape(-1, 3))
        pts.append(d.base[None, :3, 3])
    if obj is not None:
        R = quaternion_to_rotation(obj.quaternion[index0])
        pts.append(obj.position[index0] + obj.polyhedron.vertices @ R.T)
    if contacts is not None:
        pts.append(contacts.points[index0])
    pts = [p for p in pts if len(p)]
    return np.vstack(pts) if pts else np.zeros((1, 3))


def set_camera(vis: meshcat.Visualizer, target, eye) -> None:
    """Point Meshcat's default camera from ``eye`` (3,) at ``target`` (3,), world [m].

    How meshcat 0.3.2's viewer moves its camera (``viewer/src/index.js`` and three.js's
    ``OrbitControls``, read in the installed package): the scene root, a three.js
    ``Scene`` at Meshcat path ``/``, is rotated by ``Rx(-pi/2)`` so that Meshcat's z-up
    world shows in three.js's y-up world; the camera is the object at
    ``/Cameras/default/rotated``, a node rotated back by ``Rx(pi/2)``. On every render
    the orbit controls set the camera's *local* position to ``controls.target + offset``
    and call ``camera.lookAt(controls.target)``, which takes a point in three.js *world*
    coordinates. ``controls.target`` stays at ``(0, 0, 0)``: the viewer has no command
    that changes it (no ``set_target``; the server forwards only ``set_transform``,
    ``set_object``, ``set_property``, ``set_animation`` and ``delete``). Moving
    ``/Cameras/default`` alone therefore moves the eye, but the camera keeps looking at
    the world origin.

    So the scene root's transform becomes ``Rx(-pi/2) T(-target)``: three.js's world
    origin is then our ``target``, and everything in the scene (grid, axes, lights, the
    ``/meshcat`` tree, the camera) keeps its pose relative to the rest.
    ``/Cameras/default`` is placed at ``target``, so the camera's parent frame is
    three.js's world frame, exactly as in Meshcat's default set-up: orbiting, zooming and
    panning act about ``target``. The camera's local position is ``(dx, dz, -dy)`` for
    the world offset ``d = eye - target``. The server stores the root's transform like any
    node's, so both the live viewer and ``static_html`` pages replay it.

    Raises:
        InputError: ``target`` or ``eye`` not a finite 3-vector, or ``eye == target``.
    """
    target = as_array(target, (3,), "camera target [m]")
    d = as_array(eye, (3,), "camera eye [m]") - target
    if not np.linalg.norm(d) > 0:
        raise InputError("camera eye: expected a point different from the target, "
                         f"got eye = target = {target.tolist()}")
    vis["/"].set_transform(_SCENE_ROOT_ROTATION @ _pose(np.eye(3), -target))
    vis["/Cameras/default"].set_transform(_pose(np.eye(3), target))
    vis["/Cameras/default/rotated/<object>"].set_property("position", [d[0], d[2], -d[1]])


def _frame_camera(vis, points: np.ndarray) -> None:
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = 0.5 * (lo + hi)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.5)
    # 1.3: margin for geometry that extends past the node origins the points come from.
    distance = 1.3 * radius / math.sin(math.radians(CAMERA_FOV_DEG) / 2)
    direction = CAMERA_DIRECTION / np.linalg.norm(CAMERA_DIRECTION)
    set_camera(vis, centre, centre + distance * direction)


def _force_scale(contacts: ReplayContacts | None, force_scale: float | None) -> float:
    """Arrow length per newton [m/N]: ``force_scale``, else the longest force's inverse.

    The longest force is drawn ``AUTO_FORCE_LENGTH`` long (1 m/N when no force is nonzero).
    """
    if force_scale is not None:
        return force_scale
    if contacts is None:
        return 1.0
    fmax = float(np.max(np.linalg.norm(contacts.forces, axis=2), initial=0.0))
    return AUTO_FORCE_LENGTH / fmax if fmax > 0 else 1.0


# ----------------------------------------------------------------------------- public API
def build_animation(
    vis: meshcat.Visualizer,
    arms: Sequence[ReplayArm],
    obj: ReplayObject | None,
    contacts: ReplayContacts | None,
    t,
    fps: float = 30,
    force_scale: float | None = None,
) -> meshcat.animation.Animation:
    """Load the scene into ``vis`` and record its motion on a Meshcat timeline.

    The scene is also posed at the first frame (static transforms) and the camera framed on
    it, so a viewer shows it before the animation plays. Call ``vis.set_animation(anim)``
    to send the timeline.

    Args:
        vis: the Meshcat visualizer (its server holds the scene).
        arms: arms to draw; each ``q`` has T rows.
        obj: the object (``position`` (T, 3), ``quaternion`` (T, 4)), or ``None``.
        contacts: contact points and forces on the object ((T, K, 3) each), or ``None``.
        t: (T,) strictly increasing sample times [s].
        fps: frames per second of the replay; samples are subsampled to it.
        force_scale: arrow length per newton [m/N]; ``None`` makes the largest force
            ``AUTO_FORCE_LENGTH`` m long.

    Returns:
        The animation, one frame every ``1 / fps`` s from ``t[0]`` to ``t[-1]``.

    Raises:
        InputError: inconsistent sample counts, non-increasing times, bad fps or scale.
    """
    t = check_replay_inputs(arms, obj, contacts, t, fps)
    if force_scale is not None and not (force_scale > 0 and math.isfinite(force_scale)):
        raise InputError(f"force_scale: expected a positive length per newton [m/N] or None, "
                         f"got {force_scale!r}")
    indices = frame_indices(t, fps)
    anim = meshcat.animation.Animation(default_framerate=fps)

    mesh_cache: dict = {}
    drawers = [_ArmDrawer(vis, arm, mesh_cache) for arm in arms]

    if obj is not None:
        poly = obj.polyhedron
        vis["object"].set_object(
            mg.TriangularMeshGeometry(poly.vertices, polyhedron_triangles(poly)),
            mg.MeshLambertMaterial(color=OBJECT_COLOR, transparent=True,
                                   opacity=OBJECT_OPACITY),
        )

    n_contacts = 0 if contacts is None else contacts.points.shape[1]
    if contacts is not None:
        force_scale = _force_scale(contacts, force_scale)
        for j, sp in enumerate(contacts.supports):
            if sp.extent is None:
                R = _rotation_y_to(sp.normal) @ _Y_TO_Z  # slab's local z along the normal
                size = [2 * sp.half_size, 2 * sp.half_size, SUPPORT_THICKNESS]
            else:  # the rectangle, its sides along the support's axes
                R = sp.rotation
                size = [float(sp.extent[0]), float(sp.extent[1]), SUPPORT_THICKNESS]
            vis[f"supports/{sp.name}"].set_object(
                mg.Box(size),
                mg.MeshLambertMaterial(color=SUPPORT_COLORS[j % len(SUPPORT_COLORS)]))
            vis[f"supports/{sp.name}"].set_transform(
                _pose(R, sp.center - 0.5 * SUPPORT_THICKNESS * sp.normal))
        on_support = {k for ks in contacts.support_points().values() for k in ks}
        for k in range(n_contacts):
            # a support point: a cube, so the object's points on a support stand apart from
            # the arms' contacts (same colours: touching, separated)
            marker = (mg.Box([SUPPORT_MARKER_SIZE] * 3) if k in on_support
                      else mg.Sphere(CONTACT_RADIUS))
            vis[f"contacts/point_{k}"].set_object(
                marker, mg.MeshLambertMaterial(color=CONTACT_COLOR))
            if contacts.touching is not None:
                vis[f"contacts/free_{k}"].set_object(
                    marker, mg.MeshLambertMaterial(color=SEPARATED_COLOR))
            # Unit-length rod along local y from -1 to 0, pointed (radius 0) at 0.
            rod = vis[f"contacts/force_{k}/rod"]
            rod.set_object(mg.Cylinder(1.0, radiusTop=0.0, radiusBottom=FORCE_RADIUS),
                           mg.MeshLambertMaterial(color=FORCE_COLOR))
            rod.set_transform(_pose(np.eye(3), [0.0, -0.5, 0.0]))

    def contact_pose(i: int, k: int) -> tuple[np.ndarray, float]:
        f = contacts.forces[i, k]
        norm = float(np.linalg.norm(f))
        R = _rotation_y_to(f / norm) if norm > 0 else np.eye(3)
        return _pose(R, contacts.points[i, k]), max(norm * force_scale, _MIN_SCALE)

    # The timeline, one track per node and property, every frame at once (the content of
    # ``anim.at_frame(vis, frame)[node].set_transform(T)`` frame by frame, in its order).
    frames = list(range(len(indices)))

    def track(node: str, prop: str, jstype: str, values: list) -> None:
        key = vis.path.append(node)
        clip = anim.clips.get(key)
        if clip is None:
            clip = anim.clips[key] = meshcat.animation.AnimationClip(fps=anim.default_framerate)
        clip.tracks[prop] = CompactTrack(prop, jstype, list(frames),
                                         np.asarray(values, dtype=float))

    def transform_tracks(node: str, R: np.ndarray, p: np.ndarray) -> None:
        track(node, "position", "vector3", p)
        track(node, "quaternion", "quaternion", _js_quaternions(R))

    colliding = [d.load_colliding(vis, mesh_cache) for d in drawers]
    for d, red in zip(drawers, colliding, strict=True):
        H = d.pose_stack(d.arm.q[indices])
        for g, (node, s) in enumerate(zip(d.nodes, d.scales, strict=True)):
            transform_tracks(node, H[:, g, :3, :3], H[:, g, :3, 3])
            if g in red:  # the red copy shown instead while the link collides
                copy, mask = red[g]
                shown, hidden = s.tolist(), (s * _MIN_SCALE).tolist()
                on = mask[indices].tolist()
                transform_tracks(copy, H[:, g, :3, :3], H[:, g, :3, 3])
                track(node, "scale", "vector3", [hidden if o else shown for o in on])
                track(copy, "scale", "vector3", [shown if o else hidden for o in on])
            elif not np.allclose(s, 1.0):
                track(node, "scale", "vector3", [s.tolist() for _ in frames])
    if obj is not None:
        R = np.array([quaternion_to_rotation(q) for q in obj.quaternion[indices]])
        transform_tracks("object", R.reshape(-1, 3, 3), obj.position[indices])
    if n_contacts:
        eye = np.broadcast_to(np.eye(3), (len(indices), 3, 3))
        one, hidden = [1.0] * 3, [_MIN_SCALE] * 3
    for k in range(n_contacts):
        points = contacts.points[indices, k]
        transform_tracks(f"contacts/point_{k}", eye, points)
        if contacts.touching is not None:
            on = contacts.touching[indices, k].tolist()
            transform_tracks(f"contacts/free_{k}", eye, points)
            track(f"contacts/point_{k}", "scale", "vector3", [one if o else hidden for o in on])
            track(f"contacts/free_{k}", "scale", "vector3", [hidden if o else one for o in on])
        f = contacts.forces[indices, k]
        norm = _norms(f)
        pushing = norm > 0
        R = np.array(eye)
        R[pushing] = _rotations_y_to(f[pushing] / norm[pushing, None])
        transform_tracks(f"contacts/force_{k}", R, points)
        track(f"contacts/force_{k}", "scale", "vector3",
              [[1.0, max(float(n) * force_scale, _MIN_SCALE), 1.0] for n in norm])

    # Static pose at the first frame, for viewers before (or without) the animation.
    i0 = int(indices[0])
    for d, red in zip(drawers, colliding, strict=True):
        for g, (node, T, s) in enumerate(zip(d.nodes, d.poses(d.arm.q[i0]), d.scales,
                                             strict=True)):
            if g in red:
                copy, mask = red[g]
                on = bool(mask[i0])
                vis[copy].set_transform(_scaled(T, s if on else s * _MIN_SCALE))
                s = s * _MIN_SCALE if on else s
            vis[node].set_transform(_scaled(T, s))
    if obj is not None:
        vis["object"].set_transform(
            _pose(quaternion_to_rotation(obj.quaternion[i0]), obj.position[i0]))
    for k in range(n_contacts):
        T, length = contact_pose(i0, k)
        P = _pose(np.eye(3), contacts.points[i0, k])
        hidden = _scaled(P, np.full(3, _MIN_SCALE))
        if contacts.touching is not None:
            on = bool(contacts.touching[i0, k])
            vis[f"contacts/free_{k}"].set_transform(hidden if on else P)
            P = P if on else hidden
        vis[f"contacts/point_{k}"].set_transform(P)
        vis[f"contacts/force_{k}"].set_transform(_scaled(T, np.array([1.0, length, 1.0])))

    _frame_camera(vis, _scene_points(drawers, obj, contacts, i0))
    return anim


def close_visualizer(vis: meshcat.Visualizer) -> None:
    """Stop the Meshcat server process that ``vis`` started and close its socket.

    (``meshcat.Visualizer.close`` is broken in meshcat 0.3.2: its window has no ``close``.)
    """
    window = vis.window
    proc = getattr(window, "server_proc", None)
    if proc is not None and proc.poll() is None:
        proc.kill()
        proc.wait(timeout=10)
    socket = getattr(window, "zmq_socket", None)
    if socket is not None:
        socket.close(linger=0)


def _new_visualizer() -> meshcat.Visualizer:
    with contextlib.redirect_stdout(io.StringIO()):  # meshcat prints its URL
        return meshcat.Visualizer()


def write_replay_html(
    path,
    arms: Sequence[ReplayArm],
    obj: ReplayObject | None,
    t,
    contacts: ReplayContacts | None = None,
    fps: float = 30,
    title: str = "multiarm-pin replay",
    phases: Sequence[ReplayPhase] = (),
) -> Path:
    """Write a self-contained HTML page that replays the motion offline.

    The scene is built in this process (:mod:`multiarm_pin.app.replay_page`: Meshcat's
    scene without starting its server) into the compact page: three.js inlined, each
    distinct mesh once however many arms use it, everything in one compressed block, and
    the overlay (simulated time, legend, contact timeline; see
    :mod:`multiarm_pin.app.replay_overlay`). It needs no network.

    Args:
        path: output file (``.html``); its folder must exist.
        arms: arms to draw, each with (T, nq) ``q``.
        obj: the object ((T, 3) positions, (T, 4) quaternions ``[x, y, z, w]``) or None.
        t: (T,) strictly increasing sample times [s].
        contacts: optional (T, K, 3) contact points [m] and forces on the object [N], with
            their states, labels, events and supports.
        fps: frames per second of the replay.
        title: the page's title and the overlay's heading.
        phases: the task's phases (:class:`ReplayPhase`, a ``phased_pd`` run's), shown as
            the current phase, a table in the legend and the timeline's top row; none:
            the page has no phase parts.

    Returns:
        The path written.

    Raises:
        InputError: invalid replay data or a folder that does not exist.
    """
    path = Path(path)
    if not path.parent.is_dir():
        raise InputError(f"write_replay_html: folder {path.parent} does not exist")
    t = check_replay_inputs(arms, obj, contacts, t, fps)
    phases = check_phases(phases)
    vis = page_visualizer()
    anim = build_animation(vis, arms, obj, contacts, t, fps=fps)
    vis.set_animation(anim, play=True, repetitions=1)
    n_supports = 0 if contacts is None else len(contacts.supports)
    vis.window.title = str(title)
    vis.window.overlay = overlay_data(
        t, contacts, title=str(title), arm_names=[a.name for a in arms],
        force_scale=None if contacts is None else _force_scale(contacts, None),
        support_colors=[SUPPORT_COLORS[j % len(SUPPORT_COLORS)] for j in range(n_supports)],
        phases=phases, fps=fps,
        colors={"object": OBJECT_COLOR, "contact": CONTACT_COLOR,
                "separated": SEPARATED_COLOR, "force": FORCE_COLOR,
                **({"colliding": _rgb_int(COLLIDING_COLOR)}
                   if any(m.any() for a in arms for m in a.colliding.values()) else {})})
    path.write_text(vis.static_html(), encoding="utf-8")
    return path


def serve_replay(
    arms: Sequence[ReplayArm],
    obj: ReplayObject | None,
    t,
    contacts: ReplayContacts | None = None,
    fps: float = 30,
    open_browser: bool = False,
) -> tuple[str, meshcat.Visualizer]:
    """Start a live Meshcat server on localhost showing the replay.

    Args:
        arms: arms to draw, each with (T, nq) ``q``.
        obj: the object or None.
        t: (T,) strictly increasing sample times [s].
        contacts: optional contact points and forces.
        fps: frames per second of the replay.
        open_browser: open the page in the default browser.

    Returns:
        ``(url, vis)``: the page's URL and the visualizer; stop the server with
        :func:`close_visualizer` ``(vis)`` when done.
    """
    t = check_replay_inputs(arms, obj, contacts, t, fps)
    vis = _new_visualizer()
    try:
        anim = build_animation(vis, arms, obj, contacts, t, fps=fps)
        vis.set_animation(anim, play=True, repetitions=1)
    except BaseException:
        close_visualizer(vis)
        raise
    url = vis.url()
    if open_browser:
        webbrowser.open(url, new=2)
    return url, vis


def write_replay(result, system, path, fps: float = 30,
                 phases: Sequence[ReplayPhase] = ()) -> Path:
    """Write the replay page of a simulation run from Python (what ``multiarm-pin run`` writes).

    A self-contained HTML page (:func:`write_replay_html`): the arms (their meshes when they
    were loaded with ``load_visuals=True``, the default; spheres at the joints otherwise), the
    object, every contact point with its force on the object (touching contacts yellow,
    separated ones grey) and the supports, at ``fps`` frames per second.

    Args:
        result: the :class:`~multiarm_pin.sim.simulation.SimulationResult` of
            ``simulate(system, ...)``.
        system: the :class:`~multiarm_pin.system.MultiArmSystem` that was simulated.
        path: the ``.html`` file to write; its folder must exist.
        fps: frames per second of the replay.
        phases: the task's phases (:class:`ReplayPhase`) to show (a ``phased_pd`` run);
            none by default (a results folder's are read by
            :func:`~multiarm_pin.app.replay_phases.replay_phases`).

    Returns:
        The path written.

    Raises:
        InputError: a result whose shapes are not those of ``system``, or a folder that does
            not exist.
    """
    from multiarm_pin.app.run_results import replay_parts, system_trajectory_arrays

    q = getattr(result, "q", None)
    mu = getattr(result, "mu", None)
    if (q is None or mu is None or q.ndim != 2 or q.shape[1] != system.nq
            or mu.shape[1:] != (system.n_blocks, system.rows_max)):
        raise InputError(
            f"write_replay: expected the SimulationResult of this system (q of shape (T, "
            f"{system.nq}), mu (T, {system.n_blocks}, {system.rows_max})), got "
            f"{type(result).__name__}"
            + ("" if q is None or mu is None else f" with q {q.shape} and mu {mu.shape}"))
    traj = system_trajectory_arrays(system, result)
    arms, obj, contacts = replay_parts(system.arms, system.obj, traj)
    return write_replay_html(path, arms, obj, traj["t"], contacts, fps=fps, phases=phases)


__all__ = [
    "ReplayArm",
    "CompactTrack",
    "ReplayContacts",
    "ReplayEvent",
    "ReplayObject",
    "ReplayPhase",
    "ReplaySupport",
    "build_animation",
    "close_visualizer",
    "frame_indices",
    "polyhedron_triangles",
    "serve_replay",
    "set_camera",
    "write_replay",
    "write_replay_html",
]
