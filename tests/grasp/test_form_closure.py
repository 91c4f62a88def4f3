import itertools

import numpy as np
import pytest
from scipy.optimize import nnls

from multiarm_pin.exceptions import GraspError
from multiarm_pin.grasp import Grasp, contact_on_face, ferrari_canny_epsilon, form_closure
from multiarm_pin.grasp.design import two_corner_box_grasp
from multiarm_pin.model.polyhedron import box

from .conftest import random_face_point

FACES = ("+x", "-x", "+y", "-y", "+z", "-z")


def _reachable(W, u):
    """NNLS residual of u as a non-negative combination of W's columns."""
    _, res = nnls(W, u, maxiter=2000)
    return res


def _random_box_grasp(rng, n):
    P = box(rng.uniform(0.5, 2.5, 3))
    faces = [FACES[k] for k in rng.integers(0, 6, n)]
    return Grasp(tuple(contact_on_face(P, f, random_face_point(P, f, rng)) for f in faces), P)


def test_lp_verdict_agrees_with_nnls_on_random_grasps(rng):
    counts = {True: 0, False: 0}
    for _ in range(60):
        g = _random_box_grasp(rng, int(rng.integers(7, 13)))
        W = g.wrenches()
        res = form_closure(g)
        counts[res.form_closure] += 1
        # verdicts by construction: every drawn case is far from the rank (1e-9) and LP
        # (1e-9) thresholds: a rank-deficient wrench matrix (two contacts on one face line
        # up, ...) has σ_min/σ_max ~1e-17, a full-rank one > 1e-6; closed grasps have
        # ε* >= 7e-3 here, full-rank open ones ε* <= 0 up to round-off
        sv = res.singular_values
        rank_deficient = sv.size < 6 or sv.min() < 1e-12 * sv.max()
        assert rank_deficient or sv.min() > 1e-6 * sv.max()
        if res.form_closure:
            assert res.lp_epsilon > 1e-4 and not rank_deficient
        else:
            assert rank_deficient or not res.lp_epsilon > 1e-12
        # independent check: closure <=> every ±e_k is a non-negative combination
        axes = np.vstack([np.eye(6), -np.eye(6)])
        dirs = rng.normal(size=(64, 6))
        basis = np.array([_reachable(W, u) for u in axes])
        rand = np.array([_reachable(W, u / np.linalg.norm(u)) for u in dirs])
        # and far from the NNLS threshold (1e-8): reachable ~1e-15, unreachable >= 2.7e-4
        both = np.concatenate([basis, rand])
        assert not np.any((both > 1e-12) & (both < 1e-5)), both
        assert res.form_closure == bool(np.all(basis < 1e-8))
        # without closure the cone lies in a half-space: random directions fail half the time
        assert (np.sum(rand > 1e-8) == 0) == res.form_closure
        if res.form_closure:
            lam = res.coefficients
            assert np.all(lam >= res.margin - 1e-12)
            np.testing.assert_allclose(W @ lam, 0, atol=1e-9)
            assert res.ferrari_canny > 0
    assert counts[True] >= 5 and counts[False] >= 5, counts


def _planar_marginal_box(five: bool):
    """Fig 2.1 extended to 3-D: no 7-subset closes but all contacts together do.

    x-y part: contacts on ±x at y = 0 (collinear, opposite) and on ±y at x = ±a (six) or
    +y at x = 0 and -y at x = ±a (five), all at z = 0; they span {fx, fy, mz} only as a whole.
    z part: one contact at the centre of +z and three on -z around the centre: {fz, mx, my}.
    """
    P = box([2.0, 1.5, 1.0])
    a = 0.5
    xy = [("+x", [1.0, 0, 0]), ("-x", [-1.0, 0, 0])]
    if five:
        xy += [("+y", [0.0, 0.75, 0]), ("-y", [a, -0.75, 0]), ("-y", [-a, -0.75, 0])]
    else:
        xy += [("+y", [a, 0.75, 0]), ("+y", [-a, 0.75, 0]), ("-y", [a, -0.75, 0]),
               ("-y", [-a, -0.75, 0])]  # fmt: skip
    z = [("+z", [0, 0, 0.5])] + [
        ("-z", [0.4 * np.cos(t), 0.4 * np.sin(t), -0.5]) for t in (0.3, 0.3 + 2.1, 0.3 + 4.2)
    ]
    return Grasp(tuple(contact_on_face(P, f, p) for f, p in xy + z), P)


@pytest.mark.parametrize("five", [True, False])
def test_marginal_cases_of_fig_2_1_in_3d(five):
    g = _planar_marginal_box(five)
    res = form_closure(g)
    assert res.form_closure and res.rank == 6
    N = len(g)
    # the "n + 1 vectors at a time" test of earlier work misses it: no 7-subset closes
    for sub in itertools.combinations(range(N), 7):
        assert not form_closure(g.with_contacts([g.contacts[i] for i in sub])).form_closure
    # and each contact is needed
    for drop in range(N):
        rest = [c for i, c in enumerate(g.contacts) if i != drop]
        assert not form_closure(g.with_contacts(rest)).form_closure


def test_boundary_seventh_contact_is_not_closure_and_has_zero_margin():
    A, E = 0.2, 0.1
    at = form_closure(two_corner_box_grasp([2, 1.5, 1], A, E, 2 * (A - E)))
    assert not at.form_closure and at.margin == 0.0 and at.rank == 6
    assert abs(at.lp_epsilon) < 1e-12
    inside = form_closure(two_corner_box_grasp([2, 1.5, 1], A, E, 2 * (A - E) + 1e-4))
    assert inside.form_closure and 0 < inside.margin < 1e-3


def test_verdict_does_not_depend_on_origin_or_scale(rng):
    for _ in range(15):
        g = _random_box_grasp(rng, 9)
        ref = form_closure(g).form_closure
        assert form_closure(g, origin=rng.normal(size=3), length_scale=0.3).form_closure == ref


def test_ferrari_canny_is_the_minimum_support_value(rng):
    g = two_corner_box_grasp([2, 1.5, 1], 0.2, 0.1, 0.5)
    W = g.wrenches()
    eps = ferrari_canny_epsilon(W)
    dirs = rng.normal(size=(20000, 6))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    support = (dirs @ W).max(axis=1)  # h(u) = max_k u · w_k
    assert support.min() >= eps - 1e-12
    from scipy.spatial import ConvexHull

    eq = ConvexHull(W.T).equations
    u = eq[np.argmin(-eq[:, -1]), :6]
    assert abs((u @ W).max() - eps) < 1e-12


def test_fewer_than_seven_contacts_asked_to_close_raise():
    g = two_corner_box_grasp([2, 1.5, 1], 0.2, 0.1, 0.5)
    six = g.with_contacts(g.contacts[:6])
    with pytest.raises(GraspError, match="at least 7 .* got 6"):
        form_closure(six)
    assert not form_closure(six, allow_fewer=True).form_closure
    with pytest.raises(Exception, match="wrench matrix"):
        form_closure(np.zeros((5, 7)))
