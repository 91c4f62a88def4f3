"""Picking a box up from a table larger than itself by tilting it first (issue 27).

With frictionless contacts a box lying flat on a table that covers its bottom face cannot be
lifted: nothing can push up on that face. The plan (the hand-planned ``tilt_pick`` scenario,
generalised):

1. ``rest``/``tilt``: two three-tip grippers make a horizontal couple, ``pusher`` on the face
   away from the pivot edge (high, pushing toward the pivot) and ``stop`` on the face of the
   pivot edge (low, pushing back); ``phased_pd`` turns the box by ``θ`` about the pivot edge,
   whose two support vertices keep pressing (``press``);
2. ``top``: the four-tip gripper (``top``, starting apart by its ``approach``) comes down on
   the top face at the pivot side's upper corner; the three-tip ``insert`` gripper goes down
   beside the raised side, its bottom tip below the bottom face's plane;
3. ``insert``/``close``: it slides under the raised side and touches down on the bottom face;
4. ``grip``/``squeeze``: both grippers close their side tips (``loose`` until the opposite
   side touches): 13 contacts in form closure;
5. ``lift``/``carry``: the pivot edge leaves the table; the box is carried.

Everything is placed in the *pivot frame* of a candidate: x toward the pivot edge (one of
the bottom face's four edges, ``PIVOTS``), y along it, z up; ``a``, ``b``, ``c`` the box's
half sizes along them. The grips are the shipped grippers' (:data:`ROLE_GRIPS`: each tip's
contact point relative to a corner or a face of the box, and the gripper's base relative to
it), so the plan scales with the box. No arm passes through the table top (the collision
scene's slab is the support's whole ``extent``): the couple's and the insert's bases stand on
pedestals at or above the table's height (the pusher's shoulder at its hand's height, the
stop's base just above the table top, the insert's at it), 15 cm outside the table's
rectangle (each base's
offset along the axes it reaches over is moved out by the table's actual margin beyond the
box, ``RoleGrip.reach_over``), their arms reaching over the table and in; the stop's hand is
:data:`STOP_HEIGHT` up its face so that it clears the table as the face leans; the insert's
hand is level along the corner's diagonal (:func:`_corner_tri`), so that its back rises
with the raised side. The tilt angle is the smallest (on a 0.01 rad grid)
that lifts the insert gripper's bottom tip :data:`INSERT_CLEARANCE` above the table when it
slides under (:func:`tilt_angle_range`), and at most :data:`TILT_STABILITY` of the angle at
which the box's centre of mass would pass over the pivot edge; larger angles on the same grid
are tried too (:data:`EXTRA_ANGLES`).

Each candidate (pivot, angle, base offsets) is checked (:func:`check_plan`) at the key poses
of its phases: inverse kinematics of every arm's tips within joint limits with residual below
:data:`IK_RESIDUAL`, warm-started from the previous key pose with no joint moving more than
:data:`~.assessment.MAX_JOINT_STEP` (one continuous branch), coal clearances at least
``search.clearance`` (:class:`~multiarm_pin.feasibility.CollisionScene`), the final grasp
form closure (LP), and the static torques at most :data:`STATIC_TORQUE_RATIO` of the effort
limits (at rest on the table with the couple pressing, tilted with the couple alone holding
the box against the pivot edge's vertices, and carried). The search tries
every pivot edge and angle at the nominal bases, then ``search.candidates`` random base
offsets (up to :data:`BASE_STEP` m and :data:`YAW_STEP` rad per arm, clipped into the spec's
region) around the best; the best plan by (worst torque ratio, then largest clearance) is
written as a runnable scenario. Candidates are checked in this process, one after another
(not on the design search's Dask cluster).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from multiarm_pin.exceptions import DesignImpossibleError, MultiArmError

ROLES = ("pusher", "stop", "top", "insert")
"""The arms' roles: the couple (``pusher``, ``stop``), the top grasp, the bottom insert."""

ROLE_TIPS = {"pusher": 3, "stop": 3, "top": 4, "insert": 3}
"""Fingertips of each role's gripper (mp6_3f: 3, mp6_4f: 4)."""

PIVOTS = {"+x": 0.0, "+y": np.pi / 2, "-x": np.pi, "-y": -np.pi / 2}
"""Pivot edges of the bottom face (by the outward normal of the side face they bound) and the
yaw [rad] of the pivot frame in the object frame."""

INSERT_CLEARANCE = 0.045
"""Height [m] of the insert gripper's bottom tip's lowest point above the table as it slides
under the raised side."""

INSERT_DEPTH = 0.015
"""How far [m] the bottom tip's centre goes below the bottom face's plane while it slides."""

TILT_STABILITY = 0.6
"""Largest tilt as a fraction of the angle where the centre of mass passes over the pivot."""

EXTRA_ANGLES = 2
"""Angles tried above the smallest one (0.02 rad apart)."""

STATIC_TORQUE_RATIO = 0.75
"""Largest static torque over effort limit accepted at a key pose: the rest is left to the
motion (the lift's acceleration, the contacts' margins of the force distribution; a plan at
0.9 statically exceeded a wrist's limit at the lift in simulation)."""

IK_RESIDUAL = 1e-6
"""Largest IK residual [m] accepted at a key pose."""

TOUCHING_GAP = 1e-6
"""Largest gap [m] of a support vertex that carries force in the tilted pose's statics (the
pivot edge's vertices are on the table, the far edge's are lifted by ``2a sinθ``)."""

