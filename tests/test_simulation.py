"""Integrators, records, progress, warnings and errors of simulate()."""

import numpy as np
import pytest
from test_system import build_system, moving_state, one_dof_arm

from multiarm_pin.exceptions import ConstraintError, DynamicsError, InputError
from multiarm_pin.rigid_object import ObjectState, RigidObject
from multiarm_pin.simulation import INTEGRATORS, simulate
from multiarm_pin.system import MultiArmSystem, SystemState


@pytest.fixture(scope="module")
def moving():
    rng = np.random.default_rng(3)
    system, state = build_system(["ur5", "panda"], ["weld", "spherical"], rng)
    return system, moving_state(system, state, rng, speed=1.0)


def final_error(system, state, integrator, dt, ref):
    r = simulate(system, state, None, 0.2, dt, integrator)
    return max(np.abs(r.q[-1] - ref.q[-1]).max(),
               np.abs(r.object_position[-1] - ref.object_position[-1]).max())


def test_record_shapes_and_quaternion_norm(moving):
    system, state = moving
    r = simulate(system, state, None, 0.1, 0.01, "rk4")
    T, n, m = 11, system.n_arms, system.N_max
    np.testing.assert_allclose(r.t, np.arange(T) * 0.01)
    assert r.q.shape == (T, system.nq) and r.v.shape == (T, system.nv)
    assert r.mu.shape == r.phi.shape == r.phi_dot.shape == (T, n, m)
    assert r.contact_points.shape == r.normals.shape == (T, n, m, 3)
    assert r.momentum.shape == (T, 6) and r.kinetic_energy.shape == (T,)
    np.testing.assert_allclose(np.linalg.norm(r.object_quaternion, axis=1), 1, atol=1e-14)
    assert r.q[0] == pytest.approx(state.q) and r.solver[0] == "object_first"
    # the recorded accelerations are those of the forward dynamics at the recorded states
    sol, _ = system.forward_dynamics(r.state(5))
    np.testing.assert_allclose(r.object_acceleration[5], sol.a_o, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(r.mu[5], sol.mu, rtol=1e-12, atol=1e-9)
    assert r.wall_time > 0


def test_integrators_converge_with_their_order(moving):
    system, state = moving
    ref = simulate(system, state, None, 0.2, 0.1 / 128, "rk45", rtol=1e-12, atol=1e-13)
    e1 = final_error(system, state, "rk4", 0.02, ref)
    e2 = final_error(system, state, "rk4", 0.01, ref)
    assert e1 / e2 > 10  # fourth order
    s1 = final_error(system, state, "semi_implicit", 0.004, ref)
    s2 = final_error(system, state, "semi_implicit", 0.002, ref)
    assert 1.6 < s1 / s2 < 2.5  # first order
    assert e2 < 1e-6 and s2 < 1e-2


def test_rk45_agrees_with_rk4(moving):
    system, state = moving
    a = simulate(system, state, None, 0.2, 0.01, "rk45")
    b = simulate(system, state, None, 0.2, 0.0025, "rk4")
    np.testing.assert_allclose(a.q[-1], b.q[-1], atol=1e-7)
    np.testing.assert_allclose(a.object_quaternion[-1], b.object_quaternion[-1], atol=1e-7)


def test_progress_callback(moving):
    system, state = moving
    seen = []
    for integrator in INTEGRATORS:
        seen.clear()
        simulate(system, state, None, 0.05, 0.01, integrator, progress=seen.append)
        assert seen[-1] == 1.0 and all(0.0 <= x <= 1.0 for x in seen)
        assert seen == sorted(seen) or integrator == "rk45"


def test_controller_torque_is_applied_and_recorded(moving):
    system, state = moving
    calls = []

    def push(t, s, ev):
        calls.append(t)
        return np.full(system.nv, 2.0)

    r = simulate(system, state, push, 0.02, 0.01, "rk4")
    np.testing.assert_allclose(r.tau, 2.0)
    assert len(calls) == 2 * 4 + 1  # 4 stages a step, plus the last sample
    sol, _ = system.forward_dynamics(r.state(1), np.full(system.nv, 2.0))
    np.testing.assert_allclose(r.qdd[1], system.unpad(sol.qdd), rtol=1e-12, atol=1e-10)


def test_fingertips_without_control_report_separation():
    specs = [{"type": "fingertips", "contacts": [("-z", [0.0, 0.0, -0.1]),
                                                 ("+x", [0.2, 0.0, 0.0])], "radius": 0.01}]
    system, state = build_system(["ur5"], specs, None)
    assert system.unilateral.sum() == 2
    r = simulate(system, state, None, 0.05, 0.01, "rk4")
    assert r.warnings, "a falling arm pulls the fingertips: they should separate"
    assert "arm 0 (ur50) contact" in r.warnings[0] and "μ =" in r.warnings[0]
    assert r.warnings[0].startswith("t = 0 s")


def test_singular_arms_switch_solver_and_are_reported():
    arms = [one_dof_arm("a", 0.0), one_dof_arm("b", np.pi)]
    system, state = MultiArmSystem.from_initial_state(
        arms, RigidObject.box((0.4, 0.3, 0.2), 5.0), ["weld", "weld"],
        [np.zeros(1), np.zeros(1)], (0, 0, 0.3))
    r = simulate(system, state, None, 0.05, 0.01, "rk4")
    assert r.solver_switches == [0.0] and set(r.solver) == {"singular"}
    assert np.abs(r.object_position - r.object_position[0]).max() < 1e-12


def test_bad_input(moving):
    system, state = moving
    with pytest.raises(InputError, match="unknown integrator 'euler'.*rk4, rk45, semi_implicit"):
        simulate(system, state, None, 0.1, 0.01, "euler")
    with pytest.raises(InputError, match="unknown solver"):
        simulate(system, state, None, 0.1, 0.01, solver="magic")
    with pytest.raises(InputError, match="dt"):
        simulate(system, state, None, 0.1, -0.01)
    with pytest.raises(InputError, match="duration"):
        simulate(system, state, None, 0.001, 0.01)
    bad_v = SystemState(state.q, state.v + 0.5, state.obj)
    with pytest.raises(ConstraintError, match="inconsistent initial velocities"):
        simulate(system, bad_v, None, 0.1, 0.01)
    o = state.obj
    nan = SystemState(state.q, state.v, ObjectState(o.position * np.nan, o.quaternion, o.twist))
    with pytest.raises(DynamicsError, match="object position contains NaN"):
        simulate(system, nan, None, 0.1, 0.01)
    with pytest.raises(InputError, match=r"controller returned torques of shape \(2,\)"):
        simulate(system, state, lambda t, s, e: np.zeros(2), 0.1, 0.01)
    with pytest.raises(DynamicsError, match="NaN"):
        simulate(system, state, lambda t, s, e: np.full(system.nv, np.nan), 0.1, 0.01)
