"""Candidate designs: where each arm's base goes, where it holds the object, which IK branch.

A :class:`Candidate` gives, per arm, an :class:`ArmChoice`: the base (position and yaw), the
grasp and the IK seed (the branch). The grasp of a weld is a face, a point on it and the
tool's roll about the face normal (the tool's z axis points into the face); the grasp of a
fingertip gripper is the face each tip touches and the point each tip should touch (the
gripper is rigid: inverse kinematics puts every tip on its face, as near its point as the
gripper allows).

:func:`sample_candidate` draws a candidate at random (its own generator seeded from the spec's
seed and the candidate's index, so that a candidate does not depend on which worker or in which
order it is drawn); :func:`perturb` draws a neighbour of an assessed candidate for local
refinement, on the same IK branch (seeded with the configuration found).

Faces: a weld never goes on a face that rests on a support, nor on a face whose outward
normal points down (below :data:`DOWNWARD_NORMAL_Z`): an arm standing on the floor cannot
reach under the object. A fingertip may touch a supported face only outside the support's
rectangle (its ``extent``, else the rectangle of its support points, as the collision
scene's slab), so under an overhang.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin

DOWNWARD_NORMAL_Z = -0.7
"""A face whose outward normal's world z is below this is not offered to welds."""

MIN_BASE_DISTANCE = 0.1
"""Smallest horizontal distance [m] between a base and the object's footprint (sampling)."""

BASE_SPACING = 0.3
"""Smallest distance [m] between two bases (sampling)."""

REACH_FRACTION = 0.7
"""Bases are drawn within this fraction of the arm's reach bound
(:func:`~multiarm_pin.app.precheck.arm_reach`, the sum of its links' lengths, which no pose
with the tool turned to a face attains) from the contact."""

SAMPLING_TRIES = 200
"""Random draws before giving up: of a base position (then the draw nearest the conditions is
kept), of a point inside a face by the margin (then the face's centre), of an arm's choice
in a recombination (then none)."""

GRIP_TRIES = 24
"""Assignments of a fingertip gripper's tips to a corner's faces tried per candidate."""


@dataclass(frozen=True)
class ArmChoice:
    """One arm's part of a candidate.

    Attributes:
        base: (4,) ``[x, y, z, yaw]`` of the base [m, rad].
        faces: the face index of each contact (a weld: one face).
        points: (K, 3) the contact points in the object frame [m] (a weld: one point).
        roll: the weld tool's roll about the face normal [rad] (0 for fingertips).
        q_seed: (nq,) the IK seed [rad] (the branch).
        tool: (7,) a fingertip gripper's tool placement in the object frame ``[x, y, z, qx,
            qy, qz, qw]`` that puts its tips on ``points`` (:func:`fit_gripper`), or None.
    """

    base: np.ndarray
    faces: tuple[int, ...]
    points: np.ndarray
    roll: float
    q_seed: np.ndarray
    tool: np.ndarray | None = None


@dataclass(frozen=True)
class Candidate:
    """A candidate design.

    Attributes:
        index: its number in the search (the ranking's tie-break).
        arms: one :class:`ArmChoice` per arm slot.
        parent: index of the candidate it refines, or -1.
    """

    index: int
    arms: tuple[ArmChoice, ...]
    parent: int = -1


def candidate_rng(seed: int, index: int, stream: int = 0) -> np.random.Generator:
    """The candidate's own generator, from the search seed, its index and a stream only."""
    return np.random.default_rng([int(seed), int(index), int(stream)])


def face_edge_margin(poly, face: int, point: np.ndarray) -> float:
    """Distance [m] from a point on face ``face`` to the face's edges (negative: outside).

    Each other non-parallel face's plane cuts the face along a line; the point's distance to
    that line within the face's plane is ``-(n_j·p - d_j) / |n_j × n_k|``.
    """
    n_k = poly.normals[face]
    out = np.inf
    for j in range(poly.n_faces):
        if j == face:
            continue
        s = float(np.linalg.norm(np.cross(poly.normals[j], n_k)))
        if s < 1e-9:
            continue
        out = min(out, -(float(poly.normals[j] @ point) - float(poly.offsets[j])) / s)
    return float(out)


