"""The output of a design: scenario files, pictures, ``report.md`` and the best design's run.

One concept at several layers: each layer's ``report.py`` (``grasp``, ``study``, ``feasibility``,
``design``) makes that layer's report of its results.


:func:`write_design` writes a results folder (atomically, through
:class:`~multiarm_pin.app.results_io.ResultsWriter`: locked, staged, published whole)::

    DIR/
      report.md              the scores of each design, the Pareto front, the weights, the run
      design.json            the same numbers for programs
      designs/design_<k>.yaml  the k-th design: a scenario `multiarm-pin run` reads as it is
      designs/design_<k>.png   its picture (arms at the start, object, contacts, supports)
      best_run/              the best design simulated through the task
                             (`multiarm-pin run`'s folder: summary.json, replay.html, plots)

Twins: ``multiarm_pin.feasibility.report``, ``multiarm_pin.grasp.report`` and
``multiarm_pin.study.report`` (the same role, a package's report of its own results, in four
packages: this one writes a design's results folder (scenarios, pictures, ``report.md``, the
best run); ``feasibility.report`` returns the feasibility of a simulated run (limits,
collisions) as a ``FeasibilityReport``; ``grasp.report`` reads grasp files, analyses them,
formats the report and draws its picture; ``study.report`` writes a study's ``report.md`` and
its plots).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import yaml

from multiarm_pin.design.scoring import SCORES


def scenario_text(design, spec) -> str:
    """The YAML text of a design's scenario, with a header saying where it came from."""
    head = (f"# design {design.rank} of {Path(spec.file).name} (multiarm-pin design): "
            f"objective {design.objective:.4g}\n"
            "# scores: " + ", ".join(f"{k} {v:.4g}" for k, v in design.scores.items()
                                     if v is not None) + "\n")
    return head + yaml.safe_dump(design.scenario, sort_keys=False, default_flow_style=None)


