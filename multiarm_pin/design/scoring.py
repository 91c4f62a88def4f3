"""How designs are ranked: the scores, the weighted objective, the Pareto front, a total order.

Every score of :data:`SCORES` is measured on a design that met every condition
(:mod:`.assessment`); fingertip scores are None for a weld-only design. The objective is

    J = Σ_s  w_s · term_s,   term_s = min(value_s / scale_s, 1)      (higher is better)
                             term_s = 1 - value_s                     (torque_ratio)

with the weights ``w_s`` of the spec's ``weights:`` (default :attr:`Score.weight`, 1 for
each) and a score that does not apply (None) contributing 0. The caps keep one huge score
from hiding a poor one: a clearance beyond 10 cm, for example, counts as 10 cm. Designs are
sorted by ``J`` (descending), ties broken by the candidate's index, so that the ranking is a
total order, the same whatever order the candidates were assessed in.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Score:
    """One score of a design.

    Attributes:
        name: its key (in ``weights:``, the report, :attr:`Design.scores`).
        description: what it measures, with its unit.
        higher_is_better: its direction.
        scale: the value at which its term reaches 1 (higher-is-better scores).
        weight: default weight in the objective.
    """

    name: str
    description: str
    higher_is_better: bool
    scale: float
    weight: float = 1.0

    def term(self, value: float | None) -> float:
        """The score's dimensionless term of the objective (0 for None)."""
        if value is None or not np.isfinite(value):
            return 0.0
        if not self.higher_is_better:
            return 1.0 - float(value)
        return float(min(value / self.scale, 1.0))


SCORES: dict[str, Score] = {s.name: s for s in (
    Score("lp_margin", "form closure LP margin ε* of the unit contact wrenches (fingertips; "
          "dimensionless, at most 1/N)", True, 1.0 / 7.0),
    Score("ferrari_canny", "Ferrari-Canny ε: radius of the largest ball about the origin in "
          "the hull of the unit contact wrenches (fingertips; qhull)", True, 0.02),
    Score("stability", "configuration-stability bound [m]: how far every contact may move "
          "along its face before closure can be lost (fingertips)", True, 0.01),
    Score("torque_ratio", "worst static joint torque over its URDF effort limit along the "
          "task (gravity on the arms plus the object's weight through the force "
          "distribution)", False, 1.0),
    Score("clearance", "smallest distance [m] between bodies that must not touch, along the "
          "task (arm-object apart from the grasping links, arm-arm, arm-support, "
          "arm-ground, self)", True, 0.1),
    Score("manipulability", "smallest Yoshikawa manipulability sqrt(det(J Jᵀ)) of the arms "
          "at the start [m³ rad³]", True, 0.1),
)}
"""The scores, in the report's column order."""


def objective(scores: dict, weights: dict | None = None) -> float:
    """The weighted objective ``J`` of a design's scores (module docstring)."""
    weights = weights or {}
    return float(sum(weights.get(n, s.weight) * s.term(scores.get(n))
                     for n, s in SCORES.items()))


def at_least_as_good(a: dict, b: dict, tol: float = 0.0) -> bool:
    """True if scores ``a`` are at least as good as ``b`` on every score both have."""
    for n, s in SCORES.items():
        va, vb = a.get(n), b.get(n)
        if va is None or vb is None:
            continue
        if s.higher_is_better and va < vb - tol:
            return False
        if not s.higher_is_better and va > vb + tol:
            return False
    return True


def dominates(a: dict, b: dict) -> bool:
    """True if ``a`` is at least as good as ``b`` everywhere and better somewhere."""
    return at_least_as_good(a, b) and not at_least_as_good(b, a)


def pareto_front(score_list: list[dict]) -> list[int]:
    """Indices of the designs no other design dominates, in the list's order."""
    return [i for i, a in enumerate(score_list)
            if not any(dominates(b, a) for j, b in enumerate(score_list) if j != i)]


def crowding_distance(score_list: list[dict]) -> list[float]:
    """Per design, the crowding distance of NSGA-II in the scores' space (larger: lonelier).

    For each score that varies over the list: the designs sorted by it (ties by position),
    the two ends get infinity, every other design the difference of its two neighbours'
    values over the score's range; a design's distance is the sum over the scores.
    """
    out = [0.0] * len(score_list)
    for name in SCORES:
        vals = [s.get(name) for s in score_list]
        if any(v is None for v in vals) or len(vals) < 2:
            continue
        order = sorted(range(len(vals)), key=lambda i: (vals[i], i))
        span = vals[order[-1]] - vals[order[0]]
        if span <= 0.0:
            continue
        out[order[0]] = out[order[-1]] = np.inf
        for a, i, b in zip(order[:-2], order[1:-1], order[2:], strict=True):
            out[i] += (vals[b] - vals[a]) / span
    return out


def rank_key(objective_value: float, index: int) -> tuple[float, int]:
    """The total order of designs: objective descending, then candidate index."""
    return (-round(float(objective_value), 12), int(index))


__all__ = ["SCORES", "Score", "at_least_as_good", "crowding_distance", "dominates", "objective",
           "pareto_front", "rank_key"]
