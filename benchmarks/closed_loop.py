#!/usr/bin/env python
"""Benchmark: closed-loop simulation under ``object_pd`` (issue 14).

For n = 2, 4, 8, 16, 32, 64 UR5s each welded to one large box (the systems of
``solver_vs_kkt.py``) and for every shipped scenario:

- ``t_closed``: one closed-loop evaluation (``sim.closed_loop.closed_loop_evaluation``:
  blocks, compiled ``object_pd`` torques, forward dynamics on the shared buffer);
- ``t_open``: the open-loop full step at the same states
  (``MultiArmSystem.forward_dynamics``, the torques given);
- ``t_pin``: ``pin.constraintDynamics`` at the same states (weld systems only);
- ``t_closed_ref``: the reference closed loop (numpy controller, numpy blocks and solver)
  at small n, to show what the compiled path saves;
- ``rtf``: real-time factor (simulated time / wall time) of a whole ``simulate`` run with
  ``object_pd`` (RK4, dt = 2 ms; the scenario's own settings for scenarios);
- the feasibility checks of the demo (issue 23: at most +20 %): the run without them and
  with them, as interleaved rounds (``feasibility_overhead.py``'s :func:`measure`).

Per-call times are medians of interleaved single calls (``Timer`` of ``solver_vs_kkt.py``:
one call of each function per round, so that load changes hit all alike), each ratio timed
as its own pair (see :func:`measure`); ratios within one run are what counts on a shared
machine. The cold start (an empty ``NUMBA_CACHE_DIR``,
``multiarm-pin run`` of the demo) is measured in a subprocess: its wall time minus that of
the same command with the cache filled is the compile time (``cold_start.py`` measures every
shipped scenario so).

Outputs in ``--out``: ``closed_loop.csv``, ``closed_loop.md`` (report with commit and machine)
and ``closed_loop.png``.

Usage::

    .venv/bin/python benchmarks/closed_loop.py                  # full run (a few minutes)
    .venv/bin/python benchmarks/closed_loop.py --quick --out /tmp/bench
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import math  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
for _p in (str(ROOT), str(HERE)):
    if _p not in sys.path:
        sys.path.insert(0, _p)

from feasibility_overhead import TARGET as FEASIBILITY_TARGET  # noqa: E402
from feasibility_overhead import measure as measure_feasibility  # noqa: E402
from feasibility_overhead import table as feasibility_table  # noqa: E402
from report_tables import general, int_list, write_rows_csv  # noqa: E402
from solver_vs_kkt import Timer, build_bench, build_peer, environment  # noqa: E402

from multiarm_pin.app.runner import scenario_controller  # noqa: E402
from multiarm_pin.app.scenario import build_scenario, load_scenario  # noqa: E402
from multiarm_pin.exceptions import MultiArmError  # noqa: E402
from multiarm_pin.sim.closed_loop import closed_loop_evaluation  # noqa: E402
from multiarm_pin.sim.contact_loop import ContactLoop  # noqa: E402
from multiarm_pin.sim.controllers import ObjectPD  # noqa: E402
from multiarm_pin.sim.simulation import partial_result, simulate  # noqa: E402
from multiarm_pin.sim.stepper import Stepper  # noqa: E402
from multiarm_pin.sim.trajectories import MinimumJerkTrajectory  # noqa: E402

DEFAULT_ARMS = (2, 4, 8, 16, 32, 64)
QUICK_ARMS = (2, 4)
REFERENCE_MAX_ARMS = 8
SCENARIOS = tuple(sorted(p.stem for p in (ROOT / "scenarios").glob("*.yaml")))
"""Every shipped scenario."""


@dataclass
class Row:
    """One benchmarked case (times in seconds; NaN when not measured)."""

    case: str
    n_arms: int
    nv: int
    t_closed_s: float
    t_open_s: float
    t_pin_s: float
    t_closed_ref_s: float
    t_closed_api_s: float
    t_closed_run_s: float
    closed_over_open: float
    open_over_pin: float
    closed_per_arm_s: float
    sim_time_s: float
    wall_s: float
    rtf: float
    rounds: int
    note: str = ""


def lift_trajectory(state, seconds: float) -> MinimumJerkTrajectory:
    """Lift the object by 5 cm over ``seconds`` (a moving target for the controller)."""
    p = state.obj.position
    return MinimumJerkTrajectory([0.0, seconds], [p, p + [0.0, 0.0, 0.05]],
                                 [state.obj.quaternion, state.obj.quaternion])


def measure(system, states, taus, make_ctrl, timer: Timer, peer=None, baumgarte=None,
            reference: bool = True) -> tuple[list[float], int]:
    """Medians of interleaved pairs: ``[closed, open, pin, closed ref, closed API]`` and the
    rounds of the first pair.

    Each ratio is timed in its own interleaved pair, so that both of its calls run in the same
    conditions: ``(closed, open)``, then ``(open, pin)`` (``pin`` is scaled by that pair's
    ``open`` to the first pair's, so ``open / pin`` is the second pair's ratio), then the
    reference closed loop and the Python API (absolute times only). In one round-robin of
    all five, the call after the numpy reference (2 ms of other data) finds cold caches:
    1.25-1.56x for the same two calls at 2 arms, depending only on the order.
    """
    ctrl = make_ctrl()
    ctrl(0.0, states[0], system.blocks(states[0]))
    api = lambda k: closed_loop_evaluation(system, ctrl, 0.1, states[k],  # noqa: E731
                                           "object_first", baumgarte)
    loop = ContactLoop.for_run(Stepper(system, ctrl, "object_first", baumgarte), "rk4")
    closed = api
    if loop is not None and loop.ready(states[0]):  # the evaluation of simulate's compiled loop
        closed = lambda k: loop.evaluate(0.1, states[k])  # noqa: E731
    open_ = lambda k: system.forward_dynamics(states[k], taus[k],  # noqa: E731
                                              "object_first", baumgarte)
    n = len(states)
    (tc, to), rounds = timer.medians([closed, open_], n)
    tp = math.nan
    if peer is not None:
        (to2, tp2), _ = timer.medians([open_, peer.step], n)
        tp = tp2 * to / to2
    others = [api]
    if reference:
        ref = make_ctrl()
        ref.compiled = False
        ref(0.0, states[0], system.blocks(states[0]))
        others.insert(0, lambda k: closed_loop_evaluation(system, ref, 0.1, states[k],
                                                          "object_first_numpy", baumgarte,
                                                          reference=True))
    times, _ = timer.medians(others, n)
    return [tc, to, tp, times[0] if reference else math.nan, times[-1]], rounds


def run_rtf(system, state, ctrl, duration: float, dt: float, **kw
            ) -> tuple[float, float, int]:
    """(simulated time, wall time, contact events) of one ``simulate`` run."""
    t0 = time.perf_counter()
    res = simulate(system, state, ctrl, duration, dt, **kw)
    return duration, time.perf_counter() - t0, len(res.events)


def weld_rows(arms: Sequence[int], timer: Timer, n_states: int, sim_s: float) -> list[Row]:
    rows = []
    for n in arms:
        bench = build_bench(n, "weld", "ur5", n_states, seed=7)
        s = bench.system
        peer = build_peer(bench)
        traj = lift_trajectory(bench.states[0], 1.0)

        def make(s=s, traj=traj):
            return ObjectPD(s, traj)

        # the open loop is given the closed loop's own torques (same states, same work)
        ctrl = make()
        ctrl(0.0, bench.states[0], s.blocks(bench.states[0]))
        taus = [closed_loop_evaluation(s, ctrl, 0.1, st, "object_first")[2]
                for st in bench.states]
        peer.tau = [np.concatenate([np.zeros(6), t]) for t in taus]
        (tc, to, tp, tr, ta), rounds = measure(s, bench.states, taus, make, timer, peer,
                                               reference=n <= REFERENCE_MAX_ARMS)
        rest = s.project_velocities(s.state(bench.states[0].q, None,
                                            bench.states[0].obj.position,
                                            bench.states[0].obj.quaternion))
        simulate(s, rest, make(), 0.004, 0.002, integrator="rk4", solver="object_first")
        sim, wall, _ = run_rtf(s, rest, make(), sim_s, 0.002, integrator="rk4",
                               solver="object_first")  # (after a run that loads the kernels)
        rows.append(Row("weld_ur5", n, s.nv, tc, to, tp, tr, ta, wall / (4 * sim / 0.002),
                        tc / to, to / tp, tc / n, sim, wall, sim / wall, rounds))
        print(f"weld n={n:3d}: closed {tc * 1e6:8.1f} us, open {to * 1e6:8.1f} us, "
              f"pin {tp * 1e6:8.1f} us, RTF {sim / wall:6.2f}", flush=True)
    return rows


def scenario_rows(names: Sequence[str], timer: Timer, duration: float | None) -> list[Row]:
    rows = []
    for name in names:
        sc = load_scenario(ROOT / "scenarios" / f"{name}.yaml")
        built = build_scenario(sc, load_visuals=False)
        sim = sc.simulation
        T = sim.duration if duration is None else min(duration, sim.duration)
        s = built.system
        kw = dict(integrator=sim.integrator, solver=sim.solver, baumgarte=sim.baumgarte,
                  external_wrench=sc.object.external_wrench or None)  # as simulate_built
        try:  # a whole run first: every kernel it needs is loaded before the timed run
            simulate(s, built.initial_state, scenario_controller(built), T, sim.dt, **kw)
        except MultiArmError:
            pass
        note = ""
        t0 = time.perf_counter()
        events = 0
        try:
            simt, wall, events = run_rtf(s, built.initial_state, scenario_controller(built), T,
                                         sim.dt, **kw)
        except MultiArmError as exc:  # the scenario itself fails: RTF of the part before
            wall = time.perf_counter() - t0
            part = partial_result(exc)
            simt = float(part.t[-1]) if part is not None and len(part.t) else math.nan
            note = (f"the run fails ({type(exc).__name__}: "
                    f"{str(exc).splitlines()[0][:90]}...); RTF of the {simt:g} s before")
            print(f"{name}: {note}", flush=True)
        if not s.n_arms or s.supports.n_rows:  # no closed-loop evaluation: the run's RTF only
            note = note or (("no arms" if not s.n_arms else "supports")
                            + f", {events} contact events: the compiled loop's active-set "
                            "solve (no closed-loop evaluation to time alone)")
            rows.append(Row(name, s.n_arms, s.nv, *[math.nan] * 9, simt, wall, simt / wall, 0,
                            note))
            print(f"{name:26s}: RTF {simt / wall:6.2f} ({simt:g} s in {wall:.2f} s); {note}",
                  flush=True)
            continue
        if events and not note:
            note = (f"{events} contact events: the steps with separated contacts and the "
                    "events run on the compiled loop with its events")
        # states and torques of a short run, for the per-call times
        res = simulate(s, built.initial_state, scenario_controller(built), 40 * sim.dt, sim.dt,
                       **kw)
        states = [res.state(k) for k in range(0, len(res.t), 4)]
        taus = [res.tau[k] for k in range(0, len(res.t), 4)]
        (tc, to, _, tr, ta), rounds = measure(s, states, taus,
                                              lambda b=built: scenario_controller(b), timer, None,
                                              sim.baumgarte)
        rows.append(Row(name, s.n_arms, s.nv, tc, to, math.nan, tr, ta,
                        wall / (4 * simt / sim.dt), tc / to, math.nan, tc / s.n_arms, simt,
                        wall, simt / wall, rounds, note))
        print(f"{name:26s}: closed {tc * 1e6:8.1f} us, open {to * 1e6:8.1f} us, "
              f"RTF {simt / wall:6.2f} ({simt:g} s in {wall:.2f} s)", flush=True)
    return rows


def _cold_and_warm(cli: list[str], duration: float, env: dict) -> dict[str, float]:
    """Wall times of ``multiarm-pin run`` of the demo with an empty, then a filled numba cache."""
    out = {}
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as res:
        env = dict(env, NUMBA_CACHE_DIR=cache)
        for label in ("cold", "warm"):
            t0 = time.perf_counter()
            proc = subprocess.run(cli + ["run", str(ROOT / "scenarios" / "two_ur5_box.yaml"),
                                         "--duration", str(duration), "--out", res,
                                         "--quiet"],
                                  env=env, capture_output=True, text=True, cwd=ROOT)
            out[label] = time.perf_counter() - t0
            if proc.returncode != 0:
                raise SystemExit(f"cold-start run failed:\n{proc.stderr[-2000:]}")
    out["compile"] = out["cold"] - out["warm"]
    return out


def cold_start(duration: float) -> dict:
    """Compile time of a first run of the demo: ``{"cold", "warm", "compile"}`` [s, wall].

    ``multiarm-pin run`` with an empty numba cache, then with the cache that run filled.
    """
    script = Path(sys.executable).parent / "multiarm-pin"
    cli = ([str(script)] if script.exists()
           else [sys.executable, "-c", "import sys; from multiarm_pin.app.cli import main; "
                 "sys.exit(main())"])
    return _cold_and_warm(cli, duration, dict(os.environ))


def _us(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{x * 1e6:.1f}"


def _x(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{x:.2f}"


def targets(weld: Sequence[Row], scen: Sequence[Row], cold: dict | None,
            feasibility: Sequence[dict] = ()) -> list[str]:
    """The issue's targets, each with its measured value and met / NOT met."""
    out = []

    def line(ok: bool, text: str) -> None:
        out.append(f"- {'met' if ok else '**NOT met**'}: {text}")

    if weld:
        worst = max(r.closed_over_open for r in weld)
        line(worst <= 1.5, f"closed-loop evaluation <= 1.5x the open-loop step at every n "
             f"(worst {worst:.2f}x; per evaluation of a whole run, worst "
             f"{max(r.t_closed_run_s / r.t_open_s for r in weld):.2f}x)")
        by_n = {r.n_arms: r for r in weld}
        if 2 in by_n:
            line(by_n[2].open_over_pin <= 1.5, f"open-loop step within 1.5x of "
                 f"pin.constraintDynamics at 2 arms ({by_n[2].open_over_pin:.2f}x)")
        ahead = [r.n_arms for r in weld if r.open_over_pin < 1.0]
        line(bool(ahead) and all(r.open_over_pin < 1.0 for r in weld if r.n_arms >= 4),
             f"open-loop step ahead of pin.constraintDynamics from 4 arms (ahead at n = "
             f"{ahead})")
        if 8 in by_n and 64 in by_n:
            ratio = by_n[64].closed_per_arm_s / by_n[8].closed_per_arm_s
            line(ratio <= 1.5, f"closed-loop time per arm at 64 arms <= 1.5x that at 8 "
                 f"({ratio:.2f}x)")
    for r in scen:
        line(r.rtf >= 10.0, f"{r.case}: at least 10x faster than real time (RTF {r.rtf:.2f})"
             + (f"; {r.note}" if r.note else ""))
    for r in feasibility:
        line(r["run_ratio"] <= FEASIBILITY_TARGET,
             f"{r['scenario']}: the feasibility checks add at most "
             f"{100 * FEASIBILITY_TARGET:.0f} % to the run's wall time "
             f"({100 * r['run_ratio']:+.0f} % with the scan beside the simulation and the "
             f"report; made after the run instead {100 * r['ratio']:.0f} %; with every stop "
             f"monitor {100 * r['monitored_ratio']:+.0f} %; the scene {r['scene'] * 1e3:.0f} "
             "ms more)")
    if cold is not None:
        line(cold["compile"] <= 20.0, f"cold-start compile of the demo at most 20 s "
             f"({cold['compile']:.1f} s)")
    return out