def supported_rectangles(spec, poly) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """Per support, the object face resting on it and its supported rectangle (object frame).

    Returns:
        ``(face, lo, hi)`` with ``lo, hi`` (2,) the rectangle in the face's
        :meth:`~multiarm_pin.model.polyhedron.Polyhedron.face_frame` coordinates.
    """
    R_o = pin.Quaternion(spec.object.quaternion).toRotationMatrix()
    p_o = spec.object.position
    out = []
    for sp in spec.supports:
        n_w = np.asarray(sp.normal, float)
        for f in range(poly.n_faces):
            nf = R_o @ poly.normals[f]
            if nf @ n_w > -0.99:
                continue
            origin, F = poly.face_frame(f)
            plane = float(n_w @ (p_o + R_o @ origin) - n_w @ sp.point)
            if abs(plane) > 1e-3:
                continue
            pts = poly.vertices if isinstance(sp.points, str) else np.asarray(sp.points)
            uv = (pts - origin) @ F[:, :2]
            lo, hi = uv.min(axis=0), uv.max(axis=0)
            if sp.extent is not None:  # the table's rectangle around its point, in the face
                c = R_o.T @ (np.asarray(sp.point, float) - p_o) - origin
                c2 = c @ F[:, :2]
                half = 0.5 * float(max(sp.extent))
                lo, hi = np.minimum(lo, c2 - half), np.maximum(hi, c2 + half)
            out.append((f, lo, hi))
    return out


def weld_faces(spec, poly) -> list[int]:
    """The faces a weld may hold (module docstring)."""
    R_o = pin.Quaternion(spec.object.quaternion).toRotationMatrix()
    resting = {f for f, _, _ in supported_rectangles(spec, poly)}
    return [f for f in range(poly.n_faces)
            if f not in resting and (R_o @ poly.normals[f])[2] >= DOWNWARD_NORMAL_Z]


def point_allowed(spec, poly, face: int, point: np.ndarray, margin: float,
                  rects=None) -> bool:
    """A contact point lies inside its face by ``margin`` and off every supported rectangle."""
    if face_edge_margin(poly, face, point) < margin:
        return False
    for f, lo, hi in rects if rects is not None else supported_rectangles(spec, poly):
        if f != face:
            continue
        origin, F = poly.face_frame(f)
        uv = (point - origin) @ F[:, :2]
        if np.all(uv > lo - margin) and np.all(uv < hi + margin):
            return False
    return True


def sample_face_point(poly, face: int, margin: float, rng) -> np.ndarray:
    """A point drawn uniformly on face ``face`` at least ``margin`` inside its edges."""
    origin, F = poly.face_frame(face)
    verts = (poly.vertices[list(poly.faces[face])] - origin) @ F[:, :2]
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    for _ in range(SAMPLING_TRIES):
        uv = rng.uniform(lo, hi)
        p = origin + F[:, :2] @ uv
        if face_edge_margin(poly, face, p) >= margin:
            return p
    return origin.copy()


def project_to_face(poly, face: int, point: np.ndarray, margin: float) -> np.ndarray:
    """The point moved onto the face's plane and back inside its edges by ``margin``."""
    origin, F = poly.face_frame(face)
    p = point - (F[:, 2] @ (point - origin)) * F[:, 2]
    for _ in range(60):
        if face_edge_margin(poly, face, p) >= margin:
            return p
        p = origin + 0.9 * (p - origin)
    return origin.copy()


def sample_base(problem, contact_world: np.ndarray, normal_world: np.ndarray, reach: float,
                taken: list[np.ndarray], rng) -> np.ndarray:
    """A base ``[x, y, z, yaw]`` in the region, on the contact's side and within reach.

    Draws positions uniformly in the region until one is on the outer side of the contact's
    face (horizontally), within :data:`REACH_FRACTION` of ``reach`` from the contact (3-D),
    outside the object's footprint and :data:`BASE_SPACING` from the bases already taken; after
    :data:`SAMPLING_TRIES` draws, the one nearest those conditions.
    """
    b = problem.spec.bases
    best, best_bad = None, np.inf
    n_h = np.array([normal_world[0], normal_world[1], 0.0])
    for _ in range(SAMPLING_TRIES):
        p = rng.uniform(b.lower, b.upper)
        d = p - contact_world
        dist = float(np.linalg.norm(d))
        bad = max(dist - REACH_FRACTION * reach, 0.0) + \
            max(0.15 - float(np.linalg.norm(d[:2])), 0.0)
        if np.linalg.norm(n_h) > 0.3:
            bad += max(-(n_h @ d), 0.0)
        if problem.footprint_distance(p) < MIN_BASE_DISTANCE:
            bad += MIN_BASE_DISTANCE - problem.footprint_distance(p)
        for t in taken:
            bad += max(BASE_SPACING - float(np.linalg.norm(t[:2] - p[:2])), 0.0)
        if bad < best_bad:
            best, best_bad = p, bad
        if bad == 0.0:
            break
    yaw = float(rng.uniform(*b.yaw)) if b.yaw[1] > b.yaw[0] else float(b.yaw[0])
    return np.array([*best, yaw])


