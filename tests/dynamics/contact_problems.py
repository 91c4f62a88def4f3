"""Shared helpers of the unilateral-contact tests: random contact problems and references.

The references here never use the object-first Delassus operator: they build the dense mass
matrix and constraint Jacobian over all arms and solve the equality problems of an active
set with a dense least-squares KKT solve.
"""

from __future__ import annotations

import itertools

import numpy as np

from multiarm_pin.dynamics import SystemBlocks

from .synthetic import random_object_inertia, random_spd


def box_bottom_rows(half: tuple[float, float, float], n_points: int = 4) -> np.ndarray:
    """W_o columns (6, n_points) of a box's bottom vertices on a table (normal +z).

    The box (half extents ``half`` [m]) is axis-aligned with its COM at the origin; the
    vertices are ``(±a, ±b, -c)``. Row ``k``'s wrench per unit force is ``[z; r_k × z]``.
    Four vertices span only a 3-D space (z force, x and y moments): redundant by construction.
    """
    a, b, c = half
    verts = [(-a, -b, -c), (a, -b, -c), (a, b, -c), (-a, b, -c)][:n_points]
    z = np.array([0.0, 0.0, 1.0])
    return np.array([np.concatenate((z, np.cross(v, z))) for v in verts]).T


def random_contact_problem(
    rng: np.random.Generator,
    nv: list[int],
    N: list[int],
    p_bilateral: float = 0.3,
    redundant: bool = False,
) -> tuple[SystemBlocks, np.ndarray]:
    """A random feasible mixed contact problem; arms with ``nv = 0`` act on the object only.

    Bilateral rows get ``c`` consistent with a random motion ``v*``; unilateral rows get
    ``c = A v* - s`` with random slack ``s ≥ 0``, so ``v*`` is strictly feasible. With
    ``redundant``, the last row of the first arm with at least 3 rows is replaced by a
    positive combination of two of its other rows (dependent by construction).

    Returns:
        The blocks and the (n, N_max) unilateral mask.
    """
    Ms, hs, Ws, Wos, cs, unis = [], [], [], [], [], []
    a = rng.standard_normal(6)
    done = False
    for k, m in zip(nv, N, strict=True):
        Ms.append(random_spd(rng, k) if k else np.zeros((0, 0)))
        hs.append(rng.standard_normal(k))
        Wi = rng.standard_normal((k, m))
        Woi = rng.standard_normal((6, m))
        if redundant and not done and m >= 3:
            w1, w2 = rng.uniform(0.3, 1.0, 2)
            Wi[:, -1] = w1 * Wi[:, 0] + w2 * Wi[:, 1]
            Woi[:, -1] = w1 * Woi[:, 0] + w2 * Woi[:, 1]
            done = True
        q = rng.standard_normal(k)
        uni = rng.uniform(size=m) >= p_bilateral
        ci = Woi.T @ a + Wi.T @ q - np.where(uni, rng.uniform(0.0, 2.0, m), 0.0)
        Ws.append(Wi)
        Wos.append(Woi)
        cs.append(ci)
        unis.append(uni)
    assert done or not redundant
    blocks = SystemBlocks.from_lists(
        Ms, hs, Ws, Wos, cs, random_object_inertia(rng), 5.0 * rng.standard_normal(6)
    )
    return blocks, pad_rows(blocks, unis, False)


def pad_rows(blocks: SystemBlocks, rows: list, fill) -> np.ndarray:
    """Per-arm row arrays -> (n, N_max) with ``fill`` on padding."""
    dtype = bool if isinstance(fill, bool) else float
    out = np.full((blocks.n, blocks.N_max), fill, dtype=dtype)
    for i, r in enumerate(rows):
        out[i, : len(r)] = r
    return out


