"""Write ``mp6.urdf``: a 6-joint revolute arm with a rigid three-finger gripper.

Every link is a union of URDF primitives (cylinders, boxes, spheres) of uniform density
``DENSITY`` (aluminium-like). The script computes each link's mass, centre of mass and
inertia about the centre of mass from that geometry, so the URDF's ``<inertial>`` blocks
agree with its ``<collision>`` blocks by construction. Primitives that overlap are each
counted in full: the extra mass stands in for motors, gears and bolts.

Run ``python robots/mp6/generate_mp6.py`` to rewrite the URDF (the test suite checks that
the committed file equals the generator's output).

Conventions: SI units; each URDF cylinder's axis is its local z axis; ``rpy`` is URDF
roll-pitch-yaw, ``R = Rz(yaw) Ry(pitch) Rx(roll)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

DENSITY = 2700.0
"""Material density [kg/m^3] (aluminium)."""

HALF_PI = math.pi / 2
ALONG_X = (0.0, HALF_PI, 0.0)  # rpy that turns a cylinder's z axis onto x
ALONG_Y = (HALF_PI, 0.0, 0.0)  # rpy that turns a cylinder's z axis onto y (to -y, same line)

FINGERTIP_RADIUS = 0.015
"""Radius [m] of the spherical fingertips (thesis Sec 3.9.2 recommends spheres)."""

MATERIALS = {
    "mp6_grey": (0.30, 0.31, 0.34, 1.0),
    "mp6_orange": (0.93, 0.45, 0.08, 1.0),
    "mp6_black": (0.08, 0.08, 0.09, 1.0),
    "mp6_red": (0.85, 0.10, 0.10, 1.0),
}


@dataclass(frozen=True)
class Primitive:
    """One solid primitive of a link, in the link frame.

    Attributes:
        kind: ``"cylinder"`` (dims = radius, length), ``"box"`` (dims = sx, sy, sz) or
            ``"sphere"`` (dims = radius) [m].
        xyz: (3,) centre of the primitive in the link frame [m].
        rpy: (3,) orientation of the primitive in the link frame [rad].
        material: name of a colour in ``MATERIALS``.
    """

    kind: str
    dims: tuple[float, ...]
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    material: str = "mp6_grey"


@dataclass(frozen=True)
class Link:
    """A link: its name and the primitives it is made of (empty for pure frames)."""

    name: str
    primitives: tuple[Primitive, ...] = field(default=())


@dataclass(frozen=True)
class Joint:
    """A URDF joint; ``limits`` = (lower [rad], upper [rad], effort [N m], velocity [rad/s])."""

    name: str
    kind: str  # "revolute" or "fixed"
    parent: str
    child: str
    xyz: tuple[float, float, float]
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    limits: tuple[float, float, float, float] | None = None


# ---------------------------------------------------------------- geometry of the arm
L_BASE = 0.10  # base column height
L_SHOULDER = 0.16  # from joint 1 to the shoulder-lift axis
L_UPPER = 0.42  # upper arm: shoulder-lift axis to elbow axis
L_FORE_1 = 0.18  # elbow axis to forearm-roll joint
L_FORE_2 = 0.18  # forearm-roll joint to wrist-pitch axis
L_WRIST = 0.07  # wrist-pitch axis to wrist-roll joint
L_FLANGE = 0.015  # flange plate
L_PALM = 0.025  # gripper palm thickness
L_FINGER = 0.06  # finger length (palm face to fingertip centre)
FINGER_RADIAL = 0.05  # distance of each finger from the tool axis
FINGER_ANGLES_DEG = (90.0, 210.0, 330.0)  # finger k in the palm's y-z plane

TIP_X = L_PALM + L_FINGER  # fingertip centres along the gripper link's x axis


def _finger_yz(angle_deg: float) -> tuple[float, float]:
    a = math.radians(angle_deg)
    return (round(FINGER_RADIAL * math.cos(a), 6), round(FINGER_RADIAL * math.sin(a), 6))


def _cyl_x(r: float, length: float, x0: float, material: str, y=0.0, z=0.0) -> Primitive:
    """A cylinder along x from ``x0`` to ``x0 + length``."""
    return Primitive("cylinder", (r, length), (x0 + length / 2, y, z), ALONG_X, material)


LINKS = (
    Link("base_link", (Primitive("cylinder", (0.08, L_BASE), (0, 0, L_BASE / 2)),)),
    Link(
        "shoulder_link",
        (
            Primitive("cylinder", (0.06, 0.14), (0, 0, 0.07), material="mp6_orange"),
            Primitive("cylinder", (0.065, 0.14), (0, 0, L_SHOULDER), ALONG_Y, "mp6_grey"),
        ),
    ),
    Link(
        "upper_arm_link",
        (
            _cyl_x(0.045, L_UPPER, 0.0, "mp6_orange"),
            Primitive("cylinder", (0.055, 0.11), (L_UPPER, 0, 0), ALONG_Y, "mp6_grey"),
        ),
    ),
    Link("forearm_link", (_cyl_x(0.04, L_FORE_1, 0.0, "mp6_orange"),)),
    Link(
        "wrist_1_link",
        (
            _cyl_x(0.035, L_FORE_2, 0.0, "mp6_orange"),
            Primitive("cylinder", (0.04, 0.085), (L_FORE_2, 0, 0), ALONG_Y, "mp6_grey"),
        ),
    ),
    Link("wrist_2_link", (_cyl_x(0.032, L_WRIST, 0.0, "mp6_grey"),)),
    Link("flange_link", (_cyl_x(0.035, L_FLANGE, 0.0, "mp6_black"),)),
    Link(
        "gripper_link",
        (
            Primitive("box", (L_PALM, 0.13, 0.13), (L_PALM / 2, 0, 0), material="mp6_black"),
            *(
                _cyl_x(0.01, L_FINGER, L_PALM, "mp6_black", *_finger_yz(a))
                for a in FINGER_ANGLES_DEG
            ),
        ),
    ),
    *(
        Link(f"fingertip_{k + 1}", (Primitive("sphere", (FINGERTIP_RADIUS,), (0, 0, 0),
                                              material="mp6_red"),))
        for k in range(len(FINGER_ANGLES_DEG))
    ),
    Link("tool0"),
)

Y_AXIS = (0.0, 1.0, 0.0)
X_AXIS = (1.0, 0.0, 0.0)
Z_AXIS = (0.0, 0.0, 1.0)

JOINTS = (
    Joint("shoulder_pan_joint", "revolute", "base_link", "shoulder_link", (0, 0, L_BASE),
          axis=Z_AXIS, limits=(-3.05, 3.05, 200.0, 2.0)),
    Joint("shoulder_lift_joint", "revolute", "shoulder_link", "upper_arm_link",
          (0, 0, L_SHOULDER), axis=Y_AXIS, limits=(-2.0, 2.0, 200.0, 2.0)),
    Joint("elbow_joint", "revolute", "upper_arm_link", "forearm_link", (L_UPPER, 0, 0),
          axis=Y_AXIS, limits=(-2.6, 2.6, 100.0, 2.5)),
    Joint("forearm_roll_joint", "revolute", "forearm_link", "wrist_1_link", (L_FORE_1, 0, 0),
          axis=X_AXIS, limits=(-3.05, 3.05, 28.0, 3.0)),
    Joint("wrist_pitch_joint", "revolute", "wrist_1_link", "wrist_2_link", (L_FORE_2, 0, 0),
          axis=Y_AXIS, limits=(-2.1, 2.1, 28.0, 3.0)),
    Joint("wrist_roll_joint", "revolute", "wrist_2_link", "flange_link", (L_WRIST, 0, 0),
          axis=X_AXIS, limits=(-3.14, 3.14, 28.0, 3.5)),
    Joint("gripper_joint", "fixed", "flange_link", "gripper_link", (L_FLANGE, 0, 0)),
    *(
        Joint(f"fingertip_{k + 1}_joint", "fixed", "gripper_link", f"fingertip_{k + 1}",
              (TIP_X, *_finger_yz(a)))
        for k, a in enumerate(FINGER_ANGLES_DEG)
    ),
    # tool0: centroid of the fingertip centres; z axis = approach direction (gripper x).
    Joint("tool0_joint", "fixed", "gripper_link", "tool0", (TIP_X, 0, 0), rpy=ALONG_X),
)


# ---------------------------------------------------------------- mass properties
def rpy_matrix(rpy) -> np.ndarray:
    """URDF rpy [rad] -> rotation matrix (3, 3), ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                              math.cos(y), math.sin(y))
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def primitive_mass_properties(p: Primitive, density: float = DENSITY):
    """Mass [kg] and inertia (3, 3) [kg m^2] about the primitive's centre, in its own axes."""
    if p.kind == "cylinder":
        r, h = p.dims
        m = density * math.pi * r * r * h
        ixx = m * (3 * r * r + h * h) / 12
        return m, np.diag([ixx, ixx, m * r * r / 2])
    if p.kind == "box":
        a, b, c = p.dims
        m = density * a * b * c
        return m, np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) * m / 12
    if p.kind == "sphere":
        (r,) = p.dims
        m = density * 4 / 3 * math.pi * r**3
        return m, np.eye(3) * 0.4 * m * r * r
    raise ValueError(f"unknown primitive kind {p.kind!r}")


