"""Forward-dynamics solvers on synthetic blocks: agreement, residuals, singular arms, errors."""

from __future__ import annotations

import numpy as np
import pytest

import multiarm_pin.dynamics as dyn
from multiarm_pin.dynamics import SOLVERS, SystemBlocks, assemble_kkt, solve
from multiarm_pin.dynamics.dense_kkt import unpack_kkt
from multiarm_pin.exceptions import DynamicsError, InputError, SingularityError

from .synthetic import random_object_inertia, random_spd, random_system


def lstsq_kkt(blocks: SystemBlocks):
    """Least-squares (minimum-norm) solution of the dense KKT system: the singular reference."""
    K, rhs = assemble_kkt(blocks)
    x, *_ = np.linalg.lstsq(K, rhs, rcond=1e-13)
    assert np.linalg.norm(K @ x - rhs) <= 1e-9 * (np.linalg.norm(K) * np.linalg.norm(x) + 1)
    return unpack_kkt(blocks, x)


def rel_diff(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


def assert_same_motion(sol, a_o, qdd, tol=1e-9):
    scale = max(np.abs(a_o).max(), np.abs(qdd).max())
    assert np.abs(sol.a_o - a_o).max() <= tol * scale
    assert np.abs(sol.qdd - qdd).max() <= tol * scale


def test_all_names_importable():
    for name in dyn.__all__:
        assert hasattr(dyn, name), name


@pytest.mark.parametrize("seed", range(40))
def test_all_solvers_agree_on_random_consistent_systems(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 7))
    nv = rng.choice([6, 7], n).tolist()
    N = rng.integers(1, 7, n).tolist()
    blocks, _, _ = random_system(rng, nv, N)
    # the verdict "auto -> object_first" with a margin (any CPU): every S_i regular far
    # above the switching threshold (at least 700x on these seeds)
    assert dyn.reduce_arms(blocks).rcond.min() > 100 * dyn.DEFAULT_RCOND_TOL
    ref = solve(blocks, "dense_kkt")
    for name in ("object_first", "object_first_numpy", "singular", "auto"):
        sol = solve(blocks, name)
        assert sol.solver == ("singular" if name == "singular" else "object_first")
        assert sol.singular_arms == ()
        assert rel_diff(sol.a_o, ref.a_o) < 1e-9
        assert rel_diff(sol.qdd, ref.qdd) < 1e-9
        assert rel_diff(sol.mu, ref.mu) < 1e-9
        # every equation group holds to round-off, padding stays zero
        assert sol.residuals().relative < 1e-11
        assert not sol.qdd[~blocks.dof_mask].any()
        assert not sol.mu[~blocks.constraint_mask].any()
    assert ref.residuals().relative < 1e-11


def test_closed_form_single_arm_one_constraint():
    """One dof, one constraint: q̈ = a (rigid link), so (M_o[0,0] + m) a = h_o[0] + h."""
    m_o, m, h_o, h = 3.0, 2.0, 5.0, -1.0
    M_o = np.eye(6) * m_o
    h_o_vec = np.zeros(6)
    h_o_vec[0] = h_o
    W_o = np.zeros((6, 1))
    W_o[0, 0] = 1.0  # the arm pushes the object along x ...
    W = np.array([[-1.0]])  # ... and is pushed back; constraint a_x - q̈ = 0
    blocks = SystemBlocks.from_lists([[[m]]], [[h]], [W], [W_o], [[0.0]], M_o, h_o_vec)
    a = (h_o + h) / (m_o + m)
    mu = m_o * a - h_o
    for name in ("object_first", "dense_kkt", "singular"):
        sol = solve(blocks, name)
        assert sol.a_o[0] == pytest.approx(a, rel=1e-14)
        assert sol.qdd_of(0) == pytest.approx([a], rel=1e-14)
        assert sol.mu_of(0) == pytest.approx([mu], rel=1e-14)


def test_free_arm_and_mixed_padding():
    """An arm with no constraint moves freely: q̈ = M⁻¹ h, and padded entries stay zero."""
    rng = np.random.default_rng(3)
    blocks, _, _ = random_system(rng, [7, 6, 3], [0, 6, 2])
    assert blocks.nv_max == 7 and blocks.N_max == 6
    blocks.check_padding()
    ref = solve(blocks, "dense_kkt")
    for name in ("object_first", "singular", "auto"):
        sol = solve(blocks, name)
        np.testing.assert_allclose(
            sol.qdd_of(0), np.linalg.solve(blocks.M[0], blocks.h[0]), rtol=1e-12
        )
        assert sol.mu_of(0).shape == (0,)
        assert sol.qdd_of(2).shape == (3,)
        assert rel_diff(sol.qdd, ref.qdd) < 1e-9