def draw_design(problem, design, path: Path, title: str = "") -> Path:
    """Save a 3-D picture of a design at the start: arms, object, contacts, supports.

    Each arm is the polyline of its joint origins from the base to the tool (its forward
    kinematics at ``q0``); the object is its polyhedron at the start pose; contacts are dots;
    a support is its slab's top rectangle (as the collision scene sizes it).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pinocchio as pin
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    found = design.assessment
    M = problem.object_placement
    poly = problem.poly
    fig = plt.figure(figsize=(6.4, 5.6))
    ax = fig.add_subplot(projection="3d")
    faces = [np.array([M.act(poly.vertices[v]) for v in f]) for f in poly.faces]
    ax.add_collection3d(Poly3DCollection(faces, facecolor="lightsteelblue", alpha=0.3,
                                         edgecolor="k", linewidth=0.7))
    pts_all = [np.concatenate(faces)]
    for sp in problem.spec.supports:
        pts = poly.vertices if isinstance(sp.points, str) else np.asarray(sp.points)
        w = np.array([M.act(p) for p in pts])
        lo, hi = w.min(axis=0), w.max(axis=0)
        z = float(np.asarray(sp.point)[2])
        rect = np.array([[lo[0], lo[1], z], [hi[0], lo[1], z], [hi[0], hi[1], z],
                         [lo[0], hi[1], z]])
        ax.add_collection3d(Poly3DCollection([rect], facecolor="tan", alpha=0.5))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, (slot, a, q) in enumerate(zip(problem.spec.arms, found.candidate.arms, found.q0,
                                         strict=True)):
        arm = problem.arm(i, a.base)
        pin.forwardKinematics(arm.model, arm.data, q)
        pin.updateFramePlacements(arm.model, arm.data)
        chain = [arm.base_placement.translation] + \
            [arm.data.oMi[j].translation for j in range(1, arm.model.njoints)] + \
            [arm.data.oMf[arm.tool_frame_id].translation]
        chain = np.array(chain)
        c = colours[i % len(colours)]
        ax.plot(*chain.T, "-o", color=c, markersize=3, linewidth=2.5, label=slot.name)
        ax.scatter(*a.base[:3], marker="s", s=40, color=c)
        pts_all.append(chain)
    cps = found.scenario["arms"]
    for e in cps:
        j = e["joint"]
        pts = [j["placement_in_object"]["position"]] if j["type"] == "weld" else \
            [c["point"] for c in j["contacts"]]
        w = np.array([M.act(np.asarray(p, float)) for p in pts])
        ax.scatter(*w.T, color="red", s=25, depthshade=False)
    P = np.concatenate(pts_all)
    centre, half = P.mean(axis=0), 0.55 * float(np.ptp(P, axis=0).max())
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(max(centre[2] - half, -0.05), max(centre[2] - half, -0.05) + 2 * half)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _fmt(v) -> str:
    if v is None:
        return "—"
    return f"{v:.4g}"


def report_text(result, run_summary: dict | None, files: dict) -> str:
    """``report.md``: the spec, the search, the designs' scores, the Pareto front, the run."""
    spec = result.spec
    names = [n for n in SCORES if any(d.scores.get(n) is not None for d in result.designs)]
    lines = [f"# Design report: {spec.name}", "",
             f"Spec: `{spec.file}`. Seed {spec.search.seed}; {result.evaluated} candidates "
             f"evaluated ({spec.search.candidates} random, then {spec.search.refine} rounds "
             f"of local refinement) in {result.wall_time:.1f} s on {result.workers} "
             f"worker(s); {result.feasible} met every condition.", "",
             "Candidates that failed, by the first condition they failed: " +
             ", ".join(f"{k} {v}" for k, v in result.failures.items()) + ".", "",
             "## Designs", "",
             "| rank | candidate | objective | " + " | ".join(names) + " | Pareto | file |",
             "|---" * (len(names) + 5) + "|"]
    for d in result.designs:
        lines.append(f"| {d.rank} | {d.index} | {d.objective:.4g} | " +
                     " | ".join(_fmt(d.scores.get(n)) for n in names) +
                     f" | {'yes' if d.pareto else ''} | `{files[d.rank]}` |")
    lines += ["", "Scores (higher is better unless said):", ""]
    for n in names:
        s = SCORES[n]
        lines.append(f"- `{n}`: {s.description}" + ("" if s.higher_is_better
                                                     else " (lower is better)") + ".")
    lines += ["", "Objective: J = Σ w_s term_s, term_s = min(value/scale, 1) "
              "(torque_ratio: 1 - value); weights and scales:", "",
              "| score | weight | scale |", "|---|---|---|"]
    for n, s in SCORES.items():
        lines.append(f"| {n} | {spec.weights.get(n, s.weight):g} | "
                     f"{s.scale:g} |" if s.higher_is_better else
                     f"| {n} | {spec.weights.get(n, s.weight):g} | — |")
    lines += ["", f"## Pareto front ({len(result.pareto)} designs)", "",
              "| rank | candidate | objective | " + " | ".join(names) + " |",
              "|---" * (len(names) + 3) + "|"]
    for d in result.pareto[:20]:
        lines.append(f"| {d.rank} | {d.index} | {d.objective:.4g} | " +
                     " | ".join(_fmt(d.scores.get(n)) for n in names) + " |")
    if len(result.pareto) > 20:
        lines.append(f"| ... {len(result.pareto) - 20} more in design.json | |")
    lines += ["", "## Pictures", ""]
    for d in result.designs:
        lines.append(f"![design {d.rank}]({files[d.rank][:-5]}.png)")
    lines += ["", "## The best design, simulated", ""]
    if run_summary is None:
        lines.append("Not simulated (`--no-run`).")
    else:
        feas = run_summary.get("feasible")
        lines += [f"`best_run/`: status {run_summary.get('status')}, feasible {feas}, "
                  f"{run_summary.get('steps')} steps in {run_summary.get('wall_time', 0):.2f} s;"
                  f" replay: `best_run/replay.html` (or `multiarm-pin replay best_run`).", ""]
        clr = run_summary.get("clearance") or {}
        if clr:
            lines.append("Clearances along the run [m]: " + ", ".join(
                f"{k} {_fmt(v)}" for k, v in clr.items()) + ".")
    return "\n".join(lines) + "\n"


