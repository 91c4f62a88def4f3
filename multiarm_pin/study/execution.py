"""Running a study: each case a Dask task, on a local cluster or the user's scheduler.

:class:`Study` is the Python API (``Study.from_file(path).run(client=None)`` returns the
table) and what ``multiarm-pin sweep`` drives. Without a client it starts a
``distributed.LocalCluster`` of ``workers`` processes (one thread each) on this machine;
with ``scheduler="tcp://host:8786"`` it connects to an existing cluster (for instance one
started by ``dask-jobqueue`` on SLURM/PBS). Rows and summaries are written by the driver as
cases finish (:class:`~multiarm_pin.study.store.ResultsFolder`); Dask reruns the tasks of a
worker that dies on another worker.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import sys
import threading
import time
import uuid
from collections.abc import Callable
from pathlib import Path

from multiarm_pin.app.progress import LineProgress
from multiarm_pin.app.results_io import deferred_signals, folder_lock
from multiarm_pin.exceptions import StudyError
from multiarm_pin.study.case import CaseTask, run_case
from multiarm_pin.study.spec import Case, StudySpec, load_study
from multiarm_pin.study.store import ResultsFolder, rows_to_table

TABLE_FLUSH_INTERVAL = 2.0
"""Seconds between rewrites of ``results.parquet`` while a study runs (rows are written
per case in any case)."""
SCHEDULER_TIMEOUT = 10.0
"""Seconds to wait for a user's scheduler before giving up."""
WORKER_PRELOAD = "multiarm_pin.study.worker_setup"
"""The module each worker of the local cluster runs at its start (it ignores SIGINT)."""
LOCAL_CLUSTER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.gil.enabled": False,
    "distributed.worker.preload": [WORKER_PRELOAD],
}
"""Dask settings of the local cluster :func:`local_cluster` starts (not of a user's cluster).

A worker runs its case in a thread while its event loop and statistical profiler run in
other threads of the same process, so every wake-up of those takes the GIL from the case
(after ``sys.getswitchinterval()``) and hands it back, ~150 times a second with Dask's
defaults; when the machine's other core is busy, those threads also queue for the case's
core (``benchmarks/study_worker_overhead.py`` measures a study's time over a plain loop
with Dask's defaults and with these settings). Hence:

- ``profile.enabled: False``: no stack sample of the running case every 10 ms (the
  profile feeds the dashboard, which this cluster does not serve);
- ``tick.interval: 1s`` (default 20 ms): the event loop's health check, which only logs
  when the loop is blocked longer than ``distributed.admin.tick.limit`` (3 s), still does;
- ``system-monitor.gil.enabled: False``: with ``gilknocker`` installed, Dask would poll
  the GIL every 1 ms to measure this very contention.

The Nanny hands the configuration active at its creation to its worker process, also
when it restarts a worker that died; ``worker.preload`` runs :data:`WORKER_PRELOAD` in each
(see :func:`_workers_ignore_sigint`).
"""


class CaseProgress(LineProgress):
    """A one-line progress bar over cases (stderr by default).

    On a terminal it redraws in place; on a log file it writes a line per tenth of the cases
    (the first one at the start, for the cases found done by ``--resume``).
    """

    def __init__(self, label: str, total: int, done: int = 0, stream=None, width: int = 30):
        super().__init__(label, stream, width)
        self.total = max(int(total), 0)
        self.done, self.failed, self.skipped = done, 0, done
        self._next_tenth = 0.0

    def update(self, failed: bool = False) -> None:
        """One more case finished (``failed``: with an error)."""
        self.done += 1
        self.failed += int(bool(failed))
        self.draw()

    def draw(self) -> None:
        """Draw the bar (every call on a terminal, every tenth otherwise)."""
        f = self.done / self.total if self.total else 1.0
        if not self.due(f):
            return
        elapsed = time.perf_counter() - self.start
        ran = self.done - self.skipped
        left = (self.total - self.done) * elapsed / ran if ran else float("nan")
        super().draw(f, f"{self.done}/{self.total} cases ({self.failed} failed), "
                        f"{elapsed:.1f} s elapsed, ~{left:.0f} s left")


