"""The compiled rigid-body pass (:mod:`multiarm_pin._compiled.rigid_body`) and its tables.

Against Pinocchio (the reference, to 1e-12 of each quantity's magnitude) on every registry
robot with a placed base, the MP6, combined models of 1-6 mixed arms and a hand-built model of
every supported joint type; then against mechanics of its own outputs, not Pinocchio's: the
kinetic energy of the bodies (their COM frames' motion by finite differences) is ``½ vᵀ M v``,
Lagrange's equations give ``C v`` and the gravity torques, ``J`` is the derivative of the
frames' placements and ``dJ`` that of ``J``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from rigid_body_models import com_frames, every_joint_model, pinocchio_pass, random_state

from multiarm_pin._compiled import layout
from multiarm_pin._compiled.rigid_body import difference, integrate, rigid_body_pass
from multiarm_pin.exceptions import MultiArmError, UnsupportedJointError
from multiarm_pin.model.arm import Arm, load_arm
from multiarm_pin.model.arm_set import ArmSet
from multiarm_pin.model.compiled_model import (
    SUPPORTED_JOINTS,
    CompiledModel,
    is_supported,
    unsupported_joints,
)
from multiarm_pin.model.robots import ROBOTS

TOL = 1e-12
"""Agreement with Pinocchio, relative to the largest entry of each quantity."""
MP6 = Path(__file__).resolve().parents[2] / "robots" / "mp6" / "mp6.urdf"
MIXED = ("ur5", "panda", "mp6", "kinova", "ur3", "z1")
"""Arms of the combined models, in order (continuous joints: the Kinova's)."""
NAMES = ("J", "dJ", "M", "nle", "H")


def _arm(robot: str, name: str, k: int) -> Arm:
    """``robot`` with a tilted, shifted base (the k-th of a circle)."""
    angle = 2 * np.pi * k / 6
    base = pin.SE3(pin.rpy.rpyToMatrix(0.2, -0.1, angle + 0.3),
                   np.array([0.9 * np.cos(angle), 0.9 * np.sin(angle), 0.1 * k]))
    if robot == "mp6":
        return load_arm(urdf=MP6, name=name, base=base, tool_frame="tool0", load_visuals=False)
    return load_arm(robot, name=name, base=base, load_visuals=False)


def _run(cm: CompiledModel, q, v, M=None):
    """The compiled pass's ``(J, dJ, M, nle, H)`` at ``(q, v)`` (``M`` prefilled if given)."""
    out = cm.outputs()
    if M is not None:
        out = out[:2] + (M,) + out[3:]
    rigid_body_pass(cm.ints, cm.floats, q, v, *out)
    return out[:5]


def _assert_close(out, ref, tol=TOL):
    for name, a, b in zip(NAMES, out, ref, strict=True):
        scale = max(np.abs(b).max(), 1e-300)
        err = np.abs(a - b).max()
        assert err <= tol * scale, f"{name}: error {err:.3g} of magnitude {scale:.3g}"


def _check_against_pinocchio(model, tools, rng, states=3):
    cm = CompiledModel.build(model, tools)
    for _ in range(states):
        q, v = random_state(model, rng)
        _assert_close(_run(cm, q, v), pinocchio_pass(model, q, v, tools))


# ----------------------------------------------------------------------------- vs Pinocchio
@pytest.mark.parametrize("robot", sorted(ROBOTS) + ["mp6"])
def test_every_robot_with_a_placed_base_matches_pinocchio(robot, rng):
    arm = _arm(robot, robot, 1)
    assert is_supported(arm.model)
    _check_against_pinocchio(arm.model, [arm.tool_frame_id], rng)


def test_every_supported_joint_type_matches_pinocchio(rng):
    model, tools = every_joint_model(rng)
    kinds = {model.joints[j].shortname() for j in range(1, model.njoints)}
    assert kinds == set(SUPPORTED_JOINTS)
    _check_against_pinocchio(model, tools, rng, states=5)
    # at rest (gravity alone) and fast (10 rad/s)
    cm = CompiledModel.build(model, tools)
    q, v = random_state(model, rng, speed=10.0)
    for vv in (np.zeros(model.nv), v):
        _assert_close(_run(cm, q, vv), pinocchio_pass(model, q, vv, tools))


@pytest.mark.parametrize("n", [1, 2, 3, 6])
def test_arm_set_compiled_pass_equals_the_pinocchio_pass(n, rng):
    arm_set = ArmSet([_arm(MIXED[k], f"arm{k}", k) for k in range(n)])
    assert arm_set.compiled_model is not None
    for _ in range(2):
        q, v = random_state(arm_set.model, rng)
        H_ref = arm_set.pinocchio_pass(q, v)
        ref = tuple(a.copy() for a in arm_set.data_arrays()) + (H_ref,)
        out = arm_set.compiled_pass(q, v)
        _assert_close(out[:5], ref)
        assert all(a is b for a, b in zip(out, arm_set.compiled_pass(q, v), strict=True))


def test_grouped_arm_set_needs_no_grouping_in_the_compiled_pass(rng):
    arms = [_arm("ur5", f"ur{k}", k) for k in range(5)]
    grouped, whole = ArmSet(arms, group_size=2), ArmSet(arms)
    assert len(grouped.groups) == 3
    q, v = random_state(whole.model, rng)
    H_ref = whole.pinocchio_pass(q, v)
    _assert_close(grouped.compiled_pass(q, v)[:5], tuple(whole.data_arrays()) + (H_ref,))


def test_mass_matrix_is_written_only_between_joints_of_one_chain(rng):
    """Entries of joints of different trees or branches keep what the caller left there."""
    model, tools = every_joint_model(rng)
    related = np.zeros((model.nv, model.nv), dtype=bool)
    for i in range(1, model.njoints):
        for j in model.supports[i]:
            if j > 0:
                vi, vj = model.joints[i].idx_v, model.joints[j].idx_v
                related[vi, vj] = related[vj, vi] = True
    assert (~related).sum() > 40  # two trees and a branch: many entries to leave alone
    q, v = random_state(model, rng)
    ref = pinocchio_pass(model, q, v, tools)[2]
    assert np.all(ref[~related] == 0.0)
    M = np.full((model.nv, model.nv), 7.0)
    _run(CompiledModel.build(model, tools), q, v, M)
    assert np.all(M[~related] == 7.0)
    assert np.abs(M - ref)[related].max() <= TOL * np.abs(ref).max()


# ----------------------------------------------------------------------------- integrate
def test_integrate_and_difference_equal_pinocchio_across_pi(rng):
    model, tools = every_joint_model(rng)
    cm = CompiledModel.build(model, tools)
    continuous = [model.joints[j] for j in range(1, model.njoints) if model.joints[j].nq == 2]
    assert len(continuous) == 4
    out_q, out_v = np.empty(model.nq), np.empty(model.nv)
    for angle, step in ((np.pi - 1e-9, 2e-9), (-np.pi + 1e-9, -2e-9), (np.pi - 0.1, 0.5),
                        (-np.pi + 0.2, -0.9), (0.3, 0.0)):
        q, _ = random_state(model, rng)
        dv = rng.normal(size=model.nv)
        for jm in continuous:
            q[jm.idx_q], q[jm.idx_q + 1] = np.cos(angle), np.sin(angle)
            dv[jm.idx_v] = step
        integrate(cm.ints, q, dv, out_q)
        q1 = pin.integrate(model, q, dv)
        assert np.abs(out_q - q1).max() <= 1e-15
        difference(cm.ints, q, q1, out_v)
        assert np.abs(out_v - pin.difference(model, q, q1)).max() <= 1e-14
        assert np.abs(out_v - dv).max() <= 1e-14  # across ±π: the short way round
        q2, _ = random_state(model, rng)
        difference(cm.ints, q, q2, out_v)
        assert np.abs(out_v - pin.difference(model, q, q2)).max() <= 1e-14


# ----------------------------------------------------------------------------- own physics
def _shifted(cm: CompiledModel, q, direction, h):
    """``q ⊕ h · direction`` (the compiled integrate, as Pinocchio's)."""
    out = np.empty_like(q)
    integrate(cm.ints, q, h * direction, out)
    return out


@pytest.fixture(scope="module")
def com_model():
    """The every-joint model with a frame at each body's COM, and its tables."""
    model, _ = every_joint_model(np.random.default_rng(7))
    model, coms = com_frames(model)
    return model, CompiledModel.build(model, coms)


def _vee(W):
    return np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]]) / 2


