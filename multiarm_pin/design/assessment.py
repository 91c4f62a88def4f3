"""Assessing one candidate design: the checks every returned design passes, and its scores.

:func:`assess` turns a :class:`~.candidates.Candidate` into a scenario (the form
``multiarm-pin run`` reads) and checks, in the order of :data:`CONDITIONS`:

1. ``reach``: each arm's inverse kinematics at the start (:func:`~multiarm_pin.model.ik.solve_ik`
   within the joint limits; a weld's tool on its placement, a fingertip gripper's tips on their
   faces) and each contact inside its face by the face margin, off any supported area;
2. ``closure``: fingertips: form closure of the contacts by the LP
   (:func:`~multiarm_pin.grasp.form_closure.form_closure`); welds are full rank by construction;
3. ``path``: inverse kinematics at every pose of the task (its waypoints and
   ``path_samples`` poses within each segment), each warm-started from the previous one, with no
   joint moving more than :data:`MAX_JOINT_STEP` between two poses and every arm's tool
   Jacobian's smallest singular value at least :data:`MIN_SINGULAR_VALUE` at every pose (one
   continuous branch, away from the singularities where branches meet);
4. ``collision``: the clearances along the task (:class:`~multiarm_pin.feasibility.CollisionScene`
   ``scan``, as ``feasibility_report``: arm-object apart from the grasping links, arm-arm,
   arm-support, arm-ground, self) at least the spec's ``clearance`` margin, and no collision;
5. ``torque``: the static joint torques (gravity on the arms and the object's weight through the
   force distribution, :func:`~multiarm_pin.app.precheck.static_torques`) within the URDF's
   effort limits at every pose of the task (the distribution keeps every unilateral contact
   pushing; a failure to hold is a ``closure`` failure).

The candidate's :class:`Assessment` records the first condition it failed with the value it
reached (a residual, a margin, a clearance, a ratio), or its scores (:mod:`.scoring`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from multiarm_pin.design.candidates import (
    Candidate,
    candidate_rng,
    face_edge_margin,
    point_allowed,
    random_seed_configuration,
    supported_rectangles,
    weld_faces,
)
from multiarm_pin.exceptions import DynamicsError, MultiArmError, UnreachableError

CONDITIONS = ("reach", "closure", "path", "collision", "torque")
"""The conditions, in the order they are checked (a later one is further in the search)."""

MAX_JOINT_STEP = 0.5
"""Largest change [rad or m] of any joint between two successive poses of the task."""

IK_ITERATIONS = 40
"""Levenberg-Marquardt iterations per phase of each inverse kinematics solve."""

MIN_SINGULAR_VALUE = 0.02
"""Smallest singular value of each arm's tool Jacobian (world-aligned at the tool, [m/rad]
and [rad/rad] rows together) accepted at every pose of the task: a path through a
singularity (a UR5's wrist at sin q5 = 0) changes IK branch there, and the simulation's
contact-space matrix ``W M⁻¹ Wᵀ`` loses rank with the Jacobian."""

SEED_RETRIES = 2
"""IK seeds tried after the candidate's own when an arm's start pose is not found (drawn
like the candidate's, from the candidate's generator stream of that arm)."""


@dataclass
class Assessment:
    """What :func:`assess` found about one candidate.

    Attributes:
        index: the candidate's index.
        candidate: the :class:`~.candidates.Candidate`.
        ok: every condition met.
        condition: the first condition failed (one of :data:`CONDITIONS`), or None.
        value: the value it reached (``reach``/``path``: the IK residual [m or rad] or the
            joint step [rad], ``closure``: the LP margin, ``collision``: the clearance [m],
            ``torque``: the worst torque ratio), or None.
        detail: which arm, joint, face or pair, for messages.
        scores: the :data:`~.scoring.SCORES` values (designs that met every condition).
        q0: per arm, (nq_i,) its start configuration (when ``reach`` was met).
        path_q: (T, nq) the combined configuration at each pose of the task (when ``path``
            was met).
        scenario: the scenario mapping of the design (``q0`` given), when ``reach`` was met.
        solved: per arm its start configuration, or None where it was not found (or the
            arm failed the task): what :func:`~.candidates.recombine` may reuse.
        torque_arm: the arm slot of the joint with the worst torque ratio (a design), or
            None: the arm whose posture a refinement re-seeds (:func:`~.candidates.reseed`).
        manipulability_arm: the arm slot of the smallest manipulability (a design), or None.
    """

    index: int
    candidate: Candidate
    ok: bool
    condition: str | None = None
    value: float | None = None
    detail: str = ""
    scores: dict = field(default_factory=dict)
    q0: list | None = None
    path_q: np.ndarray | None = None
    scenario: dict | None = None
    solved: list | None = None
    torque_arm: int | None = None
    manipulability_arm: int | None = None

    @property
    def stage(self) -> int:
        """How far the candidate got: the failed condition's position (len for passed)."""
        return len(CONDITIONS) if self.ok else CONDITIONS.index(self.condition)


class DesignProblem:
    """A spec made ready for assessment: the object's shape, faces, task poses, arms' data.

    Picklable (a Dask task carries it). ``reach`` is each arm's reach bound [m]
    (:func:`~multiarm_pin.app.precheck.arm_reach`), ``seed_bounds`` its IK seeds' joint
    ranges, ``pan_offset`` the bearing [rad] of its tool at the neutral configuration in its
    base frame when its first joint turns about the base's vertical axis (else None).

    Args:
        spec: the :class:`~.spec.DesignSpec`.
    """

    def __init__(self, spec):
        from multiarm_pin.sim.trajectories import MinimumJerkTrajectory

        self.spec = spec
        o = spec.object
        self.object_placement = pin.SE3(pin.Quaternion(o.quaternion).toRotationMatrix(),
                                        np.asarray(o.position, float))
        self.poly = self._object().shape
        self.weld_faces = weld_faces(spec, self.poly)
        self.rects = supported_rectangles(spec, self.poly)
        traj = MinimumJerkTrajectory(**spec.trajectory)
        times = [0.0]
        tw = list(spec.trajectory["times"])
        n = spec.search.path_samples
        for a, b in zip(tw[:-1], tw[1:], strict=True):
            times += [a + (b - a) * (s + 1) / (n + 1) for s in range(n + 1)]
        self.path_times = np.array(times)
        samples = [traj.sample(t) for t in times]
        self.path_positions = np.array([s.position for s in samples])
        self.path_quaternions = np.array([s.quaternion for s in samples])
        self.path_placements = [pin.SE3(s.rotation, s.position) for s in samples]
        from multiarm_pin.app.precheck import arm_reach

        self.reach, self.seed_bounds, self.pan_offset = [], [], []
        for slot in spec.arms:
            arm = self.arm(slot.index, np.zeros(4))
            self.reach.append(arm_reach(arm))
            # bearing of the tool at the neutral configuration, for a vertical first joint
            vertical = arm.nq and arm.model.joints[1].shortname() == "JointModelRZ" and \
                arm.model.parents[1] == 0
            p = arm.tool_placement(arm.neutral()).translation
            self.pan_offset.append(float(np.arctan2(p[1], p[0])) if vertical else None)
            lo = np.maximum(arm.model.lowerPositionLimit, -np.pi)
            hi = np.minimum(arm.model.upperPositionLimit, np.pi)
            self.seed_bounds.append((lo, hi))
        self.footprint = self._footprint()
        ground = spec.scenario_base.get("ground", {"height": 0.0})
        self.ground = -np.inf if ground is None else float(ground.get("height", 0.0))
        self._base_arms: dict = {}
        self._floating: dict = {}
        self.tips_in_tool = []
        for slot in spec.arms:
            tips = np.zeros((0, 3))
            if slot.tips:
                arm = self.arm(slot.index, np.zeros(4))
                q = arm.neutral()
                oMt = arm.tool_placement(q)
                tips = np.array([np.asarray(t, float) if not isinstance(t, str) else
                                 oMt.actInv(arm.frame_placement(q, t).translation)
                                 for t in slot.tips])
            self.tips_in_tool.append(tips)

    def covered(self, f: int) -> bool:
        """Face ``f`` rests on a support that covers it whole (no fingertip can touch it)."""
        poly = self.poly
        for g, lo, hi in self.rects:
            if g != f:
                continue
            origin, F = poly.face_frame(f)
            verts = (poly.vertices[list(poly.faces[f])] - origin) @ F[:, :2]
            if np.all(verts.min(axis=0) >= lo - 1e-9) and np.all(verts.max(axis=0) <= hi + 1e-9):
                return True
        return False

    def floating_gripper(self, slot: int) -> pin.Model:
        """A free-flyer model whose frame ``tool`` is the slot's tool (for grip fits)."""
        model = self._floating.get(slot)
        if model is None:
            model = pin.Model()
            j = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "gripper")
            model.addFrame(pin.Frame("tool", j, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
            model.lowerPositionLimit = np.full(7, -1e3)
            model.upperPositionLimit = np.full(7, 1e3)
            self._floating[slot] = model
        return model

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k not in ("_base_arms", "_floating")}

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._base_arms, self._floating = {}, {}

    def lowest_joint(self, slot: int, q: np.ndarray) -> float:
        """Height [m] of the lowest joint origin of an arm at ``q`` above its base's origin."""
        arm = self._base_arms.get(slot)
        if arm is None:
            arm = self._base_arms[slot] = self.arm(slot, np.zeros(4))
        pin.forwardKinematics(arm.model, arm.data, q)
        return float(min(arm.data.oMi[j].translation[2] for j in range(2, arm.model.njoints)))

    def _object(self):
        from multiarm_pin.model.rigid_object import RigidObject

        o = self.spec.object
        if o.shape_type == "box":
            return RigidObject.box(o.size, o.mass, o.inertia)
        return RigidObject.from_vertices(o.vertices, o.mass, o.inertia)

    def _footprint(self) -> np.ndarray:
        """(V, 2) the object's vertices' horizontal positions along the task [m]."""
        pts = [np.array([M.act(v) for v in self.poly.vertices])[:, :2]
               for M in self.path_placements]
        return np.concatenate(pts)

    def footprint_distance(self, p: np.ndarray) -> float:
        """Horizontal distance [m] from ``p`` to the box bounding the object's footprint."""
        lo, hi = self.footprint.min(axis=0), self.footprint.max(axis=0)
        d = np.maximum(np.maximum(lo - p[:2], p[:2] - hi), 0.0)
        inside = np.all((p[:2] > lo) & (p[:2] < hi))
        return -1.0 if inside else float(np.linalg.norm(d))

    def arm(self, slot: int, base: np.ndarray):
        """The arm of a slot at a base ``[x, y, z, yaw]`` (no visuals)."""
        from multiarm_pin.model.arm import Arm

        s = self.spec.arms[slot]
        M = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, float(base[3])), np.asarray(base[:3], float))
        if s.robot is not None:
            return Arm.from_robot_name(s.robot, s.tool_frame, name=s.name, base_placement=M,
                                       load_visuals=False)
        return Arm.from_urdf(s.urdf, s.tool_frame, name=s.name, base_placement=M,
                             load_visuals=False)


