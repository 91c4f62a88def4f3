"""The subpackage exports exactly what it names."""

import multiarm_pin.constraints as constraints


def test_every_name_in_all_is_importable():
    for name in constraints.__all__:
        assert getattr(constraints, name) is not None, name
    assert {"ConstraintSet", "ConstraintTerms", "Joint", "make_joint"} <= set(constraints.__all__)