def dense_matrices(b: SystemBlocks) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Dense ``M`` (nt, nt), ``h`` (nt,), ``A`` (p, nt), ``c`` (p,) over the object and all arms.

    Velocity order ``[object (6), arm 0 (nv_0), arm 1, ...]``; rows arm-major real rows.
    """
    nt = 6 + int(b.nv.sum())
    M = np.zeros((nt, nt))
    h = np.zeros(nt)
    M[:6, :6] = b.M_o
    h[:6] = b.h_o
    A = np.zeros((b.n_constraints, nt))
    c = np.zeros(b.n_constraints)
    off, r = 6, 0
    for i in range(b.n):
        k, m = int(b.nv[i]), int(b.N[i])
        M[off : off + k, off : off + k] = b.M[i, :k, :k]
        h[off : off + k] = b.h[i, :k]
        A[r : r + m, :6] = b.W_o[i, :, :m].T
        A[r : r + m, off : off + k] = b.W[i, :k, :m].T
        c[r : r + m] = b.c[i, :m]
        off += k
        r += m
    return M, h, A, c


def split_motion(b: SystemBlocks, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dense velocity-ordered vector -> (a_o (6,), padded (n, nv_max))."""
    qdd = np.zeros((b.n, b.nv_max))
    off = 6
    for i in range(b.n):
        k = int(b.nv[i])
        qdd[i, :k] = v[off : off + k]
        off += k
    return v[:6].copy(), qdd


def oracle(b: SystemBlocks, unilateral: np.ndarray, active: np.ndarray | None = None,
           tol: float = 1e-9):
    """Exact mixed-LCP solution by enumerating the active sets of the unilateral rows.

    For every subset ``F`` of the active unilateral rows (largest first), solve the
    equality problem "bilateral rows and ``F`` have ``φ̈ = 0``, other multipliers 0" with a
    dense minimum-norm least-squares KKT solve, and accept it if it is consistent,
    ``μ_F ≥ 0`` and ``φ̈ ≥ 0`` on the other active unilateral rows (to ``tol`` relative).
    Any accepted set solves the problem (KKT conditions of a convex QP), so the motion is
    that of the first one found.

    Returns:
        ``(a_o (6,), qdd (n, nv_max), mu (n, N_max), n_tried)``.
    """
    M, h, A, c = dense_matrices(b)
    cm = b.constraint_mask
    act = cm if active is None else active
    uni = unilateral[cm]
    actf = act[cm]
    bil = np.flatnonzero(actf & ~uni)
    cand = np.flatnonzero(actf & uni)
    nt, p = M.shape[0], A.shape[0]
    scale = max(np.abs(h).max(), np.abs(c).max(), 1.0)
    tried = 0
    for size in range(len(cand), -1, -1):
        for F in itertools.combinations(cand, size):
            tried += 1
            rows = np.concatenate((bil, np.array(F, dtype=int)))
            Ar = A[rows]
            K = np.block([[M, -Ar.T], [Ar, np.zeros((len(rows), len(rows)))]])
            rhs = np.concatenate((h, c[rows]))
            x, *_ = np.linalg.lstsq(K, rhs, rcond=1e-12)
            if np.abs(K @ x - rhs).max() > 1e-10 * scale * max(1.0, np.abs(x).max()):
                continue
            mu = np.zeros(p)
            mu[rows] = x[nt:]
            phi = A @ x[:nt] - c
            if (mu[list(F)] >= -tol * scale).all() and (phi[cand] >= -tol * scale).all():
                a_o, qdd = split_motion(b, x[:nt])
                return a_o, qdd, b.unflatten_mu(mu), tried
    raise AssertionError("oracle: no active set solves the problem")


def admm_lcp(G: np.ndarray, g: np.ndarray, tol: float = 1e-14) -> tuple[np.ndarray, bool, int]:
    """Pinocchio's ADMM contact solver on the plain LCP ``0 ≤ λ ⟂ G λ + g ≥ 0``.

    The recipe of ``../shared/PINOCCHIO_NOTES.md``: one dummy prismatic joint per row with
    lower limit 0, one joint-limit constraint selecting them all, the dense Delassus ``G``,
    the SPECTRAL update rule and all tolerances ``tol``. Whether ADMM meets 1e-14 within
    its 10000 iterations on a singular ``G`` depends on round-off (one of the scenario states
    meets it in 281 iterations with AVX-512 OpenBLAS and not at all with Prescott's): a test
    that asserts convergence asks for a tolerance it meets with a margin on every CPU.

    Returns:
        ``(λ (p,), converged, iterations)``.
    """
    import pinocchio as pin

    n = len(g)
    model = pin.Model()
    for j in range(n):
        jid = model.addJoint(0, pin.JointModelPX(), pin.SE3.Identity(), f"dummy{j}")
        model.appendBodyToJoint(jid, pin.Inertia.FromSphere(1.0, 0.1), pin.SE3.Identity())
    model.lowerPositionLimit = np.zeros(n)
    model.upperPositionLimit = np.full(n, 1e10)
    data = model.createData()
    cm = pin.JointLimitConstraintModel(model, pin.StdVec_Index(list(range(1, n + 1))))
    cm.makeSelectionFilteredByLimitProximity(np.zeros(n))
    cd = cm.createData()
    data.q_in = np.zeros(n)
    cm.calc(model, data, cd)
    assert cm.residualSize() == n and cm.lowerResidualSize() == n
    st = pin.ADMMSolverSettings()
    st.max_iterations = 10000
    st.admm_update_rule = pin.ADMMUpdateRule.SPECTRAL
    for name in ("absolute_complementarity_tol", "absolute_feasibility_tol",
                 "relative_complementarity_tol", "relative_feasibility_tol"):
        setattr(st, name, tol)
    res = pin.ADMMSolverResult()
    ok = pin.ADMMConstraintSolver(n).solve(
        pin.DelassusOperatorDense(G), g, pin.StdVec_ConstraintModel([pin.ConstraintModel(cm)]),
        pin.StdVec_ConstraintData([pin.ConstraintData(cd)]), st, res)
    return np.array(res.retrieveConstraintImpulses()), bool(ok), int(res.iterations)