def write_report(path: Path, weld: Sequence[Row], scen: Sequence[Row], cold: dict | None,
                 env: dict, args: argparse.Namespace, wall: float,
                 feasibility: Sequence[dict] = ()) -> None:
    lines = ["# Closed-loop benchmark (object_pd)", "", "## Environment", ""]
    lines += [f"- {k}: {v}" for k, v in env.items()]
    lines += ["", "## Method", "",
              "Per-call times are medians of interleaved single calls (one call of each "
              "function per round, the same states), so their ratios hold within this run "
              "even on a loaded machine; absolute times depend on the load (above). Each "
              "ratio is timed as its own interleaved pair, both calls in the same conditions: "
              "(closed, open), then (open, pin) (`pin` scaled to the first pair's `open`), then "
              "the reference and the API alone (in one round-robin of all of them, the call "
              "after the 2 ms numpy reference finds cold caches: 1.25-1.56x for the same two "
              "calls at 2 arms, by order alone). "
              "`closed` = one closed-loop evaluation as `simulate` runs it (the compiled "
              "loop's: arm terms, blocks, object_pd and forward dynamics in one compiled call, "
              "`ContactLoop.evaluate`, its tuples held in one numba structure), "
              "`closed API` = the same through the Python API "
              "(`closed_loop_evaluation`, which returns the blocks' views), `in run` = the "
              "wall time of the whole `simulate` run divided by its evaluations (4 per RK4 "
              "step: everything a run does, per evaluation), `open` = the open-loop full step "
              "(`forward_dynamics`) at the same states with the same torques, `pin` = "
              "`pin.constraintDynamics` on one combined model (weld systems), `closed ref` = "
              "the numpy reference closed loop. RTF = simulated time / wall time of a whole "
              f"`simulate` run. Command: `{' '.join(sys.argv)}`; wall {wall:.0f} s.", "",
              "## n UR5s welded to one box", "",
              "| n | nv | closed [us] | closed API [us] | in run [us] | open [us] | pin [us] | "
              "closed ref [us] | closed/open | in run/open | open/pin | closed per arm [us] | "
              "RTF |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in weld:
        lines.append(f"| {r.n_arms} | {r.nv} | {_us(r.t_closed_s)} | {_us(r.t_closed_api_s)} "
                     f"| {_us(r.t_closed_run_s)} | {_us(r.t_open_s)} | {_us(r.t_pin_s)} | "
                     f"{_us(r.t_closed_ref_s)} | {_x(r.closed_over_open)} | "
                     f"{_x(r.t_closed_run_s / r.t_open_s)} "
                     f"| {_x(r.open_over_pin)} | {_us(r.closed_per_arm_s)} | {_x(r.rtf)} |")
    lines += ["", "## Shipped scenarios", "",
              "| scenario | arms | closed [us] | closed API [us] | in run [us] | open [us] | "
              "closed ref [us] | closed/open | in run/open | simulated [s] | wall [s] | RTF | "
              "note |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in scen:
        lines.append(f"| {r.case} | {r.n_arms} | {_us(r.t_closed_s)} | "
                     f"{_us(r.t_closed_api_s)} | {_us(r.t_closed_run_s)} | {_us(r.t_open_s)} | "
                     f"{_us(r.t_closed_ref_s)} | {_x(r.closed_over_open)} | "
                     f"{_x(r.t_closed_run_s / r.t_open_s)} | {r.sim_time_s:g} | "
                     f"{r.wall_s:.2f} | {_x(r.rtf)} | {r.note} |")
    lines += ["", "## Feasibility checks (issue 23)", "",
              "Interleaved rounds per scenario: `simulate_built` alone; the run's "
              "`feasibility_report` after it (limits and collisions at every recorded sample, "
              "the `CollisionScene` built beforehand, as the runner does); `simulate_built` as "
              "`multiarm-pin run` calls it, the collision scan checking each stretch on a "
              "worker thread while the loop simulates the next, then the report reusing the "
              "scan (the target's row); the same with the monitors of `limits: {torque, "
              "velocity, position, collision: stop}`. Ratios are medians of the per-round "
              "ratios to the first run; `scene` is the scene's construction (once per run, "
              "the arms' hulls cached per process).", ""]
    lines += list(feasibility_table(list(feasibility))) if feasibility else [
        "Not measured in this run."]
    lines += ["", "## Cold start", ""]
    if cold is None:
        lines.append("Not measured in this run (`--quick` or `--no-cold`).")
    else:
        lines += [f"`multiarm-pin run scenarios/two_ur5_box.yaml --duration "
                  f"{args.cold_duration:g}` with an empty `NUMBA_CACHE_DIR`, then again with "
                  "the cache it filled; compile time = the difference.", "",
                  "| empty cache [s] | filled cache [s] | compile [s] |",
                  "|---|---|---|",
                  f"| {cold['cold']:.1f} | {cold['warm']:.1f} | {cold['compile']:.1f} |"]
    lines += ["", "## Targets", ""] + targets(weld, scen, cold, feasibility) + [""]
    path.write_text("\n".join(lines), encoding="utf-8")


def plot(weld: Sequence[Row], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    n = [r.n_arms for r in weld]
    for attr, label, style in (("t_closed_s", "closed loop (object_pd)", "o-"),
                               ("t_open_s", "open-loop step", "s-"),
                               ("t_pin_s", "pin.constraintDynamics", "^--"),
                               ("t_closed_ref_s", "closed loop, numpy reference", "x:")):
        y = [getattr(r, attr) * 1e6 for r in weld]
        if any(math.isfinite(v) for v in y):
            ax[0].loglog(n, y, style, label=label)
    ax[0].set_xlabel("arms n")
    ax[0].set_ylabel("time per evaluation [us] (median)")
    ax[0].legend()
    ax[0].grid(True, which="both", alpha=0.3)
    ax[1].semilogx(n, [r.closed_per_arm_s * 1e6 for r in weld], "o-", label="closed loop")
    ax[1].semilogx(n, [r.t_open_s / r.n_arms * 1e6 for r in weld], "s-", label="open loop")
    ax[1].set_xlabel("arms n")
    ax[1].set_ylabel("time per arm [us]")
    ax[1].set_ylim(bottom=0)
    ax[1].legend()
    ax[1].grid(True, which="both", alpha=0.3)
    fig.suptitle("closed-loop evaluation vs open-loop step, UR5s welded to a box")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--arms", type=int_list, default=None, help="arm counts (default 2,...,64)")
    p.add_argument("--scenarios", default=None,
                   help="comma-separated scenario names (default: all shipped)")
    p.add_argument("--duration", type=float, default=None,
                   help="cap on the simulated time of each scenario run [s]")
    p.add_argument("--sim", type=float, default=None, help="simulated time of the weld runs")
    p.add_argument("--repeat", type=int, default=None, help="timing rounds per case")
    p.add_argument("--states", type=int, default=None, help="states per weld case")
    p.add_argument("--no-cold", action="store_true", help="skip the cold-start measurement")
    p.add_argument("--cold-duration", type=float, default=0.5,
                   help="simulated time of the cold-start runs [s]")
    p.add_argument("--feasibility", default="two_ur5_box",
                   help="comma-separated scenarios of the feasibility rows ('' for none)")
    p.add_argument("--feasibility-repeat", type=int, default=None,
                   help="interleaved rounds of the feasibility rows")
    p.add_argument("--out", type=Path, default=HERE / "results")
    p.add_argument("--quick", action="store_true",
                   help="smoke run: 2 and 4 arms, one scenario for 0.02 s, no cold start")
    args = p.parse_args(argv)
    q = args.quick
    args.arms = args.arms or (QUICK_ARMS if q else DEFAULT_ARMS)
    args.scenarios = (args.scenarios.split(",") if args.scenarios
                      else (["two_ur5_box"] if q else list(SCENARIOS)))
    args.duration = args.duration if args.duration is not None else (0.02 if q else None)
    args.sim = args.sim or (0.01 if q else 0.2)
    args.repeat = args.repeat or (5 if q else 200)
    args.states = args.states or (3 if q else 8)
    args.no_cold = args.no_cold or q
    args.feasibility = [n for n in args.feasibility.split(",") if n]
    args.feasibility_repeat = args.feasibility_repeat or (2 if q else 9)
    return args


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    env = environment()
    t0 = time.perf_counter()
    timer = Timer(args.repeat, warmup=2 if args.quick else 20,
                  budget_s=0.5 if args.quick else 3.0)
    weld = weld_rows(args.arms, timer, args.states, args.sim)
    scen = scenario_rows(args.scenarios, timer, args.duration)
    feasibility = [measure_feasibility(name, args.feasibility_repeat,
                                       0.1 if args.quick else None)
                   for name in args.feasibility]
    for r in feasibility:
        print(f"feasibility {r['scenario']}: checks {100 * r['ratio']:.0f} % of simulate, "
              f"stop monitors and report {100 * r['monitored_ratio']:+.0f} %", flush=True)
    cold = None if args.no_cold else cold_start(args.cold_duration)
    if cold is not None:
        print(f"cold start: {cold}", flush=True)
    wall = time.perf_counter() - t0
    write_rows_csv(weld + scen, args.out / "closed_loop.csv", Row, general)
    write_report(args.out / "closed_loop.md", weld, scen, cold, env, args, wall, feasibility)
    plot(weld, args.out / "closed_loop.png")
    print(f"wrote {args.out / 'closed_loop.csv'}, closed_loop.md, closed_loop.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
