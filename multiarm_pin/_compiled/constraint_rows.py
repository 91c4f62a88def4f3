"""Compiled constraint rows: gap, rate, ``κ`` and rows ``G`` of every contact, packed.

Mirrors :meth:`multiarm_pin.constraints.ConstraintSet.evaluate` (the numpy reference, same
formulas, those of :mod:`multiarm_pin.constraints.contact` in world axes) with a plain loop
over contacts. Inputs are the contact tables of
:attr:`~multiarm_pin.constraints.ConstraintSet.contact_tables`; the output is the packed
``rows`` segment; both laid out in :mod:`multiarm_pin._compiled.layout`.
"""

from __future__ import annotations

import math

import numpy as np

from multiarm_pin._compiled.jit import kernel
from multiarm_pin._compiled.layout import (
    CF_CURVATURE_RADIUS,
    CF_CURVATURE_SIGN,
    CF_DIRECTION,
    CF_IS_PLANE,
    CF_POINT,
    CF_PUSH_SIGN,
    CF_TIP,
    CF_TIP_RADIUS,
    CI_CARRIER,
    CI_SLOT,
    CI_SURFACE,
    CI_TOOL_CARRIES,
    ROW_G_OBJECT,
    ROW_G_TOOL,
    ROW_KAPPA,
    ROW_NORMAL,
    ROW_PHI,
    ROW_PHI_DOT,
    ROW_POINT,
)


