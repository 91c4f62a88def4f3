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


@pytest.fixture(scope="module")
def model() -> pin.Model:
    return pin.buildModelFromUrdf(str(MP6))


@pytest.fixture(scope="module")
def urdf() -> yourdfpy.URDF:
    return yourdfpy.URDF.load(str(MP6), build_scene_graph=True, load_meshes=False)


def test_committed_urdf_matches_generator():
    path = ROBOTS / "mp6" / "generate_mp6.py"
    spec = importlib.util.spec_from_file_location("generate_mp6", path)
    gen = importlib.util.module_from_spec(spec)
    sys.modules["generate_mp6"] = gen  # dataclasses look their module up there
    try:
        spec.loader.exec_module(gen)
    finally:
        del sys.modules["generate_mp6"]
    assert MP6.read_text() == gen.urdf_text(), "run robots/mp6/generate_mp6.py and commit"


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


def test_inertias_positive_definite_and_triangle_inequality(urdf):
    links = _links_with_mass(urdf)
    assert len(links) == 11
    for link in links:
        inertia = link.inertial.inertia
        np.testing.assert_allclose(inertia, inertia.T, atol=1e-15)
        principal = np.linalg.eigvalsh(inertia)
        assert principal.min() > 0, link.name
        a, b, c = principal
        assert a + b >= c and a + c >= b and b + c >= a, link.name


def test_mass_properties_agree_with_triangulated_collision_geometry(urdf):
    """Every link's mass, COM and inertia equal trimesh integrals over its collision shapes.

    Overlapping primitives are each counted in full, as in the generator: concatenating
    closed meshes sums their volume integrals. Triangulation costs at most ~0.3 % here.
    """
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
