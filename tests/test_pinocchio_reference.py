"""Weld grasps: our accelerations equal Pinocchio's own pin.constraintDynamics on the same
system built as ONE Pinocchio model (free-flyer object first, then the arms, CONTACT_6D)."""

import numpy as np
import pinocchio as pin
import pytest
from system_builders import build_system, moving_state


def pinocchio_closed_chain(system):
    """The object as a free-flyer joint (frame at the COM), then every arm appended."""
    obj = system.obj
    ff = pin.Model()
    jid = ff.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "object")
    ff.appendBodyToJoint(jid, pin.Inertia(obj.mass, np.zeros(3), obj.inertia), pin.SE3.Identity())
    model = pin.appendModel(ff, system.arm_set.model, 0, pin.SE3.Identity())
    model.gravity = pin.Motion(system.gravity, np.zeros(3))
    return model, model.getJointId("object")


def constraint_dynamics(system, state, tau):
    """(a_o [ẍ; ω̇] world, qdd (nv,), per-arm contact wrench on the object at the COM, world)."""
    model, obj_jid = pinocchio_closed_chain(system)
    data = model.createData()
    o = state.obj
    R = o.rotation
    q = np.concatenate([o.position, o.quaternion, state.q])
    # free-flyer velocity is LOCAL (body axes at the joint = COM): [Rᵀ ẋ; Rᵀ ω]
    v_l, w_l = R.T @ o.twist[:3], R.T @ o.twist[3:]
    v = np.concatenate([v_l, w_l, state.v])
    pin.framesForwardKinematics(model, data, q)
    oMobj = pin.SE3(R, o.position)
    cms = pin.StdVec_RigidConstraintModel()
    tools = []
    for arm in system.arms:
        fid = model.getFrameId(f"{arm.name}/{arm.model.frames[arm.tool_frame_id].name}")
        frame = model.frames[fid]
        oMtool = data.oMf[fid]
        tools.append(pin.SE3(oMtool))
        cms.append(pin.RigidConstraintModel(
            pin.ContactType.CONTACT_6D, model, frame.parentJoint, frame.placement,
            obj_jid, oMobj.actInv(oMtool), pin.ReferenceFrame.LOCAL))
    cds = pin.StdVec_RigidConstraintData()
    for cm in cms:
        cds.append(cm.createData())
    pin.initConstraintDynamics(model, data, cms, cds)
    a = pin.constraintDynamics(model, data, q, v, np.concatenate([np.zeros(6), tau]), cms, cds,
                               pin.ProximalSettings(1e-12, 0.0, 1))
    # spatial (body) acceleration -> classical acceleration of the COM in world axes
    a_o = np.concatenate([R @ (a[:3] + np.cross(w_l, v_l)), R @ a[3:6]])
    lam = data.lambda_c.reshape(len(system.arms), 6)
    wrenches = []
    for oMtool, lk in zip(tools, lam, strict=True):
        f = oMtool.rotation @ lk[:3]
        m = oMtool.rotation @ lk[3:] + np.cross(oMtool.translation - o.position, f)
        wrenches.append(np.concatenate([f, m]))
    return a_o, a[6:], np.array(wrenches)


@pytest.mark.parametrize("robots", [("ur5", "panda"), ("ur5", "panda", "ur5")])
@pytest.mark.parametrize("seed", [1, 2])
def test_weld_grasps_match_pinocchio_constraint_dynamics(robots, seed):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=4)
    system, state = build_system(list(robots), ["weld"] * len(robots), rng,
                                 gravity=(0.5, -0.3, -9.81),
                                 object_quaternion=q / np.linalg.norm(q))
    state = moving_state(system, state, rng, speed=1.5)
    tau = 10 * rng.normal(size=system.nv)
    a_ref, qdd_ref, wrench_ref = constraint_dynamics(system, state, tau)
    for solver in ("auto", "dense_kkt"):
        sol, ev = system.forward_dynamics(state, tau, solver=solver)
        scale = max(1.0, np.abs(a_ref).max(), np.abs(qdd_ref).max())
        assert np.abs(sol.a_o - a_ref).max() < 1e-8 * scale
        assert np.abs(system.unpad(sol.qdd) - qdd_ref).max() < 1e-8 * scale
        # per-arm contact wrench on the object: ours W_o,i μ_i; Pinocchio's λ_i is the force
        # on the arm side (joint1) in the tool frame, i.e. minus the wrench on the object
        ours = np.einsum("nik,nk->ni", ev.blocks.W_o, sol.mu)
        assert np.abs(ours + wrench_ref).max() < 1e-7 * max(1.0, np.abs(wrench_ref).max())
    # the comparison is not vacuous: the motion is far from trivial
    assert np.abs(a_ref).max() > 0.5 and np.abs(qdd_ref).max() > 1.0
