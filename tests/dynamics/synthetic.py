"""Random consistent synthetic systems for the solver tests."""

from __future__ import annotations

import numpy as np

from multiarm_pin.dynamics import SystemBlocks


def random_spd(rng: np.random.Generator, k: int, scale: float = 1.0) -> np.ndarray:
    A = rng.standard_normal((k, k))
    return scale * (A @ A.T / k + 0.5 * np.eye(k))


def random_object_inertia(rng: np.random.Generator) -> np.ndarray:
    m = rng.uniform(1.0, 10.0)
    return np.block([[m * np.eye(3), np.zeros((3, 3))], [np.zeros((3, 3)), random_spd(rng, 3)]])


def random_system(
    rng: np.random.Generator,
    nv: list[int],
    N: list[int],
    rank_W: dict[int, int] | None = None,
    consistent: bool = True,
) -> tuple[SystemBlocks, np.ndarray, list[np.ndarray]]:
    """A random system whose constraints are consistent (c = W_oᵀ a + Wᵀ q for random a, q).

    ``rank_W`` maps an arm index to the rank of its W_i (rank-deficient arms).
    Returns the blocks and the (a, q) used to build c.
    """
    rank_W = rank_W or {}
    Ms, hs, Ws, Wos, cs, qs = [], [], [], [], [], []
    a = rng.standard_normal(6)
    for i, (k, m) in enumerate(zip(nv, N, strict=True)):
        Ms.append(random_spd(rng, k))
        hs.append(rng.standard_normal(k))
        if i in rank_W:
            Wi = rng.standard_normal((k, rank_W[i])) @ rng.standard_normal((rank_W[i], m))
        else:
            Wi = rng.standard_normal((k, m))
        Ws.append(Wi)
        Woi = rng.standard_normal((6, m))
        Wos.append(Woi)
        q = rng.standard_normal(k)
        qs.append(q)
        ci = Woi.T @ a + Wi.T @ q
        if not consistent:
            ci = ci + rng.standard_normal(m)
        cs.append(ci)
    blocks = SystemBlocks.from_lists(
        Ms, hs, Ws, Wos, cs, random_object_inertia(rng), rng.standard_normal(6)
    )
    return blocks, a, qs
