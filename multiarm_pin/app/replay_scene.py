"""What a replay shows: the arms, the object, the supports and the contacts over time.

The input side of :mod:`multiarm_pin.app.replay`: one validated dataclass per part of the
scene (shapes checked at construction), the frame sampling and the object's triangles. All
positions in the world frame [m], forces [N], quaternions ``[x, y, z, w]``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from multiarm_pin.exceptions import InputError
from multiarm_pin.model.polyhedron import Polyhedron
from multiarm_pin.sim.contact_events import EVENT_KINDS as CONTACT_EVENT_KINDS
from multiarm_pin.spatial import as_array


@dataclass
class ReplayArm:
    """One arm to draw.

    Attributes:
        name: unique name; its geometry goes under the Meshcat path ``arms/<name>``.
        model: the arm's Pinocchio model (fixed base at the model's origin).
        visual_model: its visual geometry (e.g. ``example_robot_data.load(n).visual_model``
            or the VISUAL model of ``pin.buildModelsFromUrdf``); ``None`` draws a sphere
            at each joint instead.
        base_placement: pose of the model's origin in the world.
        q: (T, nq) joint positions over time [rad or m].
        color: optional RGBA in [0, 1] for all of the arm's geometry; ``None`` keeps each
            geometry's own colours: its URDF material, else its COLLADA file's materials,
            else ``GeometryObject.meshColor`` (see :mod:`multiarm_pin.app.replay_meshes`).
        colliding: per link name, (T,) bool: the samples where it collides (drawn red
            then; the collisions of a run's feasibility report). Empty: none.
    """

    name: str
    model: pin.Model
    visual_model: pin.GeometryModel | None
    base_placement: pin.SE3
    q: np.ndarray
    color: tuple[float, float, float, float] | None = None
    colliding: dict = field(default_factory=dict)

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name or "/" in self.name:
            raise InputError(f"ReplayArm.name: expected a non-empty string without '/', "
                             f"got {self.name!r}")
        if not isinstance(self.model, pin.Model):
            raise InputError(f"ReplayArm {self.name!r}: model must be a pin.Model, "
                             f"got {type(self.model).__name__}")
        if self.visual_model is not None and not isinstance(self.visual_model, pin.GeometryModel):
            raise InputError(f"ReplayArm {self.name!r}: visual_model must be a "
                             f"pin.GeometryModel or None, got {type(self.visual_model).__name__}")
        if not isinstance(self.base_placement, pin.SE3):
            raise InputError(f"ReplayArm {self.name!r}: base_placement must be a pin.SE3, "
                             f"got {type(self.base_placement).__name__}")
        self.q = as_array(self.q, (None, self.model.nq), f"ReplayArm {self.name!r}.q (T, nq)")
        if self.color is not None:
            rgba = as_array(self.color, (4,), f"ReplayArm {self.name!r}.color (RGBA)")
            if np.any(rgba < 0) or np.any(rgba > 1):
                raise InputError(f"ReplayArm {self.name!r}.color: expected RGBA values in "
                                 f"[0, 1], got {rgba.tolist()}")
            self.color = tuple(float(c) for c in rgba)
        T = len(self.q)
        colliding = {}
        for link, mask in dict(self.colliding or {}).items():
            m = np.asarray(mask)
            if m.shape != (T,) or m.dtype != bool:
                raise InputError(f"ReplayArm {self.name!r}.colliding[{link!r}]: expected ({T},) "
                                 f"bool, got {m.dtype} of shape {m.shape}")
            colliding[str(link)] = m
        self.colliding = colliding


@dataclass
class ReplayObject:
    """The manipulated object over time.

    Attributes:
        polyhedron: its shape in the object frame (origin at the COM) [m].
        position: (T, 3) COM position in the world [m].
        quaternion: (T, 4) orientation ``[x, y, z, w]`` (object axes to world axes);
            normalised here, a norm far from 1 is an error.
    """

    polyhedron: Polyhedron
    position: np.ndarray
    quaternion: np.ndarray

    def __post_init__(self):
        if not isinstance(self.polyhedron, Polyhedron):
            raise InputError(f"ReplayObject.polyhedron: expected a Polyhedron, "
                             f"got {type(self.polyhedron).__name__}")
        self.position = as_array(self.position, (None, 3), "ReplayObject.position (T, 3)")
        quat = as_array(self.quaternion, (len(self.position), 4),
                        "ReplayObject.quaternion (T, 4) [x, y, z, w]")
        norms = np.linalg.norm(quat, axis=1)
        if np.any(np.abs(norms - 1.0) > 1e-3):
            bad = int(np.argmax(np.abs(norms - 1.0)))
            raise InputError(f"ReplayObject.quaternion: row {bad} has norm {norms[bad]:.6g}, "
                             "expected unit quaternions [x, y, z, w]")
        self.quaternion = quat / norms[:, None]


@dataclass
class ReplaySupport:
    """A support plane drawn as a slab whose top face lies on the plane.

    An infinite plane is drawn as a square around the object's points; a support with an
    ``extent`` as its rectangle.

    Attributes:
        name: scene node name (``supports/<name>``).
        center: (3,) centre of the slab's top face, on the plane, world [m].
        normal: (3,) unit normal out of the support, world axes.
        half_size: half the side of the square [m] (without ``extent``).
        extent: None, or (2,) ``[lx, ly]`` [m], the rectangle's sides along ``x_axis`` and
            ``normal × x_axis``.
        x_axis: (3,) the rectangle's x axis, world (unit, in the plane); with ``extent``.
    """

    name: str
    center: np.ndarray
    normal: np.ndarray
    half_size: float
    extent: np.ndarray | None = None
    x_axis: np.ndarray | None = None

    def __post_init__(self):
        self.center = as_array(self.center, (3,), f"ReplaySupport {self.name!r}.center")
        n = as_array(self.normal, (3,), f"ReplaySupport {self.name!r}.normal")
        if np.linalg.norm(n) < 1e-9:
            raise InputError(f"ReplaySupport {self.name!r}.normal: zero length")
        self.normal = n / np.linalg.norm(n)
        if not (math.isfinite(self.half_size) and self.half_size > 0):
            raise InputError(f"ReplaySupport {self.name!r}.half_size: expected a positive "
                             f"length [m], got {self.half_size!r}")
        if self.extent is not None:
            ext = as_array(self.extent, (2,), f"ReplaySupport {self.name!r}.extent")
            if not np.all(ext > 0):
                raise InputError(f"ReplaySupport {self.name!r}.extent: expected two positive "
                                 f"lengths [m], got {ext.tolist()}")
            x = as_array(self.x_axis, (3,), f"ReplaySupport {self.name!r}.x_axis")
            x = x - (x @ self.normal) * self.normal
            if np.linalg.norm(x) < 1e-9:
                raise InputError(f"ReplaySupport {self.name!r}.x_axis: along the normal")
            self.extent, self.x_axis = ext, x / np.linalg.norm(x)

    @property
    def rotation(self) -> np.ndarray | None:
        """(3, 3) the rectangle's axes ``[x_axis, normal × x_axis, normal]`` (columns, world).

        None without ``extent``.
        """
        if self.extent is None:
            return None
        return np.column_stack([self.x_axis, np.cross(self.normal, self.x_axis), self.normal])


EVENT_KINDS = CONTACT_EVENT_KINDS
"""The kinds of :class:`ReplayEvent`: those of the simulation's contact events."""


@dataclass(frozen=True)
class ReplayEvent:
    """A contact event shown on the replay's timeline.

    Attributes:
        t: time [s].
        kind: ``"separation"`` or ``"touchdown"``.
        contact: index of the contact in ``ReplayContacts`` (0 <= contact < K).
        impulse: the impact's contact impulse [N s] (0: none, e.g. a separation by force).
    """

    t: float
    kind: str
    contact: int
    impulse: float = 0.0


@dataclass
class ReplayContacts:
    """Contact points and forces over time (K contacts, fixed count).

    Attributes:
        points: (T, K, 3) contact points in the world [m].
        forces: (T, K, 3) force applied *on the object* at each point, world axes [N].
        touching: (T, K) bool, True where contact k touches (None: always touching).
        supports: support planes to draw (:class:`ReplaySupport`).
        labels: (K,) contact names, ``"<arm>:<contact>"`` or ``"<support>[j]"`` (None:
            ``"contact k"``); the timeline has one row per arm or support they name.
        events: the contact events (:class:`ReplayEvent`) marked on the timeline.
    """

    points: np.ndarray
    forces: np.ndarray
    touching: np.ndarray | None = None
    supports: Sequence[ReplaySupport] = ()
    labels: Sequence[str] | None = None
    events: Sequence[ReplayEvent] = ()

    def __post_init__(self):
        self.points = as_array(self.points, (None, None, 3), "ReplayContacts.points (T, K, 3)")
        self.forces = as_array(self.forces, self.points.shape, "ReplayContacts.forces (T, K, 3)")
        if self.touching is not None:
            tch = np.asarray(self.touching)
            if tch.shape != self.points.shape[:2] or tch.dtype != bool:
                raise InputError(f"ReplayContacts.touching: expected a bool array of shape "
                                 f"{self.points.shape[:2]}, got {tch.dtype} {tch.shape}")
            self.touching = tch
        for sp in self.supports:
            if not isinstance(sp, ReplaySupport):
                raise InputError(f"ReplayContacts.supports: expected ReplaySupport items, got "
                                 f"{type(sp).__name__}")
        K = self.points.shape[1]
        if self.labels is not None:
            labels = [str(x) for x in self.labels]
            if len(labels) != K:
                raise InputError(f"ReplayContacts.labels: expected {K} names (one per contact), "
                                 f"got {len(labels)}")
            self.labels = labels
        for e in self.events:
            if not isinstance(e, ReplayEvent):
                raise InputError(f"ReplayContacts.events: expected ReplayEvent items, got "
                                 f"{type(e).__name__}")
            if (e.kind not in EVENT_KINDS or not 0 <= e.contact < K or not math.isfinite(e.t)
                    or not math.isfinite(e.impulse)):
                raise InputError(f"ReplayContacts.events: {e} is not an event of one of the "
                                 f"{K} contacts (kinds {', '.join(EVENT_KINDS)}, finite time "
                                 "and impulse)")

    def support_points(self) -> dict[str, list[int]]:
        """The contacts of each support, by name: the ``k`` labelled ``"<support>[j]"``.

        Returns:
            support name -> contact indices in label order (supports without labelled
            contacts, or contacts without labels: left out).
        """
        out: dict[str, list[int]] = {}
        if self.labels is None:
            return out
        for sp in self.supports:
            ks = [k for k, lab in enumerate(self.labels) if lab.startswith(f"{sp.name}[")]
            if ks:
                out[sp.name] = ks
        return out


# ----------------------------------------------------------------------------- helpers
def frame_indices(t: np.ndarray, fps: float) -> np.ndarray:
    """Sample index shown at each animation frame.

    Args:
        t: (T,) strictly increasing sample times [s].
        fps: frames per second of the replay.

    Returns:
        (F,) int indices into ``t``: for frame ``k`` the sample nearest to
        ``t[0] + k / fps``, ``F = floor((t[-1] - t[0]) fps) + 1``.
    """
    duration = float(t[-1] - t[0])
    n_frames = int(math.floor(duration * fps + 1e-9)) + 1
    times = t[0] + np.arange(n_frames) / fps
    right = np.clip(np.searchsorted(t, times), 1, max(len(t) - 1, 1))
    left = right - 1
    if len(t) == 1:
        return np.zeros(n_frames, dtype=int)
    nearer_left = (times - t[left]) <= (t[right] - times)
    return np.where(nearer_left, left, right)


def polyhedron_triangles(poly: Polyhedron) -> np.ndarray:
    """(M, 3) int vertex indices of a fan triangulation of every face, outward-facing."""
    tris = []
    for face in poly.faces:
        for j in range(1, len(face) - 1):
            tris.append((face[0], face[j], face[j + 1]))
    return np.array(tris, dtype=np.uint32)


def check_replay_inputs(arms, obj, contacts, t, fps) -> np.ndarray:
    """The sample times ``t`` (T,) [s] once the parts agree with them and ``fps`` > 0.

    Raises:
        InputError: naming the part and what is wrong (row counts, names, types).
    """
    t = as_array(t, (None,), "t (T,) [s]")
    if len(t) == 0:
        raise InputError("t: expected at least one sample time, got an empty array")
    if np.any(np.diff(t) <= 0):
        raise InputError("t: sample times must be strictly increasing")
    if not (isinstance(fps, int | float) and fps > 0 and math.isfinite(fps)):
        raise InputError(f"fps: expected a positive number of frames per second, got {fps!r}")
    if isinstance(arms, ReplayArm) or not isinstance(arms, Sequence):
        raise InputError("arms: expected a list of ReplayArm")
    names = set()
    for arm in arms:
        if not isinstance(arm, ReplayArm):
            raise InputError(f"arms: expected ReplayArm items, got {type(arm).__name__}")
        if arm.name in names:
            raise InputError(f"arms: duplicate arm name {arm.name!r}")
        names.add(arm.name)
        if len(arm.q) != len(t):
            raise InputError(f"arm {arm.name!r}: q has {len(arm.q)} rows, t has {len(t)} samples")
    if obj is not None:
        if not isinstance(obj, ReplayObject):
            raise InputError(f"obj: expected a ReplayObject or None, got {type(obj).__name__}")
        if len(obj.position) != len(t):
            raise InputError(f"obj: position has {len(obj.position)} rows, "
                             f"t has {len(t)} samples")
    if contacts is not None:
        if not isinstance(contacts, ReplayContacts):
            raise InputError(f"contacts: expected ReplayContacts or None, "
                             f"got {type(contacts).__name__}")
        if len(contacts.points) != len(t):
            raise InputError(f"contacts: points have {len(contacts.points)} rows, "
                             f"t has {len(t)} samples")
    return t


__all__ = [
    "check_replay_inputs",
    "ReplayArm",
    "ReplayObject",
    "ReplaySupport",
    "ReplayContacts",
    "ReplayEvent",
    "EVENT_KINDS",
    "frame_indices",
    "polyhedron_triangles",
]
