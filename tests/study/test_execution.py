"""Studies on a LocalCluster of 2 workers: rows identical to a plain loop, a killed worker's
tasks rerun elsewhere, an interrupted study resumed without running a finished case again.

One cluster serves the module (worker processes import pinocchio: slow to start); the
kill test runs last since it restarts a worker.
"""

import json
import os
import signal
import time

import numpy as np
import pytest

from multiarm_pin.study import Study, read_table
from multiarm_pin.study.execution import local_cluster
from multiarm_pin.study.metrics import GRASP_METRICS, SIMULATION_METRICS
from tests.run_helpers import python_sigint_handler
from tests.study.helpers import rows_by_case, tiny_grasp_study, tiny_simulation_study

pytestmark = pytest.mark.timeout(900)
TIMING = ("wall_time",)  # measured, not computed: differs between two runs of a case


@pytest.fixture(scope="module")
def client(warm_kernels):
    from distributed import Client

    cluster = local_cluster(2)
    c = Client(cluster)
    c.wait_for_workers(2, timeout=300)
    yield c
    c.close()
    cluster.close()


def _same_metrics(a: dict, b: dict, metrics) -> None:
    for m in metrics:
        if m in TIMING:
            continue
        x, y = a[m], b[m]
        assert (np.isnan(x) and np.isnan(y)) or x == y, (a["case_id"], m, x, y)


def test_dask_rows_identical_to_plain_loop(client, tmp_path):
    study = Study.from_file(tiny_simulation_study(tmp_path, masses=(2.0, 6.0), samples=2))
    dask_table = study.run(client=client, out=tmp_path / "dask")
    loop_table = study.run_loop()
    d, lp = rows_by_case(dask_table), rows_by_case(loop_table)
    assert sorted(d) == sorted(lp) == [c.case_id for c in study.cases]
    workers = set()
    for cid in d:
        assert d[cid]["status"] == "ok" == lp[cid]["status"], d[cid]["error"]
        _same_metrics(d[cid], lp[cid], SIMULATION_METRICS)
        assert d[cid]["object.mass"] == lp[cid]["object.mass"]
        assert d[cid]["controller.kp"] == lp[cid]["controller.kp"]
        workers.add(d[cid]["worker"])
    assert os.getpid() not in {int(w.split(":")[1]) for w in workers}
    # the folder holds the same rows, a summary per case and the table
    on_disk = rows_by_case(read_table(tmp_path / "dask"))
    assert sorted(on_disk) == sorted(d)
    for cid, row in d.items():
        assert on_disk[cid]["peak_joint_torque"] == row["peak_joint_torque"]
        s = json.loads((tmp_path / "dask" / "cases" / cid / "summary.json").read_text())
        assert s["status"] == "ok" and s["run"]["max_constraint_violation"] == \
            row["max_constraint_violation"]
    # physics sanity: a heavier box needs more torque (same controller draw set)
    heavy = [r["peak_joint_torque"] for r in d.values() if r["object.mass"] == 6.0]
    light = [r["peak_joint_torque"] for r in d.values() if r["object.mass"] == 2.0]
    assert min(heavy) > max(light)


def test_grasp_study_on_dask_matches_loop_and_failures_are_rows(client, tmp_path):
    study = Study.from_file(tiny_grasp_study(tmp_path, sigmas=(0.001, 0.03), samples=8))
    # through the scheduler's address, as `sweep --scheduler ADDRESS` does (own client)
    d = rows_by_case(study.run(scheduler=client.scheduler.address))
    lp = rows_by_case(study.run_loop())
    assert sorted(d) == sorted(lp)
    for cid in d:
        assert d[cid]["status"] == lp[cid]["status"]
        assert d[cid]["error"] == lp[cid]["error"]
        _same_metrics(d[cid], lp[cid], GRASP_METRICS)
    # σ = 1 mm keeps the 7-contact grasp closed (margin ~0.048); at 30 mm some contact
    # point (2.5 cm from a face edge) leaves its face: an error row, the study goes on
    small = [r for r in d.values() if r["perturb_contacts.sigma"] == 0.001]
    assert all(r["status"] == "ok" and r["form_closure"] == 1.0 for r in small)
    big = [r for r in d.values() if r["perturb_contacts.sigma"] == 0.03]
    assert any(r["status"] == "error" and "outside the face" in r["error"] for r in big)


def test_interrupted_study_resumes_without_rerunning_finished_cases(client, tmp_path):
    study = Study.from_file(tiny_grasp_study(tmp_path, sigmas=(0.001, 0.002), samples=6))
    out = tmp_path / "out"
    seen = []

    def interrupt(row):
        seen.append(row["case_id"])
        if len(seen) == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        study.run(client=client, out=out, on_case=interrupt)
    first = rows_by_case(read_table(out))
    assert sorted(first) == sorted(seen)  # every finished case is in the table
    resumed = []
    table = study.run(client=client, out=out, resume=True,
                      on_case=lambda r: resumed.append(r["case_id"]))
    assert not set(resumed) & set(first)  # no finished case ran again
    rows = rows_by_case(table)
    assert sorted(rows) == [c.case_id for c in study.cases]
    for cid, row in first.items():
        assert rows[cid]["run_token"] == row["run_token"]
    # re-running (without --resume) a complete study runs nothing and starts no cluster
    again = []
    study.run(out=out, on_case=lambda r: again.append(r))
    assert again == []


