#!/usr/bin/env python
"""Benchmark: object-first solver vs dense KKT vs Pinocchio (thesis Table 4.4 and beyond).

Three cases, each at random *consistent* states (joints built where the tools are, random
velocities projected onto the constraints' null space, random torques around gravity
compensation):

- ``revolute`` (thesis Sec 4.4, Table 4.4, and scaling): n 6-joint arms, each holding one
  large box through a revolute joint (5 frictionless point contacts). For each n:
  ``t``  = time to build the coefficient blocks (``MultiArmSystem.blocks``: Pinocchio terms
  of the arms in combined models of at most 16 arms + the compiled constraint rows and
  assembly), ``t1`` = object-first solve (compiled), ``t1np`` = the vectorised numpy
  object-first solve (``object_first_numpy``, the reference), ``t2`` = dense KKT solve
  (``multiarm_pin.dynamics.solve(blocks, name)``).
- ``weld`` (peer): the same systems with weld grasps (6 contacts), our full step
  (``MultiArmSystem.forward_dynamics``: blocks + object-first solve) against one call of
  ``pin.constraintDynamics`` on one combined Pinocchio model (free-flyer object + arms,
  ``CONTACT_6D`` constraints). Both answers are compared at every state.
- a stage profile (where the time of one full step goes) at a few n.
- ``unilateral`` (issue 12): the exact unilateral (mixed-LCP) solve
  ``solve_unilateral(blocks, unilateral)`` against the bilateral solve
  ``solve(blocks, "auto")`` of the same contacts, on states of the two-gripper form-closure
  scenario (7 fingertip contacts on two 6-joint arms, from
  ``scenarios/two_gripper_form_closure.yaml``) plus 4 table contacts under the box's lowest
  vertices appended as a zero-dof support arm (``c = 0``). Two torque families: ``random``
  (gravity compensation + N(0, 2 N m): some fingertips separate) and ``squeeze`` (gravity
  compensation + 15 N of squeeze per fingertip: the fingertips push; a table row may
  lift). Each state's motion is compared with the bilateral solve of its rows that do not
  separate. Written to
  ``solver_vs_kkt_unilateral.csv`` and to a section of the report; ``--unilateral-only``
  writes only ``unilateral.csv`` / ``unilateral.md``.

Every time is the median of many single-call timings (``time.perf_counter``, garbage
collector off, states cycled, warm-up calls excluded). Outputs in ``--out``:
``solver_vs_kkt.csv``, ``solver_vs_kkt.md`` (report) and ``solver_vs_kkt.png`` (plot).

Usage::

    .venv/bin/python benchmarks/solver_vs_kkt.py                 # full run (~2 min)
    .venv/bin/python benchmarks/solver_vs_kkt.py --quick --out /tmp/bench
    .venv/bin/python benchmarks/solver_vs_kkt.py --arms 2,4,8 --peer-arms 2,4 --repeat 500
    .venv/bin/python benchmarks/solver_vs_kkt.py --unilateral-only     # issue 12 row (~15 s)
"""

from __future__ import annotations

import os

# single-threaded BLAS/LAPACK, like Pinocchio: on a small shared VM, threaded BLAS on small
# matrices mostly measures thread contention (must be set before numpy is imported)
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import gc  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Sequence  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run from a checkout without installing
    sys.path.insert(0, str(ROOT))

from report_tables import int_list, write_rows_csv  # noqa: E402

from multiarm_pin._compiled.layout import state_vector  # noqa: E402
from multiarm_pin.app.scenario import build_scenario, load_scenario  # noqa: E402
from multiarm_pin.dynamics import (  # noqa: E402
    SystemBlocks,
    solve,
    solve_dense_kkt,
    solve_unilateral,
)
from multiarm_pin.dynamics.blocks import restrict_rows  # noqa: E402
from multiarm_pin.model.arm import Arm  # noqa: E402
from multiarm_pin.model.rigid_object import RigidObject  # noqa: E402
from multiarm_pin.spatial import quaternion_to_rotation  # noqa: E402
from multiarm_pin.system import MultiArmSystem, SystemState  # noqa: E402

THESIS_TABLE_4_4 = {
    # n: (total speed-up (t2+t)/(t1+t), solve speed-up t2/t1, time saved t2-t1 [ms])
    2: (0.98, 0.71, -6.5),
    3: (0.99, 0.77, -7.2),
    4: (0.99, 0.88, -4.9),
    5: (1.00, 1.03, 1.3),
    6: (1.01, 1.22, 12.3),
    7: (1.02, 1.41, 27.1),
    8: (1.03, 1.64, 47.7),
    9: (1.05, 1.88, 73.7),
    10: (1.06, 2.13, 104.6),
}
"""Thesis Table 4.4 (Matlab 4.2a, msolve vs msolve03), averages."""

DEFAULT_ARMS = (2, 3, 4, 5, 6, 7, 8, 9, 10, 16, 32, 64, 128)
DEFAULT_PEER_ARMS = (2, 3, 4, 6, 8, 10, 12, 16, 24, 32)
DEFAULT_PROFILE_ARMS = (2, 10, 64)
QUICK_ARMS = (2, 3)
QUICK_PEER_ARMS = (2, 3)
QUICK_PROFILE_ARMS = (2,)

ROBOT_TOOL = {"ur5": "tool0", "mp6": "tool0"}
NOMINAL_Q = {
    "ur5": np.array([0.0, -1.1, 1.6, -0.5, 1.57, 0.0]),
    "mp6": np.array([0.0, -0.6, 1.2, 0.0, 0.9, 0.0]),
}


# ---------------------------------------------------------------------------- systems
_MODELS: dict[str, pin.Model] = {}


