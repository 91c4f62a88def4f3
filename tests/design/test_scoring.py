"""Scores, the weighted objective, dominance and the Pareto front."""

import pytest

from multiarm_pin.design.scoring import (
    SCORES,
    at_least_as_good,
    crowding_distance,
    dominates,
    objective,
    pareto_front,
    rank_key,
)


def test_the_objective_is_the_documented_weighted_sum():
    s = {"torque_ratio": 0.25, "clearance": 0.05, "manipulability": 0.2, "lp_margin": None}
    # 1 - 0.25, 0.05 / 0.1, min(0.2 / 0.1, 1); lp_margin does not apply
    assert objective(s) == pytest.approx(0.75 + 0.5 + 1.0)
    assert objective(s, {"torque_ratio": 2.0, "clearance": 0.0}) == pytest.approx(1.5 + 1.0)
    assert all(sc.weight == 1.0 for sc in SCORES.values())


def test_dominance_and_the_pareto_front():
    a = {"torque_ratio": 0.2, "clearance": 0.05}
    b = {"torque_ratio": 0.3, "clearance": 0.05}
    c = {"torque_ratio": 0.1, "clearance": 0.01}
    assert at_least_as_good(a, b) and dominates(a, b) and not dominates(b, a)
    assert at_least_as_good(a, dict(a)) and not dominates(a, dict(a))
    assert not at_least_as_good(a, c) and not at_least_as_good(c, a)
    assert pareto_front([a, b, c]) == [0, 2]


def test_the_ranking_is_a_total_order():
    keys = [rank_key(1.0, 5), rank_key(1.0, 3), rank_key(2.0, 9)]
    assert sorted(keys) == [rank_key(2.0, 9), rank_key(1.0, 3), rank_key(1.0, 5)]


def test_crowding_distance_is_nsga2s_sum_of_neighbour_gaps():
    """Ends infinite; inside, per varying score, the gap between the two neighbours over the
    score's range (clearance is equal everywhere and lp_margin does not apply: no term)."""
    front = [{"torque_ratio": t, "manipulability": m, "clearance": 0.02, "lp_margin": None}
             for t, m in ((0.1, 0.01), (0.2, 0.05), (0.25, 0.06), (0.4, 0.09))]
    d = crowding_distance(front)
    assert d[0] == d[3] == float("inf")
    assert d[1] == pytest.approx((0.25 - 0.1) / 0.3 + (0.06 - 0.01) / 0.08)
    assert d[2] == pytest.approx((0.4 - 0.2) / 0.3 + (0.09 - 0.05) / 0.08)
    assert crowding_distance(front[:1]) == [0.0]
