"""The phases of a phased task (``phased_pd``) as its replay and its report show them.

A ``phased_pd`` run (:mod:`multiarm_pin.sim.controllers.phased`) goes through named phases
(rest, tilt, insert, lift...), each current from its start ``t`` until the next one starts
(the controller's ``phase_index``: the last one started; the first one also before its
start), its motion lasting ``duration``. The results folder keeps them in its
``scenario.yaml`` (the scenario as run): :func:`replay_phases` reads them back, checked by
the controller's own parser, as :class:`ReplayPhase` s whose ``press`` rows are named by
their support labels (``"table[2]"``). :func:`phase_table` gives their intervals (the
replay page's phase table and timeline row, the bands of ``contact_states.png``),
:func:`phase_indices` the phase current at given times, and :func:`phases_summary`
``summary.json``'s ``phases`` (each with the contact events during it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from multiarm_pin.app.scenario import Scenario
from multiarm_pin.exceptions import InputError
from multiarm_pin.sim.controllers.phased import current_phase, parse_phases


@dataclass(frozen=True)
class ReplayPhase:
    """A phase of a phased task (``phased_pd``) shown on the replay's timeline.

    The phase is the current one from ``t`` until the next phase's ``t`` (the controller's
    ``phase_index``: the last one started; the first one also before its ``t``); its motion
    (reference change) lasts ``duration``, after which it holds until the next phase.

    Attributes:
        name: the phase's name.
        kind: ``"tilt"``, ``"move"`` or ``"hold"``.
        t: start time [s].
        duration: duration of its motion [s] (> 0).
        press: labels of the support points planned to keep pressing (``"<support>[j]"``).
        release: names of the arms released (their contacts get no planned force).
        offsets: names of the arms whose held points move to new offsets in this phase.
    """

    name: str
    kind: str
    t: float
    duration: float
    press: tuple[str, ...] = ()
    release: tuple[str, ...] = ()
    offsets: tuple[str, ...] = ()

    @property
    def moves(self) -> bool:
        """Its reference changes: a tilt or a move, or a hold whose arms' offsets change."""
        return self.kind != "hold" or bool(self.offsets)

    def __post_init__(self):
        if not (math.isfinite(self.t) and math.isfinite(self.duration) and self.duration > 0):
            raise InputError(f"ReplayPhase {self.name!r}: expected a finite start time and a "
                             f"duration > 0 [s], got t={self.t!r}, duration={self.duration!r}")


def check_phases(phases) -> tuple[ReplayPhase, ...]:
    """The phases as a tuple, once they are :class:`ReplayPhase` s with increasing starts.

    Raises:
        InputError: another item, or a start time not after the previous one.
    """
    out = tuple(phases)
    for k, p in enumerate(out):
        if not isinstance(p, ReplayPhase):
            raise InputError(f"phases[{k}]: expected a ReplayPhase, got {type(p).__name__}")
        if k and not p.t > out[k - 1].t:
            raise InputError(f"phases[{k}] {p.name!r}: starts at {p.t} s, not after "
                             f"phases[{k - 1}] {out[k - 1].name!r} at {out[k - 1].t} s")
    return out


def phase_indices(phases: Sequence[ReplayPhase], t) -> np.ndarray:
    """(T,) int: the index of the phase current at each time of ``t`` (T,) [s].

    The last phase started at or before ``t`` (0 before the first start): ``phased_pd``'s
    own rule (:func:`~multiarm_pin.sim.controllers.phased.current_phase`); -1 everywhere
    without phases.
    """
    t = np.asarray(t, dtype=float)
    if not len(phases):
        return np.full(t.shape, -1, dtype=int)
    return current_phase([p.t for p in phases], t)


def phase_table(phases: Sequence[ReplayPhase], t_end: float) -> list[dict]:
    """The phases' intervals, as the replay page and the contact-state plot show them.

    Args:
        phases: the phases, in order.
        t_end: the run's last time [s] (the last phase's end).

    Returns:
        One dict per phase: ``name``, ``kind``, ``t`` (start) and ``end`` (the next phase's
        start; the last one's: ``t_end``) [s], ``motion_end`` (the end of its motion,
        ``t + duration``, at most ``end``; ``t`` for a phase that does not move) [s],
        ``press``, ``release`` and ``offsets`` (lists).
    """
    rows = []
    for k, p in enumerate(phases):
        end = phases[k + 1].t if k + 1 < len(phases) else max(float(t_end), p.t)
        rows.append({"name": p.name, "kind": p.kind, "t": float(p.t), "end": float(end),
                     "motion_end": float(min(p.t + p.duration, end) if p.moves else p.t),
                     "press": list(p.press), "release": list(p.release),
                     "offsets": list(p.offsets)})
    return rows


def replay_phases(scenario: Scenario, trajectory: dict) -> tuple[ReplayPhase, ...]:
    """The phases of a ``phased_pd`` run for its replay (:class:`ReplayPhase` s), else ().

    Read from the scenario's ``controller.phases`` (the results folder's ``scenario.yaml``
    holds them as run), checked by the controller's own parser
    (:func:`~multiarm_pin.sim.controllers.phased.parse_phases`); a phase's ``press`` (support
    row indices; none given: every row) becomes the rows' labels, from the trajectory's
    ``contact_labels`` (``"<support>[j]"`` in row order, after the arms' contacts).

    Args:
        scenario: the run's scenario.
        trajectory: its ``trajectory.npz`` arrays (``contact_labels``, ``support_names``).

    Raises:
        InputError: phases the controller would refuse (names the phase and key).
    """
    ctrl = scenario.controller
    if ctrl is None or ctrl.type != "phased_pd":
        return ()
    labels = [str(x) for x in trajectory.get("contact_labels", [])]
    names = tuple(str(x) for x in trajectory.get("support_names", []))
    rows = [lab for lab in labels if lab.split("[", 1)[0] in names and ":" not in lab]
    arm_names = [a.name for a in scenario.arms]
    raw = ctrl.params.get("phases")
    phases = parse_phases([{"kind": "hold"}] if raw is None else raw, arm_names, len(rows),
                          tuple(lab for lab in labels if ":" in lab))
    return tuple(ReplayPhase(p.name, p.kind, p.t, p.duration,
                             tuple(rows) if p.press is None else tuple(rows[i] for i in p.press),
                             tuple(p.release), tuple(p.offsets)) for p in phases)


def phases_summary(scenario: Scenario, trajectory: dict, events) -> list[dict]:
    """``summary.json``'s ``phases`` of a ``phased_pd`` run (empty for other controllers).

    Args:
        scenario: the run's scenario.
        trajectory: its ``trajectory.npz`` arrays.
        events: ``summary.json``'s ``events`` (dicts with ``t``, ``kind``, ``label``).

    Returns:
        The rows of :func:`phase_table` (``name``, ``kind``,
        ``t``, ``end``, ``motion_end``, ``press``, ``release``, ``offsets``), each with
        ``events``: the
        contact events during the phase, as ``"<t> s <kind> <label>"``.
    """
    phases = replay_phases(scenario, trajectory)
    rows = phase_table(phases, float(trajectory["t"][-1]))
    where = phase_indices(phases, [float(e["t"]) for e in events])
    for k, row in enumerate(rows):
        row["events"] = [f"{float(e['t']):.6g} s {e['kind']} {e['label']}"
                         for e, i in zip(events, where, strict=True) if i == k]
    return rows


__all__ = ["ReplayPhase", "check_phases", "phase_indices", "phase_table", "phases_summary",
           "replay_phases"]