def robot_model(robot: str) -> pin.Model:
    """The Pinocchio model of one arm (loaded once)."""
    if robot not in _MODELS:
        if robot == "ur5":
            import example_robot_data as erd

            _MODELS[robot] = erd.load("ur5").model
        elif robot == "mp6":
            _MODELS[robot] = pin.buildModelFromUrdf(str(ROOT / "robots" / "mp6" / "mp6.urdf"))
        else:
            raise SystemExit(f"unknown robot {robot!r}; known: {', '.join(ROBOT_TOOL)}")
    return _MODELS[robot]


@dataclass
class Bench:
    """One benchmarked system and its random consistent states."""

    system: MultiArmSystem
    states: list[SystemState]
    taus: list[np.ndarray]
    blocks: list = field(default_factory=list)


def build_bench(n: int, joint: str, robot: str, n_states: int, seed: int) -> Bench:
    """n arms on a circle around one large box, each holding it by ``joint``.

    The bases are spaced ~0.6 m apart on a circle of radius ``max(1.1, 0.6 n / 2π)`` m facing
    the centre; the box (2R x 2R x 0.3 m, 10 n kg) has its COM 0.45 m above the bases'
    plane. Each arm starts at a nominal pose plus uniform noise of ±0.35 rad and its joint is
    built where its tool is (``MultiArmSystem.from_initial_state``), so positions are
    consistent; velocities are random, projected on the constraints' null space.
    """
    rng = np.random.default_rng(seed)
    model = robot_model(robot)
    radius = max(1.1, 0.6 * n / (2 * math.pi))
    arms, q0 = [], []
    for i in range(n):
        th = 2 * math.pi * i / n
        base = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, th + math.pi),
                       np.array([radius * math.cos(th), radius * math.sin(th), 0.0]))
        arms.append(Arm.from_model(model, ROBOT_TOOL[robot], name=f"arm{i}", base_placement=base,
                                   source=robot))
        q0.append(NOMINAL_Q[robot] + rng.uniform(-0.35, 0.35, model.nq))
    obj = RigidObject.box([2 * radius, 2 * radius, 0.3], 10.0 * n)
    system, s0 = MultiArmSystem.from_initial_state(
        arms, obj, [joint] * n, q0, pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.45])))
    states, taus = [], []
    g = system.gravity_torques(s0.q)
    for _ in range(n_states):
        st = system.state(s0.q, rng.normal(0.0, 0.5, system.nv), s0.obj.position,
                          s0.obj.quaternion, rng.normal(0.0, 0.2, 6))
        states.append(system.project_velocities(st))
        taus.append(g + rng.normal(0.0, 5.0, system.nv))
    bench = Bench(system, states, taus)
    bench.blocks = [system.blocks(s, t).blocks for s, t in zip(states, taus, strict=True)]
    return bench


# ---------------------------------------------------------------------------- Pinocchio peer
@dataclass
class PinocchioPeer:
    """The weld system as one Pinocchio model: free-flyer object + all arms, CONTACT_6D."""

    model: pin.Model
    data: pin.Data
    constraints: object
    constraint_datas: object
    settings: pin.ProximalSettings
    q: list[np.ndarray]
    v: list[np.ndarray]
    tau: list[np.ndarray]

    def step(self, k: int) -> np.ndarray:
        """``pin.constraintDynamics`` at state k; returns ``ddq`` (6 + nv,)."""
        return pin.constraintDynamics(self.model, self.data, self.q[k], self.v[k], self.tau[k],
                                      self.constraints, self.constraint_datas, self.settings)


def build_peer(bench: Bench) -> PinocchioPeer:
    """Pinocchio's own closed-chain model of a weld bench (see PINOCCHIO_NOTES.md)."""
    system = bench.system
    arm_model = system.arm_set.model
    obj = system.obj
    model = pin.Model()
    jid = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "object")
    model.appendBodyToJoint(jid, pin.Inertia(obj.mass, np.zeros(3), obj.inertia),
                            pin.SE3.Identity())
    model = pin.appendModel(model, arm_model, 0, pin.SE3.Identity())
    model.gravity = arm_model.gravity
    obj_jid = model.getJointId("object")
    data = model.createData()
    s0 = bench.states[0]
    oMobj = pin.SE3(s0.obj.rotation, s0.obj.position)
    q_full = np.concatenate([s0.obj.position, s0.obj.quaternion, s0.q])
    pin.framesForwardKinematics(model, data, q_full)
    cms, cds = pin.StdVec_RigidConstraintModel(), pin.StdVec_RigidConstraintData()
    for i, arm in enumerate(system.arms):
        fid = model.getFrameId(f"{arm.name}/{arm.model.frames[arm.tool_frame_id].name}")
        tool = model.frames[fid]
        oMtool = data.oMf[fid]
        cm = pin.RigidConstraintModel(pin.ContactType.CONTACT_6D, model, tool.parentJoint,
                                      tool.placement, obj_jid, oMobj.actInv(oMtool),
                                      pin.ReferenceFrame.LOCAL)
        cm.name = f"weld{i}"
        cms.append(cm)
        cds.append(cm.createData())
    pin.initConstraintDynamics(model, data, cms, cds)
    qs, vs, taus = [], [], []
    for st, tau in zip(bench.states, bench.taus, strict=True):
        R = st.obj.rotation
        qs.append(np.concatenate([st.obj.position, st.obj.quaternion, st.q]))
        vs.append(np.concatenate([R.T @ st.obj.twist[:3], R.T @ st.obj.twist[3:], st.v]))
        taus.append(np.concatenate([np.zeros(6), tau]))
    return PinocchioPeer(model, data, cms, cds, pin.ProximalSettings(1e-12, 0.0, 1), qs, vs, taus)