@pytest.mark.parametrize(
    ("nv", "N", "rank_W", "expected"),
    [
        ([6, 3, 7], [4, 5, 2], {}, (1,)),  # arm 1 has fewer joints than constraints
        ([6, 6, 7], [3, 5, 2], {1: 3}, (1,)),  # arm 1 has a rank-deficient W_i
        ([0, 6], [6, 5], {}, (0,)),  # a fixed gripper (no joints at all)
        ([2, 6, 6, 3], [5, 4, 6, 4], {2: 4}, (0, 2, 3)),  # several singular arms
    ],
)
def test_singular_variant_matches_least_squares_kkt(nv, N, rank_W, expected):
    rng = np.random.default_rng(sum(nv) + 10 * sum(N))
    blocks, _, _ = random_system(rng, nv, N, rank_W=rank_W)
    a_ref, qdd_ref, _ = lstsq_kkt(blocks)
    for name in ("singular", "auto"):
        sol = solve(blocks, name)
        assert sol.solver == "singular"
        assert sol.singular_arms == expected
        assert_same_motion(sol, a_ref, qdd_ref)
        assert sol.residuals().relative < 1e-10
    for name in ("object_first", "object_first_numpy"):
        with pytest.raises(SingularityError, match=r"arm\(s\) \[" + str(expected[0])):
            solve(blocks, name)


def redundant_fixed_grippers(seed: int, offset: float = 0.0):
    """Two fixed grippers each welded to the object: 12 multipliers for 6 dofs.

    The constraint Jacobian ``[W_oᵀ Wᵀ]`` is 12 x 6, so it has rank 6 < 12 by construction
    (whatever the rounding): the KKT matrix is singular. With ``c = W_oᵀ a`` the constraints
    are consistent and the object acceleration must be ``a``; ``offset`` makes the second
    gripper's constraints inconsistent with the first's.
    """
    rng = np.random.default_rng(seed)
    a = rng.standard_normal(6)
    Wos = [rng.standard_normal((6, 6)) for _ in range(2)]
    M_o = random_object_inertia(rng)
    h_o = rng.standard_normal(6)
    blocks = SystemBlocks.from_lists(
        [np.zeros((0, 0))] * 2, [np.zeros(0)] * 2, [np.zeros((0, 6))] * 2, Wos,
        [Wos[0].T @ a, Wos[1].T @ (a + offset)], M_o, h_o)
    return blocks, a


@pytest.mark.parametrize("seed", range(50))
def test_redundant_fixed_grippers_singular_kkt(seed):
    """The dense KKT refuses the redundant system for every seed (structural rank test, not LU
    rounding: on some CPUs LU ends with a pivot of 1e-16 and returns arbitrary multipliers),
    naming the rank and both arms; the singular variant gives the closed-form motion and
    multipliers that balance the object's equation."""
    blocks, a = redundant_fixed_grippers(seed)
    with pytest.raises(DynamicsError, match=r"rank 6 < 12 rows.*arm\(s\) \[0, 1\] are redundant"):
        solve(blocks, "dense_kkt")
    for name in ("singular", "auto"):
        sol = solve(blocks, name)
        assert sol.singular_arms == (0, 1)
        np.testing.assert_allclose(sol.a_o, a, rtol=1e-10, atol=1e-12)
        wrench = np.einsum("nij,nj->i", blocks.W_o, sol.mu)
        np.testing.assert_allclose(wrench, blocks.M_o @ a - blocks.h_o, rtol=1e-9, atol=1e-10)
    a_ref, _, _ = lstsq_kkt(blocks)
    np.testing.assert_allclose(a_ref, a, rtol=1e-9)


def test_inconsistent_fixed_grippers_raise():
    bad, _ = redundant_fixed_grippers(7, offset=0.1)
    with pytest.raises(DynamicsError, match="inconsistent"):
        solve(bad, "auto")
    with pytest.raises(DynamicsError, match="redundant"):
        solve(bad, "dense_kkt")


