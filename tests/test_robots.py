"""Tests of our own robot descriptions in ``robots/``.

The URDF's numbers are checked against sources that do not share code with the
generator: yourdfpy parses the file on its own, trimesh integrates mass properties of
triangulated primitives, and closed-form statics give the gravity torques.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import trimesh
import yourdfpy

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
MP6 = ROBOTS / "mp6" / "mp6.urdf"
MP6_4F = ROBOTS / "mp6" / "mp6_4f.urdf"
VARIANTS = {"mp6": MP6, "mp6_4f": MP6_4F}
LINKS_WITH_MASS = {"mp6": 11, "mp6_4f": 12}  # 8 arm/gripper links + one per fingertip
DENSITY = 2700.0
G = 9.81

JOINT_NAMES = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "forearm_roll_joint",
    "wrist_pitch_joint",
    "wrist_roll_joint",
]

# Stated in robots/README.md: frame origins in the base frame at q = 0 [m].
FRAMES_AT_ZERO = {
    "tool0": (0.95, 0.0, 0.26),
    "fingertip_1": (0.95, 0.0, 0.31),
    "fingertip_2": (0.95, -0.0433013, 0.235),
    "fingertip_3": (0.95, 0.0433013, 0.235),
}


# Stated in robots/README.md for mp6_4f: frame origins in the base frame at q = 0 [m].
FRAMES_AT_ZERO_4F = {
    "gripper_link": (0.865, 0.0, 0.26),
    "tool0": (0.9803109, 0.0, 0.26),
    "fingertip_1": (0.9673205, 0.0618718, 0.2110102),
    "fingertip_2": (0.9673205, -0.030052, 0.2110102),
    "fingertip_3": (0.95, 0.0371231, 0.2783712),
    "fingertip_4": (1.0366025, -0.0689429, 0.3396084),
}
# mp6_4f's corner layout (thesis Sec 2.2.3.1, robots/README.md) [m]
A, E, D, TIP_RADIUS = 0.05, 0.02, 0.15, 0.015


@pytest.fixture(scope="module")
def model() -> pin.Model:
    return pin.buildModelFromUrdf(str(MP6))


@pytest.fixture(scope="module")
def urdf() -> yourdfpy.URDF:
    return yourdfpy.URDF.load(str(MP6), build_scene_graph=True, load_meshes=False)


@pytest.fixture(scope="module")
def model_4f() -> pin.Model:
    return pin.buildModelFromUrdf(str(MP6_4F))


@pytest.fixture(scope="module")
def urdf_4f() -> yourdfpy.URDF:
    return yourdfpy.URDF.load(str(MP6_4F), build_scene_graph=True, load_meshes=False)


def _urdf_of(variant: str) -> yourdfpy.URDF:
    return yourdfpy.URDF.load(str(VARIANTS[variant]), build_scene_graph=True,
                              load_meshes=False)


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_committed_urdf_matches_generator(variant):
    path = ROBOTS / "mp6" / "generate_mp6.py"
    spec = importlib.util.spec_from_file_location("generate_mp6", path)
    gen = importlib.util.module_from_spec(spec)
    sys.modules["generate_mp6"] = gen  # dataclasses look their module up there
    try:
        spec.loader.exec_module(gen)
    finally:
        del sys.modules["generate_mp6"]
    assert set(gen.VARIANTS) == set(VARIANTS)
    assert VARIANTS[variant].read_text() == gen.urdf_text(variant), (
        "run robots/mp6/generate_mp6.py and commit")


def test_loads_in_pinocchio_with_six_revolute_joints(model):
    assert model.nq == 6 and model.nv == 6
    assert list(model.names)[1:] == JOINT_NAMES
    assert all(j.shortname().startswith("JointModelR") for j in list(model.joints)[1:])
    # Moving mass (Pinocchio leaves the fixed base out of computeTotalMass).
    moving = pin.computeTotalMass(model)
    assert 20.0 < moving < 30.0, moving
    assert model.inertias[0].mass == pytest.approx(DENSITY * np.pi * 0.08**2 * 0.10, rel=1e-9)


def test_loads_in_yourdfpy_with_six_actuated_joints(urdf):
    assert urdf.actuated_joint_names == JOINT_NAMES
    assert urdf.robot.name == "mp6"


def test_joint_limits_are_set_and_ordered(model, urdf):
    assert np.all(model.lowerPositionLimit < 0) and np.all(model.upperPositionLimit > 0)
    assert np.all(model.effortLimit > 0) and np.all(model.velocityLimit > 0)
    for name in JOINT_NAMES:
        lim = urdf.joint_map[name].limit
        assert lim is not None and lim.lower < lim.upper and lim.effort > 0 and lim.velocity > 0


def _primitive_mesh(geometry) -> trimesh.Trimesh:
    if geometry.cylinder is not None:
        return trimesh.creation.cylinder(
            radius=geometry.cylinder.radius, height=geometry.cylinder.length, sections=256
        )
    if geometry.box is not None:
        return trimesh.creation.box(extents=geometry.box.size)
    if geometry.sphere is not None:
        return trimesh.creation.icosphere(subdivisions=5, radius=geometry.sphere.radius)
    raise AssertionError(f"unexpected geometry {geometry}")


def _links_with_mass(urdf):
    return [link for link in urdf.robot.links if link.inertial is not None]


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_inertias_positive_definite_and_triangle_inequality(variant):
    urdf = _urdf_of(variant)
    links = _links_with_mass(urdf)
    assert len(links) == LINKS_WITH_MASS[variant]
    for link in links:
        inertia = link.inertial.inertia
        np.testing.assert_allclose(inertia, inertia.T, atol=1e-15)
        principal = np.linalg.eigvalsh(inertia)
        assert principal.min() > 0, link.name
        a, b, c = principal
        assert a + b >= c and a + c >= b and b + c >= a, link.name


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_mass_properties_agree_with_triangulated_collision_geometry(variant):
    """Every link's mass, COM and inertia equal trimesh integrals over its collision shapes.

    Overlapping primitives are each counted in full, as in the generator: concatenating
    closed meshes sums their volume integrals. Triangulation costs at most ~0.3 % here.
    """
    urdf = _urdf_of(variant)
    for link in _links_with_mass(urdf):
        meshes = []
        for col in link.collisions:
            mesh = _primitive_mesh(col.geometry)
            mesh.apply_transform(col.origin)
            meshes.append(mesh)
        mesh = trimesh.util.concatenate(meshes)
        mesh.density = DENSITY
        inertial = link.inertial
        com_ref = inertial.origin[:3, 3]
        assert np.allclose(inertial.origin[:3, :3], np.eye(3))
        assert mesh.mass == pytest.approx(inertial.mass, rel=3e-3), link.name
        np.testing.assert_allclose(mesh.center_mass, com_ref, atol=2e-4, err_msg=link.name)
        scale = np.trace(inertial.inertia)
        np.testing.assert_allclose(
            mesh.moment_inertia, inertial.inertia, atol=5e-3 * scale, err_msg=link.name
        )
        # Visual and collision geometry are the same primitives.
        assert len(link.visuals) == len(link.collisions)


def test_frames_at_zero_configuration(model, urdf):
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.zeros(6))
    for name, expected in FRAMES_AT_ZERO.items():
        assert model.existFrame(name), name
        oMf = data.oMf[model.getFrameId(name)]
        np.testing.assert_allclose(oMf.translation, expected, atol=1e-6, err_msg=name)
        T = urdf.get_transform(name, "base_link")  # independent forward kinematics
        np.testing.assert_allclose(T[:3, 3], expected, atol=1e-6, err_msg=name)
    # tool0's z axis is the approach direction: along the stretched arm (+x) at q = 0.
    R_tool = data.oMf[model.getFrameId("tool0")].rotation
    np.testing.assert_allclose(R_tool[:, 2], [1, 0, 0], atol=1e-8)
    # tool0 is the centroid of the fingertip centres.
    tips = np.array([FRAMES_AT_ZERO[f"fingertip_{k}"] for k in (1, 2, 3)])
    np.testing.assert_allclose(tips.mean(axis=0), FRAMES_AT_ZERO["tool0"], atol=1e-6)


def test_fingertips_are_spheres_centred_on_their_frames(urdf):
    for k in (1, 2, 3):
        link = urdf.link_map[f"fingertip_{k}"]
        (col,) = link.collisions
        assert col.geometry.sphere is not None
        assert col.geometry.sphere.radius == pytest.approx(0.015)
        np.testing.assert_allclose(col.origin, np.eye(4), atol=1e-12)


def test_reach_is_about_095_m(model):
    """Distance from the shoulder-lift axis to tool0: 0.95 m stretched out, never more."""
    data = model.createData()
    rng = np.random.default_rng(0)
    shoulder = np.array([0.0, 0.0, 0.26])
    dists = []
    for q in [np.zeros(6), *rng.uniform(model.lowerPositionLimit, model.upperPositionLimit,
                                        (200, 6))]:
        pin.framesForwardKinematics(model, data, q)
        dists.append(np.linalg.norm(data.oMf[model.getFrameId("tool0")].translation - shoulder))
    assert dists[0] == pytest.approx(0.95, abs=1e-9)
    assert max(dists) <= 0.95 + 1e-9


def test_gravity_torque_stretched_out_matches_statics(model, urdf):
    """At q = 0 the arm is horizontal along +x: compare g(q) with the weights' moments.

    Pinocchio's g(q) = dV/dq is the torque that balances gravity, i.e. minus the moment
    of the distal links' weights about the joint axis, computed here from yourdfpy's link
    poses and the URDF masses.
    """
    data = model.createData()
    tau_g = pin.computeGeneralizedGravity(model, data, np.zeros(6))
    y = np.array([0.0, 1.0, 0.0])

    def gravity_torque_about(joint: str, axis: np.ndarray, distal_from: int) -> float:
        origin = urdf.get_transform(urdf.joint_map[joint].child, "base_link")[:3, 3]
        total = 0.0
        for link in _links_with_mass(urdf)[distal_from:]:
            com = (urdf.get_transform(link.name, "base_link") @ link.inertial.origin)[:3, 3]
            total += np.cross(com - origin, [0.0, 0.0, -link.inertial.mass * G]) @ axis
        return -total  # g(q) is the torque that balances gravity's moment

    # links are listed base, shoulder, upper arm, forearm, ... in the URDF
    assert tau_g[1] == pytest.approx(gravity_torque_about("shoulder_lift_joint", y, 2), rel=1e-6)
    assert tau_g[2] == pytest.approx(gravity_torque_about("elbow_joint", y, 3), rel=1e-6)
    # Realistic magnitude for a ~27 kg arm with 0.95 m reach, within the effort limits.
    assert 60.0 < abs(tau_g[1]) < 120.0, tau_g
    assert np.all(np.abs(tau_g) < model.effortLimit)
    # Joints whose axis is vertical or along the arm feel no gravity torque here.
    np.testing.assert_allclose(tau_g[[0, 3, 5]], 0.0, atol=1e-9)


# ------------------------------------------------------------------ mp6_4f (four fingers)
def test_4f_is_the_same_arm_with_four_fingertips(model, model_4f, urdf_4f):
    assert model_4f.nq == 6 and model_4f.nv == 6
    assert list(model_4f.names)[1:] == JOINT_NAMES
    assert urdf_4f.actuated_joint_names == JOINT_NAMES and urdf_4f.robot.name == "mp6_4f"
    for attr in ("lowerPositionLimit", "upperPositionLimit", "effortLimit", "velocityLimit"):
        np.testing.assert_array_equal(getattr(model_4f, attr), getattr(model, attr))
    # same kinematics and arm links; Pinocchio merges the fixed gripper into joint 6's body,
    # so only that body's inertia differs
    for j in range(1, 7):
        assert model_4f.jointPlacements[j].isApprox(model.jointPlacements[j])
        same = np.allclose(model_4f.inertias[j].toDynamicParameters(),
                           model.inertias[j].toDynamicParameters(), atol=1e-12)
        assert same == (j < 6), j
    assert 20.0 < pin.computeTotalMass(model_4f) < 30.0
    for k in (1, 2, 3, 4):
        link = urdf_4f.link_map[f"fingertip_{k}"]
        (col,) = link.collisions
        assert col.geometry.sphere.radius == pytest.approx(TIP_RADIUS)
        np.testing.assert_allclose(col.origin, np.eye(4), atol=1e-12)
    assert not model_4f.existFrame("fingertip_5")


def test_4f_frames_at_zero_configuration(model_4f, urdf_4f):
    data = model_4f.createData()
    pin.framesForwardKinematics(model_4f, data, np.zeros(6))
    for name, expected in FRAMES_AT_ZERO_4F.items():
        oMf = data.oMf[model_4f.getFrameId(name)]
        np.testing.assert_allclose(oMf.translation, expected, atol=1e-6, err_msg=name)
        T = urdf_4f.get_transform(name, "base_link")
        np.testing.assert_allclose(T[:3, 3], expected, atol=1e-6, err_msg=name)
    tool = data.oMf[model_4f.getFrameId("tool0")]
    np.testing.assert_allclose(tool.rotation[:, 2], [1, 0, 0], atol=1e-9)  # approach
    tips = np.array([data.oMf[model_4f.getFrameId(f"fingertip_{k}")].translation
                     for k in (1, 2, 3, 4)])
    np.testing.assert_allclose(tips.mean(axis=0), tool.translation, atol=1e-12)


def _design_tip_centres() -> np.ndarray:
    """(4, 3) tip centres in the box-corner frame (box in the negative octant), Example 2.1.

    Contacts p1 (+x), p2 (+y), p3 (+z) around the corner and the seventh p7 (+z) D further
    along -x; each sphere centre is one radius out along the face's outward normal.
    """
    points = np.array([[0, -A, -A], [-A, 0, -A], [-E, -A, 0], [-E - D, -A, 0]], float)
    return points + TIP_RADIUS * np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 1]])


def _fit_rigid(src: np.ndarray, dst: np.ndarray):
    """Kabsch: rotation R and translation p minimising |R src_k + p - dst_k|."""
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    U, _, Vt = np.linalg.svd((src - cs).T @ (dst - cd))
    S = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ S @ U.T
    return R, cd - R @ cs


def _design_pose_of_tool(model_4f):
    """Tool0 placement in the corner frame that puts the tips on the design points."""
    data = model_4f.createData()
    q = np.random.default_rng(3).uniform(-1, 1, 6)  # any q: the tips are rigid in tool0
    pin.framesForwardKinematics(model_4f, data, q)
    tool = data.oMf[model_4f.getFrameId("tool0")]
    tips_tool = np.array([tool.actInv(data.oMf[model_4f.getFrameId(f"fingertip_{k}")]
                                      .translation) for k in (1, 2, 3, 4)])
    R, p = _fit_rigid(tips_tool, _design_tip_centres())
    return R, p, tips_tool


def test_4f_tips_are_congruent_to_the_thesis_corner_layout(model_4f):
    """A rigid motion maps the four tip centres onto Example 2.1's layout exactly."""
    R, p, tips_tool = _design_pose_of_tool(model_4f)
    np.testing.assert_allclose(tips_tool @ R.T + p, _design_tip_centres(), atol=1e-9)
    assert np.linalg.det(R) == pytest.approx(1.0)  # not a mirror image
    # the gripper approaches along the corner's diagonal, into the box
    np.testing.assert_allclose(R[:, 2], -np.ones(3) / np.sqrt(3), atol=1e-9)
    # D exceeds the thesis minimum D_x = 2 (A - E) with A > E
    assert A > E and D > 2 * (A - E)


