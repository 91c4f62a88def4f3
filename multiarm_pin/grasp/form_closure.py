"""Form closure of frictionless point contacts (thesis Sec 2.1, Eq 2.1).

N unit wrenches ``w_k`` (columns of ``W``, 6 x N) give form closure iff they have rank 6 and
some strictly positive combination of them is zero (then they positively span R^6). Both
parts are decided numerically: the rank by SVD and the positive combination by a linear
program, which treats every contact at once (so the marginal cases of Fig 2.1, where no
subset of seven wrenches closes but the whole set does, are decided correctly).

Two margins are reported:

* ``margin``: the optimum of ``max ε  s.t.  W λ = 0, Σ λ = 1, λ_k >= ε`` (dimensionless,
  at most 1/N). Positive iff a strictly positive combination exists.
* ``ferrari_canny``: the radius of the largest ball centred at the origin inside the convex
  hull of the unit wrenches (a Ferrari-Canny epsilon for unit frictionless forces). If every
  wrench moves by less than this radius the grasp stays closed, which the stability layer
  uses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, QhullError

from multiarm_pin.exceptions import GraspError
from multiarm_pin.grasp.contacts import Grasp
from multiarm_pin.spatial import as_array

MIN_CONTACTS = 7
"""Frictionless form closure in 3-D needs at least seven contacts (Sec 2.1)."""

RANK_TOLERANCE = 1e-9
"""Singular values below this times the largest one count as zero."""

MARGIN_TOLERANCE = 1e-9
"""The LP margin must exceed this for the grasp to count as form closure."""


@dataclass(frozen=True)
class FormClosureResult:
    """Verdict and margins of a form-closure test.

    Attributes:
        form_closure: rank 6 and a strictly positive zero combination exist.
        rank: numerical rank of the wrench matrix.
        margin: LP margin ``ε*`` (>= 0; 0 when no strictly positive combination exists).
        lp_epsilon: the raw LP optimum (may be negative; ``nan`` when the LP is infeasible,
            i.e. no non-negative combination with unit sum is zero).
        coefficients: (N,) the LP's combination ``λ`` (sums to 1), or zeros when infeasible.
        ferrari_canny: radius of the largest origin-centred ball in the hull of the wrenches
            (same units as the wrenches; 0 when not form closure).
        singular_values: (min(6, N),) singular values of the wrench matrix.
    """

    form_closure: bool
    rank: int
    margin: float
    lp_epsilon: float
    coefficients: np.ndarray
    ferrari_canny: float
    singular_values: np.ndarray


def form_closure(
    grasp_or_wrenches: Grasp | np.ndarray,
    origin: np.ndarray | None = None,
    length_scale: float = 1.0,
    allow_fewer: bool = False,
) -> FormClosureResult:
    """Decide form closure (Eq 2.1) and compute its margins.

    Args:
        grasp_or_wrenches: a :class:`Grasp`, or a wrench matrix (6, N) whose columns are
            ``[n; p × n]``.
        origin: (3,) moment reference point [m] in the object frame (grasp only). Closure
            itself does not depend on it; the margins do.
        length_scale: ``L`` [m] dividing the moments (grasp only).
        allow_fewer: when False (default), fewer than 7 contacts raise :class:`GraspError`
            since they can never close; when True they are answered "no".

    Returns:
        A :class:`FormClosureResult`.

    Raises:
        GraspError: fewer than 7 contacts (unless ``allow_fewer``), or a malformed matrix.
    """
    if isinstance(grasp_or_wrenches, Grasp):
        W = grasp_or_wrenches.wrenches(origin, length_scale)
    else:
        W = as_array(grasp_or_wrenches, (6, None), "wrench matrix")
    N = W.shape[1]
    if N < MIN_CONTACTS and not allow_fewer:
        raise GraspError(
            f"form closure needs at least {MIN_CONTACTS} frictionless contacts in 3-D, got {N}"
        )
    sv = np.linalg.svd(W, compute_uv=False) if N else np.zeros(0)
    rank = int(np.sum(sv > RANK_TOLERANCE * max(1.0, sv.max(initial=0.0))))
    eps, lam = lp_margin(W)
    closed = rank == 6 and np.isfinite(eps) and eps > MARGIN_TOLERANCE
    fc = ferrari_canny_epsilon(W) if closed else 0.0
    margin = eps if (np.isfinite(eps) and eps > 0.0) else 0.0
    return FormClosureResult(bool(closed), rank, float(margin), float(eps), lam, float(fc), sv)


def lp_margin(W: np.ndarray) -> tuple[float, np.ndarray]:
    """Solve ``max ε  s.t.  W λ = 0, Σ λ = 1, λ_k >= ε`` (λ free otherwise).

    Args:
        W: (6, N) wrench matrix.

    Returns:
        ``(ε*, λ*)``; ``(nan, zeros)`` when ``W λ = 0, Σ λ = 1`` has no solution.
    """
    W = np.asarray(W, dtype=float)
    N = W.shape[1]
    if N == 0:
        return float("nan"), np.zeros(0)
    # x = [λ (N), ε]; minimise -ε
    c = np.zeros(N + 1)
    c[-1] = -1.0
    A_eq = np.zeros((W.shape[0] + 1, N + 1))
    A_eq[:-1, :N] = W
    A_eq[-1, :N] = 1.0
    b_eq = np.zeros(W.shape[0] + 1)
    b_eq[-1] = 1.0
    A_ub = np.hstack([-np.eye(N), np.ones((N, 1))])  # ε - λ_k <= 0
    b_ub = np.zeros(N)
    bounds = [(None, None)] * N + [(None, 1.0)]
    res = linprog(c, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq, bounds=bounds, method="highs")
    if res.status != 0:
        return float("nan"), np.zeros(N)
    return float(res.x[-1]), res.x[:N].copy()


def ferrari_canny_epsilon(W: np.ndarray) -> float:
    """Radius of the largest ball centred at the origin inside ``conv{w_k}``.

    Args:
        W: (6, N) wrench matrix (columns are the unit contact wrenches).

    Returns:
        The distance from the origin to the nearest facet of the hull, in the wrenches'
        units; 0 when the origin is not strictly inside (or the hull is flat).
    """
    pts = np.asarray(W, dtype=float).T
    if len(pts) < 7:
        return 0.0
    try:
        hull = ConvexHull(pts)
    except QhullError:
        return 0.0
    # qhull facets: normal · x + offset <= 0 inside, unit normals
    dist = -hull.equations[:, -1]
    return float(max(dist.min(), 0.0))