def link_mass_properties(link: Link, density: float = DENSITY):
    """Mass [kg], COM (3,) [m] in the link frame, inertia (3, 3) about the COM in link axes."""
    parts = []
    for p in link.primitives:
        m, inertia = primitive_mass_properties(p, density)
        R = rpy_matrix(p.rpy)
        parts.append((m, np.array(p.xyz, dtype=float), R @ inertia @ R.T))
    mass = sum(m for m, _, _ in parts)
    com = sum(m * c for m, c, _ in parts) / mass
    inertia = np.zeros((3, 3))
    for m, c, i_c in parts:
        d = c - com
        inertia += i_c + m * (d @ d * np.eye(3) - np.outer(d, d))  # parallel-axis theorem
    return mass, com, 0.5 * (inertia + inertia.T)


# ---------------------------------------------------------------- URDF text
def _f(x: float) -> str:
    if abs(x) < 1e-12:  # round-off of rotated inertias
        return "0"
    s = f"{x:.12g}"
    return "0" if s in ("-0", "0") else s


def _v(xs) -> str:
    return " ".join(_f(float(x)) for x in xs)


def _geometry(p: Primitive) -> str:
    if p.kind == "cylinder":
        return f'<cylinder radius="{_f(p.dims[0])}" length="{_f(p.dims[1])}"/>'
    if p.kind == "box":
        return f'<box size="{_v(p.dims)}"/>'
    return f'<sphere radius="{_f(p.dims[0])}"/>'