BASE_STEP = 0.1
"""Largest base offset [m] of a random candidate from the nominal base."""

YAW_STEP = 0.15
"""Largest base yaw offset [rad] of a random candidate."""


def _tri(face_x: float, y0: float, z0: float, up: float) -> list:
    """Three tips of a mp6_3f flat on an x face (pivot frame [m]).

    An equilateral triangle of circumradius 0.05 m about ``(y0, z0)``: tip 1 above the centre
    (``up`` 1) or below it (-1, the hand turned half a turn about the face normal), tips 2
    and 3 on the other side.
    """
    h = 0.05 * np.sqrt(3) / 2
    return [(face_x, y0, z0 + up * 0.05), (face_x, y0 - up * h, z0 - up * 0.025),
            (face_x, y0 + up * h, z0 - up * 0.025)]


@dataclass(frozen=True)
class RoleGrip:
    """One role's grip in the pivot frame.

    Attributes:
        faces: per tip, the pivot-frame outward normal of its face (a signed unit axis).
        points: ``points(a, b, c)`` -> per tip, its contact point [m] (pivot frame).
        anchor: ``anchor(a, b, c)`` -> (3,) the point the base is placed from [m].
        base: (3,) nominal base offset from the anchor [m] (pivot frame, z world up).
        yaw: nominal base yaw in the pivot frame [rad].
        q_seed: the IK seed of its arm.
        approach: (3,) pivot-frame approach offset (None: starts touching).
        reach_over: per pivot-frame horizontal axis the arm reaches over the table's edge
            along (``(axis, sign, distance)``: the grip's table margin [m] from the anchor to
            the edge along ``sign`` × axis that ``base`` was placed for); the base moves out
            by the table's actual margin less that one.
        tips: per contact, the index of the gripper's tip that makes it (None: in order).
    """

    faces: tuple
    points: object
    anchor: object
    base: tuple
    yaw: float
    q_seed: tuple
    approach: tuple | None = None
    reach_over: tuple = ()
    tips: tuple | None = None


STOP_HEIGHT = 0.12
"""Height [m] of the stop's tip triangle's centre above the bottom face: its hand (a 0.13 m
square, 0.1 m out from the face at its back) stays 2 cm above the table while the box turns
up to 0.3 rad, ``h cos θ - 0.065 cos θ - 0.1 sin θ >= 0.02``."""

_S = 0.05 * np.sqrt(3.0)
"""Side [m] of a mp6_3f's tip triangle (circumradius 0.05 m)."""


def _corner_tri(a: float, b: float, c: float, r: float = 0.015) -> list:
    """Three tips of a mp6_3f at the ``(-a, -b, -c)`` corner, its axis level (pivot frame).

    Tips on the -x, -y and -z faces (in that order), their centres ``r`` off the faces, the
    triangle in the vertical plane ``x + y = const``: the two side tips' centres at one height,
    ``_S`` apart along that plane, the bottom tip's centre ``_S √3 / 2`` below their midpoint
    and ``r`` under the bottom face. Its hand's axis is horizontal along ``(1, 1, 0) / √2``, so
    that when the raised side turns up the hand's back rises too (away from the table).
    """
    u, z = _S / np.sqrt(2.0), -c - r + _S * np.sqrt(3.0) / 2
    return [(-a, -b - r + u, z), (-a - r + u, -b, z),
            (-a - r + u / 2, -b - r + u / 2, -c)]


ROLE_GRIPS = {
    "pusher": RoleGrip(("-x", "-x", "-x"), lambda a, b, c: _tri(-a, 0.05, c - 0.08, 1.0),
                       lambda a, b, c: (-a, 0.05, c - 0.08), (-0.55, 0.0, -0.26), 0.0,
                       (0.0, -0.9, 1.2, 0.0, -0.3, 0.0), None, ((0, -1.0, 0.4),)),
    "stop": RoleGrip(("+x", "+x", "+x"),
                     lambda a, b, c: _tri(a, 0.05, -c + STOP_HEIGHT, -1.0),
                     lambda a, b, c: (a, 0.05, -c + STOP_HEIGHT), (0.55, -0.35, -0.11), np.pi,
                     (0.0, -0.6, 1.4, 0.0, -0.8, 0.0), None, ((0, 1.0, 0.4),)),
    "top": RoleGrip(("+x", "+y", "+z", "+z"),
                    lambda a, b, c: [(a, b - 0.05, c - 0.05), (a - 0.05, b, c - 0.05),
                                     (a - 0.02, b - 0.05, c), (a - 0.17, b - 0.05, c)],
                    lambda a, b, c: (a, b, c), (0.6, 0.15, -0.6), 2.5,
                    (0.8, -1.15, 1.05, 0.6, 0.9, -0.8), (0.04, 0.04, 0.04),
                    ((0, 1.0, 0.4), (1, 1.0, 0.3))),
    "insert": RoleGrip(("-x", "-y", "-z"), _corner_tri,
                       lambda a, b, c: (-a, -b, -c), (-0.4, -0.45, 0.0), 0.8,
                       (0.16, -0.59, 2.09, 0.17, -1.5, 1.04), (-0.08, -0.04, 0.10),
                       ((0, -1.0, 0.4), (1, -1.0, 0.3)), (2, 0, 1)),
}
"""The grips of the shipped grippers (mp6_3f flat on a face, mp6_4f around a corner as in
``pick_from_table``, mp6_3f level at the raised bottom corner), relative to the box's faces
and corners, their bases as in the hand-planned ``tilt_pick`` (a 0.8 x 0.6 x 0.4 m box on a
table 0.4 and 0.3 m wider on each side): the pusher's and the stop's on pedestals just above
the table top (the pusher's shoulder at its hand's height), the insert's at the table's
height, each 15 cm outside the table's rectangle; the top's below the table, 20 cm outside
it (its arm rises outside the table's edge)."""
_AXES = {"+x": (0, 1.0), "-x": (0, -1.0), "+y": (1, 1.0), "-y": (1, -1.0), "+z": (2, 1.0),
         "-z": (2, -1.0)}


