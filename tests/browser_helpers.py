"""Headless Chromium for the replay-page tests (a helper module, not a test file).

The flags are the README's screenshot command (no sandbox: root in a container; software
WebGL; no network services; a fresh profile per call), but the page is driven over
Chromium's DevTools pipe in real time instead of ``--virtual-time-budget``, whose runs on a
loaded machine (both cores busy beside it) often never end (:func:`_load`).
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import re
import select
import shutil
import signal
import subprocess
import tempfile
import time
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or (
    "/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None)

needs_chromium = pytest.mark.skipif(
    CHROMIUM is None, reason="chromium is not installed (make browser, or apt-get install -y "
    "chromium); the browser tests of the replay page need it")

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]


TIMEOUT = 45
"""Seconds one Chromium run may take (about 2 s alone, 3 s with both cores kept busy beside
it); a run that takes longer is killed and tried again."""
ATTEMPTS = 3
"""Runs tried before a run that does not finish is a failure."""


class _DevTools:
    """One headless Chromium driven over its DevTools pipe (``--remote-debugging-pipe``).

    Commands go to the browser's fd 3 and replies come from its fd 4, as NUL-terminated JSON
    messages; every wait has the deadline ``TIMEOUT`` s after the start
    (``subprocess.TimeoutExpired`` past it).
    """

    def __init__(self, profile: str, size: tuple[int, int]):
        to_child, self._to = os.pipe()
        self._from, from_child = os.pipe()

        def pipes_at_3_and_4():  # to_child < from_child: made first, at the lowest free fd
            os.dup2(to_child, 3)
            os.dup2(from_child, 4)

        self.proc = subprocess.Popen(
            [CHROMIUM, *FLAGS, f"--user-data-dir={profile}", f"--window-size={size[0]},{size[1]}",
             "--remote-debugging-pipe", "about:blank"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            pass_fds=(3, 4), preexec_fn=pipes_at_3_and_4, start_new_session=True)
        os.close(to_child)
        os.close(from_child)
        self.deadline = time.monotonic() + TIMEOUT
        self._buffer, self._id, self._events = b"", 0, []

    def close(self) -> None:
        """Stop the browser and its process group."""
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.proc.pid, signal.SIGKILL)
        self.proc.wait()
        os.close(self._to)
        os.close(self._from)

    def _message(self) -> dict:
        while b"\0" not in self._buffer:
            left = self.deadline - time.monotonic()
            if left <= 0 or not select.select([self._from], [], [], left)[0]:
                raise subprocess.TimeoutExpired(CHROMIUM, TIMEOUT)
            chunk = os.read(self._from, 1 << 20)
            if not chunk:
                raise RuntimeError("chromium closed its DevTools pipe")
            self._buffer += chunk
        raw, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(raw)

    def send(self, method: str, session: str | None = None, **params) -> dict:
        """The result of one command (events that arrive meanwhile are kept)."""
        self._id += 1
        message = {"id": self._id, "method": method, "params": params}
        if session is not None:
            message["sessionId"] = session
        os.write(self._to, json.dumps(message).encode() + b"\0")
        while True:
            reply = self._message()
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]
            self._events.append(reply)

    def wait_for(self, event: str) -> dict:
        """The first event ``event`` (kept or coming)."""
        for i, message in enumerate(self._events):
            if message.get("method") == event:
                return self._events.pop(i)
        while True:
            message = self._message()
            if message.get("method") == event:
                return message
            self._events.append(message)


SETTLED = """(async () => {
  if (window.multiarmReplay) await window.multiarmReplay.ready;
  if (window.viewer && window.viewer.connection) {
    let seen = -1;
    while (viewer.num_messages_received === 0 || viewer.num_messages_received !== seen) {
      seen = viewer.num_messages_received;
      await new Promise(r => setTimeout(r, 500));
    }
  }
  for (let i = 0; i < 3; i++) await new Promise(r => requestAnimationFrame(r));
})()"""
"""The page's scripts are done: a replay page's replay loaded (``multiarmReplay.ready``), a
live viewer's commands received (none new for 0.5 s), and three animation frames drawn since
(the overlay draws in its frames)."""


def _retried(once):
    """``once()``, run again when it raises ``subprocess.TimeoutExpired`` (a Chromium run that
    took longer than ``TIMEOUT``, killed with its process group), ``ATTEMPTS`` times in all."""
    for attempt in range(ATTEMPTS):
        try:
            return once()
        except subprocess.TimeoutExpired:
            if attempt == ATTEMPTS - 1:
                raise
    raise AssertionError("unreachable")


def _load(url: str, size: tuple[int, int], read) -> object:
    """``read(devtools, session)`` on ``url`` once loaded and settled (:data:`SETTLED`).

    Real time, not ``--virtual-time-budget``: on a loaded machine a virtual-time run often
    never ends (its processes idle after the page's last WebGL frame). A run that takes
    longer than ``TIMEOUT`` is killed and tried again (:func:`_retried`). The pages the tests
    load show a fixed time (``#t=``) or do not move, so the moment they are read does not
    matter. A live viewer that receives no command is waited for until the timeout.
    """
    def once():
        with tempfile.TemporaryDirectory(prefix="chromium-profile-") as profile:
            dt = _DevTools(profile, size)
            try:
                page = next((t["targetId"] for t in dt.send("Target.getTargets")["targetInfos"]
                             if t["type"] == "page"), None)
                if page is None:  # the first tab not open yet
                    page = dt.send("Target.createTarget", url="about:blank")["targetId"]
                session = dt.send("Target.attachToTarget", targetId=page,
                                  flatten=True)["sessionId"]
                dt.send("Page.enable", session)
                dt.send("Emulation.setDeviceMetricsOverride", session, width=size[0],
                        height=size[1], deviceScaleFactor=1, mobile=False)
                dt.send("Page.navigate", session, url=url)
                dt.wait_for("Page.loadEventFired")
                settled = dt.send("Runtime.evaluate", session, expression=SETTLED,
                                  awaitPromise=True)
                if "exceptionDetails" in settled:
                    raise RuntimeError(f"{url}: {settled['exceptionDetails']}")
                return read(dt, session)
            finally:
                dt.close()

    return _retried(once)


def run_command(cmd: list[str], cwd: Path) -> None:
    """Run a Chromium command line as written (the README's), in its own process group.

    It uses virtual time, whose runs on a loaded machine may never end (:func:`_load`): one
    that takes longer than ``TIMEOUT`` is killed with its group and run again
    (:func:`_retried`). A run that fails raises ``subprocess.CalledProcessError``.
    """
    def once():
        proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                start_new_session=True)
        try:
            out, err = proc.communicate(timeout=TIMEOUT)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
            raise
        if proc.returncode:
            raise subprocess.CalledProcessError(proc.returncode, cmd, out, err)

    _retried(once)


def page_url(page: Path, fragment: str = "") -> str:
    """``file://`` URL of a page, with an optional ``#...`` fragment."""
    return f"file://{Path(page).resolve()}{fragment}"


def screenshot(url: str, png: Path, size=(1280, 800)) -> np.ndarray:
    """(H, W, 3) int RGB screenshot of ``url`` (its viewport, ``size`` pixels) once settled."""
    from PIL import Image

    def shot(dt, session):
        return base64.b64decode(dt.send("Page.captureScreenshot", session, format="png")["data"])

    png.write_bytes(_load(url, size, shot))
    return np.asarray(Image.open(png).convert("RGB"), dtype=int)


def dump_dom(url: str, size=(1280, 800)) -> str:
    """The page's DOM (HTML) once settled (:data:`SETTLED`)."""
    def dom(dt, session):
        return dt.send("Runtime.evaluate", session, expression="document.documentElement.outerHTML",
                       returnByValue=True)["result"]["value"]

    return _load(url, size, dom)


def element_text(dom: str, element_id: str) -> str:
    """The text of an element of the dumped DOM (its tags made spaces)."""
    class Grab(HTMLParser):
        def __init__(self):
            super().__init__()
            self.depth, self.parts = 0, []

        def handle_starttag(self, tag, attrs):
            if tag in ("br", "hr", "img", "input"):  # no end tag
                self.parts.append(" ")
            elif self.depth or dict(attrs).get("id") == element_id:
                self.depth += 1
                self.parts.append(" ")

        def handle_endtag(self, tag):
            if self.depth:
                self.depth -= 1
                self.parts.append(" ")

        def handle_data(self, data):
            if self.depth:
                self.parts.append(data)

    grab = Grab()
    grab.feed(dom)
    assert grab.parts, f"no element #{element_id} in the DOM"
    return re.sub(r"\s+", " ", "".join(grab.parts))
