"""Results folders written safely: one run at a time, atomic publication, nothing lost.

A run writes everything into a staging folder and publishes it when it is complete, so a
reader (or an interrupted writer) sees either the old results or the new ones, and stale
files of an older run never survive beside new data. Two ways to publish, chosen before
anything is simulated (:class:`ResultsWriter`):

- **beside** (the usual case): the staging folder is ``<parent>/.<name>.tmp-XXXX`` and is
  renamed into place (the old folder, if any, renamed away first and removed after), so
  the folder is replaced whole;
- **in place**, when the target is a mount point (a container volume: it cannot be renamed
  over, ``EBUSY``) or an existing folder whose parent is not writable: the staging folder
  is ``<target>/.multiarm-pin.tmp-XXXX``, on the target's own file system, and each file is
  moved into the target by a rename (atomic per file), after which the old run's other
  files are removed and the marker is written last. The run says so on stderr.

A target that cannot take the results (a read-only mount point, a parent that cannot be
written) is refused before the simulation by creating the staging folder. If the final
move still fails, the staging folder is kept and :class:`ResultsNotMovedError` names it.

**One run at a time per results folder**: :class:`RunLock` takes an ``fcntl`` lock on
``<parent>/.<name>.lock`` (``<target>/.multiarm-pin.lock`` in place) before the folder is
checked, held until the results are published, and removed after; a second run into the
same folder, of any scenario, is refused with the first one's pid and scenario file.

Rules applied by :func:`prepare_output` (under the lock, before the simulation):

- ``--out`` naming an existing file, or a folder that holds the scenario file itself (or
  any other file that is not a results folder of ours), is refused;
- a results folder of a *different* run (another scenario file) is refused unless
  ``overwrite`` is given; a folder of the same scenario file is replaced (rerunning a
  scenario updates its results);
- the parent folder must be writable (or, in place, the target itself).

A results folder is recognised by its marker file :data:`MARKER` (written by every run)
or, for folders written before the marker existed, by a ``summary.json`` with a
``scenario_file`` entry.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
import secrets
import shutil
import signal
import tempfile
import threading
import time
from pathlib import Path

from multiarm_pin.exceptions import OutputError, ResultsNotMovedError

MARKER = ".multiarm-pin-run"
"""Marker file of a results folder; holds the scenario file's absolute path (one line)."""
LOCK_NAME = ".multiarm-pin.lock"
"""The lock file inside a results folder written in place (beside it: ``.<name>.lock``)."""
STAGING_PREFIX = ".multiarm-pin.tmp-"
"""Name prefix of the staging folder inside a results folder written in place."""

_SAFE = re.compile(r"[^A-Za-z0-9._+-]+")


def safe_component(name: str, default: str = "run") -> str:
    """``name`` made into one harmless path component.

    Anything but letters, digits, ``. _ + -`` becomes ``_``; leading dots are removed (no
    hidden folders, no ``.``/``..``); an empty result gives ``default``.

    Args:
        name: a name from a scenario (e.g. its ``name:``).
        default: used when nothing is left.

    Returns:
        A non-empty string without path separators, not starting with a dot, at most 100
        characters.
    """
    s = _SAFE.sub("_", str(name)).strip("._")[:100].strip("._") or default
    return s


def _own_entry(name: str) -> bool:
    """An entry that a run writing in place keeps in the folder (its lock, staging folders)."""
    return name == LOCK_NAME or name.startswith(STAGING_PREFIX)