def peer_difference(bench: Bench, peer: PinocchioPeer) -> float:
    """Largest relative difference between our object-first answer and Pinocchio's.

    Pinocchio's free-flyer acceleration is the spatial one in the object frame; it is
    converted to the classical ``[ẍ; ω̇]`` in world axes before comparing.
    """
    worst = 0.0
    system = bench.system
    for k, (st, tau) in enumerate(zip(bench.states, bench.taus, strict=True)):
        sol, _ = system.forward_dynamics(st, tau, "object_first")
        a = peer.step(k)
        R = st.obj.rotation
        v_local = peer.v[k][:6]
        lin = R @ (a[:3] + np.cross(v_local[3:], v_local[:3]))
        ours = np.concatenate([sol.a_o, system.unpad(sol.qdd)])
        theirs = np.concatenate([lin, R @ a[3:6], a[6:]])
        worst = max(worst, float(np.abs(ours - theirs).max() / max(1.0, np.abs(theirs).max())))
    return worst


def kkt_difference(bench: Bench) -> float:
    """Largest relative difference between the object-first and dense KKT answers."""
    worst = 0.0
    for b in bench.blocks:
        s1, s2 = solve(b, "object_first"), solve(b, "dense_kkt")
        x1 = np.concatenate([s1.a_o, s1.qdd.ravel(), s1.mu.ravel()])
        x2 = np.concatenate([s2.a_o, s2.qdd.ravel(), s2.mu.ravel()])
        worst = max(worst, float(np.abs(x1 - x2).max() / max(1.0, np.abs(x2).max())))
    return worst


# ---------------------------------------------------------------------------- timing
@dataclass
class Timer:
    """Median single-call times of several functions, measured interleaved.

    The functions are called round-robin (one call of each per round), so that a change of
    the machine's load affects all of them alike and their ratios stay meaningful.
    """

    repeat: int
    warmup: int = 20
    budget_s: float = 2.0

    def medians(self, fns: Sequence[Callable[[int], object]], n_states: int
                ) -> tuple[list[float], int]:
        """Median seconds of each ``fn(k)`` (k cycles over the states) and the rounds run."""
        for i in range(self.warmup):
            for fn in fns:
                fn(i % n_states)
        t0 = time.perf_counter()
        for fn in fns:
            fn(0)
        once = max(time.perf_counter() - t0, 1e-7)
        reps = int(max(5, min(self.repeat, self.budget_s / once)))
        times = np.empty((reps, len(fns)))
        clock = time.perf_counter
        gc_was = gc.isenabled()
        gc.disable()
        try:
            for i in range(reps):
                k = i % n_states
                row = times[i]
                for j, fn in enumerate(fns):
                    t = clock()
                    fn(k)
                    row[j] = clock() - t
        finally:
            if gc_was:
                gc.enable()
        return [float(x) for x in np.median(times, axis=0)], reps


@dataclass
class Row:
    """One line of the CSV."""

    case: str
    n_arms: int
    nv_total: int
    n_constraints: int
    t_coeff_s: float
    t_object_first_s: float
    t_object_first_numpy_s: float
    t_dense_kkt_s: float
    t_full_step_s: float
    t_pinocchio_s: float
    repeats: int
    max_rel_diff_kkt: float
    max_rel_diff_pinocchio: float



def measure_case(bench: Bench, case: str, timer: Timer, peer: PinocchioPeer | None) -> Row:
    """Time coefficient blocks, both solvers, the full step and (weld) Pinocchio."""
    system, states, taus, blocks = bench.system, bench.states, bench.taus, bench.blocks
    K = len(states)
    fns = [
        lambda k: system.blocks(states[k], taus[k]),
        lambda k: solve(blocks[k], "object_first"),
        lambda k: solve(blocks[k], "object_first_numpy"),
        # the bare assembly + LU of msolve03: the structural rank check is not timed
        lambda k: solve_dense_kkt(blocks[k], check_rank=False),
        lambda k: system.forward_dynamics(states[k], taus[k], "object_first"),
    ]
    if peer is not None:
        fns.append(peer.step)
    times, reps = timer.medians(fns, K)
    t_coeff, t1, t1np, t2, t_full = times[:5]
    t_pin, diff_pin = math.nan, math.nan
    if peer is not None:
        t_pin = times[5]
        diff_pin = peer_difference(bench, peer)
    return Row(case, system.n_arms, system.nv, int(blocks[0].n_constraints), t_coeff, t1, t1np,
               t2, t_full, t_pin, reps, kkt_difference(bench), diff_pin)


STAGES = (
    ("pinocchio", "Pinocchio: `computeJointJacobiansTimeVariation` + `crba` + "
                  "`nonLinearEffects` (groups of <= 16 arms) + tool placements"),
    ("kernels", "compiled arm terms + constraint rows + assembly (`_compiled.evaluate`)"),
    ("solve", "compiled object-first solve inside the step"),
    ("glue", "Python glue: input checks, state concatenation, result objects"),
)
"""Stages of one compiled full step (``forward_dynamics``), in order."""


def profile_stages(bench: Bench, timer: Timer) -> dict[str, float]:
    """Median time of each stage of one full step (weld or revolute system).

    ``pinocchio`` = :meth:`ArmSet.pinocchio_pass`; ``kernels`` = the compiled evaluation on
    its results (timed right after it in each round, so Pinocchio's data hold that state);
    ``solve`` = the compiled step minus the evaluation; ``glue`` = the full step minus all
    that. Also returned: ``solve_alone`` = ``solve(blocks, 'object_first')`` with its
    Python wrapper, ``solve_numpy`` = ``object_first_numpy``, ``blocks`` =
    ``MultiArmSystem.blocks``.
    """
    system, states, taus, blocks = bench.system, bench.states, bench.taus, bench.blocks
    K = len(states)
    aset = system.arm_set
    xs = [state_vector(s.obj.position, s.obj.quaternion, s.obj.twist, s.q, s.v, t)
          for s, t in zip(states, taus, strict=True)]
    Hs = [aset.pinocchio_pass(s.q, s.v) for s in states]
    path = system.compiled
    buf = np.empty(path.layout.size)

    def kernels_only(k, step):  # called right after pinocchio_pass(k): its data are state k's
        return path.kernel_pass(Hs[k], xs[k], path.params, buf, step)

    (t_pin, t_pk, t_pks, t_blocks, t_solve, t_np, t_full), _ = timer.medians([
        lambda k: aset.pinocchio_pass(states[k].q, states[k].v),
        lambda k: kernels_only(k, False),
        lambda k: kernels_only(k, True),
        lambda k: system.blocks(states[k], taus[k]),
        lambda k: solve(blocks[k], "object_first"),
        lambda k: solve(blocks[k], "object_first_numpy"),
        lambda k: system.forward_dynamics(states[k], taus[k], "object_first"),
    ], K)
    t_k, t_ks = t_pk, t_pks
    return {
        "pinocchio": t_pin,
        "kernels": t_k,
        "solve": max(t_ks - t_k, 0.0),
        "glue": max(t_full - t_pin - t_ks, 0.0),
        "full_step": t_full,
        "blocks": t_blocks,
        "solve_alone": t_solve,
        "solve_numpy": t_np,
    }