def _body_motion(cm, q, v, h=1e-6):
    """Placements of the COM frames, and their ``ṗ``, ``ω`` by central finite differences."""
    H = _run(cm, q, v)[4]
    Hp = _run(cm, _shifted(cm, q, v, h), v)[4]
    Hm = _run(cm, _shifted(cm, q, v, -h), v)[4]
    dH = (Hp - Hm) / (2 * h)
    pdot = dH[:, :3, 3]
    omega = np.array([_vee(dR @ R.T) for dR, R in zip(dH[:, :3, :3], H[:, :3, :3],
                                                         strict=True)])
    return H, pdot, omega


def test_mass_matrix_is_spd_and_gives_the_bodies_kinetic_energy(com_model, rng):
    model, cm = com_model
    for _ in range(3):
        q, v = random_state(model, rng)
        M = _run(cm, q, v)[2]
        assert np.array_equal(M, M.T)
        assert np.linalg.eigvalsh(M).min() > 1e-6
        H, pdot, omega = _body_motion(cm, q, v)
        T = 0.5 * v @ (model.armature * v)  # rotor inertia of the joints
        for j in range(1, model.njoints):
            inertia, R = model.inertias[j], H[j - 1, :3, :3]
            w = omega[j - 1]
            T += 0.5 * inertia.mass * pdot[j - 1] @ pdot[j - 1]
            T += 0.5 * w @ (R @ inertia.inertia @ R.T) @ w
        assert 0.5 * v @ M @ v == pytest.approx(T, rel=1e-8)


