"""Shared helpers of the run/CLI tests: small scenario files and a CLI subprocess."""

from __future__ import annotations

import contextlib
import os
import queue
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

Q0_UR5 = [0.0, -1.2, 1.6, -0.4, 1.57, 0.0]
"""A UR5 configuration well inside its limits, away from singularities [rad]."""


@contextlib.contextmanager
def python_sigint_handler():
    """SIGINT to Python's own handler inside the block, then back to what it was.

    A suite started with SIGINT ignored (a background job of a shell without job control,
    ``nohup``) passes that on, and Python keeps an ignored SIGINT: a test of Ctrl-C sets the
    handler it starts from.
    """
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, inherited)


def one_arm_scenario(name: str = "one_ur5", duration: float = 0.02, dt: float = 0.002,
                     mass: float = 2.0, controller: str = "{type: gravity_compensation}",
                     joint: str = "{type: weld}", q0=None, extra: str = "") -> str:
    """YAML text of a cheap scenario: one UR5 welded (at its q0, no IK) to a small box."""
    q0 = Q0_UR5 if q0 is None else q0
    return f"""name: {name}
object:
  shape: {{type: box, size: [0.4, 0.3, 0.2]}}
  mass: {mass}
  pose: {{position: [0.8, 0.11, 0.24]}}  # the tool on its -x face (no collision at t = 0)
arms:
  - name: a
    robot: ur5
    q0: {list(q0)}
    joint: {joint}
controller: {controller}
simulation: {{duration: {duration}, dt: {dt}}}
{extra}"""


def tilt_pick_event_times(events, insert: str = "three_finger") -> tuple[float, float, float]:
    """``(far, bottom, pivot)`` [s] of a tilt pick-up run's events (issue 27's order).

    ``far``: the later first separation of the far edge's support vertices (``table[2]``,
    ``table[3]``), the tilt; ``bottom``: the first touchdown of the insert arm's bottom tip
    (``<insert>:tip[2]``); ``pivot``: the earlier first separation of the pivot edge's
    (``table[0]``, ``table[1]``), the lift. A run in order has ``far < bottom < pivot``.

    Raises:
        KeyError: one of those events never happened.
    """
    first = {}
    for e in events:
        first.setdefault((e.kind, e.label), e.t)
    far = max(first[("separation", "table[2]")], first[("separation", "table[3]")])
    bottom = first[("touchdown", f"{insert}:tip[2]")]
    pivot = min(first[("separation", "table[0]")], first[("separation", "table[1]")])
    return far, bottom, pivot


def write(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` (UTF-8) and return the path."""
    path.write_text(text, encoding="utf-8")
    return path


def cli_command(*args: str) -> list[str]:
    """The ``multiarm-pin`` command line (the console script of this interpreter's venv).

    Falls back to ``python -m multiarm_pin.app.cli`` when the script is not installed.
    """
    script = Path(sys.executable).parent / "multiarm-pin"
    head = [str(script)] if script.is_file() else [sys.executable, "-m", "multiarm_pin.app.cli"]
    return [*head, *map(str, args)]


def run_cli(*args: str, cwd=None, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run ``multiarm-pin ARGS`` to completion; returns the process (text stdout/stderr)."""
    return subprocess.run(cli_command(*args), cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, env=_env())


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONUNBUFFERED"] = "1"
    return env


class CliProcess:
    """``multiarm-pin ARGS`` running in the background, its stderr read line by line."""

    def __init__(self, *args: str, cwd=None):
        self.proc = subprocess.Popen(cli_command(*args), cwd=cwd, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, env=_env())
        self.lines: queue.Queue = queue.Queue()
        self.stderr: list[str] = []
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self) -> None:
        for line in self.proc.stderr:
            self.stderr.append(line)
            self.lines.put(line)
        self.lines.put(None)

    def wait_for(self, marker: str, timeout: float = 240) -> bool:
        """Wait until a stderr line contains ``marker``; False if the process ended first."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                line = self.lines.get(timeout=1.0)
            except queue.Empty:
                continue
            if line is None:
                return False
            if marker in line:
                return True
        raise TimeoutError(f"no line with {marker!r} within {timeout} s: {''.join(self.stderr)}")

    def finish(self, timeout: float = 240) -> tuple[int, str, str]:
        """Wait for the end; returns ``(exit code, stdout, stderr)``."""
        out = self.proc.stdout.read()
        code = self.proc.wait(timeout=timeout)
        self.thread.join(timeout=10)
        return code, out, "".join(self.stderr)


def _mount(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["mount", *args], capture_output=True, text=True, timeout=60)


@contextlib.contextmanager
def bind_mount(src: Path, dst: Path, read_only: bool = False):
    """``dst`` made a bind mount of ``src`` (read-only if asked) inside the block.

    Needs root (CI runs the tests as root); elsewhere, or where mounting is not allowed,
    the test is skipped with the reason. Always unmounted when the block ends.
    """
    import pytest

    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("a bind mount needs root and mount(8) (CI runs the tests as root)")
    src.mkdir(parents=True, exist_ok=True)
    dst.mkdir(parents=True, exist_ok=True)
    p = _mount("--bind", str(src), str(dst))
    if p.returncode != 0:
        pytest.skip(f"mount --bind is not allowed here: {p.stderr.strip()}")
    try:
        if read_only:
            p = _mount("-o", "remount,ro,bind", str(dst))
            assert p.returncode == 0, p.stderr
        yield dst
    finally:
        unmount(dst)


def unmount(path: Path) -> None:
    """Unmount ``path`` (lazily if it is busy); nothing if it is not mounted."""
    p = subprocess.run(["umount", str(path)], capture_output=True, text=True, timeout=60)
    if p.returncode != 0 and "not mounted" not in p.stderr:
        subprocess.run(["umount", "-l", str(path)], capture_output=True, timeout=60)
