"""Collisions along a run (feasibility/scan.py): hand-placed cases, and stretch by stretch."""

from __future__ import annotations

import numpy as np
import pytest

from multiarm_pin.app.run_feasibility import check_initial_state
from multiarm_pin.app.runner import scenario_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario
from multiarm_pin.app.scenario.schema import parse_scenario
from multiarm_pin.feasibility import feasibility_report
from multiarm_pin.feasibility.collisions import PENETRATION_TOLERANCE
from multiarm_pin.feasibility.scan import ADVANCE_FRACTION, ADVANCE_STRIDE, RunScan
from tests.feasibility.collision_cases import (
    ALONG_A_RUN,
    ALONG_A_RUN_LINK,
    assert_clearances_are_brute_force,
)


def _run(case):
    data, file = case()
    built = build_scenario(parse_scenario(data, file), load_visuals=False)
    scene = check_initial_state(built)  # collision-free at the start (else ScenarioError)
    sim = built.scenario.simulation
    result = simulate_built(built, scenario_controller(built), sim.duration, sim.dt, sim.solver)
    return built, scene, result


def _first_mesh_collision(scene, result, k) -> int | None:
    """The first sample where pair k's meshes interpenetrate, by coal at every sample."""
    for s in range(len(result.t)):
        qs = scene.configuration(result.q[s], result.object_position[s],
                                 result.object_quaternion[s])
        if scene.mesh_penetration(qs, k) is not None:
            return s
    return None


@pytest.mark.parametrize("name", list(ALONG_A_RUN))
def test_collisions_along_a_run_name_the_pair_and_the_time(name):
    case, other, arms = ALONG_A_RUN[name]
    built, scene, result = _run(case)
    report = feasibility_report(built.system, result, ground=built.scenario.ground,
                                scene=scene)
    hits = [v for v in report.violations if v.kind == "collision" and v.other == other
            and v.arm in arms]
    assert hits, [v.describe() for v in report.violations]
    link = ALONG_A_RUN_LINK[name]
    if link is not None:
        assert link in {v.link for v in hits}, [v.describe() for v in hits]
    for v in hits:
        assert v.t_first > 0.0 and v.value < -PENETRATION_TOLERANCE  # along the run
        # the time: the first sample where coal finds the meshes of one of the link's
        # geometries interpenetrating the other body, sample by sample
        ks = [k for k in range(len(scene.pairs))
              if scene.pair_names(k) == (v.arm, v.link, v.other)]
        firsts = [s for s in (_first_mesh_collision(scene, result, k) for k in ks)
                  if s is not None]
        assert firsts and result.t[min(firsts)] == v.t_first, (v.describe(), firsts)


def test_a_run_scanned_in_stretches_equals_one_scan():
    built, scene, result = _run(ALONG_A_RUN["wrists_to_the_floor"][0])
    N = built.system.constraint_set.N
    cps = [result.contact_points[:, i, :int(N[i])] for i in range(built.system.n_arms)]
    whole = scene.scan(result.q, result.object_position, result.object_quaternion, cps)
    run = RunScan(scene, len(result.t))
    firsts = []
    edges = [0, 1, 17, 100, 101, 240, len(result.t)]
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        s = run.extend(result.q[a:b], result.object_position[a:b],
                       result.object_quaternion[a:b], [c[a:b] for c in cps])
        if s is not None:
            firsts.append(s)
    # the bounds the clearances are pruned with, summed up stretch by stretch: each pair's
    # bound at each sample at most its hull distance there, and its smallest over the run
    # (summed up from its measurements alone) at most its smallest bound
    brute = np.array([scene.hull_distances(scene.configuration(
        result.q[s], result.object_position[s], result.object_quaternion[s]))
        for s in range(len(result.t))])
    bounds = run.column_bounds(np.arange(len(scene.pairs)))
    assert np.all(bounds <= brute + 1e-12)
    assert np.all(run._column_minima() <= bounds.min(axis=0) + 1e-12)
    # every measurement of every stretch summed up: each pair's smallest is its column's
    column = np.where(np.isnan(run.exact[:run.n]), np.inf, run.exact[:run.n]).min(axis=0)
    np.testing.assert_array_equal(run._smallest, column)
    parts = run.result()
    assert whole.hits and set(parts.hits) == set(whole.hits)
    for k, hits in whole.hits.items():
        assert [h[0] for h in parts.hits[k]] == [h[0] for h in hits]
        np.testing.assert_allclose([h[1] for h in parts.hits[k]], [h[1] for h in hits],
                                   rtol=0, atol=1e-12)
    assert firsts[0] == min(h[0][0] for h in whole.hits.values())
    for name, value in whole.clearance.items():
        assert parts.clearance[name] == pytest.approx(value, abs=2e-10) if value is not None \
            else parts.clearance[name] is None


