"""Random multi-arm systems under ``object_pd`` for the closed-loop tests (a helper module).

Arms (UR5: 6 joints, Panda: 7, so padding occurs) on a circle around a box, every joint type
of the library plus fingertips, states moving and slightly off the constraint manifold.
"""

from __future__ import annotations

import dataclasses
from functools import cache
from pathlib import Path

import numpy as np
import pinocchio as pin
from system_builders import BOX_SIZE, JOINT_KINDS, Q_NOMINAL, joint_spec

from multiarm_pin.app.runner import scenario_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.model.arm import Arm
from multiarm_pin.model.rigid_object import ObjectState, RigidObject
from multiarm_pin.sim.contact_loop import ContactLoop
from multiarm_pin.sim.controllers import ObjectPD
from multiarm_pin.sim.trajectories import MinimumJerkTrajectory
from multiarm_pin.system import MultiArmSystem, SystemState

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"

EPS = np.finfo(float).eps
TOL = 1e-12
"""Relative agreement of the fused and the reference path."""

TOL_RANK_DEFICIENT_HOLD = 1e-7
"""Relative agreement on an arm whose hold task ``A_i`` is rank deficient (every Panda: 7
joints, a rank-6 task). ``object_pd`` solves that task damped by ``ε = JACOBIAN_DAMPING =
1e-8`` (relative): the solution's component along the task's null direction is
``σ_min / (σ_min² + ε s) uᵀr`` with ``σ_min`` at round-off level (~1e-16 σ_max), i.e. noise
of relative size ``ε_mach / ε ≈ 1e-8`` in either path (the two paths' Jacobians differ at
round-off, and so do their solves); ten times that bounds the difference."""


@cache
def arm(robot: str, i: int, n: int) -> Arm:
    """Arm ``i`` of ``n`` on a circle of radius 0.9 m around the origin, facing it."""
    angle = 2 * np.pi * i / n
    base = pin.SE3(pin.rpy.rpyToMatrix(0, 0, angle + np.pi),
                   np.array([0.9 * np.cos(angle), 0.9 * np.sin(angle), 0.0]))
    return Arm.from_robot_name(robot, name=f"{robot}{i}", base_placement=base)


def random_case(seed: int, n_arms: int, kinds=None):
    """``(system, state_at_rest, moving_off_state, trajectory)`` of a random system.

    ``kinds`` defaults to joint types drawn from :data:`JOINT_KINDS`; the object's
    trajectory moves it 5 cm and turns it 0.2 rad over 1 s.
    """
    rng = np.random.default_rng(seed)
    robots = [("ur5", "panda")[int(rng.integers(2))] for _ in range(n_arms)]
    if kinds is None:
        kinds = [JOINT_KINDS[int(rng.integers(len(JOINT_KINDS)))] for _ in range(n_arms)]
    q0 = [Q_NOMINAL[r] + 0.2 * rng.normal(size=len(Q_NOMINAL[r])) for r in robots]
    quat = rng.normal(size=4)
    quat /= np.linalg.norm(quat)
    system, state = MultiArmSystem.from_initial_state(
        [arm(r, i, n_arms) for i, r in enumerate(robots)], RigidObject.box(BOX_SIZE, 5.0),
        [joint_spec(k) for k in kinds], q0, pin.XYZQUATToSE3([0.0, 0.0, 0.3, *quat]),
        (0.3, -1.0, -9.0))
    o = state.obj
    moving = SystemState(state.q, rng.normal(size=system.nv),
                         ObjectState(o.position, o.quaternion, rng.normal(size=6)))
    moving = system.project_velocities(moving)
    off = SystemState(moving.q + 1e-3 * rng.normal(size=system.nq),
                      moving.v + 0.1 * rng.normal(size=system.nv),
                      ObjectState(o.position + 1e-3 * rng.normal(size=3), o.quaternion,
                                  moving.obj.twist))
    end = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, 0.0, 0.2)
                         @ pin.Quaternion(quat).toRotationMatrix()).coeffs()
    trajectory = MinimumJerkTrajectory([0.0, 1.0], [o.position, o.position + [0.05, 0, 0.03]],
                                       [quat, end])
    return system, state, off, trajectory


def object_pd(system, trajectory, **kw) -> ObjectPD:
    """An ``object_pd`` controller with non-zero null-space gains (every term acts)."""
    return ObjectPD(system, trajectory, margin=kw.pop("margin", 0.5), null_kp=25.0,
                    null_kd=10.0, **kw)


def rel_err(a, b) -> float:
    """Largest difference of ``a`` and ``b`` relative to ``max(1, max |b|)`` (0 when empty,
    e.g. the joints of a system without arms; the shapes must agree)."""
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape, (a.shape, b.shape)
    if not b.size:
        return 0.0
    return float(np.abs(a - b).max() / max(1.0, np.abs(b).max()))


