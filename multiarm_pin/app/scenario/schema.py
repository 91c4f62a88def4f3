"""Scenario files: the format, reading and validation (with did-you-mean) into specs.

A scenario is a YAML file describing the object, the arms and how each is joined to the
object, the controller and the simulation settings (format in the README)::

    name: two_ur5_box
    gravity: [0, 0, -9.81]                   # m/s^2, world
    object:
      shape: {type: box, size: [0.8, 0.4, 0.3]}     # or {type: polyhedron, vertices: [...]}
      mass: 4.0                              # kg; `inertia` (3x3 about the COM) optional
      pose: {position: [0.6, 0, 0.4], quaternion: [0, 0, 0, 1]}   # [x, y, z, w] or rpy
      twist: [0, 0, 0, 0, 0, 0]              # optional, [v; w] world axes
    arms:
      - name: left
        robot: ur5                           # or `urdf: path` (see below)
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
        extent: [1.2, 0.8]                   # optional: a rectangle [lx, ly] [m] around point
        x_axis: [1, 0, 0]                    # optional: its x side (world, onto the plane)
    limits: {torque: report, velocity: report, position: report, collision: report}  # or stop;
                                             # torque also saturate (clip to the URDF effort)
    ground: {height: 0.0}                    # the floor (collisions); null: no floor

The object may carry ``external_wrench: [{from: s, to: s, wrench: [fx, fy, fz, mx, my,
mz]}]`` (at the COM, world axes [N, N m], over each interval). A joint may say ``unilateral:
true/false`` to override its contacts' default (``fingertips`` and ``corner_gripper`` push
only; the mechanical joints are bilateral). ``arms`` may be empty when there are supports.

Joint types (the placeable entries of :data:`~multiarm_pin.constraints.JOINT_TYPES`):
``weld``, ``revolute``, ``prismatic``, ``cylindrical``, ``universal``, ``spherical``,
``corner_gripper`` (parameters ``size``, ``tip_radius``, ``points_on`` (not for
``corner_gripper``), and optionally ``placement_in_object`` / ``placement_in_tool`` of the
joint frame), and ``fingertips`` (spherical fingertips on named faces: ``tip_radius`` and
``contacts: [{tip: frame, face: +x, point: [..]}, ...]``, where ``tip`` is the frame of the
sphere's centre or its centre ``[x, y, z]`` in the tool frame [m], and optionally ``approach:
[dx, dy, dz]``: the gripper starts displaced by that vector (object frame [m]) from where its
tips touch those points, so they start apart and may touch down during the run); the old name
``contacts`` is still read, with a deprecation warning). Without ``placement_in_object`` a
joint is built where the tool is at ``q0``. Without ``q0`` the arm is placed by inverse kinematics
(:mod:`multiarm_pin.model.ik`) from ``q_seed``, meeting only what the joint constrains (the
centre of a spherical joint; centre and axis of a revolute one; axis and line of a
cylindrical one; the full placement of weld, prismatic and universal joints; each fingertip
touching its face, as near to the given point as the gripper allows), near the seed.

A relative ``urdf:`` path is looked up beside the scenario file, then among the shipped
robots (:mod:`multiarm_pin.data`: ``mp6/mp6.urdf`` or ``robots/mp6/mp6.urdf``).

Files are read strictly (:mod:`multiarm_pin.yaml_reader`: UTF-8, no duplicate keys, and the
key-path :class:`~multiarm_pin.yaml_reader.Reader` shared with the grasp files). Every error is a
:class:`~multiarm_pin.exceptions.ScenarioError` naming the file, the key path
(``arms[1].joint.type``) and what was expected; ``q0`` outside the joint limits is one
(:mod:`multiarm_pin.app.scenario_checks`). Building the system from a :class:`Scenario` is
:mod:`multiarm_pin.app.scenario.build`; the specs are :mod:`multiarm_pin.app.scenario.specs`.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pinocchio as pin

from multiarm_pin.app.scenario.specs import (
    CONTROLLER_TYPES,
    DEPRECATED_JOINT_TYPES,
    INTEGRATOR_NAMES,
    JOINT_TYPE_NAMES,
    SOLVER_NAMES,
    ArmSpec,
    ContactSpec,
    ControllerSpec,
    JointSpec,
    LimitsSpec,
    ObjectSpec,
    Scenario,
    SimulationSpec,
    SupportSpec,
)
from multiarm_pin.constraints.joint_types import JOINT_TYPES
from multiarm_pin.constraints.supports import plane_x_axis
from multiarm_pin.data import data_path
from multiarm_pin.exceptions import ConstraintError
from multiarm_pin.sim.controllers import CONTROLLERS
from multiarm_pin.yaml_reader import Reader, describe, load_yaml_file

# ----------------------------------------------------------------------------- parsing
_TOP_KEYS = ("name", "description", "gravity", "object", "arms", "controller", "simulation",
             "supports", "limits", "ground")
_LIMIT_KEYS = ("torque", "velocity", "position", "collision")
_POLICIES = ("report", "stop")
_TORQUE_POLICIES = ("report", "saturate", "stop")
_OBJECT_KEYS = ("shape", "mass", "inertia", "pose", "twist", "external_wrench")
_ARM_KEYS = ("name", "robot", "urdf", "tool_frame", "tool_offset", "base", "locked_joints",
             "q0", "q_seed", "v0", "joint")
_JOINT_KEYS = ("type", "size", "tip_radius", "points_on", "placement_in_object",
               "placement_in_tool", "contacts", "unilateral", "approach")
_SIM_KEYS = ("duration", "integrator", "dt", "solver", "baumgarte", "compiled")


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
    root = Reader(file, "", data)
    d = root.mapping(_TOP_KEYS, required=("object", "arms"))
    name = root.get("name").string() if "name" in d else Path(file).stem
    description = root.get("description").string() if "description" in d else ""
    gravity = (root.get("gravity").array((3,), "m/s^2") if "gravity" in d
               else np.array([0.0, 0.0, -9.81]))
    obj = parse_object(root.get("object"))
    supports = parse_supports(root.get("supports")) if "supports" in d else ()
    arms_r = root.get("arms")
    if not isinstance(arms_r.value, list) or (not arms_r.value and not supports):
        raise arms_r.error(f"expected a non-empty list of arms (or an empty list with "
                           f"supports), got {describe(arms_r.value)}")
    base_dir = Path(file).resolve().parent
    arms = tuple(_parse_arm(arms_r.child(i, a), i, base_dir) for i, a in enumerate(arms_r.value))
    names = [a.name for a in arms]
    for i, n in enumerate(names):
        if names.index(n) != i:
            raise arms_r.child(i, None).error(f"duplicate arm name {n!r}; names must be unique",
                                              f"arms[{i}].name")
    controller = _parse_controller(root.get("controller"), obj) if "controller" in d else \
        ControllerSpec("none")
    sim = parse_simulation(root.get("simulation")) if "simulation" in d else SimulationSpec()
    clean = dict(d)
    clean["arms"] = [dict(a) for a in d["arms"]]
    for a, spec in zip(clean["arms"], arms, strict=True):
        if spec.urdf is not None:
            a["urdf"] = spec.urdf
    limits = _parse_limits(root.get("limits")) if "limits" in d else LimitsSpec()
    ground = parse_ground(root.get("ground")) if "ground" in d else 0.0
    return Scenario(name, file, description, gravity, obj, arms, controller, sim, clean,
                    supports, limits, ground)


def _parse_limits(r: Reader) -> LimitsSpec:
    """The ``limits:`` block: a policy per kind (``torque`` may also ``saturate``).

    ``{torque: report | saturate | stop, velocity: report | stop, position: ...,
    collision: ...}``.
    """
    d = r.mapping(_LIMIT_KEYS)
    return LimitsSpec(**{k: r.get(k).string(_TORQUE_POLICIES if k == "torque"
                                            else _POLICIES) for k in d})


def parse_ground(r: Reader) -> float | None:
    """``ground: {height: h}`` [m] (the plane z = h), or ``ground: null`` for none."""
    if r.value is None:
        return None
    r.mapping(("height",), required=("height",))
    return r.get("height").number()


def parse_supports(r: Reader) -> tuple[SupportSpec, ...]:
    """The ``supports:`` block (module docstring) as :class:`SupportSpec` s.

    Raises:
        ScenarioError: invalid content (key path and what was expected).
    """
    if not isinstance(r.value, list):
        raise r.error(f"expected a list of supports {{name, plane, points, restitution, "
                      f"extent, x_axis}}, got {describe(r.value)}")
    out, names = [], []
    for k, item in enumerate(r.value):
        c = r.child(k, item)
        d = c.mapping(("name", "plane", "points", "restitution", "extent", "x_axis"),
                      required=("plane", "points"))
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
        normal = normal / np.linalg.norm(normal)
        extent = x_axis = None
        if "extent" in d:
            xr = c.get("extent")
            extent = xr.array((2,), "[lx, ly] side lengths of the rectangle [m]")
            if not np.all(extent > 0.0):
                raise xr.error(f"expected two positive side lengths [lx, ly] [m], got "
                               f"{extent.tolist()}")
        if "x_axis" in d:
            ar = c.get("x_axis")
            x_axis = ar.array((3,), "world direction of the rectangle's x side")
            try:
                plane_x_axis(normal, x_axis)
            except ConstraintError as exc:
                raise ar.error(f"x_axis {x_axis.tolist()} is parallel to the plane's normal "
                               f"{normal.tolist()} (or zero); expected a direction along the "
                               "plane (it is projected onto it)") from exc
        out.append(SupportSpec(name, point, normal, points, e, k, extent, x_axis))
    return tuple(out)


def parse_object(r: Reader) -> ObjectSpec:
    """The ``object:`` block (shape, mass, inertia, pose, twist, external wrenches).

    Raises:
        ScenarioError: invalid content (key path and what was expected).
    """
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
            raise wr.error(f"expected a list of {{from, to, wrench}}, got {describe(wr.value)}")
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


def _parse_arm(r: Reader, index: int, base_dir: Path) -> ArmSpec:
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
        candidates = [raw] if raw.is_absolute() else \
            [base_dir / raw, data_path("robots") / raw, data_path() / raw]
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
            raise lr.error(f"expected a list of joint names, got {describe(lr.value)}")
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


def _parse_joint(r: Reader) -> JointSpec:
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
                                            f"{describe(d['unilateral'])}")
        params["unilateral"] = d["unilateral"]
    for key in ("size", "tip_radius"):
        if key in d:
            params[key] = r.get(key).number(positive=(key == "size"), nonnegative=True)
    if "points_on" in d:
        if "points_on" not in JOINT_TYPES[kind].parameters:
            raise r.get("points_on").error(f"not a parameter of {kind!r} joints")
        params["points_on"] = r.get("points_on").string(("tool", "object"))
    if "approach" in d:
        if not fingertips:
            raise r.get("approach").error(f"not a parameter of {kind!r} joints (only "
                                          "fingertips start away from the object)")
        params["approach"] = r.get("approach").array((3,), "object frame [m]")
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
                           f"{describe(cr.value)}")
        contacts = []
        for k, c in enumerate(cr.value):
            cc = cr.child(k, c)
            cd = cc.mapping(("tip", "face", "point"), required=("tip", "face"))
            face = cd["face"]
            if isinstance(face, bool) or not isinstance(face, str | int):
                raise cc.get("face").error(f"expected a face name (e.g. +x) or index, got "
                                           f"{describe(face)}")
            point = cc.get("point").array((3,), "object frame [m]") if "point" in cd else None
            tr = cc.get("tip")
            if isinstance(tr.value, str):
                contacts.append(ContactSpec(tr.string(), face, point))
            elif isinstance(tr.value, list):
                tip = tr.array((3,), "a frame name or the tip's centre [x, y, z] in the tool "
                               "frame [m]")
                contacts.append(ContactSpec(f"tip{k}", face, point, tip))
            else:
                raise tr.error(f"expected a frame name or the tip's centre [x, y, z] in the "
                               f"tool frame [m], got {describe(tr.value)}")
        return JointSpec(kind, params, contacts=tuple(contacts))
    if "contacts" in d:
        raise r.get("contacts").error(f"only 'fingertips' joints take contacts, not {kind!r}")
    J_o = r.get("placement_in_object").placement() if "placement_in_object" in d else None
    J_t = r.get("placement_in_tool").placement() if "placement_in_tool" in d else None
    return JointSpec(kind, params, J_o, J_t)


def _controller_keys(kind: str) -> tuple[str, ...]:
    """Keyword parameters accepted by the controller class of ``kind`` (besides system)."""
    return CONTROLLERS[kind].parameters


def _parse_controller(r: Reader, obj: ObjectSpec) -> ControllerSpec:
    """Controller type and parameters; object_pd ``waypoints`` become its ``trajectory``.

    ``waypoints: [{t: s, position: [..], quaternion: [..] | rpy: [..]}, ...]`` are world
    poses of the object's COM frame; the initial pose is prepended at t = 0 when the first
    waypoint is later.
    """
    if not isinstance(r.value, Mapping):
        raise r.error(f"expected a mapping with 'type', got {describe(r.value)}")
    if "type" not in r.value:
        raise r.error("missing required key 'type'", f"{r.path}.type")
    kind = r.get("type").string(CONTROLLER_TYPES)
    allowed = ("type", *_controller_keys(kind))  # object_pd's include waypoints
    d = r.mapping(allowed)
    params = {k: v for k, v in d.items() if k not in ("type", "waypoints")}
    if "waypoints" in d:
        if "trajectory" in d:
            raise r.get("waypoints").error("give either waypoints or trajectory, not both")
        params["trajectory"] = parse_waypoints(r.get("waypoints"), obj)
    return ControllerSpec(kind, params)


def parse_waypoints(r: Reader, obj: ObjectSpec) -> dict:
    """object_pd's ``waypoints: [{t, position, quaternion | rpy}, ...]`` as a trajectory.

    The waypoints are world poses of the object's COM frame at strictly increasing times
    [s]; the object's initial pose is prepended at t = 0 when the first waypoint is later.

    Returns:
        ``{times: (T,), positions: (T, 3), quaternions: (T, 4) [x, y, z, w]}``.

    Raises:
        ScenarioError: not a non-empty list of such mappings, or times not increasing.
    """
    if not isinstance(r.value, list) or not r.value:
        raise r.error(f"expected a non-empty list of {{t, position, quaternion|rpy}}, got "
                      f"{describe(r.value)}")
    times, positions, quats = [], [], []
    for k, w in enumerate(r.value):
        c = r.child(k, w)
        c.mapping(("t", "position", "quaternion", "rpy"), required=("t", "position"))
        t = c.get("t").number(nonnegative=True)
        if times and t <= times[-1]:
            raise c.get("t").error(f"waypoint times must increase strictly; {t} after "
                                   f"{times[-1]}")
        M = Reader(c.file, c.path, {k2: v for k2, v in w.items() if k2 != "t"}).placement()
        times.append(t)
        positions.append(M.translation.copy())
        quats.append(pin.Quaternion(M.rotation).coeffs().copy())
    if times[0] > 0:
        times.insert(0, 0.0)
        positions.insert(0, obj.position.copy())
        quats.insert(0, obj.quaternion.copy())
    return {"times": np.array(times), "positions": np.array(positions),
            "quaternions": np.array(quats)}


def parse_simulation(r: Reader) -> SimulationSpec:
    """The ``simulation:`` block (duration, integrator, dt, solver, baumgarte).

    Raises:
        ScenarioError: invalid content (key path and what was expected).
    """
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
    compiled = d.get("compiled", s.compiled)
    if not isinstance(compiled, bool):
        raise r.get("compiled").error(f"expected true or false, got {compiled!r}")
    return SimulationSpec(duration, integrator, dt, solver, baum, compiled)


__all__ = ["load_scenario", "parse_ground", "parse_object", "parse_scenario", "parse_simulation",
           "parse_supports", "parse_waypoints"]