def with_support_rows(b: SystemBlocks, W_support: np.ndarray) -> SystemBlocks:
    """The blocks plus one zero-dof support arm whose rows (``W_o`` columns, ``c = 0``) are
    given: (6, p) wrenches at the COM, world axes, per unit force."""
    arms = range(b.n)
    p = W_support.shape[1]
    return SystemBlocks.from_lists(
        [b.M[i, : b.nv[i], : b.nv[i]] for i in arms] + [np.zeros((0, 0))],
        [b.h[i, : b.nv[i]] for i in arms] + [np.zeros(0)],
        [b.W[i, : b.nv[i], : b.N[i]] for i in arms] + [np.zeros((0, p))],
        [b.W_o[i, :, : b.N[i]] for i in arms] + [W_support],
        [b.c[i, : b.N[i]] for i in arms] + [np.zeros(p)],
        b.M_o, b.h_o)


def two_gripper_table_states(n_states: int, seed: int) -> list[SystemBlocks]:
    """Blocks of the two-gripper form-closure scenario (7 fingertip rows on two 6-joint arms)
    plus 4 table rows under the box's lowest vertices (a zero-dof support arm, ``c = 0``).

    Random consistent states (velocities projected on the constraints), torques = gravity
    compensation + 15 N squeeze per fingertip + N(0, 2 N m) noise.
    """
    from pathlib import Path

    from multiarm_pin.app.scenario import build_scenario, load_scenario
    from multiarm_pin.spatial import quaternion_to_rotation

    path = Path(__file__).resolve().parents[2] / "scenarios" / "two_gripper_form_closure.yaml"
    built = build_scenario(load_scenario(path))
    system, s0 = built.system, built.initial_state
    rng = np.random.default_rng(seed)
    g = system.gravity_torques(s0.q)
    z = np.array([0.0, 0.0, 1.0])
    out = []
    for _ in range(n_states):
        st = system.project_velocities(system.state(
            s0.q, rng.normal(0.0, 0.3, system.nv), s0.obj.position, s0.obj.quaternion,
            rng.normal(0.0, 0.1, 6)))
        b0 = system.blocks(st).blocks
        squeeze = np.concatenate([-b0.W[i, : b0.nv[i], : b0.N[i]] @ np.full(b0.N[i], 15.0)
                                  for i in range(b0.n)])
        b = system.blocks(st, g + squeeze + rng.normal(0.0, 2.0, system.nv)).blocks
        world = built.obj.shape.vertices @ quaternion_to_rotation(st.obj.quaternion).T
        low = np.argsort(world[:, 2], kind="stable")[:4]
        Wt = np.array([np.concatenate((z, np.cross(world[k], z))) for k in low]).T
        out.append(with_support_rows(b, Wt))
    return out


