"""Whole-system momentum balance of simulations: d/dt (momentum of arms + object) = Σ external.

The arms' bases are fixed to the world, so the total momentum of arms + object is not
conserved, even with τ = 0 and no gravity: the world pushes on every arm through its base.
The law that does hold, and is checked here against quantities computed independently of the
simulation's own dynamics, is Newton-Euler for the whole system (world axes, about the world
origin)::

    d/dt [p; L_O] = Σ_arms (base reaction) + Σ_bodies [m g; c × m g]

- the momentum is ``MultiArmSystem.momentum`` (recorded every sample), itself checked against
  a sum over each arm's own Pinocchio bodies (``data.oMi``, ``model.inertias``, ``data.v``)
  plus the object's ``[m ẋ; I_w ω + x × m ẋ]``;
- its rate comes from central differences of the recorded samples (second order; the error
  falls ~4x per halving of the difference step, and Richardson's extrapolation of two steps
  removes the h² term);
- each base reaction comes from ``pin.rnea`` on the arm's own model (base baked in) with the
  realised q̈ and the contact wrench on the tool as an external force: ``data.f[1]`` is the
  wrench the base (universe) transmits to joint 1's subtree, i.e. to the whole arm;
- the contact forces are internal: what the object receives, ``G_object μ``, and what the tool
  receives, ``G_tool μ``, cancel about any point (checked), so they drop out of the balance.

Also checked: the signs and frames of the base reaction on static and falling arms, the
contact wrench as an external force (RNEA then returns the applied τ = 0), each arm's own
balance against ``pin.computeCentroidalMomentumTimeVariation``, that the balance fails without
the bases (the test can fail), and that a free object conserves its momentum.
"""

from functools import cache

import numpy as np
import pinocchio as pin
import pytest
from scipy.integrate import solve_ivp
from system_builders import FINGERTIP_CONTACTS, build_system, make_arm, moving_state

from multiarm_pin.model.rigid_object import ObjectState, RigidObject
from multiarm_pin.sim.simulation import simulate
from multiarm_pin.spatial import quaternion_derivative, quaternion_to_rotation

ZERO_G = (0.0, 0.0, 0.0)
TILTED_G = (0.5, -1.0, -9.7)  # not along an axis: a mixed-up axis or sign shows
# Held as bilateral rows (issue 12 made fingertips unilateral by default): with τ = 0 these
# fingertips pull, and the balance is checked here on a constrained motion without events
# (unilateral separation is tested in tests/test_contact_events.py and the scenario tests).
FINGERTIPS = {"type": "fingertips", "contacts": FINGERTIP_CONTACTS, "radius": 0.01,
              "unilateral": False}
DT = 1e-3  # rk4 step and sampling period [s]
DURATION = 0.1  # [s]
SAMPLES = (20, 50, 80)  # where the rate is checked (central differences up to ±8 samples)
STEPS = (1, 2, 4, 8)  # difference half-widths, in samples

CASES = {  # name: (gravity, third arm's joint, speed of the random initial motion)
    "gravity-revolute": ((0.0, 0.0, -9.81), "revolute", 1.0),
    "tilted-gravity-fingertips": (TILTED_G, FINGERTIPS, 1.0),
    "no-gravity-revolute": (ZERO_G, "revolute", 2.0),
    "no-gravity-fingertips": (ZERO_G, FINGERTIPS, 2.0),
}


# ---------------------------------------------------------------------- independent terms
def own_model(arm, gravity) -> tuple[pin.Model, pin.Data]:
    """A copy of the arm's own Pinocchio model (base baked in) with the system's gravity."""
    model = pin.Model(arm.model)
    model.gravity = pin.Motion(np.asarray(gravity, float), np.zeros(3))
    return model, model.createData()


