"""One robot arm: a Pinocchio model with a base placement in the world and a tool frame.

An :class:`Arm` is loaded from an ``example_robot_data`` name (``ur5``, ``ur10``, ``panda``...)
or from a URDF file. Its base placement is baked into the Pinocchio model (``pin.appendModel``
onto an empty world), so every quantity Pinocchio computes is already in the world frame and
gravity acts in the right direction. The tool frame is an operational frame added to the model
(``<tool_frame>`` plus an optional fixed offset), so tool placements, twists, Jacobians and
accelerations all come from Pinocchio's own algorithms.

Where the models come from (the robot registry, URDF files, locking joints, frame look-up) is
:mod:`multiarm_pin.model.sources`.

For a state ``(q, v)`` :meth:`Arm.terms` computes, once, everything the dynamics needs
(:class:`ArmTerms`). To evaluate many arms at once use :class:`multiarm_pin.model.arm_set.ArmSet`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from multiarm_pin.exceptions import (
    FrameNotFoundError,
    InputError,
    SingularityError,
    URDFError,
)
from multiarm_pin.model.robots import ROBOTS, robot_entry
from multiarm_pin.model.sources import (
    frame_id,
    load_example_robot,
    lock_joints,
    unique_frame_names,
    validate_urdf,
)
from multiarm_pin.spatial import as_array, as_se3

TOOL_FRAME_NAME = "multiarm_tool"
"""Name of the operational frame that :class:`Arm` adds at its tool (frame + offset)."""

LAMBDA_CONDITION_LIMIT = 1e10
"""Largest condition number of ``Λ⁻¹`` for which the operational-space inertia ``Λ`` exists."""

def available_robots() -> list[str]:
    """Names accepted by :meth:`Arm.from_robot_name` (fixed-base arms), sorted."""
    return sorted(ROBOTS)


@dataclass(frozen=True)
class ArmTerms:
    """Everything the dynamics needs from one arm at one state; all world quantities.

    Attributes:
        q: (nq,) joint positions [rad or m].
        v: (nv,) joint velocities.
        M: (nv, nv) joint-space mass matrix [kg m^2].
        nle: (nv,) nonlinear effects ``C(q, v) v + g(q)`` [N m].
        gravity: (nv,) gravity torque ``g(q)`` [N m].
        tool_position: (3,) tool origin in the world [m].
        tool_rotation: (3, 3) tool axes -> world axes.
        tool_twist: (6,) ``[v; ω]`` of the tool origin in world axes (LOCAL_WORLD_ALIGNED).
        J: (6, nv) tool Jacobian, LOCAL_WORLD_ALIGNED (``tool_twist = J v``).
        J_local: (6, nv) tool Jacobian in the tool frame (LOCAL).
        Jdot_qdot: (6, nv) -> (6,) classical acceleration of the tool at zero joint acceleration,
            ``[ẍ; ω̇]`` in world axes [m/s^2, rad/s^2] (``a_tool = J q̈ + Jdot_qdot``).
        Lambda_inv: (6, 6) ``J M⁻¹ Jᵀ`` (LOCAL_WORLD_ALIGNED), defined at every configuration.
        Lambda_condition: condition number of ``Lambda_inv``.
    """

    q: np.ndarray
    v: np.ndarray
    M: np.ndarray
    nle: np.ndarray
    gravity: np.ndarray
    tool_position: np.ndarray
    tool_rotation: np.ndarray
    tool_twist: np.ndarray
    J: np.ndarray
    J_local: np.ndarray
    Jdot_qdot: np.ndarray
    Lambda_inv: np.ndarray
    Lambda_condition: float

    @property
    def tool_placement(self) -> pin.SE3:
        """Tool placement in the world as ``pin.SE3``."""
        return pin.SE3(self.tool_rotation, self.tool_position)

    @property
    def has_operational_space_inertia(self) -> bool:
        """False at (or too near) a singular configuration, where ``Λ`` does not exist."""
        return self.Lambda_condition < LAMBDA_CONDITION_LIMIT

    @property
    def Lambda(self) -> np.ndarray:
        """(6, 6) operational-space inertia ``Λ = (J M⁻¹ Jᵀ)⁻¹`` [kg, kg m^2].

        Raises:
            SingularityError: the arm is at (or too near) a singular configuration or has
                fewer than 6 joints, so ``J M⁻¹ Jᵀ`` cannot be inverted.
        """
        if not self.has_operational_space_inertia:
            raise SingularityError(
                "J M^-1 J^T",
                self.Lambda_condition,
                "the operational-space inertia does not exist at this configuration "
                "(singular arm or fewer than 6 joints); use Lambda_inv instead",
            )
        return np.linalg.inv(self.Lambda_inv)


@dataclass
class Arm:
    """A robot arm in the world.

    Build it with :meth:`from_robot_name`, :meth:`from_urdf` or :func:`load_arm`.

    Attributes:
        name: the arm's name in its system (used to prefix joint names in combined models).
        model: Pinocchio model with the base placement baked in and the tool frame added.
        tool_frame_id: id of the tool frame in ``model``.
        base_placement: placement of the robot's root in the world.
        tool_frame: name of the frame the tool is attached to.
        tool_offset: fixed placement of the tool relative to ``tool_frame``.
        visual_model: visual geometry (meshes), when available.
        source: where it came from (robot name or URDF path), for messages.
    """

    name: str
    model: pin.Model
    tool_frame_id: int
    base_placement: pin.SE3
    tool_frame: str
    tool_offset: pin.SE3
    visual_model: pin.GeometryModel | None = None
    source: str = ""
    data: pin.Data = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.data = self.model.createData()

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_model(
        cls,
        model: pin.Model,
        tool_frame: str,
        *,
        name: str = "arm",
        base_placement: pin.SE3 | None = None,
        tool_offset: pin.SE3 | None = None,
        visual_model: pin.GeometryModel | None = None,
        source: str = "",
    ) -> Arm:
        """Wrap a fixed-base Pinocchio model (root at its own origin).

        Args:
            model: the robot, its root at the origin of its base.
            tool_frame: a frame name of ``model``.
            name: the arm's name.
            base_placement: world placement of the robot's root (default: identity).
            tool_offset: tool placement relative to ``tool_frame`` (default: identity).
            visual_model: visual geometry of ``model``.
            source: robot name or URDF path, for messages.

        Raises:
            FrameNotFoundError: ``tool_frame`` is not a frame of the model (lists them).
            InputError: the model has a free-flyer root (not an arm).
        """
        base = pin.SE3.Identity() if base_placement is None else pin.SE3(base_placement)
        offset = pin.SE3.Identity() if tool_offset is None else pin.SE3(tool_offset)
        names = [f.name for f in model.frames]
        if not model.existFrame(tool_frame):
            raise FrameNotFoundError(tool_frame, names, source or name)
        if model.njoints > 1 and model.joints[1].shortname() == "JointModelFreeFlyer":
            raise InputError(f"{source or name}: a free-floating robot is not an arm")
        model = unique_frame_names(model)
        world = pin.Model()
        world.gravity = model.gravity
        if visual_model is not None:
            placed, placed_visual = pin.appendModel(
                world, model, pin.GeometryModel(), visual_model, 0, base
            )
        else:
            placed, placed_visual = pin.appendModel(world, model, 0, base), None
        parent_id = frame_id(placed, tool_frame, source or name)
        parent = placed.frames[parent_id]
        frame = pin.Frame(
            TOOL_FRAME_NAME,
            parent.parentJoint,
            parent_id,
            parent.placement * offset,
            pin.FrameType.OP_FRAME,
        )
        fid = placed.addFrame(frame)
        return cls(
            name=name,
            model=placed,
            tool_frame_id=fid,
            base_placement=base,
            tool_frame=tool_frame,
            tool_offset=offset,
            visual_model=placed_visual,
            source=source,
        )

    @classmethod
    def from_robot_name(
        cls,
        robot: str,
        tool_frame: str | None = None,
        *,
        name: str | None = None,
        base_placement: pin.SE3 | None = None,
        tool_offset: pin.SE3 | None = None,
        locked_joints: tuple[str, ...] = (),
        load_visuals: bool = True,
    ) -> Arm:
        """Load an arm from ``example_robot_data`` (``ur5``, ``ur10``, ``panda``, ...).

        The registry (:data:`multiarm_pin.model.robots.ROBOTS`) gives the default tool frame (the
        flange or the hand) and the gripper joints locked at their neutral value
        (``pin.buildReducedModel``); ``locked_joints`` locks more.

        Args:
            robot: registered name (:func:`available_robots`).
            tool_frame: frame of the tool (default: the registry's).
            name: the arm's name (default: ``robot``).
            base_placement: world placement of the robot's root.
            tool_offset: tool placement relative to ``tool_frame``.
            locked_joints: extra joints to lock at their neutral value.
            load_visuals: also load the visual geometry (meshes) for the replay.

        Raises:
            RobotNotFoundError: unknown name (the message lists :func:`available_robots`).
            FrameNotFoundError: ``tool_frame`` missing (the message lists the frames).
            JointNotFoundError: a locked joint is not a joint of the robot (lists them).
        """
        entry = robot_entry(robot)
        model, visual = load_example_robot(robot)
        locked = tuple(dict.fromkeys((*entry.locked_joints, *locked_joints)))
        if locked:
            model, visual = lock_joints(model, visual, locked, f"example_robot_data:{robot}")
        return cls.from_model(
            model,
            tool_frame or entry.tool_frame,
            name=name or robot,
            base_placement=base_placement,
            tool_offset=tool_offset,
            visual_model=visual if load_visuals else None,
            source=f"example_robot_data:{robot}",
        )

    @classmethod
    def from_urdf(
        cls,
        path: str | Path,
        tool_frame: str,
        *,
        name: str | None = None,
        base_placement: pin.SE3 | None = None,
        tool_offset: pin.SE3 | None = None,
        package_dirs: list[str] | None = None,
        locked_joints: tuple[str, ...] = (),
        load_visuals: bool = True,
    ) -> Arm:
        """Load an arm from a URDF file (validated with ``yourdfpy`` first).

        Args:
            path: the URDF file.
            tool_frame: a link or frame name of the URDF.
            name: the arm's name (default: the file's stem).
            base_placement: world placement of the URDF's root link.
            tool_offset: tool placement relative to ``tool_frame``.
            package_dirs: where ``package://`` meshes are looked up (default: the file's
                folder and its parents).
            locked_joints: joints to lock at their neutral value (e.g. gripper fingers).
            load_visuals: also load the visual geometry (meshes) for the replay.

        Raises:
            URDFError: missing file, malformed XML, or not a valid robot (names the file).
            FrameNotFoundError: ``tool_frame`` missing (names the file and lists the frames).
        """
        path = Path(path)
        validate_urdf(path)
        try:
            model = pin.buildModelFromUrdf(str(path))
        except Exception as exc:  # Pinocchio raises bare RuntimeError/ValueError
            raise URDFError(str(path), f"Pinocchio cannot build a model: {exc}") from exc
        if not model.existFrame(tool_frame):
            raise FrameNotFoundError(tool_frame, [f.name for f in model.frames], str(path))
        visual = None
        if load_visuals:
            dirs = package_dirs or [str(p) for p in (path.parent, *path.parents[:3])]
            try:
                visual = pin.buildGeomFromUrdf(
                    model, str(path), pin.GeometryType.VISUAL, package_dirs=dirs
                )
            except Exception:  # meshes missing: the arm still simulates, without visuals
                visual = None
        if locked_joints:
            model, visual = lock_joints(model, visual, locked_joints, str(path))
        return cls.from_model(
            model,
            tool_frame,
            name=name or path.stem,
            base_placement=base_placement,
            tool_offset=tool_offset,
            visual_model=visual,
            source=str(path),
        )

    # ------------------------------------------------------------------ properties
    @property
    def nq(self) -> int:
        """Number of configuration variables."""
        return self.model.nq

    @property
    def nv(self) -> int:
        """Number of joint velocities (degrees of freedom)."""
        return self.model.nv

    @property
    def frame_names(self) -> list[str]:
        """Names of the model's frames."""
        return [f.name for f in self.model.frames]

    def neutral(self) -> np.ndarray:
        """(nq,) neutral configuration."""
        return pin.neutral(self.model)

    def check_state(self, q, v=None) -> tuple[np.ndarray, np.ndarray]:
        """Validate a state; returns ``q`` (nq,) and ``v`` (nv,) as float arrays.

        Raises:
            InputError: wrong shapes or non-finite values (says what was expected).
        """
        q = as_array(q, (self.nq,), f"{self.name}: q")
        v = np.zeros(self.nv) if v is None else as_array(v, (self.nv,), f"{self.name}: v")
        return q, v

    # ------------------------------------------------------------------ kinematics/dynamics
    def tool_placement(self, q) -> pin.SE3:
        """World placement of the tool at configuration ``q`` (nq,)."""
        q, _ = self.check_state(q)
        pin.framesForwardKinematics(self.model, self.data, q)
        return pin.SE3(self.data.oMf[self.tool_frame_id])

    def frame_placement(self, q, frame: str) -> pin.SE3:
        """World placement of any frame of the arm at configuration ``q`` (nq,)."""
        q, _ = self.check_state(q)
        fid = frame_id(self.model, frame, self.source or self.name)
        pin.framesForwardKinematics(self.model, self.data, q)
        return pin.SE3(self.data.oMf[fid])

    def terms(self, q, v=None) -> ArmTerms:
        """All dynamic terms at ``(q, v)``, each computed once by Pinocchio.

        Args:
            q: (nq,) joint positions.
            v: (nv,) joint velocities (default zero).

        Returns:
            :class:`ArmTerms` (world frame, LOCAL_WORLD_ALIGNED at the tool origin).
        """
        q, v = self.check_state(q, v)
        model, data, fid = self.model, self.data, self.tool_frame_id
        LWA, LOCAL = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED, pin.ReferenceFrame.LOCAL
        pin.forwardKinematics(model, data, q, v, np.zeros(model.nv))
        pin.updateFramePlacements(model, data)
        M = pin.crba(model, data, q).copy()
        nle = pin.nonLinearEffects(model, data, q, v).copy()
        gravity = pin.computeGeneralizedGravity(model, data, q).copy()
        pin.computeJointJacobians(model, data, q)
        J = pin.getFrameJacobian(model, data, fid, LWA).copy()
        J_local = pin.getFrameJacobian(model, data, fid, LOCAL).copy()
        twist = pin.getFrameVelocity(model, data, fid, LWA).vector.copy()
        Jdot_qdot = pin.getFrameClassicalAcceleration(model, data, fid, LWA).vector.copy()
        oMf = data.oMf[fid]
        Lambda_inv, cond = inverse_operational_space_inertia(M, J)
        return ArmTerms(
            q=q,
            v=v,
            M=M,
            nle=nle,
            gravity=gravity,
            tool_position=oMf.translation.copy(),
            tool_rotation=oMf.rotation.copy(),
            tool_twist=twist,
            J=J,
            J_local=J_local,
            Jdot_qdot=Jdot_qdot,
            Lambda_inv=Lambda_inv,
            Lambda_condition=cond,
        )