# ---------------------------------------------------------------------------- outputs
# ---------------------------------------------------------------------------- unilateral
TWO_GRIPPER = ROOT / "scenarios" / "two_gripper_form_closure.yaml"
SQUEEZE_N = 15.0
"""Squeeze force per fingertip of the ``squeeze`` family [N]."""


@dataclass
class ContactRow:
    """One line of the unilateral CSV: one torque family of the two-gripper + table states."""

    family: str
    n_states: int
    n_rows: int
    t_bilateral_s: float
    t_unilateral_s: float
    t_bilateral_fingertips_s: float
    t_unilateral_guess_s: float
    ratio: float
    mean_pivots: float
    separating_rows: int
    fast_path_states: int
    max_complementarity: float
    max_rel_diff_bilateral: float
    states_compared: int
    repeats: int



def with_table(b: SystemBlocks, R: np.ndarray, vertices: np.ndarray) -> SystemBlocks:
    """The blocks plus a zero-dof support arm: 4 table rows (normal +z) at the lowest vertices.

    ``vertices`` (V, 3) in the object frame about the COM; ``R`` the object rotation. Row k's
    wrench per unit force is ``[z; (R v_k) × z]`` (world axes at the COM), ``c = 0``.
    """
    z = np.array([0.0, 0.0, 1.0])
    world = vertices @ R.T
    low = np.argsort(world[:, 2], kind="stable")[:4]
    Wt = np.array([np.concatenate((z, np.cross(world[k], z))) for k in low]).T
    arms = range(b.n)
    return SystemBlocks.from_lists(
        [b.M[i, : b.nv[i], : b.nv[i]] for i in arms] + [np.zeros((0, 0))],
        [b.h[i, : b.nv[i]] for i in arms] + [np.zeros(0)],
        [b.W[i, : b.nv[i], : b.N[i]] for i in arms] + [np.zeros((0, 4))],
        [b.W_o[i, :, : b.N[i]] for i in arms] + [Wt],
        [b.c[i, : b.N[i]] for i in arms] + [np.zeros(4)],
        b.M_o, b.h_o)


def build_contact_bench(n_states: int, seed: int
                        ) -> dict[str, list[tuple[SystemBlocks, SystemBlocks]]]:
    """Blocks of the two-gripper scenario + 4 table rows at random consistent states.

    Positions are the scenario's initial ones (inverse kinematics); joint and object
    velocities random (N(0, 0.3), N(0, 0.1)) projected onto the constraints' null space.
    Torques: gravity compensation + N(0, 2 N m) (``random``) or gravity compensation +
    ``-W_i f`` with ``f = SQUEEZE_N`` per fingertip (``squeeze``). Each state gives the
    blocks with the table rows and the fingertip-only blocks.
    """
    built = build_scenario(load_scenario(TWO_GRIPPER))
    system, s0 = built.system, built.initial_state
    rng = np.random.default_rng(seed)
    g = system.gravity_torques(s0.q)
    out: dict[str, list[tuple[SystemBlocks, SystemBlocks]]] = {"random": [], "squeeze": []}
    for _ in range(n_states):
        st = system.project_velocities(system.state(
            s0.q, rng.normal(0.0, 0.3, system.nv), s0.obj.position, s0.obj.quaternion,
            rng.normal(0.0, 0.1, 6)))
        R = quaternion_to_rotation(st.obj.quaternion)
        b0 = system.blocks(st).blocks
        squeeze = np.concatenate([-b0.W[i, : b0.nv[i], : b0.N[i]] @ np.full(b0.N[i], SQUEEZE_N)
                                  for i in range(b0.n)])
        for family, tau in (("random", g + rng.normal(0.0, 2.0, system.nv)),
                            ("squeeze", g + squeeze)):
            tips = system.blocks(st, tau).blocks
            out[family].append((with_table(tips, R, built.obj.shape.vertices), tips))
    return out


def measure_contacts(family: str, pairs: list[tuple[SystemBlocks, SystemBlocks]],
                     timer: Timer) -> ContactRow:
    """Time the bilateral and the unilateral solve of the same contacts (and the bilateral
    solve of the fingertips alone, for context); check the answers."""
    blocks = [p[0] for p in pairs]
    tips = [p[1] for p in pairs]
    unis = [b.constraint_mask.copy() for b in blocks]
    guesses = [solve_unilateral(b, u).mu > 0 for b, u in zip(blocks, unis, strict=True)]
    K = len(blocks)
    fns = [lambda k: solve(blocks[k], "auto"),
           lambda k: solve_unilateral(blocks[k], unis[k]),
           lambda k: solve(tips[k], "auto"),
           lambda k: solve_unilateral(blocks[k], unis[k], guess=guesses[k])]
    (t_bil, t_uni, t_tips, t_guess), reps = timer.medians(fns, K)
    pivots, separating, fast, comp, diff, compared = [], 0, 0, 0.0, 0.0, 0
    for b, uni in zip(blocks, unis, strict=True):
        sol = solve_unilateral(b, uni)
        pivots.append(sol.pivots)
        separating += int(sol.separating.sum())
        fast += sol.solver == "bilateral"
        comp = max(comp, sol.complementarity)
        # every state is compared: without its separating rows (a unique verdict, from φ̈),
        # the motion is the bilateral one of the rows left (the redundant table rows among
        # them carry loads that are not unique, but their φ̈ = 0 is)
        compared += 1
        ref = solve(restrict_rows(b, ~sol.separating)[0], "auto")
        scale = max(1.0, np.abs(ref.a_o).max(), np.abs(ref.qdd).max())
        diff = max(diff, float(max(np.abs(sol.a_o - ref.a_o).max(),
                                   np.abs(sol.qdd - ref.qdd).max()) / scale))
    return ContactRow(family, K, int(blocks[0].n_constraints), t_bil, t_uni, t_tips, t_guess,
                      t_uni / t_bil, float(np.mean(pivots)), separating, fast, comp,
                      diff if compared else math.nan, compared, reps)


