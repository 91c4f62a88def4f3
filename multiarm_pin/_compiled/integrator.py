"""Compiled integration of the loop's state vector: its tangent, an RK4 stage, a semi-implicit step.

Mirrors :class:`multiarm_pin.sim.stepper.Stepper`'s ``derivative`` (:func:`tangent`),
``advance`` (:func:`advance`: the state moved along a tangent, as RK4's stages and its final
combination take it) and the semi-implicit branch of its ``step``
(:func:`advance_semi_implicit`), for :mod:`multiarm_pin._compiled.contact_loop`.

State vector ``x``: the kernels' (:func:`~multiarm_pin._compiled.layout.state_vector`), object
state, ``q``, ``v`` and ``τ`` (zero: the blocks are made at zero torque). Tangent ``d``
(2 nv + 13,): ``[q̇; v̇; ṗ; q̇uat; ȧ]`` as ``Stepper.derivative``.
"""

from __future__ import annotations

import math

from multiarm_pin._compiled.evaluate import quaternion_rotation
from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.layout import OBJECT_STATE_SIZE, X_POSITION, X_QUATERNION, X_TWIST
from multiarm_pin._compiled.rigid_body import integrate


@kernel
def tangent(x, nv, nv_arm, v_starts, qdd, a_o, d):  # pragma: no cover - compiled
    """The tangent ``d`` (2 nv + 13,) ``[q̇; v̇; ṗ; q̇uat; ȧ]`` of ``x`` (``Stepper.derivative``).

    Args:
        x: the state vector.
        nv: joints.
        nv_arm: (n,) int joints per arm.
        v_starts: (n,) int first joint of each arm in ``v``.
        qdd: (n, k) the arms' accelerations, padded.
        a_o: (6,) the object's acceleration.
        d: output.
    """
    v0 = x.shape[0] - 2 * nv
    for j in range(nv):
        d[j] = x[v0 + j]
    for i in range(nv_arm.shape[0]):
        for a in range(nv_arm[i]):
            d[nv + v_starts[i] + a] = qdd[i, a]
    tw = x[X_TWIST:X_TWIST + 6]
    qx, qy, qz, qw = x[X_QUATERNION], x[X_QUATERNION + 1], x[X_QUATERNION + 2], x[X_QUATERNION + 3]
    wx, wy, wz = tw[3], tw[4], tw[5]
    b = 2 * nv
    d[b], d[b + 1], d[b + 2] = tw[0], tw[1], tw[2]
    d[b + 3] = 0.5 * (qw * wx + wy * qz - wz * qy)
    d[b + 4] = 0.5 * (qw * wy + wz * qx - wx * qz)
    d[b + 5] = 0.5 * (qw * wz + wx * qy - wy * qx)
    d[b + 6] = 0.5 * -(wx * qx + wy * qy + wz * qz)
    for a in range(6):
        d[b + 7 + a] = a_o[a]


@kernel(refcounts=False)
def advance(model_ints, x, d, h, hd, out):  # pragma: no cover - compiled
    """The state ``h`` [s] along the tangent ``d`` into ``out`` (``Stepper.advance``)."""
    nv = (d.shape[0] - OBJECT_STATE_SIZE) // 2
    nq = x.shape[0] - OBJECT_STATE_SIZE - 2 * nv
    for a in range(d.shape[0]):
        hd[a] = h * d[a]
    q0 = OBJECT_STATE_SIZE
    integrate(model_ints, x[q0:q0 + nq], hd[:nv], out[q0:q0 + nq])
    v0 = q0 + nq
    for j in range(nv):
        out[v0 + j] = x[v0 + j] + hd[nv + j]
        out[v0 + nv + j] = 0.0  # τ
    b = 2 * nv
    for a in range(3):
        out[a] = x[a] + hd[b + a]
    s = 0.0
    for a in range(4):
        out[X_QUATERNION + a] = x[X_QUATERNION + a] + hd[b + 3 + a]
    for a in range(4):
        s += out[X_QUATERNION + a] * out[X_QUATERNION + a]
    s = math.sqrt(s)
    for a in range(4):
        out[X_QUATERNION + a] /= s
    for a in range(6):
        out[X_TWIST + a] = x[X_TWIST + a] + hd[b + 7 + a]