def body_sums(model, data, gravity) -> tuple[np.ndarray, np.ndarray]:
    """Momentum and gravity wrench of the moving bodies (joints 1..), about the world origin.

    Needs ``pin.forwardKinematics(model, data, q, v)`` first. Returns two (6,) world-axes
    vectors ``[p; L_O]`` [kg m/s, kg m²/s] and ``[m g; c × m g]`` [N, N m]: sums over the
    bodies of ``oMi · (Y_i v_i)`` and of the weight ``m_i g`` at each body's COM.
    """
    h, w = np.zeros(6), np.zeros(6)
    for j in range(1, model.njoints):
        Y, oMi = model.inertias[j], data.oMi[j]
        h += oMi.act(pin.Force(Y.matrix() @ data.v[j].np)).vector
        c = oMi.act(Y.lever)
        w += np.concatenate([Y.mass * gravity, np.cross(c, Y.mass * gravity)])
    return h, w


def momentum_by_bodies(system, state) -> np.ndarray:
    """(6,) total momentum about the world origin from each arm's own model's bodies + object."""
    total = np.zeros(6)
    for i, arm in enumerate(system.arms):
        model, data = own_model(arm, system.gravity)
        q, v = state.q[system.arm_set.q_slices[i]], state.v[system.arm_set.v_slices[i]]
        pin.forwardKinematics(model, data, q, v)
        total += body_sums(model, data, system.gravity)[0]
    o, m = state.obj, system.obj.mass
    Iw = o.rotation @ system.obj.inertia @ o.rotation.T
    return total + np.concatenate(
        [m * o.twist[:3], Iw @ o.twist[3:] + np.cross(o.position, m * o.twist[:3])])


def shift_to_origin(wrench: np.ndarray, point: np.ndarray) -> np.ndarray:
    """(6,) wrench ``[f; m]`` about ``point`` (world axes) -> about the world origin."""
    return np.concatenate([wrench[:3], wrench[3:] + np.cross(point, wrench[:3])])


def base_reaction(model, data, tool_frame_id, q, v, a, wrench_on_tool):
    """The world's wrench on a fixed-base arm through its base, by Pinocchio's RNEA.

    Args:
        model, data: the arm's own model (base baked in) and a data of it.
        tool_frame_id: the tool frame of ``model``.
        q: (nq,) configuration; v: (nv,) velocity; a: (nv,) acceleration.
        wrench_on_tool: (6,) ``[f; m]`` applied on the tool, about the tool origin in world
            axes (LWA) [N, N m].

    Returns:
        ``(base, tau, tool)``: (6,) the wrench the universe applies to joint 1's subtree
        (``data.f[1]``, which includes the joint-1 motor torque) about the world origin in
        world axes; (nv,) the joint torques RNEA needs for that motion; (6,) the tool wrench
        about the world origin.
    """
    pin.framesForwardKinematics(model, data, q)
    tool = shift_to_origin(wrench_on_tool, data.oMf[tool_frame_id].translation)
    jid = model.frames[tool_frame_id].parentJoint
    fext = [pin.Force.Zero() for _ in range(model.njoints)]
    fext[jid] = data.oMi[jid].actInv(pin.Force(tool))  # in the joint's LOCAL frame
    tau = pin.rnea(model, data, q, v, a, fext).copy()
    return data.oMi[1].act(data.f[1]).vector.copy(), tau, tool