AIMED_SEED_FRACTION = 0.75
"""Share of random IK seeds whose first joint (a vertical base axis) turns the arm toward its
grasp (seeds not asked for a branch)."""

BRANCHES = 8
"""IK branches of a 6-joint arm whose first joint turns about its base's vertical axis (the
UR arms, the mp6): shoulder (the first joint turned toward its grasp or away from it), elbow
(the sign of the third joint) and wrist (the sign of the fifth), bits 2, 1 and 0 of the branch
number (:func:`branch_of`). Other arms have one: their seeds are drawn at random."""

SEED_TRIES = 30
"""Draws of an IK seed before one whose joints are all above the ground is kept (else the
last)."""

SEED_GROUND_CLEARANCE = 0.05
"""Height [m] above the ground of every joint origin of an IK seed."""

BRANCH_JOINT_RANGE = (0.3, np.pi - 0.3)
"""Range [rad] of the magnitude of a branch seed's elbow and wrist angles (their signs are
the branch's; away from 0 and ±π, where the branches meet; the upper end within the joint's
limit)."""


def n_branches(problem, slot: int) -> int:
    """The number of IK branches the search tells apart for an arm (:data:`BRANCHES` or 1)."""
    lo, _ = problem.seed_bounds[slot]
    return BRANCHES if problem.pan_offset[slot] is not None and len(lo) == 6 else 1


def _aim(problem, slot: int, base: np.ndarray, target: np.ndarray) -> float:
    """The first joint's angle [rad] that turns the arm's neutral reach toward ``target``."""
    d = target - base[:3]
    return float(np.arctan2(d[1], d[0]) - base[3] - problem.pan_offset[slot])


def _wrap(a):
    """Angles [rad] wrapped to (-π, π]."""
    return np.angle(np.exp(1j * np.asarray(a, float)))


def branch_of(problem, slot: int, base: np.ndarray, target: np.ndarray, q: np.ndarray) -> int:
    """The IK branch (:data:`BRANCHES`) of an arm's configuration, or 0 for one-branch arms.

    Shoulder: the first joint more than π/2 from aiming at ``target`` (world [m], the grasp);
    elbow: the third joint's angle (wrapped to ``(-π, π]``) positive; wrist: the fifth's.
    """
    if n_branches(problem, slot) == 1:
        return 0
    q = np.asarray(q, float)
    shoulder = int(np.cos(q[0] - _aim(problem, slot, base, target)) < 0.0)
    return 4 * shoulder + 2 * int(_wrap(q[2]) > 0.0) + int(_wrap(q[4]) > 0.0)


def random_seed_configuration(problem, slot: int, base: np.ndarray, target: np.ndarray,
                              rng, branch: int | None = None) -> np.ndarray:
    """An IK seed: uniform within the joint limits (each at most ±π), aimed or on a branch.

    Without ``branch``: with probability :data:`AIMED_SEED_FRACTION`, when the arm's first
    joint turns about its base's vertical axis, that joint is set so that the arm's neutral
    reach direction (:attr:`~.assessment.DesignProblem.pan_offset`) points at ``target``
    (world [m]), give or take a normal 0.2 rad; the seed falls on whichever branch it falls.
    With ``branch`` (an arm with :data:`BRANCHES`): the seed lies on that branch: its first
    joint aims at ``target``, or away from it for the shoulder's other branch, give or take
    a normal 0.2 rad; its elbow and wrist angles have the branch's signs and magnitudes in
    :data:`BRANCH_JOINT_RANGE`. Seeds are drawn again (up to :data:`SEED_TRIES` times) until
    every joint origin is :data:`SEED_GROUND_CLEARANCE` above the ground.
    """
    lo, hi = problem.seed_bounds[slot]
    branched = branch is not None and n_branches(problem, slot) > 1
    aim = branched or rng.random() < AIMED_SEED_FRACTION
    offset = problem.pan_offset[slot]
    for _ in range(SEED_TRIES):
        q = rng.uniform(lo, hi)
        if aim and offset is not None:
            away = np.pi if branched and branch & 4 else 0.0
            pan = float(_wrap(_aim(problem, slot, base, target) + away + rng.normal(0.0, 0.2)))
            q[0] = float(np.clip(pan, lo[0], hi[0]))
        if branched:
            for j, bit in ((2, 2), (4, 1)):
                sign = 1.0 if branch & bit else -1.0
                top = min(BRANCH_JOINT_RANGE[1], hi[j] if sign > 0 else -lo[j])
                bottom = min(BRANCH_JOINT_RANGE[0], top)
                q[j] = float(np.clip(sign * rng.uniform(bottom, top), lo[j], hi[j]))
        if problem.lowest_joint(slot, q) + base[2] > problem.ground + SEED_GROUND_CLEARANCE:
            break
    return q


