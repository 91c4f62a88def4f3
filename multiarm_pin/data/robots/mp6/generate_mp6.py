"""Write ``mp6.urdf`` and ``mp6_4f.urdf``: a 6-joint revolute arm with a rigid gripper.

A stand-alone data generator shipped beside the URDFs it writes (one file, so that the URDFs
can be regenerated and audited from the package data alone; hence a long one).

Two variants share the arm and differ only in the gripper:

* ``mp6``: three parallel fingers at 120° around the tool axis;
* ``mp6_4f``: four parallel fingers whose spherical tips are laid out for a box corner
  (thesis Sec 2.2.3.1): at the *design pose* tips 1, 2, 3 touch the three faces +x, +y, +z
  around a box corner and tip 4 touches the +z face a distance ``D`` further along -x, so
  that this gripper and a three-contact gripper at the opposite corner hold a box in
  7-contact form closure (see :class:`CornerLayout`).

Every link is a union of URDF primitives (cylinders, boxes, spheres) of uniform density
``DENSITY`` (aluminium-like). The script computes each link's mass, centre of mass and
inertia about the centre of mass from that geometry, so the URDF's ``<inertial>`` blocks
agree with its ``<collision>`` blocks by construction. Primitives that overlap are each
counted in full: the extra mass stands in for motors, gears and bolts.

Run ``python robots/mp6/generate_mp6.py`` to rewrite both URDFs (the test suite checks that
the committed files equal the generator's output).

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


ARM_LINKS = (
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
)
"""Links of the arm, base to flange (shared by both variants)."""

THREE_FINGER_LINKS = (
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

ARM_JOINTS = (
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
)
"""Joints of the arm, base to gripper link (shared by both variants)."""

THREE_FINGER_JOINTS = (
    *(
        Joint(f"fingertip_{k + 1}_joint", "fixed", "gripper_link", f"fingertip_{k + 1}",
              (TIP_X, *_finger_yz(a)))
        for k, a in enumerate(FINGER_ANGLES_DEG)
    ),
    # tool0: centroid of the fingertip centres; z axis = approach direction (gripper x).
    Joint("tool0_joint", "fixed", "gripper_link", "tool0", (TIP_X, 0, 0), rpy=ALONG_X),
)


LINKS = ARM_LINKS + THREE_FINGER_LINKS
"""All links of ``mp6``."""
JOINTS = ARM_JOINTS + THREE_FINGER_JOINTS
"""All joints of ``mp6``."""


# ---------------------------------------------------------------- four-finger gripper
@dataclass(frozen=True)
class CornerLayout:
    """Fingertip layout of ``mp6_4f`` at a box corner (thesis Sec 2.2.3.1, Example 2.1).

    Corner frame: origin at the corner, axes along the box's, the box in the negative octant
    (its faces +x, +y, +z through the corner). At the design pose the spherical tips touch:

    =====  ======  ================================  ===============================
    tip    face    contact point (corner frame)      thesis (corner at ``(l_x, l_y, l_z)``)
    =====  ======  ================================  ===============================
    1      +x      ``(0, -A, -A)``                   ``p1 = (l_x, a, b)``
    2      +y      ``(-A, 0, -A)``                   ``p2 = (c, l_y, d)``
    3      +z      ``(-E, -A, 0)``                   ``p3 = (e, f, l_z)``
    4      +z      ``(-E - D, -A, 0)``               seventh contact ``(e - D, f, l_z)``
    =====  ======  ================================  ===============================

    With the mirrored three contacts ``-p1, -p2, -p3`` of a second gripper at the opposite
    corner, the seven contacts are form closure for every box large enough to hold them iff
    ``A > E`` and ``D > D_x = 2 (A - E)`` (thesis Eq for ``D_x``).

    Attributes:
        A: distance [m] of contacts 1, 2 from the corner's edges, and of 3, 4 from the
            +z/+y edge.
        E: distance [m] of contact 3 from the +z/+x edge.
        D: distance [m] along -x from contact 3 to contact 4.
        radius: fingertip radius [m]; sphere centres are ``radius`` off the faces.
    """

    A: float = 0.05
    E: float = 0.02
    D: float = 0.15
    radius: float = FINGERTIP_RADIUS

    @property
    def contact_points(self) -> np.ndarray:
        """(4, 3) contact points in the corner frame [m], tips 1..4."""
        A, E, D = self.A, self.E, self.D
        return np.array([[0.0, -A, -A], [-A, 0.0, -A], [-E, -A, 0.0], [-E - D, -A, 0.0]])

    @property
    def outward_normals(self) -> np.ndarray:
        """(4, 3) outward unit normals of the touched faces (+x, +y, +z, +z), corner frame."""
        return np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [0, 0, 1.0]])

    @property
    def tip_centres(self) -> np.ndarray:
        """(4, 3) fingertip sphere centres in the corner frame [m]."""
        return self.contact_points + self.radius * self.outward_normals

    @property
    def gripper_rotation(self) -> np.ndarray:
        """(3, 3) gripper-link axes in the corner frame at the design pose.

        x (approach) points into the corner along the diagonal, ``-(1, 1, 1)/√3``; z is the
        corner's +z projected perpendicular to x, ``(-1, -1, 2)/√6``; ``y = z × x``.
        """
        x = -np.ones(3) / math.sqrt(3.0)
        z = np.array([-1.0, -1.0, 2.0]) / math.sqrt(6.0)
        return np.column_stack([x, np.cross(z, x), z])

    def tips_in_gripper(self, palm: float = L_PALM, shortest_finger: float = L_FINGER
                        ) -> np.ndarray:
        """(4, 3) tip centres in the gripper-link frame [m].

        The gripper's x axis (the wrist-roll axis) passes through the centroid of the tips;
        the palm face is the plane ``x = palm`` and the shortest finger is
        ``shortest_finger`` long (palm face to tip centre).
        """
        c = self.tip_centres
        local = (c - c.mean(axis=0)) @ self.gripper_rotation  # rows: R^T (c_k - c̄)
        local[:, 0] += palm + shortest_finger - local[:, 0].min()
        return local

    def gripper_in_corner(self, palm: float = L_PALM, shortest_finger: float = L_FINGER):
        """Design pose of the gripper link: ``(R (3, 3), p (3,))`` in the corner frame [m]."""
        R = self.gripper_rotation
        tips = self.tips_in_gripper(palm, shortest_finger)
        return R, self.tip_centres[0] - R @ tips[0]


CORNER_LAYOUT = CornerLayout()
"""The layout ``mp6_4f`` is built for: A = 0.05 m, E = 0.02 m, D = 0.15 m (D_x = 0.06 m)."""

FOUR_TIPS = CORNER_LAYOUT.tips_in_gripper()
"""(4, 3) fingertip centres of ``mp6_4f`` in its gripper-link frame [m]."""

PALM_CLEARANCE = 0.02
"""Palm margin [m] around the finger axes (the palm covers every finger's base)."""


def _four_finger_palm() -> Primitive:
    yz = FOUR_TIPS[:, 1:]
    lo = np.floor((yz.min(axis=0) - PALM_CLEARANCE) * 1000) / 1000  # whole mm
    hi = np.ceil((yz.max(axis=0) + PALM_CLEARANCE) * 1000) / 1000
    size, centre = hi - lo, (hi + lo) / 2
    return Primitive("box", (L_PALM, float(size[0]), float(size[1])),
                     (L_PALM / 2, float(centre[0]), float(centre[1])), material="mp6_black")


FOUR_FINGER_LINKS = (
    Link(
        "gripper_link",
        (
            _four_finger_palm(),
            *(
                _cyl_x(0.01, float(x - L_PALM), L_PALM, "mp6_black", float(y), float(z))
                for x, y, z in FOUR_TIPS
            ),
        ),
    ),
    *(
        Link(f"fingertip_{k + 1}", (Primitive("sphere", (FINGERTIP_RADIUS,), (0, 0, 0),
                                              material="mp6_red"),))
        for k in range(len(FOUR_TIPS))
    ),
    Link("tool0"),
)

FOUR_FINGER_JOINTS = (
    *(
        Joint(f"fingertip_{k + 1}_joint", "fixed", "gripper_link", f"fingertip_{k + 1}",
              tuple(float(v) for v in tip))
        for k, tip in enumerate(FOUR_TIPS)
    ),
    # tool0: centroid of the fingertip centres (on the gripper axis); z axis = approach.
    Joint("tool0_joint", "fixed", "gripper_link", "tool0",
          (float(FOUR_TIPS[:, 0].mean()), 0, 0), rpy=ALONG_X),
)


@dataclass(frozen=True)
class RobotVariant:
    """One URDF the generator writes.

    Attributes:
        name: robot name (also the file stem). summary: one-line description (comment).
        links, joints: the kinematic tree.
    """

    name: str
    summary: str
    links: tuple[Link, ...]
    joints: tuple[Joint, ...]

    @property
    def path(self) -> Path:
        """Where the URDF is written (next to this script)."""
        return Path(__file__).with_name(f"{self.name}.urdf")


VARIANTS = {
    "mp6": RobotVariant("mp6", "rigid 3-finger gripper", LINKS, JOINTS),
    "mp6_4f": RobotVariant(
        "mp6_4f",
        f"rigid 4-finger box-corner gripper (A={CORNER_LAYOUT.A}, E={CORNER_LAYOUT.E}, "
        f"D={CORNER_LAYOUT.D} m)",
        ARM_LINKS + FOUR_FINGER_LINKS,
        ARM_JOINTS + FOUR_FINGER_JOINTS,
    ),
}
"""Every robot the generator writes, by name."""


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


def urdf_text(robot: str = "mp6") -> str:
    """The whole URDF document of ``robot`` (a key of ``VARIANTS``) as a string."""
    if robot not in VARIANTS:
        raise ValueError(f"unknown robot {robot!r}; expected one of {', '.join(VARIANTS)}")
    v = VARIANTS[robot]
    if robot == "mp6":
        summary = ["<!-- mp6: 6-joint revolute arm, reach 0.95 m, rigid 3-finger gripper with "
                   "spherical",
                   f"     fingertips (radius {FINGERTIP_RADIUS} m); aluminium density "
                   f"{DENSITY} kg/m^3. -->"]
    else:
        summary = [f"<!-- {v.name}: the mp6 arm with a {v.summary};",
                   f"     spherical fingertips (radius {FINGERTIP_RADIUS} m); aluminium density "
                   f"{DENSITY} kg/m^3. -->"]
    lines = [
        '<?xml version="1.0"?>',
        "<!-- Generated by robots/mp6/generate_mp6.py: edit the generator, not this file. -->",
        *summary,
        f'<robot name="{v.name}">',
    ]
    for name, rgba in MATERIALS.items():
        lines.append(f'  <material name="{name}"><color rgba="{_v(rgba)}"/></material>')
    for link in v.links:
        lines += _link_xml(link)
    for joint in v.joints:
        lines += _joint_xml(joint)
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


URDF_PATH = VARIANTS["mp6"].path


def main() -> None:
    """Write every variant's URDF next to this script and print the link masses."""
    for v in VARIANTS.values():
        v.path.write_text(urdf_text(v.name))
        total = 0.0
        for link in v.links:
            if link.primitives:
                m, c, _ = link_mass_properties(link)
                total += m
                print(f"{v.name:7s} {link.name:16s} {m:7.3f} kg  com {np.round(c, 4)}")
        print(f"{v.name:7s} total {total:.3f} kg -> {v.path}")


if __name__ == "__main__":
    main()
