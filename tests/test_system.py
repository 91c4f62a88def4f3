"""Assembly: blocks against per-arm references, constraint acceleration by finite differences,
solver agreement on real mixed systems, state validation, energy and momentum."""


import numpy as np
import pinocchio as pin
import pytest
from system_builders import (
    BOX_SIZE,
    build_system,
    moving_state,
    one_dof_arm,
    random_mixed_system,
)

from multiarm_pin.exceptions import ConstraintError, DynamicsError, InputError
from multiarm_pin.model.arm import Arm
from multiarm_pin.model.rigid_object import ObjectState, RigidObject
from multiarm_pin.system import MultiArmSystem, SystemState


# ---------------------------------------------------------------------- blocks vs references
@pytest.mark.parametrize("baumgarte", [None, (3.0, 4.0)])
def test_blocks_equal_per_arm_pinocchio_and_per_joint_references(rng, baumgarte):
    system, state = random_mixed_system(rng, 4, gravity=(0.3, -1.0, -9.0))
    state = moving_state(system, state, rng)
    # move off the constraint manifold a little so that phi and phi_dot are not zero
    o = state.obj
    state = SystemState(state.q + 1e-3 * rng.normal(size=system.nq),
                        state.v + 0.1 * rng.normal(size=system.nv),
                        ObjectState(o.position, o.quaternion, o.twist))
    tau = rng.normal(size=system.nv)
    ev = system.blocks(state, tau, baumgarte)
    b = ev.blocks
    R = o.rotation
    np.testing.assert_allclose(b.M_o, system.obj.mass_matrix(R))
    np.testing.assert_allclose(b.h_o[:3], system.obj.mass * np.array([0.3, -1.0, -9.0]))
    Iw = R @ system.obj.inertia @ R.T
    np.testing.assert_allclose(b.h_o[3:], -np.cross(o.twist[3:], Iw @ o.twist[3:]), atol=1e-12)
    for i, arm in enumerate(system.arms):
        qs, vs = system.arm_set.q_slices[i], system.arm_set.v_slices[i]
        model = pin.Model(arm.model)
        model.gravity = pin.Motion(np.array([0.3, -1.0, -9.0]), np.zeros(3))
        ref_arm = Arm(arm.name, model, arm.tool_frame_id, arm.base_placement, arm.tool_frame,
                      arm.tool_offset)
        terms = ref_arm.terms(state.q[qs], state.v[vs])
        tool = terms.tool_placement
        from multiarm_pin.model.kinematics import BodyKinematics

        jt = system.joints[i].evaluate(
            BodyKinematics.single(tool.translation, tool.rotation, terms.tool_twist),
            o.kinematics())
        nv, N = arm.nv, system.joints[i].n_constraints
        np.testing.assert_allclose(b.M[i, :nv, :nv], terms.M, atol=1e-10)
        np.testing.assert_allclose(b.h[i, :nv], tau[vs] - terms.nle, atol=1e-9)
        np.testing.assert_allclose(b.W[i, :nv, :N], jt.W_bar(terms.J), atol=1e-10)
        np.testing.assert_allclose(b.W_o[i, :, :N], jt.W_bar_o, atol=1e-12)
        c_ref = (jt.drift(terms.Jdot_qdot) if baumgarte is None
                 else jt.drift_baumgarte(terms.Jdot_qdot, *baumgarte))
        np.testing.assert_allclose(b.c[i, :N], c_ref, atol=1e-9)
        np.testing.assert_allclose(ev.constraints.phi[i, :N], jt.phi, atol=1e-12)
        assert np.all(b.W[i, :, N:] == 0) and np.all(b.c[i, N:] == 0)
    b.check_padding()