def _axis(name: str) -> np.ndarray:
    k, s = _AXES[name]
    v = np.zeros(3)
    v[k] = s
    return v


def _face_name(v: np.ndarray) -> str:
    k = int(np.argmax(np.abs(v)))
    return ("+" if v[k] > 0 else "-") + "xyz"[k]


def _rz(yaw: float) -> np.ndarray:
    return pin.rpy.rpyToMatrix(0.0, 0.0, float(yaw))


def _r(x) -> list:
    return [round(float(v), 10) for v in np.ravel(x)]


# ----------------------------------------------------------------------------- spec
def check_pick_up_spec(root, obj, supports, arms) -> None:
    """The parts of a ``pick_up`` spec the tilt plan needs (raises DesignError otherwise).

    A box lying flat (its z axis vertical) on one horizontal support plane; arms with the
    shipped fingertip grippers (two more mp6_3f than needed: the couple).
    """
    if obj.shape_type != "box":
        raise root.get("object").error(f"a pick-up plans for a box; got a {obj.shape_type}")
    R = pin.Quaternion(np.asarray(obj.quaternion, float)).toRotationMatrix()
    if abs(R[2, 2] - 1.0) > 1e-9:
        raise root.get("object").error("a pick-up's box lies flat: its z axis must be "
                                       f"vertical (it is {R[:, 2].round(6).tolist()})")
    if "fixed" in (root.value.get("bases") or {}):
        raise root.error("a pick-up places the bases itself: give a region", "bases.fixed")
    if len(supports) != 1:
        raise root.error("a pick-up needs exactly one support (the table)", "supports")
    sp = supports[0]
    n = np.asarray(sp.normal, float)
    half = 0.5 * float(obj.size[2])
    if abs(n[2] - 1.0) > 1e-9 or abs(obj.position[2] - half - sp.point[2]) > 1e-6:
        raise root.error(f"the box must rest on the support's plane: a horizontal plane at "
                         f"height {obj.position[2] - half:.6g} m (got normal {n.tolist()}, "
                         f"point {np.asarray(sp.point).tolist()})", "supports[0].plane")
    kinds = sorted(len(s.tips) for s in arms if s.gripper == "fingertips")
    if kinds.count(3) < 3 or kinds.count(4) < 1:
        raise root.error("a pick-up by tilting needs three 3-tip grippers (mp6_3f: the couple "
                         "and the insert) and one 4-tip gripper (mp6_4f: the top)", "arms")


def assign_roles(spec) -> dict:
    """Role -> arm slot index.

    The first 4-tip gripper is ``top``; the 3-tip ones, in the spec's order, ``pusher``,
    ``stop``, ``insert`` (the same gripper: any order is the same plan with the names
    exchanged).
    """
    three = [s.index for s in spec.arms if len(s.tips) == 3]
    four = [s.index for s in spec.arms if len(s.tips) == 4]
    return {"pusher": three[0], "stop": three[1], "insert": three[2], "top": four[0]}


# ----------------------------------------------------------------------------- geometry
@dataclass(frozen=True)
class Candidate:
    """One plan to check: the pivot edge, the tilt angle, each role's base offset.

    Attributes:
        index: its number in the search.
        pivot: a key of :data:`PIVOTS`.
        angle: tilt [rad].
        offsets: role -> (dx, dy, dz, dyaw) base offset from its nominal base (pivot frame).
    """

    index: int
    pivot: str
    angle: float
    offsets: dict = field(default_factory=dict)


def half_sizes(size, pivot: str) -> tuple[float, float, float]:
    """``(a, b, c)``: half sizes along the pivot frame's x (toward the pivot), y, z [m]."""
    s = np.asarray(size, float) / 2
    return (s[0], s[1], s[2]) if pivot in ("+x", "-x") else (s[1], s[0], s[2])


def tilt_angle_range(a: float, c: float, radius: float) -> tuple[float, float]:
    """``(smallest, largest)`` tilt [rad] of a box for an insert gripper's tips.

    ``a``: the box's half size toward the pivot, ``c`` its half height, ``radius`` the
    insert gripper's tip radius [m].

    Smallest: the bottom tip (its contact point ``e`` in from the raised edge,
    :func:`_corner_tri`, its centre :data:`INSERT_DEPTH` below the bottom face's plane while
    it slides, 0.004 m further out) has its lowest point :data:`INSERT_CLEARANCE` above the
    table. A point at distance ``d`` from the pivot edge along the bottom face and ``h``
    below its plane is at height ``d sinθ - h cosθ`` after a turn ``θ``; with
    ``d = 2a - e + 0.004``, ``h = INSERT_DEPTH + 2 radius`` (the centre is a radius off the
    face, the lowest point a radius below it), ``d sinθ - h cosθ = H`` gives
    ``θ = asin(H / √(d² + h²)) + atan2(h, d)``.
    Largest: :data:`TILT_STABILITY` of ``atan(a / c)`` (the centre of mass over the pivot).
    """
    e = _corner_tri(a, 0.0, c, radius)[2][0] + a
    d = 2 * a - e + 0.004
    h = INSERT_DEPTH + 2 * radius
    lo = float(np.arcsin(min(INSERT_CLEARANCE / np.hypot(d, h), 1.0)) + np.arctan2(h, d))
    return lo, TILT_STABILITY * float(np.arctan2(a, c))