def sample_candidate(problem, index: int) -> Candidate:
    """A random candidate (its generator: :func:`candidate_rng` of the spec's seed, ``index``).

    Welds take distinct faces while there are enough (a random order of the weld faces);
    fingertip grippers take the faces around a random corner of a box (see
    :func:`fingertip_faces`).
    """
    spec = problem.spec
    rng = candidate_rng(spec.search.seed, index)
    poly = problem.poly
    margin = spec.search.face_margin
    order = list(rng.permutation(problem.weld_faces)) if problem.weld_faces else []
    corners_used: list[np.ndarray] = []
    arms, bases = [], []
    for i, slot in enumerate(spec.arms):
        if slot.gripper == "weld":
            if not order:
                order = list(rng.permutation(problem.weld_faces))
            f = int(order.pop(0))
            faces = (f,)
            points = sample_face_point(poly, f, margin, rng)[None]
            roll = float(rng.uniform(-np.pi, np.pi))
            tool = None
        else:
            faces, points, tool = fingertip_faces(problem, slot, corners_used, rng)
            roll = 0.0
        c_w = problem.object_placement.act(points.mean(axis=0))
        n_w = problem.object_placement.rotation @ poly.normals[faces[0]]
        if spec.bases.fixed is not None:
            M = spec.bases.fixed[i]
            base = np.array([*M.translation, float(pin.rpy.matrixToRpy(M.rotation)[2])])
        else:
            base = sample_base(problem, c_w, n_w, problem.reach[i], bases, rng)
        bases.append(base)
        q = random_seed_configuration(problem, i, base, c_w, rng)
        arms.append(ArmChoice(base, faces, points, roll, q, tool))
    return Candidate(index, tuple(arms))


def corner_assignments(n_tips: int) -> list[tuple[tuple[int, ...], int]]:
    """Every way to put a gripper's tips on the three faces around a box corner.

    Returns:
        ``(axes, extra)``: ``axes[k]`` the axis (0, 1, 2) of tip k's face for the first three
        tips (a permutation), and the axis of every further tip's face (``extra``).
    """
    from itertools import permutations

    out = []
    for perm in permutations(range(3)):
        for extra in (range(3) if n_tips > 3 else (perm[2],)):
            out.append((tuple(perm) + (extra,) * (n_tips - 3), extra))
    return out


