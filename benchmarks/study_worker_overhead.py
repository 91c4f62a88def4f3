#!/usr/bin/env python
"""Benchmark: one study case in a plain loop vs inside a Dask worker, and why (issue 15).

The studies benchmark (``studies.py``) found a ~1 s case running slower inside a worker
process than in the plain loop. This program times the same cases three ways, interleaved
over ``--repeat`` rounds, and measures inside each case (Linux: ``getrusage`` of the case's
thread and ``/proc/thread-self/schedstat``):

- ``loop``: in this process, after two warm-up cases;
- ``dask defaults``: a fresh ``LocalCluster`` of 1 worker (1 thread) with Dask's default
  configuration, every task submitted at once as :meth:`Study.run` does;
- ``study cluster``: the same through :func:`multiarm_pin.study.execution.local_cluster`,
  i.e. with ``LOCAL_CLUSTER_CONFIG`` (no worker profiler, 1 s event-loop tick).

Per case (median over cases and rounds): wall time, the thread's CPU time, the time it
waited for a CPU (run queue: other processes' load) and the rest, *blocked* (off CPU
without waiting for one: in a worker, waiting for the GIL held by the worker's other
threads), and the thread's voluntary context switches (each a wait, mostly for the GIL).
``wall - run-queue wait`` estimates the case's time on an idle machine; its ratio to the
loop's is the figure that matters.

Usage::

    .venv/bin/python benchmarks/study_worker_overhead.py               # ~2 min idle
    .venv/bin/python benchmarks/study_worker_overhead.py --cases 2 --duration 0.1  # smoke
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import resource  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
for _p in (ROOT, ROOT / "benchmarks"):
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

from studies import make_study, warm_up_study  # noqa: E402

from multiarm_pin.study.case import run_case  # noqa: E402
from multiarm_pin.study.execution import local_cluster  # noqa: E402


def _schedstat() -> tuple[float, float]:
    """(on-CPU time, run-queue wait) [s] of the calling thread so far."""
    with open("/proc/thread-self/schedstat") as fh:
        run, wait, _ = fh.read().split()
    return int(run) * 1e-9, int(wait) * 1e-9


def timed_case(task) -> dict:
    """Run one case and measure it from inside its thread (runs on the worker too)."""
    r0, s0, w0 = resource.getrusage(resource.RUSAGE_THREAD), _schedstat(), time.perf_counter()
    run_case(task)
    w = time.perf_counter() - w0
    r1, s1 = resource.getrusage(resource.RUSAGE_THREAD), _schedstat()
    oncpu, rq = s1[0] - s0[0], s1[1] - s0[1]
    return {"wall": w, "cpu": (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime),
            "runqueue": rq, "blocked": w - oncpu - rq, "idle_wall": w - rq,
            "waits": r1.ru_nvcsw - r0.ru_nvcsw}


def on_cluster(cluster, tasks, warm) -> tuple[float, list[dict]]:
    from distributed import Client

    with Client(cluster) as client:
        client.wait_for_workers(1)
        client.submit(timed_case, warm, pure=False).result()  # warm the worker
        t0 = time.perf_counter()
        out = client.gather([client.submit(timed_case, t, pure=False) for t in tasks])
        wall = time.perf_counter() - t0
    cluster.close()
    return wall, out


def dask_defaults_cluster():
    from distributed import LocalCluster

    return LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                        dashboard_address=None)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=8, help="cases per run (default 8)")
    ap.add_argument("--duration", type=float, default=1.0,
                    help="simulated seconds per case (default 1.0: ~0.9 s cases)")
    ap.add_argument("--repeat", type=int, default=2, help="interleaved rounds (default 2)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        study = make_study(Path(tmp), args.cases, args.duration)
        warm = warm_up_study(Path(tmp), args.duration, 2)
        tasks = [study.task(c) for c in study.cases]
        for c in warm.cases:
            run_case(warm.task(c))
        warm_task = warm.task(warm.cases[0])
        load_before = os.getloadavg()
        runs = {"loop": [], "dask defaults": [], "study cluster": []}
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            out = [timed_case(t) for t in tasks]
            runs["loop"].append((time.perf_counter() - t0, out))
            runs["dask defaults"].append(on_cluster(dask_defaults_cluster(), tasks, warm_task))
            runs["study cluster"].append(on_cluster(local_cluster(1), tasks, warm_task))
        load_after = os.getloadavg()

    def med(name, key):
        return statistics.median(x[key] for _, out in runs[name] for x in out)

    ref = med("loop", "idle_wall")
    print(f"{args.cases} cases x {args.repeat} rounds, {args.duration} s simulated each; "
          f"load average before {tuple(round(x, 2) for x in load_before)}, after "
          f"{tuple(round(x, 2) for x in load_after)}\n")
    print("| run | study wall [s] | case wall [s] | case CPU [s] | run-queue wait [s] | "
          "blocked [s] | GIL waits | case time w/o run-queue wait vs loop |")
    print("|---|---|---|---|---|---|---|---|")
    for name, v in runs.items():
        walls = ", ".join(f"{w:.2f}" for w, _ in v)
        print(f"| {name} | {walls} | {med(name, 'wall'):.3f} | {med(name, 'cpu'):.3f} | "
              f"{med(name, 'runqueue'):.3f} | {med(name, 'blocked'):.3f} | "
              f"{med(name, 'waits'):.0f} | {100 * (med(name, 'idle_wall') / ref - 1):+.1f} % |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