def test_nonlinear_effects_follow_lagrange_equations(com_model, rng):
    """``nle(q, 0) = ∂U/∂q`` and ``nle(q, v) - nle(q, 0) = Ṁ v - ½ ∂(vᵀ M v)/∂q``."""
    model, cm = com_model
    g = model.gravity.linear
    masses = np.array([model.inertias[j].mass for j in range(1, model.njoints)])
    q, v = random_state(model, rng)
    zero = np.zeros(model.nv)
    h = 1e-6

    def potential(qq):
        return -masses @ (_run(cm, qq, zero)[4][:, :3, 3] @ g)

    def kinetic2(qq):
        return v @ _run(cm, qq, zero)[2] @ v

    grad_U, grad_T2 = np.empty(model.nv), np.empty(model.nv)
    for k, e in enumerate(np.eye(model.nv)):
        qp, qm = _shifted(cm, q, e, h), _shifted(cm, q, e, -h)
        grad_U[k] = (potential(qp) - potential(qm)) / (2 * h)
        grad_T2[k] = (kinetic2(qp) - kinetic2(qm)) / (2 * h)
    Mdot = (_run(cm, _shifted(cm, q, v, h), zero)[2]
            - _run(cm, _shifted(cm, q, v, -h), zero)[2]) / (2 * h)
    gravity = _run(cm, q, zero)[3]
    Cv = _run(cm, q, v)[3] - gravity
    assert np.abs(gravity - grad_U).max() <= 1e-7 * np.abs(gravity).max()
    assert np.abs(Cv - (Mdot @ v - 0.5 * grad_T2)).max() <= 1e-7 * np.abs(Cv).max()
    assert v @ Mdot @ v == pytest.approx(2 * v @ Cv, rel=1e-7)  # Ṁ - 2C skew along v


def test_jacobians_are_the_derivatives_of_the_placements(com_model, rng):
    """``Σ J[:, k] v_k`` over a body's supporting joints is its twist at the world origin,
    and ``dJ`` is the derivative of ``J`` along the motion."""
    model, cm = com_model
    q, v = random_state(model, rng)
    J, dJ = _run(cm, q, v)[:2]
    H, pdot, omega = _body_motion(cm, q, v)
    for j in range(1, model.njoints):
        cols = [model.joints[s].idx_v for s in model.supports[j] if s > 0]
        twist = J[:, cols] @ v[cols]
        p = H[j - 1, :3, 3]
        expected = np.concatenate([pdot[j - 1] - np.cross(omega[j - 1], p), omega[j - 1]])
        assert np.abs(twist - expected).max() <= 1e-8 * max(1.0, np.abs(expected).max())
    h = 1e-6
    dJ_fd = (_run(cm, _shifted(cm, q, v, h), v)[0] - _run(cm, _shifted(cm, q, v, -h), v)[0]) / (
        2 * h)
    assert np.abs(dJ - dJ_fd).max() <= 1e-8 * np.abs(dJ).max()