def two_gripper_table_pushing_states(
    n_states: int, seed: int, margin: float = 2.0,
) -> list[tuple[SystemBlocks, np.ndarray]]:
    """States of :func:`two_gripper_table_states`'s system built so that every row pushes.

    By construction, not by drawing and filtering: at a random consistent state (velocities
    projected on the constraints), the multipliers ``λ*`` are chosen first, every one at least
    ``margin`` [N], and the torques are then solved for so that ``λ*`` and the motion they
    give satisfy every row with ``φ̈ = 0``:

    1. fingertip forces ``λ_f ~ U[margin, 4 margin]`` [N];
    2. table forces ``λ_t``: the table is a zero-dof support, so its rows hold only if the
       object's acceleration ``a_o = M_o⁻¹ (h_o + W_o,f λ_f + W_t λ_t)`` has ``W_tᵀ a_o = c_t``:
       three independent equations in four unknowns (the coplanar rows are redundant); of the
       line of solutions, the point with the largest smallest entry is taken, and the state is
       redrawn when that entry is below ``margin``;
    3. each arm's joint acceleration ``q̈_i``: the least-norm solution of its rows,
       ``W_iᵀ q̈_i = c_i - W_o,iᵀ a_o``;
    4. the torques ``τ_i = M_i q̈_i - h_i(0) - W_i λ_i`` (``M q̈ = h + W λ``, ``h`` containing ``τ``).

    Then ``(a_o, q̈, λ*)`` solves the unilateral problem with every row pushing by at least
    ``margin``, and since its motion is unique (``G`` is PSD), it is *the* motion: the
    verdict "every row pushes" does not rest on round-off.

    Returns:
        ``(blocks, motion)`` pairs, ``motion`` the constructed dense ``[a_o; q̈_0; q̈_1]``.
    """
    from pathlib import Path

    from multiarm_pin.app.scenario import build_scenario, load_scenario
    from multiarm_pin.spatial import quaternion_to_rotation

    path = Path(__file__).resolve().parents[2] / "scenarios" / "two_gripper_form_closure.yaml"
    built = build_scenario(load_scenario(path))
    system, s0 = built.system, built.initial_state
    rng = np.random.default_rng(seed)
    z = np.array([0.0, 0.0, 1.0])
    out: list[tuple[SystemBlocks, np.ndarray]] = []
    for _ in range(50 * n_states):
        if len(out) == n_states:
            break
        st = system.project_velocities(system.state(
            s0.q, rng.normal(0.0, 0.3, system.nv), s0.obj.position, s0.obj.quaternion,
            rng.normal(0.0, 0.1, 6)))
        b0 = system.blocks(st).blocks
        world = built.obj.shape.vertices @ quaternion_to_rotation(st.obj.quaternion).T
        low = np.argsort(world[:, 2], kind="stable")[:4]
        Wt = np.array([np.concatenate((z, np.cross(world[k], z))) for k in low]).T
        lam_f = [rng.uniform(margin, 4.0 * margin, int(b0.N[i])) for i in range(b0.n)]
        w_f = b0.h_o + sum(b0.W_o[i, :, : b0.N[i]] @ lam_f[i] for i in range(b0.n))
        Minv = np.linalg.inv(b0.M_o)
        # W_tᵀ M_o⁻¹ (w_f + W_t λ_t) = 0 (c_t = 0): λ_t = λ_p + s n on the solution line
        K = Wt.T @ Minv @ Wt
        lam_p, *_ = np.linalg.lstsq(K, -Wt.T @ Minv @ w_f, rcond=1e-10)
        n = np.linalg.svd(Wt)[2][-1]  # null vector of W_t (4 coplanar rows: rank 3)
        # the s maximising min(λ_p + s n): the best of the pairwise crossings of the lines
        cands = [(lam_p[j] - lam_p[k]) / (n[k] - n[j])
                 for j in range(4) for k in range(j + 1, 4) if abs(n[k] - n[j]) > 1e-6]
        s = max(cands, key=lambda v: (lam_p + v * n).min())
        lam_t = lam_p + s * n
        if lam_t.min() < margin:
            continue
        a_o = Minv @ (w_f + Wt @ lam_t)
        assert np.abs(Wt.T @ a_o).max() < 1e-9 * max(1.0, np.abs(a_o).max())
        taus, qdds = [], []
        for i in range(b0.n):
            k, m = int(b0.nv[i]), int(b0.N[i])
            Wi = b0.W[i, :k, :m]
            qdd_i, *_ = np.linalg.lstsq(Wi.T, b0.c[i, :m] - b0.W_o[i, :, :m].T @ a_o,
                                        rcond=None)
            taus.append(b0.M[i, :k, :k] @ qdd_i - b0.h[i, :k] - Wi @ lam_f[i])
            qdds.append(qdd_i)
        b = system.blocks(st, np.concatenate(taus)).blocks
        out.append((with_support_rows(b, Wt), np.concatenate([a_o, *qdds])))
    assert len(out) == n_states, "two_gripper_table_pushing_states: too few states pushed"
    return out
