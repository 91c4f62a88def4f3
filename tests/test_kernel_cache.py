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

from numba.core import caching

from multiarm_pin._compiled import cache, linalg

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
