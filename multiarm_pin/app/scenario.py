"""Scenario files: schema, validation (with did-you-mean) and building the system.

A scenario is a YAML file describing the object, the arms and how each is joined to the
object, the controller and the simulation settings (format in the README and issue 6)::

    name: two_ur5_box
    gravity: [0, 0, -9.81]                   # m/s^2, world
    object:
      shape: {type: box, size: [0.8, 0.4, 0.3]}     # or {type: polyhedron, vertices: [...]}
      mass: 4.0                              # kg; `inertia` (3x3 about the COM) optional
      pose: {position: [0.6, 0, 0.4], quaternion: [0, 0, 0, 1]}   # [x, y, z, w] or rpy
      twist: [0, 0, 0, 0, 0, 0]              # optional, [v; w] world axes
    arms:
      - name: left
        robot: ur5                           # or `urdf: path` (relative to this file)
        tool_frame: tool0
        base: {position: [0, 0.5, 0], rpy: [0, 0, 0]}
        q0: [...]                            # optional when the joint is placed in the object
        q_seed: [...]                        # IK seed when q0 is omitted
        joint: {type: weld}                  # or with placement_in_object: {...}
    controller: {type: none}
    simulation: {duration: 2.0, integrator: rk4, dt: 0.001, solver: auto,
                 baumgarte: {alpha: 5.0, beta: 5.0}}
    supports:                                # optional: fixed planes the object may rest on
      - name: table
        plane: {point: [0, 0, 0], normal: [0, 0, 1]}   # world; normal out of the support
        points: vertices                     # or a list of object-frame points [m]
        restitution: 0.0                     # 0 <= e <= 1

The object may carry ``external_wrench: [{from: s, to: s, wrench: [fx, fy, fz, mx, my,
mz]}]`` (at the COM, world axes [N, N m], over each interval). A joint may say ``unilateral:
true/false`` to override its contacts' default (``fingertips`` and ``corner_gripper`` push
only; the mechanical joints are bilateral). ``arms`` may be empty when there are supports.

Joint types (the placeable entries of :data:`~multiarm_pin.constraints.JOINT_TYPES`):
``weld``, ``revolute``, ``prismatic``, ``cylindrical``, ``universal``, ``spherical``,
``corner_gripper`` (parameters ``size``, ``tip_radius``, ``points_on`` (not for
``corner_gripper``), and optionally ``placement_in_object`` / ``placement_in_tool`` of the
joint frame), and ``fingertips`` (spherical fingertips on named faces: ``tip_radius`` and
``contacts: [{tip: frame, face: +x, point: [..]}, ...]``; the old name ``contacts`` is still
read, with a deprecation warning). Without ``placement_in_object`` a joint is built where
the tool is at ``q0``. Without ``q0`` the arm is placed by inverse kinematics
(:mod:`multiarm_pin.model.ik`) from ``q_seed``, meeting only what the joint constrains (the
centre of a spherical joint; centre and axis of a revolute one; axis and line of a
cylindrical one; the full placement of weld, prismatic and universal joints; each fingertip
touching its face, as near to the given point as the gripper allows), near the seed.

Files are read strictly (:mod:`multiarm_pin.app.yaml_strict`: UTF-8, no duplicate keys). Every
error is a :class:`~multiarm_pin.exceptions.ScenarioError` naming the file, the key path
(``arms[1].joint.type``) and what was expected; ``q0`` outside the joint limits is one
(:mod:`multiarm_pin.app.scenario_checks`).
"""

from __future__ import annotations

import difflib
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from multiarm_pin.constraints.joint_types import JOINT_TYPES
from multiarm_pin.dynamics import SOLVERS
from multiarm_pin.exceptions import (
    FrameNotFoundError,
    JointNotFoundError,
    MultiArmError,
    RobotNotFoundError,
    ScenarioError,
    URDFError,
)
from multiarm_pin.sim.controllers import CONTROLLERS
from multiarm_pin.sim.simulation import INTEGRATORS

JOINT_TYPE_NAMES = tuple(k for k, e in JOINT_TYPES.items() if e.placeable)
"""Joint types a scenario may name: the placeable entries of the registry (not ``custom``)."""
DEPRECATED_JOINT_TYPES = {"contacts": "fingertips"}
"""Old joint type names still read (with a warning), and the name that replaced them."""
CONTROLLER_TYPES = tuple(CONTROLLERS)
"""Controller types a scenario may name (:data:`multiarm_pin.sim.controllers.CONTROLLERS`)."""
INTEGRATOR_NAMES = tuple(INTEGRATORS)
"""Integrators a scenario may name (:data:`multiarm_pin.sim.simulation.INTEGRATORS`)."""
SOLVER_NAMES = tuple(SOLVERS)
"""Forward-dynamics solvers a scenario may name (:data:`multiarm_pin.dynamics.SOLVERS`)."""
INITIAL_GAP_TOLERANCE = 1e-6
"""Largest gap [m] of any contact in the initial state."""

REPO_ROOT = Path(__file__).resolve().parents[2]


# ----------------------------------------------------------------------------- data
@dataclass(frozen=True)
class ObjectSpec:
    """The object as read from a scenario.

    Attributes:
        shape_type: ``"box"`` or ``"polyhedron"``.
        size: (3,) box edge lengths [m] (box only).
        vertices: (V, 3) vertices in the object (COM) frame [m] (polyhedron only).
        mass: [kg].
        inertia: (3, 3) about the COM in object axes [kg m^2], or None (uniform density).
        position: (3,) initial COM position in the world [m].
        quaternion: (4,) initial orientation ``[x, y, z, w]``.
        twist: (6,) initial ``[ẋ; ω]`` in world axes [m/s, rad/s].
        external_wrench: ``((from, to, wrench (6,)), ...)``: a wrench ``[f; m]`` at the COM
            in world axes [N, N m] for ``from <= t < to`` [s].
    """

    shape_type: str
    size: np.ndarray | None
    vertices: np.ndarray | None
    mass: float
    inertia: np.ndarray | None
    position: np.ndarray
    quaternion: np.ndarray
    twist: np.ndarray
    external_wrench: tuple = ()

    @property
    def placement(self) -> pin.SE3:
        """Initial world placement of the object (COM) frame."""
        return pin.SE3(pin.Quaternion(self.quaternion).toRotationMatrix(), self.position)


