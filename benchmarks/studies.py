#!/usr/bin/env python
"""Benchmark: studies on Dask (issue 15): throughput with 2 vs 1 workers, overhead per case.

One study of ``--cases`` simulate cases of the demo pair (``scenarios/two_ur5_box.yaml``,
box mass on a grid, ``--duration`` seconds simulated: 1.0 s makes ~0.9 s of work per case on
the reference machine) is run three ways, in one run of this program, each on warm
processes:

- ``loop``: :meth:`Study.run_loop` in this process (the plain loop; after two warm-up cases,
  so imports, robot loading caches and compiled kernels are in place);
- ``dask1`` / ``dask2``: :meth:`Study.run` on a ``LocalCluster`` of 1 / 2 worker processes
  (each worker warmed by one case first; cluster start-up timed separately).

Figures (ratios within this run): throughput ``2 vs 1 workers = t(dask1) / t(dask2)``
(target >= 1.7 on 2 cores) and Dask overhead per case ``(t(dask1) - t(loop)) / t(loop)``
(target <= 10 % for ~1 s cases). The three runs are repeated ``--repeat`` times,
interleaved (loop, dask1, dask2, loop, ...). Each ratio is taken within a round, whose runs
follow each other within a minute and so see about the same load from other processes, and
the median over the rounds is the headline; the ratios of the fastest run of each kind are
shown too (other processes only ever add time, but not to every run alike). The targets
need an otherwise idle machine: the load average (``os.getloadavg``) before and after is
written with the results. The ``mean case time`` column is each case's own wall time
(``case_wall_time``) inside the worker or the loop: the part of the overhead that is the case
running slower in a worker process rather than Dask's scheduling.

Usage::

    .venv/bin/python benchmarks/studies.py --out benchmarks/results        # ~3 min idle
    .venv/bin/python benchmarks/studies.py --cases 4 --duration 0.1 --out /tmp/b   # smoke
"""

from __future__ import annotations

import os

# single-threaded BLAS in this process too, like the workers (the Nanny sets it there)
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import yaml  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from multiarm_pin.study import Study  # noqa: E402
from multiarm_pin.study.execution import local_cluster  # noqa: E402


def make_study(folder: Path, cases: int, duration: float) -> Study:
    masses = [2.0 + 0.5 * k for k in range(cases)]
    p = folder / "bench_study.yaml"
    p.write_text(yaml.safe_dump({
        "name": "bench_study",
        "base": str(ROOT / "scenarios" / "two_ur5_box.yaml"),
        "set": {"simulation.duration": duration},
        "parameters": [{"path": "object.mass", "grid": masses}],
        "metrics": ["max_constraint_violation", "peak_joint_torque", "wall_time"],
    }))
    return Study.from_file(p)


def warm_up_study(folder: Path, duration: float, n: int) -> Study:
    """A study of ``n`` cases run before timing (one per worker: imports, caches, kernels)."""
    p = folder / "warm.yaml"
    p.write_text(yaml.safe_dump({
        "name": "warm", "base": str(ROOT / "scenarios" / "two_ur5_box.yaml"),
        "set": {"simulation.duration": duration},
        "parameters": [{"path": "object.mass", "grid": [1.0 + 0.1 * k for k in range(n)]}],
        "metrics": ["wall_time"]}))
    return Study.from_file(p)


