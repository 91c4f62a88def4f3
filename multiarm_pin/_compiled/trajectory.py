"""Compiled minimum-jerk reference motion: :meth:`MinimumJerkTrajectory.motion` in numba.

Mirrors :meth:`multiarm_pin.sim.trajectories.MinimumJerkTrajectory.motion` (the reference) on
the trajectory's table (:data:`~multiarm_pin._compiled.layout.TRAJECTORY_FIELDS`, one row per
waypoint, built by :meth:`MinimumJerkTrajectory.table`): position [m], rotation (row-major),
and for the segment that starts there its displacement [m], body-frame rotation vector
``log(R_kᵀ R_{k+1})`` [rad] and that vector in world axes. The result is the reference vector
of the controller kernels (:data:`~multiarm_pin._compiled.layout.REFERENCE_FIELDS`).
"""

from __future__ import annotations

import math

from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.layout import (
    REF_ACCELERATION,
    REF_POSITION,
    REF_ROTATION,
    REF_TWIST,
    TR_AXIS,
    TR_DISPLACEMENT,
    TR_LOG,
    TR_POSITION,
    TR_ROTATION,
    TR_TIME,
)

EXP3_TAYLOR = 1e-4
"""Below this angle [rad] :func:`exp3` uses Taylor series (as ``pin.exp3`` does near 0)."""


@kernel(refcounts=False)
def exp3(wx, wy, wz, R):  # pragma: no cover - compiled
    """Rotation matrix ``exp([w]×)`` of the rotation vector ``w`` [rad] into ``R`` (3, 3).

    Rodrigues' formula ``R = cos θ I + (sin θ / θ) [w]× + ((1 - cos θ) / θ²) w wᵀ``, with the
    Taylor series of the coefficients below :data:`EXP3_TAYLOR` (``pin.exp3``'s form).
    """
    t2 = wx * wx + wy * wy + wz * wz
    t = math.sqrt(t2)
    if t > EXP3_TAYLOR:
        ct, st = math.cos(t), math.sin(t)
        a = st / t
        b = (1.0 - ct) / t2
        c = ct
    else:
        a = 1.0 - t2 / 6.0
        b = 0.5 - t2 / 24.0
        c = 1.0 - t2 / 2.0
    R[0, 0] = c + b * wx * wx
    R[1, 1] = c + b * wy * wy
    R[2, 2] = c + b * wz * wz
    R[0, 1] = b * wx * wy - a * wz
    R[1, 0] = b * wx * wy + a * wz
    R[0, 2] = b * wx * wz + a * wy
    R[2, 0] = b * wx * wz - a * wy
    R[1, 2] = b * wy * wz - a * wx
    R[2, 1] = b * wy * wz + a * wx


@kernel(refcounts=False)
def reference_motion(t, table, E, ref):  # pragma: no cover - compiled
    """The reference pose, twist and acceleration at time ``t`` [s] into ``ref``.

    Args:
        t: time [s] (finite).
        table: (K, TRAJECTORY_WIDTH) the trajectory's table, K >= 1 waypoints.
        E: (3, 3) workspace.
        ref: output (REFERENCE_SIZE,): position, rotation (row-major), twist ``[ṗ; ω]``,
            classical acceleration, world axes; held still before the first and after the
            last waypoint.
    """
    K = table.shape[0]
    if t <= table[0, TR_TIME] or K == 1:
        k = 0
        still = True
    elif t >= table[K - 1, TR_TIME]:
        k = K - 1
        still = True
    else:
        k = 0  # last waypoint with time <= t (bisect_right - 1)
        lo, hi = 0, K
        while lo < hi:
            mid = (lo + hi) // 2
            if t < table[mid, TR_TIME]:
                hi = mid
            else:
                lo = mid + 1
        k = lo - 1
        still = False
    if still:
        for a in range(3):
            ref[REF_POSITION + a] = table[k, TR_POSITION + a]
        for a in range(9):
            ref[REF_ROTATION + a] = table[k, TR_ROTATION + a]
        for a in range(6):
            ref[REF_TWIST + a] = 0.0
            ref[REF_ACCELERATION + a] = 0.0
        return
    T = table[k + 1, TR_TIME] - table[k, TR_TIME]
    tau = min(max((t - table[k, TR_TIME]) / T, 0.0), 1.0)
    t2 = tau * tau
    s = t2 * tau * (10.0 - 15.0 * tau + 6.0 * t2)
    ds = 30.0 * t2 * (1.0 - 2.0 * tau + t2)
    dds = 60.0 * tau * (1.0 - 3.0 * tau + 2.0 * t2)
    fv = ds / T
    fa = dds / (T * T)
    for a in range(3):
        d = table[k, TR_DISPLACEMENT + a]
        ax = table[k, TR_AXIS + a]
        ref[REF_POSITION + a] = table[k, TR_POSITION + a] + s * d
        ref[REF_TWIST + a] = fv * d
        ref[REF_TWIST + 3 + a] = fv * ax
        ref[REF_ACCELERATION + a] = fa * d
        ref[REF_ACCELERATION + 3 + a] = fa * ax
    exp3(s * table[k, TR_LOG], s * table[k, TR_LOG + 1], s * table[k, TR_LOG + 2], E)
    for a in range(3):  # R_k exp(s log_k)
        for b in range(3):
            acc = 0.0
            for p in range(3):
                acc += table[k, TR_ROTATION + 3 * a + p] * E[p, b]
            ref[REF_ROTATION + 3 * a + b] = acc


__all__ = ["EXP3_TAYLOR", "exp3", "reference_motion"]