def contact_section(rows: Sequence[ContactRow]) -> list[str]:
    """Markdown section of the unilateral benchmark, with its target."""
    L = ["## Unilateral contacts (issue 12): exact mixed-LCP solve vs bilateral solve\n",
         "Two-gripper form-closure scenario (`scenarios/two_gripper_form_closure.yaml`: 4 + 3 "
         "fingertips on two 6-joint arms) at random consistent states, plus 4 table contacts "
         "under the box's lowest vertices appended as a zero-dof support arm (`c = 0`; built "
         "here, not by a scenario): 11 rows, all unilateral. `bilateral` = "
         "`solve(blocks, 'auto')` of the same 11 rows (the support arm makes it take the "
         "singular-arm path); `unilateral` = `solve_unilateral(blocks, unilateral)` (compiled "
         "object-first Delassus + active-set method). Families: `random` torques (gravity "
         "compensation + N(0, 2 N m): fingertips separate), `squeeze` (gravity compensation + "
         f"{SQUEEZE_N:g} N per fingertip: the fingertips push). *diff* = largest relative "
         "motion difference from the bilateral solve of each state's rows that do not "
         "separate (every state compared). For context, *fingertips bilateral* = "
         "`solve(blocks, 'auto')` of the 7 fingertip rows alone (no support arm: the compiled "
         "object-first kernel); *unilateral, warm* = `solve_unilateral(..., guess=mu > 0)` "
         "with the pushing rows of the same state's answer as warm start (a simulation step "
         "whose contact state has not changed: no pivot).\n",
         "| family | states | rows | bilateral µs | unilateral µs | unilateral / bilateral | "
         "unilateral, warm µs | fingertips bilateral µs | mean pivots | separating rows | "
         "fast-path states | max complementarity | diff (states) |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        diff = ("n/a" if not r.states_compared else
                f"{r.max_rel_diff_bilateral:.1e} ({r.states_compared})")
        L.append(f"| {r.family} | {r.n_states} | {r.n_rows} | {_us(r.t_bilateral_s)} | "
                 f"{_us(r.t_unilateral_s)} | {r.ratio:.2f} | {_us(r.t_unilateral_guess_s)} | "
                 f"{_us(r.t_bilateral_fingertips_s)} | {r.mean_pivots:.1f} | "
                 f"{r.separating_rows} | {r.fast_path_states} | "
                 f"{r.max_complementarity:.1e} | {diff} |")
    worst = max(r.ratio for r in rows)
    L.append("")
    L.append(f"- [{'x' if worst <= 2 else ' '}] unilateral solve within 2x of the bilateral "
             f"solve of the same contacts: worst ratio {worst:.2f}")
    L.append("")
    return L


def run_contacts(args: argparse.Namespace, timer: Timer) -> list[ContactRow]:
    benches = build_contact_bench(args.states, args.seed + 12)
    rows = [measure_contacts(f, bl, timer) for f, bl in benches.items()]
    for r in rows:
        print(f"unilateral {r.family:8s} bilateral {r.t_bilateral_s * 1e6:8.1f}  unilateral "
              f"{r.t_unilateral_s * 1e6:8.1f} µs  ratio {r.ratio:.2f}  warm "
              f"{r.t_unilateral_guess_s * 1e6:6.1f}  tips bilateral "
              f"{r.t_bilateral_fingertips_s * 1e6:6.1f} µs  pivots "
              f"{r.mean_pivots:.1f}  separating {r.separating_rows}  comp "
              f"{r.max_complementarity:.1e}", flush=True)
    return rows


def _us(x: float) -> str:
    return "–" if math.isnan(x) else f"{x * 1e6:.1f}"


def crossover(rows: Sequence[Row]) -> int | None:
    """Smallest n from which our full step is faster than Pinocchio at every larger n."""
    rows = sorted(rows, key=lambda r: r.n_arms)
    ahead = None
    for r in reversed(rows):
        if r.t_full_step_s < r.t_pinocchio_s:
            ahead = r.n_arms
        else:
            break
    return ahead


