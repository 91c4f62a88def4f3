"""Scenario texts that no real system could carry out (a helper module, not a test file).

Each is self-contained (no shipped file is read, so a change to the shipped scenarios does
not change these cases) and far from the threshold of the check it triggers.
"""

from __future__ import annotations

TWO_UR5_WELDS = """name: {name}
object:
  shape: {{type: box, size: [0.8, 0.4, 0.3]}}
  mass: {mass}
  pose: {{position: [0.5, 0.0, 0.35], quaternion: {quaternion}}}
arms:
  - name: left
    robot: ur5
    tool_frame: tool0
    base: {{position: [0.0, 0.55, 0.0], rpy: [0, 0, 0]}}
    q_seed: [-3.4, -2.1, -1.6, 0.5, 0.3, -3.1]  # the demo's elbow-up left arm (no collision)
    joint:
      type: weld
      placement_in_object: {{position: [0.0, 0.2, 0.0], rpy: [1.5707963267948966, 0, 0]}}
  - name: right
    robot: ur5
    tool_frame: tool0
    base: {{position: [0.0, -0.55, 0.0], rpy: [0, 0, 0]}}
    q_seed: [0.0, -1.2, 1.6, -0.4, 1.57, 0.0]
    joint:
      type: weld
      placement_in_object: {{position: [0.0, -0.2, 0.0], rpy: [-1.5707963267948966, 0, 0]}}
controller:
  type: object_pd
  kp: 100.0
  kd: 20.0
  waypoints:
{waypoints}
simulation: {{duration: {duration}, integrator: rk4, dt: {dt}, solver: object_first,
             baumgarte: {{alpha: 5.0, beta: 5.0}}}}
"""

DEMO_WAYPOINTS = """    - {t: 0.8, position: [0.5, 0.0, 0.50]}
    - {t: 1.6, position: [0.45, 0.1, 0.50], rpy: [0.0, 0.0, 0.3]}
    - {t: 2.5, position: [0.5, 0.0, 0.35]}"""


def two_ur5_welds(name: str = "two_ur5", mass: float = 4.0, quaternion: str = "[0, 0, 0, 1]",
                  waypoints: str = DEMO_WAYPOINTS, duration: float = 2.5,
                  dt: float = 0.002) -> str:
    """Two UR5s welded to the side faces of a 0.8 x 0.4 x 0.3 m box, placed by IK."""
    return TWO_UR5_WELDS.format(name=name, mass=mass, quaternion=quaternion,
                                waypoints=waypoints, duration=duration, dt=dt)


_TWO_GRIPPERS = """name: {name}
object:
  shape: {{type: box, size: [0.8, 0.6, 0.4]}}
  mass: 4.0
  pose: {{position: [0.0, 0.0, 0.9]}}
arms:
  - name: four_finger
    urdf: mp6/mp6_4f.urdf
    tool_frame: tool0
    base: {{position: [1.0, 0.45, 0.5], rpy: [0, 0, 2.5]}}
    q_seed: [0.8, -1.15, 1.05, 0.6, 0.9, -0.8]
    joint:
      type: fingertips
      tip_radius: 0.015
      contacts:
        - {{tip: fingertip_1, face: +x, point: [0.4, 0.25, 0.15]}}
        - {{tip: fingertip_2, face: +y, point: [0.35, 0.3, 0.15]}}
        - {{tip: fingertip_3, face: +z, point: [0.38, 0.25, 0.2]}}
{fourth}  - name: three_finger
    urdf: mp6/mp6.urdf
    tool_frame: tool0
    base: {{position: [-0.8, -0.7, 0.0], rpy: [0, 0, 0.8]}}
    q_seed: [0.0, 0.0, -1.4, 0.0, 0.7, -0.75]
    joint:
      type: fingertips
      tip_radius: 0.015
      contacts:
        - {{tip: fingertip_1, face: -x, point: [-0.4, -0.25, -0.15]}}
        - {{tip: fingertip_2, face: -y, point: [-0.35, -0.3, -0.15]}}
        - {{tip: fingertip_3, face: -z, point: [-0.38, -0.25, -0.2]}}
{tail}"""
"""The two corner grippers of two_gripper_form_closure.yaml (``{fourth}``: the four-finger
gripper's fourth contact, or nothing; ``{tail}``: controller and simulation)."""

SIX_FINGERTIPS = _TWO_GRIPPERS.format(name="six_fingertips", fourth="", tail="""\
controller: {type: object_pd, margin: 5.0}
simulation: {duration: 0.01, integrator: rk4, dt: 0.002, solver: object_first}
""")
"""The two corner grippers of two_gripper_form_closure.yaml with six fingertips (the
four-finger gripper's fourth left out): six frictionless contacts are never form closure."""


GRIPPERS_STRETCHED = _TWO_GRIPPERS.format(
    name="grippers_stretched",
    fourth="        - {tip: fingertip_4, face: +z, point: [0.23, 0.25, 0.2]}\n", tail="""\
controller:
  type: object_pd
  margin: 5.0
  waypoints:
    - {t: 1.5, position: [-1.2, -1.0, 0.9]}
simulation: {duration: 0.5, integrator: rk4, dt: 0.002, solver: object_first,
             baumgarte: {alpha: 5.0, beta: 5.0}}
""")
"""The 7-contact two-gripper grasp of two_gripper_form_closure.yaml asked to carry the box
1.6 m away, out of four_finger's reach: its elbow stretches through 0 (its singularity) near
t = 0.33 s, its shoulder torque goes far over the 200 N m limit, and the run ends in an
event storm ("more than 50 contact events in one step")."""