def _advance(system, state, sol, h):
    """Second-order Taylor step of the whole state by h (negative allowed)."""
    qdd = system.unpad(sol.qdd)
    o = state.obj
    q = pin.integrate(system.arm_set.model, state.q, h * state.v + 0.5 * h * h * qdd)
    w, dw = o.twist[3:], sol.a_o[3:]
    # rotation: R(h) = exp(h w + h²/2 dw) R to second order (world angular velocity)
    R = pin.exp3(h * w + 0.5 * h * h * dw) @ o.rotation
    quat = pin.Quaternion(R).coeffs()
    return SystemState(q, state.v + h * qdd,
                       ObjectState(o.position + h * o.twist[:3] + 0.5 * h * h * sol.a_o[:3],
                                   np.array(quat), o.twist + h * sol.a_o))


@pytest.mark.parametrize("n_arms", [1, 3])
def test_forward_dynamics_keeps_constraint_acceleration_zero(rng, n_arms):
    """phi_ddot = 0 at the solution, by central differences of phi_dot along the motion."""
    system, state = random_mixed_system(rng, n_arms)
    state = moving_state(system, state, rng)
    sol, ev = system.forward_dynamics(state, rng.normal(size=system.nv))
    h = 1e-5
    plus = system.blocks(_advance(system, state, sol, h)).constraints.phi_dot
    minus = system.blocks(_advance(system, state, sol, -h)).constraints.phi_dot
    phi_ddot = (plus - minus) / (2 * h)
    # the same quantity with a wrong drift term is far from zero: the check can fail
    assert np.abs(ev.blocks.c).max() > 1e-2
    assert np.abs(phi_ddot).max() < 1e-5


@pytest.mark.parametrize("n_arms", [1, 2, 3, 4, 5, 6])
def test_all_solvers_agree_on_real_mixed_systems(n_arms):
    rng = np.random.default_rng(100 + n_arms)
    system, state = random_mixed_system(rng, n_arms)
    state = moving_state(system, state, rng)
    tau = 5 * rng.normal(size=system.nv)
    ev = system.blocks(state, tau)
    sols = {s: system.forward_dynamics(state, tau, solver=s)[0]
            for s in ("object_first", "dense_kkt", "singular", "auto")}
    ref = sols["dense_kkt"]
    for name, sol in sols.items():
        for field in ("a_o", "qdd", "mu"):
            a, r = getattr(sol, field), getattr(ref, field)
            assert np.linalg.norm(a - r) <= 1e-9 * max(np.linalg.norm(r), 1.0), (name, field)
        assert sol.residuals().relative < 1e-10
    assert sols["auto"].solver == "object_first"
    assert ev.blocks.n == n_arms


# ---------------------------------------------------------------------- validation
def test_initial_state_checks_and_velocity_projection(rng):
    system, state = build_system(["ur5", "panda"], ["weld", "revolute"], rng)
    system.check_initial_state(state)
    bad = SystemState(state.q, rng.normal(size=system.nv), state.obj)
    with pytest.raises(ConstraintError, match=r"inconsistent initial velocities: arm \d.*"
                                              r"project_velocities"):
        system.check_initial_state(bad)
    fixed = system.project_velocities(bad)
    system.check_initial_state(fixed, velocity_tol=1e-10)
    assert np.abs(system.blocks(fixed).constraints.phi_dot).max() < 1e-12
    # least-norm: the correction is orthogonal to every consistent velocity (range of Aᵀ)
    A = system.constraint_jacobian(state)
    delta = np.concatenate([fixed.v - bad.v, fixed.obj.twist - bad.obj.twist])
    _, s, vh = np.linalg.svd(A)
    null = vh[np.sum(s > 1e-10):]
    assert np.abs(null @ delta).max() < 1e-10
    assert np.linalg.norm(delta) > 0.1
    # positions off the joint
    moved = SystemState(state.q + 0.01, state.v, state.obj)
    with pytest.raises(ConstraintError, match="initial gap"):
        system.check_initial_state(moved)