def connect(scheduler: str, timeout: float = SCHEDULER_TIMEOUT):
    """A ``distributed.Client`` on the user's scheduler.

    Raises:
        StudyError: the scheduler cannot be reached within ``timeout`` seconds.
    """
    from distributed import Client

    try:
        return Client(scheduler, timeout=timeout)
    except (OSError, TimeoutError, ValueError) as exc:
        raise StudyError("--scheduler", "", f"cannot reach the Dask scheduler at "
                         f"{scheduler!r} within {timeout:g} s: {exc}") from None


def local_cluster(workers: int):
    """A ``distributed.LocalCluster`` of ``workers`` processes with one thread each.

    Its scheduler and workers run with :data:`LOCAL_CLUSTER_CONFIG` (no profiler, a slow
    event-loop tick: less GIL taken from the running case).

    Raises:
        StudyError: ``workers`` is not a positive integer.
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise StudyError("--workers", "", f"expected a positive number of workers, got "
                         f"{workers!r}")
    import dask.config
    from distributed import LocalCluster

    cluster = None
    try:
        # a Ctrl-C while the cluster starts is held until it is up (then closed whole)
        with dask.config.set(LOCAL_CLUSTER_CONFIG), _workers_ignore_sigint(), \
                deferred_signals((signal.SIGINT,)):
            # the scheduler's HTTP server (no dashboard) on a free local port: no warning
            # when another cluster holds Dask's default port. Its processes log only
            # CRITICAL: at a Ctrl-C the scheduler closes while a worker may be sending its
            # heartbeat, which distributed logs as an ERROR with two tracebacks; a case that
            # fails or a worker that dies is the study's own row (status and error)
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=logging.CRITICAL,
                                   scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})
    except BaseException:  # a Ctrl-C held during the start arrives as it ends
        if cluster is not None:
            with contextlib.suppress(Exception):
                cluster.close()
        raise
    return cluster


@contextlib.contextmanager
def _workers_ignore_sigint():
    """Worker processes started inside the block ignore SIGINT: the driver alone handles it.

    A terminal's Ctrl-C goes to its whole foreground process group, the local cluster's
    worker processes too, whose event loops would each die printing a traceback. The
    workers are forked from multiprocessing's fork server (``multiprocessing-method:
    forkserver`` inside the block), which is started here, if it is not running yet, with
    SIGINT ignored: an ignored disposition survives ``exec``, Python leaves an ignored
    SIGINT ignored, and the server hands it to every process it forks. SIGINT is ignored in
    the driver only while the server process is launched (it is not waited for). Each
    worker also ignores SIGINT from its start on (:data:`WORKER_PRELOAD`), a worker the
    Nanny restarts later too. Main thread only (elsewhere: the preload alone).
    """
    import dask.config

    if threading.current_thread() is threading.main_thread():
        from multiprocessing import forkserver

        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            forkserver.ensure_running()
        finally:
            signal.signal(signal.SIGINT, signal.default_int_handler if previous is None
                          else previous)
    with dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"}):
        yield


class Study:
    """A study: its spec, its cases, and how to run them.

    Args:
        spec: a :class:`~multiarm_pin.study.spec.StudySpec` or a study file path.
    """

    def __init__(self, spec: StudySpec | str | Path):
        self.spec = spec if isinstance(spec, StudySpec) else load_study(spec)
        self.cases: list[Case] = self.spec.cases()

    @classmethod
    def from_file(cls, path) -> Study:
        """Load a study file (raises :class:`~multiarm_pin.exceptions.StudyError`)."""
        return cls(load_study(path))

    def task(self, case: Case) -> CaseTask:
        """The worker's input for one case."""
        s = self.spec
        return CaseTask(case.case_id, case.key, case.index, case.params, s.mode, s.base_file,
                        s.base_data, case.overrides, s.metrics)

    # ------------------------------------------------------------------ running
    def run(self, client=None, out=None, workers: int = 2, scheduler: str | None = None,
            resume: bool = False, progress: bool = False,
            on_case: Callable[[dict], None] | None = None):
        """Run every unfinished case as a Dask task; return the table.

        Args:
            client: a ``distributed.Client`` to use (not closed here); None: connect to
                ``scheduler`` if given, else start a ``LocalCluster`` of ``workers``
                processes (closed at the end).
            out: results folder (rows, summaries and ``results.parquet`` written as cases
                finish; finished cases in it are skipped); None: nothing written.
            workers: worker processes of the local cluster.
            scheduler: address of an existing scheduler (``tcp://host:8786``).
            resume: the folder must already hold this study (``--resume``).
            progress: draw a progress bar on stderr.
            on_case: called with each new row as it is written (driver side).

        Returns:
            A ``pyarrow.Table``: one row per case (finished before or now), sorted by case.

        Raises:
            StudyError: unreachable scheduler (nothing written), bad ``workers``, an output
                folder holding another study.
            OutputError: another run or study is writing into ``out`` (nothing written).
            KeyboardInterrupt: after writing every finished row and the table.
        """
        with self._locked(out):
            return self._run(client, out, workers, scheduler, resume, progress, on_case)

    def _run(self, client, out, workers, scheduler, resume, progress, on_case):
        if out is not None:  # a folder that cannot take the study: before any cluster
            ResultsFolder(out).check(self.spec, resume)
        if client is None and out is not None and self._nothing_to_run(out):
            return self._drive(_LoopRunner(), out, resume, progress, on_case)  # no cluster
        own_cluster = own_client = None
        if client is None:
            if scheduler is not None:
                client = own_client = connect(scheduler)
            else:
                own_cluster = local_cluster(workers)
                from distributed import Client

                client = own_client = Client(own_cluster)
        try:
            return self._drive(_DaskRunner(client), out, resume, progress, on_case)
        finally:  # a failure to close must not replace the study's own outcome (Ctrl-C)
            for closer in (own_client, own_cluster):
                if closer is not None:
                    with contextlib.suppress(Exception):
                        closer.close()

    def _nothing_to_run(self, out) -> bool:
        folder = ResultsFolder(out)
        return (folder.path / "study.json").is_file() and \
            len(folder.finished(self.cases)) == len(self.cases)

    def run_loop(self, out=None, resume: bool = False, progress: bool = False,
                 on_case: Callable[[dict], None] | None = None):
        """Run the unfinished cases one after the other in this process (no Dask).

        Same arguments and result as :meth:`run` (the reference the Dask run is checked
        against, and the benchmark's plain loop).
        """
        with self._locked(out):
            return self._drive(_LoopRunner(), out, resume, progress, on_case)

    @contextlib.contextmanager
    def _locked(self, out):
        """Hold the results folder's lock (the one runs take) while the study writes it.

        Raises:
            OutputError: another run or study is writing into ``out`` (names its pid and file).
        """
        if out is None:
            yield
            return
        out = Path(out)
        if not out.parent.is_dir():
            try:
                out.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise StudyError(str(out), "--out", f"cannot create the folder {out.parent}: "
                                 f"{exc.strerror or exc}") from exc
        lock = folder_lock(out, self.spec.file)
        lock.acquire()
        try:
            yield
        finally:
            lock.release()

    def _drive(self, runner, out, resume: bool, progress: bool, on_case):
        folder = ResultsFolder(out) if out is not None else None
        done = folder.prepare(self.spec, self.cases, resume) if folder is not None else {}
        rows = dict(done)
        todo = [c for c in self.cases if c.case_id not in done]
        bar = CaseProgress(f"sweep {self.spec.name}", len(self.cases), len(done)) \
            if progress else None
        if bar is not None:
            bar.draw()
        last_flush = time.perf_counter()
        latch = SigintLatch()
        try:
            with latch.installed():
                for result in runner.results([self.task(c) for c in todo]):
                    row = result["row"]
                    if folder is not None:
                        folder.write_case(row, result.get("summary"))
                    rows[row["case_id"]] = row
                    if bar is not None:
                        bar.update(failed=row["status"] != "ok")
                    if on_case is not None:
                        on_case(row)
                    if folder is not None and \
                            time.perf_counter() - last_flush > TABLE_FLUSH_INTERVAL:
                        folder.write_table(rows.values())
                        last_flush = time.perf_counter()
                    latch.check()  # a Ctrl-C lost on its way (see SigintLatch)
        finally:
            runner.stop()
            if bar is not None:
                bar.close()
            if folder is not None and rows:
                folder.write_table(rows.values())
        return rows_to_table(rows.values())