# ----------------------------------------------------------------------------- unsupported
UNSUPPORTED = {
    "JointModelSpherical": pin.JointModelSpherical,
    "JointModelFreeFlyer": pin.JointModelFreeFlyer,
    "JointModelPlanar": pin.JointModelPlanar,
    "JointModelSphericalZYX": pin.JointModelSphericalZYX,
    "JointModelTranslation": pin.JointModelTranslation,
    "JointModelHelicalUnaligned": lambda: pin.JointModelHelicalUnaligned(
        np.array([0.0, 0.0, 1.0]), 0.1),
}


def _model_with(joint) -> pin.Model:
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "shoulder")
    model.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
    k = model.addJoint(j, joint, pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.3])), "wrist")
    model.appendBodyToJoint(k, pin.Inertia.Random(), pin.SE3.Identity())
    model.addFrame(pin.Frame("tool", k, 0, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    return model


@pytest.mark.parametrize("kind", sorted(UNSUPPORTED))
def test_unsupported_joints_raise_a_clear_error(kind):
    model = _model_with(UNSUPPORTED[kind]())
    assert not is_supported(model)
    assert unsupported_joints(model) == [("wrist", model.joints[2].shortname())]
    with pytest.raises(UnsupportedJointError, match=r"joint 'wrist' is a JointModel") as err:
        CompiledModel.build(model, [model.getFrameId("tool")])
    assert isinstance(err.value, MultiArmError)
    assert err.value.joint == "wrist" and err.value.joint_type.startswith(kind)


def test_arm_set_of_an_unsupported_arm_keeps_pinocchio_only(rng):
    arm = Arm.from_model(_model_with(pin.JointModelSpherical()), "tool", name="ball")
    arm_set = ArmSet([arm, _arm("ur5", "ur5", 0)])
    assert arm_set.compiled_model is None
    q = pin.randomConfiguration(arm_set.model, -np.ones(arm_set.nq), np.ones(arm_set.nq))
    arm_set.pinocchio_pass(q, np.zeros(arm_set.nv))  # the Pinocchio path still works
    with pytest.raises(UnsupportedJointError, match="'ball/wrist' is a JointModelSpherical"):
        arm_set.compiled_pass(q, np.zeros(arm_set.nv))


@pytest.mark.parametrize("n", [1, 3])
def test_energies_and_momentum_equal_pinocchios(n, rng):
    """``energy``: Pinocchio's kinetic and potential energy, and the total momentum about the
    world origin (centroidal momentum shifted there), with a tilted gravity."""
    arm_set = ArmSet([_arm(MIXED[k], f"arm{k}", k) for k in range(n)],
                     gravity=np.array([0.4, -1.1, -9.7]))
    model, data = arm_set.model, arm_set.model.createData()
    for speed in (0.0, 1.0):
        q, v = random_state(model, rng, speed=speed)
        energy = arm_set.compiled_pass(q, v)[5]
        kinetic = pin.computeKineticEnergy(model, data, q, v)
        potential = pin.computePotentialEnergy(model, data, q)
        h = pin.computeCentroidalMomentum(model, data, q, v)
        momentum = np.concatenate([h.linear, h.angular + np.cross(data.com[0], h.linear)])
        scale = max(1.0, abs(kinetic), abs(potential), np.abs(momentum).max())
        assert abs(energy[layout.EN_KINETIC] - kinetic) <= TOL * scale
        assert abs(energy[layout.EN_POTENTIAL] - potential) <= TOL * scale
        np.testing.assert_allclose(energy[layout.EN_MOMENTUM:layout.EN_MOMENTUM + 6], momentum,
                                   rtol=0, atol=TOL * scale)
        if speed > 0:  # and ½ vᵀ M v (no armature on these arms)
            M = arm_set.compiled_pass(q, v)[2]
            assert abs(energy[layout.EN_KINETIC] - 0.5 * v @ M @ v) <= TOL * scale



def test_an_empty_energy_array_skips_the_energies_and_changes_no_other_output(rng):
    """The open-loop step hands an empty ``energy``: no energies, the same bits elsewhere."""
    arm_set = ArmSet([_arm(MIXED[k], f"arm{k}", k) for k in range(3)])
    cm = arm_set.compiled_model
    q, v = random_state(arm_set.model, rng, speed=1.0)
    full, bare = cm.outputs(), cm.outputs()
    rigid_body_pass(cm.ints, cm.floats, q, v, *full)
    rigid_body_pass(cm.ints, cm.floats, q, v, *bare[:5], np.empty(0))
    for name, a, b in zip(NAMES, full[:5], bare[:5], strict=True):
        assert np.array_equal(a, b), name
    assert full[5][layout.EN_KINETIC] > 0  # the full pass did compute them