@kernel
def constraint_rows(tool_p, tool_R, tool_twist, obj_p, obj_R, obj_twist, ints, floats,
                    rows):  # pragma: no cover - compiled
    """Every contact's row (``ConstraintSet.evaluate``), packed into ``rows`` (n, m, ROW_WIDTH).

    Args:
        tool_p: (n, 3) tool positions [m].
        tool_R: (n, 3, 3) tool rotations (tool axes -> world).
        tool_twist: (n, 6) LWA tool twists [m/s, rad/s].
        obj_p: (3,) object COM position [m].
        obj_R: (3, 3) object rotation.
        obj_twist: (6,) object twist ``[ẋ; ω]``, world axes.
        ints: (K, CONTACT_INTS) int contact table (:class:`~.layout.ContactTables`).
        floats: (K, CONTACT_FLOATS) float contact table.
        rows: output (n, m, ROW_WIDTH) packed rows (fields ``ROW_*`` of
            :mod:`~multiarm_pin._compiled.layout`); padded slots zeroed.
    """
    n, m, width = rows.shape
    for i in range(n):
        for s in range(m):
            for f in range(width):
                rows[i, s, f] = 0.0
    X = np.empty((2, 3))
    Rb = np.empty((2, 3, 3))
    V = np.empty((2, 6))
    r = np.empty((2, 3))
    wr = np.empty((2, 3))
    c = np.empty(3)
    u = np.empty(3)
    d = np.empty(3)
    y = np.empty(3)
    nu = np.empty(3)
    yp = np.empty(3)
    for q in range(ints.shape[0]):
        for side in range(2):
            body = ints[q, CI_CARRIER] if side == 0 else ints[q, CI_SURFACE]
            if body < n:
                for a in range(3):
                    X[side, a] = tool_p[body, a]
                    for b in range(3):
                        Rb[side, a, b] = tool_R[body, a, b]
                for a in range(6):
                    V[side, a] = tool_twist[body, a]
            else:
                for a in range(3):
                    X[side, a] = obj_p[a]
                    for b in range(3):
                        Rb[side, a, b] = obj_R[a, b]
                for a in range(6):
                    V[side, a] = obj_twist[a]
        # tip centre c (world), lever arms from both bodies' origins, material velocities
        for a in range(3):
            c[a] = X[0, a] + (Rb[0, a, 0] * floats[q, CF_TIP] + Rb[0, a, 1] * floats[q, CF_TIP + 1]
                              + Rb[0, a, 2] * floats[q, CF_TIP + 2])
        for side in range(2):
            for a in range(3):
                r[side, a] = c[a] - X[side, a]
            wx, wy, wz = V[side, 3], V[side, 4], V[side, 5]
            wr[side, 0] = wy * r[side, 2] - wz * r[side, 1]
            wr[side, 1] = wz * r[side, 0] - wx * r[side, 2]
            wr[side, 2] = wx * r[side, 1] - wy * r[side, 0]
        for a in range(3):
            u[a] = (V[0, a] + wr[0, a]) - (V[1, a] + wr[1, a])
        # surface in world axes: direction d, point s (surface body = side 1)
        for a in range(3):
            d[a] = (Rb[1, a, 0] * floats[q, CF_DIRECTION]
                    + Rb[1, a, 1] * floats[q, CF_DIRECTION + 1]
                    + Rb[1, a, 2] * floats[q, CF_DIRECTION + 2])
            sp = (Rb[1, a, 0] * floats[q, CF_POINT] + Rb[1, a, 1] * floats[q, CF_POINT + 1]
                  + Rb[1, a, 2] * floats[q, CF_POINT + 2])
            y[a] = c[a] - X[1, a] - sp
        dy = d[0] * y[0] + d[1] * y[1] + d[2] * y[2]
        if floats[q, CF_IS_PLANE] != 0.0:
            for a in range(3):
                nu[a] = d[a]
            g = dy
            quad = 0.0
        else:
            for a in range(3):
                yp[a] = y[a] - dy * d[a]
            rho = max(math.sqrt(yp[0] * yp[0] + yp[1] * yp[1] + yp[2] * yp[2]), 1e-300)
            sgn = floats[q, CF_CURVATURE_SIGN]
            du = 0.0
            eu = 0.0
            uu = 0.0
            for a in range(3):
                e = yp[a] / rho
                nu[a] = sgn * e
                du += d[a] * u[a]
                eu += e * u[a]
                uu += u[a] * u[a]
            g = sgn * (rho - floats[q, CF_CURVATURE_RADIUS])
            quad = sgn * (uu - du * du - eu * eu) / rho
        # κ = uᵀHu + ν·(ω_C × (ω_C × r_C) - ω_S × (ω_S × r_S + 2u))
        kappa = quad
        for side in range(2):
            bx, by, bz = wr[side, 0], wr[side, 1], wr[side, 2]
            if side == 1:
                bx += 2.0 * u[0]
                by += 2.0 * u[1]
                bz += 2.0 * u[2]
            wx, wy, wz = V[side, 3], V[side, 4], V[side, 5]
            t0 = wy * bz - wz * by
            t1 = wz * bx - wx * bz
            t2 = wx * by - wy * bx
            sg = 1.0 if side == 0 else -1.0
            kappa += sg * (nu[0] * t0 + nu[1] * t1 + nu[2] * t2)
        slot = ints[q, CI_SLOT]
        i = slot // m
        s = slot - i * m
        rows[i, s, ROW_PHI] = g - floats[q, CF_TIP_RADIUS]
        rows[i, s, ROW_PHI_DOT] = nu[0] * u[0] + nu[1] * u[1] + nu[2] * u[2]
        rows[i, s, ROW_KAPPA] = kappa
        tool_side = 0 if ints[q, CI_TOOL_CARRIES] != 0 else 1
        for side in range(2):
            base = ROW_G_TOOL if side == tool_side else ROW_G_OBJECT
            sg = 1.0 if side == 0 else -1.0  # +1 carrier, -1 surface body
            rx, ry, rz = r[side, 0], r[side, 1], r[side, 2]
            rows[i, s, base + 0] = sg * nu[0]
            rows[i, s, base + 1] = sg * nu[1]
            rows[i, s, base + 2] = sg * nu[2]
            rows[i, s, base + 3] = sg * (ry * nu[2] - rz * nu[1])
            rows[i, s, base + 4] = sg * (rz * nu[0] - rx * nu[2])
            rows[i, s, base + 5] = sg * (rx * nu[1] - ry * nu[0])
        push = floats[q, CF_PUSH_SIGN]
        for a in range(3):
            rows[i, s, ROW_POINT + a] = c[a] - g * nu[a]
            rows[i, s, ROW_NORMAL + a] = push * nu[a]


__all__ = ["constraint_rows"]