def fit_gripper(problem, slot, signs: np.ndarray, axes: tuple[int, ...], rng,
                preferred: np.ndarray | None = None):
    """Place a free-floating rigid gripper with its tips on the faces around a corner.

    Inverse kinematics (:func:`~multiarm_pin.model.ik.solve_ik`) of the tool frame alone on a
    free-flyer: each tip's sphere touches its face's plane (primary), as near as it can to a
    point drawn on that face near the corner, or to ``preferred`` (K, 3) (preference). The
    fit counts when every tip
    touches inside its face by the face margin (off supported areas); the gripper's links
    against the object are the collision check's (:mod:`.assessment`).

    Returns:
        ``(faces, points, tool)``: the contact points on the faces (object frame [m]) and
        the tool's placement ``[x, y, z, qx, qy, qz, qw]`` in the object frame; or None.
    """
    from multiarm_pin.exceptions import UnreachableError
    from multiarm_pin.model.ik import PlaneTarget, PointTarget, solve_ik

    poly = problem.poly
    half = np.max(np.abs(poly.vertices), axis=0)
    tips = problem.tips_in_tool[slot.index]
    r = slot.tip_radius
    margin = problem.spec.search.face_margin
    model = problem.floating_gripper(slot.index)
    faces, targets = [], []
    for k, a in enumerate(axes):
        f = next(j for j in range(poly.n_faces) if abs(poly.normals[j][a] - signs[a]) < 1e-9)
        n, d = poly.normals[f], float(poly.offsets[f])
        if preferred is None:
            p = signs * half - signs * rng.uniform(margin + r, np.maximum(margin + r,
                                                                          half * 0.6))
            p[a] = signs[a] * half[a]
        else:
            p = preferred[k]
        faces.append(f)
        targets.append(PlaneTarget("tool", n, d + r, point=tips[k]))
        targets.append(PointTarget("tool", p + r * n, primary=False, offset=tips[k]))
    q = np.zeros(7)
    q[:3] = signs * (half + 0.1)
    q[3:] = pin.Quaternion(pin.rpy.rpyToMatrix(*rng.uniform(-np.pi, np.pi, 3))).coeffs()
    try:
        ik = solve_ik(model, targets, q, max_iter=60, restarts=0)
    except UnreachableError:
        return None
    M = pin.XYZQUATToSE3(ik.q)
    pts = np.array([M.act(t) - r * poly.normals[f] for t, f in zip(tips, faces, strict=True)])
    for f, p in zip(faces, pts, strict=True):
        if not point_allowed(problem.spec, poly, f, p, margin, problem.rects):
            return None
    return tuple(faces), pts, ik.q.copy()


def fingertip_faces(problem, slot, corners_used: list, rng):
    """Faces and points of a fingertip gripper's tips around a corner of a box.

    A corner is drawn (the opposite of the previous gripper's, else one no gripper took) and
    an assignment of the tips to its faces (:func:`corner_assignments`); a free-floating fit
    (:func:`fit_gripper`) must place the rigid gripper's tips inside those faces, else
    another assignment is drawn (up to :data:`GRIP_TRIES` times; then the last draw's
    assignment with points near the corner and no tool placement, which inverse kinematics
    will likely refuse).

    Returns:
        ``(faces, points, tool or None)`` as :func:`fit_gripper`.
    """
    poly = problem.poly
    half = np.max(np.abs(poly.vertices), axis=0)
    if corners_used and not any(np.array_equal(-corners_used[-1], c) for c in corners_used):
        signs = -corners_used[-1]
    else:
        for _ in range(50):
            signs = rng.choice([-1.0, 1.0], size=3)
            if not any(np.array_equal(signs, c) for c in corners_used):
                break
    corners_used.append(signs)
    options = corner_assignments(len(slot.tips))
    for _ in range(GRIP_TRIES):
        axes = options[int(rng.integers(len(options)))][0]
        fit = fit_gripper(problem, slot, signs, axes, rng)
        if fit is not None:
            return fit
    faces = tuple(next(j for j in range(poly.n_faces)
                       if abs(poly.normals[j][a] - signs[a]) < 1e-9) for a in axes)
    m = problem.spec.search.face_margin + slot.tip_radius
    pts = [project_to_face(poly, f, signs * (half - m), m) for f in faces]
    return faces, np.array(pts), None


