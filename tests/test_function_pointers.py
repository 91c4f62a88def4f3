"""Compiling on every core: ``function_pointers.compile_all`` and the cache's index lock."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading

import numba
import numpy as np
import pytest
from numba.core import caching

from multiarm_pin._compiled import cache, function_pointers, linalg
from multiarm_pin._compiled.function_pointers import (
    DEFAULT_MOST_PROCESSES,
    PROCESSES_VARIABLE,
    bind,
    compile_all,
    compile_of,
    compiled,
    numba_type,
    pointer,
    processes,
)

pytestmark = pytest.mark.skipif(numba.config.DISABLE_JIT, reason="compiles kernels")

# A fresh process (one Python thread: it may fork) compiles three small kernels in two
# groups, one of which cannot be compiled for its types, over two processes sharing an empty
# disk cache; it prints what it got. With "hang", the child takes a group and never ends.
_SCRIPT = r"""
import json, os, sys, time, warnings
import numba, numpy as np
from multiarm_pin._compiled import function_pointers, linalg
from multiarm_pin._compiled.function_pointers import compile_all, compile_of, compiled
if sys.argv[1] == "hang":
    parent, work = os.getpid(), function_pointers._work
    def hanging(queue, groups):
        if os.getpid() != parent:
            os.read(queue, 1)
            time.sleep(3600)
        time.sleep(0.5)  # the child takes its group first
        work(queue, groups)
    function_pointers._work = hanging
    function_pointers.CHILD_TIMEOUT = 1.0
a = np.array([[4.0, 1.0], [1.0, 3.0]])
b = np.array([[1.0], [2.0]])
jobs = [compile_of(linalg.cholesky, (a, a, 2), numba.types.boolean),
        compile_of(linalg.cholesky_solve, (a, b, 2, 1), numba.types.none)]
bad = compile_of(linalg.cholesky, (np.zeros(3), a, 2), numba.types.boolean)
out = {}
start = time.monotonic()
try:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        compile_all([[jobs[0]], [jobs[1]], [bad]] if sys.argv[1] == "bad"
                    else [[jobs[0]], [jobs[1]]])
except numba.core.errors.TypingError:
    out["error"] = "TypingError"
out["seconds"] = time.monotonic() - start
out["warnings"] = [str(w.message) for w in caught if w.category is RuntimeWarning]
L = np.zeros((2, 2))
ok = compiled(jobs[0])(a, L, 2)
x = b.copy()
compiled(jobs[1])(L, x, 2, 1)
t = os.times()
out.update(ok=bool(ok), x=x[:, 0].tolist(), expected=np.linalg.solve(a, b[:, 0]).tolist(),
           children=t.children_user + t.children_system, hits=compiled(jobs[0]).cache_hits)