# ----------------------------------------------------------------------------- scenario
def _r(x) -> list:
    return [round(float(v), 10) for v in np.ravel(x)]


def weld_placement(poly, face: int, point: np.ndarray, roll: float) -> pin.SE3:
    """The weld tool's placement in the object: origin at the point, z axis into the face.

    Its x axis is the face's first axis turned by ``roll`` about the normal.
    """
    _, F = poly.face_frame(face)
    u, v, n = F[:, 0], F[:, 1], F[:, 2]
    x = np.cos(roll) * u + np.sin(roll) * v
    z = -n
    return pin.SE3(np.column_stack([x, np.cross(z, x), z]), np.asarray(point, float))


def scenario_data(problem: DesignProblem, cand: Candidate, q0s=None, points=None) -> dict:
    """The scenario mapping of a candidate (``q0`` when given, else its IK seeds).

    Args:
        problem: the :class:`DesignProblem`.
        cand: the candidate.
        q0s: per arm its start configuration, or None.
        points: per arm (K, 3) the contact points to write (fingertips: where the tips
            touch), or None for the candidate's.
    """
    spec = problem.spec
    d = {"name": spec.name, "description": spec.description or
         f"designed by multiarm-pin design from {spec.file}"}
    d.update({k: v for k, v in spec.scenario_base.items() if k != "simulation"})
    arms = []
    for i, (slot, a) in enumerate(zip(spec.arms, cand.arms, strict=True)):
        e = {"name": slot.name}
        if slot.robot is not None:
            e["robot"] = slot.robot
        else:
            e["urdf"] = slot.urdf
        if slot.tool_frame is not None:
            e["tool_frame"] = slot.tool_frame
        e["base"] = {"position": _r(a.base[:3]), "rpy": [0.0, 0.0, round(float(a.base[3]), 10)]}
        if q0s is not None:
            e["q0"] = _r(q0s[i])
        else:
            e["q_seed"] = _r(a.q_seed)
        pts = a.points if points is None else points[i]
        if slot.gripper == "weld":
            M = weld_placement(problem.poly, a.faces[0], pts[0], a.roll)
            e["joint"] = {"type": "weld", "placement_in_object": {
                "position": _r(M.translation), "rpy": _r(pin.rpy.matrixToRpy(M.rotation))}}
        else:
            names = problem.poly.face_names
            e["joint"] = {"type": "fingertips", "tip_radius": slot.tip_radius, "contacts": [
                {"tip": t if isinstance(t, str) else _r(t), "face": names[f] if names else f,
                 "point": _r(p)}
                for t, f, p in zip(slot.tips, a.faces, pts, strict=True)]}
        arms.append(e)
    d["arms"] = arms
    d["controller"] = {"type": "object_pd", **spec.controller,
                       "waypoints": [dict(w) for w in spec.waypoints]}
    d["simulation"] = dict(spec.scenario_base["simulation"])
    return d


