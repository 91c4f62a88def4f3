"""A dense stand-in for part S's ``multiarm_pin.dynamics.unilateral`` (test helper only).

Used by ``tests/conftest.py`` only while that module does not exist on this branch, so that
the simulation layer can be tested before the exact solver is merged. Dense: the Delassus
operator ``D = J M⁻¹ Jᵀ`` of all real rows, then the mixed LCP ``y = D λ + b`` solved by
enumerating which unilateral rows push (all first), least-squares (min-norm) multipliers on
each candidate set, so redundant rows work.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from multiarm_pin.dynamics.blocks import SystemBlocks


@dataclass
class ContactSolution:
    a_o: np.ndarray
    qdd: np.ndarray
    mu: np.ndarray
    phi_dd: np.ndarray
    solver: str
    blocks: SystemBlocks


@dataclass
class ImpactSolution:
    dv_o: np.ndarray
    dqd: np.ndarray
    P: np.ndarray
    phi_dot_plus: np.ndarray


def _dense(blocks: SystemBlocks):
    n, k = blocks.n, blocks.nv_max
    nx = n * k + 6
    M = np.zeros((nx, nx))
    for i in range(n):
        M[i * k:(i + 1) * k, i * k:(i + 1) * k] = blocks.M[i]
    M[n * k:, n * k:] = blocks.M_o
    rows = np.argwhere(blocks.constraint_mask)
    J = np.zeros((len(rows), nx))
    for r, (i, j) in enumerate(rows):
        J[r, i * k:(i + 1) * k] = blocks.W[i, :, j]
        J[r, n * k:] = blocks.W_o[i, :, j]
    return M, J, rows


def _mlcp(D, b, uni, act):
    """λ with y = Dλ + b: act&~uni: y = 0; act&uni: 0 <= λ ⟂ y >= 0; ~act: λ = 0."""
    bil = np.flatnonzero(act & ~uni)
    cand = np.flatnonzero(act & uni)
    scale = max(1.0, np.abs(D).max(), np.abs(b).max())
    tol = 1e-9 * scale
    for size in range(len(cand), -1, -1):
        for S in itertools.combinations(cand, size):
            E = np.concatenate([bil, np.array(S, dtype=int)])
            lam = np.zeros(len(b))
            if len(E):
                lam[E] = np.linalg.lstsq(D[np.ix_(E, E)], -b[E], rcond=1e-12)[0]
            y = D @ lam + b
            if len(E) and np.abs(y[E]).max() > tol:
                continue
            if np.any(lam[cand] < -tol) or np.any(y[cand] < -tol):
                continue
            lam[cand] = np.maximum(lam[cand], 0.0)
            return lam
    raise RuntimeError("stand-in mixed LCP: no solution found")


def solve_unilateral(blocks, unilateral, active=None):
    M, J, rows = _dense(blocks)
    n, k = blocks.n, blocks.nv_max
    h = np.concatenate([blocks.h.ravel(), blocks.h_o])
    c = blocks.c[blocks.constraint_mask]
    Minv = np.linalg.inv(M)
    D = J @ Minv @ J.T
    b = J @ Minv @ h - c
    uni = np.asarray(unilateral)[blocks.constraint_mask]
    act = np.ones(len(c), bool) if active is None else np.asarray(active)[blocks.constraint_mask]
    lam = _mlcp(D, b, uni, act)
    x = Minv @ (h + J.T @ lam)
    mu = np.zeros(blocks.c.shape)
    mu[blocks.constraint_mask] = lam
    pdd = np.zeros(blocks.c.shape)
    pdd[blocks.constraint_mask] = J @ x - c
    return ContactSolution(x[n * k:], x[:n * k].reshape(n, k), mu, pdd, "standin", blocks)


def solve_impact(blocks, unilateral, active, phi_dot_minus, restitution):
    M, J, rows = _dense(blocks)
    n, k = blocks.n, blocks.nv_max
    m = blocks.constraint_mask
    Minv = np.linalg.inv(M)
    D = J @ Minv @ J.T
    uni = np.asarray(unilateral)[m]
    act = np.asarray(active)[m]
    pm = np.asarray(phi_dot_minus)[m]
    e = np.asarray(restitution)[m]
    b = np.where(uni, (1.0 + e) * pm, pm)
    lam = _mlcp(D, b, uni, act)
    dx = Minv @ (J.T @ lam)
    P = np.zeros(blocks.c.shape)
    P[m] = lam
    pdp = np.zeros(blocks.c.shape)
    pdp[m] = pm + J @ dx
    return ImpactSolution(dx[n * k:], dx[:n * k].reshape(n, k), P, pdp)
