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
ancestor ``j`` of ``i``) and accumulates both into the parents; the tool frames' rows follow
the joints' in the forward pass. A spatial inertia at the world origin is the 6x6 matrix
``[[m 1, -m [c]ₓ], [m [c]ₓ, I_O]]`` (``c`` the COM, ``I_O`` the rotational inertia about the
origin). Spatial vectors are ``[linear; angular]`` as in Pinocchio.

Cost: one work array of ``(rows + 2, 68)`` floats allocated per call (its time per joint
and its compile time: ``benchmarks/rigid_body_pass.py``).
"""

from __future__ import annotations

import math

import numpy as np

from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.layout import (
    EN_KINETIC,
    EN_MOMENTUM,
    EN_POTENTIAL,
    KIND_PRISMATIC,
    KIND_REVOLUTE,
    KIND_REVOLUTE_UNBOUNDED,
    MF_ARMATURE,
    MF_AXIS,
    MF_GRAVITY,
    MF_INERTIA,
    MF_LEVER,
    MF_MASS,
    MF_PLACEMENT,
    MI_IDX_Q,
    MI_IDX_V,
    MI_KIND,
    MI_PARENT,
)

_EPS = np.zeros((3, 3, 3))
_EPS[0, 1, 2] = _EPS[1, 2, 0] = _EPS[2, 0, 1] = 1.0
_EPS[0, 2, 1] = _EPS[2, 1, 0] = _EPS[1, 0, 2] = -1.0
"""Levi-Civita symbol: ``(a × b)_r = Σ ε_rst a_s b_t``, ``[a]ₓ[r, c] = Σ ε_rtc a_t``."""

# columns of the work array of rigid_body_pass, one row per joint or tool frame (private)
_T = 0  # world placement [R | p] (3x4, row-major)
_V = 12  # spatial velocity at the world origin (6)
_A = 18  # bias acceleration at the world origin, q̈ = 0, gravity included (6)
_F = 24  # Newton-Euler force, then with the subtree's (6)
_I = 30  # spatial inertia at the world origin (6x6), then composite; ends the F + I span
_WIDTH = 68
# first scratch row (index rows): joint motion and local placement (4x4, last row 0 0 0 1), V×
_JM = 0
_LOC = 16
_X = 32
# second scratch row (rows + 1): S, 6-vector y, world axis or COM, [c]ₓ, R I_c
_S = 0
_Y = 6
_U = 12
_CX = 15
_RI = 24


@kernel
def rigid_body_pass(model_ints, model_floats, q, v, J, dJ, M, nle, H,
                    energy):  # pragma: no cover - compiled
    """Joint Jacobians and their derivative, mass matrix, nonlinear effects, tool placements.

    Equals, for the model the tables were built from, what Pinocchio leaves in its ``Data``
    after ``computeJointJacobiansTimeVariation(q, v)``, ``crba(q)``, ``nonLinearEffects(q, v)``
    and the tools' ``updateFramePlacement``.

    Written with few source operations in small loops over one work array, 6x6 spatial
    matrices and the Levi-Civita symbol rather than unrolled scalar algebra: numba's compile
    time grows with the operations written, not with the iterations run.

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
        energy: output (ENERGY_SIZE,) (``ENERGY_FIELDS``): kinetic energy ``½ Σ Vᵀ I V``
            and potential energy ``-Σ m g·c`` of all bodies [J] (Pinocchio's
            ``computeKineticEnergy``, ``computePotentialEnergy``), and their total momentum
            ``Σ I V`` ``[linear; angular about the world origin]`` [kg m/s, kg m²/s]; or
            an empty array: not computed (the open-loop step, which does not record them,
            saves ~2% of the pass).
    """
    rows = model_ints.shape[0]
    nj = rows - H.shape[0]
    W = np.empty((rows + 2, _WIDTH))
    s1, s2 = rows, rows + 1
    for k in range(16):  # identities: the universe's placement, the scratch 4x4s' last rows
        e = 1.0 if k % 5 == 0 else 0.0
        W[s1, _JM + k] = e
        W[s1, _LOC + k] = e
        W[0, _T + k % 12] = 1.0 if k % 12 % 5 == 0 else 0.0
    record = energy.shape[0] != 0  # an empty array: the energies are not wanted
    for a in range(energy.shape[0]):
        energy[a] = 0.0
    for a in range(6):
        W[0, _V + a] = 0.0
        W[0, _A + a] = -model_floats[0, MF_GRAVITY + a]
    # ---------------------------------------------------------------- forward pass
    for i in range(1, rows):
        par = model_ints[i, MI_PARENT]
        kind = model_ints[i, MI_KIND]
        iq = model_ints[i, MI_IDX_Q]
        ca, sa, x = 1.0, 0.0, 0.0  # a tool frame or a prismatic joint: no rotation
        if kind == KIND_REVOLUTE:
            ca, sa = math.cos(q[iq]), math.sin(q[iq])
        elif kind == KIND_REVOLUTE_UNBOUNDED:  # [cos, sin] as stored, like Pinocchio
            ca, sa = q[iq], q[iq + 1]
        elif kind == KIND_PRISMATIC:
            x = q[iq]
        # joint motion [(1 - cos) a aᵀ + cos 1 + sin [a]ₓ | a x] (Pinocchio's toRotationMatrix),
        # then local = placement · motion and the world placement parent · local
        for k in range(3):
            W[s1, _JM + 4 * k + 3] = model_floats[i, MF_AXIS + k] * x
            for c in range(3):
                s = ((1.0 - ca) * model_floats[i, MF_AXIS + k] * model_floats[i, MF_AXIS + c]
                     + (ca if k == c else 0.0))
                for t in range(3):
                    s += sa * _EPS[k, t, c] * model_floats[i, MF_AXIS + t]
                W[s1, _JM + 4 * k + c] = s
        for r in range(3):
            for c in range(4):
                s = 0.0
                for k in range(4):
                    s += model_floats[i, MF_PLACEMENT + 4 * r + k] * W[s1, _JM + 4 * k + c]
                W[s1, _LOC + 4 * r + c] = s
        for r in range(3):
            for c in range(4):
                s = 0.0
                for k in range(4):
                    s += W[par, _T + 4 * r + k] * W[s1, _LOC + 4 * k + c]
                W[i, _T + 4 * r + c] = s
        if i >= nj:  # a tool frame
            for k in range(16):
                H[i - nj, k // 4, k % 4] = W[i, _T + k] if k < 12 else W[s1, _JM + k]
            continue
        iv = model_ints[i, MI_IDX_V]
        # S = [u; 0] (prismatic) or [p × u; u] with u = R a the world axis
        rev = 0.0 if kind == KIND_PRISMATIC else 1.0
        for r in range(3):
            s = 0.0
            for k in range(3):
                s += W[i, _T + 4 * r + k] * model_floats[i, MF_AXIS + k]
            W[s2, _U + r] = s
        for r in range(3):
            s = 0.0
            for k in range(3):
                for t in range(3):
                    s += _EPS[r, k, t] * W[i, _T + 4 * k + 3] * W[s2, _U + t]
            W[s2, _S + r] = rev * s + (1.0 - rev) * W[s2, _U + r]
            W[s2, _S + 3 + r] = rev * W[s2, _U + r]
        qd = v[iv]
        for a in range(6):
            J[a, iv] = W[s2, _S + a]
            W[i, _V + a] = W[par, _V + a] + W[s2, _S + a] * qd
        # V× = [[ω×, v×], [0, ω×]]; dS = V× S; a = a_parent + dS q̇
        for r in range(3):
            for c in range(3):
                wx, vx = 0.0, 0.0
                for t in range(3):
                    wx += _EPS[r, t, c] * W[i, _V + 3 + t]
                    vx += _EPS[r, t, c] * W[i, _V + t]
                W[s1, _X + 6 * r + c] = wx
                W[s1, _X + 6 * r + 3 + c] = vx
                W[s1, _X + 6 * (3 + r) + c] = 0.0
                W[s1, _X + 6 * (3 + r) + 3 + c] = wx
        for r in range(6):
            s = 0.0
            for c in range(6):
                s += W[s1, _X + 6 * r + c] * W[s2, _S + c]
            dJ[r, iv] = s
            W[i, _A + r] = W[par, _A + r] + s * qd
        # spatial inertia at the world origin: [[m 1, -m [c]ₓ], [m [c]ₓ, R I_c Rᵀ - m [c]ₓ²]]
        m = model_floats[i, MF_MASS]
        for r in range(3):
            s = W[i, _T + 4 * r + 3]
            for k in range(3):
                s += W[i, _T + 4 * r + k] * model_floats[i, MF_LEVER + k]
            W[s2, _U + r] = s
            for c in range(3):
                s = 0.0
                for k in range(3):
                    s += W[i, _T + 4 * r + k] * model_floats[i, MF_INERTIA + 3 * k + c]
                W[s2, _RI + 3 * r + c] = s
        for r in range(3):
            for c in range(3):
                s = 0.0
                for t in range(3):
                    s += _EPS[r, t, c] * W[s2, _U + t]
                W[s2, _CX + 3 * r + c] = s
        for r in range(3):
            for c in range(3):
                s = 0.0
                for k in range(3):
                    s += (W[s2, _RI + 3 * r + k] * W[i, _T + 4 * c + k]
                          - m * W[s2, _CX + 3 * r + k] * W[s2, _CX + 3 * k + c])
                W[i, _I + 6 * (3 + r) + 3 + c] = s
                W[i, _I + 6 * r + c] = m if r == c else 0.0
                W[i, _I + 6 * (3 + r) + c] = m * W[s2, _CX + 3 * r + c]
                W[i, _I + 6 * r + 3 + c] = -m * W[s2, _CX + 3 * r + c]
        # f = I a + V ×* (I V), with V ×* = -(V×)ᵀ
        for r in range(6):
            s = 0.0
            for c in range(6):
                s += W[i, _I + 6 * r + c] * W[i, _V + c]
            W[s2, _Y + r] = s
        if record:  # the body's kinetic energy ½ Vᵀ I V, potential energy -m g·c, momentum I V
            for r in range(6):
                energy[EN_KINETIC] += 0.5 * W[i, _V + r] * W[s2, _Y + r]
                energy[EN_MOMENTUM + r] += W[s2, _Y + r]
            for r in range(3):
                energy[EN_POTENTIAL] -= m * model_floats[0, MF_GRAVITY + r] * W[s2, _U + r]
        for r in range(6):
            s = 0.0
            for c in range(6):
                s += W[i, _I + 6 * r + c] * W[i, _A + c] - W[s1, _X + 6 * c + r] * W[s2, _Y + c]
            W[i, _F + r] = s
    # ---------------------------------------------------------------- backward pass
    for i in range(nj - 1, 0, -1):
        par = model_ints[i, MI_PARENT]
        iv = model_ints[i, MI_IDX_V]
        s = 0.0
        for a in range(6):
            s += J[a, iv] * W[i, _F + a]
        nle[iv] = s
        for r in range(6):  # I_c S, the composite inertia of the subtree times S
            s = 0.0
            for c in range(6):
                s += W[i, _I + 6 * r + c] * J[c, iv]
            W[s2, _Y + r] = s
        j = i
        while j > 0:  # M[j, i] = S_jᵀ I_c S_i for i and each of its ancestors j
            jv = model_ints[j, MI_IDX_V]
            s = model_floats[i, MF_ARMATURE] if j == i else 0.0
            for a in range(6):
                s += J[a, jv] * W[s2, _Y + a]
            M[jv, iv] = s
            M[iv, jv] = s
            j = model_ints[j, MI_PARENT]
        if par > 0:  # the subtree's force and composite inertia into the parent's
            for a in range(_F, _I + 36):
                W[par, a] += W[i, a]


@kernel(refcounts=False)
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


@kernel(refcounts=False)
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
