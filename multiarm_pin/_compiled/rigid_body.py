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

_EPS = np.zeros((3, 3, 3))
_EPS[0, 1, 2] = _EPS[1, 2, 0] = _EPS[2, 0, 1] = 1.0
_EPS[0, 2, 1] = _EPS[2, 1, 0] = _EPS[1, 0, 2] = -1.0
"""Levi-Civita symbol: ``(a × b)_r = Σ ε_rst a_s b_t``, ``[a]ₓ[r, c] = Σ ε_rtc a_t``."""


@njit(cache=True, error_model="numpy")
def rigid_body_pass(model_ints, model_floats, q, v, J, dJ, M, nle,
                    H):  # pragma: no cover - compiled
    """Joint Jacobians and their derivative, mass matrix, nonlinear effects, tool placements.

    Equals, for the model the tables were built from, what Pinocchio leaves in its ``Data``
    after ``computeJointJacobiansTimeVariation(q, v)``, ``crba(q)``, ``nonLinearEffects(q, v)``
    and the tools' ``updateFramePlacement``.

    Written with few source operations in small loops, 6x6 spatial matrices and the
    Levi-Civita symbol rather than unrolled scalar algebra: numba's compile time grows with the
    number of operations written, not with the iterations run.

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
    rows = model_ints.shape[0]
    nj = rows - H.shape[0]
    T = np.zeros((rows, 4, 4))  # world placement of each joint frame and tool frame
    V = np.zeros((nj, 6))  # spatial velocity at the world origin
    A = np.zeros((nj, 6))  # bias acceleration at the world origin (q̈ = 0, gravity)
    F = np.zeros((nj, 6))  # Newton-Euler force, then with the subtree's
    Ic = np.zeros((nj, 6, 6))  # spatial inertia at the world origin, then composite
    X = np.zeros((3, 6, 6))  # local placement, V×, scratch
    y = np.zeros((2, 6))  # S (or I V), then I_c S
    for r in range(4):
        T[0, r, r] = 1.0
    for a in range(6):
        A[0, a] = -model_floats[0, MF_GRAVITY + a]
    # ---------------------------------------------------------------- forward pass
    for i in range(1, rows):
        par = model_ints[i, MI_PARENT]
        kind = model_ints[i, MI_KIND]
        iq = model_ints[i, MI_IDX_Q]
        ax = model_floats[i, MF_AXIS:MF_AXIS + 3]  # zero for a tool frame
        ca, sa, x = 1.0, 0.0, 0.0
        if kind == KIND_REVOLUTE:
            ca, sa = math.cos(q[iq]), math.sin(q[iq])
        elif kind == KIND_REVOLUTE_UNBOUNDED:  # [cos, sin] as stored, like Pinocchio
            ca, sa = q[iq], q[iq + 1]
        elif kind == KIND_PRISMATIC:
            x = q[iq]
        # the joint's motion [rj, a x] (rj by Pinocchio's toRotationMatrix:
        # (1 - cos) a aᵀ + cos 1 + sin [a]ₓ), then the placement times it, then the parent's
        for r in range(3):
            for c in range(4):
                s = ax[r] * x if c == 3 else (1.0 - ca) * ax[r] * ax[c] + (ca if r == c else 0.0)
                for t in range(3):
                    s += sa * _EPS[r, t, c % 3] * ax[t] if c < 3 else 0.0
                X[2, r, c] = s
        for r in range(3):
            for c in range(4):
                s = model_floats[i, MF_TRANSLATION + r] if c == 3 else 0.0
                for k in range(3):
                    s += model_floats[i, MF_ROTATION + 3 * r + k] * X[2, k, c]
                X[0, r, c] = s
        for r in range(3):
            for c in range(4):
                s = T[par, r, 3] if c == 3 else 0.0
                for k in range(3):
                    s += T[par, r, k] * X[0, k, c]
                T[i, r, c] = s
        T[i, 3, 3] = 1.0
        if i >= nj:  # a tool frame
            for r in range(4):
                for c in range(4):
                    H[i - nj, r, c] = T[i, r, c]
            continue
        iv = model_ints[i, MI_IDX_V]
        # S = [u; 0] (prismatic) or [p × u; u] with u = R a the world axis
        for r in range(3):
            u = T[i, r, 0] * ax[0] + T[i, r, 1] * ax[1] + T[i, r, 2] * ax[2]
            y[0, r + 3] = u
            y[0, r] = u
        for r in range(3):
            s = 0.0
            for k in range(3):
                for t in range(3):
                    s += _EPS[r, k, t] * T[i, k, 3] * y[0, 3 + t]
            y[0, r] = y[0, r] if kind == KIND_PRISMATIC else s
            y[0, r + 3] = 0.0 if kind == KIND_PRISMATIC else y[0, r + 3]
        qd = v[iv]
        for a in range(6):
            J[a, iv] = y[0, a]
            V[i, a] = V[par, a] + y[0, a] * qd
        # X[1] = V× = [[ω×, v×], [0, ω×]]; dS = V× S; a = a_parent + dS q̇
        for r in range(6):
            for c in range(6):
                s = 0.0
                for t in range(3):
                    s += _EPS[r % 3, t, c % 3] * V[i, t + (0 if r < 3 <= c else 3)]
                X[1, r, c] = 0.0 if c < 3 <= r else s
        for r in range(6):
            s = 0.0
            for c in range(6):
                s += X[1, r, c] * y[0, c]
            dJ[r, iv] = s
            A[i, r] = A[par, r] + s * qd
        # spatial inertia at the world origin: [[m 1, -m [c]ₓ], [m [c]ₓ, R I_c Rᵀ - m [c]ₓ²]]
        m = model_floats[i, MF_MASS]
        for r in range(3):  # X[2, 0] = com, X[2, 1:4, :3] = R I_c
            s = T[i, r, 3]
            for k in range(3):
                s += T[i, r, k] * model_floats[i, MF_LEVER + k]
            X[2, 0, r] = s
            for c in range(3):
                s = 0.0
                for k in range(3):
                    s += T[i, r, k] * model_floats[i, MF_INERTIA + 3 * k + c]
                X[2, 1 + r, c] = s
        for r in range(3):  # X[0, :3, :3] = [c]ₓ
            for c in range(3):
                s = 0.0
                for t in range(3):
                    s += _EPS[r, t, c] * X[2, 0, t]
                X[0, r, c] = s
        for r in range(3):
            for c in range(3):
                s = 0.0
                for k in range(3):
                    s += X[2, 1 + r, k] * T[i, c, k] - m * X[0, r, k] * X[0, k, c]
                Ic[i, 3 + r, 3 + c] = s
                Ic[i, r, c] = m if r == c else 0.0
                Ic[i, 3 + r, c] = m * X[0, r, c]
                Ic[i, r, 3 + c] = -m * X[0, r, c]
        # f = I a + V ×* (I V), with V ×* = -(V×)ᵀ
        for r in range(6):
            s = 0.0
            for c in range(6):
                s += Ic[i, r, c] * V[i, c]
            y[1, r] = s
        for r in range(6):
            s = 0.0
            for c in range(6):
                s += Ic[i, r, c] * A[i, c] - X[1, c, r] * y[1, c]
            F[i, r] = s
    # ---------------------------------------------------------------- backward pass
    for i in range(nj - 1, 0, -1):
        par = model_ints[i, MI_PARENT]
        iv = model_ints[i, MI_IDX_V]
        s = 0.0
        for a in range(6):
            s += J[a, iv] * F[i, a]
        nle[iv] = s
        for r in range(6):  # I_c S, the composite inertia of the subtree times S
            s = 0.0
            for c in range(6):
                s += Ic[i, r, c] * J[c, iv]
            y[1, r] = s
        j = i
        while j > 0:  # M[j, i] = S_jᵀ I_c S_i for i and each of its ancestors j
            jv = model_ints[j, MI_IDX_V]
            s = model_floats[i, MF_ARMATURE] if j == i else 0.0
            for a in range(6):
                s += J[a, jv] * y[1, a]
            M[jv, iv] = s
            M[iv, jv] = s
            j = model_ints[j, MI_PARENT]
        if par > 0:
            for r in range(6):
                F[par, r] += F[i, r]
                for c in range(6):
                    Ic[par, r, c] += Ic[i, r, c]


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