def design_json(result, run_summary: dict | None) -> dict:
    """``design.json``: every returned and every Pareto design's scores, the search counts."""
    def entry(d):
        return {"rank": d.rank, "candidate": d.index, "objective": d.objective,
                "scores": d.scores, "pareto": d.pareto}

    spec = result.spec
    return {"spec": str(Path(spec.file).resolve()), "seed": spec.search.seed,
            "evaluated": result.evaluated, "feasible": result.feasible,
            "failures": result.failures, "wall_time": result.wall_time,
            "workers": result.workers,
            "weights": {n: spec.weights.get(n, s.weight) for n, s in SCORES.items()},
            "designs": [entry(d) for d in result.designs],
            "pareto": [entry(d) for d in result.pareto],
            "best_run": None if run_summary is None else {
                k: run_summary.get(k) for k in ("status", "feasible", "clearance", "steps")}}


def write_design(result, out, simulate: bool = True, overwrite: bool = False,
                 quiet: bool = True) -> Path:
    """Write a design's results folder (module docstring); returns its path.

    Args:
        result: the :class:`~.search.DesignResult`.
        out: the folder.
        simulate: simulate the best design (``best_run/``).
        overwrite: replace a results folder of another spec.
        quiet: no progress bar for the run.

    Raises:
        OutputError: an unusable folder (before anything is written).
        RunFailedError: the best design's run failed (its partial results are kept).
    """
    from multiarm_pin.app.results_io import ResultsWriter
    from multiarm_pin.app.runner import run_scenario
    from multiarm_pin.app.scenario.schema import parse_scenario
    from multiarm_pin.design.assessment import DesignProblem

    spec = result.spec
    problem = DesignProblem(spec)
    target = Path(os.path.abspath(out))
    with ResultsWriter(target, spec.file, overwrite) as w:
        (w.path / "designs").mkdir()
        files = {}
        for d in result.designs:
            rel = f"designs/design_{d.rank}.yaml"
            (w.path / rel).write_text(scenario_text(d, spec), encoding="utf-8")
            files[d.rank] = rel
            draw_design(problem, d, w.path / f"designs/design_{d.rank}.png",
                        f"{spec.name}: design {d.rank} (objective {d.objective:.3g})")
        summary = None
        if simulate and result.designs:
            sc = parse_scenario(result.designs[0].scenario, str(target / files[1]))
            run = run_scenario(sc, w.path / "best_run", quiet=quiet, html=True)
            summary = run.summary
        (w.path / "design.json").write_text(json.dumps(design_json(result, summary), indent=1,
                                                       default=_jsonable), encoding="utf-8")
        (w.path / "report.md").write_text(report_text(result, summary, files),
                                          encoding="utf-8")
        w.publish()
    return target