def _link_xml(link: Link) -> list[str]:
    if not link.primitives:
        return [f'  <link name="{link.name}"/>']
    out = [f'  <link name="{link.name}">']
    for tag in ("visual", "collision"):
        for p in link.primitives:
            out.append(f"    <{tag}>")
            out.append(f'      <origin xyz="{_v(p.xyz)}" rpy="{_v(p.rpy)}"/>')
            out.append(f"      <geometry>{_geometry(p)}</geometry>")
            if tag == "visual":
                out.append(f'      <material name="{p.material}"/>')
            out.append(f"    </{tag}>")
    mass, com, inertia = link_mass_properties(link)
    out.append("    <inertial>")
    out.append(f'      <origin xyz="{_v(com)}" rpy="0 0 0"/>')
    out.append(f'      <mass value="{_f(mass)}"/>')
    i = inertia
    out.append(
        f'      <inertia ixx="{_f(i[0, 0])}" ixy="{_f(i[0, 1])}" ixz="{_f(i[0, 2])}" '
        f'iyy="{_f(i[1, 1])}" iyz="{_f(i[1, 2])}" izz="{_f(i[2, 2])}"/>'
    )
    out.append("    </inertial>")
    out.append("  </link>")
    return out


def _joint_xml(j: Joint) -> list[str]:
    out = [f'  <joint name="{j.name}" type="{j.kind}">']
    out.append(f'    <parent link="{j.parent}"/>')
    out.append(f'    <child link="{j.child}"/>')
    out.append(f'    <origin xyz="{_v(j.xyz)}" rpy="{_v(j.rpy)}"/>')
    if j.kind == "revolute":
        lo, hi, effort, vel = j.limits
        out.append(f'    <axis xyz="{_v(j.axis)}"/>')
        out.append(
            f'    <limit lower="{_f(lo)}" upper="{_f(hi)}" effort="{_f(effort)}" '
            f'velocity="{_f(vel)}"/>'
        )
        out.append('    <dynamics damping="0" friction="0"/>')
    out.append("  </joint>")
    return out


def urdf_text() -> str:
    """The whole URDF document as a string."""
    lines = [
        '<?xml version="1.0"?>',
        "<!-- Generated by robots/mp6/generate_mp6.py: edit the generator, not this file. -->",
        "<!-- mp6: 6-joint revolute arm, reach 0.95 m, rigid 3-finger gripper with spherical",
        f"     fingertips (radius {FINGERTIP_RADIUS} m); aluminium density {DENSITY} kg/m^3. -->",
        '<robot name="mp6">',
    ]
    for name, rgba in MATERIALS.items():
        lines.append(f'  <material name="{name}"><color rgba="{_v(rgba)}"/></material>')
    for link in LINKS:
        lines += _link_xml(link)
    for joint in JOINTS:
        lines += _joint_xml(joint)
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


URDF_PATH = Path(__file__).with_name("mp6.urdf")


def main() -> None:
    """Write ``mp6.urdf`` next to this script and print the link masses."""
    URDF_PATH.write_text(urdf_text())
    total = 0.0
    for link in LINKS:
        if link.primitives:
            m, c, _ = link_mass_properties(link)
            total += m
            print(f"{link.name:16s} {m:7.3f} kg  com {np.round(c, 4)}")
    print(f"total {total:.3f} kg -> {URDF_PATH}")


if __name__ == "__main__":
    main()