def run_identity(out_dir: Path) -> str | None:
    """The scenario file a results folder was written from, or None if not a results folder.

    Args:
        out_dir: an existing folder.
    """
    marker = out_dir / MARKER
    if marker.is_file():
        try:
            return marker.read_text(encoding="utf-8").strip()
        except (OSError, UnicodeDecodeError):
            return ""
    summary = out_dir / "summary.json"
    if summary.is_file():
        try:
            data = json.loads(summary.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        if isinstance(data, dict) and isinstance(data.get("scenario_file"), str):
            return data["scenario_file"]
    return None


def _unescape_mountinfo(field: str) -> str:
    return re.sub(r"\\([0-7]{3})", lambda m: chr(int(m.group(1), 8)), field)


def mount_points() -> set[str]:
    """The mount points of this process's mount namespace (``/proc/self/mountinfo``).

    Returns:
        Absolute paths; empty where ``/proc`` is not there (then only
        :func:`os.path.ismount` is used).
    """
    try:
        with open("/proc/self/mountinfo", encoding="utf-8", errors="replace") as f:
            return {_unescape_mountinfo(line.split(" ")[4]) for line in f if line.count(" ") > 4}
    except OSError:
        return set()


def is_mount_point(path: Path) -> bool:
    """Whether ``path`` is a mount point, bind mounts of a folder of the same file system too.

    :func:`os.path.ismount` compares devices and inodes with the parent, which misses a
    bind mount of a folder of the parent's own file system; the mount table does not.
    """
    path = Path(path)
    if os.path.ismount(path):
        return True
    return os.path.realpath(path) in mount_points()


def _read_only(path: Path) -> bool:
    try:
        return bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def publishes_in_place(target: Path) -> bool:
    """Whether the results go into ``target`` file by file instead of by renaming it.

    True for an existing folder that is a mount point, or whose parent cannot be written
    while it can.
    """
    target = Path(target)
    if not target.is_dir():
        return False
    if is_mount_point(target):
        return True
    return not os.access(target.parent, os.W_OK | os.X_OK) and \
        os.access(target, os.W_OK | os.X_OK)


def prepare_output(out: str | os.PathLike, scenario_file: str | os.PathLike,
                   overwrite: bool = False, option: str = "--out") -> Path:
    """Check a results folder target before a run; returns its absolute path.

    Args:
        out: the target folder.
        scenario_file: the scenario file of the run (never written over).
        overwrite: replace a results folder of a different run.
        option: the option name for messages.

    Raises:
        OutputError: the target is a file, holds the scenario file or non-result files,
            holds results of another run (without ``overwrite``), or its parent cannot be
            created or written (names the path and the reason).
    """
    target = Path(os.path.abspath(out))
    scenario = Path(os.path.abspath(scenario_file))
    if target.exists() and not target.is_dir():
        raise OutputError(f"{option} {target}: is an existing file; expected a folder for the "
                          "results (give a new or a results folder)")
    if scenario == target or target in scenario.parents:
        raise OutputError(f"{option} {target}: holds the scenario file {scenario}; results "
                          "replace their folder whole, give a folder of its own (e.g. "
                          f"results/{safe_component(scenario.stem)})")
    if target.is_dir():
        try:
            entries = [p for p in target.iterdir() if not _own_entry(p.name)]
        except OSError as exc:
            raise OutputError(f"{option} {target}: cannot be read: "
                              f"{exc.strerror or exc}") from exc
        if entries:
            ident = run_identity(target)
            if ident is None:
                names = ", ".join(sorted(p.name for p in entries)[:5])
                raise OutputError(f"{option} {target}: is a folder that is not a results folder "
                                  f"of multiarm-pin (it holds {names}...); give a new folder, "
                                  "results are written as a whole folder")
            if ident != str(scenario) and not overwrite:
                raise OutputError(f"{option} {target}: holds the results of another run "
                                  f"({ident or 'unknown scenario'}); give --overwrite to "
                                  "replace them, or another folder")
    parent = target.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{option} {target}: cannot create the folder {parent}: "
                          f"{exc.strerror or exc}") from exc
    if not publishes_in_place(target) and not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{option} {target}: the folder {parent} is not writable")
    return target


class RunLock:
    """An exclusive ``fcntl.flock`` on a lock file: one run at a time per results folder.

    The file holds the holder's pid, scenario file and start time (one JSON line), which a
    refused run prints. It is removed on release; a run that opened it just before checks
    after locking that it still is the file at that path, and retries otherwise.

    Args:
        path: the lock file.
        target: the results folder it guards (for messages).
        scenario_file: the scenario file of this run (written into the lock file).
        option: the option name for messages.
    """

    def __init__(self, path: Path, target: Path, scenario_file: str | os.PathLike,
                 option: str = "--out"):
        self.path, self.target, self.option = Path(path), Path(target), option
        self.scenario_file = os.path.abspath(scenario_file)
        self.fd: int | None = None

    def acquire(self) -> None:
        """Take the lock (at once, never waiting).

        Raises:
            OutputError: another run holds it (names its pid and scenario file), or the lock
                file cannot be created.
        """
        for _ in range(100):
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise OutputError(f"{self.option} {self.target}: cannot create the lock file "
                                  f"{self.path}: {exc.strerror or exc}") from exc
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                os.close(fd)
                raise OutputError(f"{self.option} {self.target}: another run is writing into "
                                  f"this folder ({self.holder()}); wait for it to end, or give "
                                  "another folder") from None
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except FileNotFoundError:
                same = False
            if same:
                os.ftruncate(fd, 0)
                os.write(fd, (json.dumps({
                    "pid": os.getpid(), "scenario_file": self.scenario_file,
                    "started": time.strftime("%Y-%m-%d %H:%M:%S UTC", time.gmtime())}) + "\n"
                ).encode("utf-8"))
                self.fd = fd
                return
            os.close(fd)  # the holder removed it while we opened it: open the new one
        raise OutputError(f"{self.option} {self.target}: cannot take the lock {self.path}")

    def holder(self, wait: float = 2.0) -> str:
        """``pid N, scenario FILE, since TIME`` of the run holding the lock (read from its file).

        Args:
            wait: seconds to wait for the holder to write it (it does right after locking).
        """
        end = time.monotonic() + wait
        while True:
            try:
                info = json.loads(self.path.read_text(encoding="utf-8"))
                return (f"pid {info['pid']}, scenario {info['scenario_file']}, since "
                        f"{info['started']}")
            except (OSError, ValueError, KeyError, TypeError):
                if time.monotonic() > end:
                    return f"its lock file {self.path} does not say which"
                time.sleep(0.05)

    def release(self) -> None:
        """Remove the lock file and drop the lock."""
        if self.fd is None:
            return
        with contextlib.suppress(OSError):
            os.unlink(self.path)
        os.close(self.fd)
        self.fd = None