def pick_up_report(result, run_summary: dict | None, files: dict) -> str:
    """``report.md`` of a pick-up plan (:mod:`.pick_up`): the plans, the checks, the run."""
    from multiarm_pin.design.pick_up import CHECKS, ROLES, describe_plan

    spec = result.spec
    checked = result.checked
    fails = {c: sum(1 for x in checked if x.condition == c) for c in CHECKS}
    lines = [f"# Pick-up plan: {spec.name}", "",
             f"Spec: `{spec.file}`; strategy `{spec.pick_up['strategy']}`: tilt the box about "
             "a bottom edge, slide a gripper under the raised side, lift in form closure "
             "(`multiarm_pin.design.pick_up`).", "",
             f"{len(checked)} candidates checked in {result.wall_time:.1f} s; "
             f"{len(result.plans)} met every check. Failed, by the first check failed: " +
             ", ".join(f"{k} {v}" for k, v in fails.items()) + ".", ""]
    if result.excluded:
        lines += ["Pivot edges not tried:", ""] + [f"- {w}" for w in result.excluded] + [""]
    roles = result.plans[0].scenario["arms"] if result.plans else []
    lines += ["Roles: " + ", ".join(f"{r} `{a['name']}`" for r, a in zip(ROLES, roles,
                                                                          strict=False)), "",
              "## Plans", "", "| rank | candidate | plan | file |", "|---|---|---|---|"]
    for k, c in enumerate(result.plans[:spec.top], start=1):
        lines.append(f"| {k} | {c.candidate.index} | {describe_plan(c)} | "
                     f"`{files.get(k, '')}` |")
    if result.plans:
        best = result.plans[0]
        lines += ["", "Phases of the best plan:", "", "| phase | kind | t [s] | duration [s] |",
                  "|---|---|---|---|"]
        for p in best.scenario["controller"]["phases"]:
            lines.append(f"| {p['name']} | {p['kind']} | {p['t']:g} | {p['duration']:g} |")
        lines += ["", "Key poses checked (IK within joint limits on one branch, clearances, "
                  "and static torques at rest and carried): " + ", ".join(best.labels) + "."]
    lines += ["", "## The best plan, simulated", ""]
    if run_summary is None:
        lines.append("Not simulated (`--no-run`).")
    else:
        lines.append(f"`best_run/`: status {run_summary.get('status')}, feasible "
                     f"{run_summary.get('feasible')}, {run_summary.get('steps')} steps; "
                     "replay: `best_run/replay.html`.")
        ev = run_summary.get("events") or []
        if ev:
            lines += ["", "Events: " + "; ".join(
                f"{e.get('t', 0):.3f} s {e.get('kind')} {e.get('label')}"
                for e in ev if isinstance(e, dict)) + "."]
    return "\n".join(lines) + "\n"


def write_pick_up(result, out, simulate: bool = True, overwrite: bool = False,
                  quiet: bool = True) -> Path:
    """Write a pick-up plan's results folder; returns its path.

    As :func:`write_design`'s: ``report.md``, ``plan.json``, ``designs/design_<k>.yaml``,
    ``best_run/``.
    """
    from multiarm_pin.app.results_io import ResultsWriter
    from multiarm_pin.app.runner import run_scenario
    from multiarm_pin.app.scenario.schema import parse_scenario

    spec = result.spec
    target = Path(os.path.abspath(out))
    with ResultsWriter(target, spec.file, overwrite) as w:
        (w.path / "designs").mkdir()
        files = {}
        for k, c in enumerate(result.plans[:spec.top], start=1):
            rel = f"designs/design_{k}.yaml"
            from multiarm_pin.design.pick_up import describe_plan

            head = (f"# plan {k} of {Path(spec.file).name} (multiarm-pin design, pick_up): "
                    f"{describe_plan(c)}\n")
            (w.path / rel).write_text(head + yaml.safe_dump(c.scenario, sort_keys=False,
                                                            default_flow_style=None),
                                      encoding="utf-8")
            files[k] = rel
        summary = None
        if simulate and result.plans:
            sc = parse_scenario(result.plans[0].scenario, str(target / files[1]))
            run = run_scenario(sc, w.path / "best_run", quiet=quiet, html=True)
            summary = run.summary
        plan = {"spec": str(Path(spec.file).resolve()), "checked": len(result.checked),
                "wall_time": result.wall_time, "excluded": result.excluded,
                "plans": [{"candidate": c.candidate.index, "pivot": c.candidate.pivot,
                           "angle": c.candidate.angle, "scores": c.scores}
                          for c in result.plans[:spec.top]],
                "failed": [{"candidate": c.candidate.index, "pivot": c.candidate.pivot,
                            "angle": c.candidate.angle, "condition": c.condition,
                            "value": c.value, "detail": c.detail}
                           for c in result.checked if not c.ok],
                "best_run": None if summary is None else {
                    k: summary.get(k) for k in ("status", "feasible", "clearance", "steps")}}
        (w.path / "plan.json").write_text(json.dumps(plan, indent=1, default=_jsonable),
                                          encoding="utf-8")
        (w.path / "report.md").write_text(pick_up_report(result, summary, files),
                                          encoding="utf-8")
        w.publish()
    return target


def _jsonable(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(type(x).__name__)


__all__ = ["design_json", "draw_design", "pick_up_report", "report_text", "scenario_text",
           "write_design", "write_pick_up"]
