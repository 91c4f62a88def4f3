"""numba's on-disk cache of the kernels, made safe against edits of the kernels they call.

numba keeps a compiled kernel (``cache=True``) in an index stamped with its own source file
only. A kernel that calls kernels of other files (the compiled loop calls nearly all
of them) is compiled with their code inside, so after an edit of a callee, or of the layout
constants it reads, the caller's cache entry stays "fresh" and runs the old code: wrong
numbers, silently (seen here: a table layout changed under a cached caller). This module
stamps every kernel's cache entry with one digest of the contents of all the kernel source
files (:data:`KERNEL_FILES`) instead, so any edit of any of them recompiles every kernel once,
whichever cache folder numba uses (``NUMBA_CACHE_DIR``, ``__pycache__``, or the user-wide one
when the package folder is read-only). Content, not
modification time, so a fresh checkout with the same sources reuses a cache.

It plugs into numba's cache locators (``numba.core.caching``: the classes numba tries in turn
to place a function's cache), the extension point numba has for this; on a numba without that
point it does nothing and numba's own stamps apply.

It also makes the cache safe for several processes at once (the kernels are compiled in
child processes, :func:`~multiarm_pin._compiled.function_pointers.compile_all`, and a study
runs in several). numba saves an entry by reading a function's index, choosing the first
data file name the index does not use, writing the index, then the data: two processes that
save two signatures of one function at once choose the same name, and the index can then
point a signature at the other's code. Every index's reads and saves here hold a lock on a
file beside it (``fcntl.flock``: shared to load, exclusive to save). And two processes that
need one compile at once make it once (:func:`compile_lock`).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent
"""The ``multiarm_pin`` package folder."""

KERNEL_FILES = tuple(sorted(
    p.relative_to(PACKAGE).as_posix() for p in (PACKAGE / "_compiled").glob("*.py")))
"""Package-relative paths of every file that defines or feeds compiled kernels: the
``_compiled`` package (a test checks that no other file of the package uses numba)."""

_digest: str | None = None


def kernel_sources_digest() -> str:
    """SHA-256 of the names and contents of :data:`KERNEL_FILES` (computed once per process)."""
    global _digest
    if _digest is None:
        h = hashlib.sha256()
        for rel in KERNEL_FILES:
            h.update(rel.encode())
            h.update(b"\0")
            h.update((PACKAGE / rel).read_bytes())
            h.update(b"\0")
        _digest = h.hexdigest()
    return _digest


def is_kernel_file(py_file: str) -> bool:
    """True if ``py_file`` is one of :data:`KERNEL_FILES`."""
    try:
        rel = Path(py_file).resolve().relative_to(PACKAGE).as_posix()
    except (ValueError, OSError):
        return False
    return rel in KERNEL_FILES


def install() -> bool:
    """Put the kernels' locators first in numba's list (once); False if numba has no such list.

    Must run before the kernels are decorated (``multiarm_pin._compiled`` runs it on import).
    """
    try:
        from numba.core import caching
    except ImportError:  # pragma: no cover - numba is a dependency
        return False
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    bases = [getattr(caching, name, None) or getattr(caching, "_" + name, None)
             for name in ("UserProvidedCacheLocator", "InTreeCacheLocator",
                          "UserWideCacheLocator")]
    classes = getattr(impl, "_locator_classes", None)
    if not isinstance(classes, list) or None in bases:  # pragma: no cover - other numba
        return False
    if any(getattr(c, "_multiarm_pin", False) for c in classes):
        return True
    mine = [type(f"Kernel{base.__name__.lstrip('_')}", (_KernelStamp, base),
                 {"_multiarm_pin": True}) for base in bases]
    classes[:0] = mine
    _lock_index_files(getattr(caching, "IndexDataCacheFile", None))
    return True


@contextlib.contextmanager
def index_lock(index_path: str, exclusive: bool):
    """Hold a lock on the file ``index_path + ".lock"`` (shared, or ``exclusive``).

    Without ``fcntl`` (not POSIX), when the lock file cannot be made (no cache folder yet:
    then there is nothing to read), or where the file system does not lock (some network
    file systems refuse ``flock``), no lock is held: numba's own behaviour.
    """
    with _file_lock(index_path + ".lock", exclusive):
        yield


def index_key(cache, signature):
    """The key of ``signature``'s entry in the index of ``cache`` (a numba function cache).

    numba's own key (``_index_key``: the signature, the code generation's target, hashes of
    the function's bytecode and closure): what a compile in this process saves or loads.
    Raises what numba's cache internals raise for an object that is not such a cache.
    """
    from numba.core.registry import cpu_target

    return cache._index_key(signature, cpu_target.target_context.codegen())


@contextlib.contextmanager
def compile_lock(cache, signature):
    """Hold an exclusive lock on one signature's compile in ``cache``'s folder.

    Two processes that need the same kernel compiled for the same signature at once (two runs
    started together, a study's workers, on a cache without it) would each compile it: the
    second to take this lock finds it in the cache instead, since numba's compile looks there
    first.
    One lock file per signature, beside the function's index (``<index>.<key digest>.compile``);
    compiles of other signatures are not held up. No lock where :func:`index_lock` would hold
    none, or where the cache's paths are not known (another numba).

    Args:
        cache: the function's numba cache (``dispatcher._cache``, or a ``FunctionCache``).
        signature: what numba keys the entry by (a dispatcher's argument types; a ``cfunc``'s
            signature).
    """
    path = None
    try:
        key = index_key(cache, signature)
        cache._impl.locator.ensure_cache_path()
        digest = hashlib.sha256(repr(key).encode()).hexdigest()[:16]
        path = f"{cache._cache_file._index_path}.{digest}.compile"
    except Exception:  # noqa: BLE001, S110 - numba's cache internals, or no writable folder
        pass
    if path is None:
        yield
        return
    with _file_lock(path, exclusive=True):
        yield


@contextlib.contextmanager
def _file_lock(path: str, exclusive: bool):
    """Hold an ``flock`` on the file ``path`` (made if missing); none where it cannot be had."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        except OSError:
            pass  # not lockable here: as numba does without the lock
        yield
    finally:
        os.close(fd)  # closing the file releases the lock


def _lock_index_files(index_file) -> None:
    """Make ``IndexDataCacheFile.save`` and ``.load`` hold :func:`index_lock` (once)."""
    if index_file is None or getattr(index_file, "_multiarm_pin", False):
        return  # pragma: no cover - another numba; or installed already
    save, load = index_file.save, index_file.load

    def locked_save(self, key, data):
        with index_lock(self._index_path, exclusive=True):
            return save(self, key, data)

    def locked_load(self, key):
        with index_lock(self._index_path, exclusive=False):
            return load(self, key)

    index_file.save, index_file.load = locked_save, locked_load
    index_file._multiarm_pin = True


class _KernelStamp:
    """Locator mixin: only for kernel files, stamped with :func:`kernel_sources_digest`."""

    def get_source_stamp(self):
        """The digest of all the kernel sources (numba compares it with the index's)."""
        return kernel_sources_digest()

    @classmethod
    def from_function(cls, py_func, py_file):
        """The locator of a kernel, or None for any other function (numba tries the next)."""
        if not is_kernel_file(py_file):
            return None
        return super().from_function(py_func, py_file)


__all__ = ["KERNEL_FILES", "compile_lock", "index_key", "index_lock", "install",
           "is_kernel_file", "kernel_sources_digest"]
