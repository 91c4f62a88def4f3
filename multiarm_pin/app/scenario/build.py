"""Building a validated scenario into a system with a checked initial state.

The object, the arms (placed by ``q0`` or by inverse kinematics), their joints, the supports,
and the :class:`~multiarm_pin.system.MultiArmSystem`.

The joints are built by the system layer (:func:`~multiarm_pin.system.joints_from_initial_state`)
and the initial state is checked by :meth:`~multiarm_pin.system.MultiArmSystem.check_initial_state`
(tolerance :data:`~multiarm_pin.constraints.joint.INITIAL_GAP_TOLERANCE`); their errors become
:class:`~multiarm_pin.exceptions.ScenarioError` naming the file and the key that sets the value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from multiarm_pin.app.scenario.specs import ArmSpec, Scenario
from multiarm_pin.constraints.joint_types import JOINT_TYPES
from multiarm_pin.exceptions import (
    FrameNotFoundError,
    InitialGapError,
    JointNotFoundError,
    MultiArmError,
    RobotNotFoundError,
    ScenarioError,
    URDFError,
)
from multiarm_pin.yaml_reader import did_you_mean


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


def tips_in_tool(scenario, spec: ArmSpec, arm) -> np.ndarray:
    """(K, 3) fingertip centres in the tool frame [m] of a ``fingertips`` joint's arm.

    A tip given as a point (``tip_in_tool``) is that point; a tip given by a frame is that
    frame's origin at the neutral configuration (a rigid gripper: the same at every
    configuration).

    Raises:
        ScenarioError: a tip frame that the arm's model does not have (with did-you-mean).
    """
    q = arm.neutral()
    oMt = arm.tool_placement(q)
    out = []
    for k, c in enumerate(spec.joint.contacts):
        if c.tip_in_tool is not None:
            out.append(np.asarray(c.tip_in_tool, float))
            continue
        if not arm.model.existFrame(c.tip):
            frames = [f for f in arm.frame_names if f != "universe"]
            raise ScenarioError(
                scenario.file, f"arms[{spec.index}].joint.contacts[{k}].tip",
                f"frame {c.tip!r} not found in {arm.source}{did_you_mean(c.tip, frames)}; "
                f"frames: {', '.join(frames)}")
        out.append(oMt.actInv(arm.frame_placement(q, c.tip).translation))
    return np.array(out)


def contact_targets(scenario, spec: ArmSpec, poly, oMo: pin.SE3, tool: str):
    """IK targets for fingertips on faces: a plane per tip (primary), a point (preference).

    Args:
        scenario: the :class:`Scenario` (for messages).
        spec: the arm's spec (a ``fingertips`` joint).
        poly: the object's :class:`~multiarm_pin.model.polyhedron.Polyhedron`.
        oMo: the object's placement in the world.
        tool: the name of the arm's tool frame (a tip given in the tool frame is a point
            fixed to it).

    Raises:
        ScenarioError: an unknown face, or a point off its face.
    """
    from multiarm_pin.model.ik import PlaneTarget, PointTarget

    r = spec.joint.params.get("tip_radius", 0.0)
    approach = _approach(scenario, spec, poly)
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
        # sphere centre on the plane offset by the radius along the outward normal (and by
        # the approach offset: the gripper starts that far from its grasp)
        d_w = float(n_w @ oMo.translation) + d_o + r + float(n_o @ approach)
        frame, at = (c.tip, None) if c.tip_in_tool is None else (tool, c.tip_in_tool)
        targets.append(PlaneTarget(frame, n_w, d_w, point=at))
        targets.append(PointTarget(frame, oMo.act(p_o + r * n_o + approach), primary=False,
                                   offset=at))
    return targets


def _approach(scenario, spec: ArmSpec, poly) -> np.ndarray:
    """(3,) the fingertip joint's ``approach`` offset (object frame [m]), zero if none.

    No tip may start in the object: a tip moved to the inner side of its face's plane
    (``n_f · approach < 0``, ``n_f`` the outward normal) must be beside the face (the
    projection of its contact point so moved onto the face's plane outside the face), where
    its gap is a distance to the plane extended beyond the face, not a penetration.
    """
    a = np.asarray(spec.joint.params.get("approach", np.zeros(3)), dtype=float)
    for k, c in enumerate(spec.joint.contacts):
        try:
            f = poly.face_index(c.face)
        except MultiArmError:
            continue  # reported on its contact's key by the caller
        n = poly.normals[f]
        if float(n @ a) >= 0.0:
            continue
        point = c.point if c.point is not None else poly.vertices[list(poly.faces[f])].mean(0)
        moved = point + a - float(n @ a) * n  # on the face's plane
        if not poly.point_on_face(moved, f, 1e-9):
            continue  # beside the face
        raise ScenarioError(
            scenario.file, f"arms[{spec.index}].joint.approach",
            f"the offset {a.tolist()} m moves contact {k} ({c.tip} on face {c.face!r}) "
            f"into the object (outward normal {n.tolist()}); an approach offset must move "
            "every tip away from its face, or beside it")
    return a


def joint_targets(spec: ArmSpec, tool: str, oMo: pin.SE3) -> tuple[list, str]:
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


def _solve_arm_ik(scenario, spec: ArmSpec, arm, poly, oMo, hints: bool = True):
    """The arm's inverse kinematics (its :class:`~multiarm_pin.model.ik.IKResult`).

    When unreachable, the error says if a quaternion written w-first explains it
    (:func:`~multiarm_pin.app.diagnosis.w_first_hint`, unless ``hints`` is False).
    """
    from multiarm_pin.model.ik import PostureTarget, UnreachableError, solve_ik

    seed = spec.q_seed
    if seed is not None and len(seed) != arm.nq:
        raise ScenarioError(scenario.file, f"arms[{spec.index}].q_seed",
                            f"expected {arm.nq} numbers (nq of {arm.source}), got {len(seed)}")
    tool = arm.model.frames[arm.tool_frame_id].name
    if JOINT_TYPES[spec.joint.type].from_contacts:
        targets = contact_targets(scenario, spec, poly, oMo, tool)
        what = f"arm {spec.name!r}: fingertips on faces"
        key = f"arms[{spec.index}].joint.contacts"
    else:
        targets, goal = joint_targets(spec, tool, oMo)
        what = f"arm {spec.name!r} ({spec.joint.type} joint): {goal}"
        key = f"arms[{spec.index}].joint.placement_in_object"
        # among the configurations meeting the joint, prefer one near the seed (fingertips
        # have their points as preferences instead: those fix the gripper)
        targets.append(PostureTarget(seed if seed is not None else arm.neutral()))
    try:
        return solve_ik(arm.model, targets, seed, what=what)
    except UnreachableError as exc:
        from multiarm_pin.app.diagnosis import w_first_hint

        def reachable(other: ArmSpec, oMo_other: pin.SE3) -> bool:
            try:
                _solve_arm_ik(scenario, other, arm, poly, oMo_other, hints=False)
            except ScenarioError:
                return False
            return True

        hint = w_first_hint(scenario, spec, reachable) if hints else ""
        raise ScenarioError(scenario.file, key,
                            f"{exc}{hint} (try another q_seed, or move the arm's base)") from exc


def _fingertip_joint(scenario, spec: ArmSpec, arm, obj, oMt: pin.SE3, oMo: pin.SE3):
    """The ``fingertips`` joint of an arm whose tool is at ``oMt``: the real tip frames.

    Each fingertip's contact point is its sphere's point nearest the face, projected onto
    the face plane, so that the initial-state check reports the gap when it does not touch.
    """
    from multiarm_pin.constraints import make_joint, relative_placement

    j = spec.joint
    tips = tips_in_tool(scenario, spec, arm)
    approach = _approach(scenario, spec, obj.shape)
    # the joint is where the tips touch: the tool's placement less the approach offset
    oMt = pin.SE3(oMt.rotation, oMt.translation - oMo.rotation @ approach)
    M = relative_placement(oMt, oMo)
    r = j.params.get("tip_radius", 0.0)
    contacts = []
    for k, (c, tip) in enumerate(zip(j.contacts, tips, strict=True)):
        f = obj.shape.face_index(c.face)
        point = M.act(tip) - r * obj.shape.normals[f]
        point = point - obj.shape.signed_distance_to_face(point, f) * obj.shape.normals[f]
        if not obj.shape.contains(point, 1e-6):
            raise ScenarioError(
                scenario.file, f"arms[{spec.index}].joint.contacts[{k}]",
                f"fingertip {c.tip!r} touches the plane of face {c.face!r} at "
                f"{np.round(point, 4).tolist()} (object frame), outside the face")
        contacts.append((f, point))
    return make_joint(j.type, polyhedron=obj.shape, contacts=contacts, radius=r,
                      tip_points_in_tool=tips, tool_in_object=M, name=f"{spec.name}:{j.type}",
                      tol=1e-5, unilateral=j.params.get("unilateral", True),
                      starts_apart="approach" in j.params)


def _joint_spec(scenario, spec: ArmSpec, arm, obj):
    """The arm's joint as a spec of :func:`~multiarm_pin.system.joints_from_initial_state`.

    A joint placed in the object is ready; one without placement has its frame where the
    tool is at t = 0 (the system's builder); fingertips use the arm's tip frames.
    """
    from multiarm_pin.constraints import make_joint, relative_placement

    j = spec.joint
    label = f"{spec.name}:{j.type}"
    if JOINT_TYPES[j.type].from_contacts:
        return lambda oMt, oMo: _fingertip_joint(scenario, spec, arm, obj, oMt, oMo)
    if j.placement_in_object is not None:
        return make_joint(j.type, joint_in_object=j.placement_in_object,
                          joint_in_tool=j.placement_in_tool, name=label, **j.params)
    if j.placement_in_tool is None:
        return {"type": j.type, "name": label, **j.params}
    J_t = j.placement_in_tool
    return lambda oMt, oMo: make_joint(j.type, joint_in_object=relative_placement(oMt, oMo) * J_t,
                                       joint_in_tool=J_t, name=label, **j.params)


def _build_joint(scenario, spec: ArmSpec, arm, obj, q):
    """The arm's joint built by the system layer from the initial configuration ``q``."""
    from multiarm_pin.system import joints_from_initial_state

    try:
        return joints_from_initial_state(
            arms=[arm], obj=obj, specs=[_joint_spec(scenario, spec, arm, obj)], q0=[q],
            object_placement=scenario.object.placement,
        )[0]
    except ScenarioError:
        raise
    except MultiArmError as exc:
        raise ScenarioError(scenario.file, f"arms[{spec.index}].joint", str(exc)) from exc


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
    from multiarm_pin.system import MultiArmSystem

    obj = build_object(scenario)
    oMo = scenario.object.placement
    arms, q0s, iks, joints = [], [], [], []
    for spec in scenario.arms:
        arm = build_arm(scenario, spec, load_visuals)
        key = f"arms[{spec.index}]"
        if JOINT_TYPES[spec.joint.type].from_contacts:
            tips_in_tool(scenario, spec, arm)  # fingertip frames exist (did-you-mean)
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
        joint = _build_joint(scenario, spec, arm, obj, q)
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
        system.check_initial_state(state)
    except ScenarioError:
        raise
    except InitialGapError as exc:
        raise _initial_gap_error(scenario, arms, joints, q0s, exc) from exc
    except MultiArmError as exc:
        raise ScenarioError(scenario.file, "arms", f"inconsistent initial state: {exc}") from exc
    return BuiltScenario(scenario, arms, obj, joints, system, state, q0s, iks)


def _initial_gap_error(scenario: Scenario, arms, joints, q0s,
                       exc: InitialGapError) -> ScenarioError:
    """The system's initial-gap error as a scenario error on the key that sets it.

    A violated joint is reported on ``arms[i].q0`` (or ``q_seed`` when inverse kinematics
    placed the arm), with the gap in m and mm and the tool's position; a penetrated support on
    ``supports[k].points``.
    """
    if exc.support is not None:
        sp = scenario.supports[exc.support]
        return ScenarioError(
            scenario.file, f"supports[{sp.index}].points",
            f"the object starts penetrating support {sp.name!r}: point {exc.contact} is "
            f"{-exc.gap:.6g} m below the plane (tolerance {exc.tol:g} m); move object.pose or "
            "the plane")
    if exc.arm is None:
        return ScenarioError(scenario.file, "arms", f"inconsistent initial state: {exc}")
    spec, joint = scenario.arms[exc.arm], joints[exc.arm]
    oMt = arms[exc.arm].tool_placement(q0s[exc.arm])
    return ScenarioError(
        scenario.file, f"arms[{spec.index}].{'q0' if spec.q0 is not None else 'q_seed'}",
        f"inconsistent initial state: the {spec.joint.type} joint of arm {spec.name!r} is "
        f"violated at the initial configuration: contact {exc.contact} "
        f"({joint.contacts[exc.contact].name}) has gap {exc.gap:.6g} m ({exc.gap * 1e3:.4g} mm; "
        f"tolerance {exc.tol:g} m); the tool is at {np.round(oMt.translation, 4).tolist()} m")


def _build_supports(scenario: Scenario, obj) -> list:
    """The :class:`~multiarm_pin.constraints.Support` of each ``supports[k]``."""
    from multiarm_pin.constraints import Support

    out = []
    for sp in scenario.supports:
        pts = obj.shape.vertices if isinstance(sp.points, str) else sp.points
        try:
            out.append(Support(sp.name, sp.point, sp.normal, pts, sp.restitution,
                               extent=sp.extent, x_axis=sp.x_axis))
        except MultiArmError as exc:
            raise ScenarioError(scenario.file, f"supports[{sp.index}]", str(exc)) from exc
    return out


__all__ = ["BuiltScenario", "build_arm", "build_object", "build_scenario", "contact_targets",
           "joint_targets", "tips_in_tool"]