def folder_lock(target: Path, ident: str | os.PathLike, option: str = "--out") -> RunLock:
    """The :class:`RunLock` that guards a results folder (not yet taken).

    Its file is ``TARGET/.multiarm-pin.lock`` for a mount point (written in place), else
    ``.NAME.lock`` beside the folder, so that it exists before the folder does and outlives a
    rename of the folder. Every writer of results folders (a run, a sweep) takes this one lock,
    so two of them never write one folder at once.

    Args:
        target: the results folder.
        ident: what is written into the folder (a scenario or study file), named to a refused
            run.
        option: the option name for messages.
    """
    target = Path(target)
    lock_file = (target / LOCK_NAME if publishes_in_place(target)
                 else target.parent / f".{target.name}.lock")
    return RunLock(lock_file, target, ident, option)


class ResultsWriter:
    """Writes a results folder: lock, checks, staging, atomic publication (a context manager).

    Usage::

        with ResultsWriter(target, scenario_file) as w:   # lock, check, create the staging
            (w.path / "trajectory.npz").write_bytes(...)  # write everything into w.path
            w.publish()                                   # move it into place
        # leaving without publish() removes the staging folder; the target is untouched

    Entering takes the :class:`RunLock`, applies :func:`prepare_output`, and creates the
    staging folder (which proves the target can take the results), all before anything is
    simulated; leaving releases the lock.

    Args:
        target: the results folder.
        scenario_file: the scenario file of the run.
        overwrite: replace a results folder of another scenario file.
        option: the option name for messages.

    Attributes:
        target: the final folder (absolute).
        path: the staging folder being written.
        in_place: the results are moved into ``target`` file by file (see the module
            docstring), not by renaming the folder.
        published: :meth:`publish` succeeded.
        kept: the staging folder kept after a failed move (None otherwise).
    """

    def __init__(self, target: Path, scenario_file: str | os.PathLike, overwrite: bool = False,
                 option: str = "--out"):
        parent = Path(os.path.realpath(Path(os.path.abspath(target)).parent))
        self.target = parent / Path(os.path.abspath(target)).name
        self.scenario_file = os.path.abspath(scenario_file)
        self.overwrite, self.option = overwrite, option
        self.path: Path | None = None
        self.in_place = False
        self.published = False
        self.kept: Path | None = None
        self.lock: RunLock | None = None

    def __enter__(self) -> ResultsWriter:
        """Lock the folder, check it, create the staging folder (raises OutputError)."""
        self.in_place = publishes_in_place(self.target)
        parent = self.target.parent
        if self.in_place and not os.access(self.target, os.W_OK | os.X_OK):
            why = "a read-only file system" if _read_only(self.target) else "not writable"
            raise OutputError(f"{self.option} {self.target}: is a mount point on {why}: the "
                              "results could not be written there; give a writable folder")
        if (self.target.exists() and not self.target.is_dir()) or not self.in_place and not (
                parent.is_dir() and os.access(parent, os.W_OK | os.X_OK)):
            # no lock file can go there: raises its message (or creates the parent)
            prepare_output(self.target, self.scenario_file, self.overwrite, self.option)
        self.lock = folder_lock(self.target, self.scenario_file, self.option)
        self.lock.acquire()
        try:
            # under the lock: no other run can write the folder between this check and ours
            prepare_output(self.target, self.scenario_file, self.overwrite, self.option)
            where = self.target if self.in_place else self.target.parent
            prefix = STAGING_PREFIX if self.in_place else f".{self.target.name}.tmp-"
            try:
                self.path = Path(tempfile.mkdtemp(prefix=prefix, dir=where))
                os.chmod(self.path, 0o777 & ~_umask())  # the mode of a folder made by mkdir
            except OSError as exc:
                what = "the mount point " if self.in_place else ""
                raise OutputError(f"{self.option} {self.target}: cannot write in {what}{where}: "
                                  f"{exc.strerror or exc}") from exc
        except BaseException:
            self.lock.release()
            raise
        return self

    def __exit__(self, *exc) -> None:
        """Remove the staging folder unless published or kept; release the lock."""
        try:
            if not self.published and self.kept is None and self.path is not None:
                shutil.rmtree(self.path, ignore_errors=True)
        finally:
            if self.lock is not None:
                self.lock.release()

    def publish(self) -> Path:
        """Mark the staging folder as a run of the scenario and move it into place.

        SIGINT and SIGTERM are held back while it moves, so the target holds either the
        old results or the new ones.

        Returns:
            The target folder.

        Raises:
            ResultsNotMovedError: the move failed; the results stay in the staging folder
                (``kept``), the target is as it was (beside) or partly updated (in place).
        """
        assert self.path is not None, "publish() outside the with block"
        (self.path / MARKER).write_text(self.scenario_file + "\n", encoding="utf-8")
        with deferred_signals():
            try:
                old = self._publish_in_place() if self.in_place else self._publish_beside()
            except OSError as exc:
                self.kept = self.path
                raise ResultsNotMovedError(
                    f"{self.option} {self.target}: cannot move the results into place: "
                    f"{exc.strerror or exc}; they are kept in {self.path}", self.path) from exc
            self.published = True
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        return self.target

    def _publish_beside(self) -> Path | None:
        """Rename the old folder away and the staging folder into place; returns the old."""
        old = None
        if self.target.exists():
            while old is None or old.exists():
                old = self.target.parent / f".{self.target.name}.old-{secrets.token_hex(4)}"
            os.rename(self.target, old)
        try:
            os.rename(self.path, self.target)
        except OSError:
            if old is not None:
                os.rename(old, self.target)
            raise
        return old

    def _publish_in_place(self) -> None:
        """Move each staged file into the target, remove the old run's others, marker last."""
        new = sorted(p.name for p in self.path.iterdir() if p.name != MARKER)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.target / MARKER)  # the folder claims no run while it changes
        for name in new:
            dst = self.target / name
            if dst.is_dir() and not dst.is_symlink():
                shutil.rmtree(dst)
            os.replace(self.path / name, dst)
        keep = {*new, MARKER, LOCK_NAME, self.path.name}
        for p in list(self.target.iterdir()):
            if p.name not in keep:
                if p.is_dir() and not p.is_symlink():
                    shutil.rmtree(p, ignore_errors=True)
                else:
                    with contextlib.suppress(OSError):
                        p.unlink()
        os.replace(self.path / MARKER, self.target / MARKER)
        os.rmdir(self.path)
        return None


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_atomic(path: Path, data: bytes) -> None:
    """Write a file through a temporary name and a rename (readers never see a partial file).

    Args:
        path: the file.
        data: its content.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.tmp-", dir=path.parent)
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # the mode of a file opened the usual way
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def deferred_signals(signums=(signal.SIGINT, signal.SIGTERM), deliver: bool = True):
    """Hold SIGINT/SIGTERM back inside the block and deliver them when it ends.

    Only in the main thread (elsewhere signals cannot be handled and the block just runs).

    Args:
        signums: the signals held back.
        deliver: send the first held signal to this process when the block ends; False
            leaves it to the caller.

    Yields:
        The list of signals received inside the block (filled as they arrive).
    """
    received: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return
    previous = {}
    for s in signums:
        previous[s] = signal.signal(s, lambda signum, frame: received.append(signum))
    try:
        yield received
    finally:
        for s, h in previous.items():
            signal.signal(s, signal.SIG_DFL if h is None else h)
        if deliver:
            for s in received[:1]:
                os.kill(os.getpid(), s)


__all__ = [
    "LOCK_NAME",
    "MARKER",
    "STAGING_PREFIX",
    "ResultsWriter",
    "RunLock",
    "folder_lock",
    "deferred_signals",
    "is_mount_point",
    "mount_points",
    "prepare_output",
    "publishes_in_place",
    "run_identity",
    "safe_component",
    "write_atomic",
]
