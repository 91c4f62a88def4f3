"""The kernels' on-disk cache (``_compiled/cache.py``): stamped with every kernel source, so
that editing one kernel file recompiles the cached kernels of the others (numba alone would
keep a caller compiled with the old callee)."""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from numba.core import caching

from multiarm_pin._compiled import cache, linalg
from multiarm_pin._compiled.jit import jit_disabled

PACKAGE = Path(cache.__file__).resolve().parent.parent


def imports_numba(path: Path) -> bool:
    """True if the module imports numba (anywhere in it)."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                 else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
        if any(n.split(".")[0] == "numba" for n in names):
            return True
    return False


def test_every_file_that_uses_numba_is_stamped():
    uses = {p.relative_to(PACKAGE).as_posix() for p in PACKAGE.rglob("*.py")
            if imports_numba(p) and "__pycache__" not in p.parts}
    stamped = set(cache.KERNEL_FILES)
    assert uses <= stamped, uses - stamped
    assert {f for f in uses if not f.startswith("_compiled/")} == set()  # one compiled layer
    assert all((PACKAGE / f).exists() for f in stamped)


def test_kernels_use_the_digest_stamp():
    assert cache.install()  # idempotent
    impl = getattr(caching, "CacheImpl", None) or caching._CacheImpl
    assert sum(getattr(c, "_multiarm_pin", False) for c in impl._locator_classes) == 3
    locator = linalg.cholesky._cache._impl.locator
    assert locator.get_source_stamp() == cache.kernel_sources_digest()
    assert not cache.is_kernel_file(__file__)


PROBE = """
import json, sys
import numpy as np
from multiarm_pin._compiled import linalg
A = np.array([[4.0, 1.0], [1.0, 3.0]])
L = np.zeros((2, 2))
assert linalg.cholesky(A, L, np.int64(2))
st = linalg.cholesky.stats
print(json.dumps({"hits": sum(st.cache_hits.values()), "misses": sum(st.cache_misses.values()),
                  "file": linalg.__file__}))
"""


def probe(root: Path, cache_dir: Path) -> dict:
    import json

    env = dict(os.environ, PYTHONPATH=str(root), NUMBA_CACHE_DIR=str(cache_dir))
    env.pop("NUMBA_DISABLE_JIT", None)
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True,
                         text=True, check=True, cwd=root)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_editing_another_kernel_file_recompiles(tmp_path):
    """A copy of the package: compile, reuse, then edit a *different* kernel file."""
    root = tmp_path / "src"
    shutil.copytree(PACKAGE, root / "multiarm_pin",
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    cache_dir = tmp_path / "numba_cache"
    first = probe(root, cache_dir)
    assert Path(first["file"]).resolve().is_relative_to(root.resolve())
    assert first["misses"] == 1 and first["hits"] == 0
    assert probe(root, cache_dir)["hits"] == 1  # unchanged sources: loaded from the cache
    other = root / "multiarm_pin" / "_compiled" / "trajectory.py"
    other.write_text(other.read_text(encoding="utf-8") + "\n# edited\n", encoding="utf-8")
    again = probe(root, cache_dir)
    assert again["misses"] == 1 and again["hits"] == 0  # recompiled, though linalg.py is as it was


@pytest.mark.skipif(jit_disabled(), reason="numba's cache of a compiled kernel")
def test_a_compile_lock_holds_one_signature_and_not_the_others():
    # flock: two holders in one process (two open files) exclude each other, as two processes
    import threading

    from numba import types

    c = linalg.cholesky._cache
    one, other = (types.float64[:, ::1], types.int64), (types.float64[:, :], types.int64)
    order = []
    held, done = threading.Event(), threading.Event()

    def holder():
        with cache.compile_lock(c, one):
            held.set()
            order.append(("other taken meanwhile", done.wait(20.0)))
            order.append("released")

    thread = threading.Thread(target=holder)
    thread.start()
    assert held.wait(20.0)
    with cache.compile_lock(c, other):  # another signature: not held up
        done.set()
    with cache.compile_lock(c, one):  # the same one: once the holder has let go
        order.append("taken")
    thread.join()
    assert order == [("other taken meanwhile", True), "released", "taken"]
    with cache.compile_lock(object(), one):  # no numba cache behind it: no lock, no error
        order.append("unlocked")
    assert order[-1] == "unlocked"


@pytest.mark.skipif(jit_disabled(), reason="nothing is compiled without the JIT")
def test_compiled_holds_the_compile_lock_only_to_compile(monkeypatch):
    import contextlib

    import numpy as np
    from numba import types

    from multiarm_pin._compiled import function_pointers

    taken = []

    @contextlib.contextmanager
    def recording(c, signature):
        taken.append((c._py_func, signature))
        yield

    monkeypatch.setattr(function_pointers, "compile_lock", recording)
    # types no other test compiles copy2 for: float32, the source a strided view
    a, b = np.zeros((2, 3), np.float32), np.ones((2, 6), np.float32)[:, ::2]
    entry = function_pointers.compile_of(linalg.copy2, (a, b))
    assert entry.types not in linalg.copy2.overloads
    first = function_pointers.compiled(entry)
    function_pointers.compiled(entry)  # made: no lock
    cfunc = function_pointers.compile_of(linalg.copy2, (a, b), types.none)
    function_pointers.compiled(cfunc)
    function_pointers.compiled(cfunc)
    assert taken == [(linalg.copy2.py_func, entry.types),
                     (linalg.copy2.py_func, types.none(*entry.types))]
    first(a, b)
    assert (a == 1).all()
