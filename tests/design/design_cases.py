"""Shared helpers of the design tests: small-budget specs and independent re-checks.

The re-checks use only Pinocchio and coal calls made here (forward kinematics, ``rnea``,
frame Jacobians, ``coal.distance``), not the designer's own checks.
"""

from __future__ import annotations

import copy
import dataclasses

import coal
import numpy as np
import pinocchio as pin
import pytest
import yaml
from scipy.spatial import ConvexHull

from multiarm_pin.data import data_path

TWO_UR5_SPEC = data_path("scenarios", "designs", "two_ur5_box.yaml")
TWO_UR5_SCENARIO = data_path("scenarios", "two_ur5_box.yaml")

UR5_TIPS = [[0.053, -0.031, 0.16], [-0.053, -0.031, 0.16], [0.0, 0.061, 0.16],
            [-0.071, 0.078, 0.184]]
"""A four-fingertip corner gripper on a UR5's ``tool0`` (tip centres in the tool frame [m]):
three tips 0.16 m ahead of the flange touch the three faces around a box corner (the tool's
z axis along the corner's diagonal), the fourth a second point of one of them."""


def ur5_tips_spec_data() -> dict:
    """A design spec: two UR5s with :data:`UR5_TIPS` grippers lift a 2 kg box by 0.1 m."""
    return {
        "name": "ur5_tips",
        "object": {"shape": {"type": "box", "size": [0.5, 0.4, 0.3]}, "mass": 2.0,
                   "pose": {"position": [0.0, 0.0, 0.45]}},
        "task": {"lift": 0.1, "duration": 1.0},
        "arms": [{"robot": "ur5", "count": 2,
                  "gripper": {"fingertips": UR5_TIPS, "tip_radius": 0.015}}],
        "bases": {"region": {"x": [-0.9, 0.9], "y": [-0.9, 0.9], "z": 0.0}, "yaw": "free"},
        "search": {"candidates": 12, "refine": 0, "polish": 1, "seed": 0, "clearance": 0.01,
                   "face_margin": 0.015},
        "top": 2,
        "simulation": {"duration": 1.2, "dt": 0.002},
    }


def spec_data(path=TWO_UR5_SPEC) -> dict:
    """A shipped spec's mapping (a deep copy to edit)."""
    return copy.deepcopy(yaml.safe_load(path.read_text(encoding="utf-8")))


def small(spec, candidates: int = 24, refine: int = 1, polish: int = 1):
    """The spec with a small search budget."""
    return dataclasses.replace(spec, search=dataclasses.replace(
        spec.search, candidates=candidates, refine=refine, polish=polish))


def tool_pose_errors(system, q: np.ndarray, oMo: pin.SE3, tools_in_object) -> np.ndarray:
    """Per arm, the position [m] and angle [rad] between its tool and its grasp placement."""
    out = []
    for i, arm in enumerate(system.arms):
        qi = q[system.arm_set.q_slices[i]]
        pin.framesForwardKinematics(arm.model, arm.data, qi)
        oMt = arm.data.oMf[arm.tool_frame_id]
        target = oMo * tools_in_object[i]
        out.append((np.linalg.norm(oMt.translation - target.translation),
                    np.linalg.norm(pin.log3(target.rotation.T @ oMt.rotation))))
    return np.array(out)


def coal_clearance(scene, q_scene: np.ndarray) -> float:
    """Smallest ``coal.distance`` [m] over the scene's non-grasp pairs at a configuration.

    The placements come from Pinocchio's forward kinematics of the scene's model; each pair
    is measured by a direct ``coal.distance`` call on its two (hull) geometries.
    """
    data = scene.model.createData()
    gdata = pin.GeometryData(scene.hull)
    pin.updateGeometryPlacements(scene.model, data, scene.hull, gdata, q_scene)
    best = np.inf
    for k, (a, b) in enumerate(scene.pairs.tolist()):
        if scene.grasp_pair[k]:
            continue
        req, res = coal.DistanceRequest(), coal.DistanceResult()
        req.gjk_tolerance = 1e-11
        d = coal.distance(scene.hull.geometryObjects[a].geometry, gdata.oMg[a],
                          scene.hull.geometryObjects[b].geometry, gdata.oMg[b], req, res)
        best = min(best, float(d))
    return best


