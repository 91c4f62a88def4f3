"""Object-first forward dynamics (thesis Eq 4.10-4.12, Lilly-Orin style), vectorised over arms.

With ``S_i = W_iᵀ M_i⁻¹ W_i`` and ``r_i = c_i - W_iᵀ M_i⁻¹ h_i`` (our sign convention, see
``docs/ARCHITECTURE.md``) the constraint rows give ``S_i μ_i = r_i - W_o,iᵀ a_o``. Eliminating
every ``μ_i`` from the object equation::

    (M_o + Σ W_o,i S_i⁻¹ W_o,iᵀ) a_o = h_o + Σ W_o,i S_i⁻¹ r_i
    μ_i = S_i⁻¹ (r_i - W_o,iᵀ a_o),     q̈_i = M_i⁻¹ (h_i + W_i μ_i)

:func:`solve_object_first` runs the compiled kernel
:func:`multiarm_pin._compiled.object_first.object_first` (per-arm Cholesky factorisations of
``M_i`` and ``S_i``, same conditioning criteria) and hands every doubtful case to
:func:`solve_object_first_numpy`, the vectorised reference described next.

In :func:`solve_object_first_numpy` all per-arm work is done on stacked arrays with batched
solves (a compiled Cholesky per arm, :func:`_batched_solve`): one solve with
``M`` (right-hand sides ``[W h]`` together), one solve with ``S`` (right-hand sides
``[W_oᵀ r I]`` together: the identity gives ``diag(S⁻¹)`` for the conditioning test), then a
6 x 6 Cholesky solve with a LAPACK condition estimate. No Python loop over arms. (A
condition estimate from the Cholesky diagonal of ``S`` was tried first: at a UR5 elbow
singularity it over-estimated the reciprocal condition number by 1e4 and let 4e-8 errors
through.)

Twins: ``multiarm_pin._compiled.object_first`` (the same concept, object-first forward dynamics,
at the compiled layer: that module is the kernel :func:`solve_object_first` calls first; this
one also holds the numpy reference that decides the cases the kernel reports as doubtful).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack

from multiarm_pin._compiled.linalg import batched_spd_solve
from multiarm_pin._compiled.object_first import SOLVE_OK, object_first
from multiarm_pin.dynamics.blocks import Solution, SystemBlocks
from multiarm_pin.exceptions import DynamicsError, InputError, SingularityError


def _batched_solve(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``A⁻¹ B`` for stacks (n, k, k) SPD, (n, k, p); NaN for arms whose ``A`` fails to factor.

    The compiled batched Cholesky solve (:func:`multiarm_pin._compiled.linalg.batched_spd_solve`):
    the mass matrices and the padded ``S_i`` are symmetric positive definite (cheaper on these
    small stacks than the LAPACK gufunc behind ``numpy.linalg.solve``).
    """
    return batched_spd_solve(A, B)


_QUIET = {"invalid": "ignore", "divide": "ignore"}

DEFAULT_RCOND_TOL = 1e-7
"""An arm whose ``S_i`` has an estimated reciprocal condition number below this is singular.

Chosen so that "auto" keeps 1e-9 relative accuracy. Measured with a UR5 welded to an object
approaching its elbow singularity: the object-first error relative to the dense KKT was about
``2e-18 / rcond`` (true reciprocal condition number of ``S``; 7e-10 at 3e-9, 4e-8 at 3e-11),
while the singular-arm variant stays at round-off. The estimate of :class:`ArmReduction` is
at most ``N²`` times the true value, so an accepted arm has a true rcond above ``3e-9``.
Over 300 random UR5 poses with a weld the median estimate was 7e-4; "auto" switched at 9 of
them, and all 300 agreed with the dense KKT to 1e-9.

(A scale-invariant estimate from the equilibrated ``S`` was tried and dropped: it accepts an
arm whose constraint column ``W_j`` is tiny but not zero, where object-first lost 6 digits.)
"""

OBJECT_RCOND_TOL = 1e-7
"""Smallest accepted reciprocal condition number (LAPACK ``dpocon`` estimate) of the reduced
object matrix ``M_o + Σ W_o,i S_i⁻¹ W_o,iᵀ``. Arms far heavier than the object along their
constraints make it badly conditioned: measured object-first error ``~5e-17 / rcond``
(4e-8 at 1.3e-9) while the singular variant (all arms) stays at round-off."""


