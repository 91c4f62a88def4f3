"""The registry of forward-dynamics solvers and the one entry point, :func:`solve`.

:data:`SOLVERS` maps each solver name (the name a scenario file uses too) to a
:class:`SolverEntry`; :func:`solve` dispatches through it. The ``"auto"`` policy lives in one
function, :func:`solve_auto`: object-first, handing the arms whose ``S_i`` is singular or
badly conditioned (all arms when the reduced object matrix is) to the singular-arm variant.
Solvers whose entry says ``compiled`` also run fused with the compiled blocks
(:meth:`multiarm_pin.system.MultiArmSystem.forward_dynamics`, the closed loop); a doubtful
case of that fused path (a status other than ``SOLVE_OK``) is decided by the entry's function
with ``compiled=False``, the numpy reference, so results and errors are those of :func:`solve`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

from multiarm_pin._registry import lookup
from multiarm_pin.dynamics.blocks import Solution, SystemBlocks
from multiarm_pin.dynamics.dense_kkt import solve_dense_kkt
from multiarm_pin.dynamics.object_first import (
    DEFAULT_RCOND_TOL,
    solve_object_first,
    solve_object_first_numpy,
)
from multiarm_pin.dynamics.singular import finish_singular, solve_singular
from multiarm_pin.exceptions import InputError, UnsupportedSolverError


def solve_auto(blocks: SystemBlocks, rcond_tol: float = DEFAULT_RCOND_TOL, *,
               compiled: bool = True) -> Solution:
    """The ``"auto"`` policy: object-first, the singular-arm variant where it would lose accuracy.

    Arms whose ``S_i`` has an estimated reciprocal condition number below ``rcond_tol`` go to
    :func:`~multiarm_pin.dynamics.singular.finish_singular`; all arms do when the reduced
    object matrix is badly conditioned (``OBJECT_RCOND_TOL``). The solution says so in
    ``solver`` and ``singular_arms``.

    Args:
        blocks: the system blocks.
        rcond_tol: reciprocal-condition threshold of ``S_i``.
        compiled: the compiled kernel first (its doubtful cases go to the numpy reference);
            False: the numpy reference alone.
    """
    if compiled:
        return solve_object_first(blocks, rcond_tol, fallback=finish_singular)
    return solve_object_first_numpy(blocks, rcond_tol, fallback=finish_singular)


def _object_first(blocks: SystemBlocks, rcond_tol: float = DEFAULT_RCOND_TOL, *,
                  compiled: bool = True) -> Solution:
    """Object-first, raising :class:`~multiarm_pin.exceptions.SingularityError` when singular."""
    if compiled:
        return solve_object_first(blocks, rcond_tol)
    return solve_object_first_numpy(blocks, rcond_tol)


def _object_first_numpy(blocks: SystemBlocks, rcond_tol: float = DEFAULT_RCOND_TOL) -> Solution:
    return solve_object_first_numpy(blocks, rcond_tol)


def _dense_kkt(blocks: SystemBlocks, rcond_tol: float = DEFAULT_RCOND_TOL) -> Solution:
    del rcond_tol  # the dense KKT solve has no conditioning threshold
    return solve_dense_kkt(blocks)


@dataclass(frozen=True)
class SolverEntry:
    """One forward-dynamics solver of the registry.

    Attributes:
        name: the solver name.
        function: ``function(blocks, rcond_tol, **options) -> Solution``; ``compiled=False``
            is accepted when :attr:`compiled` (the numpy reference), ``singular_arms`` when
            :attr:`accepts_singular_arms`.
        compiled: a compiled path exists that runs fused with the compiled blocks.
        accepts_singular_arms: takes ``singular_arms`` (arms treated as singular in any case).
        description: one line for humans.
        unilateral: it serves systems with unilateral rows (a simulation then solves the
            mixed LCP on the object-first Delassus operator,
            :func:`~multiarm_pin.dynamics.unilateral.solve_unilateral`, whose fast path is the
            object-first solve); the others hold every row as an equality and a simulation
            with unilateral rows refuses them (:func:`solver_for_rows`).
    """

    name: str
    function: Callable[..., Solution]
    compiled: bool
    accepts_singular_arms: bool
    description: str
    unilateral: bool = False


SOLVERS: dict[str, SolverEntry] = {e.name: e for e in (
    SolverEntry("auto", solve_auto, True, False,
                "object-first, switching to the singular-arm variant when an arm is singular",
                unilateral=True),
    SolverEntry("object_first", _object_first, True, False,
                "object-first (Eq 4.10-4.12), compiled; raises SingularityError when singular",
                unilateral=True),
    SolverEntry("dense_kkt", _dense_kkt, False, False,
                "the dense KKT system (reference); raises on a singular KKT matrix"),
    SolverEntry("singular", solve_singular, False, True,
                "the singular-arm variant for every arm found singular (or named)"),
    SolverEntry("object_first_numpy", _object_first_numpy, False, False,
                "the vectorised numpy reference of object_first; raises like it"),
)}
"""Every forward-dynamics solver, by name (the names :func:`solve` and scenarios accept)."""


def solver_entry(solver: str) -> SolverEntry:
    """The registry entry of ``solver``.

    Raises:
        InputError: unknown name (lists the known ones, with a did-you-mean).
    """
    return lookup(SOLVERS, solver, "solver")


def solver_for_rows(solver: str, unilateral_rows: Sequence[str]) -> SolverEntry:
    """The registry entry of the solver a run names, checked against the run's rows.

    A solver is honoured or refused, never replaced: with unilateral rows only the entries
    whose :attr:`SolverEntry.unilateral` is True serve (``auto`` and ``object_first``: the
    mixed LCP on the object-first Delassus operator).

    Args:
        solver: a name of :data:`SOLVERS`.
        unilateral_rows: labels of the run's unilateral rows (empty: bilateral rows only).

    Raises:
        InputError: unknown name.
        UnsupportedSolverError: unilateral rows and a solver that does not serve them (the
            message names the solver, the rows and the solvers that serve them).
    """
    entry = solver_entry(solver)
    if len(unilateral_rows) and not entry.unilateral:
        raise UnsupportedSolverError(solver, unilateral_rows,
                                     [e.name for e in SOLVERS.values() if e.unilateral])
    return entry


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
        solver: a name of :data:`SOLVERS`: ``"auto"`` (:func:`solve_auto`),
            ``"object_first"`` (raises :class:`~multiarm_pin.exceptions.SingularityError`
            instead), ``"dense_kkt"`` (reference, raises on a singular KKT matrix),
            ``"singular"``, or ``"object_first_numpy"`` (the vectorised numpy reference of
            the compiled ``"object_first"``; raises like it).
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
    entry = solver_entry(solver)
    if singular_arms is None:
        return entry.function(blocks, rcond_tol)
    if not entry.accepts_singular_arms:
        raise InputError(f"singular_arms is only accepted by solver='singular', not {solver!r}")
    return entry.function(blocks, rcond_tol, singular_arms)


__all__ = ["SOLVERS", "SolverEntry", "solve", "solve_auto", "solver_entry", "solver_for_rows"]
