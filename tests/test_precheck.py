"""Checks before simulating (multiarm_pin.app.precheck): each fires on a hostile case, with the
right numbers (against an independent computation), and never on a shipped scenario."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hostile_scenarios import SIX_FINGERTIPS
from run_helpers import Q0_UR5, REPO, one_arm_scenario, run_cli, write

from multiarm_pin.app import precheck
from multiarm_pin.app.diagnosis import fastest_rate
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.model.arm import Arm

SHIPPED = sorted((REPO / "scenarios").glob("*.yaml"))
BOX_CENTRE = np.array([0.8, 0.11, 0.24])  # one_arm_scenario's object position [m]

THREE_DIGITS = 6e-3  # relative tolerance of a number printed with 3 significant digits


def _build(tmp_path: Path, text: str, name: str = "case.yaml"):
    return build_scenario(load_scenario(write(tmp_path / name, text)), load_visuals=False)


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_no_shipped_scenario_is_flagged(path):
    built = build_scenario(load_scenario(path), load_visuals=False)
    assert precheck.precheck_warnings(built) == []


def _independent_static_torques(mass: float) -> tuple[np.ndarray, Arm]:
    """One UR5 at Q0_UR5 holding the box alone: rnea gravity + Jᵀ (its wrench on the box).

    The arm is the only support of the box, so its wrench on it is unique: the force
    ``m g`` up at the COM, i.e. at the tool origin ``[f; (c - p) × f]`` in world axes.
    """
    arm = Arm.from_robot_name("ur5", name="a", load_visuals=False)
    model, data = arm.model, arm.model.createData()
    q = np.array(Q0_UR5)
    g = pin.rnea(model, data, q, np.zeros(6), np.zeros(6))
    J = pin.computeFrameJacobian(model, data, q, arm.tool_frame_id,
                                 pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
    p = data.oMf[arm.tool_frame_id].translation
    f = np.array([0.0, 0.0, mass * 9.81])
    return g + J.T @ np.r_[f, np.cross(BOX_CENTRE - p, f)], arm


def test_box_typed_in_grams_warns_with_the_static_torques_through_the_cli(tmp_path):
    """4000 kg on one UR5: the run is not refused, but stderr and summary.json say why no arm
    could hold it, with the torques of rnea + Jᵀ f computed here."""
    scenario = write(tmp_path / "grams.yaml", one_arm_scenario(name="grams", mass=4000.0,
                                                               duration=0.004))
    out = tmp_path / "out"
    proc = run_cli("run", scenario, "--out", out, "--quiet", "--no-html")
    assert proc.returncode == 0, proc.stderr
    tau, arm = _independent_static_torques(4000.0)
    effort = np.array(arm.model.effortLimit)
    names = precheck.joint_names(arm)
    warn = next(line for line in proc.stderr.splitlines() if "holding the start pose" in line)
    m = re.search(r"needs (\S+) N m at joint '(\w+)' of arm 'a', (\S+)x its effort limit "
                  r"(\S+) N m", warn)
    assert m, warn
    value, joint, ratio, limit = float(m[1]), m[2], float(m[3]), float(m[4])
    worst = int(np.argmax(np.abs(tau) / effort))
    assert joint == names[worst]
    assert value == pytest.approx(tau[worst], rel=1e-4)
    assert limit == effort[worst]
    assert ratio == pytest.approx(abs(tau[worst]) / limit, rel=THREE_DIGITS)
    assert ratio > 50  # far beyond the limit: a verdict by construction
    for j, v, r in re.findall(r"a:(\w+) (\S+) N m \((\S+)x\)", warn):
        c = names.index(j)
        assert float(v) == pytest.approx(tau[c], rel=1e-3)
        assert float(r) == pytest.approx(abs(tau[c]) / effort[c], rel=THREE_DIGITS)
    scale = next(line for line in proc.stderr.splitlines() if "the arms' own mass" in line)
    m_arm = sum(i.mass for i in arm.model.inertias)
    assert "object.mass: 4000 kg" in scale and f"{4000 / m_arm:.3g}x" in scale
    assert "typed in grams" in scale
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert warn.removeprefix("warning: ") in summary["input_warnings"]


def test_light_box_has_no_torque_or_scale_warning(tmp_path):
    built = _build(tmp_path, one_arm_scenario(mass=2.0))
    assert precheck.static_torque_warnings(built) == []
    assert precheck.scale_warnings(built) == []
    tau, _ = _independent_static_torques(2.0)
    ours, how = precheck.static_torques(built.system, built.initial_state)
    assert how == "by the arms alone"
    np.testing.assert_allclose(ours, tau, rtol=1e-9, atol=1e-9)


def test_rpy_in_degrees_is_pointed_out(tmp_path):
    text = one_arm_scenario().replace("    q0:", "    base: {rpy: [0, 0, 360]}\n    q0:")
    warns = precheck.angle_warnings(_build(tmp_path, text))
    assert len(warns) == 1
    assert "arms[0].base.rpy[2]: 360 rad is more than 2π" in warns[0]
    assert f"{np.deg2rad(360):.6g}" in warns[0]


def test_size_typed_in_millimetres_is_pointed_out(tmp_path):
    text = one_arm_scenario().replace("size: [0.4, 0.3, 0.2]", "size: [400, 300, 200]")
    built = _build(tmp_path, text)
    warns = precheck.scale_warnings(built)
    assert len(warns) == 1 and "object.shape.size: the object is 400 m across" in warns[0]
    assert "typed in mm" in warns[0]


def test_reach_bounds_the_tool_distance(rng):
    """arm_reach is an upper bound of |tool - base| over random configurations."""
    arm = Arm.from_robot_name("ur5", name="a", load_visuals=False)
    reach = precheck.arm_reach(arm)
    lo, hi = arm.model.lowerPositionLimit, arm.model.upperPositionLimit
    far = max(np.linalg.norm(arm.tool_placement(rng.uniform(lo, hi)).translation)
              for _ in range(300))
    assert far <= reach and far > 0.5 * reach


def test_six_fingertips_without_support_are_not_form_closure(tmp_path):
    """Six frictionless contacts can never be form closure (7 are needed)."""
    built = _build(tmp_path, SIX_FINGERTIPS)
    assert built.system.unilateral.sum() == 6
    warns = precheck.grasp_warnings(built)
    assert len(warns) == 1
    assert "arms: the grasp is not form closure (6 unilateral contacts" in warns[0]
    assert "no support to rest on" in warns[0]


def test_the_same_grasp_on_a_support_is_not_flagged(tmp_path):
    text = SIX_FINGERTIPS.replace("controller:", """supports:
  - name: table
    plane: {point: [0, 0, 0.7], normal: [0, 0, 1]}
    points: [[0.3, 0.2, -0.2], [0.3, -0.2, -0.2], [-0.3, 0.2, -0.2], [-0.3, -0.2, -0.2]]