def hold_task_conditions(ctrl, ev) -> np.ndarray:
    """(n,) condition numbers ``σ_max / σ_min`` of the arms' hold rows ``A_i = J_v + J_ω × d``
    (SVD; inf when ``A_i`` has fewer rows than joints)."""
    out = []
    for i in range(len(ctrl.hold_mask)):
        J = ev.arms.J[i][:, :ev.blocks.nv[i]]
        R = ev.arms.tools.rotation[i]
        rows = [J[:3] - np.cross(R @ p, J[3:].T).T
                for p in ctrl.hold_points_in_tool[i][ctrl.hold_mask[i]]]
        s = np.linalg.svd(np.vstack(rows), compute_uv=False)
        out.append(s[0] / s[-1] if len(s) == ev.blocks.nv[i] and s[-1] > 0 else np.inf)
    return np.array(out)


def run_scenario(name, duration, compiled, monkeypatch, integrator=None, **kw):
    """A run of a shipped scenario, with or without the compiled loop.

    ``compiled`` False turns the compiled loop off (the stepper takes every step; a
    controller's own compiled path stays on). ``integrator``: the scenario's own, or this one.

    Returns ``(result, calls)``: ``calls`` lists the ``(k0, k1)`` of every stretch the
    compiled loop was asked to run.
    """
    sc = load_scenario(SCENARIOS / f"{name}.yaml")
    if integrator is not None:
        sc = dataclasses.replace(sc, simulation=dataclasses.replace(sc.simulation,
                                                                    integrator=integrator))
    built = build_scenario(sc, load_visuals=False)
    sim = sc.simulation
    calls = []
    original = ContactLoop.run

    def counted(self, *args):
        calls.append(args[3:5])
        return original(self, *args)

    with monkeypatch.context() as mp:
        mp.setattr(ContactLoop, "run", counted)
        if not compiled:
            mp.setattr(ContactLoop, "for_run", classmethod(lambda cls, *a: None))
        result = simulate_built(built, scenario_controller(built), duration, sim.dt, sim.solver,
                                **kw)
    return result, calls


RUN_FIELDS = ("q", "v", "object_position", "object_quaternion", "object_twist", "tau", "mu", "phi",
          "phi_dot", "contact_points", "normals", "object_acceleration", "qdd",
          "kinetic_energy", "potential_energy", "momentum", "constraint_violation")
PLANNED = ("tau", "mu", "object_acceleration", "qdd")
"""Fields that carry a Panda's rank-deficient hold task's round-off noise (relative
``TOL_RANK_DEFICIENT_HOLD``, see ``closed_loop_cases``): the two runs fix the controller's
held points from evaluations equal to round-off, not bit for bit."""


def run_tolerance(field: str) -> float:
    """Agreement of the compiled and the Python loop on a recorded field."""
    return TOL_RANK_DEFICIENT_HOLD if field in PLANNED else 1e-9


def support_resultant(result, block: int) -> np.ndarray:
    """(T, 6) resultant ``[f; m]`` [N, N m] of contact block ``block``'s forces about the
    object's COM, world axes, from the recorded multipliers, normals and contact points.

    Unique even where its split among the block's rows is not (a support's coplanar
    vertices are redundant: which of them carries the load is decided by round-off).
    """
    f = result.mu[:, block, :, None] * result.normals[:, block]
    lever = result.contact_points[:, block] - result.object_position[:, None, :]
    return np.concatenate([f.sum(axis=1), np.cross(lever, f).sum(axis=1)], axis=1)


def assert_same_contact_run(fast, ref, tol: float, field_tol: float | None = None,
                            support_block: int | None = None) -> None:
    """The compiled run ``fast`` equals the Python run ``ref``: events, samples and fields.

    Events: the same (kind, block, row, rebound) in the same order, times within ``tol``,
    gap rates before and after to 1e-7; impulses row by row on the arms' rows, and on the
    rows of ``support_block`` (a support's plane: one normal for every row) their sum over
    the rows hit at one instant. Fields: ``RUN_FIELDS`` within ``field_tol`` (default
    ``tol``), the support block's multipliers through :func:`support_resultant`.
    """
    key = [(e.kind, e.block, e.row, e.rebound) for e in ref.events]
    assert [(e.kind, e.block, e.row, e.rebound) for e in fast.events] == key
    sums: dict[float, list[float]] = {}
    for a, b in zip(fast.events, ref.events, strict=True):
        assert abs(a.t - b.t) <= tol
        fields = ["phi_dot", "phi_dot_after"]
        if b.block == support_block:
            group = sums.setdefault(b.t, [0.0, 0.0])
            group[0] += a.impulse
            group[1] += b.impulse
        else:
            fields.append("impulse")
        for f in fields:
            assert abs(getattr(a, f) - getattr(b, f)) <= 1e-7 * (1.0 + abs(getattr(b, f))), f
    for t, (pa, pb) in sums.items():
        assert abs(pa - pb) <= 1e-7 * (1.0 + abs(pb)), ("support impulse", t)
    field_tol = tol if field_tol is None else field_tol
    for field in RUN_FIELDS:
        a, b = getattr(fast, field), getattr(ref, field)
        if field == "mu" and support_block is not None:
            assert rel_err(support_resultant(fast, support_block),
                           support_resultant(ref, support_block)) <= field_tol, "support"
            a, b = np.delete(a, support_block, axis=1), np.delete(b, support_block, axis=1)
        assert rel_err(a, b) <= field_tol, field
    np.testing.assert_array_equal(fast.t, ref.t)
    np.testing.assert_array_equal(fast.active, ref.active)
    assert list(fast.solver) == list(ref.solver)