class SigintLatch:
    """A Ctrl-C remembered until the driver looks (:meth:`check`), even when it was lost.

    Python raises ``KeyboardInterrupt`` wherever the main thread is when SIGINT arrives; in a
    garbage-collector callback (distributed installs one) the exception is printed as
    "ignored" and dropped, and the study would run on to its end. The latch's handler notes
    the signal before raising, so the driver's loop stops at its next result anyway; and while
    the latch is installed, such a dropped ``KeyboardInterrupt`` is not printed (Python's
    ``sys.unraisablehook``): the latch holds it, and the user sees the interrupt's own message.

    Attributes:
        hit: a SIGINT arrived while the latch was installed.
    """

    def __init__(self):
        self.hit = False

    def check(self) -> None:
        """Raise ``KeyboardInterrupt`` if a SIGINT arrived (and was lost on its way)."""
        if self.hit:
            raise KeyboardInterrupt

    def _handler(self, signum, frame) -> None:
        self.hit = True
        raise KeyboardInterrupt

    @contextlib.contextmanager
    def installed(self):
        """The latch's SIGINT handler inside the block.

        Only over Python's default handler, in the main thread: a caller's own handler, or an
        ignored SIGINT, is kept.
        """
        if threading.current_thread() is not threading.main_thread() or \
                signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
            yield self
            return
        previous = sys.unraisablehook

        def hook(unraisable) -> None:
            if not (self.hit and isinstance(unraisable.exc_value, KeyboardInterrupt)):
                previous(unraisable)

        signal.signal(signal.SIGINT, self._handler)
        sys.unraisablehook = hook
        try:
            yield self
        finally:
            sys.unraisablehook = previous
            signal.signal(signal.SIGINT, signal.default_int_handler)