def perturb(problem, parent: Candidate, q0s: list[np.ndarray], index: int,
            scale: float) -> Candidate:
    """A neighbour of an assessed candidate, on the same IK branches.

    Bases move by a normal step of ``0.1 scale`` m (clipped to the region) and yaw by
    ``0.3 scale`` rad; weld points move by ``0.05 scale`` m on their face (kept inside by the
    margin) and rolls by ``0.3 scale`` rad; half the time a fingertip gripper is fitted
    again (:func:`fit_gripper`) at its corner with its points moved by ``0.03 scale`` m,
    else it keeps its grip. The IK seed is the configuration found for the parent.
    """
    spec = problem.spec
    rng = candidate_rng(spec.search.seed, index)
    b = spec.bases
    margin = spec.search.face_margin
    arms = []
    for i, a in enumerate(parent.arms):
        base = a.base.copy()
        if b.fixed is None:
            base[:3] = np.clip(base[:3] + rng.normal(0.0, 0.1 * scale, 3), b.lower, b.upper)
            if b.yaw[1] > b.yaw[0]:
                yaw = base[3] + rng.normal(0.0, 0.3 * scale)
                base[3] = float(np.clip(yaw, *b.yaw)) if b.yaw != (-np.pi, np.pi) else \
                    float(_wrap(yaw))
        slot = spec.arms[i]
        points = a.points
        if slot.gripper == "weld":
            points = np.array([project_to_face(problem.poly, f,
                                               p + rng.normal(0.0, 0.05 * scale, 3), margin)
                               for f, p in zip(a.faces, a.points, strict=True)])
        roll = a.roll + (rng.normal(0.0, 0.3 * scale) if slot.gripper == "weld" else 0.0)
        faces, tool = a.faces, a.tool
        if slot.gripper != "weld" and a.tool is not None and rng.random() < 0.5:
            signs = np.sign(a.points.mean(axis=0))
            axes = tuple(int(np.argmax(np.abs(problem.poly.normals[f]))) for f in a.faces)
            pref = np.array([project_to_face(problem.poly, f,
                                             p + rng.normal(0.0, 0.03 * scale, 3), margin)
                             for f, p in zip(a.faces, a.points, strict=True)])
            fit = fit_gripper(problem, slot, signs, axes, rng, pref)
            if fit is not None:
                faces, points, tool = fit
        arms.append(replace(a, base=base, faces=faces, points=points, roll=float(roll),
                            q_seed=np.asarray(q0s[i], float).copy(), tool=tool))
    return Candidate(index, tuple(arms), parent.index)


def reseed(problem, parent: Candidate, q0s: list[np.ndarray], index: int,
           arm: int, branch: int | None = None) -> Candidate:
    """The same design with arm ``arm`` on another IK branch: a fresh seed for its posture.

    Bases and grasps stay; every other arm is seeded with its configuration found for the
    parent; arm ``arm`` with a new :func:`random_seed_configuration` on ``branch`` (None:
    a random seed, mostly aimed at its grasp).
    With the tool held fully (a weld, a fitted gripper) a 6-joint arm's posture is one of
    its IK branches, which decides how far its links' weight and the object's act from its
    shoulder: the static torques.
    """
    rng = candidate_rng(problem.spec.search.seed, index)
    arms = []
    for i, a in enumerate(parent.arms):
        if i == arm:
            q = random_seed_configuration(problem, i, a.base,
                                          problem.object_placement.act(a.points.mean(axis=0)),
                                          rng, branch)
        else:
            q = np.asarray(q0s[i], float).copy()
        arms.append(replace(a, q_seed=q))
    return Candidate(index, tuple(arms), parent.index)


def approach(problem, parent: Candidate, q0s: list[np.ndarray], index: int, arm: int | None,
             step: float) -> Candidate:
    """The same design with arm ``arm``'s base (None: every arm's) moved toward its grasp.

    Horizontally, by a uniform ``[0, step]`` m (away from it for a negative ``step``; one
    draw for every moved arm; an arm stays where the move leaves the region or comes within
    :data:`MIN_BASE_DISTANCE` of the object's footprint); every arm seeded with its
    configuration found for the parent. The object's weight and the arm's own act on its
    shoulder over the horizontal distance to the grasp: a nearer base lowers the static
    torques, until the links meet the object; the distance also sets how far the arm is
    stretched (its manipulability). Moving every arm at once follows the trade-off between
    the two, which moving one arm (then another one sets the worst score) cannot.
    """
    rng = candidate_rng(problem.spec.search.seed, index)
    b = problem.spec.bases
    frac = rng.uniform(0.0, 1.0)
    arms = []
    for i, a in enumerate(parent.arms):
        base = a.base.copy()
        if (arm is None or i == arm) and b.fixed is None:
            d = problem.object_placement.act(a.points.mean(axis=0))[:2] - base[:2]
            n = float(np.linalg.norm(d))
            if n > 1e-9:
                moved = base.copy()
                moved[:2] += step * frac * d / n
                inside = np.all(moved[:3] >= b.lower) and np.all(moved[:3] <= b.upper)
                if inside and problem.footprint_distance(moved[:3]) >= MIN_BASE_DISTANCE:
                    base = moved
        arms.append(replace(a, base=base, q_seed=np.asarray(q0s[i], float).copy()))
    return Candidate(index, tuple(arms), parent.index)


