"""External wrench schedules: values over time and bad input."""

import numpy as np
import pytest

from multiarm_pin.exceptions import InputError
from multiarm_pin.sim.disturbances import WrenchSchedule


def test_intervals_are_half_open_and_add_up():
    w = WrenchSchedule([(0.1, 0.3, [1, 0, 0, 0, 0, 2]), (0.2, 0.4, [0, 3, 0, 0, 0, 0])])
    np.testing.assert_array_equal(w(0.0), np.zeros(6))
    np.testing.assert_array_equal(w(0.1), [1, 0, 0, 0, 0, 2])
    np.testing.assert_array_equal(w(0.25), [1, 3, 0, 0, 0, 2])
    np.testing.assert_array_equal(w(0.3), [0, 3, 0, 0, 0, 0])
    np.testing.assert_array_equal(w(0.4), np.zeros(6))
    assert w.switch_times == [0.1, 0.2, 0.3, 0.4] and bool(w) and not WrenchSchedule()


@pytest.mark.parametrize(("item", "match"), [
    ((0.3, 0.1, [0] * 6), "0 <= from < to"),
    ((-1.0, 0.1, [0] * 6), "0 <= from < to"),
    ((0.0, 0.1, [0] * 5), "6 finite numbers"),
    ((0.0, 0.1, [0, 0, 0, 0, 0, np.nan]), "6 finite numbers"),
    ((0.0, 0.1), "expected"),
])
def test_bad_intervals_raise(item, match):
    with pytest.raises(InputError, match=match):
        WrenchSchedule([item])
