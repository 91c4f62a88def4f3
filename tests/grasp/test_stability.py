import numpy as np
import pytest

from multiarm_pin.exceptions import GraspError
from multiarm_pin.grasp import GraspContact, form_closure
from multiarm_pin.grasp.design import two_corner_box_grasp
from multiarm_pin.grasp.stability import (
    closure_bound,
    independence_bound,
    linearised_margins,
    tangent_basis,
)


def _slide(g, rng, delta, which=None):
    """Move every contact (or those in `which`) along its face by a random |p̄| < delta."""
    cs = list(g.contacts)
    for k in which if which is not None else range(len(cs)):
        T = tangent_basis(g, k)
        u = rng.normal(size=2)
        u *= rng.uniform(0, 1) * delta / np.linalg.norm(u)
        c = cs[k]
        cs[k] = GraspContact(c.point + T @ u, c.normal, c.face, c.label)
    return g.with_contacts(cs)


@pytest.mark.parametrize("A,E,D", [(0.2, 0.1, 0.5), (0.3, 0.1, 0.45), (0.1, 0.12, 0.1)])
def test_perturbing_inside_the_closure_bound_never_breaks_closure(rng, A, E, D):
    g = two_corner_box_grasp([2.0, 1.5, 1.0], A, E, D)
    cb = closure_bound(g)
    assert cb.bound > 0
    delta = 0.999 * min(cb.bound, cb.edge_distances.min())
    for _ in range(150):
        assert form_closure(_slide(g, rng, delta)).form_closure
    # the bound is not vacuous: somewhat larger slides can break the grasp
    broken = sum(not form_closure(_slide(g, rng, 40 * cb.bound)).form_closure for _ in range(150))
    assert broken > 0


def test_independence_bound_keeps_six_contacts_independent(rng):
    g = two_corner_box_grasp([2.0, 1.5, 1.0], 0.2, 0.1, 0.5)
    delta = independence_bound(g)
    assert delta > 0
    for _ in range(300):
        # worst case: all six pushed to the limit
        h = _slide(g, rng, delta * 0.999, which=range(6))
        assert np.linalg.svd(h.wrenches()[:, :6], compute_uv=False)[-1] > 1e-12
    sigma_a = np.linalg.svd(
        2 * np.column_stack([np.cross(c.point, c.normal) for c in g.contacts[:3]]), compute_uv=False
    )[-1]
    # Case I (T1 = I): delta = sigma_min(a) / sqrt(3 * 2^2)
    assert abs(delta - sigma_a / np.sqrt(12)) < 1e-12


def test_linearised_gradients_match_finite_differences():
    g = two_corner_box_grasp([2.0, 1.5, 1.0], 0.2, 0.1, 0.5)
    lm = linearised_margins(g)
    assert np.all(lm.measures < 0) and lm.min_tolerance > 0
    h = 1e-6
    for k in range(7):
        T = tangent_basis(g, k)
        for ax in range(2):
            cs_p, cs_m = list(g.contacts), list(g.contacts)
            c = g.contacts[k]
            cs_p[k] = GraspContact(c.point + h * T[:, ax], c.normal, c.face, c.label)
            cs_m[k] = GraspContact(c.point - h * T[:, ax], c.normal, c.face, c.label)
            fd = (linearised_margins(g.with_contacts(cs_p)).measures
                  - linearised_margins(g.with_contacts(cs_m)).measures) / (2 * h)  # fmt: skip
            np.testing.assert_allclose(lm.gradients[:, k, ax], fd, atol=1e-6)


def test_example_2_4_measure_f_x_minus_e_y():
    # Example 2.4's first measure f x - e y: one measure of Eq 2.3 (c (f x - e y) / det, see
    # box_corner_region_lines) is a positive multiple of it as a function of the seventh
    # contact (x, y); the multiple involves the other contacts, so the thesis's linearised
    # estimate |y δe_t| + |x δf_t| + ... is for the normalised measure.
    g = two_corner_box_grasp([2.0, 1.5, 1.0], 0.2, 0.1, 0.5)
    lm = linearised_margins(g)
    x, y = g.contacts[6].point[:2]
    e, f = g.contacts[2].point[:2]
    T7 = tangent_basis(g, 6)[:2, :]  # in-face axes in x-y coordinates
    grads_xy = lm.gradients[:, 6, :] @ np.linalg.inv(T7)  # d g / d(x, y)
    line = np.array([f, -e]) / np.hypot(e, f)
    k = int(np.argmax(np.abs(grads_xy @ line) / np.linalg.norm(grads_xy, axis=1)))
    r = grads_xy[k] @ line / np.hypot(e, f)
    np.testing.assert_allclose(grads_xy[k], r * np.array([f, -e]), atol=1e-9)
    np.testing.assert_allclose(lm.measures[k], r * (f * x - e * y), atol=1e-9)
    assert r > 0


def test_stability_input_errors():
    g = two_corner_box_grasp([2.0, 1.5, 1.0], 0.2, 0.1, 0.5)
    with pytest.raises(GraspError, match="six contact indices"):
        independence_bound(g, (0, 1, 2))
    with pytest.raises(GraspError, match="linearised margins"):
        linearised_margins(g, fixed=(0, 1, 2, 3, 4, 5), last=5)
