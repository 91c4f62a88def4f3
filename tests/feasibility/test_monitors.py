"""Stop policies decided while a run runs (feasibility/monitors.py, simulate(monitors=...))."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numba
import numpy as np
import pytest

from multiarm_pin.app.run_feasibility import check_initial_state
from multiarm_pin.app.runner import scenario_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario
from multiarm_pin.app.scenario.schema import parse_scenario
from multiarm_pin.exceptions import RunStoppedError
from multiarm_pin.feasibility import feasibility_report
from multiarm_pin.feasibility.monitors import LimitMonitor, feasibility_monitors
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
    # the longest stretch of this run: 10 % of it (compiled loops), or the stepper's stride;
    # the monitors are shown at most two at once (those recorded while the worker checked)
    top = max((len(full.t) - 1) // 10, MONITOR_STRIDE)
    assert 0 < k < len(full.t) - 2 * top - 2  # a stop well before the end
    spy = Spy()
    with pytest.raises(RunStoppedError, match="limits.collision") as info:
        _simulate(built, feasibility_monitors(built.system, ("collision",), scene) + (spy,))
    assert info.value.sample == k and info.value.t == first.t_first
    part = partial_result(info.value)
    assert len(part.t) == k + 1 and part.t[-1] == first.t_first  # nothing after it
    np.testing.assert_array_equal(part.q, full.q[:k + 1])
    # the simulation stopped within two stretches of the violation, not at the end of the run
    assert max(b for _, b in spy.stretches) <= k + 2 * top < len(full.t)
    assert all(b - a <= 2 * top for a, b in spy.stretches)
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


def test_stretches_recorded_while_the_worker_checks_are_shown_together():
    # the first check holds the worker until the loop has handed back a stretch after the
    # one it showed (without batches, the loop would wait for the worker there: the check
    # fails at its timeout): the stretches recorded meanwhile are shown at once, every
    # sample still once and in order
    import threading

    built = _built(demo_data(duration=2.5), "scenarios/two_ur5_box.yaml")
    passed = threading.Event()
    handed_back = []  # the samples at which the loop handed back (its progress reports)
    n = 1250

    class Held(Spy):
        def check(self, record, k0, k1):
            if not self.stretches:
                self.first_end = k1
                assert passed.wait(20.0), "the loop waited for the worker"
            return super().check(record, k0, k1)

    def progress(frac):
        k = round(frac * n)
        handed_back.append(k)
        if spy.stretches or k > getattr(spy, "first_end", n) + 1:
            passed.set()

    spy = Held()
    result = simulate(built.system, built.initial_state, scenario_controller(built), 2.5,
                      0.002, monitors=(spy,), progress=progress)
    assert len(result.t) == n + 1
    starts = [a for a, _ in spy.stretches]
    ends = [b for _, b in spy.stretches]
    assert starts[0] == 0 and ends[-1] == len(result.t) and starts[1:] == ends[:-1]
    a, b = spy.stretches[1]  # shown once the worker was free: several hand-backs
    assert len([k for k in handed_back if a < k < b]) >= 1, (spy.stretches, handed_back)


def test_monitors_prepare_on_the_worker_once_before_their_first_check():
    # a monitor's own set-up for a run (the collision scan's arrays) is made on the worker
    # as the run starts, beside the loop's loading or compile, for the run's record
    import threading

    built = _built(demo_data(duration=0.3), "scenarios/two_ur5_box.yaml")

    class Preparing(Spy):
        def __init__(self):
            super().__init__()
            self.prepared = []

        def prepare(self, record):
            self.prepared.append((threading.current_thread() is threading.main_thread(),
                                  len(record.t), len(self.stretches)))

    spy = Preparing()
    scan_only = feasibility_monitors(built.system, (), check_initial_state(built))
    result = _simulate(built, scan_only + (spy,))
    assert spy.prepared == [(False, len(result.t), 0)]
    (collision,) = (m for m in scan_only if hasattr(m, "prepare"))
    scan = collision.scan  # made by prepare, then extended by every check
    assert scan.T == scan.n == len(result.t)
    collision.prepare(SimpleNamespace(t=result.t))
    assert collision.scan is scan


@pytest.mark.skipif(numba.config.DISABLE_JIT, reason="compile_all compiles nothing without JIT")
def test_a_compile_ends_the_monitors_worker_and_keeps_what_it_found(monkeypatch):
    # a loop compiled in the middle of a run (the contact loop after the closed loop) may fork
    # children to compile only with no other thread: compile_all ends the monitors' worker
    # first; the check it was running is done and its stop is raised as it would have been
    import threading

    from multiarm_pin._compiled import function_pointers
    from multiarm_pin.sim.simulation import _Watch

    class Stop(Spy):
        def check(self, record, k0, k1):
            super().check(record, k0, k1)
            return k0 + 3

    stop = Stop()
    watch = _Watch((stop,))
    record = SimpleNamespace(t=np.linspace(0.0, 1.0, 200))
    before = threading.active_count()
    watch.recorded(record, MONITOR_STRIDE + 2)  # the first stretch: a worker checks it
    assert threading.active_count() == before + 1
    counted = []
    monkeypatch.setattr(function_pointers, "_ready", lambda job: False)
    monkeypatch.setattr(function_pointers, "compiled", lambda job: None)
    monkeypatch.setattr(function_pointers, "processes",
                        lambda: counted.append(threading.active_count()) or 1)
    function_pointers.compile_all([["a"], ["b"]])  # two groups left: worth a child
    assert counted == [before]  # the worker had ended when the processes were counted
    assert stop.stretches == [(0, MONITOR_STRIDE + 1)]
    with pytest.raises(RunStoppedError, match=r"spy: stop at the first violation \(sample 3\)"):
        watch.finish()


@pytest.mark.skipif(numba.config.DISABLE_JIT, reason="types of compiled calls")
@pytest.mark.parametrize("case", sorted(ALONG_A_RUN))
def test_the_collision_scans_warm_up_calls_its_kernels_with_the_runs_types(monkeypatch, case):
    # what compiles the scan beside the run's loop (WarmUp) must be what the run then calls:
    # every kernel call of the run's scan and report has the types of a warm-up call
    from multiarm_pin._compiled import scan as scan_kernels
    from multiarm_pin.feasibility.monitors import CollisionMonitor

    data, file = ALONG_A_RUN[case][0]()
    built = _built(data, file)
    scene = check_initial_state(built)
    calls: dict[str, set] = {"run": set(), "warm": set()}
    side = ["run"]

    def recording(name, kernel):
        def call(*args):
            calls[side[0]].add((name, tuple(numba.typeof(a) for a in args)))
            return kernel(*args)
        return call

    for name in ("joint_placements", "path_lengths", "first_exceeding", "grasp_openings",
                 "round_heights", "ground_heights", "pair_bounds", "support_max"):  # from Python
        monkeypatch.setattr(scan_kernels, name, recording(name, getattr(scan_kernels, name)))

    class Keep(Spy):
        def check(self, record, k0, k1):
            self.record = record
            return super().check(record, k0, k1)

    monitor, keep = CollisionMonitor(scene, stop=False), Keep()
    _simulate(built, (monitor, keep))
    monitor.scan.result()
    scan, exact = monitor.scan, monitor.scan.exact.copy()
    side[0] = "warm"
    monitor.warm_up(keep.record, built.initial_state)
    assert monitor.scan is scan  # the warm-up scans on its own
    np.testing.assert_array_equal(scan.exact, exact)
    assert {n for n, _ in calls["run"]} >= {"joint_placements", "path_lengths", "pair_bounds"}
    assert calls["run"] <= calls["warm"], calls["run"] - calls["warm"]