class PickUpPlanner:
    """Builds and checks tilt plans for a ``pick_up`` spec (module docstring).

    Args:
        spec: the :class:`~.spec.DesignSpec` (``spec.pick_up`` set).
    """

    def __init__(self, spec):
        self.spec = spec
        o = spec.object
        self.size = np.asarray(o.size, float)
        self.M0 = pin.SE3(pin.Quaternion(np.asarray(o.quaternion, float)).toRotationMatrix(),
                          np.asarray(o.position, float))
        self.roles = assign_roles(spec)
        self.radius = {r: spec.arms[i].tip_radius for r, i in self.roles.items()}

    # ------------------------------------------------------------------ scenario
    def angles(self, pivot: str) -> tuple[list[float], str | None]:
        """The tilt angles tried about ``pivot`` (0.01 rad grid), or ``[]`` and why not."""
        a, _, c = half_sizes(self.size, pivot)
        lo, hi = tilt_angle_range(a, c, self.radius["insert"])
        first = np.ceil(lo * 100 - 1e-9) / 100
        out = [round(first + 0.02 * k, 2) for k in range(EXTRA_ANGLES + 1)]
        out = [t for t in out if t <= hi]
        if not out:
            return [], (f"pivot {pivot}: the tilt that lets the insert gripper under the "
                        f"raised side ({lo:.3f} rad) exceeds {TILT_STABILITY:g} of the "
                        f"tipping angle ({hi / TILT_STABILITY:.3f} rad): the box is too tall "
                        f"for its length toward this edge")
        return out, None

    def table_margin(self, point: np.ndarray, direction: np.ndarray) -> float:
        """Horizontal distance [m] from ``point`` along ``direction`` to the table's edge.

        The table is the support's rectangle (``extent`` about its point, sides along its x
        axis); without an extent, the box's own footprint edge (distance 0 beyond it is
        taken as the bottom face's edge: no margin).
        """
        from multiarm_pin.constraints.supports import plane_x_axis

        sp = self.spec.supports[0]
        if sp.extent is None:
            return 0.0
        n = np.asarray(sp.normal, float)
        ex = plane_x_axis(n, sp.x_axis)
        ey = np.cross(n, ex)
        d = np.asarray(direction, float)
        rel = np.asarray(point, float) - np.asarray(sp.point, float)
        t = np.inf
        for e, half in ((ex, sp.extent[0] / 2), (ey, sp.extent[1] / 2)):
            u, x = float(e @ d), float(e @ rel)
            if abs(u) > 1e-12:
                t = min(t, ((half if u > 0 else -half) - x) / u)
        return float(t)

    def frame(self, pivot: str) -> np.ndarray:
        """(3, 3) the pivot frame's axes in the object frame."""
        return _rz(PIVOTS[pivot])

    def scenario(self, cand: Candidate) -> dict:
        """The runnable scenario of a candidate (``phased_pd``, ``tilt_pick``'s form)."""
        spec = self.spec
        P = self.frame(cand.pivot)
        a, b, c = half_sizes(self.size, cand.pivot)
        Rw = self.M0.rotation @ P  # pivot frame in the world
        p0 = self.M0.translation
        base = {k: v for k, v in spec.scenario_base.items() if k != "simulation"}
        sup = dict(spec.scenario_base["supports"][0])
        corners = [(a, b, -c), (a, -b, -c), (-a, b, -c), (-a, -b, -c)]
        sup["points"] = [_r(P @ np.array(v)) for v in corners]
        base["supports"] = [sup]
        arms = []
        for role in ROLES:
            slot = spec.arms[self.roles[role]]
            g = ROLE_GRIPS[role]
            pts = [P @ np.array(p) for p in g.points(a, b, c)]
            faces = [_face_name(P @ _axis(f)) for f in g.faces]
            off = np.asarray(cand.offsets.get(role, (0.0, 0.0, 0.0, 0.0)), float)
            anchor = p0 + Rw @ np.array(g.anchor(a, b, c))
            shift = np.zeros(3)
            for k, sign, dist in g.reach_over:
                shift[k] = sign * (self.table_margin(anchor, Rw[:, k] * sign) - dist)
            pos = anchor + Rw @ (np.array(g.base) + shift + off[:3])
            pos = np.clip(pos, spec.bases.lower, spec.bases.upper)  # the IK checks the reach
            yaw = float(np.arctan2(Rw[1, 0], Rw[0, 0])) + g.yaw + off[3]
            yaw = float(np.arctan2(np.sin(yaw), np.cos(yaw)))
            joint = {"type": "fingertips", "tip_radius": float(slot.tip_radius)}
            if g.approach is not None:
                joint["approach"] = _r(P @ np.array(g.approach))
            names = list(slot.tips) if g.tips is None else [slot.tips[k] for k in g.tips]
            joint["contacts"] = [{"tip": t, "face": f, "point": _r(p)}
                                 for t, f, p in zip(names, faces, pts, strict=True)]
            arms.append({"name": slot.name, "urdf": slot.urdf, "tool_frame": slot.tool_frame,
                         "base": {"position": _r(pos), "rpy": _r([0.0, 0.0, yaw])},
                         "q_seed": list(g.q_seed), "joint": joint})
        pivot_w = p0 + Rw @ np.array([a, 0.0, -c])
        axis_w = Rw @ np.array([0.0, 1.0, 0.0])
        ctrl = {"type": "phased_pd", "margin": float(spec.controller.get("margin", 2.0)),
                "support_margin": 2.0, "phases": self.phases(cand, pivot_w, axis_w)}
        for k in ("kp", "kd"):
            if k in spec.controller:
                ctrl[k] = float(spec.controller[k])
        end = ctrl["phases"][-1]["t"] + ctrl["phases"][-1]["duration"]
        sim = dict(spec.scenario_base.get("simulation", {}))
        sim.update({"duration": round(end + 0.5, 6), "dt": float(sim.get("dt", 0.004))})
        out = {"name": f"{spec.name}_plan", "description":
               f"tilt about the {cand.pivot} bottom edge by {cand.angle:g} rad, slide a gripper"
               " under the raised side, lift in form closure (planned by multiarm-pin design)"}
        out.update(base)
        out["arms"] = arms
        out["controller"] = ctrl
        out["simulation"] = sim
        return out

    def phases(self, cand: Candidate, pivot_w, axis_w) -> list[dict]:
        """``phased_pd`` phases of a plan (module docstring); offsets in the object frame."""
        P = self.frame(cand.pivot)
        names = {r: self.spec.arms[i].name for r, i in self.roles.items()}

        def v(x):
            return _r(P @ np.array(x, float))

        d = INSERT_DEPTH
        top, ins = names["top"], names["insert"]
        loose = [f"{top}:tip[0]", f"{top}:tip[1]", f"{ins}:tip[0]", f"{ins}:tip[1]"]
        lift = self.spec.pick_up["lift"]
        carry = self.spec.pick_up["carry"]
        out = [
            {"name": "rest", "kind": "hold", "t": 0.0, "duration": 0.1,
             "offsets": {names["pusher"]: v([0.0005, 0, 0]), names["stop"]: v([-0.0005, 0, 0])}},
            {"name": "tilt", "kind": "tilt", "t": 0.1, "duration": 1.0, "pivot": _r(pivot_w),
             "axis": _r(axis_w), "angle": float(cand.angle), "press": [0, 1]},
            {"name": "top", "kind": "hold", "t": 1.1, "duration": 0.8, "press": [0, 1],
             "offsets": {top: v([0.004, 0.004, -0.0005]), ins: v([-0.08, -0.04, -d])}},
            {"name": "insert", "kind": "hold", "t": 1.9, "duration": 0.8, "press": [0, 1],
             "offsets": {ins: v([-0.004, -0.004, -d])}},
            {"name": "close", "kind": "hold", "t": 2.7, "duration": 0.6, "press": [0, 1],
             "offsets": {ins: v([-0.004, -0.004, 0.0005])}},
            {"name": "grip", "kind": "hold", "t": 3.3, "duration": 0.6, "press": [0, 1],
             "loose": loose, "offsets": {top: v([-0.0005, -0.0005, -0.0005]),
                                         ins: v([0.0005, 0.0005, 0.0005])}},
            {"name": "squeeze", "kind": "hold", "t": 3.9, "duration": 0.2, "press": [0, 1]},
            {"name": "lift", "kind": "move", "t": 4.1, "duration": 0.5, "press": [],
             "displacement": _r(lift)}]
        if np.any(carry != 0.0):
            out.append({"name": "carry", "kind": "move", "t": 4.6, "duration": 0.5,
                        "press": [], "displacement": _r(carry)})
        return out

    # ------------------------------------------------------------------ key poses
    def key_poses(self, cand: Candidate, scenario: dict) -> list[tuple[str, pin.SE3, dict]]:
        """The key poses: ``(label, object placement, {arm: (3,) object-frame offset})``.

        At the start and at the end of each phase (the tilt and the slide also halfway).
        """
        phases = scenario["controller"]["phases"]
        offs = {}
        for arm in scenario["arms"]:
            ap = arm["joint"].get("approach")
            offs[arm["name"]] = np.array(ap if ap is not None else [0.0, 0.0, 0.0])
        M = self.M0
        out = [("start", M, dict(offs))]
        for p in phases:
            new = {k: np.asarray(x, float) for k, x in p.get("offsets", {}).items()}
            if p["kind"] == "tilt":
                axis, piv = np.asarray(p["axis"]), np.asarray(p["pivot"])
                for s, tag in ((0.5, " halfway"), (1.0, "")):
                    R = pin.exp3(axis * p["angle"] * s)
                    Mk = pin.SE3(R @ M.rotation, piv + R @ (M.translation - piv))
                    out.append((p["name"] + tag, Mk, dict(offs)))
                M = out[-1][1]
                continue
            if p["kind"] == "move":
                M = pin.SE3(M.rotation, M.translation + np.asarray(p["displacement"]))
            if p["name"] == "insert":
                half = dict(offs)
                half.update({k: 0.5 * (offs[k] + x) for k, x in new.items()})
                out.append((p["name"] + " halfway", M, half))
            offs = dict(offs)
            offs.update(new)
            out.append((p["name"], M, dict(offs)))
        return out

    # ------------------------------------------------------------------ checks
    def check(self, cand: Candidate) -> PlanCheck:
        """Check a candidate (module docstring); never raises for an unplannable one."""
        try:
            return check_plan(self, cand)
        except MultiArmError as exc:
            return PlanCheck(cand, False, "build", np.inf, str(exc))