@dataclass(slots=True)
class ArmReduction:
    """Per-arm quantities shared by the object-first and singular-arm solvers.

    Attributes:
        X: (n, nv_max, N_max + 1) ``M_i⁻¹ [W_i  h_i]``.
        S: (n, N_max, N_max) ``W_iᵀ M_i⁻¹ W_i``, with a positive value on the padded diagonal
            (the arm's largest diagonal entry, or 1) so that padded multipliers solve to 0 and
            the condition estimate is not changed by padding.
        r: (n, N_max) ``c_i - W_iᵀ M_i⁻¹ h_i`` (zero on padding).
        Z: (n, N_max, 7) ``S_i⁻¹ [W_o,iᵀ  r_i]`` (meaningless for singular arms).
        rcond: (n,) estimate of the reciprocal condition number of each ``S_i``:
            ``1 / (max_j S_jj · max_j |(S⁻¹)_jj|)``. As ``λ_max / N <= max_j S_jj <= λ_max``
            and likewise for ``S⁻¹``, it is never smaller than the true ``λ_min / λ_max`` and
            at most ``N_max²`` times larger; 0 where the solve failed.
    """

    X: np.ndarray
    S: np.ndarray
    r: np.ndarray
    Z: np.ndarray
    rcond: np.ndarray


def reduce_arms(blocks: SystemBlocks) -> ArmReduction:
    """Compute ``M_i⁻¹ [W_i h_i]``, ``S_i``, ``r_i``, ``S_i⁻¹[W_o,iᵀ r_i]`` and conditioning.

    Args:
        blocks: the system blocks.

    Returns:
        The stacked per-arm quantities (see :class:`ArmReduction`).

    Raises:
        InputError: a block contains NaN or infinity.
        DynamicsError: some ``M_i`` is singular.
    """
    with np.errstate(**_QUIET):
        X, S, r, Z, cond = _reduce(blocks)
        rcond = _check_reduction(blocks, X, 1.0 / cond)
    return ArmReduction(X, S, r, Z[:, :, :7], rcond)


_CONST_CACHE: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}