def test_local_cluster_workers_take_less_gil_from_the_case(client):
    """The workers run with LOCAL_CLUSTER_CONFIG (no profiler sampling the case every
    10 ms, a 1 s event-loop tick); this process's own Dask configuration is untouched."""
    import dask.config

    def worker_settings(dask_worker):
        return {"profile": dask.config.get("distributed.worker.profile.enabled"),
                "profiling": "profile" in dask_worker.periodic_callbacks,
                "tick_ms": dask_worker.periodic_callbacks["tick"].callback_time,
                "gil": dask.config.get("distributed.admin.system-monitor.gil.enabled")}

    settings = client.run(worker_settings)
    assert len(settings) == 2
    for s in settings.values():
        assert s == {"profile": False, "profiling": False, "tick_ms": 1000.0, "gil": False}
    assert dask.config.get("distributed.worker.profile.enabled") is True
    assert dask.config.get("distributed.admin.tick.interval") == "20ms"


def test_killed_worker_tasks_rerun_elsewhere(client, tmp_path):
    study = Study.from_file(tiny_simulation_study(tmp_path, masses=(2.0, 3.0, 4.0),
                                                  samples=2, duration=0.02))
    killed = {}
    pids = client.run(os.getpid)  # {worker address: pid}, asked before the study starts

    def kill_a_busy_worker(row):
        if killed:
            return
        deadline = time.monotonic() + 120
        while True:  # the next case is being handed out: wait until a worker holds one
            busy = {w: keys for w, keys in client.processing().items() if keys and w in pids}
            if busy or time.monotonic() > deadline:
                break
            time.sleep(0.01)
        assert busy, "no worker was running a case after the first row"
        addr, keys = next(iter(busy.items()))
        os.kill(pids[addr], signal.SIGKILL)
        killed.update(pid=pids[addr], keys=list(keys), after=row["case_id"])

    table = study.run(client=client, out=tmp_path / "out", on_case=kill_a_busy_worker)
    rows = rows_by_case(table)
    assert killed, "no row arrived"
    assert sorted(rows) == [c.case_id for c in study.cases]
    assert all(r["status"] == "ok" for r in rows.values()), [r["error"] for r in rows.values()]
    # the cases that were running on the killed worker ran again on a live process
    rerun = [cid for cid in rows if any(f"case-{cid}-" in str(k) for k in killed["keys"])]
    assert rerun, killed
    for cid in rerun:
        assert int(rows[cid]["worker"].split(":")[1]) != killed["pid"]
    # every worker ignores SIGINT, the one the Nanny started again in place of the killed one
    # too (WORKER_PRELOAD): a terminal's Ctrl-C is the driver's alone
    client.wait_for_workers(2, timeout=300)
    ignored = client.run(lambda: (os.getpid(), signal.getsignal(signal.SIGINT) == signal.SIG_IGN))
    assert len(ignored) == 2 and killed["pid"] not in {pid for pid, _ in ignored.values()}
    assert all(ign for _, ign in ignored.values()), ignored


def test_a_ctrl_c_swallowed_on_its_way_still_stops_the_driver():
    """A SIGINT whose KeyboardInterrupt is dropped where it was raised (as in a garbage
    collector callback, which Python reports as "ignored") is remembered: the driver's next
    check raises it. Outside the block, SIGINT has Python's default handler again."""
    from multiarm_pin.study.execution import SigintLatch

    with python_sigint_handler():  # even if the suite was started with SIGINT ignored
        latch = SigintLatch()
        with latch.installed():
            latch.check()  # nothing yet
            try:  # the swallowing callback
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(1.0)  # the handler runs at the next bytecode boundary
            except KeyboardInterrupt:
                pass
            with pytest.raises(KeyboardInterrupt):
                latch.check()
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
        latch2 = SigintLatch()
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)  # a caller's choice is kept
        try:
            with latch2.installed():
                assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
        finally:
            signal.signal(signal.SIGINT, previous)


def test_a_ctrl_c_dropped_in_a_finaliser_is_not_printed_but_other_errors_are(monkeypatch):
    """Python prints an exception raised where it cannot propagate (a finaliser, a garbage
    collector callback) as "Exception ignored ... Traceback": for the latch's own interrupt
    that is noise beside the interrupt's message, for any other error it is kept."""
    import gc
    import sys

    from multiarm_pin.study.execution import SigintLatch

    with python_sigint_handler():  # even if the suite was started with SIGINT ignored
        seen = []

        def record(unraisable):
            seen.append(type(unraisable.exc_value))

        monkeypatch.setattr(sys, "unraisablehook", record)
        latch = SigintLatch()

        class Interrupted:
            def __del__(self):
                latch._handler(signal.SIGINT, None)  # the signal lands here

        class Failing:
            def __del__(self):
                raise ValueError("kept")

        with latch.installed():
            Interrupted()
            Failing()
            gc.collect()
            with pytest.raises(KeyboardInterrupt):
                latch.check()
        assert seen == [ValueError]
        assert sys.unraisablehook is record
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
        Interrupted()  # outside the block the hook is the caller's again
        assert seen == [ValueError, KeyboardInterrupt]