def test_nan_and_bad_arguments_are_clear_errors(rng):
    system, state = build_system(["ur5", "ur5"], ["weld", "weld"], rng)
    q = state.q.copy()
    q[3] = np.nan
    with pytest.raises(DynamicsError, match=r"arms' q contains NaN.*\[3\]"):
        system.blocks(SystemState(q, state.v, state.obj))
    o = state.obj
    with pytest.raises(DynamicsError, match="object twist contains NaN"):
        system.forward_dynamics(SystemState(state.q, state.v, ObjectState(
            o.position, o.quaternion, np.array([0, 0, np.nan, 0, 0, 0]))))
    with pytest.raises(InputError, match=r"tau: expected shape \(12,\)"):
        system.blocks(state, np.zeros(3))
    with pytest.raises(DynamicsError, match="tau contains NaN"):
        system.blocks(state, np.full(12, np.nan))
    with pytest.raises(InputError, match="baumgarte"):
        system.blocks(state, baumgarte=(1.0,))
    with pytest.raises(InputError, match="unknown solver 'fast'.*dense_kkt"):
        system.forward_dynamics(state, solver="fast")
    with pytest.raises(InputError, match="one joint per arm"):
        MultiArmSystem(system.arms, system.obj, system.joints[:1])
    with pytest.raises(InputError, match=r"arms' v: expected shape \(12,\)"):
        system.state(state.q, np.zeros(5))
    with pytest.raises(ConstraintError, match="cannot be built from the initial state"):
        build_system(["ur5"], [{"type": "teleport"}], rng)


def _read_only(a: np.ndarray) -> np.ndarray:
    b = np.array(a)
    b.setflags(write=False)
    return b


def _strided(a: np.ndarray) -> np.ndarray:
    return np.repeat(a, 2)[::2]  # equal values, a non-contiguous view


@pytest.mark.parametrize("make", [_read_only, _strided, list, lambda a: a.astype(np.float32)],
                         ids=["read_only", "strided", "list", "float32"])
def test_state_parts_of_other_types_give_the_same_step_and_compile_nothing(rng, make):
    """The fast path hands the parts to the kernel as they are; an other type than the
    kernel's (read-only, strided, list, float32) is converted by the checked path: same
    results as float64 arrays, and no new specialisation of the kernel (a minute each)."""
    from multiarm_pin._compiled import evaluate as kernels

    system, state = build_system(["ur5", "ur5"], ["weld", "weld"], rng)
    state = moving_state(system, state, rng)
    o = state.obj
    if make is not list:  # float32 must hold the values exactly for an exact comparison
        state = SystemState(*(np.float32(a).astype(float) for a in (state.q, state.v)),
                            ObjectState(*(np.float32(a).astype(float)
                                          for a in (o.position, o.quaternion, o.twist))))
        o = state.obj
    tau = np.float32(rng.normal(size=system.nv)).astype(float)
    sol, _ = system.forward_dynamics(state, tau)
    compiled = getattr(kernels.evaluate_state, "signatures", [])
    before = len(compiled)
    other = SystemState(make(state.q), make(state.v),
                        ObjectState(make(o.position), make(o.quaternion), make(o.twist)))
    for st, t in ((other, tau), (state, make(tau)), (other, make(tau))):
        got, ev = system.forward_dynamics(st, t)
        for name in ("a_o", "qdd", "mu"):
            assert np.array_equal(getattr(got, name), getattr(sol, name)), name
        assert np.array_equal(ev.blocks.M, system.blocks(state).blocks.M)
    assert len(getattr(kernels.evaluate_state, "signatures", [])) == before
    zero, _ = system.forward_dynamics(state)
    assert np.array_equal(zero.qdd, system.forward_dynamics(state, np.zeros(system.nv))[0].qdd)
    with pytest.raises(InputError, match=r"object quaternion expected shape \(4,\)"):
        system.forward_dynamics(SystemState(state.q, state.v, ObjectState(
            o.position, o.quaternion[:3], o.twist)))
    with pytest.raises(InputError, match=r"arms' q expected shape \(12,\)"):
        system.forward_dynamics(SystemState(state.q[:11], state.v, o))


