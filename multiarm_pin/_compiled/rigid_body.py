"""Compiled rigid-body pass: the Pinocchio calls of an evaluation, callable from other kernels.

Mirrors :meth:`multiarm_pin.model.arm_set.ArmSet.pinocchio_pass` (the reference, Pinocchio's
``computeJointJacobiansTimeVariation``, ``crba``, ``nonLinearEffects`` and
``updateFramePlacement`` of each tool) on the tables of
:class:`~multiarm_pin.model.compiled_model.CompiledModel` (layout in
:mod:`multiarm_pin._compiled.layout`: ``MI_*``, ``MF_*``, ``KIND_*``), and Pinocchio's
``integrate`` / ``difference`` for the supported joints.

One forward pass over the joints (parents before children, Pinocchio's order) computes, in
world axes and at the world origin, each joint's placement, motion-subspace column ``S``
(``J``), its time derivative ``V × S`` (``dJ``), the body's spatial velocity ``V``, its bias
acceleration ``a`` (Newton-Euler with ``q̈ = 0``, the base accelerating at ``-g``), its spatial
inertia and the force ``f = I a + V ×* I V``. One backward pass projects the forces
(``nle = Sᵀ f``) and the composite inertias (CRBA: ``M[j, i] = S_jᵀ I_i^c S_i`` for every
ancestor ``j`` of ``i``) and accumulates both into the parents. A spatial inertia at the world
origin is stored as mass ``m``, first moment ``h = m c`` and rotational inertia about the
origin ``I_O``; it maps a motion ``[v; ω]`` to ``[m v - h × ω; h × v + I_O ω]``. Spatial
vectors are ``[linear; angular]`` as in Pinocchio.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from multiarm_pin._compiled.layout import (
    KIND_PRISMATIC,
    KIND_REVOLUTE,
    KIND_REVOLUTE_UNBOUNDED,
    MF_ARMATURE,
    MF_AXIS,
    MF_GRAVITY,
    MF_INERTIA,
    MF_LEVER,
    MF_MASS,
    MF_ROTATION,
    MF_TRANSLATION,
    MI_IDX_Q,
    MI_IDX_V,
    MI_KIND,
    MI_PARENT,
)

# per-joint work columns of rigid_body_pass (private to this kernel)
_W_R = 0  # world rotation of the joint frame (9, row-major)
_W_P = 9  # world position of the joint origin (3)
_W_V = 12  # spatial velocity at the world origin (6)
_W_A = 18  # bias spatial acceleration at the world origin, q̈ = 0, gravity included (6)
_W_F = 24  # Newton-Euler force at the world origin, then with the subtree's (6)
_W_M = 30  # mass of the body, then of the subtree (composite)
_W_H = 31  # first moment m c about the world origin (3)
_W_I = 34  # rotational inertia about the world origin (9, row-major)
_W_SIZE = 43


@njit(cache=True, error_model="numpy")
def rigid_body_pass(model_ints, model_floats, q, v, J, dJ, M, nle,
                    H):  # pragma: no cover - compiled
    """Joint Jacobians and their derivative, mass matrix, nonlinear effects, tool placements.

    Equals, for the model the tables were built from, what Pinocchio leaves in its ``Data``
    after ``computeJointJacobiansTimeVariation(q, v)``, ``crba(q)``, ``nonLinearEffects(q, v)``
    and the tools' ``updateFramePlacement``.

    Args:
        model_ints: (njoints + n_tools, MODEL_INTS) int64, columns ``MI_*``: rows ``0..njoints-1``
            the joints (row 0 the universe), then one row per tool frame.
        model_floats: (njoints + n_tools, MODEL_FLOATS) float64, columns ``MF_*``.
        q: (nq,) configuration [rad, m; ``[cos θ, sin θ]`` for a continuous joint].
        v: (nv,) velocity [rad/s, m/s].
        J: output (6, nv) joint Jacobian columns ``[v; ω]`` at the world origin, world axes
            (``data.J``).
        dJ: output (6, nv) their time derivative, same frame (``data.dJ``).
        M: output (nv, nv) mass matrix, both triangles (``data.M`` after ``crba``, armature
            on the diagonal) [kg m², kg]. Only the entries of joint pairs of which one
            supports the other are written: the caller keeps the others zero (between arms,
            between branches of one tree).
        nle: output (nv,) nonlinear effects ``C(q, v) v + g(q)`` [N m, N] (``data.nle``).
        H: output (n_tools, 4, 4) world placements of the tool frames [m]; ``n_tools`` is
            read from its first axis.
    """
    n_tools = H.shape[0]
    nj = model_ints.shape[0] - n_tools
    w = np.zeros((nj, _W_SIZE))
    rot = np.empty((3, 3))  # joint placement rotation times the joint's own rotation
    rj = np.empty((3, 3))  # the joint's own rotation
    S = np.empty(6)
    F = np.empty(6)
    com = np.empty(3)
    w[0, _W_R] = w[0, _W_R + 4] = w[0, _W_R + 8] = 1.0
    for a in range(6):
        w[0, _W_A + a] = -model_floats[0, MF_GRAVITY + a]
    # ---------------------------------------------------------------- forward pass
    for i in range(1, nj):
        par = model_ints[i, MI_PARENT]
        kind = model_ints[i, MI_KIND]
        iq = model_ints[i, MI_IDX_Q]
        iv = model_ints[i, MI_IDX_V]
        wi = w[i]
        wp = w[par]
        fl = model_floats[i]
        ax, ay, az = fl[MF_AXIS], fl[MF_AXIS + 1], fl[MF_AXIS + 2]
        # the joint's own rotation (Pinocchio's toRotationMatrix for revolute joints)
        if kind == KIND_PRISMATIC:
            for r in range(3):
                for c in range(3):
                    rj[r, c] = 1.0 if r == c else 0.0
        else:
            if kind == KIND_REVOLUTE:
                ca, sa = math.cos(q[iq]), math.sin(q[iq])
            else:  # KIND_REVOLUTE_UNBOUNDED: [cos, sin] as stored, like Pinocchio
                ca, sa = q[iq], q[iq + 1]
            t = 1.0 - ca
            rj[0, 0] = t * ax * ax + ca
            rj[1, 1] = t * ay * ay + ca
            rj[2, 2] = t * az * az + ca
            rj[0, 1] = t * ax * ay - sa * az
            rj[1, 0] = t * ax * ay + sa * az
            rj[0, 2] = t * ax * az + sa * ay
            rj[2, 0] = t * ax * az - sa * ay
            rj[1, 2] = t * ay * az - sa * ax
            rj[2, 1] = t * ay * az + sa * ax
        for r in range(3):
            for c in range(3):
                rot[r, c] = (fl[MF_ROTATION + 3 * r] * rj[0, c]
                             + fl[MF_ROTATION + 3 * r + 1] * rj[1, c]
                             + fl[MF_ROTATION + 3 * r + 2] * rj[2, c])
        for r in range(3):
            for c in range(3):
                wi[_W_R + 3 * r + c] = (wp[_W_R + 3 * r] * rot[0, c]
                                        + wp[_W_R + 3 * r + 1] * rot[1, c]
                                        + wp[_W_R + 3 * r + 2] * rot[2, c])
            wi[_W_P + r] = wp[_W_P + r] + (wp[_W_R + 3 * r] * fl[MF_TRANSLATION]
                                           + wp[_W_R + 3 * r + 1] * fl[MF_TRANSLATION + 1]
                                           + wp[_W_R + 3 * r + 2] * fl[MF_TRANSLATION + 2])
        # world axis (the joint's rotation leaves its axis unchanged)
        ux = wi[_W_R] * ax + wi[_W_R + 1] * ay + wi[_W_R + 2] * az
        uy = wi[_W_R + 3] * ax + wi[_W_R + 4] * ay + wi[_W_R + 5] * az
        uz = wi[_W_R + 6] * ax + wi[_W_R + 7] * ay + wi[_W_R + 8] * az
        if kind == KIND_PRISMATIC:
            x = q[iq]
            wi[_W_P] += ux * x
            wi[_W_P + 1] += uy * x
            wi[_W_P + 2] += uz * x
            S[0], S[1], S[2], S[3], S[4], S[5] = ux, uy, uz, 0.0, 0.0, 0.0
        else:  # rotation about the axis through the joint origin p: [p × u; u]
            px, py, pz = wi[_W_P], wi[_W_P + 1], wi[_W_P + 2]
            S[0], S[1], S[2] = py * uz - pz * uy, pz * ux - px * uz, px * uy - py * ux
            S[3], S[4], S[5] = ux, uy, uz
        qd = v[iv]
        for a in range(6):
            J[a, iv] = S[a]
            wi[_W_V + a] = wp[_W_V + a] + S[a] * qd
        # dS = V × S (motion cross product), and the bias acceleration a = a_parent + dS q̇
        vx, vy, vz = wi[_W_V], wi[_W_V + 1], wi[_W_V + 2]
        ox, oy, oz = wi[_W_V + 3], wi[_W_V + 4], wi[_W_V + 5]
        d0 = oy * S[2] - oz * S[1] + vy * S[5] - vz * S[4]
        d1 = oz * S[0] - ox * S[2] + vz * S[3] - vx * S[5]
        d2 = ox * S[1] - oy * S[0] + vx * S[4] - vy * S[3]
        d3 = oy * S[5] - oz * S[4]
        d4 = oz * S[3] - ox * S[5]
        d5 = ox * S[4] - oy * S[3]
        dJ[0, iv], dJ[1, iv], dJ[2, iv] = d0, d1, d2
        dJ[3, iv], dJ[4, iv], dJ[5, iv] = d3, d4, d5
        wi[_W_A] = wp[_W_A] + d0 * qd
        wi[_W_A + 1] = wp[_W_A + 1] + d1 * qd
        wi[_W_A + 2] = wp[_W_A + 2] + d2 * qd
        wi[_W_A + 3] = wp[_W_A + 3] + d3 * qd
        wi[_W_A + 4] = wp[_W_A + 4] + d4 * qd
        wi[_W_A + 5] = wp[_W_A + 5] + d5 * qd
        # the body's spatial inertia at the world origin: m, h = m c, I_O = R I_c Rᵀ + m [c]ₓᵀ[c]ₓ
        m = fl[MF_MASS]
        for r in range(3):
            com[r] = wi[_W_P + r] + (wi[_W_R + 3 * r] * fl[MF_LEVER]
                                     + wi[_W_R + 3 * r + 1] * fl[MF_LEVER + 1]
                                     + wi[_W_R + 3 * r + 2] * fl[MF_LEVER + 2])
            for c in range(3):  # rot <- R I_c
                rot[r, c] = (wi[_W_R + 3 * r] * fl[MF_INERTIA + c]
                             + wi[_W_R + 3 * r + 1] * fl[MF_INERTIA + 3 + c]
                             + wi[_W_R + 3 * r + 2] * fl[MF_INERTIA + 6 + c])
        c2 = com[0] * com[0] + com[1] * com[1] + com[2] * com[2]
        for r in range(3):
            for c in range(3):
                wi[_W_I + 3 * r + c] = (rot[r, 0] * wi[_W_R + 3 * c]
                                        + rot[r, 1] * wi[_W_R + 3 * c + 1]
                                        + rot[r, 2] * wi[_W_R + 3 * c + 2]
                                        - m * com[r] * com[c])
            wi[_W_I + 4 * r] += m * c2
        wi[_W_M] = m
        hx, hy, hz = m * com[0], m * com[1], m * com[2]
        wi[_W_H], wi[_W_H + 1], wi[_W_H + 2] = hx, hy, hz
        # f = I a + V ×* (I V)
        for pass_ in range(2):
            base = _W_A if pass_ == 0 else _W_V
            lx, ly, lz = wi[base], wi[base + 1], wi[base + 2]
            gx, gy, gz = wi[base + 3], wi[base + 4], wi[base + 5]
            f0 = m * lx - (hy * gz - hz * gy)
            f1 = m * ly - (hz * gx - hx * gz)
            f2 = m * lz - (hx * gy - hy * gx)
            n0 = hy * lz - hz * ly + wi[_W_I] * gx + wi[_W_I + 1] * gy + wi[_W_I + 2] * gz
            n1 = hz * lx - hx * lz + wi[_W_I + 3] * gx + wi[_W_I + 4] * gy + wi[_W_I + 5] * gz
            n2 = hx * ly - hy * lx + wi[_W_I + 6] * gx + wi[_W_I + 7] * gy + wi[_W_I + 8] * gz
            if pass_ == 0:
                wi[_W_F], wi[_W_F + 1], wi[_W_F + 2] = f0, f1, f2
                wi[_W_F + 3], wi[_W_F + 4], wi[_W_F + 5] = n0, n1, n2
            else:  # [v; ω] ×* [f; n] = [ω × f; v × f + ω × n]
                wi[_W_F] += oy * f2 - oz * f1
                wi[_W_F + 1] += oz * f0 - ox * f2
                wi[_W_F + 2] += ox * f1 - oy * f0
                wi[_W_F + 3] += vy * f2 - vz * f1 + oy * n2 - oz * n1
                wi[_W_F + 4] += vz * f0 - vx * f2 + oz * n0 - ox * n2
                wi[_W_F + 5] += vx * f1 - vy * f0 + ox * n1 - oy * n0
    # ---------------------------------------------------------------- backward pass
    for i in range(nj - 1, 0, -1):
        par = model_ints[i, MI_PARENT]
        iv = model_ints[i, MI_IDX_V]
        wi = w[i]
        for a in range(6):
            S[a] = J[a, iv]
        tau = 0.0
        for a in range(6):
            tau += S[a] * wi[_W_F + a]
        nle[iv] = tau
        # F = I_c S (composite inertia of the subtree of i)
        m = wi[_W_M]
        hx, hy, hz = wi[_W_H], wi[_W_H + 1], wi[_W_H + 2]
        F[0] = m * S[0] - (hy * S[5] - hz * S[4])
        F[1] = m * S[1] - (hz * S[3] - hx * S[5])
        F[2] = m * S[2] - (hx * S[4] - hy * S[3])
        for r in range(3):
            F[3 + r] = (wi[_W_I + 3 * r] * S[3] + wi[_W_I + 3 * r + 1] * S[4]
                        + wi[_W_I + 3 * r + 2] * S[5])
        F[3] += hy * S[2] - hz * S[1]
        F[4] += hz * S[0] - hx * S[2]
        F[5] += hx * S[1] - hy * S[0]
        mii = model_floats[i, MF_ARMATURE]
        for a in range(6):
            mii += S[a] * F[a]
        M[iv, iv] = mii
        j = par
        while j > 0:
            jv = model_ints[j, MI_IDX_V]
            mji = 0.0
            for a in range(6):
                mji += J[a, jv] * F[a]
            M[jv, iv] = mji
            M[iv, jv] = mji
            j = model_ints[j, MI_PARENT]
        if par > 0:
            wp = w[par]
            for a in range(6):
                wp[_W_F + a] += wi[_W_F + a]
            for a in range(13):
                wp[_W_M + a] += wi[_W_M + a]
    # ---------------------------------------------------------------- tool frames
    for t in range(n_tools):
        row = nj + t
        wp = w[model_ints[row, MI_PARENT]]
        fl = model_floats[row]
        for r in range(3):
            for c in range(3):
                H[t, r, c] = (wp[_W_R + 3 * r] * fl[MF_ROTATION + c]
                              + wp[_W_R + 3 * r + 1] * fl[MF_ROTATION + 3 + c]
                              + wp[_W_R + 3 * r + 2] * fl[MF_ROTATION + 6 + c])
            H[t, r, 3] = wp[_W_P + r] + (wp[_W_R + 3 * r] * fl[MF_TRANSLATION]
                                         + wp[_W_R + 3 * r + 1] * fl[MF_TRANSLATION + 1]
                                         + wp[_W_R + 3 * r + 2] * fl[MF_TRANSLATION + 2])
            H[t, 3, r] = 0.0
        H[t, 3, 3] = 1.0


@njit(cache=True, error_model="numpy")
def integrate(model_ints, q, dv, out):  # pragma: no cover - compiled
    """``out = q ⊕ dv``, equal to ``pin.integrate(model, q, dv)`` for the supported joints.

    A continuous joint's ``[cos, sin]`` is rotated by ``dv`` then brought back near the unit
    circle by Pinocchio's first-order normalisation (factor ``(3 - |z|²) / 2``).

    Args:
        model_ints: (rows, MODEL_INTS) int64 model table (``MI_*``); frame rows are skipped.
        q: (nq,) configuration.
        dv: (nv,) tangent increment [rad, m].
        out: output (nq,) (may be ``q`` itself).
    """
    for i in range(model_ints.shape[0]):
        kind = model_ints[i, MI_KIND]
        iq = model_ints[i, MI_IDX_Q]
        iv = model_ints[i, MI_IDX_V]
        if kind == KIND_REVOLUTE or kind == KIND_PRISMATIC:
            out[iq] = q[iq] + dv[iv]
        elif kind == KIND_REVOLUTE_UNBOUNDED:
            ca, sa = q[iq], q[iq + 1]
            cw, sw = math.cos(dv[iv]), math.sin(dv[iv])
            c1 = cw * ca - sw * sa
            s1 = sw * ca + cw * sa
            scale = (3.0 - (c1 * c1 + s1 * s1)) / 2.0
            out[iq] = c1 * scale
            out[iq + 1] = s1 * scale


@njit(cache=True, error_model="numpy")
def difference(model_ints, q0, q1, out):  # pragma: no cover - compiled
    """``out = q1 ⊖ q0``, equal to ``pin.difference(model, q0, q1)`` for the supported joints.

    A continuous joint's difference is the angle of ``z0* z1`` in ``(-π, π]``.

    Args:
        model_ints: (rows, MODEL_INTS) int64 model table (``MI_*``); frame rows are skipped.
        q0: (nq,) start configuration.
        q1: (nq,) end configuration.
        out: output (nv,) tangent vector [rad, m].
    """
    for i in range(model_ints.shape[0]):
        kind = model_ints[i, MI_KIND]
        iq = model_ints[i, MI_IDX_Q]
        iv = model_ints[i, MI_IDX_V]
        if kind == KIND_REVOLUTE or kind == KIND_PRISMATIC:
            out[iv] = q1[iq] - q0[iq]
        elif kind == KIND_REVOLUTE_UNBOUNDED:
            c0, s0, c1, s1 = q0[iq], q0[iq + 1], q1[iq], q1[iq + 1]
            out[iv] = math.atan2(c0 * s1 - s0 * c1, c0 * c1 + s0 * s1)