def balance_terms(system, r, k) -> dict[str, np.ndarray]:
    """Every external and contact wrench of sample ``k`` of run ``r`` (world origin, world axes).

    Keys: ``base`` (n, 6) reactions of the bases on the arms; ``gravity_arms`` (n, 6);
    ``gravity_object`` (6,); ``tool`` (n, 6) contact wrench on each tool ``G_toolᵀ μ``;
    ``object`` (n, 6) contact wrench of each joint on the object ``G_objectᵀ μ``;
    ``arm_rate`` (n, 6) each arm's momentum rate by ``computeCentroidalMomentumTimeVariation``;
    ``tau_error`` (n,) ``max |τ_rnea - τ_applied|`` per arm.
    """
    st = r.state(k)
    ct = system.blocks(st).constraints
    n = system.n_arms
    out = {name: np.zeros((n, 6)) for name in ("base", "gravity_arms", "tool", "object",
                                                 "arm_rate")}
    out["tau_error"] = np.zeros(n)
    for i, arm in enumerate(system.arms):
        model, data = own_model(arm, system.gravity)
        qs, vs = system.arm_set.q_slices[i], system.arm_set.v_slices[i]
        q, v, a = st.q[qs], st.v[vs], r.qdd[k, vs]
        mu = r.mu[k, i]
        out["base"][i], tau, out["tool"][i] = base_reaction(
            model, data, arm.tool_frame_id, q, v, a, ct.G_tool[i].T @ mu)
        out["tau_error"][i] = np.abs(tau - r.tau[k, vs]).max()
        out["object"][i] = shift_to_origin(ct.G_object[i].T @ mu, st.obj.position)
        pin.forwardKinematics(model, data, q, v)
        out["gravity_arms"][i] = body_sums(model, data, system.gravity)[1]
        pin.computeCentroidalMomentumTimeVariation(model, data, q, v, a)
        dh, c = data.dhg, data.com[0]  # rate about the (moving) COM; shift: ċ × m ċ = 0
        out["arm_rate"][i] = np.concatenate([dh.linear, dh.angular + np.cross(c, dh.linear)])
    m = system.obj.mass
    out["gravity_object"] = shift_to_origin(np.concatenate([m * system.gravity, np.zeros(3)]),
                                            st.obj.position)
    return out


@cache
def run(case: str):
    """Three UR5s (two welded to the box, one by ``case``'s joint), τ = 0, no Baumgarte."""
    gravity, third, speed = CASES[case]
    rng = np.random.default_rng(3)
    system, state = build_system(["ur5", "ur5", "ur5"], ["weld", "weld", third], rng,
                                 gravity=gravity)
    state = moving_state(system, state, rng, speed=speed)
    return system, simulate(system, state, None, DURATION, DT, "rk4")


def rate(r, k, s) -> np.ndarray:
    """(6,) central difference of the recorded momentum at sample k, half-width s samples."""
    return (r.momentum[k + s] - r.momentum[k - s]) / (2 * s * DT)


# ---------------------------------------------------------------------- signs on one arm
def test_static_arm_base_reaction_is_minus_its_weight_and_carries_the_motor_torque():
    """An arm held at rest by its gravity torques: the base carries −(weight) at the COM."""
    arm = make_arm("ur5", "ur5_0", 0.7)
    model, data = own_model(arm, TILTED_G)
    g = np.array(TILTED_G)
    rng = np.random.default_rng(11)
    zero = np.zeros(model.nv)
    tau_1 = []
    for _ in range(3):
        q = pin.neutral(model) + rng.uniform(-2.0, 2.0, model.nq)
        tau_g = pin.computeGeneralizedGravity(model, data, q).copy()
        base, tau, _ = base_reaction(model, data, arm.tool_frame_id, q, zero, zero, np.zeros(6))
        np.testing.assert_allclose(tau, tau_g, atol=1e-10)
        m = pin.computeTotalMass(model)  # moving bodies only (the base link is the world's)
        c = pin.centerOfMass(model, data, q).copy()
        weight = np.concatenate([m * g, np.cross(c, m * g)])
        np.testing.assert_allclose(base, -weight, atol=1e-10 * m * 9.81)
        # its moment about joint 1's axis is the joint-1 motor torque: base · S_1 = τ_1
        # (S_1 = the joint's twist about the world origin, WORLD Jacobian column 0)
        S1 = pin.computeJointJacobians(model, data, q)[:, 0]
        assert base @ S1 == pytest.approx(tau_g[0], abs=1e-10)
        tau_1.append(abs(tau_g[0]))
        # falling from rest with τ = 0: the base reaction is what the arm's momentum rate
        # (a different Pinocchio algorithm) leaves after gravity; no torque about joint 1
        a = pin.aba(model, data, q, zero, zero).copy()
        base, tau, _ = base_reaction(model, data, arm.tool_frame_id, q, zero, a, np.zeros(6))
        np.testing.assert_allclose(tau, 0.0, atol=1e-9)
        pin.computeCentroidalMomentumTimeVariation(model, data, q, zero, a)
        dh = data.dhg
        rate_o = np.concatenate([dh.linear, dh.angular + np.cross(data.com[0], dh.linear)])
        np.testing.assert_allclose(base, rate_o - weight, atol=1e-9 * m * 9.81)
        assert base @ S1 == pytest.approx(0.0, abs=1e-9)
        assert np.abs(base + weight).max() > 1.0  # falling: the base no longer holds it all
    assert max(tau_1) > 1.0  # tilted gravity: the first joint does carry a torque