# ----------------------------------------------------------------------------- checks
def _without(q0s: list, i: int) -> list:
    return [None if k == i else q for k, q in enumerate(q0s)]


def _fail(cand: Candidate, condition: str, value: float, detail: str, **kw) -> Assessment:
    return Assessment(cand.index, cand, False, condition, float(value), detail, **kw)


def _start_ik(problem: DesignProblem, sc, cand: Candidate):
    """Per arm the start configuration and (K, 3) contact points, or a ``reach`` failure."""
    from multiarm_pin.app.scenario.build import (
        build_arm,
        contact_targets,
        joint_targets,
        tips_in_tool,
    )
    from multiarm_pin.model.ik import PoseTarget, solve_ik

    oMo = problem.object_placement
    q0s, points, arms = [], [], []
    for spec_arm, slot, a in zip(sc.arms, problem.spec.arms, cand.arms, strict=True):
        arm = build_arm(sc, spec_arm, load_visuals=False)
        tool = arm.model.frames[arm.tool_frame_id].name
        if slot.gripper == "weld":
            targets = joint_targets(spec_arm, tool, oMo)[0]
        elif a.tool is not None:  # the fitted grip: the tool where it puts the tips
            targets = [PoseTarget(tool, oMo * pin.XYZQUATToSE3(a.tool))]
        else:
            targets = contact_targets(sc, spec_arm, problem.poly, oMo, tool)
        ik, residual = None, np.inf
        rng = candidate_rng(problem.spec.search.seed, cand.index, 1 + slot.index)
        for t in range(1 + SEED_RETRIES):
            seed = a.q_seed if t == 0 else random_seed_configuration(
                problem, slot.index, a.base, oMo.act(a.points.mean(axis=0)), rng)
            try:
                ik = solve_ik(arm.model, targets, seed, max_iter=IK_ITERATIONS, restarts=0,
                              what=f"arm {slot.name}")
                break
            except UnreachableError as exc:
                residual = min(residual, exc.residual)
        if ik is None:
            solved = q0s + [None] * (len(cand.arms) - len(q0s))
            return None, _fail(cand, "reach", residual, slot.name, solved=solved)
        if slot.gripper == "weld":
            pts = a.points
        else:  # where the tips touch: sphere centres moved by the radius into the faces
            oMt = arm.tool_placement(ik.q)
            tips = tips_in_tool(sc, spec_arm, arm)
            M = oMo.actInv(oMt)
            pts = np.array([M.act(t) - slot.tip_radius * problem.poly.normals[f]
                            for t, f in zip(tips, a.faces, strict=True)])
            for k, (f, p) in enumerate(zip(a.faces, pts, strict=True)):
                m = face_edge_margin(problem.poly, f, p)
                if not point_allowed(problem.spec, problem.poly, f, p,
                                     problem.spec.search.face_margin, problem.rects):
                    solved = q0s + [None] * (len(cand.arms) - len(q0s))
                    return None, _fail(cand, "reach", max(problem.spec.search.face_margin - m,
                                                          1e-12),
                                       f"{slot.name}:tip[{k}] outside its face's margin",
                                       solved=solved)
        q0s.append(ik.q)
        points.append(pts)
        arms.append(arm)
    return (q0s, points, arms), None


