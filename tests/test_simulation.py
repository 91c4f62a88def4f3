"""Integrators, records, progress, warnings and errors of simulate()."""

import pickle

import numpy as np
import pinocchio as pin
import pytest
from system_builders import build_system, moving_state, one_dof_arm

from multiarm_pin.dynamics import SOLVERS
from multiarm_pin.dynamics.unilateral import UNILATERAL_SOLVERS
from multiarm_pin.exceptions import (
    ConstraintError,
    DynamicsError,
    InputError,
    UnsupportedSolverError,
)
from multiarm_pin.model.rigid_object import ObjectState, RigidObject
from multiarm_pin.sim.simulation import INTEGRATORS, simulate
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
    assert "contact ur50:" in r.warnings[0] and "(arm 0)" in r.warnings[0]
    assert "μ =" in r.warnings[0]
    assert r.warnings[0].startswith("t = 0 s")


def test_singular_arms_switch_solver_and_are_reported():
    arms = [one_dof_arm("a", 0.0), one_dof_arm("b", np.pi)]
    system, state = MultiArmSystem.from_initial_state(
        arms, RigidObject.box((0.4, 0.3, 0.2), 5.0), ["weld", "weld"],
        [np.zeros(1), np.zeros(1)], pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.3])))
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


def test_a_solver_is_honoured_or_refused_never_replaced(moving):
    """Bilateral rows: every solver runs and is what the record names (``auto`` may choose
    among the registry's). Unilateral rows: ``auto`` and ``object_first`` run the mixed LCP
    (recorded under its names), the others are refused, naming the solver and the rows."""
    system, state = moving
    for name in SOLVERS:
        recorded = set(simulate(system, state, None, 0.02, 0.01, solver=name).solver)
        assert recorded <= set(SOLVERS), (name, recorded)
        if name in ("dense_kkt", "singular", "object_first"):
            assert recorded == {name}
    specs = [{"type": "fingertips", "contacts": [("-z", [0.0, 0.0, -0.1]),
                                                 ("+x", [0.2, 0.0, 0.0])], "radius": 0.01}]
    system, state = build_system(["ur5"], specs, None)
    rows = [label for b, r, label in system.contact_labels if system.contact_unilateral[b, r]]
    assert len(rows) == 2
    for name, entry in SOLVERS.items():
        if entry.unilateral:
            recorded = set(simulate(system, state, None, 0.02, 0.01, solver=name).solver)
            assert recorded <= set(UNILATERAL_SOLVERS), (name, recorded)
            continue
        with pytest.raises(UnsupportedSolverError) as info:
            simulate(system, state, None, 0.02, 0.01, solver=name)
        err = info.value
        assert isinstance(err, InputError) and err.solver == name and err.rows == rows
        assert str(err).startswith(f"solver {name!r} cannot serve the unilateral rows of this "
                                   f"system ({rows[0]}, {rows[1]})")
        assert str(err).endswith("name one of auto, object_first")
        assert pickle.loads(pickle.dumps(err)).rows == rows  # a worker's error reaches the driver


# ----------------------------------------------------------------------------- issue 13
# Partial records on errors and interrupts; the stepwise rk45; the memory guard.
def _failing_after(monkeypatch, calls: int, exc: BaseException):
    """Make the forward-dynamics solve raise ``exc`` from its ``calls``-th call on.

    The stepper solves once per closed-loop evaluation (fused with the blocks and the
    controller, ``multiarm_pin.sim.closed_loop``), so the evaluation is what fails here: in
    runs with ``compiled=False`` (the compiled loop would take the steps otherwise).
    """
    import multiarm_pin.sim.stepper as stepper

    real = stepper.closed_loop_evaluation
    count = [0]

    def evaluate(*args, **kwargs):
        count[0] += 1
        if count[0] >= calls:
            raise exc
        return real(*args, **kwargs)

    monkeypatch.setattr(stepper, "closed_loop_evaluation", evaluate)