print(json.dumps(out))
"""


def _run(tmp_path, *args, processes="2"):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"),
               **{PROCESSES_VARIABLE: processes})
    env.pop("NUMBA_DISABLE_JIT", None)
    done = subprocess.run([sys.executable, "-c", _SCRIPT, *args], env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_compile_all_over_two_processes_gives_the_same_functions(tmp_path):
    first = _run(tmp_path, "good")
    assert first["ok"]
    np.testing.assert_allclose(first["x"], first["expected"], rtol=1e-12)
    assert first["children"] > 0.0  # a child process ran
    again = _run(tmp_path, "good")  # all on disk now: loaded, no child
    assert again["x"] == first["x"]
    assert again["children"] == 0.0
    assert again["hits"] == 1


def test_a_compile_that_fails_in_any_process_raises_here(tmp_path):
    out = _run(tmp_path, "bad")
    assert out["error"] == "TypingError"
    np.testing.assert_allclose(out["x"], out["expected"], rtol=1e-12)


def test_a_child_that_hangs_is_stopped_and_its_group_compiled_here(tmp_path):
    out = _run(tmp_path, "hang")
    assert len(out["warnings"]) == 1 and "was stopped" in out["warnings"][0]
    assert out["seconds"] < 300.0  # not the child's hour
    assert out["ok"]
    np.testing.assert_allclose(out["x"], out["expected"], rtol=1e-12)


def test_one_process_compiles_here_without_a_child(tmp_path):
    out = _run(tmp_path, "good", processes="1")
    assert out["children"] == 0.0
    np.testing.assert_allclose(out["x"], out["expected"], rtol=1e-12)


def test_processes_follows_the_variable_and_never_forks_beside_threads(monkeypatch):
    linux = sys.platform.startswith("linux")
    monkeypatch.setenv(PROCESSES_VARIABLE, "6")
    assert processes() == (6 if linux else 1)
    monkeypatch.delenv(PROCESSES_VARIABLE)
    assert processes() == (min(DEFAULT_MOST_PROCESSES, len(os.sched_getaffinity(0))) if linux
                           else 1)
    monkeypatch.setenv(PROCESSES_VARIABLE, "not a number")
    assert processes() == 1
    monkeypatch.setenv(PROCESSES_VARIABLE, "0")
    assert processes() == 1
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        monkeypatch.setenv(PROCESSES_VARIABLE, "3")
        assert processes() == 1
    finally:
        stop.set()
        other.join()


def test_a_pending_function_is_typed_as_the_compiled_one():
    a = np.array([[4.0, 1.0], [1.0, 3.0]])
    job = compile_of(linalg.cholesky, (a, a, 2), numba.types.boolean)
    made = compiled(job)
    assert job.function_type == numba.typeof(made)
    assert numba_type((job.function_type, (job.function_type,))) == numba.typeof((made, (made,)))
    assert compile_of(linalg.cholesky_solve, (a, a, 2, 1)) == compile_of(
        linalg.cholesky_solve, (numba.typeof(a), numba.typeof(a), numba.types.int64, 1))


@numba.njit
def _factor_and_solve(a, L, x, functions):
    """Calls ``functions``, ``(cholesky, (cholesky_solve, ()))``, as pointers or functions."""
    f = bind(functions)
    ok = f[0](a, L, 2)
    f[1][0](L, x, 2, 1)
    return ok, len(f[1][1])


def test_pointers_from_python_call_their_functions_without_calling_back(monkeypatch):
    from numba.experimental import function_type

    a = np.array([[4.0, 1.0], [1.0, 3.0]])
    b = np.array([[1.0], [2.0]])
    jobs = (compile_of(linalg.cholesky, (a, a, 2), numba.types.boolean),
            compile_of(linalg.cholesky_solve, (a, b, 2, 1), numba.types.none))
    pointers = (pointer(jobs[0]), (pointer(jobs[1]), ()))
    functions = (compiled(jobs[0]), (compiled(jobs[1]), ()))
    assert pointers[0] == (compiled(jobs[0]).address, jobs[0].function_type)
    assert numba.typeof(pointers[0]) == jobs[0].pointer_type
    calls = []
    real = function_type._get_wrapper_address
    monkeypatch.setattr(function_type, "_get_wrapper_address",
                        lambda f, sig: calls.append(f) or real(f, sig))
    for given in (pointers, functions):
        x = b.copy()
        _factor_and_solve(a, np.zeros((2, 2)), x, given)  # compiles for these types
        calls.clear()
        x = b.copy()
        ok, empty = _factor_and_solve(a, np.zeros((2, 2)), x, given)
        assert ok and empty == 0
        np.testing.assert_allclose(x[:, 0], np.linalg.solve(a, b[:, 0]), rtol=1e-14)
        # numba unboxes a first-class function by asking Python for its address at every
        # call; a pointer is an integer
        assert (len(calls) == 0) if given is pointers else (len(calls) >= 2)
    assert bind(pointers) is pointers  # in Python (no JIT): as given


def test_every_cache_index_read_and_save_holds_the_lock(tmp_path):
    assert caching.IndexDataCacheFile.save.__name__ == "locked_save"
    assert caching.IndexDataCacheFile.load.__name__ == "locked_load"
    index = str(tmp_path / "f.nbi")
    probe = ("import fcntl, os, sys\n"
             "fd = os.open(sys.argv[1] + '.lock', os.O_RDWR | os.O_CREAT)\n"
             "try:\n    fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)\n    print('free')\n"
             "except BlockingIOError:\n    print('held')\n")

    def other_process_sees():
        return subprocess.run([sys.executable, "-c", probe, index], capture_output=True,
                              text=True, timeout=60).stdout.strip()

    with cache.index_lock(index, exclusive=True):
        assert other_process_sees() == "held"
    assert other_process_sees() == "free"
    with cache.index_lock(index, exclusive=False):
        assert other_process_sees() == "free"  # readers share it


def test_compile_all_does_nothing_twice():
    a = np.array([[4.0, 1.0], [1.0, 3.0]])
    job = compile_of(linalg.cholesky, (a, a, 2), numba.types.boolean)
    compile_all([[job]])
    made = compiled(job)
    compile_all([[job], [job]])
    assert compiled(job) is made
    assert function_pointers._ready(job)


def test_a_file_system_that_does_not_lock_leaves_the_index_unlocked(tmp_path, monkeypatch):
    import fcntl

    def refuse(fd, op):
        raise OSError(37, "No locks available")

    monkeypatch.setattr(fcntl, "flock", refuse)
    with cache.index_lock(str(tmp_path / "f.nbi"), exclusive=True):
        pass  # no error: numba's own, unlocked behaviour


def test_more_groups_than_the_queue_holds_are_compiled_here(monkeypatch):
    a = np.array([[4.0, 1.0], [1.0, 3.0]])
    job = compile_of(linalg.cholesky, (a, a, 2), numba.types.boolean)
    made = compiled(job)
    forks = []
    monkeypatch.setattr(function_pointers, "processes", lambda: 2)
    monkeypatch.setattr(function_pointers, "_ready", lambda j: False)
    monkeypatch.setattr(os, "fork", lambda: forks.append(1) or 0)
    compile_all([[job]] * 257)  # one byte a group number: 257 do not fit
    assert not forks
    assert compiled(job) is made


def test_registered_workers_are_ended_only_for_a_compile_worth_a_child(monkeypatch):
    import threading
    from concurrent.futures import ThreadPoolExecutor

    class Owner:
        def __init__(self):
            self.pool = ThreadPoolExecutor(1)
            self.pool.submit(int).result()  # its thread runs
            self.ended = 0

        def end_worker(self):
            self.pool.shutdown(wait=True)
            self.ended += 1

    owner = Owner()
    function_pointers.register_thread_owner(owner)
    left = {"a": True, "b": True}
    monkeypatch.setattr(function_pointers, "_ready", lambda job: left[job])
    monkeypatch.setattr(function_pointers, "compiled", lambda job: None)
    monkeypatch.setattr(function_pointers, "processes", lambda: 1)
    try:
        compile_all([["a"], ["b"]])  # nothing left to compile
        left["a"] = False
        compile_all([["a"], ["b"]])  # one group left: compiled here, no child
        assert owner.ended == 0
        left["b"] = False
        threads = threading.active_count()
        compile_all([["a"], ["b"]])
        assert owner.ended == 1 and threading.active_count() == threads - 1
    finally:
        owner.pool.shutdown(wait=True)


def test_groups_ride_with_the_next_compile_and_warm_ups_run_only_where_groups_are_taken(
        monkeypatch):
    ran = []

    def fails():
        ran.append("fails")
        raise RuntimeError("a warm-up's error is dropped")

    warm = (function_pointers.WarmUp(lambda: ran.append("warm")),
            function_pointers.WarmUp(fails))
    taken = []
    monkeypatch.setattr(function_pointers, "compiled", taken.append)
    monkeypatch.setattr(function_pointers, "processes", lambda: 1)
    function_pointers.compile_with_next(["rider"])
    function_pointers.compile_with_next(warm)
    gone = ("forgotten",)
    function_pointers.compile_with_next(gone)
    function_pointers.forget(gone)
    compile_all([["a"]])  # one process: everything here, in order; no warm-up runs
    assert taken == ["a", "rider"] and ran == []
    compile_all([["b"]])  # the riders went with the first call
    assert taken == ["a", "rider", "b"]
    read, write = os.pipe()  # the queue a forking compile_all's processes read
    os.write(write, bytes([1, 0]))
    os.close(write)
    try:
        function_pointers._work(read, [["c"], warm])
    finally:
        os.close(read)
    assert ran == ["warm", "fails"] and taken[-1] == "c"


def test_riders_are_taken_after_the_first_group_of_each_process():
    # the groups come largest first; a rider (a warm-up of a few seconds) goes ahead of the
    # small ones that end the compile, not last where the other processes would wait for it
    own = [["big"], ["loop"], ["mid"], ["small"]]
    rider = ("warm",)
    order = function_pointers._queue_order(own, [rider], 2)
    assert order == [["big"], ["loop"], rider, ["mid"], ["small"]]
    assert function_pointers._queue_order(own, [rider], 1)[:2] == [["big"], rider]
    assert function_pointers._queue_order(own[:1], [rider], 4) == [["big"], rider]
    # an own group equal to a rider is still the caller's
    twin = ["warm"]
    assert function_pointers._queue_order([twin], [rider], 1) == [twin, rider]


def test_a_compile_leaves_the_owners_and_riders_of_other_threads_alone(monkeypatch):
    # a run in another thread may be using its worker and expects its riders with its own
    # compile: neither is this thread's to end or to take
    import threading

    class Owner:
        ended = 0

        def end_worker(self):
            self.ended += 1

    owner, rider = Owner(), ["theirs"]
    registered = threading.Event()
    done = threading.Event()

    def other_run():
        function_pointers.register_thread_owner(owner)
        function_pointers.compile_with_next(rider)
        registered.set()
        done.wait(20.0)
        function_pointers.forget(rider)

    other = threading.Thread(target=other_run)
    other.start()
    try:
        assert registered.wait(20.0)
        taken = []
        monkeypatch.setattr(function_pointers, "_ready", lambda job: False)
        monkeypatch.setattr(function_pointers, "compiled", taken.append)
        monkeypatch.setattr(function_pointers, "processes", lambda: 1)
        compile_all([["a"], ["b"]])
        assert owner.ended == 0 and taken == ["a", "b"]
    finally:
        done.set()
        other.join()