def environment() -> dict[str, str]:
    """CPU, core count and library versions."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import scipy

    import multiarm_pin

    try:
        load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        load = "?"
    import subprocess

    try:
        commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                                capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--",
                                "multiarm_pin"], capture_output=True, text=True,
                               timeout=10).stdout.strip()
        commit = (commit or "?") + (" (with uncommitted changes in multiarm_pin/)"
                                    if dirty else "")
    except (OSError, subprocess.SubprocessError):
        commit = "?"
    return {
        "git commit": commit,
        "CPU": f"{cpu} ({os.cpu_count()} logical cores)",
        "load average at start (1, 5, 15 min)": load,
        "BLAS threads (OPENBLAS_NUM_THREADS)": os.environ.get("OPENBLAS_NUM_THREADS", "?"),
        "Python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "pinocchio": pin.__version__,
        "numba": _numba_version(),
        "multiarm_pin": getattr(multiarm_pin, "__version__", "?"),
        "platform": platform.platform(),
    }


def _numba_version() -> str:
    try:
        import numba
    except ImportError:  # pragma: no cover
        return "not installed"
    return numba.__version__


def write_report(path: Path, rows: Sequence[Row], profiles: dict[tuple[str, int], dict],
                 env: dict[str, str], args: argparse.Namespace, wall_s: float,
                 contact_rows: Sequence[ContactRow] = ()) -> None:
    rev = sorted([r for r in rows if r.case == "revolute"], key=lambda r: r.n_arms)
    weld = sorted([r for r in rows if r.case == "weld"], key=lambda r: r.n_arms)
    L: list[str] = []
    L.append("# Object-first solver vs dense KKT vs Pinocchio\n")
    L.append(f"Generated by `benchmarks/solver_vs_kkt.py {' '.join(sys.argv[1:])}`"
             f" in {wall_s:.0f} s.\n")
    L.append("## Environment\n")
    L += [f"- {k}: {v}" for k, v in env.items()]
    L.append("\n## Method\n")
    L.append(
        f"- Arms: `{args.robot}` (6 revolute joints each) on a circle around one large box; "
        "each arm holds the box through a joint built where its tool is (revolute: 5 "
        "frictionless point contacts, 1 DOF; weld: 6 contacts, 0 DOF).\n"
        f"- {args.states} random consistent states per system (positions on the constraint "
        "manifold, random joint and object velocities projected onto the constraints' null "
        "space, torques = gravity compensation + N(0, 5 N m)); states are cycled.\n"
        "- Every time is the **median** of single-call timings (`time.perf_counter`); the "
        "functions compared in one table row are called **interleaved** (round-robin, one call "
        "of each per round) so that load changes on the machine hit them alike; "
        f"up to {args.repeat} rounds per row (fewer for slow calls: ~"
        f"{args.budget:g} s budget, at least 5), after {args.warmup} warm-up rounds that "
        "are excluded; the garbage collector is off while timing.\n"
        "- `t` = `MultiArmSystem.blocks(state, tau)` (Pinocchio terms of the arms in "
        "combined models of at most 16 arms + compiled (numba) arm terms, constraint rows and "
        "block assembly, with input checks); `t1` = `solve(blocks, 'object_first')` (compiled "
        "kernel: per-arm Cholesky); `t1np` = `solve(blocks, 'object_first_numpy')` (the "
        "vectorised numpy object-first solver, batched LAPACK: the reference and previous "
        "implementation); `t2` = `solve_dense_kkt(blocks, check_rank=False)` "
        "(assembles and LU-solves the full KKT matrix, like the thesis's `msolve03`; the "
        "structural rank check that `solve(blocks, 'dense_kkt')` adds is not timed); "
        "full step = `MultiArmSystem.forward_dynamics(state, tau, 'object_first')` "
        "(blocks and solve in one compiled call).\n"
        "- Pinocchio peer: one `pin.Model` with a free-flyer object followed by all arms "
        "(`pin.appendModel`), one `CONTACT_6D` `RigidConstraintModel` per arm (tool joint ↔ "
        "object joint, LOCAL), one call of `pin.constraintDynamics` with `ProximalSettings(1e-12, "
        "0, 1)` (exact KKT solution) per step. Its answer is compared with ours at every state "
        "(column *diff vs Pinocchio*: largest |difference| / max(1, |value|) over object and "
        "joint accelerations).\n"
        "- The machine is a shared 2-core VM: absolute times vary by up to ~2x between runs; "
        "ratios are taken within one run.\n")

    if rev:
        L.append("## Thesis case (Table 4.4): 6-joint arms, revolute grasps\n")
        L.append("`t`, `t1`, `t2` in µs. Thesis figures (Matlab 4.2a, 1990s hardware) in "
                 "brackets; its time saved is in ms.\n")
        L.append("| n | constraints | t | t1 object-first | t1np numpy object-first | t2 dense "
                 "KKT | total speed-up (t2+t)/(t1+t) [thesis] | solve speed-up t2/t1 [thesis] | "
                 "t2/t1np | time saved t2-t1 µs [thesis ms] | diff vs KKT |")
        L.append("|---|---|---|---|---|---|---|---|---|---|---|")
        for r in rev:
            th = THESIS_TABLE_4_4.get(r.n_arms)
            tt, t1, t2 = r.t_coeff_s, r.t_object_first_s, r.t_dense_kkt_s
            b = [f" [{x:g}]" for x in th] if th else ["", "", ""]
            L.append(f"| {r.n_arms} | {r.n_constraints} | {_us(tt)} | {_us(t1)} | "
                     f"{_us(r.t_object_first_numpy_s)} | {_us(t2)} | "
                     f"{(t2 + tt) / (t1 + tt):.2f}{b[0]} | {t2 / t1:.2f}{b[1]} | "
                     f"{t2 / r.t_object_first_numpy_s:.2f} | "
                     f"{(t2 - t1) * 1e6:.1f}{b[2]} | {r.max_rel_diff_kkt:.1e} |")
        L.append("")
        L.append("## Scaling with the number of arms (revolute grasps)\n")
        L.append("| n | t per arm µs | t1 per arm µs | t1np per arm µs | t2 per arm µs | "
                 "full step µs | full step per arm µs |")
        L.append("|---|---|---|---|---|---|---|")
        for r in rev:
            n = r.n_arms
            L.append(f"| {n} | {_us(r.t_coeff_s / n)} | {_us(r.t_object_first_s / n)} | "
                     f"{_us(r.t_object_first_numpy_s / n)} | "
                     f"{_us(r.t_dense_kkt_s / n)} | {_us(r.t_full_step_s)} | "
                     f"{_us(r.t_full_step_s / n)} |")
        L.append("")
    if weld:
        L.append("## Peer: weld grasps, our full step vs `pin.constraintDynamics`\n")
        L.append("| n | t full step µs | t Pinocchio µs | ours / Pinocchio | t µs | t1 µs | "
                 "t1np µs | t2 µs | diff vs Pinocchio | diff vs KKT |")
        L.append("|---|---|---|---|---|---|---|---|---|---|")
        for r in weld:
            L.append(f"| {r.n_arms} | {_us(r.t_full_step_s)} | {_us(r.t_pinocchio_s)} | "
                     f"{r.t_full_step_s / r.t_pinocchio_s:.2f} | {_us(r.t_coeff_s)} | "
                     f"{_us(r.t_object_first_s)} | {_us(r.t_object_first_numpy_s)} | "
                     f"{_us(r.t_dense_kkt_s)} | "
                     f"{r.max_rel_diff_pinocchio:.1e} | {r.max_rel_diff_kkt:.1e} |")
        n_ahead = crossover(weld)
        L.append("")
        L.append("Our full step is ahead of `pin.constraintDynamics` from **n = "
                 f"{n_ahead}** arms on (measured n)." if n_ahead is not None else
                 "Our full step is not ahead of `pin.constraintDynamics` at the largest n "
                 "measured.")
        L.append("")
    if profiles:
        L.append("## Where the time of one full step goes\n")
        L.append("Median µs per stage of the compiled step, stages timed on the same states "
                 "(`kernels` = compiled evaluation on Pinocchio's results; `solve` = "
                 "compiled step minus compiled evaluation; `glue` = full step minus the rest). "
                 "Share = stage / full step. Below the line, for comparison: `blocks` alone, "
                 "the compiled solve called alone (with its Python wrapper) and the numpy "
                 "object-first solve.\n")
        keys = sorted(profiles)
        L.append("| stage | " + " | ".join(f"{c} n={n}" for c, n in keys) + " |")
        L.append("|---|" + "---|" * len(keys))
        for name, label in STAGES:
            cells = []
            for key in keys:
                p = profiles[key]
                cells.append(f"{p[name] * 1e6:.1f} ({100 * p[name] / p['full_step']:.0f}%)")
            L.append(f"| {label} | " + " | ".join(cells) + " |")
        L.append("| **full step** (`forward_dynamics`) | "
                 + " | ".join(f"**{profiles[k]['full_step'] * 1e6:.1f}**" for k in keys) + " |")
        for name, label in (("blocks", "`MultiArmSystem.blocks` alone"),
                            ("solve_alone", "`solve(blocks, 'object_first')` alone"),
                            ("solve_numpy", "`solve(blocks, 'object_first_numpy')`")):
            L.append(f"| {label} | " + " | ".join(f"{profiles[k][name] * 1e6:.1f}"
                                                   for k in keys) + " |")
        L.append("")
    if contact_rows:
        L += contact_section(contact_rows)
    L.append("## Targets (issue 7)\n")
    L += targets(rev, weld)
    L.append("")
    path.write_text("\n".join(L) + "\n")


def targets(rev: Sequence[Row], weld: Sequence[Row]) -> list[str]:
    """Checklist of the issue's targets with the measured values."""
    out = []
    by_n = {r.n_arms: r for r in rev}
    ge2 = [r for r in rev if r.n_arms >= 2]
    if ge2:
        ok = all(r.t_object_first_s < r.t_dense_kkt_s for r in ge2)
        worst = min(ge2, key=lambda r: r.t_dense_kkt_s / r.t_object_first_s)
        out.append(f"- [{'x' if ok else ' '}] object-first faster than dense KKT at every "
                   f"n >= 2 (smallest t2/t1 = {worst.t_dense_kkt_s / worst.t_object_first_s:.2f}"
                   f" at n = {worst.n_arms})")
    if 10 in by_n:
        s = by_n[10].t_dense_kkt_s / by_n[10].t_object_first_s
        out.append(f"- [{'x' if s >= 5 else ' '}] at least 5x faster at n = 10: "
                   f"t2/t1 = {s:.2f} (thesis 2.13)")
    if 8 in by_n and 64 in by_n:
        s = by_n[64].t_object_first_s / by_n[8].t_object_first_s
        out.append(f"- [{'x' if s <= 10 else ' '}] linear scaling t1(64)/t1(8) = {s:.2f} "
                   "(<= 10; 8 would be exactly linear)")
    wb = {r.n_arms: r for r in weld}

    def against_pinocchio(n: int, met: Callable[[float], bool], claim: str) -> None:
        """The row of a target on our full step / pin.constraintDynamics at ``n`` arms."""
        if n in wb:
            s = wb[n].t_full_step_s / wb[n].t_pinocchio_s
            out.append(f"- [{'x' if met(s) else ' '}] {claim} at {n} arms: {s:.2f}x "
                       f"({_us(wb[n].t_full_step_s)} vs {_us(wb[n].t_pinocchio_s)} µs)")

    against_pinocchio(2, lambda s: s <= 3, "full step within 3x of pin.constraintDynamics")
    against_pinocchio(10, lambda s: s < 1, "ahead of pin.constraintDynamics")
    if weld:
        n_ahead = crossover(weld)
        out.append(f"- ours ahead from n = {n_ahead}" if n_ahead is not None
                   else "- ours not ahead at any measured n")
    return out