@dataclass
class PlanCheck:
    """What :func:`check_plan` found about one candidate.

    Attributes:
        candidate: the :class:`Candidate`.
        ok: every check met.
        condition: the first failed (``build``, ``reach``, ``path``, ``closure``,
            ``collision``, ``torque``), or None.
        value: its value (residual [m], joint step [rad], LP margin, clearance [m], torque
            ratio).
        detail: which arm, pose or pair.
        scenario: the scenario mapping (when built).
        scores: ``torque_ratio``, ``clearance``, ``lp_margin``, ``ik_residual`` (a plan);
            ``torque_ratios``: per statically checked key pose (``rest``, ``tilt``, the
            last), its largest static torque over effort limit.
        key_q: per key pose, the arms' configurations (T, nq).
        labels: the key poses' labels.
    """

    candidate: Candidate
    ok: bool
    condition: str | None
    value: float | None
    detail: str
    scenario: dict | None = None
    scores: dict = field(default_factory=dict)
    key_q: np.ndarray | None = None
    labels: list = field(default_factory=list)


CHECKS = ("build", "reach", "path", "closure", "collision", "torque")
"""The checks of a plan, in order."""


def grasp_wrenches(built) -> np.ndarray:
    """(6, N) the wrenches ``[n; p × n]`` of a built scenario's fingertip contacts.

    At their grasp places, object frame, ``n`` the inward normal.
    """
    cols = []
    for j in built.joints:
        for c in j.contacts:
            n = -c.surface.normal
            p = j.tool_in_object.act(c.point) + c.radius * c.surface.normal
            cols.append(np.r_[n, np.cross(p, n)])
    return np.array(cols).T


