"""Stop policies decided while a run runs (feasibility/monitors.py, simulate(monitors=...))."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from multiarm_pin.app.run_feasibility import check_initial_state
from multiarm_pin.app.runner import scenario_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario
from multiarm_pin.app.scenario.schema import parse_scenario
from multiarm_pin.exceptions import RunStoppedError
from multiarm_pin.feasibility import feasibility_report
from multiarm_pin.feasibility.monitors import LimitMonitor, stop_monitors
from multiarm_pin.sim.simulation import MONITOR_STRETCH, MONITOR_STRIDE, partial_result, simulate
from tests.feasibility.collision_cases import ALONG_A_RUN, demo_data


class Spy:
    """A monitor that finds nothing and keeps the stretches it was shown."""

    name = "spy"

    def __init__(self):
        self.stretches = []

    def check(self, record, k0, k1):
        self.stretches.append((k0, k1))
        return None


def _built(data, file):
    return build_scenario(parse_scenario(data, file), load_visuals=False)


def _simulate(built, monitors=()):
    sim = built.scenario.simulation
    return simulate_built(built, scenario_controller(built), sim.duration, sim.dt, sim.solver,
                          monitors=monitors)


def test_a_collision_stop_ends_the_run_at_the_reports_first_collision():
    data, file = ALONG_A_RUN["forearms_crossing"][0]()
    built = _built(data, file)
    scene = check_initial_state(built)
    full = _simulate(built)
    first = feasibility_report(built.system, full, ground=0.0, scene=scene).first(
        ("collision",))
    k = int(np.flatnonzero(full.t == first.t_first)[0])
    # the longest stretch of this run: 10 % of it (compiled loops), or the stepper's stride
    top = max((len(full.t) - 1) // 10, MONITOR_STRIDE)
    assert 0 < k < len(full.t) - top - 2  # a stop well before the end
    spy = Spy()
    with pytest.raises(RunStoppedError, match="limits.collision") as info:
        _simulate(built, stop_monitors(built.system, ("collision",), scene) + (spy,))
    assert info.value.sample == k and info.value.t == first.t_first
    part = partial_result(info.value)
    assert len(part.t) == k + 1 and part.t[-1] == first.t_first  # nothing after it
    np.testing.assert_array_equal(part.q, full.q[:k + 1])
    # the simulation stopped within a stretch of the violation, not at the end of the run
    assert max(b for _, b in spy.stretches) <= k + 1 + top < len(full.t)
    again = feasibility_report(built.system, part, ground=0.0, scene=scene).first(
        ("collision",))
    assert (again.arm, again.link, again.other, again.t_first) == (
        first.arm, first.link, first.other, first.t_first)


def test_a_limit_stop_ends_at_the_first_sample_beyond_the_limit():
    # the demo carrying its box, with velocity limits lowered to half its peak speed ratio:
    # the first sample beyond them, computed here from the URDF's limits, ends the run
    data = demo_data(duration=0.5)
    data["controller"]["waypoints"] = [{"t": 0.5, "position": [0.5, 0.0, 0.5]}]
    built = _built(data, "scenarios/two_ur5_box.yaml")
    full = _simulate(built)
    vmax = np.concatenate([a.model.velocityLimit for a in built.system.arms])
    ratio = np.abs(full.v) / vmax
    scale = 0.5 * ratio.max()
    k = int(np.flatnonzero((ratio > scale).any(axis=1))[0])
    assert 0 < k < len(full.t) - 1
    monitor = LimitMonitor(built.system, ("velocity",))
    monitor.limits = dataclasses.replace(monitor.limits,
                                         velocity=monitor.limits.velocity * scale)
    with pytest.raises(RunStoppedError, match="limits.velocity") as info:
        _simulate(built, (monitor,))
    part = partial_result(info.value)
    assert info.value.sample == k and len(part.t) == k + 1
    np.testing.assert_array_equal(part.v, full.v[:k + 1])


@pytest.mark.parametrize("integrator", ["rk4", "semi_implicit", "rk45"])
def test_monitors_see_every_sample_once_in_order(integrator):
    built = _built(demo_data(duration=0.3), "scenarios/two_ur5_box.yaml")
    spy = Spy()
    result = simulate(built.system, built.initial_state, scenario_controller(built), 0.3, 0.002,
                      integrator=integrator, monitors=(spy,))
    starts = [a for a, _ in spy.stretches]
    ends = [b for _, b in spy.stretches]
    assert starts[0] == 0 and ends[-1] == len(result.t) and starts[1:] == ends[:-1]
    assert all(0 < b - a <= MONITOR_STRETCH for a, b in spy.stretches)