def inverse_operational_space_inertia(M: np.ndarray, J: np.ndarray) -> tuple[np.ndarray, float]:
    """``Λ⁻¹ = J M⁻¹ Jᵀ`` through a Cholesky factor of ``M``, and its condition number.

    Args:
        M: (nv, nv) symmetric positive-definite mass matrix.
        J: (k, nv) Jacobian.

    Returns:
        ``(Λ⁻¹ (k, k), condition number)``; the condition number is ``inf`` when singular.
    """
    L = np.linalg.cholesky(M)
    X = np.linalg.solve(L, J.T)  # L X = Jᵀ  ->  Λ⁻¹ = Xᵀ X
    Lambda_inv = X.T @ X
    s = np.linalg.svd(Lambda_inv, compute_uv=False)
    cond = float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    return Lambda_inv, cond


def load_arm(
    robot: str | None = None,
    *,
    urdf: str | Path | None = None,
    name: str | None = None,
    base: pin.SE3 | None = None,
    tool_frame: str | None = None,
    tool_offset: pin.SE3 | None = None,
    locked_joints: tuple[str, ...] = (),
    load_visuals: bool = True,
    package_dirs: list[str] | None = None,
) -> Arm:
    """Load an arm by ``example_robot_data`` name or from a URDF path (exactly one of them).

    Example: ``load_arm("ur5", name="left", base=pin.SE3(np.eye(3), np.array([0, 0.5, 0])))``.

    Args:
        robot: a registered name (:func:`available_robots`), or None with ``urdf``.
        urdf: a URDF file (then ``tool_frame`` is required).
        name: the arm's name in its system (default: ``robot`` or the file's stem).
        base: placement of the robot's root in the world, ``pin.SE3`` (default: identity).
        tool_frame: frame of the tool (default for a robot name: the registry's flange or
            hand).
        tool_offset: fixed placement of the tool relative to ``tool_frame``, ``pin.SE3``.
        locked_joints: joints locked at their neutral value (besides the registry's).
        load_visuals: also load the meshes, which only the replay draws (True, the default of
            every arm loader: a replay of arms loaded without them shows spheres at the
            joints; the ``run`` command and studies pass False when they write no replay).
        package_dirs: where a URDF's ``package://`` meshes are looked up.

    Raises:
        InputError: neither or both of ``robot`` and ``urdf``, a URDF without ``tool_frame``,
            or a placement that is not a ``pin.SE3``.
        RobotNotFoundError, URDFError, FrameNotFoundError, JointNotFoundError: see
            :meth:`Arm.from_robot_name` and :meth:`Arm.from_urdf`.
    """
    if (robot is None) == (urdf is None):
        raise InputError("give exactly one of robot (a name) or urdf (a path)")
    placements = {
        "base_placement": None if base is None else as_se3(base, "load_arm base"),
        "tool_offset": None if tool_offset is None else as_se3(tool_offset, "load_arm tool_offset"),
    }
    if robot is not None:
        if package_dirs is not None:
            raise InputError(f"{robot}: package_dirs is for URDF arms only")
        return Arm.from_robot_name(robot, tool_frame, name=name, locked_joints=locked_joints,
                                   load_visuals=load_visuals, **placements)
    if tool_frame is None:
        raise InputError(f"{urdf}: a URDF arm needs tool_frame")
    return Arm.from_urdf(urdf, tool_frame, name=name, package_dirs=package_dirs,
                         locked_joints=locked_joints, load_visuals=load_visuals, **placements)
