import numpy as np
import pytest

from multiarm_pin.exceptions import GraspError, SingularityError
from multiarm_pin.grasp import Grasp, block_decomposition, check_independence, contact_on_face
from multiarm_pin.grasp.independence import CONDITION_NAMES, necessary_conditions
from multiarm_pin.model.polyhedron import box

from .conftest import corner_grasp, random_corner_parameters, random_face_point

FACES = ("+x", "-x", "+y", "-y", "+z", "-z")


def test_eq_2_2_inverse_matches_numpy_inverse(rng):
    """Random six-contact box grasps: the skip of dependent sets is a verdict with a margin
    (σ_min of W either at round-off, a structural dependence, or above 1e-4: 21 of the 30
    sets are compared)."""
    compared = 0
    for _ in range(30):
        P = box(rng.uniform(0.5, 2.5, 3))
        faces = [FACES[k] for k in rng.integers(0, 6, 6)]
        g = Grasp(tuple(contact_on_face(P, f, random_face_point(P, f, rng)) for f in faces), P)
        W = g.wrenches()
        sigma = np.linalg.svd(W, compute_uv=False)[-1]
        assert sigma < 1e-12 or sigma > 1e-4, sigma
        if sigma < 1e-6:
            continue
        try:
            dec = block_decomposition(g.points, g.normals)
        except GraspError:
            assert np.linalg.matrix_rank(g.normals) < 3
            continue
        assert dec.independent
        compared += 1
        inv = dec.inverse()
        order = list(dec.order)
        np.testing.assert_allclose(inv @ W[:, order], np.eye(6), atol=1e-9)
        np.testing.assert_allclose(inv, np.linalg.inv(W[:, order]), atol=1e-8)
        # the blocks satisfy their definitions
        np.testing.assert_allclose(dec.e_A @ dec.T1, -dec.e_B, atol=1e-12)
        np.testing.assert_allclose(dec.a @ dec.T2, -dec.a_A, atol=1e-9)
    assert compared >= 15, compared


def test_case_i_symmetric_contacts_have_T1_identity(rng):
    size, prm = random_corner_parameters(rng)
    dec = block_decomposition(*(lambda g: (g.points, g.normals))(corner_grasp(size, *prm)))
    np.testing.assert_allclose(dec.T1, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(dec.a, 2 * dec.a_A, atol=1e-14)


def test_dependent_first_normals_are_reordered():
    P = box([2, 1.5, 1])
    pts = [("+x", [1, 0.2, 0.1]), ("-x", [-1, 0.3, -0.2]), ("+y", [0.3, 0.75, 0.2]),
           ("-y", [-0.2, -0.75, 0.3]), ("+z", [0.4, 0.1, 0.5]),
           ("-z", [-0.3, 0.2, -0.5])]  # fmt: skip
    g = Grasp(tuple(contact_on_face(P, f, p) for f, p in pts), P)
    rep = check_independence(g)
    assert rep.decomposition.order[:3] != (0, 1, 2)
    assert rep.decomposition.cond_e_A < 10


def _grasp(pts):
    P = box([2, 1.5, 1])
    return Grasp(tuple(contact_on_face(P, f, p) for f, p in pts), P)


CASES = {
    # all six normals through the centre
    "four_normals_concurrent": [("+x", [1, 0, 0]), ("-x", [-1, 0, 0]), ("+y", [0, 0.75, 0]),
                                ("-y", [0, -0.75, 0]), ("+z", [0, 0, 0.5]), ("-z", [0, 0, -0.5])],
    # four contacts on ±z
    "four_normals_parallel": [("+x", [1, 0.2, 0.1]), ("+y", [0.3, 0.75, 0.2]),
                              ("+z", [0.4, 0.1, 0.5]), ("+z", [-0.4, 0.3, 0.5]),
                              ("-z", [-0.3, -0.2, -0.5]), ("-z", [0.2, 0.3, -0.5])],
    # four normals in the plane z = 0.1
    "four_normals_coplanar": [("+x", [1, 0.2, 0.1]), ("-x", [-1, -0.3, 0.1]),
                              ("+y", [0.3, 0.75, 0.1]), ("-y", [-0.2, -0.75, 0.1]),
                              ("+z", [0.4, 0.1, 0.5]), ("-z", [-0.3, 0.2, -0.5])],
    # three parallel (+z twice, -z) and the other three concurrent at the centre
    "three_parallel_rest_concurrent": [("+x", [1, 0, 0]), ("+y", [0, 0.75, 0]),
                                       ("-x", [-1, 0, 0]), ("+z", [0.4, 0.1, 0.5]),
                                       ("+z", [-0.4, 0.3, 0.5]), ("-z", [0.2, -0.3, -0.5])],
}  # fmt: skip


@pytest.mark.parametrize("name", sorted(CASES))
def test_each_violated_necessary_condition_is_named_and_means_dependent(name):
    rep = check_independence(_grasp(CASES[name]))
    names = [n for n, _ in rep.violated]
    assert name in names, names
    assert not rep.independent
    assert rep.sigma_min < 1e-9
    assert any(CONDITION_NAMES[name] in m for m in rep.messages)


def test_necessary_conditions_never_fire_on_independent_sets(rng):
    fired = 0
    for _ in range(200):
        P = box(rng.uniform(0.5, 2.5, 3))
        faces = [FACES[k] for k in rng.integers(0, 6, 6)]
        pts = [random_face_point(P, f, rng) for f in faces]
        # snap some coordinates to 0 to create special configurations often
        pts = [np.where(rng.random(3) < 0.3, 0.0, p) if f[1] != "xyz"[i % 3] else p
               for i, (f, p) in enumerate(zip(faces, pts, strict=True))]  # fmt: skip
        try:
            g = Grasp(tuple(contact_on_face(P, f, p) for f, p in zip(faces, pts, strict=True)), P)
        except GraspError:
            continue
        sigma = np.linalg.svd(g.wrenches(), compute_uv=False)[-1]
        violated = necessary_conditions(g.points, g.normals)
        if violated:
            fired += 1
            assert sigma < 1e-8, (violated, sigma)
    assert fired > 0


def test_independence_input_errors():
    g = _grasp(CASES["four_normals_concurrent"])
    with pytest.raises(GraspError, match="six distinct contact indices"):
        check_independence(g, (0, 1, 2, 3, 4))
    with pytest.raises(GraspError, match="exactly six"):
        block_decomposition(np.zeros((5, 3)), np.ones((5, 3)))
    with pytest.raises(GraspError, match="no three"):
        block_decomposition(np.zeros((6, 3)), np.tile([0, 0, 1.0], (6, 1)))
    rep = check_independence(g)
    with pytest.raises(SingularityError):
        rep.decomposition.inverse()
