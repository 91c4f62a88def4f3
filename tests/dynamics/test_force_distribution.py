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
    μ = Wᵀν + Σ_active λ_k e_k with λ >= 0 (stationarity, dual feasibility)."""
    scale = max(np.abs(mu).max(), 1.0)
    np.testing.assert_allclose(W @ mu, w, atol=tol * scale)
    assert np.all(mu[U] >= margin - tol * scale)
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
