"""Minimum-jerk pose trajectories through waypoints, for the object (or any rigid body).

Between consecutive waypoints ``(t_k, p_k, R_k)`` and ``(t_{k+1}, p_{k+1}, R_{k+1})`` the
motion is the rest-to-rest minimum-jerk profile ``s(τ) = 10τ³ - 15τ⁴ + 6τ⁵``,
``τ = (t - t_k) / (t_{k+1} - t_k)``, applied to

- the position: ``p(t) = p_k + s (p_{k+1} - p_k)``;
- the orientation, along the geodesic (slerp): ``R(t) = R_k exp(s θ u)`` with
  ``θ u = log(R_kᵀ R_{k+1})`` (shortest rotation, ``θ <= π``). The angular velocity is then
  ``ω = ṡ θ R_k u`` and the angular acceleration ``ω̇ = s̈ θ R_k u`` (world axes), since ``u``
  is fixed by ``exp(s θ u)``.

Velocities and accelerations are zero at every waypoint. Before the first time the pose is
held at the first waypoint, after the last time at the last one.
"""

from __future__ import annotations

import bisect
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from multiarm_pin._compiled import layout
from multiarm_pin.exceptions import InputError
from multiarm_pin.spatial import (
    as_array,
    as_se3,
    as_unit_quaternion,
    rotation_to_quaternion,
    se3_from,
    se3_to_pose,
)


def minimum_jerk(tau: float) -> tuple[float, float, float]:
    """The rest-to-rest minimum-jerk profile and its first two derivatives in ``τ``.

    Args:
        tau: normalised time, clipped to [0, 1].

    Returns:
        ``(s, ds/dτ, d²s/dτ²)``: ``s = 10τ³ - 15τ⁴ + 6τ⁵``.
    """
    t = min(max(float(tau), 0.0), 1.0)
    t2 = t * t
    s = t2 * t * (10.0 - 15.0 * t + 6.0 * t2)
    ds = 30.0 * t2 * (1.0 - 2.0 * t + t2)
    dds = 60.0 * t * (1.0 - 3.0 * t + 2.0 * t2)
    return s, ds, dds


@dataclass(frozen=True)
class PoseSample:
    """A pose with its velocity and acceleration at one time.

    Attributes:
        position: (3,) [m], world.
        quaternion: (4,) ``[x, y, z, w]`` (body axes -> world axes).
        rotation: (3, 3) the same orientation as a matrix.
        twist: (6,) ``[ṗ; ω]`` world axes [m/s, rad/s].
        acceleration: (6,) classical ``[p̈; ω̇]`` world axes [m/s², rad/s²].
    """

    position: np.ndarray
    quaternion: np.ndarray
    rotation: np.ndarray
    twist: np.ndarray
    acceleration: np.ndarray


_ZERO6 = np.zeros(6)
_ZERO6.setflags(write=False)


