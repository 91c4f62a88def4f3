"""Compiled assembly: the padded coefficient blocks from arm terms and constraint rows.

Mirrors ``MultiArmSystem.blocks(..., reference=True)`` (the ``einsum`` assembly of
:mod:`multiarm_pin.dynamics.evaluation`): ``W``, ``W_o``, ``c``, ``h`` per arm and the object's
``M_o``, ``h_o``, from the arm segments and packed rows of the flat buffer and the parameter
vector, all laid out in :mod:`multiarm_pin._compiled.layout`.
"""

from __future__ import annotations

import numpy as np

from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.layout import (
    P_BAUMGARTE_ALPHA,
    P_BAUMGARTE_BETA,
    P_BAUMGARTE_ON,
    P_GRAVITY,
    P_INERTIA,
    P_MASS,
    ROW_G_OBJECT,
    ROW_G_TOOL,
    ROW_KAPPA,
    ROW_PHI,
    ROW_PHI_DOT,
)


@kernel
def assemble(J, Jdq, nle, tau_padded, rows, params, obj_R, obj_twist, h, W, W_o, c, M_o,
             h_o):  # pragma: no cover - compiled
    """The padded blocks (``MultiArmSystem.blocks``) from arm terms and constraint rows.

    ``W_i = J_iᵀ G_tool,iᵀ``, ``W_o,i = G_object,iᵀ``, ``c_i = -G_tool,i J̇q̇_i - κ_i``
    (minus ``2α φ̇ + β² φ`` when Baumgarte is on in ``params``), ``h_i = τ_i - nle_i``,
    ``M_o = diag(m I, R I_c Rᵀ)``, ``h_o = [m g; -ω × (R I_c Rᵀ ω)]``.

    Args:
        J: (n, 6, k) LWA tool Jacobians (:func:`arm_terms`).
        Jdq: (n, 6) classical tool accelerations at q̈ = 0.
        nle: (n, k) nonlinear effects [N m].
        tau_padded: (n, k) joint torques [N m], zero on padding.
        rows: (n, m, ROW_WIDTH) packed constraint rows of
            :func:`~multiarm_pin._compiled.constraint_rows.constraint_rows`.
        params: (N_PARAMS,) the parameter vector (:data:`~.layout.PARAM_FIELDS`: object
            mass [kg], inertia about the COM in object axes [kg m²], gravity [m/s²] in the
            world, Baumgarte ``α``, ``β`` and on-flag).
        obj_R: (3, 3) object rotation.
        obj_twist: (6,) object twist ``[ẋ; ω]``, world axes.
        h: output (n, k) ``τ - nle``.
        W: output (n, k, m) ``J_iᵀ G_tool,iᵀ``.
        W_o: output (n, 6, m) ``G_object,iᵀ``.
        c: output (n, m) constraint right-hand sides.
        M_o: output (6, 6) object inertia at the COM, world axes.
        h_o: output (6,) object bias wrench [N, N m].
    """
    n, k = nle.shape
    m = rows.shape[1]
    alpha, beta = params[P_BAUMGARTE_ALPHA], params[P_BAUMGARTE_BETA]
    on = params[P_BAUMGARTE_ON]
    mass = params[P_MASS]
    inertia_body = params[P_INERTIA:P_INERTIA + 9].reshape((3, 3))
    gravity = params[P_GRAVITY:P_GRAVITY + 3]
    for i in range(n):
        for a in range(k):
            h[i, a] = tau_padded[i, a] - nle[i, a]
        for s in range(m):
            for a in range(k):
                acc = 0.0
                for r in range(6):
                    acc += J[i, r, a] * rows[i, s, ROW_G_TOOL + r]
                W[i, a, s] = acc
            gj = 0.0
            for r in range(6):
                W_o[i, r, s] = rows[i, s, ROW_G_OBJECT + r]
                gj += rows[i, s, ROW_G_TOOL + r] * Jdq[i, r]
            cs = -gj - rows[i, s, ROW_KAPPA]
            if on != 0.0:
                cs -= 2.0 * alpha * rows[i, s, ROW_PHI_DOT] + beta * beta * rows[i, s, ROW_PHI]
            c[i, s] = cs
    object_terms(mass, inertia_body, gravity, obj_R, obj_twist, M_o, h_o)


@kernel
def object_terms(mass, inertia_body, gravity, obj_R, obj_twist, M_o, h_o
                 ):  # pragma: no cover - compiled
    """The object's ``M_o = diag(m I, R I_c Rᵀ)`` and ``h_o = [m g; -ω × I_w ω]``.

    Args:
        mass: [kg].
        inertia_body: (3, 3) inertia about the COM, object axes [kg m²].
        gravity: (3,) [m/s²].
        obj_R: (3, 3) object axes in world axes.
        obj_twist: (6,) ``[ẋ; ω]`` world axes.
        M_o: output (6, 6).
        h_o: output (6,) [N, N m], world axes at the COM.
    """
    Iw = np.zeros((3, 3))
    for a in range(3):
        for b in range(3):
            t = 0.0
            for p in range(3):
                for q in range(3):
                    t += obj_R[a, p] * inertia_body[p, q] * obj_R[b, q]
            Iw[a, b] = t
    for a in range(6):
        for b in range(6):
            M_o[a, b] = 0.0
    for a in range(3):
        M_o[a, a] = mass
        for b in range(3):
            M_o[3 + a, 3 + b] = Iw[a, b]
    wx, wy, wz = obj_twist[3], obj_twist[4], obj_twist[5]
    Lx = Iw[0, 0] * wx + Iw[0, 1] * wy + Iw[0, 2] * wz
    Ly = Iw[1, 0] * wx + Iw[1, 1] * wy + Iw[1, 2] * wz
    Lz = Iw[2, 0] * wx + Iw[2, 1] * wy + Iw[2, 2] * wz
    for a in range(3):
        h_o[a] = mass * gravity[a]
    h_o[3] = wz * Ly - wy * Lz
    h_o[4] = wx * Lz - wz * Lx
    h_o[5] = wy * Lx - wx * Ly


__all__ = ["assemble", "object_terms"]
