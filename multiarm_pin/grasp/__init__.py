"""Grasp analysis: form closure with frictionless point contacts on polyhedra (thesis ch. 2)."""

from multiarm_pin.grasp.contacts import (
    Contact,
    Grasp,
    contact_from_point_normal,
    contact_on_face,
    wrench_matrix,
)
from multiarm_pin.grasp.form_closure import FormClosureResult, ferrari_canny_epsilon, form_closure
from multiarm_pin.grasp.independence import (
    BlockDecomposition,
    IndependenceReport,
    block_decomposition,
    check_independence,
)
from multiarm_pin.grasp.seventh_contact import (
    ContactRegion,
    box_corner_region_lines,
    region_by_generators,
    region_by_inverse,
)

__all__ = [
    "BlockDecomposition",
    "Contact",
    "ContactRegion",
    "FormClosureResult",
    "Grasp",
    "IndependenceReport",
    "block_decomposition",
    "box_corner_region_lines",
    "check_independence",
    "contact_from_point_normal",
    "contact_on_face",
    "ferrari_canny_epsilon",
    "form_closure",
    "region_by_generators",
    "region_by_inverse",
    "wrench_matrix",
]