def test_redundancy_names_only_the_dependent_arms():
    """Arm 0 has joints, so its rows are independent of everything else; arms 1 and 2 are
    fixed grippers with 4 + 4 rows acting on the 6 object dofs only: rank 3 + 6 = 9 < 11."""
    rng = np.random.default_rng(2)
    arm0, _, _ = random_system(rng, [6], [3])
    Wos = [arm0.W_o[0]] + [rng.standard_normal((6, 4)) for _ in range(2)]
    a = rng.standard_normal(6)
    blocks = SystemBlocks.from_lists(
        [arm0.M[0], np.zeros((0, 0)), np.zeros((0, 0))],
        [arm0.h[0], np.zeros(0), np.zeros(0)],
        [arm0.W[0], np.zeros((0, 4)), np.zeros((0, 4))], Wos,
        [arm0.c[0], Wos[1].T @ a, Wos[2].T @ a], arm0.M_o, arm0.h_o)
    assert dyn.redundant_constraints(blocks) == (9, (1, 2))
    with pytest.raises(DynamicsError, match=r"rank 9 < 11 rows.*arm\(s\) \[1, 2\]"):
        solve(blocks, "dense_kkt")
    # an independent system has full rank and nothing redundant
    assert dyn.redundant_constraints(arm0) == (3, ())


def test_rank_verdict_is_invariant_to_row_scaling():
    """Scaling a constraint row (both its W_o column and its W column) by 1e-8 or 1e8 changes
    nothing in the rank verdict: a constraint equation's scale is arbitrary."""
    rng = np.random.default_rng(9)
    b, _, _ = random_system(rng, [6, 7], [4, 5])
    for scale in (1e-8, 1e8):
        W, W_o, c = b.W.copy(), b.W_o.copy(), b.c.copy()
        W[1, :, 2] *= scale
        W_o[1, :, 2] *= scale
        c[1, 2] *= scale
        scaled = SystemBlocks(b.M, b.h, W, W_o, c, b.M_o, b.h_o, b.nv, b.N)
        assert dyn.redundant_constraints(scaled) == (9, ())
        assert rel_diff(solve(scaled, "dense_kkt").a_o, solve(b, "dense_kkt").a_o) < 1e-9


def test_any_partition_gives_the_same_motion():
    rng = np.random.default_rng(11)
    blocks, _, _ = random_system(rng, [6, 7, 6, 7], [5, 3, 6, 1])
    ref = solve(blocks, "object_first")
    for arms in ([0], [1, 3], [0, 1, 2, 3]):
        sol = solve(blocks, "singular", singular_arms=arms)
        assert sol.singular_arms == tuple(arms)
        assert rel_diff(sol.a_o, ref.a_o) < 1e-9
        assert rel_diff(sol.qdd, ref.qdd) < 1e-9
        assert rel_diff(sol.mu, ref.mu) < 1e-9


def ill_conditioned(delta: float) -> SystemBlocks:
    """Arm 1 gets two constraint columns of W_1 parallel up to a relative ``delta``."""
    rng = np.random.default_rng(5)
    blocks, _, _ = random_system(rng, [6, 6], [2, 2])
    W = blocks.W.copy()
    W[1, :, 1] = W[1, :, 0] + delta * rng.standard_normal(6)
    c = blocks.c.copy()
    c[1] = blocks.W_o[1].T @ np.ones(6) + W[1].T @ np.ones(6)
    return SystemBlocks(blocks.M, blocks.h, W, blocks.W_o, c, blocks.M_o, blocks.h_o,
                        blocks.nv, blocks.N)


def test_badly_conditioned_arm_is_detected():
    """S_1 with condition ~1e14 counts as singular; object-first alone is inaccurate there."""
    ill = ill_conditioned(1e-7)
    red = dyn.reduce_arms(ill)
    true_rcond = 1.0 / np.linalg.cond(red.S[1])
    assert red.rcond[1] >= true_rcond * (1 - 1e-6)  # the estimate is an upper bound
    assert red.rcond[1] < 1e-10 and red.rcond[0] > 1e-6
    ref = solve(ill, "dense_kkt")  # the full KKT matrix is well conditioned here
    sol = solve(ill, "auto")
    assert sol.solver == "singular" and sol.singular_arms == (1,)
    assert rel_diff(sol.a_o, ref.a_o) < 1e-9 and rel_diff(sol.qdd, ref.qdd) < 1e-9
    with pytest.raises(SingularityError):
        solve(ill, "object_first")
    # forcing past the arm test, object-first still refuses: the reduced object matrix is
    # then badly conditioned too
    with pytest.raises(SingularityError, match="reduced object matrix"):
        solve(ill, "object_first", rcond_tol=0.0)


