"""Force distribution: feasibility against linprog, optimality against KKT and SLSQP."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog, minimize

from multiarm_pin.dynamics import (
    SystemBlocks,
    distribute_forces,
    inverse_dynamics,
    min_norm_forces,
    solve,
)
from multiarm_pin.exceptions import DynamicsError, InputError

from .synthetic import random_spd

G = 9.81
MASS = 5.0
HALF = np.array([0.3, 0.2, 0.1])  # box half extents [m]
# Seven frictionless contacts on the box faces: (point in the COM frame, inward normal).
CONTACTS = [
    ((-0.3, -0.12, -0.06), (1, 0, 0)),
    ((0.3, 0.08, 0.07), (-1, 0, 0)),
    ((-0.11, -0.2, -0.06), (0, 1, 0)),
    ((0.08, 0.2, 0.04), (0, -1, 0)),
    ((-0.03, -0.04, -0.1), (0, 0, 1)),
    ((-0.09, 0.1, 0.1), (0, 0, -1)),
    ((-0.23, 0.14, -0.1), (0, 0, 1)),
]


def contact_wrenches(contacts) -> np.ndarray:
    """(6, K) zero-pitch wrenches [n; r × n] about the COM."""
    return np.array([np.r_[n, np.cross(p, n)] for p, n in
                     ((np.array(p, float), np.array(n, float)) for p, n in contacts)]).T


def form_closure_lp(W: np.ndarray) -> bool:
    """Rank 6 and a strictly positive combination of the columns is zero (Eq 2.1)."""
    K = W.shape[1]
    res = linprog(np.zeros(K), A_eq=W, b_eq=np.zeros(6), bounds=[(1, None)] * K,
                  method="highs")
    return np.linalg.matrix_rank(W) == 6 and res.status == 0


def feasible_lp(W, w, U, margin) -> bool:
    K = W.shape[1]
    bounds = [(margin, None) if u else (None, None) for u in U]
    res = linprog(np.zeros(K), A_eq=W, b_eq=w, bounds=bounds, method="highs")
    return res.status == 0


def best_margin_lp(W, w, U, cap=1e3) -> float:
    """max t s.t. W μ = w, μ_k >= t on U (capped at ``cap``); -inf when W μ = w has no
    solution."""
    K = W.shape[1]
    c = np.zeros(K + 1)
    c[-1] = -1.0
    A_ub = np.hstack([-np.eye(K)[U], np.ones((int(U.sum()), 1))])
    res = linprog(c, A_ub=A_ub, b_ub=np.zeros(int(U.sum())),
                  A_eq=np.hstack([W, np.zeros((6, 1))]), b_eq=w,
                  bounds=[(None, None)] * K + [(None, cap)], method="highs")
    return float(res.x[-1]) if res.status == 0 else -np.inf


def assert_kkt_optimal(W, w, U, margin, mu, tol=1e-8):
    """Certificate for the convex QP min ½‖μ‖² s.t. Wμ = w, μ_U >= m:
    μ = Wᵀν + Σ_active λ_k e_k with λ >= 0 (stationarity, dual feasibility). ``margin``:
    one for all or one per multiplier."""
    scale = max(np.abs(mu).max(), 1.0)
    margin = np.broadcast_to(np.asarray(margin, dtype=float), mu.shape)
    np.testing.assert_allclose(W @ mu, w, atol=tol * scale)
    assert np.all(mu[U] >= margin[U] - tol * scale)
    active = np.flatnonzero(U & (mu <= margin + 1e-7 * scale))
    E = np.zeros((len(mu), len(active)))
    E[active, np.arange(len(active))] = 1.0
    B = np.hstack([W.T, E])
    y, *_ = np.linalg.lstsq(B, mu, rcond=None)
    assert np.linalg.norm(B @ y - mu) <= 1e-7 * scale
    lam = y[6:]
    assert np.all(lam >= -1e-7 * scale), lam


def slsqp_reference(W, w, U, margin, start):
    res = minimize(
        lambda x: x @ x, start, jac=lambda x: 2 * x, method="SLSQP",
        constraints=[{"type": "eq", "fun": lambda x: W @ x - w, "jac": lambda x: W}],
        bounds=[(margin, None) if u else (None, None) for u in U],
        options={"ftol": 1e-14, "maxiter": 500},
    )
    assert res.success, res.message
    return res.x


def box_blocks(rng, split=(4, 3)) -> SystemBlocks:
    """Two 6-dof arms holding the box through the seven contacts (4 + 3), object at rest."""
    W_c = contact_wrenches(CONTACTS)
    parts = np.split(np.arange(7), [split[0]])
    M_o = np.diag([MASS] * 3 + [0.1, 0.2, 0.25])
    h_o = np.r_[0.0, 0.0, -MASS * G, 0.0, 0.0, 0.0]
    Ms, hs, Ws, Wos, cs = [], [], [], [], []
    for idx in parts:
        Ms.append(random_spd(rng, 6))
        hs.append(rng.standard_normal(6))
        Ws.append(rng.standard_normal((6, len(idx))))
        Wos.append(W_c[:, idx])
        cs.append(np.zeros(len(idx)))
    return SystemBlocks.from_lists(Ms, hs, Ws, Wos, cs, M_o, h_o)


def test_the_seven_contacts_are_a_form_closure_grasp():
    assert form_closure_lp(contact_wrenches(CONTACTS))
    assert not form_closure_lp(contact_wrenches(CONTACTS[:6]))


@pytest.mark.parametrize("margin", [0.0, 1.0, 10.0, 200.0])
def test_box_under_gravity_keeps_every_contact_above_margin(margin):
    rng = np.random.default_rng(1)
    blocks = box_blocks(rng)
    weight_wrench = blocks.M_o @ np.zeros(6) - blocks.h_o  # = [0, 0, m g, 0, 0, 0]
    U = blocks.constraint_mask.copy()
    fd = distribute_forces(blocks, weight_wrench, U, margin)
    W = blocks.stacked_W_o()
    assert fd.min_unilateral >= margin - 1e-9
    assert_kkt_optimal(W, weight_wrench, np.ones(7, bool), margin, fd.mu_flat)
    # an independent QP solver from a feasible (linprog) start finds the same optimum
    start = linprog(np.zeros(7), A_eq=W, b_eq=weight_wrench, bounds=[(margin, None)] * 7,
                    method="highs").x
    ref = slsqp_reference(W, weight_wrench, np.ones(7, bool), margin, start)
    np.testing.assert_allclose(fd.mu_flat, ref, rtol=1e-5, atol=1e-5)
    # the contact forces add up to the weight
    np.testing.assert_allclose(W @ fd.mu_flat, [0, 0, MASS * G, 0, 0, 0], atol=1e-9)
    # inverse dynamics with these internal forces holds the box still, and forward dynamics
    # with the resulting torques gives back the same, all-positive contact forces
    ide = inverse_dynamics(blocks, np.zeros(6), mu_I=fd.mu_I, basis=fd.basis)
    np.testing.assert_allclose(ide.mu, fd.mu, atol=1e-9)
    sol = solve(blocks.with_torques(ide.tau), "auto")
    np.testing.assert_allclose(sol.a_o, 0.0, atol=1e-9)
    assert blocks.flatten_mu(sol.mu).min() >= margin - 1e-8


def test_echelon_coordinates_roundtrip():
    blocks = box_blocks(np.random.default_rng(2))
    w = -blocks.h_o
    fd = distribute_forces(blocks, w, blocks.constraint_mask, 5.0, basis="echelon")
    assert fd.basis.method == "echelon" and fd.mu_I.shape == (1,)
    ide = inverse_dynamics(blocks, np.zeros(6), mu_I=fd.mu_I, basis=fd.basis)
    np.testing.assert_allclose(ide.mu, fd.mu, atol=1e-9)


def test_six_contacts_cannot_keep_every_force_positive():
    """Six independent contacts: μ = W⁻¹ w is unique; a negative entry makes it infeasible."""
    W = contact_wrenches(CONTACTS[:6])
    w = np.r_[0, 0, MASS * G, 0, 0, 0]
    mu = np.linalg.solve(W, w)
    assert mu.min() < 0
    assert not feasible_lp(W, w, np.ones(6, bool), 0.0)
    with pytest.raises(DynamicsError, match=f"achievable smallest force is {mu.min():.6g}"):
        min_norm_forces(W, w, np.ones(6, bool), 0.0)
    # with only the contacts that came out positive declared unilateral, it is feasible
    U = mu >= 0
    np.testing.assert_allclose(min_norm_forces(W, w, U, 0.0), mu, atol=1e-9)


def test_best_margin_reported_for_a_non_closure_grasp():
    # drop the top contact: the box can still be held against gravity, but the pushes of the
    # bottom contacts are bounded by the weight, so a huge margin is impossible
    contacts = CONTACTS[:5] + CONTACTS[6:]
    W = contact_wrenches(contacts)
    w = np.r_[0, 0, MASS * G, 0, 0, 0]
    U = np.ones(6, bool)
    mu = min_norm_forces(W, w, U, 0.0)
    assert mu.min() >= -1e-9
    assert not feasible_lp(W, w, U, 1000.0)
    with pytest.raises(DynamicsError, match="no internal force keeps every unilateral"):
        min_norm_forces(W, w, U, 1000.0)


@pytest.mark.parametrize("seed", range(30))
def test_random_problems_agree_with_linprog_and_kkt(seed):
    rng = np.random.default_rng(seed)
    K = int(rng.integers(6, 13))
    W = rng.standard_normal((6, K))
    w = rng.standard_normal(6) * 5
    U = rng.random(K) < 0.7
    margin = float(rng.choice([0.0, 0.5, 2.0]))
    # a verdict by construction: the best reachable margin is never within 1e-3 of the one
    # asked for, so the feasible / infeasible verdict cannot turn on rounding
    if U.any():
        assert abs(best_margin_lp(W, w, U) - margin) > 1e-3
    if feasible_lp(W, w, U, margin):
        mu = min_norm_forces(W, w, U, margin)
        assert_kkt_optimal(W, w, U, margin, mu)
    else:
        with pytest.raises(DynamicsError):
            min_norm_forces(W, w, U, margin)


def test_no_unilateral_gives_min_norm_and_bad_input_raises():
    rng = np.random.default_rng(9)
    W = rng.standard_normal((6, 8))
    w = rng.standard_normal(6)
    np.testing.assert_allclose(min_norm_forces(W, w, np.zeros(8, bool)), np.linalg.pinv(W) @ w,
                               atol=1e-12)
    with pytest.raises(InputError, match="margin"):
        min_norm_forces(W, w, np.ones(8, bool), -1.0)
    with pytest.raises(InputError, match="unilateral"):
        min_norm_forces(W, w, np.ones(7, bool))
    with pytest.raises(DynamicsError, match="cannot produce"):
        min_norm_forces(W[:, :4], w, np.ones(4, bool))
    blocks = box_blocks(rng)
    with pytest.raises(InputError, match=r"shape \(2, 4\)"):
        distribute_forces(blocks, w, np.ones(7, bool))


# The box's four bottom vertices on a table (normal +z): rows 0, 1 on the +x edge (a pivot).
BOTTOM = [(0.3, 0.2, -0.1), (0.3, -0.2, -0.1), (-0.3, 0.2, -0.1), (-0.3, -0.2, -0.1)]


def support_rows(omega):
    """(G (4, 6), κ (4,)) of the bottom vertices at rest orientation, angular velocity ω."""
    G_s = contact_wrenches([(p, (0, 0, 1)) for p in BOTTOM]).T
    kappa = np.array([np.cross(omega, np.cross(omega, p))[2] for p in BOTTOM])
    return G_s, kappa


def test_per_multiplier_margins_are_the_qp_with_those_bounds():
    rng = np.random.default_rng(11)
    W = contact_wrenches(CONTACTS)
    w = np.r_[0.0, 0.0, MASS * G, 0.0, 0.0, 0.0] + rng.normal(size=6)
    U = np.ones(7, dtype=bool)
    m = np.array([1.0, 0.0, 3.0, 0.5, 2.0, 0.0, 4.0])
    mu = min_norm_forces(W, w, U, m)
    assert_kkt_optimal(W, w, U, m, mu)  # an optimality certificate of the QP
    assert np.any(np.abs(mu - m) < 1e-9) and np.all(mu >= m - 1e-9)  # some bound is active
    # one margin for all is the scalar margin
    np.testing.assert_array_equal(min_norm_forces(W, w, U, np.full(7, 2.0)),
                                  min_norm_forces(W, w, U, 2.0))
    with pytest.raises(InputError, match="margin"):
        min_norm_forces(W, w, U, np.array([1.0, -1.0, 0, 0, 0, 0, 0]))


@pytest.mark.parametrize("seed", range(3))
def test_forces_with_the_pivot_pressing_are_the_qp_and_keep_it_on_the_table(seed):
    """Seven arm contacts (form closure) and the two +x bottom vertices pressing with a
    margin: the object's acceleration keeps them on the table (``G a + κ = 0``), the
    object's equation holds with the support forces, and the stacked forces are the
    minimum-norm ones under the margins (a KKT certificate of the QP)."""
    from multiarm_pin.dynamics.force_distribution import distribute_with_supports

    rng = np.random.default_rng(seed)
    b = box_blocks(rng)
    omega = 0.3 * rng.normal(size=3)
    G_s, kappa = support_rows(omega)
    a_d = rng.normal(size=6)
    sm = np.array([3.0, 3.0, np.nan, np.nan])
    U = np.ones((2, 4), dtype=bool)
    U[1, 3] = False  # padding
    d = distribute_with_supports(b, a_d, U & b.constraint_mask, 1.0, G_s, kappa, sm)
    np.testing.assert_allclose(G_s[:2] @ d.a_o + kappa[:2], 0.0, atol=1e-12)
    np.testing.assert_allclose(d.unreached, 0.0, atol=1e-9)  # rank 6: all reachable
    lhs = b.stacked_W_o() @ d.forces.mu_flat + G_s.T @ d.support_mu
    np.testing.assert_allclose(lhs, b.M_o @ d.a_o - b.h_o, atol=1e-9)
    assert d.support_mu[2] == d.support_mu[3] == 0.0
    assert np.all(d.support_mu[:2] >= 3.0 - 1e-9) and d.forces.min_unilateral >= 1.0 - 1e-9
    W = np.hstack([b.stacked_W_o(), G_s[:2].T])
    w = b.M_o @ d.a_o - b.h_o
    m = np.r_[np.ones(7), 3.0, 3.0]
    assert_kkt_optimal(W, w, np.ones(9, dtype=bool), m, np.r_[d.forces.mu_flat,
                                                              d.support_mu[:2]])
    # the supports act on the object like an external wrench: the inverse dynamics of the
    # arms with it in h_o returns the same arm multipliers
    res = inverse_dynamics(b.replaced(h_o=b.h_o + d.support_wrench), d.a_o, None,
                           d.forces.mu_I, d.forces.basis)
    np.testing.assert_allclose(res.mu, d.forces.mu, atol=1e-9)


def _opposed_contacts(rng):
    """Two arms with one contact each, on the -x face (pushing +x, high) and the +x face
    (pushing -x, low): their wrenches ``W_c`` (6, 2), the box's ``M_o``, ``h_o`` (gravity)
    and the blocks (random arm inertias and Jacobians)."""
    W_c = contact_wrenches([((-0.3, 0.0, 0.05), (1, 0, 0)), ((0.3, 0.0, -0.08), (-1, 0, 0))])
    M_o = np.diag([MASS] * 3 + [0.1, 0.2, 0.25])
    h_o = np.r_[0.0, 0.0, -MASS * G, 0.0, 0.0, 0.0]
    b = SystemBlocks.from_lists([random_spd(rng, 6)] * 2, [np.zeros(6)] * 2,
                                [rng.normal(size=(6, 1))] * 2, [W_c[:, :1], W_c[:, 1:]],
                                [np.zeros(1)] * 2, M_o, h_o)
    return W_c, M_o, h_o, b


def test_an_unreachable_wrench_is_left_to_the_motion_without_moving_the_pivot():
    """Two arm contacts (±x) and the pivot: rank 4. The wrench part no contact makes is
    ``M_o⁻¹``-orthogonal to every column (it changes no contact's acceleration) and the
    pivot stays on the table; without supports or arms the desired motion is taken as is."""
    from multiarm_pin.dynamics.force_distribution import distribute_with_supports

    rng = np.random.default_rng(5)
    W_c, M_o, h_o, b = _opposed_contacts(rng)
    G_s, kappa = support_rows(np.zeros(3))
    a_d = rng.normal(size=6)
    d = distribute_with_supports(b, a_d, np.ones((2, 1), bool), 0.0, G_s, kappa,
                                 np.array([0.0, 0.0, np.nan, np.nan]))
    W = np.hstack([W_c, G_s[:2].T])
    assert np.linalg.norm(d.unreached) > 1e-3
    np.testing.assert_allclose(W.T @ np.linalg.solve(M_o, d.unreached), 0.0, atol=1e-10)
    np.testing.assert_allclose(G_s[:2] @ d.a_o + kappa[:2], 0.0, atol=1e-12)
    lhs = W_c @ d.forces.mu_flat + G_s.T @ d.support_mu
    np.testing.assert_allclose(lhs, M_o @ d.a_o - h_o, atol=1e-9)


def test_best_effort_forces_push_and_make_the_closest_wrench():
    """Two opposed arm contacts and the pivot, asked to turn the box about -y (the far
    side down, into the table: only pulls would do it): without ``best_effort`` it
    raises; with it, every multiplier meets its margin and the wrench is the closest one
    (in the M_o⁻¹ metric) that such forces make (the bounded least-squares optimum: an
    independent solve on the shifted, nonnegative multipliers by NNLS)."""
    from scipy.optimize import nnls

    from multiarm_pin.dynamics.force_distribution import distribute_with_supports

    rng = np.random.default_rng(2)
    W_c, M_o, h_o, b = _opposed_contacts(rng)
    G_s, kappa = support_rows(np.zeros(3))
    a_d = np.array([0.0, 0.0, 0.0, 0.0, -100.0, 0.0])
    sm = np.array([2.0, 2.0, np.nan, np.nan])
    U = np.ones((2, 1), bool)
    with pytest.raises(DynamicsError):
        distribute_with_supports(b, a_d, U, 5.0, G_s, kappa, sm)
    d = distribute_with_supports(b, a_d, U, 5.0, G_s, kappa, sm, best_effort=True)
    m = np.array([5.0, 5.0, 2.0, 2.0])
    x = np.r_[d.forces.mu_flat, d.support_mu[:2]]
    assert np.all(x >= m - 1e-9)
    W = np.hstack([W_c, G_s[:2].T])
    a = d.a_o + np.linalg.solve(M_o, d.unreached)  # the acceleration before step 2's rest
    w = M_o @ a - h_o
    np.testing.assert_allclose(W @ x + d.unreached, w, atol=1e-9)
    ev, V = np.linalg.eigh(M_o)
    S = (V / np.sqrt(ev)) @ V.T
    y, _ = nnls(S @ W, S @ (w - W @ m))
    ref = np.linalg.norm(S @ (W @ (y + m) - w))
    assert np.linalg.norm(S @ d.unreached) <= ref + 1e-9


def test_per_row_arm_margins_with_supports_are_the_qp():
    """Arm margins given row by row (0 on two rows: they may rest without force) and the
    pivot pressing: the forces are the minimum-norm ones under those bounds (KKT)."""
    from multiarm_pin.dynamics.force_distribution import distribute_with_supports

    rng = np.random.default_rng(7)
    b = box_blocks(rng)
    G_s, kappa = support_rows(np.zeros(3))
    m = np.array([[4.0, 0.0, 4.0, 4.0], [0.0, 4.0, 4.0, 0.0]])
    U = b.constraint_mask.copy()
    d = distribute_with_supports(b, rng.normal(size=6), U, m, G_s, kappa,
                                 np.array([1.0, 1.0, np.nan, np.nan]))
    W = np.hstack([b.stacked_W_o(), G_s[:2].T])
    x = np.r_[d.forces.mu_flat, d.support_mu[:2]]
    assert_kkt_optimal(W, b.M_o @ d.a_o - b.h_o, np.ones(9, dtype=bool),
                       np.r_[b.flatten_mu(m), 1.0, 1.0], x)
