"""Impacts (velocity-level Newton restitution) on blocks: closed forms, energy, enumeration."""

from __future__ import annotations

import numpy as np
import pytest

from multiarm_pin.dynamics import SystemBlocks, solve_impact
from multiarm_pin.exceptions import InputError

from .contact_problems import (
    box_bottom_rows,
    dense_matrices,
    oracle,
    pad_rows,
    random_contact_problem,
)


def support_blocks(Wo: np.ndarray, M_o: np.ndarray) -> SystemBlocks:
    """A free object whose rows all belong to one zero-dof support arm."""
    p = Wo.shape[1]
    return SystemBlocks.from_lists([np.zeros((0, 0))], [np.zeros(0)], [np.zeros((0, p))],
                                   [Wo], [np.zeros(p)], M_o, np.zeros(6))


def kinetic_energy(b: SystemBlocks, v_o: np.ndarray, qd: np.ndarray) -> float:
    return 0.5 * (v_o @ b.M_o @ v_o + np.einsum("ni,nij,nj->", qd, b.M, qd))


@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_box_dropped_flat(e):
    """A box falling flat with speed v hits a table on its four bottom vertices at once.

    The rows ``[z; r_k × z]`` span z-force and x, y moments only (4 rows, rank 3). By
    symmetry the impulse is a pure vertical impulse through the COM: ``Δv_z = P_tot / m``,
    ``Δω = 0``. Newton's law on every vertex (``φ̇⁻ = -v``) ``φ̇⁺ = -e φ̇⁻ = e v`` gives
    ``v_z⁺ = e v``, ``P_tot = m (1 + e) v``. A fifth row, a wall the box moves away from
    (``φ̇⁻ > 0``), gets no impulse and keeps its velocity. Kinetic energy: ``e²`` times.
    """
    m, v, e_wall = 2.5, 1.7, 0.5
    M_o = np.diag([m, m, m, 0.1, 0.2, 0.15])
    x = np.array([1.0, 0.0, 0.0])
    wall = np.concatenate((x, np.cross([0.3, 0.0, 0.0], x)))[:, None]
    Wo = np.hstack((box_bottom_rows((0.3, 0.2, 0.1)), wall))
    b = support_blocks(Wo, M_o)
    v_o = np.array([0.4, 0.0, -v, 0.0, 0.0, 0.0])
    vm = (Wo.T @ v_o)[None, :]
    assert np.allclose(vm, [[-v] * 4 + [0.4]])
    mask = b.constraint_mask.copy()
    rest = np.array([[e] * 4 + [e_wall]])
    sol = solve_impact(b, mask, mask, vm, rest)
    v_plus = v_o + sol.dv_o
    assert np.abs(v_plus - [0.4, 0.0, e * v, 0, 0, 0]).max() < 1e-13
    assert np.abs(sol.phi_dot_plus - [[e * v] * 4 + [0.4]]).max() < 1e-13
    assert abs(sol.P.sum() - m * (1 + e) * v) < 1e-12
    assert sol.P[0, 4] == 0.0 and (sol.P >= 0).all()
    assert sol.complementarity < 1e-12
    ke0 = kinetic_energy(b, v_o, np.zeros((1, 1)))
    ke1 = kinetic_energy(b, v_plus, np.zeros((1, 1)))
    assert abs((ke1 - 0.5 * m * 0.4**2) - e**2 * 0.5 * m * v**2) < 1e-12
    assert ke1 <= ke0 + 1e-12


@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("theta", [0.3, 1.0])
def test_tilted_rod_hits_floor(e, theta):
    """A rod (mass m, length L, ``I = m L²/12`` about y) in the xz plane at angle θ from
    the floor falls without rotating at speed v; its lower end ``r = (-d, 0, -L/2 sin θ)``,
    ``d = L/2 cos θ``, hits a frictionless floor (normal z).

    Row ``[z; r × z]`` with ``r × z = (0, d, 0)``: ``φ̇ = v_z + d ω_y``. An impulse ``P z``
    at the end gives ``Δv_z = P/m`` and ``Δω_y = d P / I``, so ``φ̇⁺ = φ̇⁻ + P (1/m + d²/I)``.
    Newton ``φ̇⁺ = -e φ̇⁻`` with ``φ̇⁻ = -v``: ``P = (1 + e) v / (1/m + d²/I)``,
    ``v_z⁺ = -v + P/m``, ``ω_y⁺ = d P / I``, ``v_x`` unchanged; for e = 1 the kinetic energy
    is conserved.
    """
    m, L, v, vx = 1.3, 0.8, 2.0, 0.25
    Iy = m * L * L / 12
    M_o = np.diag([m, m, m, Iy, Iy, 1e-3])
    r = np.array([-0.5 * L * np.cos(theta), 0.0, -0.5 * L * np.sin(theta)])
    z = np.array([0.0, 0.0, 1.0])
    Wo = np.concatenate((z, np.cross(r, z)))[:, None]
    d = 0.5 * L * np.cos(theta)
    assert np.allclose(Wo[3:, 0], [0.0, d, 0.0])
    b = support_blocks(Wo, M_o)
    v_o = np.array([vx, 0.0, -v, 0.0, 0.0, 0.0])
    vm = np.array([[-v]])
    sol = solve_impact(b, np.array([[True]]), np.array([[True]]), vm, np.array([[e]]))
    P = (1 + e) * v / (1 / m + d * d / Iy)
    v_plus = v_o + sol.dv_o
    assert abs(sol.P[0, 0] - P) < 1e-12
    assert np.abs(v_plus - [vx, 0.0, -v + P / m, 0.0, d * P / Iy, 0.0]).max() < 1e-12
    assert abs(sol.phi_dot_plus[0, 0] - e * v) < 1e-12
    ke0 = kinetic_energy(b, v_o, np.zeros((1, 1)))
    ke1 = kinetic_energy(b, v_plus, np.zeros((1, 1)))
    assert ke1 <= ke0 + 1e-12
    if e == 1.0:
        assert abs(ke1 - ke0) < 1e-12 * ke0