def timed_dask(study: Study, workers: int, folder: Path, duration: float) -> dict:
    from distributed import Client

    t0 = time.perf_counter()
    cluster = local_cluster(workers)
    client = Client(cluster)
    client.wait_for_workers(workers)
    start = time.perf_counter() - t0
    try:
        # warm every worker: one case each, submitted to each worker
        import os as _os

        pids = client.run(_os.getpid)
        from multiarm_pin.study.case import run_case

        warm = warm_up_study(folder, duration, len(pids))
        futs = [client.submit(run_case, warm.task(c), workers=[w], pure=False)
                for c, w in zip(warm.cases, pids, strict=True)]
        client.gather(futs)
        t0 = time.perf_counter()
        table = study.run(client=client)
        wall = time.perf_counter() - t0
    finally:
        client.close()
        cluster.close()
    status = table.column("status").to_pylist()
    return {"wall": wall, "start": start, "ok": status.count("ok"), "n": len(status),
            "case_mean": sum(table.column("case_wall_time").to_pylist()) / len(status)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=12, help="cases in the study (default 12)")
    ap.add_argument("--duration", type=float, default=1.0,
                    help="simulated seconds per case (default 1.0: with building the arms "
                         "and the inverse kinematics, ~0.9 s of work per case)")
    ap.add_argument("--repeat", type=int, default=3,
                    help="interleaved rounds of loop, 1 and 2 workers (default 3; the "
                         "median of the ratios within each round is reported)")
    ap.add_argument("--out", default="benchmarks/results", help="output folder")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    load_before = os.getloadavg()
    loops, d1s, d2s = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        study = make_study(folder, args.cases, args.duration)
        warm_up_study(folder, args.duration, 2).run_loop()
        for _ in range(args.repeat):  # interleaved: slow spells of other load hit all three
            t0 = time.perf_counter()
            loop = study.run_loop()
            wall = time.perf_counter() - t0
            status = loop.column("status").to_pylist()
            loops.append({"wall": wall, "start": 0.0, "ok": status.count("ok"),
                          "n": len(status), "case_mean": sum(
                              loop.column("case_wall_time").to_pylist()) / loop.num_rows})
            d1s.append(timed_dask(study, 1, folder, args.duration))
            d2s.append(timed_dask(study, 2, folder, args.duration))
    load_after = os.getloadavg()
    runs = {"loop": (0, loops), "dask1": (1, d1s), "dask2": (2, d2s)}
    # ratios within each round (its three runs see about the same load), median over rounds
    overheads = [d1["wall"] / lp["wall"] - 1 for lp, d1 in zip(loops, d1s, strict=True)]
    speedups = [d1["wall"] / d2["wall"] for d1, d2 in zip(d1s, d2s, strict=True)]
    slowdowns = [d1["case_mean"] / lp["case_mean"] - 1 for lp, d1 in zip(loops, d1s,
                                                                          strict=True)]
    overhead, speedup = statistics.median(overheads), statistics.median(speedups)
    slowdown = statistics.median(slowdowns)
    per_case = statistics.median([(d1["wall"] - lp["wall"]) / args.cases
                                  for lp, d1 in zip(loops, d1s, strict=True)])
    # the fastest run of each kind (others only ever add time, though not to all runs alike)
    fast = {name: min(v, key=lambda d: d["wall"]) for name, (_, v) in runs.items()}
    fast_overhead = fast["dask1"]["wall"] / fast["loop"]["wall"] - 1
    fast_speedup = fast["dask1"]["wall"] / fast["dask2"]["wall"]
    rows = [{"run": name, "round": r + 1, "workers": workers, "cases": args.cases,
             "wall_s": d["wall"], "per_case_s": d["wall"] / args.cases,
             "case_mean_s": d["case_mean"], "startup_s": d["start"]}
            for r in range(args.repeat) for name, (workers, v) in runs.items()
            for d in [v[r]]]
    with open(out / "studies.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    lines = [
        "# Studies on Dask: throughput and overhead",
        "",
        f"`{' '.join(['benchmarks/studies.py', *(argv or sys.argv[1:])])}` on "
        f"{platform.node()} ({os.cpu_count()} CPUs), Python {platform.python_version()}; "
        f"load average (1, 5, 15 min) before {tuple(round(x, 2) for x in load_before)}, "
        f"after {tuple(round(x, 2) for x in load_after)}.",
        "",
        f"Study: {args.cases} cases of the demo pair, {args.duration} s simulated each; "
        "every process warm (one case run first on each) before timing; "
        f"{args.repeat} interleaved rounds (loop, dask1, dask2, loop, ...). Wall [s] of the "
        "whole study and, in parentheses, mean time of one case inside its process "
        "(`case_wall_time`); cluster start-up is not in the wall time.",
        "",
        "| round | loop | dask1 | dask2 | overhead dask1 vs loop | 2 vs 1 workers |",
        "|---|---|---|---|---|---|",
    ]
    lines += [f"| {r + 1} | {lp['wall']:.2f} ({lp['case_mean']:.3f}) | "
              f"{d1['wall']:.2f} ({d1['case_mean']:.3f}) | "
              f"{d2['wall']:.2f} ({d2['case_mean']:.3f}) | {100 * o:+.1f} % | {sp:.2f}x |"
              for r, (lp, d1, d2, o, sp) in
              enumerate(zip(loops, d1s, d2s, overheads, speedups, strict=True))]
    lines += [
        "",
        f"- throughput 2 vs 1 workers: **{speedup:.2f}x** (median over rounds; "
        f"target >= 1.7x)",
        f"- Dask overhead vs the plain loop: **{100 * overhead:+.1f} %** (median over "
        f"rounds, {per_case * 1000:+.0f} ms per case; target <= 10 %), of which the case "
        f"itself running slower in the worker: {100 * slowdown:+.1f} %",
        f"- fastest run of each kind: 2 vs 1 workers {fast_speedup:.2f}x, overhead "
        f"{100 * fast_overhead:+.1f} % (loop {fast['loop']['wall']:.2f} s, dask1 "
        f"{fast['dask1']['wall']:.2f} s, dask2 {fast['dask2']['wall']:.2f} s)",
        f"- cluster start-up (median): 1 worker "
        f"{statistics.median(d['start'] for d in d1s):.1f} s, 2 workers "
        f"{statistics.median(d['start'] for d in d2s):.1f} s",
        "",
        "The targets assume an otherwise idle 2-core machine; with other processes running "
        "(load average above), two workers share the cores with them.",
    ]
    (out / "studies.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    ok = [d["ok"] for d in loops + d1s + d2s]
    if min(ok) != args.cases:
        print(f"warning: failed cases {ok}", file=sys.stderr)
        return 1
    return 0

if __name__ == "__main__":
    sys.exit(main())
