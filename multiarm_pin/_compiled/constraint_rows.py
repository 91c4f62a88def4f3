"""Compiled constraint rows: gap, rate, ``κ`` and rows ``G`` of every contact, packed.

Mirrors :meth:`multiarm_pin.constraints.ConstraintSet.evaluate` (the numpy reference, same
formulas, those of :mod:`multiarm_pin.constraints.contact` in world axes) with a plain loop
over contacts. Inputs are the contact tables of
:attr:`~multiarm_pin.constraints.ConstraintSet.contact_tables`; the output is the packed
``rows`` segment; both laid out in :mod:`multiarm_pin._compiled.layout`.
"""

from __future__ import annotations

import math

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


@kernel(refcounts=False)
def _body(body, n, tool_p, tool_R, tool_twist, obj_p, obj_R, obj_twist):  # pragma: no cover
    """Position, rotation and twist of a contact's body, as tuples of scalars.

    Tool ``body`` or, past the ``n`` tools, the object: ``(3,)`` [m], the rotation's rows
    ``((3,), (3,), (3,))``, ``(6,)`` [m/s, rad/s]. Read element by element (no view of a
    tool's row).
    """
    if body < n:
        P, R, V = tool_p, tool_R, tool_twist
        return ((P[body, 0], P[body, 1], P[body, 2]),
                ((R[body, 0, 0], R[body, 0, 1], R[body, 0, 2]),
                 (R[body, 1, 0], R[body, 1, 1], R[body, 1, 2]),
                 (R[body, 2, 0], R[body, 2, 1], R[body, 2, 2])),
                (V[body, 0], V[body, 1], V[body, 2], V[body, 3], V[body, 4], V[body, 5]))
    P, R, V = obj_p, obj_R, obj_twist
    return ((P[0], P[1], P[2]),
            ((R[0, 0], R[0, 1], R[0, 2]), (R[1, 0], R[1, 1], R[1, 2]), (R[2, 0], R[2, 1], R[2, 2])),
            (V[0], V[1], V[2], V[3], V[4], V[5]))