# ---------------------------------------------------------------------- momentum itself
@pytest.mark.parametrize("case", ["gravity-revolute", "no-gravity-fingertips"])
def test_recorded_momentum_equals_the_sum_over_bodies(case):
    system, r = run(case)
    for k in (0, 50, len(r.t) - 1):
        ref = momentum_by_bodies(system, r.state(k))
        np.testing.assert_allclose(r.momentum[k], ref, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(system.momentum(r.state(k)), ref, rtol=1e-12, atol=1e-12)
    assert np.abs(r.momentum).max() > 1.0  # a real motion


# ---------------------------------------------------------------------- the balance
@pytest.mark.parametrize("case", list(CASES))
def test_momentum_rate_equals_base_reactions_plus_gravity(case):
    """d/dt (total momentum) = Σ base reactions + Σ weights, to ~1e-11 of the largest term."""
    system, r = run(case)
    assert set(r.solver) == {"object_first"}
    assert r.constraint_violation.max() < 1e-8  # no Baumgarte, and none needed
    for k in SAMPLES:
        terms = balance_terms(system, r, k)
        external = terms["base"].sum(0) + terms["gravity_arms"].sum(0) + terms["gravity_object"]
        rates = {s: rate(r, k, s) for s in STEPS}
        scale = max(np.abs(terms["base"].sum(0)).max(), np.abs(external).max(),
                    np.abs(terms["gravity_arms"].sum(0)).max())
        # the contact forces are internal (action = reaction about the origin), the contact
        # wrench was applied right (RNEA returns the τ = 0 that was applied)
        np.testing.assert_allclose(terms["tool"] + terms["object"], 0.0, atol=1e-12 * scale)
        assert terms["tau_error"].max() < 1e-10
        assert np.abs(terms["tool"]).max() > 0.1  # the arms do push on the object
        # each arm alone: its momentum rate = base + its weight + the contact wrench on it
        np.testing.assert_allclose(
            terms["arm_rate"],
            terms["base"] + terms["gravity_arms"] + terms["tool"], atol=1e-10 * scale)
        # the whole system, by finite differences of the recorded momentum (second order)
        err = {s: np.abs(rates[s] - external).max() / scale for s in STEPS}
        for s in STEPS[:-1]:
            assert 3.0 < err[2 * s] / err[s] < 5.0, (k, err)
        assert err[1] < 1e-5, (k, err)
        richardson = (4.0 * rates[1] - rates[2]) / 3.0  # the h² term removed
        assert np.abs(richardson - external).max() < 1e-9 * scale, (k, err)


def test_balance_fails_without_the_bases():
    """No gravity: the momentum still changes, by exactly what the bases push."""
    system, r = run("no-gravity-revolute")
    dp = r.momentum[-1] - r.momentum[0]
    assert np.abs(dp).max() > 1e4 * 1e-9 * np.abs(r.momentum).max()  # not conserved
    for k in SAMPLES:
        terms = balance_terms(system, r, k)
        assert np.abs(terms["gravity_arms"]).max() == 0.0
        base = terms["base"].sum(0)
        richardson = (4.0 * rate(r, k, 1) - rate(r, k, 2)) / 3.0
        tol = 1e-9 * np.abs(base).max()
        assert np.abs(richardson - base).max() < tol
        assert np.abs(base).max() > 0.5  # [N or N m]: ~1e9 times the tolerance
        assert np.abs(richardson - 0.0).max() > 1e8 * tol  # bases left out: fails
        assert np.abs(richardson + base).max() > 1e8 * tol  # a sign error: fails
        # each arm's share matters: dropping any one base breaks the balance too
        for i in range(system.n_arms):
            assert np.abs(richardson - (base - terms["base"][i])).max() > 1e6 * tol


# ---------------------------------------------------------------------- a free object
def free_object():
    """A box with three different principal moments (uniform density, 0.4 x 0.3 x 0.2 m)."""
    return RigidObject.box((0.4, 0.3, 0.2), 5.0)


def object_momentum(obj, state: ObjectState) -> np.ndarray:
    """(6,) ``[m ẋ; I_w ω + x × m ẋ]`` about the world origin, world axes."""
    h = obj.momentum(state)
    return np.concatenate([h[:3], h[3:] + np.cross(state.position, h[:3])])


def test_free_object_momentum_rate_is_zero_without_gravity():
    """Instantaneous: d/dt [m ẋ; I_w ω + x × m ẋ] = 0 from ``RigidObject.acceleration``."""
    obj = free_object()
    rng = np.random.default_rng(5)
    for _ in range(5):
        quat = rng.normal(size=4)
        st = ObjectState.create(rng.normal(size=3), quat / np.linalg.norm(quat),
                                5.0 * rng.normal(size=6))
        R, w = st.rotation, st.twist[3:]
        Iw = R @ obj.inertia @ R.T
        gyro = np.cross(w, Iw @ w)  # d/dt(I_w) ω: what ω̇ must cancel
        a = obj.acceleration(st, np.zeros(3))
        d_lin = obj.mass * a[:3]
        d_ang = Iw @ a[3:] + gyro + np.cross(st.position, obj.mass * a[:3])
        assert np.abs(gyro).max() > 0.05  # the body tumbles: ω̇ ≠ 0
        np.testing.assert_allclose(d_lin, 0.0, atol=1e-15)
        np.testing.assert_allclose(d_ang, 0.0, atol=1e-14 * np.abs(gyro).max())
        # with a wrench applied at the COM the rate is that wrench (the check can fail)
        f = rng.normal(size=6)
        a = obj.acceleration(st, np.zeros(3), f)
        d = np.concatenate([obj.mass * a[:3], Iw @ a[3:] + gyro
                            + np.cross(st.position, obj.mass * a[:3])])
        np.testing.assert_allclose(d, shift_to_origin(f, st.position), atol=1e-13)


def test_free_object_conserves_momentum_while_it_tumbles():
    """Integrated: a spin near the intermediate axis flips over, the momentum stays put."""
    obj = free_object()
    st0 = ObjectState.create([0.3, -0.2, 1.0], [0.0, 0.0, 0.0, 1.0],
                             [0.4, -0.1, 0.2, 0.05, 6.0, 0.05])  # body y: intermediate axis

    def f(_, y):
        st = ObjectState(y[:3], y[3:7] / np.linalg.norm(y[3:7]), y[7:])
        return np.concatenate([st.twist[:3], quaternion_derivative(st.quaternion, st.twist[3:]),
                               obj.acceleration(st, np.zeros(3))])

    y0 = np.concatenate([st0.position, st0.quaternion, st0.twist])
    out = solve_ivp(f, (0.0, 4.0), y0, method="DOP853", rtol=1e-12, atol=1e-14,
                    t_eval=np.linspace(0.0, 4.0, 41))
    assert out.success
    h0 = object_momentum(obj, st0)
    y_axis = []
    for y in out.y.T:
        st = ObjectState(y[:3], y[3:7] / np.linalg.norm(y[3:7]), y[7:])
        np.testing.assert_allclose(object_momentum(obj, st), h0, rtol=0, atol=1e-10)
        y_axis.append((quaternion_to_rotation(st.quaternion) @ [0.0, 1.0, 0.0])[1])
    w = out.y[10:, :]
    assert np.abs(w - w[:, :1]).max() > 1.0  # ω (world) changes: conservation is not trivial
    assert min(y_axis) < 0.0  # the body's y axis turned more than 90° away from the spin
