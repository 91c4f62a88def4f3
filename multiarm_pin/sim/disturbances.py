"""Disturbances: external wrenches on the object over time intervals.

A :class:`WrenchSchedule` is a list of ``(t_from, t_to, wrench)``: the wrench ``[fx, fy, fz,
mx, my, mz]`` [N, N m] acts at the object's COM in world axes for ``t_from <= t < t_to`` and
is zero elsewhere; overlapping intervals add up. The simulation adds it to the object's force
terms ``h_o`` (docs/ARCHITECTURE.md) and records it at every sample.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from multiarm_pin.exceptions import InputError


class WrenchSchedule:
    """Piecewise-constant external wrench at the object's COM, world axes.

    Args:
        intervals: ``[(t_from, t_to, wrench (6,)), ...]`` with ``0 <= t_from < t_to`` [s].

    Raises:
        InputError: an interval that is not increasing, or a wrench that is not 6 finite
            numbers (names the interval index).
    """

    def __init__(self, intervals: Sequence = ()):
        items = []
        for k, item in enumerate(intervals):
            try:
                a, b, w = item
                a, b = float(a), float(b)
                w = np.asarray(w, dtype=float)
            except (TypeError, ValueError) as exc:
                raise InputError(f"external_wrench[{k}]: expected (from, to, wrench), got "
                                 f"{item!r}") from exc
            if not (np.isfinite(a) and np.isfinite(b) and 0.0 <= a < b):
                raise InputError(f"external_wrench[{k}]: expected 0 <= from < to [s], got "
                                 f"from = {a}, to = {b}")
            if w.shape != (6,) or not np.all(np.isfinite(w)):
                raise InputError(f"external_wrench[{k}]: expected 6 finite numbers [fx, fy, fz, "
                                 f"mx, my, mz] [N, N m], got {np.asarray(w).tolist()}")
            items.append((a, b, w))
        self.intervals: tuple[tuple[float, float, np.ndarray], ...] = tuple(items)

    def __bool__(self) -> bool:
        """True when some interval is defined."""
        return bool(self.intervals)

    def __call__(self, t: float) -> np.ndarray:
        """(6,) ``[f; m]`` [N, N m] at time ``t`` [s] (sum of the intervals holding ``t``)."""
        out = np.zeros(6)
        for a, b, w in self.intervals:
            if a <= t < b:
                out = out + w
        return out

    def table(self) -> np.ndarray:
        """(K, WRENCH_WIDTH) the intervals as the compiled loop reads them.

        Columns :data:`multiarm_pin._compiled.layout.WRENCH_FIELDS` (``from``, ``to``, the
        wrench); K = 0 for an empty schedule.
        """
        from multiarm_pin._compiled import layout

        out = np.zeros((len(self.intervals), layout.WRENCH_WIDTH))
        for k, (a, b, w) in enumerate(self.intervals):
            out[k, layout.WE_FROM], out[k, layout.WE_TO] = a, b
            out[k, layout.WE_WRENCH:layout.WE_WRENCH + 6] = w
        return out

    @property
    def switch_times(self) -> list[float]:
        """Sorted times [s] at which the wrench changes."""
        return sorted({x for a, b, _ in self.intervals for x in (a, b)})


__all__ = ["WrenchSchedule"]