def turn(problem, parent: Candidate, q0s: list[np.ndarray], index: int, arm: int,
         step: float) -> Candidate:
    """The same design with arm ``arm``'s weld turned about its face normal (its roll).

    By a uniform ``[-step, step]`` rad; every arm seeded with its configuration found for the
    parent (inverse kinematics turns arm ``arm``'s wrist after the tool). Bases, points and
    the postures up to the wrist stay, and so the manipulability; the static torques the
    force distribution asks of the arms can change. A fingertip arm (no roll) is unchanged.
    """
    rng = candidate_rng(problem.spec.search.seed, index)
    d = float(rng.uniform(-step, step))
    arms = []
    for i, a in enumerate(parent.arms):
        q = np.asarray(q0s[i], float).copy()
        roll = a.roll
        if i == arm and problem.spec.arms[i].gripper == "weld":
            roll = float(_wrap(a.roll + d))
        arms.append(replace(a, roll=roll, q_seed=q))
    return Candidate(index, tuple(arms), parent.index)


def slide(problem, parent: Candidate, q0s: list[np.ndarray], index: int, arm: int,
          step: float) -> Candidate:
    """The same design with arm ``arm``'s weld point moved on its face.

    By a step drawn uniformly in the face's plane within ``step`` m in each of its two axes,
    kept inside the face by the margin (:func:`project_to_face`); every arm seeded with its
    configuration found for the parent. Where an arm holds the object sets the levers of
    the object's weight about its joints. A fingertip arm (a rigid grip) is unchanged.
    """
    rng = candidate_rng(problem.spec.search.seed, index)
    d = rng.uniform(-step, step, 2)
    margin = problem.spec.search.face_margin
    arms = []
    for i, a in enumerate(parent.arms):
        points = a.points
        if i == arm and problem.spec.arms[i].gripper == "weld":
            _, F = problem.poly.face_frame(a.faces[0])
            points = project_to_face(problem.poly, a.faces[0], a.points[0] + F[:, :2] @ d,
                                     margin)[None]
        arms.append(replace(a, points=points, q_seed=np.asarray(q0s[i], float).copy()))
    return Candidate(index, tuple(arms), parent.index)


def arm_pool(problem, assessments) -> dict:
    """Per kind of arm, the arm choices of assessed candidates whose start pose was found.

    A kind is ``(robot, urdf, tool frame, gripper)``; each entry is the arm's
    :class:`ArmChoice` with its start configuration as IK seed. Arms of a candidate that failed
    the task on that arm (its ``solved`` entry None) are left out. The entries are in the
    order of the candidates' indices, then of the arms.
    """
    pool: dict = {}
    for e in sorted(assessments, key=lambda e: e.index):
        if not e.solved:
            continue
        for slot, a, q in zip(problem.spec.arms, e.candidate.arms, e.solved, strict=True):
            if q is not None:
                pool.setdefault(_kind(slot), []).append(replace(a, q_seed=np.asarray(q)))
    return pool


def _kind(slot) -> tuple:
    return (slot.robot, slot.urdf, slot.tool_frame, slot.gripper)


def recombine(problem, pool: dict, index: int) -> Candidate | None:
    """A candidate whose arms are drawn from :func:`arm_pool` (each arm reached its grasp).

    Welds take distinct faces, fingertip grippers distinct first faces, bases
    :data:`BASE_SPACING` apart; an arm's choice is drawn again (up to :data:`SAMPLING_TRIES`
    times) until it fits. None when the pool cannot furnish every arm.
    """
    rng = candidate_rng(problem.spec.search.seed, index)
    arms, faces = [], set()
    for slot in problem.spec.arms:
        entries = pool.get(_kind(slot), [])
        if not entries:
            return None
        choice = None
        for _ in range(SAMPLING_TRIES):
            c = entries[int(rng.integers(len(entries)))]
            if c.faces[0] in faces:
                continue
            if any(np.linalg.norm(c.base[:2] - a.base[:2]) < BASE_SPACING for a in arms):
                continue
            choice = c
            break
        if choice is None:
            return None
        faces.add(choice.faces[0])
        arms.append(choice)
    return Candidate(index, tuple(arms), -1)


__all__ = ["BRANCHES", "ArmChoice", "Candidate", "approach", "arm_pool", "branch_of",
           "candidate_rng", "face_edge_margin", "fingertip_faces", "n_branches", "perturb",
           "point_allowed", "project_to_face", "random_seed_configuration", "recombine", "reseed",
           "sample_base", "sample_candidate", "sample_face_point", "slide",
           "supported_rectangles", "turn", "weld_faces"]