@pytest.mark.parametrize("scale", [1e-6, 1e-9, 1e-12])
def test_tiny_constraint_column_is_detected(scale):
    """W_1[:, 0] tiny but not zero: the arm barely moves along constraint 0."""
    rng = np.random.default_rng(3)
    b, _, _ = random_system(rng, [6, 6, 7], [5, 4, 6])
    W = b.W.copy()
    W[1, :, 0] *= scale
    tiny = SystemBlocks(b.M, b.h, W, b.W_o, b.c, b.M_o, b.h_o, b.nv, b.N)
    ref = solve(tiny, "dense_kkt")
    sol = solve(tiny, "auto")
    assert sol.solver == "singular" and 1 in sol.singular_arms
    assert rel_diff(sol.qdd, ref.qdd) < 1e-9 and rel_diff(sol.a_o, ref.a_o) < 1e-9
    with pytest.raises(SingularityError):
        solve(tiny, "object_first")


@pytest.mark.parametrize("heavy", [1e9, 1e12])
def test_arm_far_heavier_than_object_falls_back(heavy):
    """S_i well conditioned but tiny: M_o + W_o S⁻¹ W_oᵀ is badly conditioned (5 of 6
    directions stiff), object-first would lose digits; auto hands every arm over."""
    rng = np.random.default_rng(3)
    b, _, _ = random_system(rng, [6], [5])
    big = SystemBlocks(b.M * heavy, b.h * heavy, b.W, b.W_o, b.c, b.M_o, b.h_o, b.nv, b.N)
    assert dyn.reduce_arms(big).rcond[0] > 1e-2
    ref = solve(big, "dense_kkt")
    sol = solve(big, "auto")
    assert sol.solver == "singular" and sol.singular_arms == (0,)
    assert rel_diff(sol.a_o, ref.a_o) < 1e-9 and rel_diff(sol.qdd, ref.qdd) < 1e-9
    for name in ("object_first", "object_first_numpy"):
        with pytest.raises(SingularityError, match="reduced object matrix"):
            solve(big, name)
    moderate = SystemBlocks(b.M * 1e3, b.h, b.W, b.W_o, b.c, b.M_o, b.h_o, b.nv, b.N)
    assert solve(moderate, "auto").solver == "object_first"


def test_moderately_conditioned_arm_stays_object_first():
    ill = ill_conditioned(1e-2)
    red = dyn.reduce_arms(ill)
    assert 100 * dyn.DEFAULT_RCOND_TOL < red.rcond[1] < 1e-2  # a verdict with a margin
    sol = solve(ill, "auto")
    assert sol.solver == "object_first"
    assert rel_diff(sol.a_o, solve(ill, "dense_kkt").a_o) < 1e-9


@pytest.mark.parametrize("delta", [1e-2, 1e-3, 1e-4, 3e-5, 1e-5, 1e-6, 1e-8, 1e-10, 0.0])
def test_auto_keeps_accuracy_across_conditioning(delta):
    """Whatever the conditioning of S_1, "auto" matches the (well-conditioned) dense KKT."""
    ill = ill_conditioned(delta)
    ref = solve(ill, "dense_kkt")
    sol = solve(ill, "auto")
    assert rel_diff(sol.a_o, ref.a_o) < 1e-9
    assert rel_diff(sol.qdd, ref.qdd) < 1e-9
    assert sol.residuals().relative < 1e-9


def test_unknown_solver_lists_known_ones():
    blocks, _, _ = random_system(np.random.default_rng(0), [6], [3])
    with pytest.raises(InputError) as info:
        solve(blocks, "msolve")
    for name in SOLVERS:
        assert name in str(info.value)
    with pytest.raises(InputError, match="singular_arms"):
        solve(blocks, "auto", singular_arms=[0])
    with pytest.raises(InputError, match="singular_arms"):
        solve(blocks, "singular", singular_arms=[3])
    with pytest.raises(InputError, match="rcond_tol"):
        solve(blocks, "auto", rcond_tol=-1.0)
    with pytest.raises(InputError, match="SystemBlocks"):
        solve("blocks", "auto")


@pytest.mark.parametrize("field", ["M", "h", "W", "W_o", "c", "M_o", "h_o"])
@pytest.mark.parametrize("solver", ["auto", "object_first", "dense_kkt", "singular"])
def test_nan_in_any_block_raises_input_error(field, solver):
    blocks, _, _ = random_system(np.random.default_rng(1), [6, 7], [3, 4])
    arrays = {f: getattr(blocks, f).copy() for f in ("M", "h", "W", "W_o", "c", "M_o", "h_o")}
    arr = arrays[field]
    idx = (1,) + (0,) * (arr.ndim - 1) if field not in ("M_o", "h_o") else (0,) * arr.ndim
    arr[idx] = np.nan
    bad = SystemBlocks(**arrays, nv=blocks.nv, N=blocks.N)
    match = f"{field} contains NaN" + (r".*arm\(s\) \[1\]" if field not in ("M_o", "h_o") else "")
    with pytest.raises(InputError, match=match):
        solve(bad, solver)


