"""Headless Chromium for the replay-page tests (a helper module, not a test file).

The flags are the README's screenshot command: no sandbox (root in a container), software
WebGL, no network services, a fresh profile per call.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import tempfile
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
"""Seconds one Chromium run may take: a run takes about 5 s alone and 20-23 s with both
cores kept busy beside it; a rare one never ends (more often on a loaded machine), and each
such hang costs the whole timeout."""
ATTEMPTS = 6
"""Runs tried before a hang is a failure (hangs come in runs on a loaded machine: three in a
row have been seen)."""


def _run(args: list[str], url: str, budget_ms: int) -> subprocess.CompletedProcess:
    """Run Chromium once; a run that hangs is killed with its process group and run again."""
    for attempt in range(ATTEMPTS):
        with tempfile.TemporaryDirectory(prefix="chromium-profile-") as profile:
            cmd = [CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *args,
                   f"--virtual-time-budget={budget_ms}", url]
            proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                    start_new_session=True)
            try:
                out, err = proc.communicate(timeout=TIMEOUT)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.communicate()
                if attempt == ATTEMPTS - 1:
                    raise
                continue
            if proc.returncode:
                raise subprocess.CalledProcessError(proc.returncode, cmd, out, err)
            return subprocess.CompletedProcess(cmd, 0, out, err)
    raise AssertionError("unreachable")


def page_url(page: Path, fragment: str = "") -> str:
    """``file://`` URL of a page, with an optional ``#...`` fragment."""
    return f"file://{Path(page).resolve()}{fragment}"


def screenshot(url: str, png: Path, size=(1280, 800), budget_ms: int = 15000) -> np.ndarray:
    """(H, W, 3) int RGB screenshot of ``url`` after ``budget_ms`` of virtual time."""
    from PIL import Image

    _run([f"--screenshot={png}", f"--window-size={size[0]},{size[1]}"], url, budget_ms)
    return np.asarray(Image.open(png).convert("RGB"), dtype=int)


def dump_dom(url: str, size=(1280, 800), budget_ms: int = 15000) -> str:
    """The page's DOM (HTML) after its scripts ran for ``budget_ms`` of virtual time."""
    out = _run(["--dump-dom", f"--window-size={size[0]},{size[1]}"], url, budget_ms)
    return out.stdout.decode("utf-8", errors="replace")


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
