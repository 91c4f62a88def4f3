import numpy as np
import pytest

from multiarm_pin.exceptions import GraspError
from multiarm_pin.grasp import form_closure
from multiarm_pin.grasp.design import two_corner_box_grasp
from multiarm_pin.grasp.optimisation import GripperLayout, optimise_grasp
from multiarm_pin.grasp.stability import closure_bound
from multiarm_pin.model.polyhedron import box

GRIPPERS = [GripperLayout(("+x", "+y", "+z", "+z"), reach=1.2),
            GripperLayout(("-x", "-y", "-z"), reach=1.2)]  # fmt: skip


def test_optimisation_improves_the_bound_and_respects_reach():
    # start from the thesis design (Example 2.1 layout, D = 0.5 m): bound about 9 mm
    design = two_corner_box_grasp([2.0, 1.5, 1.0], 0.2, 0.1, 0.5)
    P = design.polyhedron
    g0 = design.with_contacts([design.contacts[i] for i in (0, 1, 2, 6, 3, 4, 5)])
    frames = [P.face_frame(c.face) for c in g0.contacts]
    s0 = np.array([(c.point - o) @ R[:, :2] for c, (o, R) in zip(g0.contacts, frames, strict=True)])
    res = optimise_grasp(P, GRIPPERS, seed=3, samples=60, refine=1, maxiter=200, initial=s0)
    assert form_closure(res.grasp).form_closure
    assert res.objective >= res.initial_objective - 1e-12
    assert res.bound >= 2 * closure_bound(g0).bound
    for g, layout in enumerate(GRIPPERS):
        pts = res.grasp.points[res.gripper_of_contact == g]
        d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
        assert d.max() <= layout.reach + 1e-9
    for c in res.grasp.contacts:
        assert P.point_on_face(c.point, c.face, 1e-9)
    again = optimise_grasp(P, GRIPPERS, seed=3, samples=60, refine=1, maxiter=200, initial=s0)
    np.testing.assert_array_equal(again.grasp.points, res.grasp.points)


def test_optimisation_input_errors():
    P = box([2.0, 1.5, 1.0])
    with pytest.raises(GraspError, match=">= 7 contacts"):
        optimise_grasp(P, [GripperLayout(("+x", "-x", "+y"))])
    with pytest.raises(GraspError, match="reach must be positive"):
        optimise_grasp(P, [GripperLayout(("+x",) * 7, reach=0.0)])
    with pytest.raises(GraspError, match="unknown face"):
        optimise_grasp(P, [GripperLayout(("+q",) * 7)])