def _constants(n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Read-only (n, m, m) identity stack and (n, 1) ones, cached per shape."""
    const = _CONST_CACHE.get((n, m))
    if const is None:
        eye = np.ascontiguousarray(np.broadcast_to(np.eye(m), (n, m, m)))
        ones = np.ones((n, 1))
        eye.flags.writeable = False
        ones.flags.writeable = False
        const = (eye, ones)
        if len(_CONST_CACHE) < 256:
            _CONST_CACHE[(n, m)] = const
    return const


def _reduce(b: SystemBlocks) -> tuple[np.ndarray, ...]:
    """Hot path of :func:`reduce_arms` (call inside ``np.errstate(invalid="ignore")``).

    Returns ``X, S, r, Z, cond``: ``Z = S⁻¹ [W_oᵀ r I]`` (n, m, 7 + m) and ``cond`` (n,) the
    estimate ``max_j S_jj · max_j |(S⁻¹)_jj|`` of the condition number of each ``S_i`` (NaN
    where the solve failed). Diagonals are read as strided views of the flattened stacks
    (cheaper than np.diagonal).
    """
    n, m = b.M.shape[0], b.N_max
    X = _batched_solve(b.M, np.concatenate((b.W, b.h[:, :, None]), axis=2))
    WtX = np.matmul(b.W.transpose(0, 2, 1), X)  # (n, m, m + 1) = [S  Wᵀ M⁻¹ h]
    S = WtX[:, :, :m]
    r = b.c - WtX[:, :, m]
    diag = WtX.reshape(n, -1)[:, :: m + 2]  # S_jj, a view into S
    smax = diag.max(axis=1)
    if b.has_constraint_padding:  # padded rows of S are zero: put the arm's max S_jj there
        smax = np.where(smax > 0.0, smax, 1.0)
        diag += b.padding_diagonal * smax[:, None]
    Z = _batched_solve(
        S, np.concatenate((b.W_o.transpose(0, 2, 1), r[:, :, None], _constants(n, m)[0]), axis=2)
    )
    return X, S, r, Z, smax * np.abs(Z.reshape(n, -1)[:, 7 :: m + 8]).max(axis=1)



Finisher = Callable[[SystemBlocks, ArmReduction, np.ndarray], Solution] | None
"""The ``fallback`` of the object-first solves: ``(blocks, reduction, singular (n,) bool) ->
Solution``, the singular-arm variant that finishes the solve (None: raise instead)."""

def _check_reduction(b: SystemBlocks, X: np.ndarray, rcond: np.ndarray) -> np.ndarray:
    """Rare path: NaN in the inputs, singular ``M_i``; failed solve of ``S_i`` -> rcond 0."""
    bad = ~np.isfinite(rcond)
    if bad.any():
        b.check_finite()
        badM = ~np.isfinite(X).reshape(b.n, -1).all(axis=1)
        if badM.any():
            raise DynamicsError(
                f"joint-space mass matrix M_i of arm(s) {np.flatnonzero(badM).tolist()} is "
                "singular; a mass matrix must be symmetric positive definite"
            )
        rcond = np.where(bad, 0.0, rcond)
    return rcond


def solve_object_first(
    blocks: SystemBlocks, rcond_tol: float = DEFAULT_RCOND_TOL, *, fallback: Finisher = None
) -> Solution:
    """Forward dynamics by eliminating the multipliers into the object (Eq 4.10-4.12), compiled.

    The compiled kernel :func:`multiarm_pin._compiled.object_first.object_first` (per-arm
    Cholesky of ``M_i`` and ``S_i``, the same conditioning criterion and thresholds). Whenever
    it reports a problem (a singular or badly conditioned ``S_i`` or reduced object matrix, a
    singular ``M_i``, NaN) the call is handed to :func:`solve_object_first_numpy`, which decides,
    falls back to the singular variant or raises exactly as documented there; so results and
    errors are those of the numpy version (to round-off).

    Args:
        blocks: the system blocks (see :class:`SystemBlocks`).
        rcond_tol: arms whose estimated reciprocal condition number of ``S_i`` is below this
            are singular.
        fallback: as for :func:`solve_object_first_numpy`.

    Returns:
        The solution: ``a_o`` (6,) [m/s², rad/s²] LWA at the COM, ``qdd`` (n, nv_max),
        ``mu`` (n, N_max).

    Raises:
        SingularityError, DynamicsError, InputError: as :func:`solve_object_first_numpy`.
    """
    _check_tol(rcond_tol)
    b = blocks
    n, k, m = b.W.shape
    a_o = np.empty(6)
    qdd = np.empty((n, k))
    mu = np.empty((n, m))
    status = object_first(
        _c(b.M), _c(b.h), _c(b.W), _c(b.W_o), _c(b.c), _c(b.M_o), _c(b.h_o), b.N,
        float(rcond_tol), OBJECT_RCOND_TOL, a_o, qdd, mu)
    if status != SOLVE_OK:
        return solve_object_first_numpy(b, rcond_tol, fallback=fallback)
    return Solution(a_o, qdd, mu, "object_first", (), b)


def _c(a: np.ndarray) -> np.ndarray:
    """C-contiguous float64 (one compiled specialisation of the kernel for every input)."""
    return a if a.flags.c_contiguous else np.ascontiguousarray(a)


def solve_object_first_numpy(
    blocks: SystemBlocks, rcond_tol: float = DEFAULT_RCOND_TOL, *, fallback: Finisher = None
) -> Solution:
    """Forward dynamics by eliminating the multipliers into the object (Eq 4.10-4.12), numpy.

    The vectorised numpy reference of :func:`solve_object_first` (batched LAPACK solves).

    Args:
        blocks: the system blocks (see :class:`SystemBlocks`).
        rcond_tol: arms whose estimated reciprocal condition number of ``S_i`` is below this
            are singular.
        fallback: the singular-arm variant to hand singular arms to (the ``auto`` policy
            passes :func:`multiarm_pin.dynamics.singular.finish_singular`, called as
            ``fallback(blocks, reduction, singular_mask)``; the solution says so in
            ``solver``/``singular_arms``); all arms are handed over when the reduced object
            matrix is badly conditioned (``OBJECT_RCOND_TOL``). If None both raise.

    Returns:
        The solution: ``a_o`` (6,) [m/s², rad/s²] LWA at the COM, ``qdd`` (n, nv_max),
        ``mu`` (n, N_max).

    Raises:
        SingularityError: some ``S_i``, or the reduced object matrix, is singular or badly
            conditioned and ``fallback`` is None.
        DynamicsError: singular ``M_i``.
        InputError: NaN or infinity in the blocks, ``M_o`` not positive definite.
    """
    _check_tol(rcond_tol)
    b = blocks
    with np.errstate(**_QUIET):
        X, S, r, Z, cond = _reduce(b)
        if not float(cond.max()) * rcond_tol <= 1.0:  # also catches NaN
            rcond = _check_reduction(b, X, 1.0 / cond)
            singular = rcond < rcond_tol
            if fallback is not None:
                return fallback(b, ArmReduction(X, S, r, Z[:, :, :7], rcond), singular)
            arms = np.flatnonzero(singular).tolist()
            worst = float(rcond[singular].min())
            raise SingularityError(
                f"S_i = W_iᵀ M_i⁻¹ W_i of arm(s) {arms}",
                np.inf if worst <= 0 else 1.0 / worst,
                "the arm is at a singularity or has fewer independent joint directions than "
                "constraints; use solver='auto' or solver='singular'",
            )
    Z7 = Z[:, :, :7]
    AB = b.W_o.transpose(1, 0, 2).reshape(6, -1) @ Z7.reshape(-1, 7)
    A = b.M_o + AB[:, :6]
    chol, a_o, info = lapack.dposv(A, b.h_o + AB[:, 6])
    rcond_A = lapack.dpocon(chol, A.trace())[0] if info == 0 else 0.0
    if not (rcond_A >= OBJECT_RCOND_TOL and math.isfinite(a_o.sum())):
        b.check_finite()
        if fallback is not None:  # e.g. arms far heavier than the object along their rows
            rcond = _check_reduction(b, X, 1.0 / cond)
            return fallback(
                b, ArmReduction(X, S, r, Z7, rcond), np.ones(b.n, dtype=bool)
            )
        raise SingularityError(
            "reduced object matrix M_o + Σ W_o,i S_i⁻¹ W_o,iᵀ",
            np.inf if rcond_A <= 0 else 1.0 / rcond_A,
            "object-first would lose accuracy; use solver='auto' or solver='singular'",
        )
    mu = Z[:, :, 6] - Z[:, :, :6] @ a_o  # S⁻¹ (r - W_oᵀ a_o)
    ones = _constants(b.n, b.N_max)[1]
    qdd = np.matmul(X, np.concatenate((mu, ones), axis=1)[:, :, None])[:, :, 0]
    return Solution(a_o, qdd, mu, "object_first", (), b)


def solve_object_system(b: SystemBlocks, A: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve a reduced 6 x 6 object system ``A a_o = rhs`` (A symmetric positive definite).

    Args:
        b: the blocks (for error diagnosis).
        A: (6, 6) reduced object matrix.
        rhs: (6,) or (6, p) right-hand side(s).

    Returns:
        ``A⁻¹ rhs``, same shape as ``rhs``.

    Raises:
        InputError: NaN or infinity in the blocks.
        DynamicsError: ``A`` not positive definite.
    """
    _, x, info = lapack.dposv(A, rhs)
    if info != 0 or not math.isfinite(x.sum()):
        b.check_finite()
        raise DynamicsError(
            f"reduced object matrix M_o + Σ W_o,i S_i⁻¹ W_o,iᵀ is not positive definite "
            f"(LAPACK info {info}); the equations of motion have no unique solution"
        )
    return x


def _check_tol(rcond_tol: float) -> None:
    if rcond_tol is DEFAULT_RCOND_TOL:
        return
    if not (isinstance(rcond_tol, float | int) and 0.0 <= rcond_tol < 1.0):
        raise InputError(f"rcond_tol: expected a number in [0, 1), got {rcond_tol!r}")
