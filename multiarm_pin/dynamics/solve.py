"""One entry point for every forward-dynamics solver, selected by name."""

from __future__ import annotations

from collections.abc import Iterable

from multiarm_pin.dynamics.blocks import Solution, SystemBlocks
from multiarm_pin.dynamics.dense_kkt import solve_dense_kkt
from multiarm_pin.dynamics.object_first import (
    DEFAULT_RCOND_TOL,
    solve_object_first,
    solve_object_first_numpy,
)
from multiarm_pin.dynamics.singular import solve_singular
from multiarm_pin.exceptions import InputError

SOLVERS = ("auto", "object_first", "dense_kkt", "singular", "object_first_numpy")
"""Names accepted by :func:`solve`."""


def solve(
    blocks: SystemBlocks,
    solver: str = "auto",
    *,
    rcond_tol: float = DEFAULT_RCOND_TOL,
    singular_arms: Iterable[int] | None = None,
) -> Solution:
    """Solve the forward dynamics of the blocks with the named solver.

    Args:
        blocks: the system blocks (:class:`SystemBlocks`).
        solver: ``"auto"`` (object-first, switching to the singular-arm variant when some
            ``S_i`` is singular or badly conditioned), ``"object_first"`` (raises
            :class:`~multiarm_pin.exceptions.SingularityError` instead), ``"dense_kkt"``
            (reference, raises on a singular KKT matrix), ``"singular"``, or
            ``"object_first_numpy"`` (the vectorised numpy reference of the compiled
            ``"object_first"``; raises like it).
        rcond_tol: reciprocal-condition threshold below which ``S_i`` counts as singular.
        singular_arms: only for ``"singular"``: arms to treat as singular in any case.

    Returns:
        :class:`Solution` with ``a_o`` (6,), ``qdd`` (n, nv_max), ``mu`` (n, N_max), the
        solver actually used and the singular arms found.

    Raises:
        InputError: unknown solver name (the message lists the known ones), bad options,
            NaN or infinity in the blocks.
        SingularityError: ``"object_first"`` met a singular ``S_i``.
        DynamicsError: the system has no solution (inconsistent constraints, singular KKT
            matrix with ``"dense_kkt"``, singular mass matrix).
    """
    if not isinstance(blocks, SystemBlocks):
        raise InputError(f"blocks: expected SystemBlocks, got {type(blocks).__name__}")
    if singular_arms is not None and solver != "singular":
        raise InputError(f"singular_arms is only accepted by solver='singular', not {solver!r}")
    if solver == "auto":
        return solve_object_first(blocks, rcond_tol, fallback=True)
    if solver == "object_first":
        return solve_object_first(blocks, rcond_tol, fallback=False)
    if solver == "object_first_numpy":
        return solve_object_first_numpy(blocks, rcond_tol, fallback=False)
    if solver == "dense_kkt":
        return solve_dense_kkt(blocks)
    if solver == "singular":
        return solve_singular(blocks, rcond_tol, singular_arms)
    raise InputError(f"unknown solver {solver!r}; known solvers: {', '.join(SOLVERS)}")