def rnea_static_torques(system, state) -> np.ndarray:
    """(nv,) joint torques holding a state still: ``rnea(q, 0, 0) + Jᵀ w`` per arm.

    ``w`` is the wrench each arm applies on the object, ``W_o μ`` at the object's COM (world
    axes) with ``μ`` the force distribution's multipliers (margin 0), moved to the tool
    frame's origin; ``J`` the tool frame's Jacobian in world-aligned axes there.
    """
    from multiarm_pin.dynamics.force_distribution import distribute_forces

    b = system.blocks(state).blocks
    mu = distribute_forces(b, -np.asarray(b.h_o, float), system.unilateral).mu
    c = np.asarray(state.obj.position, float)
    taus = []
    for i, arm in enumerate(system.arms):
        qi = np.asarray(state.q)[system.arm_set.q_slices[i]]
        w_com = b.W_o[i] @ mu[i]  # the wrench the arm applies on the object, at the COM
        pin.framesForwardKinematics(arm.model, arm.data, qi)
        p = arm.data.oMf[arm.tool_frame_id].translation
        f = w_com[:3]
        m_p = w_com[3:] + np.cross(c - p, f)
        J = pin.computeFrameJacobian(arm.model, arm.data, qi, arm.tool_frame_id,
                                     pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        g = pin.rnea(arm.model, arm.data, qi, np.zeros(arm.nv), np.zeros(arm.nv))
        taus.append(g + J.T @ np.concatenate([f, m_p]))
    return np.concatenate(taus), mu, b


def tip_centre(arm, q: np.ndarray, contact) -> np.ndarray:
    """(3,) a fingertip's centre in the world [m] by Pinocchio's forward kinematics: its frame,
    or its point in the tool frame (``contact.tip_in_tool``)."""
    pin.framesForwardKinematics(arm.model, arm.data, q)
    if contact.tip_in_tool is None:
        return arm.data.oMf[arm.model.getFrameId(contact.tip)].translation.copy()
    return arm.data.oMf[arm.tool_frame_id].act(np.asarray(contact.tip_in_tool, float))


def recheck_fingertip_design(spec, problem, design) -> None:
    """Re-check a fingertip design by independent means (asserts).

    Closure of the contacts its scenario states by the LP and by a qhull ε of our own (equal
    to its Ferrari-Canny score); every tip on its face along the task (forward kinematics,
    below 1e-6 m); joint limits; ``coal.distance`` at least the clearance margin; static
    torques by ``rnea + Jᵀ w`` equal to the designer's, within the efforts, every fingertip
    pushing.
    """
    from multiarm_pin.app.precheck import static_torques
    from multiarm_pin.app.scenario import build_scenario
    from multiarm_pin.app.scenario.schema import parse_scenario
    from multiarm_pin.feasibility import CollisionScene
    from multiarm_pin.grasp.form_closure import form_closure

    L = float(np.max(np.linalg.norm(problem.poly.vertices, axis=1)))
    built = build_scenario(parse_scenario(design.scenario, spec.file), load_visuals=False)
    system = built.system
    pts, normals = [], []
    for a in built.scenario.arms:
        for c in a.joint.contacts:
            f = problem.poly.face_index(c.face)
            assert abs(problem.poly.signed_distance_to_face(c.point, f)) < 1e-9
            pts.append(c.point)
            normals.append(-problem.poly.normals[f])
    W = np.array([np.concatenate([n, np.cross(p, n) / L])
                  for p, n in zip(pts, normals, strict=True)]).T
    assert form_closure(W).form_closure
    hull = ConvexHull(W.T)
    assert np.all(hull.equations[:, -1] < 0)  # the origin strictly inside the hull
    eps = float(-hull.equations[:, -1].max())
    # the designer measured the tips where they touch; the file rounds them to 1e-10 m
    assert design.scores["ferrari_canny"] == pytest.approx(eps, rel=1e-6)
    scene = CollisionScene(system, built.initial_state, 0.0)
    oMo0 = problem.object_placement
    tips_obj = []
    for i, arm in enumerate(system.arms):
        q0 = built.initial_state.q[system.arm_set.q_slices[i]]
        tips_obj.append([oMo0.actInv(tip_centre(arm, q0, c))
                         for c in built.scenario.arms[i].joint.contacts])
    for k, (M, q) in enumerate(zip(problem.path_placements, design.assessment.path_q,
                                   strict=True)):
        for i, arm in enumerate(system.arms):
            qi = q[system.arm_set.q_slices[i]]
            for c, t in zip(built.scenario.arms[i].joint.contacts, tips_obj[i], strict=True):
                err = np.linalg.norm(tip_centre(arm, qi, c) - M.act(t))
                assert err < 1e-6, (design.rank, k, c.tip, err)
            assert np.all(qi >= arm.model.lowerPositionLimit - 1e-12)
            assert np.all(qi <= arm.model.upperPositionLimit + 1e-12)
        q_scene = np.concatenate([q, M.translation, pin.Quaternion(M.rotation).coeffs()])
        assert coal_clearance(scene, q_scene) >= spec.search.clearance - 1e-9
        st = system.state(q, None, M.translation, pin.Quaternion(M.rotation).coeffs())
        tau, mu, b = rnea_static_torques(system, st)
        np.testing.assert_allclose(tau, static_torques(system, st)[0], atol=1e-8)
        assert np.all(mu[system.unilateral] >= -1e-9)  # every fingertip pushes
        effort = np.concatenate([a.model.effortLimit for a in system.arms])
        assert np.all(np.abs(tau) <= effort)