def test_4f_gripper_does_not_penetrate_the_box_at_the_design_pose(model_4f, urdf_4f):
    """Palm, fingers and tips stay outside the corner's octant (a box of any larger size).

    For each collision primitive (triangulated), a linear programme looks for a convex
    combination of its vertices inside ``{x, y, z <= -depth}``; only the fingertip spheres
    may reach the faces (they touch them), none may go deeper than the mesh error.
    """
    from scipy.optimize import linprog

    R_ct, p_ct, _ = _design_pose_of_tool(model_4f)
    tool_in_corner = np.eye(4)
    tool_in_corner[:3, :3], tool_in_corner[:3, 3] = R_ct, p_ct
    tool_in_base = urdf_4f.get_transform("tool0", "base_link")
    base_in_corner = tool_in_corner @ np.linalg.inv(tool_in_base)

    def penetrates(vertices: np.ndarray, depth: float) -> bool:
        n = len(vertices)
        res = linprog(np.zeros(n), A_ub=vertices.T, b_ub=np.full(3, -depth),
                      A_eq=np.ones((1, n)), b_eq=[1.0], bounds=(0, None), method="highs")
        return res.status == 0

    checked = 0
    for name in ["gripper_link", "fingertip_1", "fingertip_2", "fingertip_3", "fingertip_4"]:
        link_in_corner = base_in_corner @ urdf_4f.get_transform(name, "base_link")
        for col in urdf_4f.link_map[name].collisions:
            mesh = _primitive_mesh(col.geometry)
            mesh.apply_transform(link_in_corner @ col.origin)
            depth = 1e-4 if name.startswith("fingertip") else 1e-9
            assert not penetrates(mesh.vertices, depth), name
            checked += 1
    assert checked == 1 + 4 + 4  # palm, 4 fingers, 4 spheres
    # and the spheres do reach their faces: the lowest point along each face normal
    centres = _design_tip_centres()
    normals = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 1]])
    np.testing.assert_allclose(np.einsum("ij,ij->i", centres, normals) - TIP_RADIUS, 0,
                               atol=1e-12)


