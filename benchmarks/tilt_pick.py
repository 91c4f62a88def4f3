#!/usr/bin/env python
"""Benchmark: the pick-up planner (issue 27) on drawn boxes, each plan simulated.

Boxes are drawn in the README's range (edges 0.4-1.0 m, masses 1-8 kg, lying along the
table's axes on the shipped spec's table plane, the table 0.4 and 0.3 m wider than the box on
each side: :func:`~multiarm_pin.design.pick_up.with_box`), with the shipped
``designs/tilt_pick.yaml``'s arms, region widened to x, y in [-2, 2] m, z in [0, 1.4] m
(pedestals: a taller box needs its couple's bases higher). Each is planned
(:func:`~multiarm_pin.design.pick_up.plan_pick_up`, ``first=True``) and, when it plans,
simulated (the Python stepper) and judged against the issue's "done when": the far edge's
support vertices separate first, the insert gripper's bottom tip touches down on the bottom
face, then the pivot's vertices separate; no contact force below zero; feasible (the
feasibility report: no collision, joints within limits); the final pose on the closed form
(the start turned by the plan's angle about its pivot edge, then lifted and carried) to 1e-3 m.

The report (``tilt_pick.md`` in ``--out``) gives the command, date, commit, machine, and per
box: its size, mass, the plan or the reason it is impossible, the run's verdict, and the wall
times. It is rewritten after each box (a partial run keeps what it did).

Usage::

    .venv/bin/python benchmarks/tilt_pick.py --cases 10 --out benchmarks/results
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
import pinocchio as pin  # noqa: E402
import yaml  # noqa: E402

from benchmarks._machine import run_line  # noqa: E402
from multiarm_pin.data import data_path  # noqa: E402
from multiarm_pin.design.pick_up import describe_plan, plan_pick_up, with_box  # noqa: E402
from multiarm_pin.design.spec import parse_design  # noqa: E402
from multiarm_pin.exceptions import DesignImpossibleError, MultiArmError  # noqa: E402


def judge(plan, run, report) -> tuple[bool, str]:
    """The issue's "done when" on one run: (passed, what was seen)."""
    sc = plan.scenario
    first = {}
    for e in run.events:
        first.setdefault((e.kind, e.label), e.t)
    ins = sc["arms"][3]["name"]
    try:
        far = max(first[("separation", "table[2]")], first[("separation", "table[3]")])
        bottom = first[("touchdown", f"{ins}:tip[2]")]
        pivot = min(first[("separation", "table[0]")], first[("separation", "table[1]")])
    except KeyError as exc:
        return False, f"missing event {exc}"
    tilt = next(p for p in sc["controller"]["phases"] if p["kind"] == "tilt")
    R = pin.exp3(np.asarray(tilt["axis"]) * tilt["angle"])
    c = np.asarray(tilt["pivot"])
    p0 = np.asarray(sc["object"]["pose"]["position"], float)
    goal = c + R @ (p0 - c)
    for p in sc["controller"]["phases"]:
        if p["kind"] == "move":
            goal = goal + np.asarray(p["displacement"])
    err = float(np.linalg.norm(run.object_position[-1] - goal))
    mu_min = float(run.mu.min())
    ok = far < bottom < pivot and mu_min >= 0.0 and report.feasible and err < 1e-3
    why = "" if report.feasible else " (" + "; ".join(
        v.describe() for v in report.violations[:3]) + ")"
    return ok, (f"events far {far:.3f} s < bottom {bottom:.3f} s < pivot {pivot:.3f} s: "
                f"{far < bottom < pivot}; min force {mu_min:.3g} N; feasible "
                f"{report.feasible}{why}; final pose error {err:.2g} m")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", type=int, default=10)
    p.add_argument("--seed", type=int, default=2027)
    p.add_argument("--out", default="benchmarks/results")
    args = p.parse_args(argv)
    from multiarm_pin.app.run_feasibility import check_initial_state
    from multiarm_pin.app.runner import scenario_controller, simulate_built
    from multiarm_pin.app.scenario import build_scenario
    from multiarm_pin.app.scenario.schema import parse_scenario
    from multiarm_pin.feasibility import feasibility_report

    base = yaml.safe_load(data_path("scenarios", "designs", "tilt_pick.yaml").read_text())
    base["bases"]["region"] = {"x": [-2.0, 2.0], "y": [-2.0, 2.0], "z": [0.0, 1.4]}
    rng = np.random.default_rng(args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    head = ["# Pick-up planner on drawn boxes (issue 27)", "",
            f"Command: `python benchmarks/tilt_pick.py {' '.join(argv or sys.argv[1:])}`; "
            f"{run_line()}; load average at the start {os.getloadavg()[0]:.1f} (a shared "
            "machine: wall times include others' work).", "",
            "Boxes: edges uniform in 0.4-1.0 m, mass uniform in 1-8 kg, along the table's axes "
            "(table 0.4 / 0.3 m wider each side), the shipped spec's arms, bases in x, y "
            "[-2, 2] m, z [0, 1.4] m. Each planned box is simulated and judged against the "
            "issue's done-when (events far edge -> bottom touchdown -> pivot, no negative "
            "force, feasible, final pose to 1e-3 m).", "",
            "| case | size [m] | mass [kg] | plan | plan [s] | run | run [s] |",
            "|---|---|---|---|---|---|---|"]
    rows, counts = [], {"planned": 0, "succeeded": 0, "impossible": 0, "failed": 0}
    reasons = []
    for k in range(args.cases):
        size, mass = rng.uniform(0.4, 1.0, 3), rng.uniform(1.0, 8.0)
        spec = parse_design(with_box(base, size, mass), f"case{k}")
        t0 = time.perf_counter()
        try:
            plan = plan_pick_up(spec, first=True).plans[0]
        except DesignImpossibleError as exc:
            counts["impossible"] += 1
            reason = str(exc).split(": ", 2)[-1]
            reasons.append(f"case {k}: {reason}")
            rows.append(f"| {k} | {np.round(size, 3).tolist()} | {mass:.2f} | impossible: "
                        f"{reason} | {time.perf_counter() - t0:.1f} | — | — |")
            _write(out, head, rows, counts, reasons)
            continue
        tp = time.perf_counter() - t0
        counts["planned"] += 1
        t1 = time.perf_counter()
        try:
            built = build_scenario(parse_scenario(plan.scenario, f"case{k}"),
                                   load_visuals=False)
            scene = check_initial_state(built)
            sim = built.scenario.simulation
            run = simulate_built(built, scenario_controller(built), sim.duration, sim.dt,
                                 sim.solver)
            rep = feasibility_report(built.system, run, ground=built.scenario.ground,
                                     scene=scene)
            ok, seen = judge(plan, run, rep)
        except MultiArmError as exc:
            ok, seen = False, f"run failed: {exc}"
        counts["succeeded" if ok else "failed"] += 1
        rows.append(f"| {k} | {np.round(size, 3).tolist()} | {mass:.2f} | "
                    f"{describe_plan(plan)} | {tp:.1f} | {'success' if ok else 'FAILED'}: "
                    f"{seen} | {time.perf_counter() - t1:.1f} |")
        _write(out, head, rows, counts, reasons)
        print(rows[-1], flush=True)
    _write(out, head, rows, counts, reasons)
    return 0


def _write(out: Path, head: list, rows: list, counts: dict, reasons: list) -> None:
    n = len(rows)
    lines = head + rows + ["", f"Summary: {n} boxes drawn; {counts['planned']} planned, "
                               f"{counts['succeeded']} of them simulated to success, "
                               f"{counts['failed']} failed in simulation; "
                               f"{counts['impossible']} reported impossible."]
    if reasons:
        lines += ["", "Impossible, and why:", ""] + [f"- {r}" for r in reasons]
    tmp = out / "tilt_pick.md.tmp"
    tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    tmp.replace(out / "tilt_pick.md")


if __name__ == "__main__":
    sys.exit(main())
