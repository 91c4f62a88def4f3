"""Run by each worker process of a study's local cluster at its start (a Dask preload).

SIGINT is ignored in the worker: a terminal's Ctrl-C reaches its whole process group, and
the driver alone handles it (it stops the study, keeps the finished rows and closes the
cluster, which stops the workers). Workers started by
:func:`multiarm_pin.study.execution.local_cluster` already ignore it from their spawn; this
covers a worker that the Nanny restarts later.
"""

from __future__ import annotations

import signal
import threading


def dask_setup(worker) -> None:
    """Ignore SIGINT in this worker process (Dask's preload hook; ``worker`` is unused)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


__all__ = ["dask_setup"]