@kernel(refcounts=False)
def _cross(a0, a1, a2, b0, b1, b2):  # pragma: no cover - compiled
    """``a × b`` as a tuple."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@kernel(refcounts=False)
def _rotate(R, v0, v1, v2):  # pragma: no cover - compiled
    """``R v`` for ``R`` as rows (tuples), as a tuple."""
    return (R[0][0] * v0 + R[0][1] * v1 + R[0][2] * v2,
            R[1][0] * v0 + R[1][1] * v1 + R[1][2] * v2,
            R[2][0] * v0 + R[2][1] * v1 + R[2][2] * v2)


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

    The 3-vectors are tuples of scalars (no work arrays): ``C`` is the carrier's side, ``S``
    the surface body's.
    """
    n, m, width = rows.shape
    for i in range(n):
        for s in range(m):
            for f in range(width):
                rows[i, s, f] = 0.0
    for q in range(ints.shape[0]):
        XC, RC, VC = _body(ints[q, CI_CARRIER], n, tool_p, tool_R, tool_twist, obj_p, obj_R,
                           obj_twist)
        XS, RS, VS = _body(ints[q, CI_SURFACE], n, tool_p, tool_R, tool_twist, obj_p, obj_R,
                           obj_twist)
        # tip centre c (world), lever arms from both bodies' origins, material velocities
        tip = _rotate(RC, floats[q, CF_TIP], floats[q, CF_TIP + 1], floats[q, CF_TIP + 2])
        c0, c1, c2 = XC[0] + tip[0], XC[1] + tip[1], XC[2] + tip[2]
        rC = (c0 - XC[0], c1 - XC[1], c2 - XC[2])
        rS = (c0 - XS[0], c1 - XS[1], c2 - XS[2])
        wrC = _cross(VC[3], VC[4], VC[5], rC[0], rC[1], rC[2])
        wrS = _cross(VS[3], VS[4], VS[5], rS[0], rS[1], rS[2])
        u0 = (VC[0] + wrC[0]) - (VS[0] + wrS[0])
        u1 = (VC[1] + wrC[1]) - (VS[1] + wrS[1])
        u2 = (VC[2] + wrC[2]) - (VS[2] + wrS[2])
        # surface in world axes: direction d, point s (surface body = side S)
        d0, d1, d2 = _rotate(RS, floats[q, CF_DIRECTION], floats[q, CF_DIRECTION + 1],
                             floats[q, CF_DIRECTION + 2])
        sp = _rotate(RS, floats[q, CF_POINT], floats[q, CF_POINT + 1], floats[q, CF_POINT + 2])
        y0, y1, y2 = c0 - XS[0] - sp[0], c1 - XS[1] - sp[1], c2 - XS[2] - sp[2]
        dy = d0 * y0 + d1 * y1 + d2 * y2
        if floats[q, CF_IS_PLANE] != 0.0:
            nu0, nu1, nu2 = d0, d1, d2
            g = dy
            quad = 0.0
        else:
            yp0, yp1, yp2 = y0 - dy * d0, y1 - dy * d1, y2 - dy * d2
            rho = max(math.sqrt(yp0 * yp0 + yp1 * yp1 + yp2 * yp2), 1e-300)
            sgn = floats[q, CF_CURVATURE_SIGN]
            e0, e1, e2 = yp0 / rho, yp1 / rho, yp2 / rho
            nu0, nu1, nu2 = sgn * e0, sgn * e1, sgn * e2
            du = ((0.0 + d0 * u0) + d1 * u1) + d2 * u2
            eu = ((0.0 + e0 * u0) + e1 * u1) + e2 * u2
            uu = ((0.0 + u0 * u0) + u1 * u1) + u2 * u2
            g = sgn * (rho - floats[q, CF_CURVATURE_RADIUS])
            quad = sgn * (uu - du * du - eu * eu) / rho
        # κ = uᵀHu + ν·(ω_C × (ω_C × r_C) - ω_S × (ω_S × r_S + 2u))
        t0, t1, t2 = _cross(VC[3], VC[4], VC[5], wrC[0], wrC[1], wrC[2])
        kappa = quad + 1.0 * (nu0 * t0 + nu1 * t1 + nu2 * t2)
        t0, t1, t2 = _cross(VS[3], VS[4], VS[5], wrS[0] + 2.0 * u0, wrS[1] + 2.0 * u1,
                            wrS[2] + 2.0 * u2)
        kappa += -1.0 * (nu0 * t0 + nu1 * t1 + nu2 * t2)
        slot = ints[q, CI_SLOT]
        i = slot // m
        s = slot - i * m
        rows[i, s, ROW_PHI] = g - floats[q, CF_TIP_RADIUS]
        rows[i, s, ROW_PHI_DOT] = nu0 * u0 + nu1 * u1 + nu2 * u2
        rows[i, s, ROW_KAPPA] = kappa
        tool_carries = ints[q, CI_TOOL_CARRIES] != 0
        for side in range(2):
            base = ROW_G_TOOL if (side == 0) == tool_carries else ROW_G_OBJECT
            sg = 1.0 if side == 0 else -1.0  # +1 carrier, -1 surface body
            rx, ry, rz = rC if side == 0 else rS
            rows[i, s, base + 0] = sg * nu0
            rows[i, s, base + 1] = sg * nu1
            rows[i, s, base + 2] = sg * nu2
            rows[i, s, base + 3] = sg * (ry * nu2 - rz * nu1)
            rows[i, s, base + 4] = sg * (rz * nu0 - rx * nu2)
            rows[i, s, base + 5] = sg * (rx * nu1 - ry * nu0)
        push = floats[q, CF_PUSH_SIGN]
        rows[i, s, ROW_POINT + 0] = c0 - g * nu0
        rows[i, s, ROW_POINT + 1] = c1 - g * nu1
        rows[i, s, ROW_POINT + 2] = c2 - g * nu2
        rows[i, s, ROW_NORMAL + 0] = push * nu0
        rows[i, s, ROW_NORMAL + 1] = push * nu1
        rows[i, s, ROW_NORMAL + 2] = push * nu2


__all__ = ["constraint_rows"]