def test_clearances_equal_every_pair_at_every_sample_of_the_demo():
    # the demo carrying its box: pairs at nearly constant distance (a wrist and the tool's
    # box turning about each other), pairs bounded along the measured closest axis
    from tests.feasibility.collision_cases import DEMO

    data, _ = ALONG_A_RUN["wrists_to_the_floor"][0]()
    data["controller"]["waypoints"] = [{"t": 0.5, "position": [0.45, 0.1, 0.5],
                                        "rpy": [0.0, 0.0, 0.3]}]
    data["simulation"]["duration"] = 0.5
    built, scene, result = _run(lambda: (data, str(DEMO)))
    scan = scene.scan(result.q, result.object_position, result.object_quaternion, None)
    brute = assert_clearances_are_brute_force(scene, result, scan)
    assert scan.measured < brute.size / 4


@pytest.mark.parametrize("name", ["wrists_to_the_floor", "fingertip_into_the_table"])
def test_the_compiled_stretches_equal_their_numpy_references(name):
    # the nogil kernels of _compiled/scan.py (placements, path lengths, searches, ground
    # heights of hulls and of round fingertips, grasp zones, bounds, support functions)
    # against the numpy of the same scan, run side by side in the same stretches: the same
    # path lengths, the same samples measured with the same distances, the same report
    built, scene, result = _run(ALONG_A_RUN[name][0])
    N = built.system.constraint_set.N
    cps = [result.contact_points[:, i, :int(N[i])] for i in range(built.system.n_arms)]
    runs = [RunScan(scene, len(result.t), compiled=c) for c in (True, False)]
    edges = [0, 1, 40, 41, 200, len(result.t)]
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        firsts = [run.extend(result.q[a:b], result.object_position[a:b],
                             result.object_quaternion[a:b], [c[a:b] for c in cps])
                  for run in runs]
        assert firsts[0] == firsts[1]
    fast, ref = runs
    assert len(fast.geo.round_ground) or name != "fingertip_into_the_table"  # spheres
    for key in ("path_shift", "path_turn", "ground_lower"):
        np.testing.assert_allclose(getattr(fast, key), getattr(ref, key), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(np.isnan(fast.exact), np.isnan(ref.exact))
    # coal's distances themselves (one geometry data, warm-started GJK) agree to its
    # tolerance, GJK_TOLERANCE = 1e-11 m
    np.testing.assert_allclose(fast.exact, ref.exact, rtol=0, atol=1e-10)
    np.testing.assert_array_equal(fast.due, ref.due)
    ks = np.arange(len(scene.pairs))
    np.testing.assert_allclose(fast.column_bounds(ks), ref.column_bounds(ks), rtol=0,
                               atol=1e-10)
    a, b = fast.result(), ref.result()
    assert a.hits.keys() == b.hits.keys() and a.measured == b.measured
    for k in a.hits:
        assert [h[0] for h in a.hits[k]] == [h[0] for h in b.hits[k]]
    for cat, value in b.clearance.items():
        assert a.clearance[cat] == pytest.approx(value, abs=1e-10) if value is not None \
            else a.clearance[cat] is None


def test_a_pair_is_measured_again_where_its_bound_fails_or_at_a_shared_sample():
    # conservative advancement: after a measurement d at sample a (apart), the pair's next
    # one is at the first sample b where its path bound C(b) - C(a) may eat d's budget, or
    # earlier at a multiple of ADVANCE_STRIDE, never at an ordinary sample before that
    built, scene, result = _run(ALONG_A_RUN["wrists_to_the_floor"][0])
    run = RunScan(scene, len(result.t))
    run.extend(result.q, result.object_position, result.object_quaternion, None)
    tol, checked = run.tol, 0
    for k in np.flatnonzero(~run.geo.ground):  # the ground's pairs: exact heights
        at = np.flatnonzero(~np.isnan(run.exact[:, k]))
        C = run._column_path(int(k))
        for a, b in zip(at[:-1].tolist(), at[1:].tolist(), strict=True):
            d = run.exact[a, k]
            if d < -tol:  # penetrating: every sample
                assert b == a + 1
                continue
            target = -tol if scene.grasp_pair[k] or d <= tol else ADVANCE_FRACTION * d
            assert b % ADVANCE_STRIDE == 0 or C[b] > C[a] + (d - target), (k, a, b)
            checked += 1
    assert checked > 100


def test_a_convex_pairs_hull_penetration_is_its_hit_without_a_second_check(monkeypatch):
    # fingertip_into_the_table: mp6 links (coal cylinders and spheres, no meshes) against
    # the table's slab: each such pair is its own hull, so the scan's hull measurement is
    # the hit, as CollisionScene.mesh_penetration finds it, and nothing is measured twice
    built, scene, result = _run(ALONG_A_RUN["fingertip_into_the_table"][0])
    N = built.system.constraint_set.N
    cps = [result.contact_points[:, i, :int(N[i])] for i in range(built.system.n_arms)]
    second = []
    placed = type(scene)._placed_mesh_penetration
    monkeypatch.setattr(type(scene), "_placed_mesh_penetration",
                        lambda self, k: second.append(k) or placed(self, k))
    scan = scene.scan(result.q, result.object_position, result.object_quaternion, cps)
    monkeypatch.undo()
    assert scene.convex_pair.all()  # the mp6 arms, the box, the table's slab, the ground
    ground = scene.pairs[:, 1] == scene.ground_index  # measured by their lowest point
    own = [k for k in scan.hits if scene.convex_pair[k] and not ground[k]]
    assert own and not set(own) & set(second)
    for k in own:
        for s, depth, point in scan.hits[k]:
            qs = scene.configuration(result.q[s], result.object_position[s],
                                     result.object_quaternion[s])
            again = scene.mesh_penetration(qs, k)
            # coal's EPA, warm-started from the pair's last query, agrees to its tolerance
            assert again is not None and depth == pytest.approx(again[0], abs=1e-9)
            np.testing.assert_allclose(point, again[1], rtol=0, atol=1e-6)


def test_a_pair_with_a_mesh_is_not_its_own_hull():
    # the demo's UR5 links are meshes (their hulls only bound them) but for ee_link, a coal
    # box: a pair with a mesh is checked again on its meshes, two boxes are their own hulls
    from tests.feasibility.collision_cases import DEMO, demo_data

    built = build_scenario(parse_scenario(demo_data(), str(DEMO)), load_visuals=False)
    scene = check_initial_state(built)
    names = [(scene.names[a], scene.names[b]) for a, b in scene.pairs.tolist()]
    meshes = [k for k, (a, b) in enumerate(names)
              if "/" in a and "/" in b and "ee_link" not in a + b]
    assert len(meshes) > 50 and not scene.convex_pair[meshes].any()
    boxes = [k for k, pair in enumerate(names)
             if pair in {("left/ee_link", "right/ee_link"), ("left/ee_link", "object"),
                         ("left/ee_link", "ground")}]
    assert len(boxes) == 3 and scene.convex_pair[boxes].all()


def test_the_stable_order_is_numpys_stable_argsort():
    from multiarm_pin._compiled.scan import stable_order

    rng = np.random.default_rng(7)
    cases = [np.empty(0), np.array([1.0]), np.array([np.inf, -np.inf, 0.0, np.nan, 0.0]),
             np.full(6, 2.5)]
    cases += [rng.integers(0, 5, n).astype(float) for n in (2, 9, 40)]  # many ties
    cases += [np.where(rng.random(30) < 0.2, np.nan, rng.normal(size=30))]
    for a in cases:
        np.testing.assert_array_equal(stable_order(a), np.argsort(a, kind="stable"))
