"""Compiled arm terms: stacked, padded mass matrices, nonlinear effects and tool Jacobians.

Mirrors :meth:`multiarm_pin.model.arm_set.ArmSet.evaluate` (the numpy reference): from the
arrays of one combined Pinocchio model after ``computeJointJacobiansTimeVariation`` and
``crba``, each arm's padded ``M``, ``nle``, LOCAL_WORLD_ALIGNED tool Jacobian, ``J̇q̇``, tool
placement and twist, written into the arm segments of the flat buffer
(:mod:`multiarm_pin._compiled.layout`).
"""

from __future__ import annotations

import numpy as np

from multiarm_pin._compiled.jit import kernel


@kernel
def arm_terms(J_world, dJ_world, M_full, nle_full, v, H, idx, nv_arm, support,
              M, nle, J, Jdq, p, R, twist, vp):  # pragma: no cover - compiled
    """Stacked, padded arm terms from the combined Pinocchio model's arrays (``ArmSet.evaluate``).

    Args:
        J_world: (6, nv) ``data.J`` after ``computeJointJacobiansTimeVariation``: world
            Jacobian columns at the world origin.
        dJ_world: (6, nv) ``data.dJ``, their time derivative (same frame).
        M_full: (nv, nv) ``data.M`` after ``crba`` (full symmetric) [kg m², kg].
        nle_full: (nv,) ``data.nle`` [N m or N].
        v: (nv,) combined joint velocity [rad/s or m/s].
        H: (n, 4, 4) world placements of the n tool frames [m].
        idx: (n, k) int, index of each arm's joint in the combined vector (padded with 0).
        nv_arm: (n,) int, joints per arm.
        support: (n, k) int, 1 where the joint moves the arm's tool.
        M: output (n, k, k) mass matrices, identity on padded dofs.
        nle: output (n, k) nonlinear effects, zero on padding.
        J: output (n, 6, k) LWA tool Jacobians (zero columns on padding and on joints that
            do not move the tool).
        Jdq: output (n, 6) classical tool accelerations at q̈ = 0 (world axes) [m/s², rad/s²].
        p: output (n, 3) tool positions [m].
        R: output (n, 3, 3) tool rotations (tool axes -> world).
        twist: output (n, 6) LWA tool twists [m/s, rad/s].
        vp: output (n, k) padded joint velocities.
    """
    n, k = idx.shape
    acc = np.empty(6)
    tw = np.empty(6)
    for i in range(n):
        nvi = nv_arm[i]
        px, py, pz = H[i, 0, 3], H[i, 1, 3], H[i, 2, 3]
        p[i, 0], p[i, 1], p[i, 2] = px, py, pz
        for a in range(3):
            for b in range(3):
                R[i, a, b] = H[i, a, b]
        for r in range(6):
            acc[r] = 0.0
            tw[r] = 0.0
        for a in range(k):
            if a < nvi:
                ia = idx[i, a]
                va = v[ia]
                vp[i, a] = va
                nle[i, a] = nle_full[ia]
                for b in range(k):
                    M[i, a, b] = M_full[ia, idx[i, b]] if b < nvi else 0.0
            else:
                va = 0.0
                vp[i, a] = 0.0
                nle[i, a] = 0.0
                for b in range(k):
                    M[i, a, b] = 1.0 if b == a else 0.0
            if a < nvi and support[i, a] != 0:
                ia = idx[i, a]
                wx, wy, wz = J_world[3, ia], J_world[4, ia], J_world[5, ia]
                # LWA column at the tool point: linear + ω × p
                J[i, 0, a] = J_world[0, ia] - (py * wz - pz * wy)
                J[i, 1, a] = J_world[1, ia] - (pz * wx - px * wz)
                J[i, 2, a] = J_world[2, ia] - (px * wy - py * wx)
                J[i, 3, a] = wx
                J[i, 4, a] = wy
                J[i, 5, a] = wz
                for r in range(6):
                    tw[r] += J[i, r, a] * va
                    acc[r] += dJ_world[r, ia] * va
            else:
                for r in range(6):
                    J[i, r, a] = 0.0
        for r in range(6):
            twist[i, r] = tw[r]
        # classical acceleration of the tool point: a_O + α × p + ω × v_p
        ax, ay, az = acc[3], acc[4], acc[5]
        ox, oy, oz = tw[3], tw[4], tw[5]
        Jdq[i, 0] = acc[0] + (ay * pz - az * py) + (oy * tw[2] - oz * tw[1])
        Jdq[i, 1] = acc[1] + (az * px - ax * pz) + (oz * tw[0] - ox * tw[2])
        Jdq[i, 2] = acc[2] + (ax * py - ay * px) + (ox * tw[1] - oy * tw[0])
        Jdq[i, 3], Jdq[i, 4], Jdq[i, 5] = ax, ay, az


__all__ = ["arm_terms"]