class _LoopRunner:
    def results(self, tasks):
        for t in tasks:
            yield run_case(t)

    def stop(self) -> None:
        pass


class _DaskRunner:
    def __init__(self, client):
        self.client = client
        self.futures = []

    def results(self, tasks):
        from distributed import as_completed

        run = uuid.uuid4().hex[:8]
        by_key = {}
        for t in tasks:
            fut = self.client.submit(run_case, t, key=f"case-{t.case_id}-{t.key}-{run}",
                                     pure=False)
            by_key[fut.key] = t
            self.futures.append(fut)
        for fut in as_completed(self.futures):
            task = by_key[fut.key]
            try:
                result = fut.result()
            except Exception as exc:  # noqa: BLE001 - KilledWorker, a lost connection...
                result = {"row": _lost_row(task, exc), "summary": None}
            fut.release()
            yield result

    def stop(self) -> None:
        pending = [f for f in self.futures if not f.done()]
        if pending:
            self.client.cancel(pending)
        self.futures = []


def _lost_row(task: CaseTask, exc: BaseException) -> dict:
    """The row of a case whose task failed in Dask itself (its workers kept dying)."""
    import math

    row = {"case_id": task.case_id, "key": task.key, "index": task.index, **task.params}
    for m in task.metrics:
        row[m] = math.nan
    row.update(status="lost", error=f"{type(exc).__name__}: {exc}", case_wall_time=math.nan,
               worker="", run_token="")
    return row


__all__ = ["LOCAL_CLUSTER_CONFIG", "WORKER_PRELOAD", "CaseProgress", "Study", "connect",
           "local_cluster"]
