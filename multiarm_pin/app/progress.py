"""One-line text progress bars on a stream (stderr by default).

:class:`LineProgress` holds what every bar shares: the stream, whether it is a terminal
(redraw in place) or a log file (one line per tenth of the work), the ``[####----]`` drawing
and closing the line. :class:`ProgressBar` is the simulation's bar (fraction of the
simulated time); a bar over other units (cases of a study) subclasses :class:`LineProgress`
and writes its own text after the bar.
"""

from __future__ import annotations

import sys
import time


class LineProgress:
    """A one-line progress bar: terminal detection, throttling to tenths, drawing.

    Args:
        label: text before the bar.
        stream: where to write (default ``sys.stderr``).
        width: characters of the bar.

    Attributes:
        interactive: the stream is a terminal (the line is redrawn in place).
        shown: something was drawn.
        start: ``time.perf_counter()`` at creation [s].
    """

    def __init__(self, label: str, stream=None, width: int = 30):
        self.label, self.width = label, width
        self.stream = sys.stderr if stream is None else stream
        isatty = getattr(self.stream, "isatty", None)
        self.interactive = bool(isatty()) if callable(isatty) else False
        self.start = time.perf_counter()
        self.shown = False
        self._next_tenth = 0.1

    def due(self, fraction: float) -> bool:
        """Whether to draw at ``fraction`` (0..1): always on a terminal, else once a tenth."""
        if self.interactive:
            return True
        if fraction < self._next_tenth and fraction < 1.0:
            return False
        self._next_tenth = (int(fraction * 10 + 1e-9) + 1) / 10
        return True

    def draw(self, fraction: float, text: str) -> None:
        """Write ``label [###---] text`` for ``fraction`` (0..1) done (unconditionally)."""
        n = int(round(min(max(fraction, 0.0), 1.0) * self.width))
        start, end = ("\r", "") if self.interactive else ("", "\n")
        self.stream.write(f"{start}{self.label} [{'#' * n}{'-' * (self.width - n)}] {text} {end}")
        self.stream.flush()
        self.shown = True

    def close(self) -> None:
        """End the line if anything was drawn on a terminal."""
        if self.shown and self.interactive:
            self.stream.write("\n")
            self.stream.flush()


class ProgressBar(LineProgress):
    """The bar of a simulation: fraction of the simulated time, elapsed and remaining time.

    Redraws at most every ``min_interval`` seconds; shows nothing for runs shorter than
    ``delay`` seconds of wall time (short runs stay quiet). On a stream that is not a
    terminal (a log file, CI) it writes one line per tenth of the run instead of redrawing.

    Args:
        label: text before the bar.
        total_time: simulated duration [s].
        stream: where to write (default ``sys.stderr``).
        width: characters of the bar.
        delay: wall time [s] before the first drawing.
        min_interval: least wall time [s] between two drawings.
    """

    def __init__(self, label: str, total_time: float, stream=None, width: int = 30,
                 delay: float = 0.5, min_interval: float = 0.1):
        super().__init__(label, stream, width)
        self.total_time = float(total_time)
        self.delay, self.min_interval = delay, min_interval
        self._last = -1.0
        self._ended = False  # the end (100 %) was drawn

    def __call__(self, fraction: float) -> None:
        """Update with the fraction done (0..1)."""
        now = time.perf_counter()
        elapsed = now - self.start
        if elapsed < self.delay and fraction < 1.0:
            return
        if fraction < 1.0 and now - self._last < self.min_interval:
            return
        f = min(max(float(fraction), 0.0), 1.0)
        if f >= 1.0 and self._ended or not self.due(f):
            return
        self._ended = f >= 1.0
        self._last = now
        eta = elapsed * (1 - f) / f if f > 0 else float("nan")
        self.draw(f, f"{100 * f:5.1f}% t = {f * self.total_time:.3f}/{self.total_time:.3f} s, "
                     f"{elapsed:.1f} s elapsed, ~{eta:.1f} s left")


__all__ = ["LineProgress", "ProgressBar"]