def check_plan(planner: PickUpPlanner, cand: Candidate) -> PlanCheck:
    """Build a candidate's scenario and check it at its key poses (module docstring)."""
    from multiarm_pin.app.precheck import effort_limits, static_torques
    from multiarm_pin.app.scenario import build_scenario
    from multiarm_pin.app.scenario.schema import parse_scenario
    from multiarm_pin.design.assessment import MAX_JOINT_STEP
    from multiarm_pin.exceptions import DynamicsError, UnreachableError
    from multiarm_pin.feasibility import CollisionScene
    from multiarm_pin.grasp.form_closure import form_closure
    from multiarm_pin.model.ik import ik_frame_points

    spec = planner.spec
    data = planner.scenario(cand)

    def fail(cond, value, detail, **kw):
        return PlanCheck(cand, False, cond, value, detail, data, **kw)

    # reach: the builder's IK at the start (tips on their faces, or apart by the approach)
    lo, hi = spec.bases.yaw
    for arm in data["arms"]:
        yaw = float(arm["base"]["rpy"][2])
        turns = [yaw + 2 * np.pi * k for k in (-1, 0, 1)]
        if not any(lo - 1e-9 <= y <= hi + 1e-9 for y in turns):
            return fail("build", yaw, f"{arm['name']}'s base yaw {yaw:.3g} rad outside the "
                                      f"region's [{lo:.3g}, {hi:.3g}]")
    try:
        built = build_scenario(parse_scenario(data, spec.file), load_visuals=False)
    except UnreachableError as exc:
        return fail("reach", exc.residual, str(exc))
    system, st0 = built.system, built.initial_state
    arms = system.arm_set.arms
    q_start = np.split(np.asarray(st0.q, float), np.cumsum([a.nq for a in arms])[:-1])
    data["arms"] = [dict(a, q0=_r(q)) for a, q in zip(data["arms"], q_start, strict=True)]
    # closure of the final grasp (all 13 contacts)
    W = grasp_wrenches(built)
    fc = form_closure(W)
    if not fc.form_closure:
        return fail("closure", float(fc.lp_epsilon), "the final grasp is not form closure")
    # path: every key pose, warm-started from the previous one
    poses = planner.key_poses(cand, data)
    tips = [[c["tip"] for c in a["joint"]["contacts"]] for a in data["arms"]]
    # per arm, (K, 3) its tip centres in the object frame at the grasp (the start's, less
    # the approach offset of a gripper that starts apart): what phased_pd holds
    local = []
    for i, a in enumerate(arms):
        ap = np.asarray(data["arms"][i]["joint"].get("approach", np.zeros(3)), float)
        local.append(np.array([planner.M0.actInv(a.frame_placement(q_start[i], t).translation)
                               - ap for t in tips[i]]))
    Q, prev, worst_res = [], [q.copy() for q in q_start], 0.0
    for label, M, offs in poses:
        row = []
        for i, a in enumerate(arms):
            name = data["arms"][i]["name"]
            target = np.array([M.act(p + offs[name]) for p in local[i]])
            try:
                ik = ik_frame_points(a, tips[i], target, prev[i], restarts=0, max_iter=80)
            except UnreachableError as exc:
                return fail("path", exc.residual, f"{name} at {label}: {exc}")
            res = float(max(np.linalg.norm(a.frame_placement(ik.q, t).translation - p)
                            for t, p in zip(tips[i], target, strict=True)))
            step = float(np.max(np.abs(ik.q - prev[i])))
            if res > IK_RESIDUAL:
                return fail("path", res, f"{name} at {label}: IK residual {res:.3g} m")
            if step > MAX_JOINT_STEP:
                return fail("path", step, f"{name} jumps {step:.3g} rad at {label} (another "
                                          "IK branch)")
            lo, hi = a.model.lowerPositionLimit, a.model.upperPositionLimit
            if np.any(ik.q < lo - 1e-9) or np.any(ik.q > hi + 1e-9):
                return fail("path", step, f"{name} beyond a joint limit at {label}")
            worst_res = max(worst_res, res)
            prev[i] = ik.q
            row.append(ik.q)
        Q.append(np.concatenate(row))
    Q = np.array(Q)
    labels = [p[0] for p in poses]
    # collisions and clearances at the key poses
    ground = data.get("ground", {"height": 0.0})
    ground = None if ground is None else float(ground.get("height", 0.0))
    scene = CollisionScene(system, st0, ground)
    pos = np.array([p[1].translation for p in poses])
    quat = np.array([pin.Quaternion(p[1].rotation).coeffs() for p in poses])
    cps = [np.array([[p[1].act(c + p[2][data["arms"][i]["name"]]) for c in loc]
                     for p in poses]) for i, loc in enumerate(local)]
    scan = scene.scan(Q, pos, quat, cps)
    clear = {k: v for k, v in scan.clearance.items() if v is not None}
    worst = min(clear, key=clear.get) if clear else None
    min_clear = clear[worst] if clear else np.inf
    if scan.hits:
        k = next(iter(scan.hits))
        arm, link, other = scene.pair_names(k)
        return fail("collision", min(h[1] for h in scan.hits[k]),
                    f"{arm}/{link} and {other} collide", key_q=Q, labels=labels)
    if min_clear < spec.search.clearance:
        return fail("collision", min_clear, f"{worst.replace('_', '-')} clearance "
                    f"{min_clear * 1e3:.3g} mm", key_q=Q, labels=labels)
    # static torques: at rest on the table (the couple pressing, the supports carrying the
    # rest), tilted (the couple alone against the pivot edge's vertices: the other arms
    # are apart, the far edge's vertices are off the table) and carried at the end (the arms
    # alone)
    limits = np.concatenate([effort_limits(a) for a in arms])
    couple = [role in ("pusher", "stop") for role in ROLES]  # data["arms"] in ROLES' order
    tilted = labels.index(next(p["name"] for p in data["controller"]["phases"]
                               if p["kind"] == "tilt"))
    worst_ratio, worst_at, ratios = 0.0, "", {}
    for k, supports, engaged in ((1, True, None), (tilted, True, couple),
                                 (len(poses) - 1, False, None)):
        st = system.state(Q[k], None, pos[k], quat[k])
        try:
            tau, _ = static_torques(system, st, supports=supports, engaged_arms=engaged,
                                    support_gap=None if engaged is None else TOUCHING_GAP)
        except DynamicsError as exc:
            return fail("closure", 0.0, f"the contacts cannot hold the object at "
                                        f"{labels[k]}: {exc}", key_q=Q, labels=labels)
        ratio = float(np.max(np.abs(tau) / limits))
        ratios[labels[k]] = ratio
        if ratio > worst_ratio:
            worst_ratio, worst_at = ratio, labels[k]
    if worst_ratio > STATIC_TORQUE_RATIO:
        return fail("torque", worst_ratio, f"static torque {worst_ratio:.3g} of its limit at "
                    f"{worst_at} (at most {STATIC_TORQUE_RATIO:g})", key_q=Q, labels=labels)
    scores = {"torque_ratio": worst_ratio, "clearance": float(min_clear),
              "lp_margin": float(fc.lp_epsilon), "ik_residual": worst_res,
              "torque_ratios": ratios}
    return PlanCheck(cand, True, None, None, "", data, scores, Q, labels)


