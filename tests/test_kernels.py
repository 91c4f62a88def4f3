"""Compiled hot path (multiarm_pin._compiled) against the numpy reference implementation.

The numpy path (``MultiArmSystem.blocks(..., reference=True)``: ``ArmSet.evaluate``,
``ConstraintSet.evaluate``, einsum assembly; solver ``object_first_numpy``) is itself tested
against per-arm Pinocchio, per-joint formulas and finite differences elsewhere; here the
compiled path must reproduce it to 1e-12 (relative) on random systems with every joint type,
both robots (UR5 6-dof, Panda 7-dof: padding), tips on the tool and on the object, planes,
spheres and cylinders (outside and inside), with and without Baumgarte, and must keep the
singular-arm fallback and the error behaviour.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest
from dynamics.synthetic import random_system
from numba.core import config
from system_builders import JOINT_KINDS, build_system, joint_spec, moving_state

from multiarm_pin._compiled import controller_kernels, evaluate, layout, linalg, phased
from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.object_first import (
    SOLVE_ARM_SINGULAR,
    SOLVE_OBJECT_SINGULAR,
    SOLVE_OK,
    object_first,
)
from multiarm_pin.constraints import custom
from multiarm_pin.dynamics import DEFAULT_RCOND_TOL, SystemBlocks, reduce_arms, solve
from multiarm_pin.exceptions import DynamicsError, InputError, SingularityError
from multiarm_pin.model.rigid_object import ObjectState
from multiarm_pin.system import SystemState

TOL = 1e-12

SOCKETS = [  # curved surfaces, inside and outside, tips on both bodies
    {"point": [0.1, 0, 0], "surface": {"type": "sphere", "center": [0, 0, 0], "radius": 0.1,
                                       "inside": True},
     "tip_radius": 0.01, "points_on": "object"},
    {"point": [0, 0.1, 0], "surface": {"type": "sphere", "center": [0, 0, 0], "radius": 0.1,
                                       "inside": True}},
    {"point": [0.05, 0.2, 0.3], "surface": {"type": "cylinder", "center": [0, 0.2, 0],
                                            "axis": [0, 0, 1], "radius": 0.05,
                                            "inside": True},
     "tip_radius": 0.005},
    {"point": [0.0, -0.2, 0.1], "surface": {"type": "sphere", "center": [0, -0.3, 0.1],
                                            "radius": 0.1}, "points_on": "object"},
    {"point": [0.05, -0.05, 0.05], "surface": {"type": "plane", "point": [0, 0, 0.05],
                                               "normal": [1, 1, 0]},
     "points_on": "object", "tip_radius": 0.02},
]


def sockets(oMt: pin.SE3, oMo: pin.SE3):
    """A custom joint of SOCKETS whose frame is the tool frame at t = 0."""
    return custom(SOCKETS, oMo.actInv(oMt), name="sockets")


def random_spec(rng, kind: str):
    if kind == "sockets":
        return sockets
    spec = joint_spec(kind)
    if kind not in ("fingertips", "corner_gripper") and rng.random() < 0.5:
        spec = {**spec, "points_on": "object"}
    return spec


def random_system_and_state(seed: int, n_arms: int):
    """Mixed robots and joints, a random consistent moving state, moved slightly off the
    constraint manifold so that φ and φ̇ are not zero (Baumgarte terms matter)."""
    rng = np.random.default_rng(seed)
    robots = [("ur5", "panda")[int(rng.integers(2))] for _ in range(n_arms)]
    kinds = [(JOINT_KINDS + ["sockets"])[int(rng.integers(len(JOINT_KINDS) + 1))]
             for _ in range(n_arms)]
    q = rng.normal(size=4)
    system, state = build_system(robots, [random_spec(rng, k) for k in kinds], rng,
                                 gravity=(0.3, -1.0, -9.0), object_quaternion=q / np.linalg.norm(q))
    state = moving_state(system, state, rng)
    o = state.obj
    off = SystemState(state.q + 1e-3 * rng.normal(size=system.nq),
                      state.v + 0.1 * rng.normal(size=system.nv),
                      ObjectState(o.position + 1e-3 * rng.normal(size=3), o.quaternion, o.twist))
    return system, state, off, rng.normal(size=system.nv)


def assert_close(a, b, name):
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape, f"{name}: shape {a.shape} != {b.shape}"
    if a.dtype.kind in "bi":
        np.testing.assert_array_equal(a, b, err_msg=name)
        return
    err = np.abs(a - b).max(initial=0.0)
    assert err <= TOL * max(1.0, np.abs(b).max(initial=0.0)), f"{name}: {err:.3g}"


BLOCK_FIELDS = ("M", "h", "W", "W_o", "c", "M_o", "h_o", "nv", "N", "dof_mask",
                "constraint_mask", "padding_diagonal")
ROW_FIELDS = ("phi", "phi_dot", "kappa", "G_tool", "G_object", "contact_points", "normals",
              "N", "mask")
ARM_FIELDS = ("M", "nle", "J", "Jdot_qdot", "v")


def assert_evaluations_equal(ev, ref):
    for f in BLOCK_FIELDS:
        assert_close(getattr(ev.blocks, f), getattr(ref.blocks, f), f"blocks.{f}")
    assert ev.blocks.has_constraint_padding == ref.blocks.has_constraint_padding
    for f in ROW_FIELDS:
        assert_close(getattr(ev.constraints, f), getattr(ref.constraints, f), f"constraints.{f}")
    for f in ARM_FIELDS:
        assert_close(getattr(ev.arms, f), getattr(ref.arms, f), f"arms.{f}")
    for f in ("position", "rotation", "twist"):
        assert_close(getattr(ev.arms.tools, f), getattr(ref.arms.tools, f), f"tools.{f}")


# ------------------------------------------------------------------ blocks
@pytest.mark.parametrize("seed,n_arms", [(s, 1 + s % 8) for s in range(10)])
def test_compiled_blocks_equal_numpy_reference(seed, n_arms):
    system, state, off, tau = random_system_and_state(seed, n_arms)
    for st in (state, off):
        for baumgarte in (None, (3.0, 4.0)):
            for t in (None, tau):
                ev = system.blocks(st, t, baumgarte)
                ref = system.blocks(st, t, baumgarte, reference=True)
                assert_evaluations_equal(ev, ref)
    # the comparison is not vacuous: off the manifold, Baumgarte changes c
    ev0, ev1 = system.blocks(off), system.blocks(off, None, (3.0, 4.0))
    assert np.abs(ev0.blocks.c - ev1.blocks.c).max() > 1e-6
    assert np.abs(ev0.constraints.phi).max() > 1e-6


def test_every_surface_and_tip_placement_is_exercised():
    """The systems of the comparison above cover what the constraint kernel distinguishes."""
    seen = set()
    for seed in range(10):
        system, *_ = random_system_and_state(seed, 1 + seed % 8)
        tables = system.constraint_set.contact_tables
        ints, floats = tables.ints, tables.floats
        for row_i, row_f in zip(ints, floats, strict=True):
            kind = ("plane" if row_f[layout.CF_IS_PLANE] else "curved",
                    "inside" if row_f[layout.CF_CURVATURE_SIGN] < 0 else "out",
                    "tool-tip" if row_i[layout.CI_TOOL_CARRIES] else "object-tip")
            seen.add(kind)
        seen.add(("padding", system.N_max > int(system.constraint_set.N.min())))
        seen.add(("dof padding", system.arm_set.nv_max > int(system.arm_set.nv_arm.min())))
    for needed in [("plane", "out", "tool-tip"), ("plane", "out", "object-tip"),
                   ("curved", "out", "tool-tip"), ("curved", "out", "object-tip"),
                   ("curved", "inside", "tool-tip"), ("curved", "inside", "object-tip"),
                   ("padding", True), ("dof padding", True)]:
        assert needed in seen, needed


def test_evaluations_do_not_alias_later_calls():
    system, state, off, tau = random_system_and_state(3, 4)
    ev = system.blocks(state, tau, (1.0, 2.0))
    sol, ev_fd = system.forward_dynamics(state, tau)
    keep = {f: getattr(ev.blocks, f).copy() for f in ("M", "h", "W", "W_o", "c", "M_o", "h_o")}
    phi = ev.constraints.phi.copy()
    a_o = sol.a_o.copy()
    system.blocks(off, -tau)
    system.forward_dynamics(off, -tau)
    for f, value in keep.items():
        np.testing.assert_array_equal(getattr(ev.blocks, f), value)
    np.testing.assert_array_equal(ev.constraints.phi, phi)
    np.testing.assert_array_equal(sol.a_o, a_o)
    assert sol.blocks is ev_fd.blocks


def test_lazy_views_behave_like_the_dataclasses():
    system, state, _, tau = random_system_and_state(5, 3)
    ev = system.blocks(state, tau)
    ref = system.blocks(state, tau, reference=True)
    assert isinstance(ev.blocks, SystemBlocks)
    assert ev.arms.M is ev.arms.M  # cached after the first access
    assert np.shares_memory(ev.arms.M, ev.blocks.M)
    for obj in (ev.blocks, ev.arms, ev.constraints):
        assert {f.name for f in dataclasses.fields(obj)} <= set(dir(obj))
    ev.blocks.check_padding()
    ev.blocks.check_finite()
    # the public constructor and with_torques still validate and work from the views
    b2 = ev.blocks.with_torques(system.pad(tau))
    np.testing.assert_allclose(b2.h, ev.blocks.h + system.pad(tau))
    with pytest.raises(InputError):
        ev.blocks.with_torques(np.zeros((1, 1)))
    rebuilt = SystemBlocks(*(getattr(ev.blocks, f) for f in BLOCK_FIELDS[:9]))
    assert_close(solve(rebuilt).qdd, solve(ref.blocks).qdd, "qdd")


def test_grouped_pinocchio_models_give_the_same_terms(monkeypatch):
    """Arms split over several combined Pinocchio models (as for > GROUP_SIZE arms)."""
    import multiarm_pin.model.arm_set as arm_set_module

    monkeypatch.setattr(arm_set_module, "GROUP_SIZE", 2)
    for seed, n_arms in ((21, 5), (22, 4)):
        system, state, off, tau = random_system_and_state(seed, n_arms)
        aset = system.arm_set
        assert [g.arms for g in aset.groups][:2] == [slice(0, 2), slice(2, 4)]
        assert len(aset.groups) == (n_arms + 1) // 2
        for st in (state, off):
            ev = system.blocks(st, tau, (1.0, 2.0))
            assert_evaluations_equal(ev, system.blocks(st, tau, (1.0, 2.0), reference=True))
            sol, _ = system.forward_dynamics(st, tau)
            ref = solve(system.blocks(st, tau, reference=True).blocks, "object_first_numpy")
            for f in ("a_o", "qdd", "mu"):
                assert_close(getattr(sol, f), getattr(ref, f), f)
        full = pin.computeGeneralizedGravity(aset.model, aset.data, state.q)
        assert_close(system.gravity_torques(state.q), full, "gravity")
        assert_close(aset.gravity(state.q), aset.pad_v(full), "padded gravity")
        tk = aset.tool_kinematics(state.q, state.v)
        ref_terms = aset.evaluate(state.q, state.v)
        for f in ("position", "rotation", "twist"):
            assert_close(getattr(tk, f), getattr(ref_terms.tools, f), f)
        for f in ("kinetic_energy", "potential_energy", "momentum"):  # per group vs all
            grouped = getattr(system, f)(off)
            monkeypatch.setattr(aset, "groups", [dataclasses.replace(
                aset.groups[0], model=aset.model, data=aset.data, arms=slice(0, n_arms),
                q=slice(0, system.nq), v=slice(0, system.nv))])
            assert_close(grouped, getattr(system, f)(off), f)
            monkeypatch.undo()
            monkeypatch.setattr(arm_set_module, "GROUP_SIZE", 2)
        with pytest.raises(InputError, match="group_size"):
            arm_set_module.ArmSet(system.arms, group_size=0)


# ------------------------------------------------------------------ solve
@pytest.mark.parametrize("seed,n_arms", [(s, 1 + (3 * s) % 8) for s in range(10, 18)])
def test_compiled_step_equals_numpy_solvers(seed, n_arms):
    system, state, _, tau = random_system_and_state(seed, n_arms)
    for baumgarte in (None, (2.0, 3.0)):
        ref_blocks = system.blocks(state, tau, baumgarte, reference=True).blocks
        ref = solve(ref_blocks, "object_first_numpy")
        kkt = solve(ref_blocks, "dense_kkt")
        for solver in ("auto", "object_first"):
            sol, ev = system.forward_dynamics(state, tau, solver, baumgarte)
            alone = solve(ev.blocks, solver)
            assert sol.solver == alone.solver == "object_first" and sol.singular_arms == ()
            for s in (sol, alone):
                for f in ("a_o", "qdd", "mu"):
                    assert_close(getattr(s, f), getattr(ref, f), f)
                    scale = np.abs(getattr(kkt, f)).max()
                    assert np.abs(getattr(s, f) - getattr(kkt, f)).max() <= 1e-9 * scale
                assert s.residuals().relative < 1e-11
                assert not s.qdd[~ev.blocks.dof_mask].any()
                assert not s.mu[~ev.blocks.constraint_mask].any()


def welded_ur5s(elbow: float):
    """Two UR5s welded to a box, arm 1 with its elbow at ``elbow`` rad (0: straight)."""
    from system_builders import make_arm

    from multiarm_pin.model.rigid_object import RigidObject
    from multiarm_pin.system import MultiArmSystem

    arms = [make_arm("ur5", f"w{i}", np.pi * i) for i in range(2)]
    q0 = [np.array([0.0, -1.2, 1.5, -1.9, -1.57, 0.0]),
          np.array([0.3, -1.2, elbow, -1.0, 0.7, 0.2])]
    obj = RigidObject.box((0.4, 0.3, 0.2), 5.0)
    system, state = MultiArmSystem.from_initial_state(
        arms, obj, ["weld", "weld"], q0, pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.3])))
    rng = np.random.default_rng(7)
    return system, moving_state(system, state, rng), rng.normal(size=system.nv)


def test_singular_arm_falls_back_exactly_as_before():
    system, state, tau = welded_ur5s(0.0)
    J = system.blocks(state).arms.J[1]
    assert np.linalg.svd(J, compute_uv=False)[-1] < 1e-12  # a genuine singularity
    b = system.blocks(state, tau).blocks
    out = (np.empty(6), np.empty((2, 6)), np.empty((2, 6)))
    status = object_first(b.M, b.h, b.W, b.W_o, b.c, b.M_o, b.h_o, b.N, 1e-7, 1e-7,
                                  *out)
    assert status == SOLVE_ARM_SINGULAR
    sol, _ = system.forward_dynamics(state, tau, "auto")
    assert sol.solver == "singular" and sol.singular_arms == (1,)
    ref = solve(system.blocks(state, tau, reference=True).blocks, "dense_kkt")
    for f in ("a_o", "qdd"):
        assert np.abs(getattr(sol, f) - getattr(ref, f)).max() < 1e-9 * np.abs(ref.qdd).max()
    assert solve(b, "auto").singular_arms == (1,)
    for call in (lambda: system.forward_dynamics(state, tau, "object_first"),
                 lambda: solve(b, "object_first")):
        with pytest.raises(SingularityError, match=r"arm\(s\) \[1\]"):
            call()


@pytest.mark.parametrize("elbow", [1e-1, 1e-2, 1e-3, 1e-5, 1e-8])
def test_near_singular_decision_matches_numpy(elbow):
    """Approaching the elbow singularity the compiled and numpy solvers switch alike."""
    system, state, tau = welded_ur5s(elbow)
    b = system.blocks(state, tau).blocks
    # a verdict by construction: every case keeps a factor >= 2 from the switching threshold
    # (closest: rcond 3.5e-8 at elbow 1e-3), far beyond what rounding changes in the estimate
    rcond = reduce_arms(b).rcond
    assert np.all((rcond > 2 * DEFAULT_RCOND_TOL) | (rcond < DEFAULT_RCOND_TOL / 2))
    auto = solve(b, "auto")
    sol, _ = system.forward_dynamics(state, tau, "auto")
    assert sol.solver == auto.solver
    try:
        ref = solve(b, "object_first_numpy")
    except SingularityError:
        ref = None
        with pytest.raises(SingularityError):
            solve(b, "object_first")
    if ref is not None:  # Cholesky vs LU: round-off amplified by cond(S_i) ~ 1/rcond here
        qdd = solve(b, "object_first").qdd
        assert np.abs(qdd - ref.qdd).max() < 1e-9 * np.abs(ref.qdd).max()
    kkt = solve(b, "dense_kkt")
    assert np.abs(sol.qdd - kkt.qdd).max() < 1e-9 * np.abs(kkt.qdd).max()


@pytest.mark.parametrize("heavy", [1e9, 1e12])
def test_badly_conditioned_object_matrix_is_flagged(heavy):
    rng = np.random.default_rng(3)
    b, _, _ = random_system(rng, [6], [5])
    big = SystemBlocks(b.M * heavy, b.h * heavy, b.W, b.W_o, b.c, b.M_o, b.h_o, b.nv, b.N)
    out = (np.empty(6), np.empty((1, 6)), np.empty((1, 5)))
    status = object_first(big.M, big.h, big.W, big.W_o, big.c, big.M_o, big.h_o,
                          big.N, 1e-7, 1e-7, *out)
    assert status == SOLVE_OBJECT_SINGULAR
    assert object_first(b.M, b.h, b.W, b.W_o, b.c, b.M_o, b.h_o, b.N, 1e-7, 1e-7,
                        *out) == SOLVE_OK
    with pytest.raises(SingularityError, match="reduced object matrix"):
        solve(big, "object_first")
    assert solve(big, "auto").solver == "singular"


# ------------------------------------------------------------------ small linear algebra
@pytest.mark.parametrize("size", [1, 3, 6, 7])
def test_cholesky_solve_and_inverse_diagonal(size):
    rng = np.random.default_rng(size)
    B = rng.normal(size=(size, size))
    A = B @ B.T + 0.1 * np.eye(size)
    L = np.zeros((size, size))
    assert linalg.cholesky(A, L, size)
    np.testing.assert_allclose(np.tril(L), np.linalg.cholesky(A), rtol=1e-12, atol=1e-13)
    X = rng.normal(size=(size, 3))
    Y = X.copy()
    linalg.cholesky_solve(L, Y, size, 3)
    np.testing.assert_allclose(A @ Y, X, atol=1e-10 * np.abs(X).max() * np.linalg.cond(A))
    d = np.empty(size)
    linalg.inverse_diagonal(L, size, d, np.empty(size))
    np.testing.assert_allclose(d, np.diag(np.linalg.inv(A)), rtol=1e-10)
    indefinite = A - 2 * np.linalg.eigvalsh(A)[-1] * np.eye(size)
    assert not linalg.cholesky(indefinite, L, size)
    A[0, 0] = np.nan
    assert not linalg.cholesky(A, L, size)


def _qr_factors(A):
    """``householder_qr`` of ``A`` (rows, cols) inside a larger array: ``(Q, R, untouched)``.

    ``Q`` (rows, rows) is rebuilt by ``householder_reflect`` from the identity's columns;
    ``untouched``: the entries outside the leading block kept their values.
    """
    rows, cols = A.shape
    r = min(rows, cols)
    big = np.full((rows + 2, cols + 1), 7.0)
    big[:rows, :cols] = A
    beta, diag = np.full(r + 1, 7.0), np.full(r + 1, 7.0)
    linalg.householder_qr(big, np.int64(rows), np.int64(cols), beta, diag)
    untouched = (np.all(big[rows:] == 7.0) and np.all(big[:, cols:] == 7.0)
                 and beta[r] == 7.0 and diag[r] == 7.0)
    R = np.triu(big[:rows, :cols], 1)
    R[np.arange(r), np.arange(r)] = diag[:r]
    Q = np.eye(rows)
    for i in range(rows):
        for j in range(r - 1, -1, -1):
            linalg.householder_reflect(big, np.int64(rows), np.int64(j), beta, Q[:, i])
    return Q, R, untouched


@pytest.mark.parametrize("shape", [(1, 1), (6, 3), (7, 7), (8, 5), (4, 6), (6, 12)])
def test_householder_qr_equals_numpy(shape):
    """``linalg.householder_qr`` (the QR of ``min_norm_rows`` and ``column_least_squares``)
    against LAPACK on random full-rank matrices: ``Q R = A``, ``Q`` orthogonal, ``R`` that of
    ``np.linalg.qr`` (same sign rule but on a square or wide block's last row), and least
    squares / minimum-norm solutions equal to ``np.linalg.lstsq``'s."""
    rows, cols = shape
    rng = np.random.default_rng(rows * 31 + cols)
    A = rng.normal(size=shape) * 10.0 ** rng.uniform(-2, 2)
    Q, R, untouched = _qr_factors(A)
    scale = np.abs(A).max()
    assert untouched
    assert np.abs(Q @ R - A).max() <= 1e-14 * 10 * scale
    assert np.abs(Q.T @ Q - np.eye(rows)).max() <= 1e-14 * 10
    r = min(shape)
    sign = np.ones((r, 1))
    if rows <= cols:  # LAPACK leaves the last row's one-entry column as it is
        sign[-1] = -1.0
    np.testing.assert_allclose(R[:r], sign * np.linalg.qr(A, mode="r"), rtol=0,
                               atol=1e-12 * scale * np.linalg.cond(A))
    f = rng.normal(size=rows)
    if cols <= rows:  # the least squares of column_least_squares
        out = np.empty(cols)
        phased.column_least_squares(A, np.arange(cols), np.int64(cols), f, out)
        want = np.linalg.lstsq(A, f, rcond=None)[0]
        assert np.abs(out - want).max() <= 1e-12 * np.linalg.cond(A) * np.abs(want).max()
    if cols <= rows:  # the minimum-norm x of Aᵀ x = g (min_norm_rows)
        g = rng.normal(size=cols)
        x = np.empty(rows)
        assert controller_kernels.min_norm_rows(A, np.int64(cols), np.int64(rows), g, x,
                                                np.empty(shape), np.empty(cols))
        want = np.linalg.lstsq(A.T, g, rcond=None)[0]
        assert np.abs(x - want).max() <= 1e-12 * np.linalg.cond(A) * np.abs(want).max()


@pytest.mark.parametrize("r, s, c", [(6, 6, 1), (6, 3, 0), (1, 6, 4), (6, 0, 2), (3, 5, 7)])
def test_mat_vec_and_mat_mat_equal_numpy(r, s, c):
    """``linalg.mat_vec`` and ``mat_mat`` (the products of ``phased``'s kernels) equal numpy's
    ``@`` to round-off, empty dimensions included (a product over none is zero)."""
    rng = np.random.default_rng(100 * r + 10 * s + c)
    A, B, x = rng.normal(size=(r, s)), rng.normal(size=(s, c)), rng.normal(size=s)
    out = np.full(r, np.nan)
    linalg.mat_vec(A, x, out)
    np.testing.assert_allclose(out, A @ x, rtol=0, atol=1e-14 * max(1, s))
    prod = np.full((r, c), np.nan)
    linalg.mat_mat(A, B, prod)
    np.testing.assert_allclose(prod, A @ B, rtol=0, atol=1e-14 * max(1, s))


@pytest.mark.parametrize("rows, cols, rank", [(6, 4, 4), (6, 4, 2), (3, 5, 3), (5, 5, 0)])
def test_spectral_solve_is_the_pseudo_inverse_solve(rows, cols, rank):
    """``linalg.spectral_solve`` on a thin SVD, and on the eigendecomposition of a symmetric
    indefinite matrix, is the pseudo-inverse solve at the matrix's rank. The matrices are
    made from their factors: kept values of magnitude 1 to 3, dropped ones exactly 0 (their
    computed values at round-off, 1e-15 or less), the tolerance 1e-8 between them."""
    rng = np.random.default_rng(10 * rows + cols + rank)
    Q1 = np.linalg.qr(rng.normal(size=(rows, rows)))[0][:, :rank]
    Q2 = np.linalg.qr(rng.normal(size=(cols, cols)))[0][:, :rank]
    sigma = rng.uniform(1.0, 3.0, size=rank)
    A = (Q1 * sigma) @ Q2.T
    f = rng.normal(size=rows)
    U, sv, Vt = np.linalg.svd(A, full_matrices=False)
    out = np.full(cols, np.nan)
    linalg.spectral_solve(U, sv, Vt, f, 1e-8, out)
    np.testing.assert_allclose(out, (Q2 / sigma) @ (Q1.T @ f), rtol=0, atol=1e-12)
    e = sigma * np.where(np.arange(rank) % 2, -1.0, 1.0)  # eigenvalues of both signs
    S = (Q2 * e) @ Q2.T
    ev, V = np.linalg.eigh(S)
    g = rng.normal(size=cols)
    sym = np.full(cols, np.nan)
    linalg.spectral_solve(V, ev, np.ascontiguousarray(V.T), g, 1e-8, sym)
    np.testing.assert_allclose(sym, (Q2 / e) @ (Q2.T @ g), rtol=0, atol=1e-12)


@pytest.mark.parametrize("rows, cols, zero", [(6, 4, [1]), (7, 7, [0, 5]), (6, 3, [0, 1, 2]),
                                              (3, 5, []), (4, 6, [2])])
def test_column_least_squares_without_full_column_rank_equals_lstsq(rows, cols, zero):
    """Columns of zeros (their QR pivot is exactly 0) or more columns than rows: by
    construction not of full column rank, so ``column_least_squares`` takes
    ``np.linalg.lstsq``'s minimum-norm solution at its rank (``rcond = eps max(p, n)``); on a
    subset of ``E``'s columns in shuffled order, the entries past ``n`` untouched."""
    rng = np.random.default_rng(rows * 17 + cols + 100 * len(zero))
    A = rng.normal(size=(rows, cols)) * 3.0
    A[:, zero] = 0.0
    E = np.zeros((rows, cols + 2))
    order = rng.permutation(cols + 2)[:cols]
    E[:, order] = A
    f = rng.normal(size=rows)
    out = np.full(cols + 1, np.nan)
    phased.column_least_squares(E, order, np.int64(cols), f, out)
    want = np.linalg.lstsq(A, f, rcond=np.finfo(float).eps * max(rows, cols))[0]
    assert np.abs(out[:cols] - want).max() <= 1e-10 * max(1.0, np.abs(want).max())
    assert np.isnan(out[cols])


@pytest.mark.parametrize("shape, rank", [((6, 3), 2), ((7, 7), 4), ((8, 5), 1), ((4, 6), 3)])
def test_householder_qr_shows_rank_deficiency_with_margin(shape, rank):
    """Rank deficient by construction (``A = B C``, inner size ``rank``, columns in general
    position): ``R``'s first ``rank`` pivots stay above 1e-3 of the largest, the rest and
    ``R``'s trailing rows fall to round-off (below 1e-12: five orders under
    ``RANK_MARGIN``, which ``min_norm_rows`` then refuses); ``Q R = A`` still, and ``R``'s
    leading rows are ``np.linalg.qr``'s."""
    rows, cols = shape
    rng = np.random.default_rng(rows * 31 + cols + 1000 * rank)
    A = rng.normal(size=(rows, rank)) @ rng.normal(size=(rank, cols))
    assert np.linalg.matrix_rank(A) == rank
    Q, R, untouched = _qr_factors(A)
    scale = np.abs(A).max()
    assert untouched
    assert np.abs(Q @ R - A).max() <= 1e-14 * 10 * scale
    pivots = np.abs(np.diag(R))
    assert pivots[:rank].min() >= 1e-3 * pivots.max()
    assert np.abs(R[rank:]).max() <= 1e-12 * pivots.max()
    np.testing.assert_allclose(R[:rank], np.linalg.qr(A, mode="r")[:rank], rtol=0,
                               atol=1e-10 * scale)
    if cols <= rows:
        assert not controller_kernels.min_norm_rows(A, np.int64(cols), np.int64(rows),
                                                    np.ones(cols), np.empty(rows),
                                                    np.empty(shape), np.empty(cols))


# ------------------------------------------------------------------ errors
def test_bad_input_raises_the_same_clear_errors():
    system, state, _, tau = random_system_and_state(2, 2)
    o = state.obj
    bad_q = state.q.copy()
    bad_q[1] = np.nan
    bad_twist = o.twist.copy()
    bad_twist[4] = np.inf
    bad_tau = tau.copy()
    bad_tau[0] = np.nan
    cases = [
        (SystemState(bad_q, state.v, o), None, DynamicsError, "arms' q"),
        (SystemState(state.q, state.v, ObjectState(o.position, o.quaternion, bad_twist)), None,
         DynamicsError, "object twist"),
        (state, bad_tau, DynamicsError, "tau"),
        (state, tau[:-1], InputError, "tau"),
        (SystemState(state.q[:-1], state.v, o), None, InputError, "arms' q"),
        ("not a state", None, InputError, "SystemState"),
    ]
    for st, t, exc, text in cases:
        for call in (lambda st=st, t=t: system.blocks(st, t),
                     lambda st=st, t=t: system.blocks(st, t, reference=True),
                     lambda st=st, t=t: system.forward_dynamics(st, t)):
            with pytest.raises(exc, match=text):
                call()
    with pytest.raises(InputError, match="baumgarte"):
        system.forward_dynamics(state, tau, baumgarte=(-1.0, 2.0))
    with pytest.raises(InputError, match="unknown solver"):
        system.forward_dynamics(state, tau, solver="nope")


def test_layout_covers_the_buffer():
    off, size = layout.buffer_layout(3, 7, 5)
    shapes = layout.segment_shapes(3, 7, 5)
    assert list(shapes) == list(layout.SEGMENTS)
    assert off[0] == 0 and off[-1] == size
    assert all(off[j + 1] - off[j] == np.prod(shapes[s])
               for j, s in enumerate(layout.SEGMENTS))


def test_compiled_views_are_the_python_segments():
    """The kernels' views (numba, from SHAPE_CODES) and Python's (from SEGMENT_TABLE) agree."""
    n, k, m = 3, 7, 5
    segments = layout.segment_slices(n, k, m)
    buf = np.arange(float(segments["mu"].stop))
    off = layout.offsets(layout.dims_vector(k, m, 0, n))
    arms = evaluate.arm_views(buf, off, n, k, m)
    blocks = evaluate.block_views(buf, off, n, k, m)
    solution = evaluate.solution_views(buf, off, n, k, m)
    names = ("M", "nle", "J", "Jdot_qdot", "position", "rotation", "twist", "v", "rows", "h",
             "W", "W_o", "c", "M_o", "h_o", "a_o", "qdd", "mu")
    assert names == layout.SEGMENTS
    for name, view in zip(names, (*arms, *blocks, *solution), strict=True):
        np.testing.assert_array_equal(view, segments[name].view(buf), err_msg=name)
    assert layout.ROW_WIDTH == sum(w for _, w in layout.ROW_FIELDS) == 21
    assert layout.N_PARAMS == 18 and layout.CONTACT_FLOATS == 14


@kernel
def _shaped_and_reshaped(buf, start, n, k):  # pragma: no cover - compiled
    return (layout.shaped(buf, start, (n, k)), buf[start:start + n * k].reshape((n, k)),
            layout.shaped(buf, start + 1, (n * k - 1,)))


@pytest.mark.skipif(config.DISABLE_JIT, reason="the compiled view's type needs the JIT")
def test_shaped_is_the_slice_reshaped():
    """``layout.shaped`` in a kernel: ``buf[start:start + size].reshape(shape)``, the same
    memory, strides and numba type, and writable through it."""
    buf = np.arange(20.0)
    view, reshaped, flat = _shaped_and_reshaped(buf, 3, 2, 5)
    np.testing.assert_array_equal(view, reshaped)
    assert view.strides == reshaped.strides == (40, 8) and np.shares_memory(view, buf)
    np.testing.assert_array_equal(flat, buf[4:13])
    types = _shaped_and_reshaped.nopython_signatures[0].return_type.types
    assert types[0] == types[1]
    view[1, 2] = -1.0
    assert buf[3 + 5 + 2] == -1.0


def test_compiled_evaluation_is_read_only_views_of_one_buffer():
    """Blocks, arm terms and rows of the compiled path share one buffer and cannot be set."""
    system, state, _, tau = random_system_and_state(1, 3)
    ev = system.blocks(state, tau)
    assert np.shares_memory(ev.blocks.M, ev.arms.M)
    assert all(np.shares_memory(a, ev.blocks.buffer) for a in (ev.constraints.phi, ev.arms.J))
    with pytest.raises(AttributeError, match="read-only"):
        ev.blocks.h = ev.blocks.h + 1.0
    with pytest.raises(AttributeError, match="read-only"):
        ev.constraints.phi = ev.constraints.phi
    more = ev.blocks.dof_mask.astype(float)
    shifted = ev.blocks.with_torques(more)
    assert type(shifted) is type(ev.blocks) and np.shares_memory(shifted.W, ev.blocks.W)
    np.testing.assert_array_equal(shifted.h, ev.blocks.h + more)
    tables = system.constraint_set.contact_tables
    assert tables is system.constraint_set.contact_tables  # built once
    assert not tables.ints.flags.writeable and not tables.floats.flags.writeable


@pytest.mark.parametrize("cols", [1, 3, 5, 6, 7, 11])
@pytest.mark.parametrize("rank", [6, 5, 3])
def test_singular_values_equal_numpy_svd(cols, rank):
    """One-sided Jacobi (``linalg.singular_values``, the grasp-rank kernel's) against LAPACK,
    full-rank and rank-deficient 6 x c matrices with spread singular values."""
    rng = np.random.default_rng(100 * cols + rank)
    U, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    V, _ = np.linalg.qr(rng.normal(size=(cols, cols)))
    k = min(rank, cols)
    s = np.zeros(min(6, cols))
    s[:k] = 10.0 ** rng.uniform(-6, 2, size=k)
    A = U[:, :len(s)] @ np.diag(s) @ V[:, :len(s)].T
    out = np.empty(cols)
    linalg.singular_values(A.copy(), out)
    got = np.sort(out)[::-1][:len(s)]
    want = np.linalg.svd(A, compute_uv=False)
    assert np.abs(got - want).max() <= 1e-13 * want[0]
    assert np.sort(out)[::-1][len(s):].max(initial=0.0) <= 1e-13 * want[0]  # c > 6: zeros