controller:""")
    built = _build(tmp_path, text)
    assert precheck.grasp_warnings(built) == []
    assert precheck.static_torque_warnings(built) == []
    tau, how = precheck.static_torques(built.system, built.initial_state, supports=True)
    assert how == "by the arms and the supports" and np.isfinite(tau).all()
    # the stand takes most of the weight: the torques stay near the arms' own gravity torques
    g = built.system.gravity_torques(built.initial_state.q)
    assert np.abs(tau - g).max() < np.abs(g).max()


@pytest.mark.parametrize(("kp", "kd", "rate"), [(100.0, 20.0, 10.0), (400.0, 10.0, 20.0)])
def test_fastest_rate_is_the_closed_form_of_the_pd(tmp_path, kp, kd, rate):
    """s² + kd s + kp: a double root -kd/2 when kd² = 4 kp; |s| = sqrt(kp) when underdamped."""
    text = one_arm_scenario(controller=f"{{type: object_pd, kp: {kp}, kd: {kd}}}", dt=0.5,
                            duration=1.0)
    built = _build(tmp_path, text)
    r, source = fastest_rate(built, built.initial_state)
    assert r == pytest.approx(rate, rel=1e-9) and "controller.kp" in source
    warns = precheck.step_warnings(built, 0.5)
    assert len(warns) == 1 and f"dt · rate = {0.5 * rate:.3g}" in warns[0]
    assert precheck.step_warnings(built, 0.002) == []


def test_joint_pd_rate_is_the_generalised_eigenvalue_of_its_stiffness(tmp_path):
    """joint_pd without damping: modes ±i sqrt(λ(M⁻¹ K_p)); λ from scipy's eigh(K_p, M)."""
    from scipy.linalg import eigh

    kp = 4000.0
    built = _build(tmp_path, one_arm_scenario(controller=f"{{type: joint_pd, kp: {kp}, kd: 0}}"))
    arm = built.arms[0]
    M = pin.crba(arm.model, arm.model.createData(), np.array(Q0_UR5))
    lam = eigh(kp * np.eye(6), np.triu(M) + np.triu(M, 1).T, eigvals_only=True)
    r, source = fastest_rate(built, built.initial_state)
    assert r == pytest.approx(np.sqrt(lam.max()), rel=1e-9) and "joint-space gains" in source


def test_a_weld_alone_is_form_closure_through_its_rows_counted_both_ways(tmp_path):
    """A weld resists every wrench: its 6 bilateral rows, each as ±, positively span R^6."""
    from multiarm_pin.grasp.form_closure import form_closure

    built = _build(tmp_path, one_arm_scenario())
    W = precheck.grasp_wrenches(built.system, built.initial_state, 0.3)
    assert W.shape == (6, 12)
    assert form_closure(W).form_closure
    assert not form_closure(W[:, ::2], allow_fewer=True).form_closure  # one way only: no


def test_static_torques_on_chosen_rows_only():
    """``static_torques`` with rows left out: ``tilt_pick`` at its start, the box resting on
    the table. No arm engaged, the table's vertices alone carry the weight, so each arm's
    torque is its own gravity torque (Pinocchio's ``computeGeneralizedGravity``, to 1e-9
    N m; with the arms' rows in, the least-norm distribution would load them too); with no
    support row within a gap of -1 m either, nothing holds the box: a DynamicsError."""
    from multiarm_pin.exceptions import DynamicsError

    built = build_scenario(load_scenario(REPO / "scenarios" / "tilt_pick.yaml"),
                           load_visuals=False)
    system, st = built.system, built.initial_state
    tau, how = precheck.static_torques(system, st, supports=True,
                                       engaged_arms=[False] * system.n_arms, support_gap=1e-6)
    assert how == "by the arms and the supports"
    qs = np.split(np.asarray(st.q), np.cumsum([a.nq for a in system.arms])[:-1])
    want = np.concatenate([pin.computeGeneralizedGravity(a.model, a.data, q)
                           for a, q in zip(system.arms, qs, strict=True)])
    assert np.abs(tau - want).max() < 1e-9
    with pytest.raises(DynamicsError):
        precheck.static_torques(system, st, supports=True,
                                engaged_arms=[False] * system.n_arms, support_gap=-1.0)