@dataclass(frozen=True)
class SupportSpec:
    """A support as read from a scenario.

    Attributes:
        name: unique name. point: (3,) a point of the plane, world [m]. normal: (3,) unit
        normal out of the support, world axes. points: ``"vertices"`` or (P, 3) points in
        the object frame [m]. restitution: Newton's coefficient, 0..1. index: position in
        the file's ``supports`` list.
    """

    name: str
    point: np.ndarray
    normal: np.ndarray
    points: str | np.ndarray
    restitution: float
    index: int


@dataclass(frozen=True)
class ContactSpec:
    """One fingertip contact of a ``fingertips`` joint.

    Attributes:
        tip: frame name of the fingertip's sphere centre in the arm's model.
        face: face name (``+x`` ...) or index of the object's polyhedron.
        point: (3,) desired contact point on that face, object frame [m], or None (the
            face's centre is used as a preference).
    """

    tip: str
    face: str | int
    point: np.ndarray | None


@dataclass(frozen=True)
class JointSpec:
    """How an arm is joined to the object.

    Attributes:
        type: one of :data:`JOINT_TYPE_NAMES`.
        params: extra parameters of the joint library (``size``, ``tip_radius``, ...).
        placement_in_object: joint frame in the object frame, or None (tool at ``q0``).
        placement_in_tool: joint frame in the tool frame, or None (identity).
        contacts: fingertip contacts (``fingertips`` type only).
    """

    type: str
    params: dict = field(default_factory=dict)
    placement_in_object: pin.SE3 | None = None
    placement_in_tool: pin.SE3 | None = None
    contacts: tuple[ContactSpec, ...] = ()


@dataclass(frozen=True)
class ArmSpec:
    """One arm as read from a scenario.

    Attributes:
        name: unique name.
        robot: ``example_robot_data`` name, or None.
        urdf: absolute URDF path, or None.
        tool_frame: frame the tool is attached to (None: the robot's default).
        tool_offset: tool placement relative to ``tool_frame`` (None: identity).
        base: world placement of the robot's root.
        locked_joints: joints locked at their neutral value (URDF arms).
        q0: (nq,) initial configuration, or None (inverse kinematics).
        q_seed: (nq,) seed of the inverse kinematics, or None (neutral).
        v0: (nv,) initial joint velocities, or None (zero).
        joint: the joint to the object.
        index: position in the file's ``arms`` list.
    """

    name: str
    robot: str | None
    urdf: str | None
    tool_frame: str | None
    tool_offset: pin.SE3 | None
    base: pin.SE3
    locked_joints: tuple[str, ...]
    q0: np.ndarray | None
    q_seed: np.ndarray | None
    v0: np.ndarray | None
    joint: JointSpec
    index: int


@dataclass(frozen=True)
class ControllerSpec:
    """Controller type and its parameters (passed to ``make_controller``)."""

    type: str
    params: dict = field(default_factory=dict)


@dataclass(frozen=True)
class SimulationSpec:
    """Simulation settings.

    Attributes:
        duration: [s]. integrator: one of :data:`INTEGRATOR_NAMES`. dt: step and output sampling
        period [s]. solver: one of :data:`SOLVER_NAMES`. baumgarte: ``(α, β)`` [1/s].
    """

    duration: float = 2.0
    integrator: str = "rk4"
    dt: float = 1e-3
    solver: str = "auto"  # object-first, switching to the singular-arm variant when needed
    baumgarte: tuple[float, float] = (5.0, 5.0)


@dataclass(frozen=True)
class Scenario:
    """A validated scenario file.

    Attributes:
        name: scenario name. file: where it was read from. description: free text.
        gravity: (3,) [m/s^2] world. object: :class:`ObjectSpec`. arms: the arms.
        controller: :class:`ControllerSpec`. simulation: :class:`SimulationSpec`.
        data: the parsed YAML mapping (URDF paths made absolute), for copying the scenario.
    """

    name: str
    file: str
    description: str
    gravity: np.ndarray
    object: ObjectSpec
    arms: tuple[ArmSpec, ...]
    controller: ControllerSpec
    simulation: SimulationSpec
    data: dict
    supports: tuple[SupportSpec, ...] = ()