def test_singular_system_without_solution_raises():
    """Two one-joint arms welded to the object: 8 DOF, 12 constraints. At rest it is
    consistent (the singular-arm solver finds the static answer); with velocities or a
    Baumgarte correction that no motion can realise, there is no solution."""
    arms = [one_dof_arm("a", 0.0), one_dof_arm("b", np.pi)]
    obj = RigidObject.box(BOX_SIZE, 5.0)
    q0 = [np.zeros(1), np.zeros(1)]
    system, state = MultiArmSystem.from_initial_state(
        arms, obj, ["weld", "weld"], q0, pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.3])))
    sol, _ = system.forward_dynamics(state)
    assert sol.solver == "singular" and set(sol.singular_arms) == {0, 1}
    np.testing.assert_allclose(sol.a_o, 0, atol=1e-9)
    np.testing.assert_allclose(system.unpad(sol.qdd), 0, atol=1e-9)
    spinning = SystemState(state.q, np.array([1.0, 0.5]), state.obj)
    with pytest.raises(DynamicsError, match="inconsistent"):
        system.forward_dynamics(spinning)
    twisted = SystemState(state.q + [0.3, -0.3], state.v, state.obj)
    with pytest.raises(DynamicsError, match="inconsistent"):
        system.forward_dynamics(twisted, baumgarte=(5.0, 5.0))
    with pytest.raises(DynamicsError):
        system.forward_dynamics(spinning, solver="dense_kkt")


# ---------------------------------------------------------------------- energy and momentum
def test_energy_and_momentum_against_body_sums(rng):
    system, state = random_mixed_system(rng, 3)
    state = moving_state(system, state, rng)
    model = system.arm_set.model
    data = model.createData()
    pin.forwardKinematics(model, data, state.q, state.v)
    ke, h_lin, h_ang, pe = 0.0, np.zeros(3), np.zeros(3), 0.0
    g = system.gravity
    for j in range(1, model.njoints):
        Y, vj, oMi = model.inertias[j], data.v[j], data.oMi[j]
        ke += 0.5 * vj.np @ (Y.matrix() @ vj.np)
        f0 = oMi.act(pin.Force(Y.matrix() @ vj.np))  # momentum about the world origin
        h_lin += f0.linear
        h_ang += f0.angular
        pe -= Y.mass * g @ (oMi.act(Y.lever))
    o, m = state.obj, system.obj.mass
    Iw = o.rotation @ system.obj.inertia @ o.rotation.T
    ke += 0.5 * m * o.twist[:3] @ o.twist[:3] + 0.5 * o.twist[3:] @ Iw @ o.twist[3:]
    pe -= m * g @ o.position
    h_lin += m * o.twist[:3]
    h_ang += Iw @ o.twist[3:] + np.cross(o.position, m * o.twist[:3])
    assert system.kinetic_energy(state) == pytest.approx(ke, rel=1e-12)
    assert system.potential_energy(state) == pytest.approx(pe, rel=1e-12)
    np.testing.assert_allclose(system.momentum(state), np.concatenate([h_lin, h_ang]),
                               rtol=1e-11, atol=1e-11)


