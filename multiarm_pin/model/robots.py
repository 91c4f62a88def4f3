"""Registry of the ``example_robot_data`` arms that :class:`~.arm.Arm` loads by name.

Each entry says which frame is the arm's tool (its end effector: the flange a tool is bolted
to, or the hand of a built-in gripper; never a fingertip) and which joints are locked at
their neutral value (gripper fingers, which a rigid grasp does not move). A test walks the
registry: every robot loads, its tool frame is the documented one at the end of the chain,
and it runs a short weld scenario.

| robot | tool frame | kind | locked joints |
|---|---|---|---|
| ``ur3``, ``ur5``, ``ur10`` (+ ``_limited``) | ``tool0`` | flange | |
| ``panda``, ``panda_collision`` | ``panda_hand_tcp`` | hand (between the fingers) | fingers |
| ``kinova`` (Jaco j2s6s200) | ``j2s6s200_end_effector`` | hand | |
| ``xarm7`` | ``link_eef`` | flange | |
| ``z1`` | ``gripperStator`` (its body frame) | hand | ``jointGripper`` |

Each entry also says how it is loaded: ``example_robot_data.load(name)``, or a named
``example_robot_data`` loader class when that registry is wrong: example-robot-data 5.0.0
registers ``ur3`` with its UR5 loader (``ur5_robot.urdf``), so our ``ur3`` entry names
``UR3Loader`` (``ur3_robot.urdf``: 0.1198 m shoulder offset, not the UR5's 0.13585 m).

Configurations: ``q0`` has ``nq`` numbers, which is not always the number of joints: a
continuous (unbounded revolute) joint is stored as ``(cos θ, sin θ)``. The Kinova Jaco has
three, so its ``q0`` takes 9 numbers (``nq = 9``, ``nv = 6``).
"""

from __future__ import annotations

from dataclasses import dataclass

from multiarm_pin.exceptions import RobotNotFoundError


@dataclass(frozen=True)
class RobotEntry:
    """One arm of the registry.

    Attributes:
        name: the ``example_robot_data`` name.
        tool_frame: the frame used as the tool when a scenario gives none.
        tool_kind: ``"flange"`` (tool mounting face) or ``"hand"`` (gripper body/centre).
        locked_joints: joints locked at their neutral value (gripper fingers).
        description: one line for humans.
        loader: name of the ``example_robot_data.robots_loader`` class that loads it, or
            ``""`` for ``example_robot_data.load(name)``.
    """

    name: str
    tool_frame: str
    tool_kind: str
    locked_joints: tuple[str, ...] = ()
    description: str = ""
    loader: str = ""

    def load(self):
        """The ``example_robot_data`` robot wrapper (``.model``, ``.visual_model``).

        Loading parses the URDF and reads every mesh (seconds for some robots).
        """
        import example_robot_data as erd

        if not self.loader:
            return erd.load(self.name)
        from example_robot_data import robots_loader

        return getattr(robots_loader, self.loader)().robot


_PANDA_FINGERS = ("panda_finger_joint1", "panda_finger_joint2")

ROBOTS: dict[str, RobotEntry] = {e.name: e for e in (
    RobotEntry("ur3", "tool0", "flange", description="Universal Robots UR3, 6 joints",
               loader="UR3Loader"),
    RobotEntry("ur5", "tool0", "flange", description="Universal Robots UR5, 6 joints"),
    RobotEntry("ur10", "tool0", "flange", description="Universal Robots UR10, 6 joints"),
    RobotEntry("ur5_limited", "tool0", "flange",
               description="UR5 with joint ranges limited to ±π"),
    RobotEntry("ur10_limited", "tool0", "flange",
               description="UR10 with joint ranges limited to ±π"),
    RobotEntry("panda", "panda_hand_tcp", "hand", _PANDA_FINGERS,
               "Franka Emika Panda, 7 joints; tool centre point between the locked fingers"),
    RobotEntry("panda_collision", "panda_hand_tcp", "hand", _PANDA_FINGERS,
               "Panda with collision meshes as visuals"),
    RobotEntry("kinova", "j2s6s200_end_effector", "hand",
               description="Kinova Jaco j2s6s200, 6 joints (3 continuous: q0 takes nq = 9 "
                           "numbers, nv = 6); its fingers are fixed links"),
    RobotEntry("xarm7", "link_eef", "flange", description="UFactory xArm7, 7 joints"),
    RobotEntry("z1", "gripperStator", "hand", ("jointGripper",),
               "Unitree Z1, 6 joints; the gripper's moving jaw is locked"),
)}
"""Arms loadable by name, by name."""


def robot_entry(name: str) -> RobotEntry:
    """The registry entry of ``name``.

    Raises:
        RobotNotFoundError: unknown name (lists the known ones, with a did-you-mean).
    """
    try:
        return ROBOTS[name]
    except (KeyError, TypeError):
        raise RobotNotFoundError(name, ROBOTS) from None


__all__ = ["ROBOTS", "RobotEntry", "robot_entry"]