def impact_as_acceleration_problem(b: SystemBlocks, uni, vm, e) -> SystemBlocks:
    """The impact as an acceleration-level problem for the oracle: ``h = h_o = 0`` and
    ``c = -(1 + e) φ̇⁻`` on unilateral rows, ``-φ̇⁻`` on bilateral rows."""
    c = np.where(uni, -(1.0 + e) * vm, -vm) * b.constraint_mask
    return SystemBlocks(b.M, np.zeros_like(b.h), b.W, b.W_o, c, b.M_o, np.zeros(6), b.nv, b.N)


def random_impact(seed: int):
    """A random impact problem; bilateral rows start with ``φ̇⁻ = 0``, unilateral rows
    approach or separate. Feasible: the unilateral rows admit a direction increasing all of
    them (generic rows; the redundant row is a positive combination of unilateral rows)."""
    rng = np.random.default_rng(2000 + seed)
    n = int(rng.integers(1, 5))
    nv = [int(x) for x in rng.choice([0, 3, 6, 7], n)]
    N = [int(x) for x in rng.integers(1, 4, n)]
    redundant = seed % 3 == 0 and max(N) >= 3
    b, uni = random_contact_problem(rng, nv, N, redundant=redundant)
    if redundant:  # the dependent row and its two parents unilateral: always feasible
        i = int(np.argmax(np.array(N) >= 3))
        uni[i, : N[i]] = True
    vm = pad_rows(b, [rng.uniform(-2.0, 0.5, m) for m in N], 0.0)
    vm[~uni & b.constraint_mask] = 0.0  # bilateral rows start consistent
    e = pad_rows(b, [rng.uniform(0.0, 1.0, m) for m in N], 0.0)
    return b, uni, vm, e


@pytest.mark.parametrize("seed", range(24))
def test_random_impacts_match_enumeration(seed):
    b, uni, vm, e = random_impact(seed)
    act = b.constraint_mask.copy()
    sol = solve_impact(b, uni, act, vm, e)
    dv, dqd, _, _ = oracle(impact_as_acceleration_problem(b, uni, vm, e), uni)
    scale = max(np.abs(dv).max(), np.abs(dqd).max(), 1e-300)
    assert np.abs(sol.dv_o - dv).max() < 1e-10 * scale
    assert np.abs(sol.dqd - dqd).max() < 1e-10 * scale
    # φ̇⁺ from the dense Jacobian, complementarity, signs, padding
    M, h, A, c = dense_matrices(b)
    v = np.concatenate([sol.dv_o] + [sol.dqd[i, : b.nv[i]] for i in range(b.n)])
    assert np.abs(b.flatten_mu(sol.phi_dot_plus) - (b.flatten_mu(vm) + A @ v)).max() < 1e-12
    assert sol.complementarity < 1e-10
    assert (sol.P[uni] >= 0).all()
    assert (sol.phi_dot_plus + e * vm)[uni].min(initial=0.0) >= -1e-12
    assert np.abs(sol.phi_dot_plus[act & ~uni]).max(initial=0.0) < 1e-12
    assert not sol.P[~b.constraint_mask].any()
    r = sol.residuals()
    assert max(r.object, r.arms) <= 1e-12 * r.scale
    ref = solve_impact(b, uni, act, vm, e, reference=True)  # numpy Delassus, same core
    assert np.abs(ref.dv_o - sol.dv_o).max() <= 1e-12 * scale
    assert np.abs(ref.phi_dot_plus - sol.phi_dot_plus).max() <= 1e-12 * max(np.abs(vm).max(), 1)