def plot(rows: Sequence[Row], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5))
    rev = sorted([r for r in rows if r.case == "revolute"], key=lambda r: r.n_arms)
    weld = sorted([r for r in rows if r.case == "weld"], key=lambda r: r.n_arms)

    def line(rs, attr, label, style, scale=1e6):
        if rs:
            ax.plot([r.n_arms for r in rs], [getattr(r, attr) * scale for r in rs], style,
                    label=label)

    line(rev, "t_coeff_s", "revolute: t coefficient blocks", "o-")
    line(rev, "t_object_first_s", "revolute: t1 object-first solve", "s-")
    line(rev, "t_dense_kkt_s", "revolute: t2 dense KKT solve", "^-")
    line(rev, "t_full_step_s", "revolute: full step (t + t1)", "D-")
    line(weld, "t_full_step_s", "weld: our full step", "v--")
    line(weld, "t_pinocchio_s", "weld: pin.constraintDynamics", "x--")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("number of arms n")
    ax.set_ylabel("median time per call [µs]")
    ax.set_title("Forward dynamics of n 6-joint arms holding one object")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# ---------------------------------------------------------------------------- main
def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--arms", type=int_list, default=None,
                   help="numbers of arms of the revolute case (thesis Table 4.4 + scaling); "
                        f"default {','.join(map(str, DEFAULT_ARMS))}")
    p.add_argument("--peer-arms", type=int_list, default=None,
                   help="numbers of arms of the weld case against pin.constraintDynamics; "
                        f"default {','.join(map(str, DEFAULT_PEER_ARMS))}")
    p.add_argument("--profile-arms", type=int_list, default=None,
                   help="numbers of arms for the stage profile (weld); default "
                        f"{','.join(map(str, DEFAULT_PROFILE_ARMS))}")
    p.add_argument("--repeat", type=int, default=None,
                   help="timed rounds per table row (default 2000, quick 50)")
    p.add_argument("--budget", type=float, default=None,
                   help="seconds per table row, roughly (default 4, quick 0.3)")
    p.add_argument("--states", type=int, default=None,
                   help="random states per system (default 8, quick 2)")
    p.add_argument("--robot", choices=sorted(ROBOT_TOOL), default="ur5")
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results")
    p.add_argument("--quick", action="store_true",
                   help="small smoke run (< 1 min): 2-3 arms, few repeats")
    p.add_argument("--unilateral-only", action="store_true",
                   help="only the unilateral-contact case (issue 12): writes unilateral.csv "
                        "and unilateral.md in --out")
    args = p.parse_args(argv)
    q = args.quick
    args.arms = args.arms or (QUICK_ARMS if q else DEFAULT_ARMS)
    args.peer_arms = args.peer_arms or (QUICK_PEER_ARMS if q else DEFAULT_PEER_ARMS)
    args.profile_arms = args.profile_arms or (QUICK_PROFILE_ARMS if q else DEFAULT_PROFILE_ARMS)
    args.repeat = args.repeat or (50 if q else 2000)
    args.budget = args.budget or (0.3 if q else 4.0)
    args.states = args.states or (2 if q else 8)
    if args.repeat < 1 or args.states < 1 or args.budget <= 0:
        p.error("--repeat, --states and --budget must be positive")
    return args


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    start = time.perf_counter()
    env = environment()
    args.out.mkdir(parents=True, exist_ok=True)
    args.warmup = 5 if args.quick else 20
    timer = Timer(args.repeat, warmup=args.warmup, budget_s=args.budget)
    if args.unilateral_only:
        contact_rows = run_contacts(args, timer)
        write_rows_csv(contact_rows, args.out / "unilateral.csv", ContactRow)
        L = ["# Unilateral contacts: exact mixed-LCP solve vs bilateral solve\n",
             f"Generated by `benchmarks/solver_vs_kkt.py {' '.join(sys.argv[1:])}` in "
             f"{time.perf_counter() - start:.0f} s; timing method as in `solver_vs_kkt.md` "
             f"(medians of interleaved single calls, up to {args.repeat} rounds, "
             f"{args.states} states per family).\n", "## Environment\n"]
        L += [f"- {k}: {v}" for k, v in env.items()]
        L.append("")
        L += contact_section(contact_rows)
        (args.out / "unilateral.md").write_text("\n".join(L) + "\n")
        print(f"wrote {args.out}/unilateral.csv, .md", flush=True)
        return 0
    rows: list[Row] = []
    profiles: dict[tuple[str, int], dict] = {}
    for n in args.arms:
        bench = build_bench(n, "revolute", args.robot, args.states, args.seed + n)
        rows.append(measure_case(bench, "revolute", timer, None))
        _log(rows[-1])
        del bench
        gc.collect()
    for n in sorted(set(args.peer_arms) | set(args.profile_arms)):
        bench = build_bench(n, "weld", args.robot, args.states, args.seed + 1000 + n)
        if n in args.peer_arms:
            rows.append(measure_case(bench, "weld", timer, build_peer(bench)))
            _log(rows[-1])
        if n in args.profile_arms:
            profiles[("weld", n)] = profile_stages(bench, timer)
            print(f"profile weld n={n}: " + ", ".join(
                f"{k} {v * 1e6:.1f}" for k, v in profiles[("weld", n)].items()), flush=True)
        del bench
        gc.collect()
    contact_rows = run_contacts(args, timer)
    write_rows_csv(rows, args.out / "solver_vs_kkt.csv", Row)
    write_rows_csv(contact_rows, args.out / "solver_vs_kkt_unilateral.csv", ContactRow)
    write_report(args.out / "solver_vs_kkt.md", rows, profiles, env, args,
                 time.perf_counter() - start, contact_rows)
    plot(rows, args.out / "solver_vs_kkt.png")
    print(f"wrote {args.out}/solver_vs_kkt.csv, .md, .png in "
          f"{time.perf_counter() - start:.0f} s", flush=True)
    return 0


def _log(r: Row) -> None:
    print(f"{r.case:8s} n={r.n_arms:3d}  t={r.t_coeff_s * 1e6:8.1f}"
          f"  t1={r.t_object_first_s * 1e6:8.1f}"
          f"  t2={r.t_dense_kkt_s * 1e6:9.1f}  full={r.t_full_step_s * 1e6:8.1f}"
          f"  pin={r.t_pinocchio_s * 1e6:8.1f} µs  diff kkt {r.max_rel_diff_kkt:.1e}"
          f"  pin {r.max_rel_diff_pinocchio:.1e}", flush=True)


if __name__ == "__main__":
    raise SystemExit(main())