# ----------------------------------------------------------------------------- search
@dataclass
class PickUpResult:
    """What :func:`plan_pick_up` found.

    Attributes:
        spec: the spec.
        plans: the plans that met every check, best first (:class:`PlanCheck`).
        checked: every candidate's :class:`PlanCheck`, in search order.
        excluded: why pivot edges were not tried (their angle range is empty).
        wall_time: seconds.
    """

    spec: object
    plans: list
    checked: list
    excluded: list
    wall_time: float


def _rank(c: PlanCheck) -> tuple:
    return (round(c.scores["torque_ratio"], 9), -round(c.scores["clearance"], 9),
            c.candidate.index)


def _progress(c: PlanCheck) -> tuple:
    """Furthest check first, then nearest to meeting it."""
    k = CHECKS.index(c.condition)
    v = c.value if c.value is not None and np.isfinite(c.value) else np.inf
    v = -v if c.condition in ("closure", "collision") else v
    return (-k, v, c.candidate.index)


def plan_pick_up(spec, seed: int | None = None, progress=None,
                 first: bool = False) -> PickUpResult:
    """Search the tilt plans of a ``pick_up`` spec (module docstring).

    Pivot edges are tried smallest tilt first (the edge the box is longest toward), each
    at its angles smallest first. ``first``: stop at the first plan that meets every check
    (random bases only while none met every check: what a quick plan or a test needs).

    Raises:
        DesignImpossibleError: no candidate met every check (the message names every pivot
            edge's reason and the furthest check reached with its value).
    """
    t0 = time.perf_counter()
    planner = PickUpPlanner(spec)
    rng = np.random.default_rng(spec.search.seed if seed is None else int(seed))
    checked, excluded, combos = [], [], []
    for pivot in PIVOTS:
        angles, why = planner.angles(pivot)
        if why is not None:
            excluded.append(why)
        combos += [(pivot, t) for t in angles]
    combos.sort(key=lambda pt: (pt[1], list(PIVOTS).index(pt[0])))
    for pivot, t in combos:
        checked.append(planner.check(Candidate(len(checked), pivot, t)))
        if first and checked[-1].ok:
            break
    if progress is not None:
        progress(f"{len(checked)} pivot edges and angles at the nominal bases, "
                 f"{sum(c.ok for c in checked)} met every check")
    if combos and not (first and any(c.ok for c in checked)):
        for _ in range(spec.search.candidates):
            if first and checked[-1].ok:
                break
            ok = sorted((c for c in checked if c.ok), key=_rank)
            parent = ok[0] if ok else min(checked, key=_progress)
            offs = {}
            for role in ROLES:
                base = np.asarray(parent.candidate.offsets.get(role, np.zeros(4)), float)
                step = np.r_[rng.uniform(-BASE_STEP, BASE_STEP, 2),
                             rng.uniform(-BASE_STEP / 2, BASE_STEP / 2),
                             rng.uniform(-YAW_STEP, YAW_STEP)]
                offs[role] = tuple(float(x) for x in base + 0.5 * step)
            pc = parent.candidate
            checked.append(planner.check(Candidate(len(checked), pc.pivot, pc.angle, offs)))
        if progress is not None:
            progress(f"{len(checked)} candidates, {sum(c.ok for c in checked)} met every check")
    plans = sorted((c for c in checked if c.ok), key=_rank)
    if not plans:
        raise impossible(spec, checked, excluded)
    return PickUpResult(spec, plans, checked, excluded, time.perf_counter() - t0)