def impulses_unique(b: SystemBlocks, seed: int) -> bool:
    """True when the rows of ``random_impact(seed)`` are independent by construction: no
    redundant row, and at most 6 rows beyond what each arm's joints make independent (the
    rest act through the object's 6 dofs). Only then is which row takes an impulse unique."""
    excess = sum(max(0, int(m) - int(k)) for k, m in zip(b.nv, b.N, strict=True))
    return not (seed % 3 == 0 and int(b.N.max()) >= 3) and excess <= 6


def test_random_impacts_are_not_trivial():
    """Rows hit (``P > 0``) and rows leave (``P = 0``, ``φ̇⁺ > 0``), counted on the cases
    whose impulses are unique only (with redundant rows which of them takes the impulse is
    decided by round-off); ``φ̇⁺`` of the rows counted as leaving is at least 0.04 here."""
    hit = separate = unique = 0
    for seed in range(24):
        b, uni, vm, e = random_impact(seed)
        if not impulses_unique(b, seed):
            continue
        unique += 1
        sol = solve_impact(b, uni, b.constraint_mask.copy(), vm, e)
        hit += int((sol.P[uni] > 0).sum())
        separate += int(((sol.P == 0) & uni & (sol.phi_dot_plus > 0)).sum())
    assert unique >= 15 and hit >= 15 and separate >= 15


@pytest.mark.parametrize("seed", range(12))
def test_energy_never_increases(seed):
    """All-unilateral rows, pre-impact velocity ``v⁻`` random, ``φ̇⁻ = A v⁻``; the active rows
    are the closing ones (``φ̇⁻ ≤ 0``). The jump of kinetic energy is
    ``ΔT = Pᵀ A v⁻ + ½ Pᵀ G P = ½ Σ P_k (φ̇⁻_k + φ̇⁺_k) = ½ Σ P_k (1 - e_k) φ̇⁻_k`` (``P_k > 0``
    only where ``φ̇⁺_k = -e_k φ̇⁻_k``), so ``ΔT ≤ 0`` for ``e ≤ 1``, and ``ΔT = 0`` when every
    ``e_k = 1``.
    """
    rng = np.random.default_rng(3000 + seed)
    n = int(rng.integers(1, 4))
    nv = [int(x) for x in rng.choice([0, 6, 7], n)]
    N = [int(x) for x in rng.integers(1, 5, n)]
    b, uni = random_contact_problem(rng, nv, N, p_bilateral=0.0)
    M, h, A, c = dense_matrices(b)
    v = rng.standard_normal(M.shape[0])
    vm = b.unflatten_mu(A @ v)
    act = b.constraint_mask & (vm <= 0.0)
    assert act.any()
    T0 = 0.5 * v @ M @ v
    for e in (pad_rows(b, [rng.uniform(0.0, 1.0, m) for m in N], 0.0),
              b.constraint_mask.astype(float)):
        sol = solve_impact(b, uni, act, vm, e)
        dv = np.concatenate([sol.dv_o] + [sol.dqd[i, : b.nv[i]] for i in range(b.n)])
        T1 = 0.5 * (v + dv) @ M @ (v + dv)
        dT = 0.5 * float(np.sum(sol.P * (1.0 - e) * vm))
        assert abs((T1 - T0) - dT) < 1e-12 * T0
        assert T1 <= T0 * (1 + 1e-12)
        if (e[b.constraint_mask] == 1.0).all():
            assert abs(T1 - T0) < 1e-12 * T0
        assert sol.P.any()


def test_bad_input():
    b, uni, vm, e = random_impact(1)
    act = b.constraint_mask.copy()
    bad = e.copy()
    bad[0, 0] = 1.5
    with pytest.raises(InputError, match=r"restitution: expected Newton coefficients in \[0, 1\]"
                                         r", got 1.5 at arm 0, row 0"):
        solve_impact(b, uni, act, vm, bad)
    bad[0, 0] = -0.1
    with pytest.raises(InputError, match="restitution"):
        solve_impact(b, uni, act, vm, bad)
    bad[0, 0] = np.nan
    with pytest.raises(InputError, match="restitution: NaN or infinity at arm 0, row 0"):
        solve_impact(b, uni, act, vm, bad)
    nan = vm.copy()
    nan[0, 0] = np.inf
    with pytest.raises(InputError, match="phi_dot_minus: NaN or infinity"):
        solve_impact(b, uni, act, nan, e)
    with pytest.raises(InputError, match=r"phi_dot_minus: expected shape \(n, N_max\)"):
        solve_impact(b, uni, act, vm[:, :-1], e)
    with pytest.raises(InputError, match=r"restitution: expected an array of numbers"):
        solve_impact(b, uni, act, vm, "high")
    with pytest.raises(InputError, match="active: expected a bool array"):
        solve_impact(b, uni, None, vm, e)
    b, uni, vm, e = next(c for c in map(random_impact, range(30))
                         if not c[0].constraint_mask.all())
    pad = ~b.constraint_mask
    act = b.constraint_mask.copy()
    with pytest.raises(InputError, match="unilateral: True on padding"):
        solve_impact(b, pad, act, vm, e)