def test_4f_gravity_torque_stretched_out_matches_statics(model_4f, urdf_4f):
    """Shoulder and elbow gravity torques at q = 0 from the URDF masses (yourdfpy poses)."""
    data = model_4f.createData()
    tau_g = pin.computeGeneralizedGravity(model_4f, data, np.zeros(6))
    y = np.array([0.0, 1.0, 0.0])
    links = _links_with_mass(urdf_4f)
    for joint, index, first in (("shoulder_lift_joint", 1, 2), ("elbow_joint", 2, 3)):
        origin = urdf_4f.get_transform(urdf_4f.joint_map[joint].child, "base_link")[:3, 3]
        moment = sum(
            np.cross((urdf_4f.get_transform(lk.name, "base_link") @ lk.inertial.origin)[:3, 3]
                     - origin, [0.0, 0.0, -lk.inertial.mass * G]) @ y
            for lk in links[first:]
        )
        assert tau_g[index] == pytest.approx(-moment, rel=1e-6), joint
    assert tau_g[0] == pytest.approx(0.0, abs=1e-9)  # vertical axis
    assert np.all(np.abs(tau_g) < model_4f.effortLimit)


# ----------------------------------------------------------------------------- registry
# multiarm_pin.model.robots: every robot that available_robots() lists is walked.
def _registry():
    from multiarm_pin.model.arm import available_robots

    return available_robots()