@pytest.mark.parametrize("ratio", [0.8, 1.25])
def test_contact_dynamics_of_a_box_on_two_supports_under_a_torque(ratio):
    """Closed form (as in test_contact_events): both sides press iff τ <= W a / 2.

    Box ``a x b x c``, mass m, on its four bottom vertices (plane z = 0), torque τ about +y.
    Both press: ``F_L = W/2 - τ/a``, ``F_R = W/2 + τ/a`` and the box does not move. Beyond
    the threshold (25 % above) the left side lifts and ``F_R = (W/m + a τ / (2 I)) /
    (1/m + a² / (4 I))`` with ``I = m (a² + c²)/12``; the pivot's normal acceleration is 0.
    """
    from multiarm_pin.constraints import Support

    a, b, c, m, g = 0.6, 0.4, 0.2, 3.0, 9.81
    V = np.array([[sx * a / 2, sy * b / 2, -c / 2] for sx in (-1, 1) for sy in (-1, 1)])
    system = MultiArmSystem([], RigidObject.box([a, b, c], m), [], gravity=(0, 0, -g),
                            supports=[Support("table", [0, 0, 0], [0, 0, 1], V, 0.0)])
    state = system.state(np.zeros(0), None, [0.0, 0.0, c / 2])
    W = m * g
    tau = ratio * W * a / 2
    sol, rows = system.contact_dynamics(state, external_wrench=[0, 0, 0, 0, tau, 0])
    left, right = sol.mu[0, :2].sum(), sol.mu[0, 2:4].sum()
    np.testing.assert_allclose(rows.phi[0, :4], 0.0, atol=1e-15)
    if ratio < 1:
        np.testing.assert_allclose([left, right], [W / 2 - tau / a, W / 2 + tau / a],
                                   rtol=1e-10)
        np.testing.assert_allclose(sol.a_o, 0.0, atol=1e-10)
    else:
        I_yy = m * (a * a + c * c) / 12
        F_R = (W / m + a * tau / (2 * I_yy)) / (1 / m + a * a / (4 * I_yy))
        assert left == 0.0 and sol.phi_dd[0, :2].min() > 0.1
        np.testing.assert_allclose(right, F_R, rtol=1e-10)
    with pytest.raises(InputError, match="active: expected a bool array of shape"):
        system.contact_dynamics(state, active=np.ones((2, 2), dtype=bool))


def test_contact_dynamics_equals_solve_unilateral_on_contact_blocks():
    """pick_from_table (2 arms, 7 fingertips, 4 stand rows): same as the by-hand call.

    Reference: ``solve_unilateral(contact_blocks(...), contact_unilateral, active)`` built
    step by step from :meth:`blocks` and :meth:`contact_blocks`, with random torques and an
    active set missing one fingertip and one stand row: equal to 1e-12. And on the
    two-gripper grasp (no supports) under object_pd's torques, whose planned forces are all
    at least its 5 N margin, the solution equals the bilateral :meth:`forward_dynamics`
    (when every unilateral row pushes, the LCP is the bilateral solve) to 1e-9.
    """
    from pathlib import Path

    import yaml

    from multiarm_pin.app.scenario import build_scenario, parse_scenario
    from multiarm_pin.dynamics.unilateral import solve_unilateral

    root = Path(__file__).resolve().parents[1] / "scenarios"
    path = root / "pick_from_table.yaml"
    built = build_scenario(parse_scenario(yaml.safe_load(path.read_text()), str(path)))
    system, state = built.system, built.initial_state
    rng = np.random.default_rng(3)
    tau = rng.normal(scale=5.0, size=system.nv)
    active = system.contact_mask.copy()
    active[0, 1] = False
    active[system.n_arms, 2] = False
    sol, rows = system.contact_dynamics(state, tau, active, (5.0, 5.0))
    ev = system.blocks(state, tau, (5.0, 5.0))
    full, rows_ref = system.contact_blocks(state, ev.blocks, ev.constraints, (5.0, 5.0))
    ref = solve_unilateral(full, system.contact_unilateral, active)
    np.testing.assert_allclose(sol.a_o, ref.a_o, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sol.qdd, ref.qdd, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sol.mu, ref.mu, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(rows.phi, rows_ref.phi)
    assert sol.mu[0, 1] == 0.0 and sol.mu[system.n_arms, 2] == 0.0
    # no supports, every fingertip pushing (object_pd's torques plan >= 5 N on each): the
    # complementarity problem is the bilateral one
    from multiarm_pin.sim.controllers import ObjectPD

    path = root / "two_gripper_form_closure.yaml"
    built = build_scenario(parse_scenario(yaml.safe_load(path.read_text()), str(path)))
    system, state = built.system, built.initial_state
    ctrl = ObjectPD(system, margin=5.0)
    tau = ctrl(0.0, state, system.blocks(state))
    assert ctrl.last.mu[system.unilateral].min() >= 5.0 - 1e-6
    sol, _ = system.contact_dynamics(state, tau)
    bil, _ = system.forward_dynamics(state, tau, "dense_kkt")
    np.testing.assert_allclose(sol.a_o, bil.a_o, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(sol.mu, bil.mu, rtol=1e-9, atol=1e-9)
