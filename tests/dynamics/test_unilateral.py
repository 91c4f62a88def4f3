"""Unilateral (mixed LCP) forward dynamics on blocks, against independent references.

References: exact enumeration of active sets with dense KKT solves
(:func:`contact_problems.oracle`), the dense ``A M⁻¹ Aᵀ``, the bilateral solvers, closed forms
and Pinocchio's ADMM contact solver.
"""

from __future__ import annotations

import numpy as np
import pytest

from multiarm_pin.dynamics import (
    DEFAULT_RCOND_TOL,
    SystemBlocks,
    delassus_operator,
    reduce_arms,
    solve,
    solve_unilateral,
)
from multiarm_pin.exceptions import DynamicsError, InputError

from .contact_problems import (
    admm_lcp,
    box_bottom_rows,
    dense_matrices,
    oracle,
    random_contact_problem,
)
from .synthetic import random_system


def rel(a: np.ndarray, b: np.ndarray, scale: float | None = None) -> float:
    s = scale if scale is not None else max(np.abs(b).max(), 1e-300)
    return float(np.abs(a - b).max() / s)


def random_case(seed: int):
    """1-4 arms of 0 (support), 3, 6 or 7 joints with 1-4 rows each, up to ~12 rows."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 5))
    nv = [int(x) for x in rng.choice([0, 3, 6, 7], n)]
    N = [int(x) for x in rng.integers(1, 5, n)]
    if seed % 3 == 0 and max(N) < 3:
        N[0] = 3
    redundant = seed % 3 == 0
    blocks, uni = random_contact_problem(rng, nv, N, redundant=redundant)
    # generic rank: each arm's rows are independent through its joints up to nv_i; the
    # excess rows act through the object's 6 dofs
    excess = sum(max(0, m - k) for k, m in zip(nv, N, strict=True))
    unique_mu = not redundant and excess <= 6
    return blocks, uni, unique_mu


def check_contact_conditions(sol, tol=1e-10):
    """μ ≥ 0 exactly and φ̈ ≥ 0 to round-off on unilateral rows, complementarity, padding."""
    b = sol.blocks
    uni = sol.active & sol.unilateral
    scale = max(np.abs(sol.phi_dd).max(), 1.0)
    assert (sol.mu[uni] >= 0.0).all()
    assert (sol.phi_dd[uni] >= -1e-12 * scale).all()
    assert sol.complementarity < tol
    assert sol.residuals().complementarity == sol.complementarity
    bil = sol.active & ~sol.unilateral
    assert np.abs(sol.phi_dd[bil]).max(initial=0.0) < 1e-10 * scale
    assert not sol.mu[~b.constraint_mask].any()
    assert not sol.phi_dd[~b.constraint_mask].any()
    assert not sol.qdd[~b.dof_mask].any()
    r = sol.residuals()
    assert max(r.object, r.arms) <= 1e-12 * r.scale


@pytest.mark.parametrize("seed", range(45))
def test_matches_active_set_enumeration(seed):
    blocks, uni, unique_mu = random_case(seed)
    a_o, qdd, mu, _ = oracle(blocks, uni)
    sol = solve_unilateral(blocks, uni)
    scale = max(np.abs(a_o).max(), np.abs(qdd).max())
    assert rel(sol.a_o, a_o, scale) < 1e-10
    assert rel(sol.qdd, qdd, scale) < 1e-10
    if unique_mu:
        assert rel(sol.mu, mu, max(np.abs(mu).max(), 1.0)) < 1e-10
    check_contact_conditions(sol)
    # the active-set method alone (no bilateral fast path) gives the same motion
    sol2 = solve_unilateral(blocks, uni, fast_path=False)
    assert sol2.solver == "active_set"
    assert rel(sol2.a_o, a_o, scale) < 1e-10
    assert rel(sol2.qdd, qdd, scale) < 1e-10
    check_contact_conditions(sol2)


def test_enumeration_covers_separation_and_redundancy():
    """The random cases are not trivial: rows separate, rows push, some sets are redundant.

    Counted only from unique quantities: ``separating`` is read off ``φ̈`` (unique: the
    motion is), and pushing rows only where ``μ`` is unique; with redundant rows, which of
    them carries the load is decided by round-off."""
    separated = pushing = redundant = supports = 0
    for seed in range(45):
        blocks, uni, unique_mu = random_case(seed)
        sol = solve_unilateral(blocks, uni)
        separated += int(sol.separating.sum())
        if unique_mu:
            pushing += int((sol.mu[uni] > 0).sum())
        redundant += not unique_mu
        supports += int((blocks.nv == 0).any())
    assert separated >= 40 and pushing >= 40 and redundant >= 15 and supports >= 15


@pytest.mark.parametrize("seed", range(15))
def test_compiled_kernel_equals_numpy_reference(seed):
    """The compiled kernel (Delassus, core, motion) and the numpy Delassus + the same core."""
    blocks, uni, unique_mu = random_case(seed)
    rng = np.random.default_rng(200 + seed)
    active = blocks.constraint_mask & (rng.uniform(size=uni.shape) < 0.8)
    for act in (None, active):
        sol = solve_unilateral(blocks, uni, act, fast_path=False)
        ref = solve_unilateral(blocks, uni, act, reference=True)
        assert ref.solver == sol.solver == "active_set"
        scale = max(np.abs(ref.a_o).max(), np.abs(ref.qdd).max())
        assert rel(sol.a_o, ref.a_o, scale) < 1e-12 and rel(sol.qdd, ref.qdd, scale) < 1e-12
        assert rel(sol.phi_dd, ref.phi_dd, max(np.abs(ref.phi_dd).max(), 1.0)) < 1e-12
        if unique_mu:
            assert rel(sol.mu, ref.mu, max(np.abs(ref.mu).max(), 1.0)) < 1e-12


def test_guess_is_only_a_starting_point():
    """Any warm-start guess gives the same motion; the previous answer's pushing rows (with a
    margin above round-off) are the final active set at once: no pivot.

    The no-pivot check runs where every pushing multiplier clears 1e-6 of the largest; the
    count of such cases is taken over the unique-μ cases only (with redundant rows the
    pushing set, hence the check's condition, is decided by round-off)."""
    exact = 0
    for seed in range(30):
        blocks, uni, unique_mu = random_case(seed)
        ref = solve_unilateral(blocks, uni, fast_path=False)
        scale = max(np.abs(ref.a_o).max(), np.abs(ref.qdd).max())
        rng = np.random.default_rng(300 + seed)
        pushing = ref.mu > 0
        for guess in (pushing, blocks.constraint_mask & (rng.uniform(size=uni.shape) < 0.5),
                      np.zeros_like(uni), blocks.constraint_mask.copy()):
            for kw in ({}, {"reference": True}):
                sol = solve_unilateral(blocks, uni, fast_path=False, guess=guess, **kw)
                assert rel(sol.a_o, ref.a_o, scale) < 1e-10
                assert rel(sol.qdd, ref.qdd, scale) < 1e-10
                check_contact_conditions(sol)
        mu_push = np.abs(ref.mu[pushing & uni])
        if mu_push.size and mu_push.min() > 1e-6 * np.abs(ref.mu).max():
            exact += unique_mu
            assert solve_unilateral(blocks, uni, fast_path=False, guess=pushing).pivots == 0
    assert exact >= 15
    blocks, uni, _ = random_case(1)
    pad = ~blocks.constraint_mask
    assert pad.any()
    with pytest.raises(InputError, match="guess: True on padding"):
        solve_unilateral(blocks, uni, guess=pad)


@pytest.mark.parametrize("seed", range(10))
def test_inactive_rows_are_dropped(seed):
    blocks, uni, _ = random_case(seed)
    rng = np.random.default_rng(100 + seed)
    active = blocks.constraint_mask & (rng.uniform(size=uni.shape) < 0.6)
    a_o, qdd, _, _ = oracle(blocks, uni, active)
    sol = solve_unilateral(blocks, uni, active)
    scale = max(np.abs(a_o).max(), np.abs(qdd).max())
    assert rel(sol.a_o, a_o, scale) < 1e-10 and rel(sol.qdd, qdd, scale) < 1e-10
    assert not sol.mu[~active].any()
    check_contact_conditions(sol)
    # φ̈ is reported on inactive rows too: the dense rates of the motion
    M, h, A, c = dense_matrices(blocks)
    v = np.concatenate([sol.a_o] + [sol.qdd[i, : blocks.nv[i]] for i in range(blocks.n)])
    assert rel(blocks.flatten_mu(sol.phi_dd), A @ v - c, 1.0) < 1e-12


@pytest.mark.parametrize("seed", range(10))
def test_delassus_equals_dense(seed):
    """G = A M⁻¹ Aᵀ and b = A M⁻¹ h - c, with A, M built densely over all arms."""
    blocks, _, _ = random_case(seed)
    M, h, A, c = dense_matrices(blocks)
    D = delassus_operator(blocks)
    G_ref = A @ np.linalg.solve(M, A.T)
    assert rel(D.G, G_ref) < 1e-12
    assert rel(D.b, A @ np.linalg.solve(M, h) - c) < 1e-12
    D0 = delassus_operator(blocks, with_h=False)
    assert rel(D0.G, G_ref) < 1e-12 and not D0.b.any()


@pytest.mark.parametrize("seed", range(20))
def test_all_pushing_equals_bilateral_solve(seed):
    """Flip the rows whose bilateral multiplier pulls: then every unilateral row pushes and
    the unilateral solve is the bilateral one."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 5))
    blocks, _, _ = random_system(rng, rng.choice([6, 7], n).tolist(),
                                 rng.integers(1, 6, n).tolist())
    ref = solve(blocks, "auto")
    sign = np.where(ref.mu < 0, -1.0, 1.0)
    flipped = SystemBlocks(blocks.M, blocks.h, blocks.W * sign[:, None, :],
                           blocks.W_o * sign[:, None, :], blocks.c * sign, blocks.M_o,
                           blocks.h_o, blocks.nv, blocks.N)
    ref = solve(flipped, "auto")
    # verdicts with margins (any CPU): every S_i regular far above the object-first
    # threshold, every multiplier pushing far above round-off
    assert reduce_arms(flipped).rcond.min() > 100 * DEFAULT_RCOND_TOL
    mu_real = ref.mu[flipped.constraint_mask]
    assert mu_real.min() > 1e-6 * np.abs(mu_real).max()
    uni = flipped.constraint_mask.copy()
    uni[0, 0] = False  # one bilateral row among them
    sol = solve_unilateral(flipped, uni)
    assert sol.solver == "bilateral"
    assert np.array_equal(sol.a_o, ref.a_o) and np.array_equal(sol.qdd, ref.qdd)
    assert np.array_equal(sol.mu, ref.mu)
    # the active-set method (warm start: all rows) agrees to round-off
    sol2 = solve_unilateral(flipped, uni, fast_path=False)
    G = delassus_operator(flipped).G
    assert np.linalg.eigvalsh(G)[0] > 1e-6 * np.diag(G).min()  # warm start: G_AA regular
    assert sol2.solver == "active_set" and sol2.pivots == 0
    scale = max(np.abs(ref.a_o).max(), np.abs(ref.qdd).max())
    assert rel(sol2.a_o, ref.a_o, scale) < 1e-12 and rel(sol2.qdd, ref.qdd, scale) < 1e-12
    assert rel(sol2.mu, ref.mu) < 1e-12


# ------------------------------------------------------------------ Pinocchio ADMM
def test_admm_recipe_solves_a_known_lcp():
    """The recipe itself: a 2 x 2 LCP with one pushing and one separating row."""
    G = np.array([[2.0, 1.0], [1.0, 2.0]])
    g = np.array([-2.0, 3.0])  # λ = (1, 0): w = (0, 4)
    lam, ok, _ = admm_lcp(G, g)
    assert ok and np.abs(lam - [1.0, 0.0]).max() < 1e-12


def admm_case(seed: int):
    """A problem with independent rows (30% bilateral for odd seeds) solved by us and by
    Pinocchio's ADMM. ``G`` and ``b`` are built densely (not by our Delassus code); the
    bilateral rows are condensed out (Schur complement on ``G_BB``), leaving the plain LCP
    ``0 ≤ λ_U ⟂ S λ_U + g ≥ 0``, ``S = G_UU - G_UB G_BB⁻¹ G_BU``,
    ``g = b_U - G_UB G_BB⁻¹ b_B``, for ADMM; then ``μ_B = -G_BB⁻¹ (b_B + G_BU λ_U)``."""
    rng = np.random.default_rng(1000 + seed)
    n = int(rng.integers(1, 4))
    nv = [int(x) for x in rng.choice([0, 6, 7], n)]
    N = [int(x) for x in rng.integers(1, 5, n)]
    if sum(max(0, m - k) for k, m in zip(nv, N, strict=True)) > 6:  # keep rows independent
        N = [min(m, k) if k else 1 for k, m in zip(nv, N, strict=True)]
    blocks, uni = random_contact_problem(rng, nv, N, p_bilateral=0.3 if seed % 2 else 0.0)
    M, h, A, c = dense_matrices(blocks)
    G = A @ np.linalg.solve(M, A.T)
    b = A @ np.linalg.solve(M, h) - c
    u = blocks.flatten_mu(uni).astype(bool)
    B, U = np.flatnonzero(~u), np.flatnonzero(u)
    X = np.linalg.solve(G[np.ix_(B, B)], np.column_stack((G[np.ix_(B, U)], b[B])))
    S = G[np.ix_(U, U)] - G[np.ix_(U, B)] @ X[:, :-1]
    g = b[U] - G[np.ix_(U, B)] @ X[:, -1]
    lam_u, ok, _ = admm_lcp(0.5 * (S + S.T), g)
    assert ok
    lam = np.zeros(len(b))
    lam[U] = lam_u
    lam[B] = -(X[:, -1] + X[:, :-1] @ lam_u)
    sol = solve_unilateral(blocks, uni)
    return blocks, uni, sol, lam


@pytest.mark.parametrize("seed", range(10))
def test_matches_pinocchio_admm(seed):
    """Our μ equals ADMM's λ (unique: independent rows), bilateral rows included."""
    blocks, uni, sol, lam = admm_case(seed)
    mu = blocks.flatten_mu(sol.mu)
    assert rel(mu, lam, max(np.abs(lam).max(), 1.0)) < 1e-10
    check_contact_conditions(sol)


def test_admm_cases_mix_pushing_separating_and_bilateral():
    pushing = zero = bilateral = 0
    for seed in range(10):
        blocks, uni, sol, _ = admm_case(seed)
        pushing += int((sol.mu[uni] > 0).sum())
        zero += int((sol.mu[uni] == 0).sum())
        bilateral += int((blocks.constraint_mask & ~uni).sum())
    assert pushing >= 8 and zero >= 8 and bilateral >= 4


# ------------------------------------------------------------------ closed forms
def test_box_on_table_rests_and_lifts():
    """A free box (mass m, half extents a, b, c) on a table: four bottom vertices as the rows
    of a zero-dof support arm (rank 3: redundant).

    Under gravity alone, or with moments ``|τ_x| ≤ m g b``, ``|τ_y| ≤ m g a`` (the
    resultant stays inside the bottom face), it rests: ``z̈ = ω̇_x = ω̇_y = 0`` and the total
    normal force is ``m g`` (the individual forces are not unique). Pulled up by
    ``f_z > 0`` (gravity included in ``h_o``) it lifts: every μ = 0, ``a_o = M_o⁻¹ h_o``.
    """
    m, half = 2.0, (0.3, 0.2, 0.1)
    inertia = np.diag([0.1, 0.2, 0.3])
    M_o = np.block([[m * np.eye(3), np.zeros((3, 3))], [np.zeros((3, 3)), inertia]])
    Wo = box_bottom_rows(half)
    g = 9.81
    for wrench, rests in (([0, 0, -m * g, 0, 0, 0], True),
                          ([0, 0, -m * g, 0.5 * m * g * half[1], 0.3, 0], True),
                          ([0, 0, 1.5 * m * g, 0, 0, 0], False)):
        blocks = SystemBlocks.from_lists([np.zeros((0, 0))], [np.zeros(0)],
                                         [np.zeros((0, 4))], [Wo], [np.zeros(4)], M_o,
                                         np.array(wrench, dtype=float))
        uni = blocks.constraint_mask.copy()
        sol = solve_unilateral(blocks, uni)
        check_contact_conditions(sol)
        if rests:
            assert np.abs(sol.a_o[[2, 3, 4]]).max() < 1e-12
            assert abs(sol.mu.sum() - m * g) < 1e-12
        else:
            assert not sol.mu.any()
            assert np.abs(sol.a_o - np.linalg.solve(M_o, wrench)).max() < 1e-14


def test_box_on_two_supports_under_torque():
    """A box of mass m and inertia ``I_y`` on two frictionless point supports, contact points
    ``r_1 = (-a, 0, -c)``, ``r_2 = (a, 0, -c)`` from the COM, normal +z; torque ``τ`` about y.

    A normal force ``f z`` at ``r = (x, 0, -c)`` has moment ``r × f z = (0, -x f, 0)``.
    Both pressing (``a_o = 0``): ``f₁ + f₂ = m g`` and ``τ + a f₁ - a f₂ = 0``, so
    ``f₁ = (m g - τ/a)/2``, ``f₂ = (m g + τ/a)/2``: both ``≥ 0`` iff ``|τ| ≤ m g a``.
    For ``τ > m g a`` support 1 lifts and the box pivots on support 2, whose row
    ``[z; r₂ × z]ᵀ a_o = z̈ - a ω̇_y = 0``; with ``m z̈ = f - m g`` and
    ``I_y ω̇_y = τ - a f``: ``f = m (g I_y + a τ) / (I_y + m a²)``. Support 1 then
    separates: ``φ̈₁ = z̈ + a ω̇_y = 2 a ω̇_y > 0``.
    """
    m, a, c, Iy, g = 3.0, 0.25, 0.1, 0.07, 9.81
    M_o = np.diag([m, m, m, 0.05, Iy, 0.06])
    verts = [(-a, 0.0, -c), (a, 0.0, -c)]
    z = np.array([0.0, 0.0, 1.0])
    Wo = np.array([np.concatenate((z, np.cross(v, z))) for v in verts]).T
    tau_max = m * g * a
    lifted = 0
    for tau in (0.0, 0.4 * tau_max, -0.9 * tau_max, 1.3 * tau_max, 2.0 * tau_max):
        h_o = np.array([0.0, 0.0, -m * g, 0.0, tau, 0.0])
        blocks = SystemBlocks.from_lists([np.zeros((0, 0))], [np.zeros(0)],
                                         [np.zeros((0, 2))], [Wo], [np.zeros(2)], M_o, h_o)
        sol = solve_unilateral(blocks, blocks.constraint_mask.copy())
        check_contact_conditions(sol)
        f = sol.mu[0]
        if abs(tau) <= tau_max:
            assert np.abs(f - [(m * g - tau / a) / 2, (m * g + tau / a) / 2]).max() < 1e-12
            assert np.abs(sol.a_o).max() < 1e-12
        else:
            lifted += 1
            f2 = m * (g * Iy + a * tau) / (Iy + m * a * a)
            wdot = (tau - a * f2) / Iy
            assert f[0] == 0.0 and abs(f[1] - f2) < 1e-12
            assert abs(sol.a_o[2] - (f2 - m * g) / m) < 1e-12
            assert abs(sol.a_o[4] - wdot) < 1e-12
            assert wdot > 0.1 and abs(sol.phi_dd[0, 0] - 2 * a * wdot) < 1e-12
    assert lifted == 2


# ------------------------------------------------------------------ errors
def test_infeasible_and_inconsistent_raise():
    rng = np.random.default_rng(5)
    Wo = rng.standard_normal((6, 1))
    # the same row twice, once bilateral with c = 0, once unilateral demanding φ̈ ≥ 1:
    # φ̈ = 0 and φ̈ - 1 ≥ 0 cannot both hold
    blocks = SystemBlocks.from_lists([np.zeros((0, 0))], [np.zeros(0)], [np.zeros((0, 2))],
                                     [np.hstack((Wo, Wo))], [np.array([0.0, 1.0])],
                                     np.eye(6), rng.standard_normal(6))
    uni = np.array([[False, True]])
    for kw in ({}, {"reference": True}):
        with pytest.raises(DynamicsError, match="cannot all hold.*arm 0, row 1"):
            solve_unilateral(blocks, uni, **kw)
    blocks = SystemBlocks.from_lists([np.zeros((0, 0))], [np.zeros(0)], [np.zeros((0, 2))],
                                     [np.hstack((Wo, Wo))], [np.array([0.0, 1.0])],
                                     np.eye(6), rng.standard_normal(6))
    for kw in ({}, {"reference": True}):
        with pytest.raises(DynamicsError, match=r"inconsistent: row \(arm 0, row [01]\)"):
            solve_unilateral(blocks, np.zeros((1, 2), dtype=bool), **kw)


def test_singular_mass_matrix_is_named():
    blocks, uni, _ = random_case(4)
    M = blocks.M.copy()
    M[1, 0, :] = M[1, :, 0] = 0.0
    bad = SystemBlocks(M, blocks.h, blocks.W, blocks.W_o, blocks.c, blocks.M_o, blocks.h_o,
                       blocks.nv, blocks.N)
    assert blocks.nv[1] > 0
    for kw in ({}, {"reference": True}):
        with pytest.raises(DynamicsError, match=r"mass matrix M_i of arm\(s\) \[1\]"):
            solve_unilateral(bad, uni, **kw)


def test_bad_input():
    blocks, uni, _ = random_case(1)
    with pytest.raises(InputError, match=r"unilateral: expected a bool array of shape"):
        solve_unilateral(blocks, uni[:, :-1])
    with pytest.raises(InputError, match=r"unilateral: expected a bool array"):
        solve_unilateral(blocks, uni.astype(float))
    pad = uni.copy()
    pad[1, blocks.N[1]] = True
    for kw in ({}, {"reference": True}, {"fast_path": False}):
        with pytest.raises(InputError, match=r"unilateral: True on padding \(arm 1, row 1"):
            solve_unilateral(blocks, pad, **kw)
        with pytest.raises(InputError, match=r"active: True on padding \(arm 1, row 1"):
            solve_unilateral(blocks, uni, pad, **kw)
    with pytest.raises(InputError, match="expected SystemBlocks"):
        solve_unilateral("blocks", uni)
    nan = SystemBlocks(blocks.M, blocks.h.copy(), blocks.W, blocks.W_o, blocks.c, blocks.M_o,
                       blocks.h_o, blocks.nv, blocks.N)
    nan.h[0, 0] = np.nan
    with pytest.raises(InputError, match="h contains NaN"):
        solve_unilateral(nan, uni)