def _mid_configuration(arm):
    """A configuration inside the limits, off the zero pose (no aligned-axes singularity)."""
    from multiarm_pin.feasibility.limits import one_dof_limits

    lo, hi, _ = one_dof_limits(arm.model)
    q = pin.integrate(arm.model, arm.neutral(), 0.3 * np.ones(arm.nv))
    bounded = np.isfinite(lo) & np.isfinite(hi)
    q[bounded] = (lo[bounded] + hi[bounded]) / 2 + 0.2 * (hi[bounded] - lo[bounded]) / 2
    return q


@pytest.mark.parametrize("robot", _registry())
def test_registry_robot_loads_with_its_hand_or_flange_and_runs_a_weld(robot, tmp_path):
    import multiarm_pin.model.robots as robots
    from multiarm_pin.app.runner import run_scenario
    from multiarm_pin.app.scenario import parse_scenario
    from multiarm_pin.model.arm import Arm

    entry = robots.ROBOTS[robot]
    arm = Arm.from_robot_name(robot, load_visuals=False)
    assert arm.tool_frame == entry.tool_frame and entry.tool_kind in ("flange", "hand")
    assert f"``{entry.tool_frame}``" in robots.__doc__  # documented in the registry's table
    assert "finger" not in entry.tool_frame and "tip" not in entry.tool_frame
    # at the end effector: attached to the last joint left after locking the gripper, with
    # no joint below it (a fingertip would sit below a finger joint or beside the hand)
    tool = arm.model.frames[arm.tool_frame_id]
    assert tool.parentJoint == arm.model.njoints - 1
    assert arm.model.nv == {"panda": 7, "panda_collision": 7, "xarm7": 7}.get(robot, 6)
    q0 = _mid_configuration(arm)
    tool = arm.tool_placement(q0)
    # the box 5 cm beyond the flange along the tool's z axis, its axes the tool's (a weld
    # needs no touch: nothing of the arm inside it); no floor: this mid-range pose is not a
    # stance
    centre = tool.translation + (0.05 + 0.05) * tool.rotation[:, 2]
    quat = pin.Quaternion(tool.rotation).coeffs()  # [x, y, z, w]
    data = {
        "name": f"weld_{robot}",
        "object": {"shape": {"type": "box", "size": [0.1, 0.1, 0.1]}, "mass": 1.0,
                   "pose": {"position": [float(x) for x in centre],
                            "quaternion": [float(x) for x in quat]}},
        "arms": [{"name": "a", "robot": robot, "q0": [float(x) for x in q0],
                  "joint": {"type": "weld"}}],
        "controller": {"type": "gravity_compensation"},
        "simulation": {"duration": 0.006, "dt": 0.002},
        "ground": None,
    }
    sc = parse_scenario(data, str(tmp_path / "s.yaml"))
    res = run_scenario(sc, tmp_path / "out", html=False, plots=False)
    s = res.summary
    assert s["status"] == "complete" and s["finite"] and s["steps"] == 3
    assert s["arms"][0]["tool_frame"] == entry.tool_frame
    assert s["max_constraint_violation"] < 1e-6


