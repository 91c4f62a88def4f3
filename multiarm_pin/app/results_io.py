"""Results folders written safely: atomic publication, no overwritten input, no mixed runs.

A run writes everything into a fresh temporary folder beside its target
(``<parent>/.<name>.tmp-XXXX``) and renames it into place only when it is complete, so a
reader (or an interrupted writer) sees either the old folder untouched or the new one
whole; stale files of an older run never survive beside new data.

Rules applied by :func:`prepare_output` before the simulation starts:

- ``--out`` naming an existing file, or a folder that holds the scenario file itself (or
  any other file that is not a results folder of ours), is refused;
- a results folder of a *different* run (another scenario file) is refused unless
  ``overwrite`` is given; a folder of the same scenario file is replaced (rerunning a
  scenario updates its results);
- the parent folder must be writable: the temporary folder is created there at once.

A results folder is recognised by its marker file :data:`MARKER` (written by every run)
or, for folders written before the marker existed, by a ``summary.json`` with a
``scenario_file`` entry.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import signal
import tempfile
import threading
from pathlib import Path

from multiarm_pin.exceptions import OutputError

MARKER = ".multiarm-pin-run"
"""Marker file of a results folder; holds the scenario file's absolute path (one line)."""

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
            entries = list(target.iterdir())
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
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{option} {target}: the folder {parent} is not writable")
    return target


class ResultsWriter:
    """Writes a results folder atomically (a context manager).

    Usage::

        with ResultsWriter(target, scenario_file) as w:   # creates the temporary folder
            (w.path / "trajectory.npz").write_bytes(...)  # write everything into w.path
            w.publish()                                   # rename into place
        # leaving without publish() removes the temporary folder; the target is untouched

    Attributes:
        target: the final folder (absolute).
        path: the temporary folder being written.
    """

    def __init__(self, target: Path, scenario_file: str | os.PathLike):
        self.target = Path(target)
        self.scenario_file = os.path.abspath(scenario_file)
        self.path: Path | None = None
        self.published = False

    def __enter__(self) -> ResultsWriter:
        """Create the temporary folder beside the target (checks it can be written)."""
        try:
            self.path = Path(tempfile.mkdtemp(prefix=f".{self.target.name}.tmp-",
                                              dir=self.target.parent))
        except OSError as exc:
            raise OutputError(f"--out {self.target}: cannot write in {self.target.parent}: "
                              f"{exc.strerror or exc}") from exc
        return self

    def __exit__(self, *exc) -> None:
        """Remove the temporary folder unless it was published."""
        if not self.published and self.path is not None:
            shutil.rmtree(self.path, ignore_errors=True)

    def publish(self) -> Path:
        """Mark the folder as a run of the scenario and rename it into place.

        SIGINT and SIGTERM are held back during the swap (two renames), so the target is
        either the old folder or the new one.

        Returns:
            The target folder.
        """
        assert self.path is not None, "publish() outside the with block"
        (self.path / MARKER).write_text(self.scenario_file + "\n", encoding="utf-8")
        with deferred_signals():
            old = None
            if self.target.exists():
                old = Path(tempfile.mkdtemp(prefix=f".{self.target.name}.old-",
                                            dir=self.target.parent))
                os.rename(self.target, old / "previous")
            os.rename(self.path, self.target)
            self.published = True
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        return self.target


def write_atomic(path: Path, data: bytes) -> None:
    """Write a file through a temporary name and a rename (readers never see a partial file).

    Args:
        path: the file.
        data: its content.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.tmp-", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def deferred_signals(signums=(signal.SIGINT, signal.SIGTERM)):
    """Hold SIGINT/SIGTERM back inside the block and deliver them when it ends.

    Only in the main thread (elsewhere signals cannot be handled and the block just runs).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    received: list[int] = []
    previous = {}
    for s in signums:
        previous[s] = signal.signal(s, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        for s, h in previous.items():
            signal.signal(s, signal.SIG_DFL if h is None else h)
        for s in received[:1]:
            os.kill(os.getpid(), s)


__all__ = [
    "MARKER",
    "ResultsWriter",
    "deferred_signals",
    "prepare_output",
    "run_identity",
    "safe_component",
    "write_atomic",
]