# ----------------------------------------------------------------------------- validation
def did_you_mean(word: str, options: Sequence[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``options``, or an empty string."""
    close = difflib.get_close_matches(str(word), [str(o) for o in options], n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


class _Reader:
    """Reads one YAML value with its key path; every failure is a ScenarioError."""

    def __init__(self, file: str, path: str, value):
        self.file, self.path, self.value = file, path, value

    def error(self, message: str, key: str | None = None) -> ScenarioError:
        return ScenarioError(self.file, key if key is not None else self.path, message)

    def child(self, key, value) -> _Reader:
        if isinstance(key, int):
            return _Reader(self.file, f"{self.path}[{key}]", value)
        return _Reader(self.file, f"{self.path}.{key}" if self.path else str(key), value)

    def mapping(self, allowed: Sequence[str], required: Sequence[str] = ()) -> dict:
        if not isinstance(self.value, Mapping):
            raise self.error(f"expected a mapping with keys {', '.join(allowed)}, got "
                             f"{_describe(self.value)}")
        for k in self.value:
            if k not in allowed:
                raise self.error(
                    f"unknown key {k!r}{did_you_mean(k, allowed)}; expected keys: "
                    f"{', '.join(allowed)}",
                    self.child(k, None).path,
                )
        for k in required:
            if k not in self.value:
                raise self.error(f"missing required key {k!r}", self.child(k, None).path)
        return dict(self.value)

    def get(self, key: str) -> _Reader:
        return self.child(key, self.value.get(key) if isinstance(self.value, Mapping) else None)

    def string(self, choices: Sequence[str] | None = None) -> str:
        if not isinstance(self.value, str):
            what = f"one of {', '.join(choices)}" if choices else "a string"
            raise self.error(f"expected {what}, got {_describe(self.value)}")
        if choices is not None and self.value not in choices:
            raise self.error(f"unknown value {self.value!r}{did_you_mean(self.value, choices)}; "
                             f"expected one of {', '.join(choices)}")
        return self.value

    def number(self, positive: bool = False, nonnegative: bool = False) -> float:
        v = self.value
        if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v):
            raise self.error(f"expected a number, got {_describe(v)}")
        if positive and v <= 0:
            raise self.error(f"expected a positive number, got {v}")
        if nonnegative and v < 0:
            raise self.error(f"expected a number >= 0, got {v}")
        return float(v)

    def array(self, shape: Sequence[int | None], meaning: str = "") -> np.ndarray:
        exp = _shape_text(shape) + (f" ({meaning})" if meaning else "")
        v = self.value
        if isinstance(v, str | bytes | Mapping) or v is None or isinstance(v, bool):
            raise self.error(f"expected a list of numbers of shape {exp}, got {_describe(v)}")
        try:
            arr = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            raise self.error(f"expected numbers of shape {exp}, got {_describe(v)}") from None
        if arr.ndim != len(shape) or any(
            s is not None and s != n for s, n in zip(shape, arr.shape, strict=False)
        ):
            if len(shape) == 1 and arr.ndim == 1:
                raise self.error(f"expected {shape[0]} numbers {exp}, got {arr.shape[0]}: "
                                 f"{arr.tolist()}")
            raise self.error(f"expected shape {exp}, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise self.error(f"expected finite numbers, got {arr.tolist()}")
        return arr

    def quaternion(self) -> np.ndarray:
        q = self.array((4,), "[x, y, z, w]")
        n = float(np.linalg.norm(q))
        if abs(n - 1.0) > 1e-6:
            raise self.error(f"expected a unit quaternion [x, y, z, w], got norm {n:.9g}: "
                             f"{q.tolist()}")
        return q / n

    def placement(self) -> pin.SE3:
        d = self.mapping(("position", "quaternion", "rpy"))
        if "quaternion" in d and "rpy" in d:
            raise self.error("give only one of quaternion [x, y, z, w] or rpy")
        p = self.get("position").array((3,), "m") if "position" in d else np.zeros(3)
        if "quaternion" in d:
            R = pin.Quaternion(self.get("quaternion").quaternion()).toRotationMatrix()
        elif "rpy" in d:
            r = self.get("rpy").array((3,), "roll, pitch, yaw [rad]")
            R = pin.rpy.rpyToMatrix(*r)
        else:
            R = np.eye(3)
        return pin.SE3(R, p)


def _describe(v) -> str:
    if isinstance(v, Mapping):
        return f"a mapping with keys {list(v)}"
    if isinstance(v, list | tuple):
        return f"a list of {len(v)}: {v!r}"[:120]
    return f"{type(v).__name__} {v!r}"[:120]


def _shape_text(shape) -> str:
    inner = ", ".join("n" if s is None else str(s) for s in shape)
    return f"({inner},)" if len(shape) == 1 else f"({inner})"


_TOP_KEYS = ("name", "description", "gravity", "object", "arms", "controller", "simulation",
             "supports")
_OBJECT_KEYS = ("shape", "mass", "inertia", "pose", "twist", "external_wrench")
_ARM_KEYS = ("name", "robot", "urdf", "tool_frame", "tool_offset", "base", "locked_joints",
             "q0", "q_seed", "v0", "joint")
_JOINT_KEYS = ("type", "size", "tip_radius", "points_on", "placement_in_object",
               "placement_in_tool", "contacts", "unilateral")
_SIM_KEYS = ("duration", "integrator", "dt", "solver", "baumgarte")


def load_scenario(path) -> Scenario:
    """Read and validate a scenario YAML file.

    Args:
        path: the file.

    Returns:
        The :class:`Scenario` (no robot loaded yet; see :func:`build_scenario`).

    Raises:
        ScenarioError: unreadable or non-UTF-8 file, YAML syntax error, a duplicate key
            (naming both lines), or invalid content (names the key path and what was
            expected).
    """
    from multiarm_pin.app.yaml_strict import load_yaml_file

    path = Path(path)
    return parse_scenario(load_yaml_file(path), str(path))


def parse_scenario(data, file: str = "<scenario>") -> Scenario:
    """Validate a parsed scenario mapping.

    Args:
        data: the mapping read from YAML.
        file: the file it came from (for messages and to resolve relative URDF paths).

    Raises:
        ScenarioError: invalid content.
    """
    root = _Reader(file, "", data)
    d = root.mapping(_TOP_KEYS, required=("object", "arms"))
    name = root.get("name").string() if "name" in d else Path(file).stem
    description = root.get("description").string() if "description" in d else ""
    gravity = (root.get("gravity").array((3,), "m/s^2") if "gravity" in d
               else np.array([0.0, 0.0, -9.81]))
    obj = _parse_object(root.get("object"))
    supports = _parse_supports(root.get("supports")) if "supports" in d else ()
    arms_r = root.get("arms")
    if not isinstance(arms_r.value, list) or (not arms_r.value and not supports):
        raise arms_r.error(f"expected a non-empty list of arms (or an empty list with "
                           f"supports), got {_describe(arms_r.value)}")
    base_dir = Path(file).resolve().parent
    arms = tuple(_parse_arm(arms_r.child(i, a), i, base_dir) for i, a in enumerate(arms_r.value))
    names = [a.name for a in arms]
    for i, n in enumerate(names):
        if names.index(n) != i:
            raise arms_r.child(i, None).error(f"duplicate arm name {n!r}; names must be unique",
                                              f"arms[{i}].name")
    controller = _parse_controller(root.get("controller"), obj) if "controller" in d else \
        ControllerSpec("none")
    sim = _parse_simulation(root.get("simulation")) if "simulation" in d else SimulationSpec()
    clean = dict(d)
    clean["arms"] = [dict(a) for a in d["arms"]]
    for a, spec in zip(clean["arms"], arms, strict=True):
        if spec.urdf is not None:
            a["urdf"] = spec.urdf
    return Scenario(name, file, description, gravity, obj, arms, controller, sim, clean,
                    supports)


def _parse_supports(r: _Reader) -> tuple[SupportSpec, ...]:
    if not isinstance(r.value, list):
        raise r.error(f"expected a list of supports {{name, plane, points, restitution}}, got "
                      f"{_describe(r.value)}")
    out, names = [], []
    for k, item in enumerate(r.value):
        c = r.child(k, item)
        d = c.mapping(("name", "plane", "points", "restitution"), required=("plane", "points"))
        name = c.get("name").string() if "name" in d else f"support{k}"
        if name in names:
            raise c.get("name").error(f"duplicate support name {name!r}; names must be unique")
        names.append(name)
        pr = c.get("plane")
        pr.mapping(("point", "normal"), required=("point", "normal"))
        point = pr.get("point").array((3,), "world point [m]")
        normal = pr.get("normal").array((3,), "world direction out of the support")
        if np.linalg.norm(normal) < 1e-9:
            raise pr.get("normal").error(f"the normal has zero length ({normal.tolist()}); "
                                         "expected a direction pointing out of the support")
        ptr = c.get("points")
        if isinstance(ptr.value, str):
            if ptr.value != "vertices":
                raise ptr.error(f"expected 'vertices' or a list of [x, y, z] points in the "
                                f"object frame [m], got {ptr.value!r}")
            points = "vertices"
        else:
            points = ptr.array((None, 3), "points in the object frame [m]")
            if len(points) == 0:
                raise ptr.error("expected at least one [x, y, z] point (object frame [m])")
        e = 0.0
        if "restitution" in d:
            er = c.get("restitution")
            e = er.number(nonnegative=True)
            if e > 1.0:
                raise er.error(f"expected a coefficient of restitution in [0, 1], got {e}")
        out.append(SupportSpec(name, point, normal / np.linalg.norm(normal), points, e, k))
    return tuple(out)


def _parse_object(r: _Reader) -> ObjectSpec:
    d = r.mapping(_OBJECT_KEYS, required=("shape", "mass"))
    sr = r.get("shape")
    sd = sr.mapping(("type", "size", "vertices"), required=("type",))
    kind = sr.get("type").string(("box", "polyhedron"))
    size = vertices = None
    if kind == "box":
        if "size" not in sd:
            raise sr.error("missing required key 'size' (3 edge lengths [m])", f"{sr.path}.size")
        size = sr.get("size").array((3,), "edge lengths [m]")
        if np.any(size <= 0):
            raise sr.get("size").error(f"expected three positive lengths [m], got {size.tolist()}")
    else:
        if "vertices" not in sd:
            raise sr.error("missing required key 'vertices' ((V, 3) [m])", f"{sr.path}.vertices")
        vertices = sr.get("vertices").array((None, 3), "vertices [m]")
    mass = r.get("mass").number(positive=True)
    inertia = r.get("inertia").array((3, 3), "kg m^2 about the COM") if "inertia" in d else None
    position, quaternion = np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])
    if "pose" in d:
        pr = r.get("pose")
        M = pr.placement()
        position = M.translation.copy()
        quaternion = pin.Quaternion(M.rotation).coeffs().copy()
    twist = r.get("twist").array((6,), "[v; w] world axes") if "twist" in d else np.zeros(6)
    wrenches = []
    if "external_wrench" in d:
        wr = r.get("external_wrench")
        if not isinstance(wr.value, list):
            raise wr.error(f"expected a list of {{from, to, wrench}}, got {_describe(wr.value)}")
        for k, item in enumerate(wr.value):
            c = wr.child(k, item)
            c.mapping(("from", "to", "wrench"), required=("from", "to", "wrench"))
            a = c.get("from").number(nonnegative=True)
            b = c.get("to").number(nonnegative=True)
            if b <= a:
                raise c.get("to").error(f"expected to > from = {a} [s], got {b}")
            w = c.get("wrench").array((6,), "[fx, fy, fz, mx, my, mz] at the COM, world [N, N m]")
            wrenches.append((a, b, w))
    return ObjectSpec(kind, size, vertices, mass, inertia, position, quaternion, twist,
                      tuple(wrenches))


def _parse_arm(r: _Reader, index: int, base_dir: Path) -> ArmSpec:
    d = r.mapping(_ARM_KEYS, required=("joint",))
    name = r.get("name").string() if "name" in d else f"arm{index}"
    if "/" in name or not name:
        raise r.get("name").error(f"expected a non-empty name without '/', got {name!r}")
    if ("robot" in d) == ("urdf" in d):
        raise r.error("give exactly one of 'robot' (an example_robot_data name) or 'urdf' "
                      "(a path)")
    robot = r.get("robot").string() if "robot" in d else None
    urdf = None
    if "urdf" in d:
        raw = Path(r.get("urdf").string())
        candidates = [raw] if raw.is_absolute() else [base_dir / raw, REPO_ROOT / raw]
        found = next((c for c in candidates if c.is_file()), None)
        if found is None:
            raise r.get("urdf").error(
                f"URDF file not found (looked at {', '.join(str(c) for c in candidates)})")
        urdf = str(found.resolve())
    tool_frame = r.get("tool_frame").string() if "tool_frame" in d else None
    if urdf is not None and tool_frame is None:
        raise r.error("a URDF arm needs 'tool_frame'", f"{r.path}.tool_frame")
    tool_offset = r.get("tool_offset").placement() if "tool_offset" in d else None
    base = r.get("base").placement() if "base" in d else pin.SE3.Identity()
    locked = ()
    if "locked_joints" in d:
        lr = r.get("locked_joints")
        if not isinstance(lr.value, list):
            raise lr.error(f"expected a list of joint names, got {_describe(lr.value)}")
        locked = tuple(lr.child(k, v).string() for k, v in enumerate(lr.value))
    q0 = r.get("q0").array((None,), "joint positions [rad]") if "q0" in d else None
    q_seed = r.get("q_seed").array((None,), "joint positions [rad]") if "q_seed" in d else None
    v0 = r.get("v0").array((None,), "joint velocities [rad/s]") if "v0" in d else None
    joint = _parse_joint(r.get("joint"))
    if q0 is None and joint.placement_in_object is None and \
            not JOINT_TYPES[joint.type].from_contacts:
        raise r.error(
            "give q0, or place the joint in the object (joint.placement_in_object) so that "
            "inverse kinematics can put the arm there", f"{r.path}.q0")
    return ArmSpec(name, robot, urdf, tool_frame, tool_offset, base, locked, q0, q_seed, v0,
                   joint, index)


def _parse_joint(r: _Reader) -> JointSpec:
    d = r.mapping(_JOINT_KEYS, required=("type",))
    kind = r.get("type").string((*JOINT_TYPE_NAMES, *DEPRECATED_JOINT_TYPES))
    if kind in DEPRECATED_JOINT_TYPES:
        kind = DEPRECATED_JOINT_TYPES[kind]
        warnings.warn(f"{r.file}: {r.path}.type: {r.value['type']!r} is deprecated; write "
                      f"{kind!r}", FutureWarning, stacklevel=2)
    fingertips = JOINT_TYPES[kind].from_contacts
    params = {}
    if "unilateral" in d:
        if not isinstance(d["unilateral"], bool):
            raise r.get("unilateral").error(f"expected true or false, got "
                                            f"{_describe(d['unilateral'])}")
        params["unilateral"] = d["unilateral"]
    for key in ("size", "tip_radius"):
        if key in d:
            params[key] = r.get(key).number(positive=(key == "size"), nonnegative=True)
    if "points_on" in d:
        if "points_on" not in JOINT_TYPES[kind].parameters:
            raise r.get("points_on").error(f"not a parameter of {kind!r} joints")
        params["points_on"] = r.get("points_on").string(("tool", "object"))
    if fingertips:
        for key in ("placement_in_object", "placement_in_tool", "size"):
            if key in d:
                raise r.get(key).error(
                    f"not a parameter of {kind!r} joints (expected contacts, tip_radius)")
        if "contacts" not in d:
            raise r.error("missing required key 'contacts' (list of {tip, face, point})",
                          f"{r.path}.contacts")
        cr = r.get("contacts")
        if not isinstance(cr.value, list) or not cr.value:
            raise cr.error(f"expected a non-empty list of {{tip, face, point}}, got "
                           f"{_describe(cr.value)}")
        contacts = []
        for k, c in enumerate(cr.value):
            cc = cr.child(k, c)
            cd = cc.mapping(("tip", "face", "point"), required=("tip", "face"))
            face = cd["face"]
            if isinstance(face, bool) or not isinstance(face, str | int):
                raise cc.get("face").error(f"expected a face name (e.g. +x) or index, got "
                                           f"{_describe(face)}")
            point = cc.get("point").array((3,), "object frame [m]") if "point" in cd else None
            contacts.append(ContactSpec(cc.get("tip").string(), face, point))
        return JointSpec(kind, params, contacts=tuple(contacts))
    if "contacts" in d:
        raise r.get("contacts").error(f"only 'fingertips' joints take contacts, not {kind!r}")
    J_o = r.get("placement_in_object").placement() if "placement_in_object" in d else None
    J_t = r.get("placement_in_tool").placement() if "placement_in_tool" in d else None
    return JointSpec(kind, params, J_o, J_t)


def _controller_keys(kind: str) -> tuple[str, ...]:
    """Keyword parameters accepted by the controller class of ``kind`` (besides system)."""
    return CONTROLLERS[kind].parameters


def _parse_controller(r: _Reader, obj: ObjectSpec) -> ControllerSpec:
    """Controller type and parameters; object_pd ``waypoints`` become its ``trajectory``.

    ``waypoints: [{t: s, position: [..], quaternion: [..] | rpy: [..]}, ...]`` are world
    poses of the object's COM frame; the initial pose is prepended at t = 0 when the first
    waypoint is later.
    """
    if not isinstance(r.value, Mapping):
        raise r.error(f"expected a mapping with 'type', got {_describe(r.value)}")
    if "type" not in r.value:
        raise r.error("missing required key 'type'", f"{r.path}.type")
    kind = r.get("type").string(CONTROLLER_TYPES)
    allowed = ("type", *_controller_keys(kind))  # object_pd's include waypoints
    d = r.mapping(allowed)
    params = {k: v for k, v in d.items() if k not in ("type", "waypoints")}
    if "waypoints" in d:
        if "trajectory" in d:
            raise r.get("waypoints").error("give either waypoints or trajectory, not both")
        wr = r.get("waypoints")
        if not isinstance(wr.value, list) or not wr.value:
            raise wr.error(f"expected a non-empty list of {{t, position, quaternion|rpy}}, got "
                           f"{_describe(wr.value)}")
        times, positions, quats = [], [], []
        for k, w in enumerate(wr.value):
            c = wr.child(k, w)
            c.mapping(("t", "position", "quaternion", "rpy"), required=("t", "position"))
            t = c.get("t").number(nonnegative=True)
            if times and t <= times[-1]:
                raise c.get("t").error(f"waypoint times must increase strictly; {t} after "
                                       f"{times[-1]}")
            M = _Reader(c.file, c.path, {k2: v for k2, v in w.items() if k2 != "t"}).placement()
            times.append(t)
            positions.append(M.translation.copy())
            quats.append(pin.Quaternion(M.rotation).coeffs().copy())
        if times[0] > 0:
            times.insert(0, 0.0)
            positions.insert(0, obj.position.copy())
            quats.insert(0, obj.quaternion.copy())
        params["trajectory"] = {"times": np.array(times), "positions": np.array(positions),
                                "quaternions": np.array(quats)}
    return ControllerSpec(kind, params)


def _parse_simulation(r: _Reader) -> SimulationSpec:
    d = r.mapping(_SIM_KEYS)
    s = SimulationSpec()
    duration = r.get("duration").number(positive=True) if "duration" in d else s.duration
    integrator = (r.get("integrator").string(INTEGRATOR_NAMES) if "integrator" in d
                  else s.integrator)
    dt = r.get("dt").number(positive=True) if "dt" in d else s.dt
    solver = r.get("solver").string(SOLVER_NAMES) if "solver" in d else s.solver
    baum = s.baumgarte
    if "baumgarte" in d:
        br = r.get("baumgarte")
        bd = br.mapping(("alpha", "beta"), required=("alpha", "beta"))
        del bd
        baum = (br.get("alpha").number(nonnegative=True), br.get("beta").number(nonnegative=True))
    if dt > duration:
        raise r.get("dt").error(f"dt = {dt} s is longer than the duration {duration} s")
    return SimulationSpec(duration, integrator, dt, solver, baum)


# ----------------------------------------------------------------------------- building
def build_object(scenario: Scenario):
    """The :class:`~multiarm_pin.model.rigid_object.RigidObject` of a scenario.

    Raises:
        ScenarioError: invalid shape/inertia (key ``object.*``).
    """
    from multiarm_pin.model.rigid_object import RigidObject

    o = scenario.object
    try:
        if o.shape_type == "box":
            return RigidObject.box(o.size, o.mass, o.inertia)
        return RigidObject.from_vertices(o.vertices, o.mass, o.inertia)
    except MultiArmError as exc:
        key = "object.inertia" if o.inertia is not None and "inertia" in str(exc) else \
            "object.shape"
        raise ScenarioError(scenario.file, key, str(exc)) from exc


def build_arm(scenario: Scenario, spec: ArmSpec, load_visuals: bool = True):
    """Load one arm (:class:`~multiarm_pin.model.arm.Arm`) with its base placement and tool frame.

    Raises:
        ScenarioError: unknown robot (``arms[i].robot``, did-you-mean), missing tool frame
            (``arms[i].tool_frame``), bad URDF (``arms[i].urdf``) or locked joints.
    """
    from multiarm_pin.model.arm import Arm, available_robots

    key = f"arms[{spec.index}]"
    try:
        if spec.robot is not None:
            return Arm.from_robot_name(spec.robot, spec.tool_frame, name=spec.name,
                                       base_placement=spec.base, tool_offset=spec.tool_offset,
                                       locked_joints=spec.locked_joints,
                                       load_visuals=load_visuals)
        return Arm.from_urdf(spec.urdf, spec.tool_frame, name=spec.name,
                             base_placement=spec.base, tool_offset=spec.tool_offset,
                             locked_joints=spec.locked_joints, load_visuals=load_visuals)
    except RobotNotFoundError as exc:
        raise ScenarioError(
            scenario.file, f"{key}.robot",
            f"unknown robot {spec.robot!r}{did_you_mean(spec.robot, available_robots())}; "
            f"available robots: {', '.join(available_robots())} (or give 'urdf: path')",
        ) from exc
    except FrameNotFoundError as exc:
        frames = [f for f in exc.available if f != "universe"]
        raise ScenarioError(
            scenario.file, f"{key}.tool_frame",
            f"frame {exc.frame!r} not found in {exc.source}{did_you_mean(exc.frame, frames)}; "
            f"frames: {', '.join(frames)}",
        ) from exc
    except URDFError as exc:
        raise ScenarioError(scenario.file, f"{key}.urdf", str(exc)) from exc
    except JointNotFoundError as exc:
        raise ScenarioError(scenario.file, f"{key}.locked_joints", str(exc)) from exc
    except MultiArmError as exc:
        raise ScenarioError(scenario.file, key, str(exc)) from exc


@dataclass
class BuiltScenario:
    """A scenario turned into a system ready to simulate.

    Attributes:
        scenario: the validated file.
        arms: the loaded arms (base placements baked in).
        obj: the rigid object.
        joints: one joint per arm.
        system: the :class:`~multiarm_pin.system.MultiArmSystem`.
        initial_state: the validated initial :class:`~multiarm_pin.system.SystemState`.
        q0: per-arm initial configurations (nq_i,), given or found by inverse kinematics.
        ik: per-arm :class:`~multiarm_pin.model.ik.IKResult` (None where ``q0`` was given).
    """

    scenario: Scenario
    arms: list
    obj: object
    joints: list
    system: object
    initial_state: object
    q0: list
    ik: list


def _placed_target(spec: ArmSpec, oMo: pin.SE3) -> pin.SE3:
    J_t = spec.joint.placement_in_tool or pin.SE3.Identity()
    return oMo * spec.joint.placement_in_object * J_t.inverse()


def _tips_in_tool(scenario, spec: ArmSpec, arm) -> np.ndarray:
    """(K, 3) fingertip centres in the tool frame, from the arm's (rigid) tip frames."""
    q = arm.neutral()
    oMt = arm.tool_placement(q)
    out = []
    for k, c in enumerate(spec.joint.contacts):
        if not arm.model.existFrame(c.tip):
            frames = [f for f in arm.frame_names if f != "universe"]
            raise ScenarioError(
                scenario.file, f"arms[{spec.index}].joint.contacts[{k}].tip",
                f"frame {c.tip!r} not found in {arm.source}{did_you_mean(c.tip, frames)}; "
                f"frames: {', '.join(frames)}")
        out.append(oMt.actInv(arm.frame_placement(q, c.tip).translation))
    return np.array(out)


def _contact_targets(scenario, spec: ArmSpec, poly, oMo: pin.SE3):
    """IK targets for fingertips on faces: a plane per tip (primary), a point (preference)."""
    from multiarm_pin.model.ik import PlaneTarget, PointTarget

    r = spec.joint.params.get("tip_radius", 0.0)
    targets = []
    for k, c in enumerate(spec.joint.contacts):
        key = f"arms[{spec.index}].joint.contacts[{k}]"
        try:
            f = poly.face_index(c.face)
        except MultiArmError as exc:
            raise ScenarioError(scenario.file, f"{key}.face", str(exc)) from exc
        n_o, d_o = poly.normals[f], poly.offsets[f]
        if c.point is not None:
            if not poly.point_on_face(c.point, f, 1e-6):
                raise ScenarioError(
                    scenario.file, f"{key}.point",
                    f"point {c.point.tolist()} is not on face {c.face!r} (distance to its "
                    f"plane {poly.signed_distance_to_face(c.point, f):.3g} m) or lies outside")
            p_o = c.point
        else:
            p_o = poly.vertices[list(poly.faces[f])].mean(axis=0)
        n_w = oMo.rotation @ n_o
        # sphere centre on the plane offset by the radius along the outward normal
        d_w = float(n_w @ oMo.translation) + d_o + r
        targets.append(PlaneTarget(c.tip, n_w, d_w))
        targets.append(PointTarget(c.tip, oMo.act(p_o + r * n_o), primary=False))
    return targets


def _joint_targets(spec: ArmSpec, tool: str, oMo: pin.SE3) -> tuple[list, str]:
    """IK targets of a placed joint: only what the joint constrains.

    The joint frame ``J_t`` on the tool must meet ``J_o`` on the object: its origin alone for
    a spherical joint; origin and z axis for a revolute one; z axis and the origin on the z
    line for a cylindrical one; the full placement for weld, prismatic and universal.

    Returns:
        ``(targets, description)``.
    """
    from multiarm_pin.model.ik import AxisTarget, PlaneTarget, PointTarget, PoseTarget

    J_t = spec.joint.placement_in_tool or pin.SE3.Identity()
    oMj = oMo * spec.joint.placement_in_object
    kind = spec.joint.type
    o, z = J_t.translation, J_t.rotation[:, 2]
    if kind == "spherical":
        return [PointTarget(tool, oMj.translation, offset=o)], "joint centre at its point"
    if kind == "revolute":
        return ([PointTarget(tool, oMj.translation, offset=o),
                 AxisTarget(tool, z, oMj.rotation[:, 2])], "joint centre and axis")
    if kind == "cylindrical":
        R, p = oMj.rotation, oMj.translation
        return ([AxisTarget(tool, z, R[:, 2]),
                 PlaneTarget(tool, R[:, 0], float(R[:, 0] @ p), point=o),
                 PlaneTarget(tool, R[:, 1], float(R[:, 1] @ p), point=o)],
                "joint axis on its line")
    return [PoseTarget(tool, _placed_target(spec, oMo))], "tool at joint.placement_in_object"


def _solve_arm_ik(scenario, spec: ArmSpec, arm, poly, oMo):
    from multiarm_pin.model.ik import PostureTarget, UnreachableError, solve_ik

    seed = spec.q_seed
    if seed is not None and len(seed) != arm.nq:
        raise ScenarioError(scenario.file, f"arms[{spec.index}].q_seed",
                            f"expected {arm.nq} numbers (nq of {arm.source}), got {len(seed)}")
    if JOINT_TYPES[spec.joint.type].from_contacts:
        targets = _contact_targets(scenario, spec, poly, oMo)
        what = f"arm {spec.name!r}: fingertips on faces"
        key = f"arms[{spec.index}].joint.contacts"
    else:
        tool = arm.model.frames[arm.tool_frame_id].name
        targets, goal = _joint_targets(spec, tool, oMo)
        what = f"arm {spec.name!r} ({spec.joint.type} joint): {goal}"
        key = f"arms[{spec.index}].joint.placement_in_object"
        # among the configurations meeting the joint, prefer one near the seed (fingertips
        # have their points as preferences instead: those fix the gripper)
        targets.append(PostureTarget(seed if seed is not None else arm.neutral()))
    try:
        return solve_ik(arm.model, targets, seed, what=what)
    except UnreachableError as exc:
        raise ScenarioError(scenario.file, key,
                            f"{exc} (try another q_seed, or move the arm's base)") from exc


def _build_joint(scenario, spec: ArmSpec, arm, obj, q, oMo):
    from multiarm_pin.constraints import make_joint, relative_placement

    key = f"arms[{spec.index}].joint"
    j = spec.joint
    label = f"{spec.name}:{j.type}"
    try:
        if JOINT_TYPES[j.type].from_contacts:
            tips = _tips_in_tool(scenario, spec, arm)
            M = relative_placement(arm.tool_placement(q), oMo)
            r = j.params.get("tip_radius", 0.0)
            contacts = []
            for k, (c, tip) in enumerate(zip(j.contacts, tips, strict=True)):
                f = obj.shape.face_index(c.face)
                centre = M.act(tip)
                point = centre - r * obj.shape.normals[f]
                gap = obj.shape.signed_distance_to_face(point, f)
                # touching point: project onto the face plane; the initial-state check
                # reports the gap if the arm does not touch
                point = point - gap * obj.shape.normals[f]
                if not obj.shape.contains(point, 1e-6):
                    raise ScenarioError(
                        scenario.file, f"{key}.contacts[{k}]",
                        f"fingertip {c.tip!r} touches the plane of face {c.face!r} at "
                        f"{np.round(point, 4).tolist()} (object frame), outside the face")
                contacts.append((f, point))
            return make_joint(j.type, polyhedron=obj.shape, contacts=contacts, radius=r,
                              tip_points_in_tool=tips, tool_in_object=M, name=label, tol=1e-5,
                              unilateral=j.params.get("unilateral", True))
        if j.placement_in_object is not None:
            return make_joint(j.type, joint_in_object=j.placement_in_object,
                              joint_in_tool=j.placement_in_tool, name=label, **j.params)
        J_t = j.placement_in_tool or pin.SE3.Identity()
        M = relative_placement(arm.tool_placement(q), oMo) * J_t
        return make_joint(j.type, joint_in_object=M, joint_in_tool=j.placement_in_tool,
                          name=label, **j.params)
    except ScenarioError:
        raise
    except MultiArmError as exc:
        raise ScenarioError(scenario.file, key, str(exc)) from exc


def build_scenario(scenario: Scenario, load_visuals: bool = True) -> BuiltScenario:
    """Load the arms, place them (given ``q0`` or inverse kinematics), build joints and system.

    Args:
        scenario: a validated :class:`Scenario`.
        load_visuals: also load the arms' meshes (only the replay needs them; True like
            every arm loader, see :func:`~multiarm_pin.model.arm.load_arm`).

    Returns:
        :class:`BuiltScenario` with a consistent initial state (velocities projected onto the
        constraints when ``v0``/``twist`` are given).

    Raises:
        ScenarioError: unknown robot, missing frame, wrong ``q0`` length, an unreachable
            placement (with the IK residual), or an initial state that violates a joint
            (key ``arms[i].q0``, with the gap).
    """
    from multiarm_pin.app.scenario_checks import check_within_limits
    from multiarm_pin.model.kinematics import BodyKinematics
    from multiarm_pin.system import MultiArmSystem

    obj = build_object(scenario)
    oMo = scenario.object.placement
    arms, q0s, iks, joints = [], [], [], []
    for spec in scenario.arms:
        arm = build_arm(scenario, spec, load_visuals)
        key = f"arms[{spec.index}]"
        if JOINT_TYPES[spec.joint.type].from_contacts:
            _tips_in_tool(scenario, spec, arm)  # fingertip frames exist (did-you-mean)
        if spec.q0 is not None:
            if len(spec.q0) != arm.nq:
                raise ScenarioError(scenario.file, f"{key}.q0",
                                    f"expected {arm.nq} numbers (nq of {arm.source}), got "
                                    f"{len(spec.q0)}")
            check_within_limits(scenario.file, f"{key}.q0", arm, spec.q0)
            q, ik = spec.q0.copy(), None
        else:
            ik = _solve_arm_ik(scenario, spec, arm, obj.shape, oMo)
            q = ik.q
        if spec.v0 is not None and len(spec.v0) != arm.nv:
            raise ScenarioError(scenario.file, f"{key}.v0",
                                f"expected {arm.nv} numbers (nv of {arm.source}), got "
                                f"{len(spec.v0)}")
        joint = _build_joint(scenario, spec, arm, obj, q, oMo)
        # initial state must satisfy the joint: report the gap against the key q0
        oMt = arm.tool_placement(q)
        tool = BodyKinematics.single(oMt.translation, oMt.rotation, np.zeros(6))
        objk = BodyKinematics.single(oMo.translation, oMo.rotation, np.zeros(6))
        gaps = np.array([s.phi for s in joint.contact_states(tool, objk, active_only=False)])
        worst = int(np.argmax(np.abs(gaps)))
        if abs(gaps[worst]) > INITIAL_GAP_TOLERANCE:
            where = "q0" if spec.q0 is not None else "q_seed"
            raise ScenarioError(
                scenario.file, f"{key}.{where}",
                f"inconsistent initial state: the {spec.joint.type} joint of arm "
                f"{spec.name!r} is violated at the initial configuration: contact {worst} "
                f"({joint.contacts[worst].name}) has gap {gaps[worst]:.6g} m (tolerance "
                f"{INITIAL_GAP_TOLERANCE:g} m, {int((np.abs(gaps) > INITIAL_GAP_TOLERANCE).sum())}"
                f" of {len(gaps)} contacts violated); the tool is at "
                f"{np.round(oMt.translation, 4).tolist()} m",
            )
        arms.append(arm)
        q0s.append(q)
        iks.append(ik)
        joints.append(joint)
    supports = _build_supports(scenario, obj)
    try:
        system = MultiArmSystem(arms, obj, joints, scenario.gravity, supports)
        v = np.concatenate([a.v0 if a.v0 is not None else np.zeros(arm.nv)
                            for a, arm in zip(scenario.arms, arms, strict=True)] + [np.zeros(0)])
        state = system.state(np.concatenate(q0s + [np.zeros(0)]), v, scenario.object.position,
                             scenario.object.quaternion, scenario.object.twist)
        if np.any(v != 0) or np.any(scenario.object.twist != 0):
            state = system.project_velocities(state)
        _check_support_gaps(scenario, system, state)
        system.check_initial_state(state)
    except ScenarioError:
        raise
    except MultiArmError as exc:
        raise ScenarioError(scenario.file, "arms", f"inconsistent initial state: {exc}") from exc
    return BuiltScenario(scenario, arms, obj, joints, system, state, q0s, iks)


def _build_supports(scenario: Scenario, obj) -> list:
    """The :class:`~multiarm_pin.constraints.Support` of each ``supports[k]``."""
    from multiarm_pin.constraints import Support

    out = []
    for sp in scenario.supports:
        pts = obj.shape.vertices if isinstance(sp.points, str) else sp.points
        try:
            out.append(Support(sp.name, sp.point, sp.normal, pts, sp.restitution))
        except MultiArmError as exc:
            raise ScenarioError(scenario.file, f"supports[{sp.index}]", str(exc)) from exc
    return out


def _check_support_gaps(scenario: Scenario, system, state) -> None:
    """Raise if the object starts penetrating a support (key ``supports[k].points``)."""
    if not system.supports.n_rows:
        return
    phi = system.support_terms(state).phi
    for sp_index, sp in enumerate(scenario.supports):
        rows = np.flatnonzero(system.supports.support_index == sp_index)
        j = int(rows[np.argmin(phi[rows])])
        if phi[j] < -INITIAL_GAP_TOLERANCE:
            raise ScenarioError(
                scenario.file, f"supports[{sp.index}].points",
                f"the object starts penetrating support {sp.name!r}: point "
                f"{int(system.supports.point_index[j])} is {-phi[j]:.6g} m below the plane "
                f"(tolerance {INITIAL_GAP_TOLERANCE:g} m, "
                f"{int((phi[rows] < -INITIAL_GAP_TOLERANCE).sum())} point(s) below); move "
                "object.pose or the plane")


__all__ = [
    "CONTROLLER_TYPES",
    "DEPRECATED_JOINT_TYPES",
    "INTEGRATOR_NAMES",
    "JOINT_TYPE_NAMES",
    "SOLVER_NAMES",
    "ArmSpec",
    "BuiltScenario",
    "ContactSpec",
    "ControllerSpec",
    "JointSpec",
    "ObjectSpec",
    "Scenario",
    "SimulationSpec",
    "SupportSpec",
    "build_arm",
    "build_object",
    "build_scenario",
    "did_you_mean",
    "load_scenario",
    "parse_scenario",
]
