"""Whether what a run simulated is physically possible: limits and collisions, with causes.

One concept at several layers: each layer's ``report.py`` (``grasp``, ``study``, ``feasibility``,
``design``) makes that layer's report of its results.


:func:`feasibility_report` checks every recorded sample of a
:class:`~multiarm_pin.sim.result.SimulationResult` against the arms' joint limits
(:mod:`.limits`) and for collisions (:mod:`.collisions`) and returns a
:class:`FeasibilityReport`: ``feasible``, the ``violations`` (kind, arm, joint or link and the
other body, first time, worst value and the limit), per-joint peaks and margins, and the
clearances. :func:`check_design` answers the same for one state, before anything is
simulated. :data:`LIMIT_KINDS` and :data:`POLICIES` are the scenario's ``limits:`` block.

Twins: ``multiarm_pin.design.report``, ``multiarm_pin.grasp.report`` and
``multiarm_pin.study.report`` (the same role, a package's report of its own results, in four
packages: this one returns the feasibility of a simulated run (limits, collisions) as a
``FeasibilityReport``; ``design.report`` writes a design's results folder (scenarios, pictures,
``report.md``, the best run); ``grasp.report`` reads grasp files, analyses them, formats the
report and draws its picture; ``study.report`` writes a study's ``report.md`` and its plots).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from multiarm_pin.feasibility.collisions import CATEGORIES, CollisionScene
from multiarm_pin.feasibility.limits import arm_limits, limit_statistics

LIMIT_KINDS = ("torque", "velocity", "position", "collision")
"""The kinds of violation (the keys of a scenario's ``limits:`` block)."""

POLICIES = ("report", "stop")
"""What a run does at a violation: ``report`` it, or ``stop`` at the first one (exit 1)."""


@dataclass(frozen=True)
class Violation:
    """One limit exceeded, or one pair of bodies in collision, over a run (or at a state).

    Attributes:
        kind: one of :data:`LIMIT_KINDS`.
        arm: the arm's name.
        joint: the joint's name (limits), or None.
        link: the link's name (collisions), or None.
        other: the other body of a collision (``"<arm>/<link>"``, ``"object"``, a support's
            name, ``"ground"``), or None.
        t_first: first time [s] it happens.
        value: the worst value: ``|τ|`` [N m], ``|v|`` [rad/s], ``q`` [rad] or the signed
            distance [m] (negative: penetration depth).
        limit: the limit it exceeds (effort, velocity, the position bound it passes, 0 m).
        t_worst: time [s] of the worst value.
        intervals: a collision's time intervals ``((t0, t1), ...)`` [s]: the first and last
            sample of each run of consecutive samples in collision (empty for the limits).
    """

    kind: str
    arm: str
    joint: str | None
    link: str | None
    other: str | None
    t_first: float
    value: float
    limit: float
    t_worst: float | None = None
    intervals: tuple = ()

    def as_dict(self) -> dict:
        """The JSON form of ``summary.json``'s ``violations`` entries."""
        d = {"kind": self.kind, "arm": self.arm}
        if self.joint is not None:
            d["joint"] = self.joint
        if self.link is not None:
            d["link"] = self.link
            d["other"] = self.other
        d.update(t_first=self.t_first, value=self.value, limit=self.limit)
        if self.kind == "collision":
            d["intervals"] = [[float(a), float(b)] for a, b in self.intervals]
        return d

    def describe(self) -> str:
        """One line for people."""
        if self.kind == "collision":
            return (f"collision: {self.arm}/{self.link} and {self.other} from t = "
                    f"{self.t_first:.4g} s, {-self.value * 1e3:.3g} mm deep at worst")
        unit = {"torque": "N m", "velocity": "rad/s", "position": "rad"}[self.kind]
        return (f"{self.kind} limit: {self.arm} joint {self.joint} from t = {self.t_first:.4g} s,"
                f" {abs(self.value):.4g} {unit} against {abs(self.limit):.4g} {unit}")


@dataclass
class FeasibilityReport:
    """Whether a run (or a state) was physically possible.

    Attributes:
        feasible: no violation.
        violations: every :class:`Violation`, in order of ``t_first``.
        limits: per arm, per joint ``{peak_torque_ratio, peak_velocity_ratio,
            position_margin}`` (None where the URDF gives no such limit).
        clearance: per category of :data:`~.collisions.CATEGORIES` the smallest distance [m]
            over the run (on the convex hulls; grasp pairs left out), None without pairs or
            without the collision check.
        collisions_checked: the collision check ran.
    """

    feasible: bool
    violations: list[Violation] = field(default_factory=list)
    limits: dict = field(default_factory=dict)
    clearance: dict = field(default_factory=dict)
    collisions_checked: bool = True

    def first(self, kinds=LIMIT_KINDS) -> Violation | None:
        """The earliest violation of one of ``kinds``, or None."""
        vs = [v for v in self.violations if v.kind in kinds]
        return min(vs, key=lambda v: v.t_first) if vs else None

    def as_summary(self) -> dict:
        """``summary.json``'s feasibility keys.

        ``feasible``, ``violations``, ``limits``, ``clearance`` and ``collisions_checked``
        (False for an interrupted run, checked against the limits only).
        """
        return {"feasible": self.feasible,
                "violations": [v.as_dict() for v in self.violations],
                "limits": self.limits, "clearance": self.clearance,
                "collisions_checked": self.collisions_checked}

    def describe(self, max_lines: int = 8) -> list[str]:
        """Lines for people: the violations (at most ``max_lines``)."""
        lines = [v.describe() for v in self.violations[:max_lines]]
        if len(self.violations) > max_lines:
            lines.append(f"... {len(self.violations) - max_lines} more in summary.json")
        return lines


def _none_if_inf(x):
    return None if x is None or not np.isfinite(x) else float(x)


def _intervals(samples: np.ndarray, t: np.ndarray) -> tuple:
    """``((t0, t1), ...)`` [s] of the runs of consecutive indices in sorted ``samples``."""
    breaks = np.flatnonzero(np.diff(samples) > 1)
    first = np.concatenate([[0], breaks + 1])
    last = np.concatenate([breaks, [len(samples) - 1]])
    return tuple((float(t[samples[a]]), float(t[samples[b]])) for a, b in zip(first, last,
                                                                               strict=True))


def _grasp_points(system, result) -> list[np.ndarray]:
    """Per arm, (T, N_i, 3) its grasp's recorded contact points [m]."""
    return [result.contact_points[:, i, :int(system.constraint_set.N[i])]
            for i in range(system.n_arms)]


def feasibility_report(system, result, *, ground: float | None = 0.0, collisions: bool = True,
                       scene: CollisionScene | None = None, scan=None) -> FeasibilityReport:
    """Check every recorded sample of a run against the joint limits and for collisions.

    Args:
        system: the simulated :class:`~multiarm_pin.system.MultiArmSystem`.
        result: its :class:`~multiarm_pin.sim.result.SimulationResult` (partial results too;
            samples from the first non-finite one on are not checked).
        ground: height [m] of the ground plane, or None for none.
        collisions: also check collisions (False: limits only; ``clearance`` is empty).
        scene: a :class:`CollisionScene` of the system to reuse (built otherwise).
        scan: the :class:`~multiarm_pin.feasibility.scan.RunScan` of ``scene`` that a
            collision monitor fed while the run ran; reused when it holds exactly the
            samples checked here (a complete run), else the samples are scanned here.

    Returns:
        :class:`FeasibilityReport`.
    """
    # a failed run may end on non-finite samples: the checks are of the finite ones before
    finite = np.all(np.isfinite(result.q), axis=1) & np.all(
        np.isfinite(result.v), axis=1) & np.all(np.isfinite(result.tau), axis=1) & np.all(
        np.isfinite(result.object_position), axis=1) & np.all(
        np.isfinite(result.object_quaternion), axis=1)
    n = len(finite) if finite.all() else int(np.argmin(finite))
    t = np.asarray(result.t)[:n]
    violations, limits = [], {}
    aset = system.arm_set
    for i, arm in enumerate(system.arms):
        lim = arm_limits(arm)
        q = result.q[:n, aset.q_slices[i]]
        v = result.v[:n, aset.v_slices[i]]
        tau = result.tau[:n, aset.v_slices[i]]
        stats = limit_statistics(lim, t, q, v, tau)
        per = {}
        for c, (name, st) in enumerate(zip(lim.joints, stats, strict=True)):
            per[name] = {"peak_torque_ratio": _none_if_inf(st.peak_torque_ratio),
                         "peak_velocity_ratio": _none_if_inf(st.peak_velocity_ratio),
                         "position_margin": _none_if_inf(st.position_margin)}
            if st.t_torque is not None:
                k = int(np.argmax(np.abs(tau[:, c])))
                violations.append(Violation("torque", arm.name, name, None, None, st.t_torque,
                                            float(tau[k, c]), float(lim.effort[c]),
                                            float(t[k])))
            if st.t_velocity is not None:
                k = int(np.argmax(np.abs(v[:, c])))
                violations.append(Violation("velocity", arm.name, name, None, None,
                                            st.t_velocity, float(v[k, c]),
                                            float(lim.velocity[c]), float(t[k])))
            if st.t_position is not None:
                bound = lim.lower[c] if st.worst_q < lim.lower[c] else lim.upper[c]
                violations.append(Violation("position", arm.name, name, None, None,
                                            st.t_position, st.worst_q, float(bound)))
        limits[arm.name] = per
    clearance = {}
    if collisions and system.n_arms and n:
        scene = scene or CollisionScene(system, result.state(0), ground)
        if scan is not None and scan.scene is scene and scan.n == n:
            scan = scan.result()
        else:
            scan = scene.scan(result.q[:n], result.object_position[:n],
                              result.object_quaternion[:n],
                              [c[:n] for c in _grasp_points(system, result)])
        clearance = {k: _none_if_inf(v) for k, v in scan.clearance.items()}
        # a link of several geometries: one violation per pair of names
        by_names: dict[tuple, list] = {}
        for k, hits in scan.hits.items():
            by_names.setdefault(scene.pair_names(k), []).extend(hits)
        for (arm, link, other), hits in by_names.items():
            samples = np.unique([h[0] for h in hits])
            worst = min(hits, key=lambda h: h[1])
            violations.append(Violation("collision", arm, None, link, other,
                                        float(t[samples[0]]), float(worst[1]), 0.0,
                                        float(t[worst[0]]), _intervals(samples, t)))
    violations.sort(key=lambda x: (x.t_first, LIMIT_KINDS.index(x.kind)))
    return FeasibilityReport(not violations, violations, limits, clearance,
                             bool(collisions and system.n_arms))


def check_design(system, state, *, ground: float | None = 0.0,
                 scene: CollisionScene | None = None) -> FeasibilityReport:
    """Feasibility of one state, before anything is simulated: limits and collisions.

    Position and velocity limits are checked on the state; torques are not (no controller
    has run): the report's ``peak_torque_ratio`` entries are None.

    Args:
        system: the :class:`~multiarm_pin.system.MultiArmSystem`.
        state: a :class:`~multiarm_pin.system.SystemState` (e.g. the initial state).
        ground: height [m] of the ground plane, or None.
        scene: a :class:`CollisionScene` to reuse.

    Returns:
        :class:`FeasibilityReport` whose times are 0.
    """
    from types import SimpleNamespace

    T1 = SimpleNamespace(t=np.zeros(1), q=np.asarray(state.q)[None],
                         v=np.asarray(state.v)[None], tau=np.full((1, system.nv), np.nan))
    violations, limits = [], {}
    aset = system.arm_set
    for i, arm in enumerate(system.arms):
        lim = arm_limits(arm)
        stats = limit_statistics(lim, T1.t, T1.q[:, aset.q_slices[i]],
                                 T1.v[:, aset.v_slices[i]], np.zeros((1, arm.nv)))
        per = {}
        for c, (name, st) in enumerate(zip(lim.joints, stats, strict=True)):
            per[name] = {"peak_torque_ratio": None,
                         "peak_velocity_ratio": _none_if_inf(st.peak_velocity_ratio),
                         "position_margin": _none_if_inf(st.position_margin)}
            if st.t_velocity is not None:
                violations.append(Violation("velocity", arm.name, name, None, None, 0.0,
                                            float(T1.v[0, aset.v_slices[i]][c]),
                                            float(lim.velocity[c])))
            if st.t_position is not None:
                bound = lim.lower[c] if st.worst_q < lim.lower[c] else lim.upper[c]
                violations.append(Violation("position", arm.name, name, None, None, 0.0,
                                            st.worst_q, float(bound)))
        limits[arm.name] = per
    clearance = {}
    if system.n_arms:
        scene = scene or CollisionScene(system, state, ground)
        qs = scene.configuration(state.q, state.obj.position, state.obj.quaternion)
        d = scene.hull_distances(qs)
        for ci, name in enumerate(CATEGORIES):
            cols = (scene.category == ci) & ~scene.grasp_pair
            clearance[name] = float(d[cols].min()) if np.any(cols) else None
        ct = system.constraint_set.evaluate(system.arm_set.tool_kinematics(state.q, state.v),
                                            state.obj.kinematics())
        cps = [ct.contact_points[i, :int(system.constraint_set.N[i])]
               for i in range(system.n_arms)]
        deepest: dict[tuple, float] = {}  # a link of several geometries: once, its deepest
        for c in scene.collisions(qs, cps, d):
            key = (c.arm, c.link, c.other)
            deepest[key] = min(deepest.get(key, 0.0), c.distance)
        for (arm, link, other), depth in deepest.items():
            violations.append(Violation("collision", arm, None, link, other, 0.0, depth, 0.0,
                                        0.0, ((0.0, 0.0),)))
    return FeasibilityReport(not violations, violations, limits, clearance, bool(system.n_arms))


__all__ = ["LIMIT_KINDS", "POLICIES", "FeasibilityReport", "Violation", "check_design",
           "feasibility_report"]