def test_from_lists_rejects_bad_input():
    rng = np.random.default_rng(2)
    M, h, W, Wo, c = random_spd(rng, 6), np.zeros(6), np.ones((6, 2)), np.ones((6, 2)), np.zeros(2)
    M_o, h_o = random_object_inertia(rng), np.zeros(6)
    SystemBlocks.from_lists([M], [h], [W], [Wo], [c], M_o, h_o)  # fine
    cases = [
        (([M], [h], [W], [Wo], [c, c], M_o, h_o), "c_list has 2 entries"),
        (([M[:5]], [h], [W], [Wo], [c], M_o, h_o), "square"),
        (([M], [h], [W[:5]], [Wo], [c], M_o, h_o), r"W_list\[0\]"),
        (([M], [h], [W], [Wo[:5]], [c], M_o, h_o), r"W_o_list\[0\]: expected shape \(6, 2\)"),
        (([M], [h[:3]], [W], [Wo], [c], M_o, h_o), r"h_list\[0\]"),
        (([M], [h], [W], [Wo], [c], M_o[:3], h_o), "M_o"),
        (([M], [h], [W], [Wo], [np.array([np.nan, 0])], M_o, h_o), "NaN"),
        (([], [], [], [], [], M_o, h_o), "at least one arm"),
        (([M], [h], [W], [Wo], [["a", "b"]], M_o, h_o), "numbers"),
    ]
    for args, match in cases:
        with pytest.raises(InputError, match=match):
            SystemBlocks.from_lists(*args)


def test_constructor_rejects_bad_shapes_and_padding():
    blocks, _, _ = random_system(np.random.default_rng(4), [6, 7], [3, 4])
    f = {k: getattr(blocks, k) for k in ("M", "h", "W", "W_o", "c", "M_o", "h_o", "nv", "N")}
    with pytest.raises(InputError, match=r"W_o: expected shape \(2, 6, 4\)"):
        SystemBlocks(**{**f, "W_o": f["W_o"][:, :5]})
    with pytest.raises(InputError, match="nv: expected values in"):
        SystemBlocks(**{**f, "nv": np.array([6, 8])})
    with pytest.raises(InputError, match="float64"):
        SystemBlocks(**{**f, "h": f["h"].tolist()})
    W = f["W"].copy()
    W[0, 6, 0] = 1.0  # arm 0 has 6 joints: row 6 is padding
    with pytest.raises(InputError, match="padding in W"):
        SystemBlocks(**{**f, "W": W}).check_padding()


def test_singular_mass_matrices_raise():
    blocks, _, _ = random_system(np.random.default_rng(6), [6, 6], [3, 3])
    f = {k: getattr(blocks, k) for k in ("M", "h", "W", "W_o", "c", "M_o", "h_o", "nv", "N")}
    M_o = f["M_o"].copy()
    M_o[3:, 3:] = 0.0
    for solver in ("auto", "object_first", "singular"):
        with pytest.raises(InputError, match="M_o"):
            solve(SystemBlocks(**{**f, "M_o": M_o}), solver)
    M = f["M"].copy()
    M[1] = 0.0
    for solver in ("auto", "object_first", "singular"):
        with pytest.raises(DynamicsError, match=r"M_i of arm\(s\) \[1\]"):
            solve(SystemBlocks(**{**f, "M": M}), solver)
    with pytest.raises(DynamicsError):
        solve(SystemBlocks(**{**f, "M": M}), "dense_kkt")


def test_with_torques_adds_to_h():
    blocks, _, _ = random_system(np.random.default_rng(8), [6, 7], [3, 4])
    tau = np.zeros((2, 7))
    tau[0, :6] = 1.0
    h_before = blocks.h.copy()
    driven = blocks.with_torques(tau)
    assert np.array_equal(driven.h, blocks.h + tau)
    assert np.array_equal(blocks.h, h_before)  # the original blocks are untouched
    for name in ("M", "W", "W_o", "c", "M_o", "h_o", "nv", "N", "dof_mask", "constraint_mask"):
        assert np.array_equal(getattr(driven, name), getattr(blocks, name))
    assert np.allclose(solve(driven, "object_first").qdd, solve(driven, "dense_kkt").qdd)
    tau[0, 6] = 1.0
    with pytest.raises(InputError, match="padded"):
        blocks.with_torques(tau)
