"""Design spec files: the object, the task, the arms available, where bases may go.

A design spec is a YAML file (format in the README's "Designing a system")::

    name: two_ur5_box
    object: {shape: {type: box, size: [0.8, 0.4, 0.3]}, mass: 4.0,
             pose: {position: [0.5, 0.0, 0.35]}}           # a scenario's object block
    supports: [...]                          # optional, a scenario's supports block
    task:
      waypoints: [{t: 0.8, position: [0.5, 0.0, 0.5]}, ...]   # object_pd's form
      # or: lift: 0.15 (m, straight up), duration: 1.0 (s, default 1)
    arms:
      - {robot: ur5, count: 2, gripper: weld}
      - {gripper: {fingertips: mp6_4f}}      # a named gripper of GRIPPERS (arm and hand)
      - {robot: ur5, gripper: {fingertips: [[0.05, 0, 0.1], ...], tip_radius: 0.015}}
                                             # tip centres in the tool frame [m] (or frames)
    bases:
      region: {x: [-0.2, 1.2], y: [-0.9, 0.9], z: 0.0}
      yaw: free                              # or a number [rad], or [lo, hi]
      # or fixed: [{position: [..], rpy: [..]}, ...] (one per arm)
    search: {candidates: 96, refine: 2, polish: 6, seed: 0, clearance: 0.01, face_margin: 0.03}
    weights: {torque_ratio: 1.0, clearance: 1.0, manipulability: 1.0}   # see scoring.SCORES
    top: 3
    controller: {kp: 100.0, kd: 20.0, margin: 5.0}   # object_pd gains of the output scenarios
    simulation: {dt: 0.002, ...}             # a scenario's simulation block (duration: the task's)

The object, supports, controller and simulation blocks are read by the scenario reader
(:mod:`multiarm_pin.app.scenario.schema`), so their errors name the same key paths. Every
error is a :class:`~multiarm_pin.exceptions.DesignError` naming the file, the key path and
what was expected.

Twins: ``multiarm_pin.study.spec`` (the same role, a package's input file reader, in another
package, for another format: that module reads study files, a base file and what to vary; this
one reads design spec files).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from multiarm_pin.exceptions import DesignError, ScenarioError
from multiarm_pin.yaml_reader import Reader, describe, load_yaml_file

_TOP_KEYS = ("name", "description", "gravity", "object", "supports", "task", "arms", "bases",
             "search", "weights", "top", "controller", "simulation", "ground")
_ARM_KEYS = ("robot", "urdf", "tool_frame", "count", "gripper", "name")
_SEARCH_KEYS = ("candidates", "refine", "polish", "seed", "clearance", "face_margin",
                "path_samples")


@dataclass(frozen=True)
class Gripper:
    """A named fingertip gripper: the arm that carries it and its rigid tips.

    Attributes:
        urdf: the arm-and-hand URDF, relative to the shipped ``robots/`` folder.
        tool_frame: the frame whose placement the design chooses.
        tips: names of the fingertip frames (their centres are rigid in the tool frame).
        tip_radius: radius of each spherical fingertip [m].
    """

    urdf: str
    tool_frame: str
    tips: tuple[str, ...]
    tip_radius: float


GRIPPERS: dict[str, Gripper] = {
    "mp6_4f": Gripper("mp6/mp6_4f.urdf", "tool0",
                      ("fingertip_1", "fingertip_2", "fingertip_3", "fingertip_4"), 0.015),
    "mp6_3f": Gripper("mp6/mp6.urdf", "tool0", ("fingertip_1", "fingertip_2", "fingertip_3"),
                      0.015),
}
"""The shipped fingertip grippers (:mod:`multiarm_pin.data` ``robots/mp6``)."""


@dataclass(frozen=True)
class ArmSlot:
    """One arm of the design (an ``arms`` entry with ``count: n`` gives n slots).

    Attributes:
        name: the arm's name in the output scenarios.
        robot: an example_robot_data name, or None (``urdf`` given).
        urdf: absolute URDF path, or None.
        tool_frame: the tool frame (None: the robot registry's).
        gripper: ``"weld"`` or ``"fingertips"``.
        tips: the fingertips (fingertips only): each a frame name of the arm, or its
            sphere's centre ``(x, y, z)`` in the tool frame [m].
        tip_radius: fingertip radius [m] (fingertips only).
        index: position in the design's arms.
    """

    name: str
    robot: str | None
    urdf: str | None
    tool_frame: str | None
    gripper: str
    tips: tuple[str | tuple[float, float, float], ...] = ()
    tip_radius: float = 0.0
    index: int = 0


@dataclass(frozen=True)
class BaseRegion:
    """Where bases may go: a box of positions and a yaw range, or fixed placements.

    Attributes:
        lower, upper: (3,) corners of the positions' box [m] (z equal for a floor).
        yaw: ``(lo, hi)`` [rad] of the base yaw about the world z axis.
        fixed: one ``pin.SE3`` per arm slot, or None (search the region).
    """

    lower: np.ndarray
    upper: np.ndarray
    yaw: tuple[float, float]
    fixed: tuple | None = None


@dataclass(frozen=True)
class SearchSettings:
    """How hard to search.

    Attributes:
        candidates: random candidates of the first round.
        refine: rounds of local refinement around the best candidates.
        polish: rounds of refinement of the Pareto front after them (:func:`~.search._polish`).
        seed: the random seed (every candidate's own seed derives from it and its index).
        clearance: smallest distance [m] accepted between bodies that must not touch.
        face_margin: smallest distance [m] from a contact to its face's edges.
        path_samples: poses checked per segment of the task (besides its waypoints).
    """

    candidates: int = 64
    refine: int = 2
    polish: int = 6
    seed: int = 0
    clearance: float = 0.01
    face_margin: float = 0.03
    path_samples: int = 4


@dataclass(frozen=True)
class DesignSpec:
    """A validated design spec.

    Attributes:
        name, file, description: as in a scenario.
        scenario_base: the scenario keys the outputs share (gravity, object, supports,
            ground, simulation) as read.
        object, supports: the scenario reader's :class:`ObjectSpec` and supports.
        waypoints: the task, object_pd's waypoint mappings ``{t, position, quaternion}``.
        trajectory: ``{times, positions, quaternions}`` with the start pose at t = 0.
        arms: the :class:`ArmSlot` of each arm.
        bases: :class:`BaseRegion`.
        search: :class:`SearchSettings`.
        weights: the objective's weight of each score (:data:`~.scoring.SCORES`).
        top: number of designs returned.
        controller: object_pd parameters of the output scenarios (besides waypoints).
        pick_up: ``task: {pick_up: {lift, carry}, strategy}`` read as ``{"lift": (3,),
            "carry": (3,), "strategy": "tilt" | "auto"}`` (world displacements [m]), or None
            for a waypoint task (:mod:`.pick_up` plans it).
    """

    name: str
    file: str
    description: str
    scenario_base: dict
    object: object
    supports: tuple
    waypoints: tuple
    trajectory: dict
    arms: tuple[ArmSlot, ...]
    bases: BaseRegion
    search: SearchSettings
    weights: dict = field(default_factory=dict)
    top: int = 3
    controller: dict = field(default_factory=dict)
    pick_up: dict | None = None


def load_design(path) -> DesignSpec:
    """Read and validate a design spec file.

    Raises:
        DesignError: invalid content (file, key path, what was expected); ScenarioError for
            an unreadable file or a YAML syntax error.
    """
    data = load_yaml_file(path)
    return parse_design(data, str(path))


def _design_error(exc: ScenarioError) -> DesignError:
    return DesignError(exc.file, exc.key, exc.message, exc.line, exc.column)


def parse_design(data, file: str = "<design>") -> DesignSpec:
    """Validate a parsed design spec mapping (see the module docstring).

    Raises:
        DesignError: invalid content.
    """
    try:
        return _parse(data, file)
    except DesignError:
        raise
    except ScenarioError as exc:  # the scenario reader's blocks: same key paths
        raise _design_error(exc) from exc


def _parse(data, file: str) -> DesignSpec:
    from multiarm_pin.app.scenario.schema import (
        parse_ground,
        parse_object,
        parse_simulation,
        parse_supports,
        parse_waypoints,
    )

    root = Reader(file, "", data)
    d = root.mapping(_TOP_KEYS, required=("object", "task", "arms", "bases"))
    name = root.get("name").string() if "name" in d else Path(file).stem
    description = root.get("description").string() if "description" in d else ""
    if "gravity" in d:
        root.get("gravity").array((3,), "m/s^2")
    obj = parse_object(root.get("object"))
    supports = parse_supports(root.get("supports")) if "supports" in d else ()
    if "ground" in d:
        parse_ground(root.get("ground"))
    pick_up = _parse_pick_up(root.get("task"), obj)
    if pick_up is None:
        waypoints, trajectory = _parse_task(root.get("task"), obj)
    else:
        waypoints = pick_up.pop("waypoints")
        trajectory = parse_waypoints(Reader(file, "task", list(waypoints)), obj)
    controller = {}
    if "controller" in d:
        cr = root.get("controller")
        controller = cr.mapping(("kp", "kd", "margin"))
        for k in controller:
            cr.get(k).number(nonnegative=True)
    base = {k: d[k] for k in ("gravity", "object", "supports", "ground") if k in d}
    sim = dict(d.get("simulation") or {})
    sim.setdefault("duration", float(trajectory["times"][-1]) + 0.2)
    sim.setdefault("integrator", "rk4")
    sim.setdefault("dt", 0.002)
    sim.setdefault("solver", "object_first")
    sim.setdefault("baumgarte", {"alpha": 5.0, "beta": 5.0})
    parse_simulation(Reader(file, "simulation", sim))
    base["simulation"] = sim
    arms = _parse_arms(root.get("arms"), Path(file).resolve().parent)
    for s in arms:
        if s.gripper == "fingertips" and obj.shape_type != "box":
            raise root.get("arms").error(
                "a fingertip gripper's grip is fitted around a corner of a box; the object is "
                f"a {obj.shape_type} (welds may hold any polyhedron)")
    bases = _parse_bases(root.get("bases"), len(arms))
    search = _parse_search(root.get("search")) if "search" in d else SearchSettings()
    weights = _parse_weights(root.get("weights")) if "weights" in d else {}
    top = 3
    if "top" in d:
        top = int(root.get("top").number(positive=True))
    if pick_up is not None:
        from multiarm_pin.design.pick_up import check_pick_up_spec

        check_pick_up_spec(root, obj, supports, arms)
    return DesignSpec(name, file, description, base, obj, supports, tuple(waypoints),
                      trajectory, arms, bases, search, weights, top, controller, pick_up)


PICK_UP_STRATEGIES = ("tilt", "auto")
"""``task.strategy`` of a pick-up: ``tilt`` always plans the tilt; ``auto`` uses the plain
design search when the supports leave an overhang fingertips reach (or an arm welds)."""


def _parse_pick_up(r: Reader, obj) -> dict | None:
    """``task: {pick_up: {lift: h, carry: [dx, dy, dz]}, strategy: tilt | auto}``, or None.

    ``task: pick_up`` alone takes the defaults (lift 0.05 m, no carry, strategy auto).
    """
    if r.value == "pick_up":
        v = {"pick_up": {}}
        r = Reader(r.file, r.path, v)
    elif not isinstance(r.value, Mapping) or "pick_up" not in r.value:
        return None
    d = r.mapping(("pick_up", "strategy"), required=("pick_up",))
    pr = r.get("pick_up")
    lift, carry = 0.05, np.zeros(3)
    if pr.value is not None:
        pd = pr.mapping(("lift", "carry"))
        if "lift" in pd:
            lift = pr.get("lift").number(positive=True)
        if "carry" in pd:
            carry = pr.get("carry").array((3,), "[dx, dy, dz] world [m]")
    strategy = r.get("strategy").string(PICK_UP_STRATEGIES) if "strategy" in d else "auto"
    up = np.array([0.0, 0.0, lift])
    p0 = np.asarray(obj.position, float)
    q = np.asarray(obj.quaternion, float).tolist()
    waypoints = [{"t": 0.5, "position": (p0 + up).tolist(), "quaternion": q}]
    if np.any(carry != 0.0):
        waypoints.append({"t": 1.0, "position": (p0 + up + carry).tolist(), "quaternion": q})
    return {"lift": up, "carry": carry, "strategy": strategy, "waypoints": waypoints}


def _parse_task(r: Reader, obj) -> tuple[list[dict], dict]:
    """The task's waypoints and their trajectory (the start pose at t = 0).

    Returns ``(waypoints, trajectory)``: object_pd waypoints ``{t, position, quaternion}``
    (world, COM frame) and ``{times, positions, quaternions}``.

    ``waypoints`` are read by the scenario reader
    (:func:`~multiarm_pin.app.scenario.schema.parse_waypoints`); ``lift: h`` is one waypoint
    ``h`` above the start at ``duration``.
    """
    from multiarm_pin.app.scenario.schema import parse_waypoints

    d = r.mapping(("waypoints", "lift", "duration"))
    if ("waypoints" in d) == ("lift" in d):
        raise r.error("give exactly one of 'lift' (a height [m]) or 'waypoints' (object_pd's "
                      "form: [{t, position, quaternion | rpy}, ...])")
    if "lift" in d:
        h = r.get("lift").number(positive=True)
        T = r.get("duration").number(positive=True) if "duration" in d else 1.0
        p = obj.position + np.array([0.0, 0.0, h])
        wr = Reader(r.file, f"{r.path}.lift", [{"t": T, "position": p.tolist(),
                                                 "quaternion": obj.quaternion.tolist()}])
    else:
        if "duration" in d:
            raise r.get("duration").error("'duration' goes with 'lift' (waypoints carry "
                                          "times)")
        wr = r.get("waypoints")
    trajectory = parse_waypoints(wr, obj)
    given = len(wr.value)  # the rows after the prepended start pose
    waypoints = [{"t": float(t), "position": p.tolist(), "quaternion": q.tolist()}
                 for t, p, q in zip(trajectory["times"][-given:],
                                    trajectory["positions"][-given:],
                                    trajectory["quaternions"][-given:], strict=True)]
    return waypoints, trajectory


def _parse_arms(r: Reader, base_dir: Path) -> tuple[ArmSlot, ...]:
    from multiarm_pin.data import data_path

    if not isinstance(r.value, list) or not r.value:
        raise r.error(f"expected a non-empty list of {{robot, count, gripper}}, got "
                      f"{describe(r.value)}")
    slots = []
    for i, item in enumerate(r.value):
        c = r.child(i, item)
        d = c.mapping(_ARM_KEYS, required=("gripper",))
        count = int(c.get("count").number(positive=True)) if "count" in d else 1
        gr = c.get("gripper")
        tips, radius, gripper = (), 0.0, "weld"
        robot = c.get("robot").string() if "robot" in d else None
        urdf = c.get("urdf").string() if "urdf" in d else None
        tool = c.get("tool_frame").string() if "tool_frame" in d else None
        if isinstance(gr.value, str):
            gr.string(("weld",))
        else:
            gd = gr.mapping(("fingertips", "tip_radius"), required=("fingertips",))
            fr = gr.get("fingertips")
            gripper = "fingertips"
            if isinstance(fr.value, str):
                g = GRIPPERS.get(fr.value)
                if g is None:
                    fr.string(tuple(GRIPPERS))
                tips, radius = g.tips, g.tip_radius
                if robot is None and urdf is None:
                    urdf, tool = str(data_path("robots", g.urdf)), g.tool_frame
            else:
                if not isinstance(fr.value, list) or not fr.value:
                    raise fr.error(f"expected a named gripper ({', '.join(GRIPPERS)}) or a "
                                   f"list of fingertips (frame names or centres [x, y, z] in "
                                   f"the tool frame [m]), got {describe(fr.value)}")
                tips = tuple(_parse_tip(fr.child(k, v)) for k, v in enumerate(fr.value))
                if len(tips) < 3:
                    raise fr.error(f"a fingertip gripper fitted around a box corner needs at "
                                   f"least 3 tips (one per face), got {len(tips)}")
            if "tip_radius" in gd:
                radius = gr.get("tip_radius").number(nonnegative=True)
        if (robot is None) == (urdf is None):
            raise c.error("give exactly one of 'robot' (an example_robot_data name) or 'urdf' "
                          "(a path), or a named fingertip gripper")
        if urdf is not None and not Path(urdf).is_absolute():
            cands = [base_dir / urdf, data_path("robots") / urdf]
            found = next((p for p in cands if p.is_file()), None)
            if found is None:
                raise c.get("urdf").error(f"URDF file not found (looked at "
                                          f"{', '.join(str(p) for p in cands)})")
            urdf = str(found.resolve())
        if urdf is not None and tool is None:
            raise c.error("a URDF arm needs 'tool_frame'", f"{c.path}.tool_frame")
        stem = c.get("name").string() if "name" in d else (robot or Path(urdf).stem)
        for _ in range(count):
            slots.append(ArmSlot(f"{stem}_{len(slots)}" if count > 1 or "name" not in d
                                 else stem, robot, urdf, tool, gripper, tips, radius,
                                 len(slots)))
    names = [s.name for s in slots]
    if len(set(names)) != len(names):
        raise r.error(f"arm names must be unique, got {names}")
    return tuple(slots)


def _parse_tip(r: Reader) -> str | tuple[float, float, float]:
    """A fingertip: a frame name of the arm, or its centre ``[x, y, z]`` in the tool frame."""
    if isinstance(r.value, str):
        return r.string()
    if not isinstance(r.value, list):
        raise r.error(f"expected a frame name or a fingertip centre [x, y, z] in the tool "
                      f"frame [m], got {describe(r.value)}")
    return tuple(float(v) for v in r.array((3,), "fingertip centre in the tool frame [m]"))


def _parse_bases(r: Reader, n_arms: int) -> BaseRegion:
    d = r.mapping(("region", "yaw", "fixed"))
    if ("region" in d) == ("fixed" in d):
        raise r.error("give exactly one of 'region' ({x: [lo, hi], y: [lo, hi], z: h}) or "
                      "'fixed' (one base placement per arm)")
    if "fixed" in d:
        fr = r.get("fixed")
        if not isinstance(fr.value, list) or len(fr.value) != n_arms:
            raise fr.error(f"expected {n_arms} base placements (one per arm), got "
                           f"{describe(fr.value)}")
        fixed = tuple(fr.child(k, v).placement() for k, v in enumerate(fr.value))
        p = np.array([M.translation for M in fixed])
        return BaseRegion(p.min(axis=0), p.max(axis=0), (0.0, 0.0), fixed)
    rr = r.get("region")
    rd = rr.mapping(("x", "y", "z"), required=("x", "y"))
    lo, hi = np.zeros(3), np.zeros(3)
    for a, key in enumerate(("x", "y", "z")):
        if key not in rd:
            continue
        kr = rr.get(key)
        if isinstance(kr.value, int | float) and not isinstance(kr.value, bool):
            lo[a] = hi[a] = kr.number()
        else:
            v = kr.array((2,), f"[lo, hi] {key} [m]")
            if v[1] < v[0]:
                raise kr.error(f"expected lo <= hi, got {v.tolist()}")
            lo[a], hi[a] = v
    yaw = (-np.pi, np.pi)
    if "yaw" in d:
        yr = r.get("yaw")
        if isinstance(yr.value, str):
            yr.string(("free",))
        elif isinstance(yr.value, list):
            v = yr.array((2,), "[lo, hi] yaw [rad]")
            if v[1] < v[0]:
                raise yr.error(f"expected lo <= hi, got {v.tolist()}")
            yaw = (float(v[0]), float(v[1]))
        else:
            y = yr.number()
            yaw = (y, y)
    return BaseRegion(lo, hi, yaw)


def _parse_search(r: Reader) -> SearchSettings:
    d = r.mapping(_SEARCH_KEYS)
    s = SearchSettings()
    vals = {}
    for k in ("candidates", "path_samples"):
        if k in d:
            vals[k] = int(r.get(k).number(positive=True))
    for k in ("refine", "polish", "seed"):
        if k in d:
            vals[k] = int(r.get(k).number(nonnegative=True))
    for k in ("clearance", "face_margin"):
        if k in d:
            vals[k] = r.get(k).number(nonnegative=True)
    return SearchSettings(**{**s.__dict__, **vals})


def _parse_weights(r: Reader) -> dict:
    from multiarm_pin.design.scoring import SCORES

    if not isinstance(r.value, Mapping):
        raise r.error(f"expected a mapping of score names ({', '.join(SCORES)}) to weights, "
                      f"got {describe(r.value)}")
    d = r.mapping(tuple(SCORES))
    return {k: r.get(k).number(nonnegative=True) for k in d}


__all__ = ["GRIPPERS", "PICK_UP_STRATEGIES", "ArmSlot", "BaseRegion", "DesignSpec", "Gripper",
           "SearchSettings", "load_design", "parse_design"]