@pytest.mark.parametrize("integrator, calls", [("rk4", 23), ("semi_implicit", 6),
                                               ("rk45", 23)])
def test_singular_mid_run_keeps_the_samples_and_names_the_time(moving, monkeypatch,
                                                               integrator, calls):
    from multiarm_pin.exceptions import SingularityError
    from multiarm_pin.sim.simulation import partial_result

    system, state = moving
    full = simulate(system, state, None, 0.1, 0.01, integrator, compiled=False)
    _failing_after(monkeypatch, calls, SingularityError("S_1", float("inf")))
    with pytest.raises(SingularityError, match=r"^t = [0-9.]+ s: S_1 is singular") as info:
        simulate(system, state, None, 0.1, 0.01, integrator, compiled=False)
    part = partial_result(info.value)
    T = len(part.t)
    assert 1 <= T < len(full.t)
    t_fail = float(str(info.value).split()[2])
    assert part.t[-1] <= t_fail  # the samples kept were completed before the failure
    for name in ("q", "v", "object_position", "mu", "constraint_violation"):
        got, ref = getattr(part, name), getattr(full, name)
        assert got.shape == (T, *ref.shape[1:])
        np.testing.assert_array_equal(got, ref[:T])  # the same samples as the full run


def test_interrupt_keeps_the_samples(moving, monkeypatch):
    from multiarm_pin.sim.simulation import partial_result

    system, state = moving
    _failing_after(monkeypatch, 9, KeyboardInterrupt())
    with pytest.raises(KeyboardInterrupt) as info:
        simulate(system, state, None, 0.1, 0.01, "rk4", compiled=False)
    part = partial_result(info.value)
    # rk4 solves 4 times a step (the sample's own evaluation, then 3 stages): solves 1-8 make
    # samples 0 and 1 and the step to 0.02; the 9th, sample 2's evaluation, is interrupted
    np.testing.assert_allclose(part.t, [0.0, 0.01])


def test_rk45_record_equals_scipy_solve_ivp(moving):
    """The stepwise rk45 gives solve_ivp(t_eval=grid)'s values (independent driver)."""
    from scipy.integrate import solve_ivp

    from multiarm_pin.sim.stepper import Stepper

    system, state = moving
    r = simulate(system, state, None, 0.05, 0.01, "rk45")
    st = Stepper(system, None, "auto", None)
    nq, nv = system.nq, system.nv

    def fun(t, y):
        o = y[nq + nv + 3:nq + nv + 7]
        s = SystemState(y[:nq], y[nq:nq + nv],
                        ObjectState(y[nq + nv:nq + nv + 3], o / np.linalg.norm(o),
                                    y[nq + nv + 7:]))
        return st.derivative(s, st.evaluate(t, s)[0])

    o = state.obj
    y0 = np.concatenate([state.q, state.v, o.position, o.quaternion, o.twist])
    ref = solve_ivp(fun, (0.0, 0.05), y0, method="RK45", t_eval=r.t, rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(r.q, ref.y[:nq].T, rtol=0, atol=1e-12)
    np.testing.assert_allclose(r.object_position, ref.y[nq + nv:nq + nv + 3].T, atol=1e-12)


def test_memory_guard_refuses_before_allocating(moving):
    from multiarm_pin.sim.simulation import record_bytes

    system, state = moving
    # the estimate is the record's real size: compare with a short run's arrays
    r = simulate(system, state, None, 0.05, 0.01, "rk4")
    arrays = [v for v in vars(r).values() if isinstance(v, np.ndarray) and len(v) == len(r.t)]
    real = sum(a.nbytes for a in arrays)
    assert real <= record_bytes(system, len(r.t)) <= 1.2 * real
    with pytest.raises(InputError, match=r"duration: 1e\+12 s .* samples, whose record needs"):
        simulate(system, state, None, 1e12, 0.001, "rk4")
    with pytest.raises(InputError, match="limit 1 KiB"):
        simulate(system, state, None, 0.05, 0.01, "rk4", max_record_bytes=1024)
