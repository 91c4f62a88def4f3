"""Grasp analysis: form closure with frictionless point contacts on polyhedra (thesis ch. 2).

Contacts push along the object's inward normal ``n`` at ``p``; their wrenches are
``[n; p × n]`` in the object frame. The layer decides form closure (Eq 2.1) with a margin,
checks six independent contacts (Eq 2.2), finds where a seventh contact closes the grasp
(Eq 2.3 and Eq 2.4), bounds how far contacts may slide (Sec 2.3), recovers the object frame
from contact points (Sec 2.4), and helps design and optimise grasps.
"""

from multiarm_pin.grasp.contacts import (
    Grasp,
    GraspContact,
    contact_from_point_normal,
    contact_on_face,
    wrench_matrix,
)
from multiarm_pin.grasp.design import (
    minimal_seventh_offset,
    parallel_planes_object,
    seventh_offset_min,
    two_corner_box_grasp,
)
from multiarm_pin.grasp.form_closure import FormClosureResult, ferrari_canny_epsilon, form_closure
from multiarm_pin.grasp.independence import (
    BlockDecomposition,
    IndependenceReport,
    block_decomposition,
    check_independence,
)
from multiarm_pin.grasp.object_frame import (
    ObjectPose,
    object_frame_from_box_contacts,
    object_frame_lstsq,
    objfrm,
)
from multiarm_pin.grasp.optimisation import GripperLayout, OptimisedGrasp, optimise_grasp
from multiarm_pin.grasp.report import analyse, load_grasp_file
from multiarm_pin.grasp.seventh_contact import (
    ContactRegion,
    SeventhContactRegion,
    box_corner_region_lines,
    region_by_generators,
    region_by_inverse,
    seventh_contact_regions,
)
from multiarm_pin.grasp.stability import (
    ClosureBound,
    LinearisedMargins,
    closure_bound,
    independence_bound,
    linearised_margins,
)

__all__ = [
    "BlockDecomposition",
    "ClosureBound",
    "GraspContact",
    "ContactRegion",
    "FormClosureResult",
    "Grasp",
    "GripperLayout",
    "IndependenceReport",
    "LinearisedMargins",
    "ObjectPose",
    "OptimisedGrasp",
    "SeventhContactRegion",
    "analyse",
    "block_decomposition",
    "box_corner_region_lines",
    "check_independence",
    "closure_bound",
    "contact_from_point_normal",
    "contact_on_face",
    "ferrari_canny_epsilon",
    "form_closure",
    "independence_bound",
    "linearised_margins",
    "load_grasp_file",
    "minimal_seventh_offset",
    "object_frame_from_box_contacts",
    "object_frame_lstsq",
    "objfrm",
    "optimise_grasp",
    "parallel_planes_object",
    "region_by_generators",
    "region_by_inverse",
    "seventh_contact_regions",
    "seventh_offset_min",
    "two_corner_box_grasp",
    "wrench_matrix",
]
