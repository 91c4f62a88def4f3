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
import yaml

from multiarm_pin.data import data_path

TWO_UR5_SPEC = data_path("scenarios", "designs", "two_ur5_box.yaml")
TWO_UR5_SCENARIO = data_path("scenarios", "two_ur5_box.yaml")


def spec_data(path=TWO_UR5_SPEC) -> dict:
    """A shipped spec's mapping (a deep copy to edit)."""
    return copy.deepcopy(yaml.safe_load(path.read_text(encoding="utf-8")))


def small(spec, candidates: int = 24, refine: int = 1):
    """The spec with a small search budget."""
    return dataclasses.replace(spec, search=dataclasses.replace(
        spec.search, candidates=candidates, refine=refine))


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