@kernel
def advance_semi_implicit(model_ints, x, d, h, v_new, R, out):  # pragma: no cover - compiled
    """One semi-implicit Euler step ``h`` [s] of ``x`` with the tangent ``d`` into ``out``.

    ``Stepper.step``'s semi-implicit branch: velocities first (``v + h q̈``, twist ``+ h a``),
    then the configuration with the new velocities (the arms' by ``integrate``, the position
    ``+ h ẋ``, the orientation by the exact exponential of ``h ω``:
    :func:`~multiarm_pin.spatial.integrate_quaternion`, its Rodrigues formula and Eigen's
    rotation-to-quaternion conversion, ``w >= 0``). ``v_new`` (nv,) and ``R`` (3, 3) are
    workspaces.
    """
    nv = v_new.shape[0]
    nq = x.shape[0] - OBJECT_STATE_SIZE - 2 * nv
    q0 = OBJECT_STATE_SIZE
    v0 = q0 + nq
    b = 2 * nv
    for j in range(nv):
        v_new[j] = x[v0 + j] + h * d[nv + j]
        out[v0 + nv + j] = 0.0  # τ
    for a in range(6):
        out[X_TWIST + a] = x[X_TWIST + a] + h * d[b + 7 + a]
    for j in range(nv):
        out[v0 + j] = v_new[j]
        v_new[j] = h * v_new[j]
    integrate(model_ints, x[q0:q0 + nq], v_new, out[q0:q0 + nq])
    for a in range(3):
        out[X_POSITION + a] = x[X_POSITION + a] + h * out[X_TWIST + a]
    # dR = exp3(h ω) (Rodrigues; its Taylor series near zero), then dR R(quat)
    wx, wy, wz = out[X_TWIST + 3] * h, out[X_TWIST + 4] * h, out[X_TWIST + 5] * h
    t2 = wx * wx + wy * wy + wz * wz
    if t2 > 1e-8:
        t = math.sqrt(t2)
        ct, st = math.cos(t), math.sin(t)
        a_vx, a_vxvx = st / t, (1.0 - ct) / t2
    else:
        ct = 1.0 - t2 / 2.0
        a_vx, a_vxvx = 1.0 - t2 / 6.0, 0.5 - t2 / 24.0
    dR00, dR11, dR22 = ct + a_vxvx * wx * wx, ct + a_vxvx * wy * wy, ct + a_vxvx * wz * wz
    dR01, dR10 = a_vxvx * wx * wy - a_vx * wz, a_vxvx * wx * wy + a_vx * wz
    dR02, dR20 = a_vxvx * wx * wz + a_vx * wy, a_vxvx * wx * wz - a_vx * wy
    dR12, dR21 = a_vxvx * wy * wz - a_vx * wx, a_vxvx * wy * wz + a_vx * wx
    quaternion_rotation(x[X_QUATERNION:X_QUATERNION + 4], R)
    m = R  # dR R, column by column in place (each column of the product needs its own)
    for c in range(3):
        r0, r1, r2 = R[0, c], R[1, c], R[2, c]
        m[0, c] = dR00 * r0 + dR01 * r1 + dR02 * r2
        m[1, c] = dR10 * r0 + dR11 * r1 + dR12 * r2
        m[2, c] = dR20 * r0 + dR21 * r1 + dR22 * r2
    o = X_QUATERNION  # Eigen's Quaternion(Matrix3) (as pin.Quaternion), then w >= 0
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0.0:
        t = math.sqrt(tr + 1.0)
        out[o + 3] = 0.5 * t
        t = 0.5 / t
        out[o] = (m[2, 1] - m[1, 2]) * t
        out[o + 1] = (m[0, 2] - m[2, 0]) * t
        out[o + 2] = (m[1, 0] - m[0, 1]) * t
    else:
        i = 0
        if m[1, 1] > m[0, 0]:
            i = 1
        if m[2, 2] > m[i, i]:
            i = 2
        j = (i + 1) % 3
        k = (j + 1) % 3
        t = math.sqrt(m[i, i] - m[j, j] - m[k, k] + 1.0)
        out[o + i] = 0.5 * t
        t = 0.5 / t
        out[o + 3] = (m[k, j] - m[j, k]) * t
        out[o + j] = (m[j, i] + m[i, j]) * t
        out[o + k] = (m[k, i] + m[i, k]) * t
    if out[o + 3] < 0.0:
        for a in range(4):
            out[o + a] = -out[o + a]


__all__ = ["advance", "advance_semi_implicit", "tangent"]