def _smallest_singular_value(arm, q: np.ndarray) -> float:
    """Smallest singular value of the arm's (6, nv) tool Jacobian at ``q`` (world-aligned)."""
    J = pin.computeFrameJacobian(arm.model, arm.data, q, arm.tool_frame_id,
                                 pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
    return float(np.linalg.svd(J, compute_uv=False)[-1])


def _manipulability(arm, q: np.ndarray) -> float:
    J = pin.computeFrameJacobian(arm.model, arm.data, q, arm.tool_frame_id,
                                 pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
    return float(np.sqrt(max(np.linalg.det(J @ J.T), 0.0)))


def grasp_of(problem: DesignProblem, cand: Candidate, points) -> object:
    """The fingertip contacts as a :class:`~multiarm_pin.grasp.Grasp` (object frame)."""
    from multiarm_pin.grasp.contacts import Grasp, contact_on_face

    contacts = []
    for slot, a, pts in zip(problem.spec.arms, cand.arms, points, strict=True):
        if slot.gripper == "weld":
            continue
        for f, p in zip(a.faces, pts, strict=True):
            contacts.append(contact_on_face(problem.poly, f, p, tol=1e-6))
    return Grasp(tuple(contacts), problem.poly)


def closure_scores(problem: DesignProblem, system, state, grasp) -> dict:
    """Form closure LP margin, Ferrari-Canny ε (qhull) and the stability bound [m].

    The wrenches are those of :func:`~multiarm_pin.app.precheck.grasp_wrenches` at the start
    (moments over the object's largest vertex distance).
    """
    from multiarm_pin.app.precheck import grasp_wrenches
    from multiarm_pin.grasp.form_closure import form_closure
    from multiarm_pin.grasp.stability import closure_bound

    L = float(np.max(np.linalg.norm(problem.poly.vertices, axis=1)))
    fc = form_closure(grasp_wrenches(system, state, L), allow_fewer=True)
    out = {"form_closure": fc.form_closure, "lp_epsilon": fc.lp_epsilon,
           "lp_margin": fc.margin, "ferrari_canny": fc.ferrari_canny, "stability": 0.0}
    if fc.form_closure:
        out["stability"] = closure_bound(grasp).bound
    return out


def assess(problem: DesignProblem, cand: Candidate) -> Assessment:
    """Check one candidate against every condition and score it (module docstring)."""
    from multiarm_pin.app.scenario import build_scenario
    from multiarm_pin.app.scenario.schema import parse_scenario
    from multiarm_pin.exceptions import ScenarioError

    spec = problem.spec
    try:
        sc = parse_scenario(scenario_data(problem, cand), spec.file)
        start, failed = _start_ik(problem, sc, cand)
        if failed is not None:
            return failed
        q0s, points, arms = start
        data = scenario_data(problem, cand, q0s, points)
        built = build_scenario(parse_scenario(data, spec.file), load_visuals=False)
    except ScenarioError as exc:
        return _fail(cand, "reach", np.inf, str(exc))
    system, state0 = built.system, built.initial_state
    fingertips = any(s.gripper != "weld" for s in spec.arms)
    scores = {}
    if fingertips:
        try:
            grasp = grasp_of(problem, cand, points)
        except MultiArmError as exc:
            return _fail(cand, "reach", np.inf, str(exc), q0=q0s, scenario=data)
        cs = closure_scores(problem, system, state0, grasp)
        if not cs["form_closure"]:
            eps = cs["lp_epsilon"] if np.isfinite(cs["lp_epsilon"]) else -1.0
            return _fail(cand, "closure", eps, "fingertip contacts not form closure",
                         q0=q0s, scenario=data)
        scores.update({k: cs[k] for k in ("lp_margin", "ferrari_canny", "stability")})
    # the task: each pose's inverse kinematics from the previous configuration
    from multiarm_pin.model.ik import ik_tool_placement

    oMo = problem.object_placement
    tools = [oMo.actInv(arm.tool_placement(q)) for arm, q in zip(arms, q0s, strict=True)]
    Q = [np.concatenate(q0s)]
    prev = [q.copy() for q in q0s]
    for k, M in enumerate(problem.path_placements[1:], start=1):
        row = []
        for i, (arm, tool) in enumerate(zip(arms, tools, strict=True)):
            try:
                ik = ik_tool_placement(arm, M * tool, prev[i], max_iter=IK_ITERATIONS,
                                       restarts=0)
            except UnreachableError as exc:
                return _fail(cand, "path", exc.residual,
                             f"{spec.arms[i].name} at t = {problem.path_times[k]:.3g} s",
                             q0=q0s, scenario=data, solved=_without(q0s, i))
            step = float(np.max(np.abs(ik.q - prev[i])))
            if step > MAX_JOINT_STEP:
                return _fail(cand, "path", step, f"{spec.arms[i].name} jumps {step:.3g} rad "
                             f"at t = {problem.path_times[k]:.3g} s (another IK branch)",
                             q0=q0s, scenario=data, solved=_without(q0s, i))
            prev[i] = ik.q
            row.append(ik.q)
        Q.append(np.concatenate(row))
    Q = np.array(Q)
    for k, q in enumerate(Q):
        at = 0
        for i, arm in enumerate(arms):
            sigma = _smallest_singular_value(arm, q[at:at + arm.nq])
            at += arm.nq
            if sigma < MIN_SINGULAR_VALUE:
                return _fail(cand, "path", MIN_SINGULAR_VALUE - sigma,
                             f"{spec.arms[i].name} near a singularity at t = "
                             f"{problem.path_times[k]:.3g} s (smallest singular value of its "
                             f"tool Jacobian {sigma:.3g}, needs {MIN_SINGULAR_VALUE:g})",
                             q0=q0s, scenario=data, solved=_without(q0s, i))
    # collisions and clearances along the task
    from multiarm_pin.feasibility import CollisionScene

    ground = spec.scenario_base.get("ground", {"height": 0.0})
    ground = None if ground is None else float(ground.get("height", 0.0))
    scene = CollisionScene(system, state0, ground)
    ct = system.constraint_set.evaluate(system.arm_set.tool_kinematics(state0.q, state0.v),
                                        state0.obj.kinematics())
    cps_obj = [np.array([oMo.actInv(p) for p in ct.contact_points[i,
                                                                  :int(system.constraint_set.N[i])]])
               for i in range(system.n_arms)]
    cps = [np.array([[M.act(p) for p in c] for M in problem.path_placements]) for c in cps_obj]
    scan = scene.scan(Q, problem.path_positions, problem.path_quaternions, cps)
    clear = {k: v for k, v in scan.clearance.items() if v is not None}
    worst = min(clear, key=clear.get) if clear else None
    min_clear = clear[worst] if clear else np.inf
    if scan.hits or min_clear < spec.search.clearance:
        if scan.hits:
            k = next(iter(scan.hits))
            arm, link, other = scene.pair_names(k)
            detail = f"{arm}/{link} and {other} collide"
            min_clear = min(min_clear, min(h[1] for h in scan.hits[k]))
        else:
            detail = f"{worst.replace('_', '-')} clearance"
        return _fail(cand, "collision", min_clear, detail, q0=q0s, scenario=data, path_q=Q,
                     solved=list(q0s))
    scores["clearance"] = float(min_clear)
    # static torques along the task
    from multiarm_pin.app.precheck import effort_limits, joint_names, static_torques

    limits = np.concatenate([effort_limits(a) for a in arms])
    names = [f"{a.name} {j}" for a in arms for j in joint_names(a)]
    worst_ratio, worst_at, worst_j = 0.0, "", 0
    for k, q in enumerate(Q):
        st = system.state(q, None, problem.path_positions[k], problem.path_quaternions[k])
        try:
            tau, _ = static_torques(system, st)
        except DynamicsError as exc:
            return _fail(cand, "closure", 0.0, f"the contacts cannot hold the object at t = "
                         f"{problem.path_times[k]:.3g} s: {exc}", q0=q0s, scenario=data,
                         path_q=Q)
        ratio = np.abs(tau) / limits
        j = int(np.argmax(ratio))
        if ratio[j] > worst_ratio:
            worst_ratio, worst_j, worst_at = float(ratio[j]), j, f"{names[j]} at t = " \
                f"{problem.path_times[k]:.3g} s"
    if worst_ratio > 1.0:
        return _fail(cand, "torque", worst_ratio, worst_at, q0=q0s, scenario=data, path_q=Q)
    scores["torque_ratio"] = worst_ratio
    manip = [_manipulability(a, q) for a, q in zip(arms, q0s, strict=True)]
    scores["manipulability"] = min(manip)
    ends = np.cumsum([len(effort_limits(a)) for a in arms])
    return Assessment(cand.index, cand, True, None, None, worst_at, scores, q0s, Q, data,
                      list(q0s), int(np.searchsorted(ends, worst_j, side="right")),
                      int(np.argmin(manip)))


__all__ = ["CONDITIONS", "MIN_SINGULAR_VALUE", "Assessment", "DesignProblem", "assess",
           "candidate_from_scenario", "closure_scores", "grasp_of", "scenario_data",
           "weld_placement"]


def candidate_from_scenario(problem: DesignProblem, scenario, index: int = 0) -> Candidate:
    """A scenario's own design as a candidate (to score a hand-made design the same way).

    Its bases (position and yaw), its welds' faces, points and rolls, its fingertips' faces
    and points, and as IK seeds the configurations its builder finds (``q0`` or inverse
    kinematics from ``q_seed``).

    Args:
        problem: the :class:`DesignProblem` of a spec with the scenario's arms, in order.
        scenario: a scenario file path or :class:`~multiarm_pin.app.scenario.specs.Scenario`.
        index: the candidate's index.

    Raises:
        InputError: an arm's base is not upright, or a weld's tool z axis does not point
            into one face.
    """
    from multiarm_pin.app.scenario import build_scenario, load_scenario
    from multiarm_pin.design.candidates import ArmChoice
    from multiarm_pin.exceptions import InputError

    sc = scenario if hasattr(scenario, "arms") else load_scenario(scenario)
    built = build_scenario(sc, load_visuals=False)
    poly = problem.poly
    arms = []
    for spec_arm, q in zip(sc.arms, built.q0, strict=True):
        B = spec_arm.base
        if B.rotation[2, 2] < 1.0 - 1e-9:
            raise InputError(f"arm {spec_arm.name!r}: its base is not upright")
        base = np.array([*B.translation, float(pin.rpy.matrixToRpy(B.rotation)[2])])
        if spec_arm.joint.type == "weld":
            M = spec_arm.joint.placement_in_object
            z = M.rotation[:, 2]
            f = int(np.argmax(-(poly.normals @ z)))
            if -(poly.normals[f] @ z) < 1.0 - 1e-9:
                raise InputError(f"arm {spec_arm.name!r}: the tool's z axis does not point "
                                 "into a face")
            _, F = poly.face_frame(f)
            x = M.rotation[:, 0]
            roll = float(np.arctan2(x @ F[:, 1], x @ F[:, 0]))
            arms.append(ArmChoice(base, (f,), M.translation[None].copy(), roll, q.copy()))
        else:
            faces = tuple(poly.face_index(c.face) for c in spec_arm.joint.contacts)
            pts = np.array([c.point for c in spec_arm.joint.contacts])
            arms.append(ArmChoice(base, faces, pts, 0.0, q.copy()))
    return Candidate(index, tuple(arms))
