"""Contacts made during a run: a fingertip gripper that starts apart (``joint.approach``).

The gripper's tool starts displaced by the approach offset from the placement where its tips
touch their points; its rows start inactive (gap > tolerance) and touch down when the arm
brings the tips onto the faces. Checked on the Python stepper (the reference) and against it
on the compiled contact loop.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml
from closed_loop_cases import assert_same_contact_run

from multiarm_pin.app.runner import simulate_built
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.exceptions import ConstraintError, ScenarioError
from multiarm_pin.sim.contact_loop import ContactLoop

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"
APPROACH = [0.004, 0.004, 0.004]
"""[m] object frame: the four-finger gripper's tips (on +x, +y, +z, +z) start 4 mm off."""


def _scenario(tmp_path, approach=APPROACH, controller="none"):
    d = yaml.safe_load((SCENARIOS / "pick_from_table.yaml").read_text(encoding="utf-8"))
    d = copy.deepcopy(d)
    for arm in d["arms"]:  # the file is written elsewhere: absolute robot paths
        arm["urdf"] = str((SCENARIOS / arm["urdf"]).resolve())
    if approach is not None:
        d["arms"][0]["joint"]["approach"] = approach
    d["controller"] = {"type": controller}
    p = tmp_path / "approach.yaml"
    p.write_text(yaml.safe_dump(d), encoding="utf-8")
    return p


def _run(path, duration, contact_loop: bool, monkeypatch):
    sc = load_scenario(path)
    built = build_scenario(sc, load_visuals=False)
    calls = []
    original = ContactLoop.run

    def counted(self, *args):
        calls.append(args[3:5])
        return original(self, *args)

    with monkeypatch.context() as mp:
        mp.setattr(ContactLoop, "run", counted)
        if not contact_loop:
            mp.setattr(ContactLoop, "for_run", classmethod(lambda cls, *a: None))
        # zero torque as None: the kind of controller the compiled contact loop takes
        res = simulate_built(built, None, duration, sc.simulation.dt, sc.simulation.solver)
    return built, res, calls


def test_tips_start_apart_by_the_offset_along_their_normals(tmp_path):
    """Each tip's initial gap is ``n_f · approach`` (closed form: the tool is translated by
    the offset, the face normals are the object's axes), here 4 mm on +x, +y, +z, +z."""
    built = build_scenario(load_scenario(_scenario(tmp_path)), load_visuals=False)
    phi = built.system.blocks(built.initial_state).constraints.phi
    np.testing.assert_allclose(phi[0, :4], 0.004, atol=1e-9)
    assert np.abs(phi[1, :3]).max() < 1e-9  # the other gripper touches
    assert built.joints[0].starts_apart and not built.joints[1].starts_apart


def test_a_gripper_that_starts_apart_touches_down(tmp_path, monkeypatch):
    """Zero torque: the arms fall; the apart gripper's tips are never active before their
    first touchdown (no separation event for them at t = 0), carry no force until then, and
    a +z tip touches down on the top face with a closing speed."""
    built, res, _ = _run(_scenario(tmp_path), 0.04, False, monkeypatch)
    mine = [e for e in res.events if e.block == 0]
    assert mine and mine[0].kind == "touchdown" and mine[0].phi_dot < -0.1
    assert mine[0].label in ("four_finger:tip[2]", "four_finger:tip[3]")
    before = res.t < mine[0].t
    assert not res.active[before, 0, :4].any()
    assert np.abs(res.mu[before, 0, :4]).max() == 0.0
    # the gap closed from 4 mm by the arm's fall before the touchdown
    assert res.phi[0, 0, 2] == pytest.approx(0.004, abs=1e-9)


def test_the_contact_loop_equals_the_stepper_with_a_late_touchdown(tmp_path, monkeypatch):
    path = _scenario(tmp_path)
    _, fast, calls = _run(path, 0.04, True, monkeypatch)
    _, ref, _ = _run(path, 0.04, False, monkeypatch)
    assert calls, "the contact loop did not run"
    assert any(e.kind == "touchdown" and e.block == 0 for e in ref.events)
    assert_same_contact_run(fast, ref, 1e-9, support_block=2)


def test_an_approach_into_the_object_or_on_a_mechanical_joint_is_a_clear_error(tmp_path):
    with pytest.raises(ScenarioError, match=r"arms\[0\]\.joint\.approach.*into the object"):
        build_scenario(load_scenario(_scenario(tmp_path, approach=[-0.01, 0.0, 0.0])),
                       load_visuals=False)
    d = yaml.safe_load(_scenario(tmp_path).read_text(encoding="utf-8"))
    d["arms"][0]["joint"] = {"type": "weld", "approach": [0, 0, 0.01]}
    p = tmp_path / "weld.yaml"
    p.write_text(yaml.safe_dump(d), encoding="utf-8")
    with pytest.raises(ScenarioError, match=r"arms\[0\]\.joint\.approach.*not a parameter"):
        load_scenario(p)


def test_a_tip_beside_its_face_starts_apart_and_the_other_joints_are_checked(tmp_path):
    """An offset past the +x face and 4 mm down puts the +z tips beside the top face, below
    its extended plane (gaps -4 mm - nothing touched): accepted, their rows inactive at
    t = 0; the other gripper's joint is still checked (a moved object is an error)."""
    from multiarm_pin.model.rigid_object import ObjectState
    from multiarm_pin.sim.stepper import Stepper
    from multiarm_pin.system import SystemState

    built = build_scenario(load_scenario(_scenario(tmp_path, approach=[0.2, 0.004, -0.004])),
                           load_visuals=False)
    s, state = built.system, built.initial_state
    phi = s.blocks(state).constraints.phi
    np.testing.assert_allclose(phi[0, :4], [0.2, 0.004, -0.004, -0.004], atol=1e-9)
    stepper = Stepper(s, None, "object_first", None)
    stepper.init_active(stepper.blocks_at(0.0, state)[1], 1e-6)
    assert not stepper.active[0, :4].any() and stepper.active[1, :3].all()
    o = state.obj
    pushed = SystemState(state.q, state.v, ObjectState(o.position + [0.01, 0.0, 0.0],
                                                       o.quaternion, o.twist))
    with pytest.raises(ConstraintError, match="initial gap"):
        s.check_initial_state(pushed, tol=1e-6)


def test_the_contact_loop_keeps_a_tip_beside_its_face_out_of_the_penetration(tmp_path,
                                                                            monkeypatch):
    """A tip that starts beside its face, below the face's extended plane: the compiled
    contact loop takes the run and keeps that tip's negative gap out of the recorded
    penetration as the stepper does (``beside_start``): both runs equal, every recorded
    constraint violation far below the tip's 4 mm gap."""
    from multiarm_pin.sim.stepper import Stepper

    path = _scenario(tmp_path, approach=[0.2, 0.004, -0.004])
    built = build_scenario(load_scenario(path), load_visuals=False)
    stepper = Stepper(built.system, None, "object_first", None)
    stepper.init_active(stepper.blocks_at(0.0, built.initial_state)[1], 1e-6)
    assert ContactLoop.for_run(stepper, "rk4") is not None and stepper.beside_start.any()
    _, fast, calls = _run(path, 0.02, True, monkeypatch)
    _, ref, _ = _run(path, 0.02, False, monkeypatch)
    assert calls, "the contact loop did not run"
    assert_same_contact_run(fast, ref, 1e-9, support_block=2)
    assert fast.constraint_violation.max() < 1e-3