def impossible(spec, checked: list, excluded: list) -> DesignImpossibleError:
    """The error of a pick-up no candidate could plan: why, per pivot edge and check."""
    parts = list(excluded)
    if checked:
        best = min(checked, key=_progress)
        parts.append(f"furthest candidate (pivot {best.candidate.pivot}, tilt "
                     f"{best.candidate.angle:g} rad) failed {best.condition}: {best.detail}")
        cond, value = best.condition, best.value
    else:
        cond, value = "tilt", float("nan")
    return DesignImpossibleError(cond, value, f"{spec.file}: no tilt plan found in "
                                              f"{len(checked)} candidates: " + "; ".join(parts))


def has_overhang(spec) -> bool:
    """The bottom face is not covered whole by the support (fingertips reach under it)."""
    from multiarm_pin.design.assessment import DesignProblem

    problem = DesignProblem(spec)
    bottom = [f for f, _, _ in problem.rects]
    return bool(bottom) and not all(problem.covered(f) for f in bottom)


def with_box(data: dict, size, mass: float, yaw: float = 0.0,
             margin=(0.4, 0.3)) -> dict:
    """A pick-up spec mapping for another box on the same table plane.

    The box (``size`` (3,) [m], ``mass`` [kg], turned ``yaw`` [rad] about z) lies with its
    centre above the spec's box's; the support is a rectangle with its sides along the box's
    (``x_axis``) ``margin`` [m] wider than the box on each side along the box's x and y
    (the table larger than the box), its points the bottom face's corners. ``data`` (a
    parsed spec mapping) is not changed.
    """
    import copy

    out = copy.deepcopy(data)
    size = np.asarray(size, float)
    sp = out["supports"][0]
    h = float(np.asarray(sp["plane"]["point"], float)[2])
    p = np.asarray(out["object"]["pose"]["position"], float)
    out["object"]["shape"] = {"type": "box", "size": _r(size)}
    out["object"]["mass"] = float(mass)
    out["object"]["pose"] = {"position": _r([p[0], p[1], h + size[2] / 2]),
                             "rpy": [0.0, 0.0, float(yaw)]}
    sp["extent"] = _r(size[:2] + 2 * np.asarray(margin, float))
    sp["x_axis"] = _r(_rz(yaw)[:, 0])
    sp["plane"] = {"point": _r([p[0], p[1], h]), "normal": [0.0, 0.0, 1.0]}
    half = size / 2
    sp["points"] = [_r([sx * half[0], sy * half[1], -half[2]]) for sx in (1, -1)
                    for sy in (1, -1)]
    return out


def use_tilt(spec) -> bool:
    """Whether a pick-up spec takes the tilt plan.

    ``strategy: tilt``, or ``auto`` with no simpler plan (no arm welds and the table covers
    the bottom face whole).
    """
    if spec.pick_up["strategy"] == "tilt":
        return True
    return not (any(s.gripper == "weld" for s in spec.arms) or has_overhang(spec))


def describe_plan(c: PlanCheck) -> str:
    """One line: the pivot, the angle, the roles' arms, the scores."""
    s = c.scores
    return (f"pivot {c.candidate.pivot} edge, tilt {c.candidate.angle:g} rad; torque ratio "
            f"{s['torque_ratio']:.3g}, clearance {s['clearance'] * 1e3:.3g} mm, LP margin "
            f"{s['lp_margin']:.3g}, IK residual {s['ik_residual']:.2g} m")


__all__ = ["CHECKS", "PIVOTS", "ROLES", "ROLE_GRIPS", "Candidate", "PickUpPlanner",
           "PickUpResult", "PlanCheck", "assign_roles", "check_pick_up_spec", "check_plan",
           "describe_plan", "grasp_wrenches", "has_overhang", "plan_pick_up",
           "tilt_angle_range", "use_tilt", "with_box"]