@pytest.mark.parametrize("robot", _registry())
def test_locked_joints_work_for_every_robot(robot, tmp_path):
    from multiarm_pin.app.scenario import build_arm, parse_scenario
    from multiarm_pin.exceptions import ScenarioError
    from multiarm_pin.model.arm import Arm

    full = Arm.from_robot_name(robot, load_visuals=False)
    first = full.model.names[1]
    locked = Arm.from_robot_name(robot, locked_joints=(first,), load_visuals=False)
    assert locked.nv == full.nv - 1 and not locked.model.existJointName(first)
    assert locked.tool_frame == full.tool_frame

    def spec(joints):
        data = {"object": {"shape": {"type": "box", "size": [0.2, 0.2, 0.2]}, "mass": 1.0},
                "arms": [{"robot": robot, "q0": [0.0], "locked_joints": joints,
                          "joint": {"type": "weld"}}]}
        sc = parse_scenario(data, str(tmp_path / "s.yaml"))
        return sc, sc.arms[0]

    sc, a = spec([first])
    assert build_arm(sc, a, load_visuals=False).nv == full.nv - 1  # used, not ignored
    sc, a = spec(["no_such_joint"])
    with pytest.raises(ScenarioError, match=r"arms\[0\].locked_joints: joints \['no_such_joint'\]"
                       r" not found"):
        build_arm(sc, a, load_visuals=False)
