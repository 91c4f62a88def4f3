"""Checks made while a run runs: the ``stop`` policies of a scenario's ``limits:`` block.

:func:`~multiarm_pin.sim.simulation.simulate` calls each monitor of its ``monitors`` on every
stretch of samples it has recorded (``check(record, k0, k1)``, samples ``k0 .. k1 - 1`` of
the run's :class:`~multiarm_pin.sim.result.Recorder`); a monitor returns the first sample
that violates what it watches, or None, and the run then ends there
(:class:`~multiarm_pin.exceptions.RunStoppedError`, the samples up to and including that one kept).
The samples a monitor sees are those :func:`~multiarm_pin.feasibility.feasibility_report`
checks after a run, with the same rules, so a stop falls on the report's first violation.

- :class:`LimitMonitor`: the URDF's effort, velocity or position limits (any of them).
- :class:`CollisionMonitor`: collisions (:class:`~.scan.RunScan`, fed stretch by stretch).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from multiarm_pin.feasibility.limits import exceeded, system_limits
from multiarm_pin.feasibility.scan import RunScan


def _finite_rows(*arrays) -> int:
    """How many leading rows of every array are finite."""
    ok = np.ones(len(arrays[0]), dtype=bool)
    for a in arrays:
        ok &= np.isfinite(a.reshape(len(a), -1)).all(axis=1)
    return len(ok) if ok.all() else int(np.argmin(ok))


class LimitMonitor:
    """Stops a run at the first sample beyond a joint limit of the given kinds.

    Args:
        system: the simulated :class:`~multiarm_pin.system.MultiArmSystem`.
        kinds: any of ``"torque"`` (the applied torque ``|τ|`` against the effort),
            ``"velocity"``, ``"position"``.
    """

    def __init__(self, system, kinds):
        self.kinds = tuple(kinds)
        self.limits = system_limits(system)
        self.name = "limits." + "/".join(self.kinds)

    def check(self, record, k0: int, k1: int) -> int | None:
        """The first sample in ``[k0, k1)`` beyond a limit, or None."""
        over = exceeded(self.limits, record.q[k0:k1], record.v[k0:k1], record.tau[k0:k1])
        rows = np.zeros(k1 - k0, dtype=bool)
        for kind in self.kinds:
            rows |= over[kind].any(axis=1)
        hit = np.flatnonzero(rows)
        return k0 + int(hit[0]) if len(hit) else None


class CollisionMonitor:
    """Scans a run for collisions while it runs; stops it at the first one if ``stop``.

    Args:
        scene: the run's :class:`~multiarm_pin.feasibility.CollisionScene`.
        stop: end the run at the first collision (the ``stop`` policy); False: only scan, so
            that the run's report reuses the scan (:attr:`scan`) made while the run ran
            instead of scanning every sample after it.

    Samples from the first non-finite one on are not checked (a failing run's last ones).
    """

    name = "limits.collision"

    def __init__(self, scene, stop: bool = True):
        self.scene = scene
        self.stop = bool(stop)
        self.scan: RunScan | None = None
        self._stopped = False

    def warm_up(self, record, state) -> None:
        """Scan two samples at ``state``, shaped as ``record``'s, and report the clearances.

        On a scan of its own (this monitor is unchanged): the scan's kernels are called
        with the types of this run's, so that they may compile beside the run's loop
        (:class:`~multiarm_pin._compiled.function_pointers.WarmUp`).

        Args:
            record: the run's recorder (only the shapes of its contact points are read).
            state: a :class:`~multiarm_pin.system.SystemState`, the run's initial one.
        """
        two = SimpleNamespace(
            t=np.zeros(2), q=np.tile(np.asarray(state.q, float), (2, 1)),
            p=np.tile(np.asarray(state.obj.position, float), (2, 1)),
            quat=np.tile(np.asarray(state.obj.quaternion, float), (2, 1)),
            points=np.zeros((2, *record.points.shape[1:])))
        probe = CollisionMonitor(self.scene, stop=False)
        probe.check(two, 0, 2)
        scan = probe.scan
        if scan is None:
            return
        scan.result()
        # what the clearances call only for some runs: the bounds of a pair over the samples,
        # and a hull's support function
        if len(self.scene.pairs):
            scan.column_bounds(np.arange(1))
        hull = next((g for g, V in enumerate(scan.geo.hull_vertices) if V is not None), None)
        if hull is not None:
            scan.geo.support(hull, np.zeros((1, 3)), scan.compiled)

    def prepare(self, record) -> None:
        """Make the run's scan, its arrays for ``record``'s samples (else the first check does)."""
        if self.scan is None:
            self.scan = RunScan(self.scene, len(record.t))

    def check(self, record, k0: int, k1: int) -> int | None:
        """The first sample in ``[k0, k1)`` where two bodies collide, or None."""
        if self._stopped:
            return None
        self.prepare(record)
        q, p, quat = record.q[k0:k1], record.p[k0:k1], record.quat[k0:k1]
        n = _finite_rows(q, p, quat)
        if n < k1 - k0:
            self._stopped = True
        system = self.scene.system
        N = system.constraint_set.N
        cps = [record.points[k0:k0 + n, i, :int(N[i])] for i in range(system.n_arms)]
        hit = self.scan.extend(q[:n], p[:n], quat[:n], cps)
        return hit if self.stop else None


def feasibility_monitors(system, stops, scene=None) -> tuple:
    """A run's feasibility monitors: those of its ``stop`` policies, and its collision scan.

    Args:
        system: the :class:`~multiarm_pin.system.MultiArmSystem`.
        stops: the kinds (of :data:`~.report.LIMIT_KINDS`) whose policy is ``stop``.
        scene: its :class:`~multiarm_pin.feasibility.CollisionScene`; built for a
            ``"collision"`` stop when None.

    Returns:
        A :class:`LimitMonitor` of the joint kinds among ``stops`` (if any), and a
        :class:`CollisionMonitor` when ``"collision"`` is a stop (it stops the run) or when a
        ``scene`` is given (it only scans, so that the run's report reuses its scan:
        :func:`~multiarm_pin.feasibility.feasibility_report`'s ``scan``); none for a system
        without arms.
    """
    monitors = []
    joint_kinds = [k for k in stops if k in ("torque", "velocity", "position")]
    if joint_kinds and system.n_arms:
        monitors.append(LimitMonitor(system, joint_kinds))
    if "collision" in stops and system.n_arms:
        if scene is None:
            from multiarm_pin.feasibility.collisions import CollisionScene

            scene = CollisionScene(system)
        monitors.append(CollisionMonitor(scene))
    elif scene is not None and system.n_arms:  # scanned while the run runs, for its report
        monitors.append(CollisionMonitor(scene, stop=False))
    return tuple(monitors)


__all__ = ["CollisionMonitor", "LimitMonitor", "feasibility_monitors"]
