"""Unilateral contacts at the scenario level: a grasp keeps or loses contact, a pick-up.

Both use the scenarios' own files, shortened (a few hundred steps) so that they stay fast.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from multiarm_pin.app.runner import run_scenario
from multiarm_pin.app.scenario import parse_scenario

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


def _scenario(name: str, **changes):
    """The scenario file ``name`` with top-level sections updated (dict merge)."""
    path = SCENARIOS / f"{name}.yaml"
    data = yaml.safe_load(path.read_text(encoding="utf-8"))
    for key, value in changes.items():
        if isinstance(value, dict) and isinstance(data.get(key), dict):
            data[key] = {**data[key], **value}
        else:
            data[key] = value
    return parse_scenario(copy.deepcopy(data), str(path))


@pytest.mark.parametrize("margin", [5.0, 0.0])
def test_grasp_keeps_contact_with_its_margin_and_separates_without(margin, tmp_path):
    """Same run twice: the two-gripper grasp held still, pushed down by 4 N from t = 0.02 s.

    object_pd plans forces for the object's weight only (it does not know the push). With
    ``margin = 5`` every fingertip keeps at least 5 N planned; a 4 N push (a tenth of the
    weight) takes at most a few newtons off any of them, so the grasp stays closed over the
    whole run: no event, every fingertip active, the smallest force above 4 N (measured
    4.18 N: a 4 N margin to zero). With ``margin = 0`` the least-norm distribution leaves the
    top fingertip nearest the +x+y+z corner (four_finger:tip[2], planned force 0 to
    round-off) with nothing, and the downward push opens it at once: a separation event
    at the push's onset, the row inactive afterwards, its force zero.
    """
    sc = _scenario("two_gripper_form_closure",
                   object={"external_wrench": [{"from": 0.02, "to": 1.0,
                                                "wrench": [0, 0, -4.0, 0, 0, 0]}]},
                   controller={"type": "object_pd", "margin": margin},
                   simulation={"duration": 0.1, "dt": 0.002, "integrator": "rk4",
                               "solver": "object_first"})
    res = run_scenario(sc, tmp_path, html=False, plots=False)
    r = res.result
    uni = r.unilateral
    np.testing.assert_allclose(r.external_wrench[r.t >= 0.02, 2], -4.0)
    if margin > 0:
        assert r.events == []
        assert r.active[:, uni].all()
        assert r.mu[:, uni].min() > 4.0
    else:
        first = r.events[0]
        assert (first.kind, first.label) == ("separation", "four_finger:tip[2]")
        assert abs(first.t - 0.02) < 1e-12
        assert not r.active[r.t > 0.02, 0, 2].any()
        assert np.all(r.mu[r.t > 0.02, 0, 2] == 0.0)
        assert res.summary["arms"][0]["separations"] >= 1


def test_pick_from_table_records_lift_off_and_touchdown(tmp_path):
    """pick_from_table with its schedule compressed: lift off at once, touch down at the end.

    The stand's four rows start active (the box rests on them); object_pd first holds the
    box (the arms take its weight: stand forces fall to 0), then lifts it 5 mm
    (t = 0.02..0.12 s): the rows let go (``μ = 0``, ``φ̈ > 0``), a separation event each.
    Lowering it to 0.5 mm above, then slowly (0.2 s) to 0.1 mm below its start height brings
    the stand back: touchdown events of the stand's rows, closing slower than the last
    segment's peak speed ``1.875 · 0.6 mm / 0.2 s ≈ 5.6 mm/s`` (minimum jerk). Every event
    is in the result, in ``summary.json`` and in ``trajectory.npz``.

    Only what is physically determined is asserted: each stand row's first event (lift-off)
    and its first touchdown (the put-down's impact, the four rows at once: the box is level)
    with its closing speed, zero stand forces in between, and the box resting on the stand at
    the end. Not the exact event list after the put-down: there the four coplanar stand rows
    are redundant (which of them takes the impulse is decided by round-off) and fingertips
    whose gap rate is zero to round-off (1e-18 m/s) separate and touch again in the same
    instant, a sequence that may change with the CPU's rounding.
    """
    wp = [{"t": 0.02, "position": [0.0, 0.0, 0.9]}, {"t": 0.12, "position": [0.0, 0.0, 0.905]},
          {"t": 0.25, "position": [0.0, 0.0, 0.9005]}, {"t": 0.45, "position": [0.0, 0.0, 0.8999]}]
    sc = _scenario("pick_from_table", controller={"waypoints": wp},
                   simulation={"duration": 0.5, "dt": 0.002, "integrator": "rk4",
                               "solver": "object_first"})
    res = run_scenario(sc, tmp_path, html=False, plots=True)
    r = res.result
    table = [e for e in r.events if e.body == "table"]
    assert {e.row for e in table} == {0, 1, 2, 3}
    first_down = []
    for row in range(4):
        events = [e for e in table if e.row == row]
        lift = events[0]
        assert lift.kind == "separation" and 0.02 <= lift.t <= 0.12, lift
        downs = [e for e in events if e.kind == "touchdown"]
        assert downs, f"table row {row} never touches down again"
        down = downs[0]
        # closing speed: above the resting speed (1 mm/s; measured 4.0 mm/s), below the peak
        assert 0.25 < down.t < 0.5 and -0.0057 < down.phi_dot < -1e-3, down
        first_down.append(down.t)
    assert max(first_down) - min(first_down) < 1e-9
    n = len(res.built.arms)
    between = (r.t > max(e.t for e in table if e.kind == "separation" and e.t < 0.12) + 1e-12) \
        & (r.t < min(first_down))
    assert between.sum() > 100 and not r.mu[between, n, :4].any()
    # at the end the box rests on the stand, which carries most of its weight (measured all)
    weight = res.built.obj.mass * 9.81
    assert abs(r.object_position[-1, 2] - r.object_position[0, 2]) < 1e-6
    assert r.mu[-1, n, :4].sum() > 0.5 * weight
    summary = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    assert [(e["t"], e["kind"], e["label"]) for e in summary["events"]] == \
        [(e.t, e.kind, e.label) for e in r.events]
    z = np.load(tmp_path / "trajectory.npz")
    labels = list(z["contact_labels"])
    assert [labels[k] for k in z["event_contact"]] == [e.label for e in r.events]
    assert (tmp_path / "contact_states.png").read_bytes()[:4] == b"\x89PNG"


def test_grasp_failure_shows_which_contact_goes_first(tmp_path):
    """grasp_failure up to just after its push starts (t = 0.15 s, 60 N down at the COM).

    With margin 5 N every fingertip pushes before the push (min force >= 5 N). The push
    exceeds what the top fingertips' preload can take: the one nearest the corner,
    four_finger:tip[2], lets go first, at the push's onset (the first sample where the
    wrench acts), and is recorded as the run's first event, in summary.json too.
    """
    sc = _scenario("grasp_failure", simulation={"duration": 0.17, "dt": 0.002,
                                                "integrator": "rk4", "solver": "object_first"})
    res = run_scenario(sc, tmp_path, html=False, plots=False)
    r = res.result
    uni = r.unilateral
    before = r.t < 0.15 - 1e-12
    assert r.mu[before][:, uni].min() >= 5.0 - 1e-6
    first = r.events[0]
    assert (first.kind, first.label, first.body) == ("separation", "four_finger:tip[2]",
                                                     "four_finger")
    assert abs(first.t - 0.15) < 1e-12
    assert res.summary["events"][0]["label"] == "four_finger:tip[2]"
    assert res.summary["warnings"][0].startswith("t = 0.15 s: contact four_finger:tip[2] (arm 0)")


def test_grasp_failure_object_pd_holds_the_arms_once_the_grasp_is_lost(tmp_path):
    """grasp_failure up to 0.26 s: tip[3] separates inside a step, object_pd then holds.

    After four_finger:tip[2] (0.15 s), four_finger:tip[3] separates where its multiplier
    reaches zero, located by root finding between grid points (not at a multiple of dt).
    The five touching contacts left span rank 5 < 6 wrenches, so object_pd holds the
    arms still from that very evaluation: exactly one object_pd warning, stamped with the
    separation's time; nothing raises (before, its inverse dynamics failed before 0.5 s).
    Separated contacts carry no force, and the box, pushed down and no longer held in
    form closure, moves down.
    """
    sc = _scenario("grasp_failure", simulation={"duration": 0.26, "dt": 0.002,
                                                "integrator": "rk4", "solver": "object_first"})
    res = run_scenario(sc, tmp_path, html=False, plots=False)
    r = res.result
    sep = [e for e in r.events if e.kind == "separation"]
    assert [e.label for e in sep[:2]] == ["four_finger:tip[2]", "four_finger:tip[3]"]
    te = sep[1].t
    assert 0.2 < te < 0.26
    assert abs(te / r.dt - round(te / r.dt)) > 1e-3  # inside a step, not on the grid
    holds = [w for w in r.warnings if "object_pd" in w]
    assert len(holds) == 1 and holds[0].startswith(f"t = {te:.6g} s: object_pd:")
    assert "rank 5 < 6" in holds[0]
    assert any("object_pd" in w for w in res.summary["warnings"])
    after = r.t > te
    assert np.all(r.mu[after][:, 0, 2:4] == 0.0) and not r.active[after][:, 0, 2:4].any()
    assert r.object_twist[-1, 2] < -0.1