class MinimumJerkTrajectory:
    """Rest-to-rest minimum-jerk segments through pose waypoints.

    Args:
        times: (K,) strictly increasing waypoint times [s], K >= 1.
        positions: (K, 3) waypoint positions [m].
        quaternions: (K, 4) waypoint orientations ``[x, y, z, w]`` (unit; identity if None).

    Raises:
        InputError: wrong shapes, non-increasing times, NaN, non-unit quaternions.
    """

    def __init__(self, times, positions, quaternions=None):
        t = np.atleast_1d(as_array(times, (None,), "trajectory times [s]"))
        K = len(t)
        if K < 1:
            raise InputError("trajectory: expected at least one waypoint")
        if np.any(np.diff(t) <= 0):
            raise InputError(f"trajectory times: expected strictly increasing, got {t.tolist()}")
        p = as_array(positions, (K, 3), f"trajectory positions ({K} waypoints)")
        if quaternions is None:
            q = np.tile([0.0, 0.0, 0.0, 1.0], (K, 1))
        else:
            q = as_array(quaternions, (K, 4), f"trajectory quaternions ({K} waypoints)")
            q = np.array([as_unit_quaternion(x, f"trajectory quaternion {k}")
                          for k, x in enumerate(q)])
        self.times = t
        self.positions = p
        self.quaternions = q
        self._R = np.array([pin.Quaternion(x).toRotationMatrix() for x in q])
        # body-frame rotation vector of each segment: R_{k+1} = R_k exp(log_k)
        self._log = np.array([pin.log3(self._R[k].T @ self._R[k + 1]) for k in range(K - 1)])
        # per segment, for motion() (the controller's hot path): the times as Python floats,
        # each segment's displacement and world rotation axis (the same expressions, once)
        self._times = t.tolist()
        self._dp = [p[k + 1] - p[k] for k in range(K - 1)]
        self._axis = [self._R[k] @ self._log[k] for k in range(K - 1)]
        self._table: np.ndarray | None = None  # see table()

    @classmethod
    def through(cls, times, placements) -> MinimumJerkTrajectory:
        """Minimum-jerk segments through placements, the public API's form of waypoints.

        Args:
            times: (K,) strictly increasing waypoint times [s].
            placements: K ``pin.SE3`` world placements of the body (its COM frame for the
                object).

        Raises:
            InputError: a placement that is not a ``pin.SE3``, a count mismatch, or what the
                constructor refuses.
        """
        Ms = [as_se3(M, f"trajectory placement {k}") for k, M in enumerate(placements)]
        if not Ms:
            raise InputError("trajectory: expected at least one placement")
        poses = [se3_to_pose(M) for M in Ms]
        return cls(times, [p for p, _ in poses], [q for _, q in poses])

    @classmethod
    def hold(cls, position, quaternion=(0.0, 0.0, 0.0, 1.0)) -> MinimumJerkTrajectory:
        """A constant pose (one waypoint at t = 0)."""
        return cls([0.0], [position], [quaternion])

    @classmethod
    def from_waypoints(cls, waypoints, start=None) -> MinimumJerkTrajectory:
        """The trajectory through pose waypoints written as mappings (as in a scenario file).

        Args:
            waypoints: non-empty sequence of ``{t, position, quaternion | rpy}``: time [s]
                (>= 0, strictly increasing), position (3,) [m], orientation as a quaternion
                ``[x, y, z, w]`` or roll-pitch-yaw [rad] (identity if neither), world.
            start: ``(position (3,), quaternion (4,))`` prepended at t = 0 when the first
                waypoint is later (the pose the motion starts from); None: nothing prepended.

        Raises:
            InputError: not a list of such mappings, unknown or missing keys, bad numbers,
                times not increasing.
        """
        if isinstance(waypoints, str | bytes | Mapping) or not isinstance(waypoints, Sequence) \
                or not waypoints:
            raise InputError(f"waypoints: expected a non-empty list of {{t, position, "
                             f"quaternion | rpy}}, got {waypoints!r}")
        times, positions, quats = [], [], []
        for k, w in enumerate(waypoints):
            keys = set(w) if isinstance(w, Mapping) else set()
            if not isinstance(w, Mapping) or not {"t", "position"} <= keys or \
                    keys - {"t", "position", "quaternion", "rpy"}:
                raise InputError(f"waypoint {k}: expected a mapping with t, position and "
                                 f"optionally quaternion or rpy, got {w!r}")
            t = float(as_array(w["t"], (), f"waypoint {k} t [s]"))
            if t < 0 or (times and t <= times[-1]):
                raise InputError(f"waypoint {k}: times must be >= 0 and increase strictly, "
                                 f"got {t} after {times[-1] if times else 'none'}")
            M = se3_from(w["position"], quaternion=w.get("quaternion"), rpy=w.get("rpy"),
                         name=f"waypoint {k}")
            times.append(t)
            positions.append(M.translation.copy())
            quats.append(rotation_to_quaternion(M.rotation))
        if start is not None and times[0] > 0:
            times.insert(0, 0.0)
            positions.insert(0, as_array(start[0], (3,), "start position"))
            quats.insert(0, as_unit_quaternion(start[1], "start quaternion"))
        return cls(times, positions, quats)

    @property
    def duration(self) -> float:
        """Time of the last waypoint [s]."""
        return float(self.times[-1])

    def __call__(self, t: float) -> PoseSample:
        """Sample at time ``t`` [s] (see :class:`PoseSample`)."""
        return self.sample(t)

    def sample(self, t: float) -> PoseSample:
        """Pose, twist and classical acceleration at time ``t`` [s].

        Returns:
            :class:`PoseSample`; held constant before the first and after the last waypoint.
        """
        t = float(t)
        if not np.isfinite(t):
            raise InputError(f"trajectory time: expected a finite number [s], got {t}")
        times = self.times
        if t <= times[0] or len(times) == 1:
            return self._still(0)
        if t >= times[-1]:
            return self._still(len(times) - 1)
        k = int(np.searchsorted(times, t, side="right")) - 1
        T = times[k + 1] - times[k]
        s, ds, dds = minimum_jerk((t - times[k]) / T)
        ds /= T
        dds /= T * T
        dp = self.positions[k + 1] - self.positions[k]
        log = self._log[k]
        R = self._R[k] @ pin.exp3(s * log)
        axis_world = self._R[k] @ log
        twist = np.concatenate([ds * dp, ds * axis_world])
        acc = np.concatenate([dds * dp, dds * axis_world])
        return PoseSample(self.positions[k] + s * dp, rotation_to_quaternion(R), R, twist, acc)

    def motion(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`sample` without the quaternion: the controller's hot path.

        Args:
            t: time [s] (finite; not re-checked).

        Returns:
            ``(position (3,) [m], rotation (3, 3), twist (6,) [m/s, rad/s], acceleration (6,)
            [m/s², rad/s²])``, world axes; the arrays may be the trajectory's own (read only).
        """
        times = self._times
        if t <= times[0] or len(times) == 1:
            return self.positions[0], self._R[0], _ZERO6, _ZERO6
        if t >= times[-1]:
            return self.positions[-1], self._R[-1], _ZERO6, _ZERO6
        k = bisect.bisect_right(times, t) - 1  # np.searchsorted(side="right") - 1
        T = times[k + 1] - times[k]
        s, ds, dds = minimum_jerk((t - times[k]) / T)
        dp = self._dp[k]
        log = self._log[k]
        Rk = self._R[k]
        axis_world = self._axis[k]
        twist = np.empty(6)
        acc = np.empty(6)
        twist[:3] = (ds / T) * dp
        twist[3:] = (ds / T) * axis_world
        acc[:3] = (dds / (T * T)) * dp
        acc[3:] = (dds / (T * T)) * axis_world
        return self.positions[k] + s * dp, Rk @ pin.exp3(s * log), twist, acc

    def table(self) -> np.ndarray:
        """(K, TRAJECTORY_WIDTH) the trajectory as the compiled kernels read it.

        One row per waypoint (:data:`multiarm_pin._compiled.layout.TRAJECTORY_FIELDS`): the
        values :meth:`motion` uses, so that
        :func:`multiarm_pin._compiled.trajectory.reference_motion` gives its motion. Made once
        and kept (read-only).
        """
        if self._table is None:
            K = len(self.times)
            tab = np.zeros((K, layout.TRAJECTORY_WIDTH))
            tab[:, layout.TR_TIME] = self.times
            tab[:, layout.TR_POSITION:layout.TR_POSITION + 3] = self.positions
            tab[:, layout.TR_ROTATION:layout.TR_ROTATION + 9] = self._R.reshape(K, 9)
            for k in range(K - 1):
                tab[k, layout.TR_DISPLACEMENT:layout.TR_DISPLACEMENT + 3] = self._dp[k]
                tab[k, layout.TR_LOG:layout.TR_LOG + 3] = self._log[k]
                tab[k, layout.TR_AXIS:layout.TR_AXIS + 3] = self._axis[k]
            tab.setflags(write=False)
            self._table = tab
        return self._table

    def _still(self, k: int) -> PoseSample:
        return PoseSample(self.positions[k].copy(), self.quaternions[k].copy(),
                          self._R[k].copy(), np.zeros(6), np.zeros(6))


def pose_error(position_ref, rotation_ref, position, rotation) -> np.ndarray:
    """(6,) pose error ``[p_ref - p; log(R_ref Rᵀ)]`` in world axes [m, rad].

    The angular part is the world-axes rotation vector taking ``R`` to ``R_ref``.
    """
    return np.concatenate([np.asarray(position_ref) - np.asarray(position),
                           pin.log3(np.asarray(rotation_ref) @ np.asarray(rotation).T)])


__all__ = ["MinimumJerkTrajectory", "PoseSample", "minimum_jerk", "pose_error"]
