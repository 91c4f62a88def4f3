"""Classical accelerations of points and frames moving relative to the object (thesis Eq 3.6).

Used by :class:`~multiarm_pin.sim.controllers.object_pd.ObjectPD` to turn a desired object
acceleration into desired accelerations of the held points.
"""

from __future__ import annotations

import numpy as np

from multiarm_pin.spatial import as_array, cross


def tool_acceleration_from_object(offset, object_twist, object_acceleration,
                                  relative_twist=None, relative_acceleration=None) -> np.ndarray:
    """Classical accelerations of frames that move relative to the object (thesis Eq 3.6).

    A frame (a tool) at ``p = x_o + r`` with orientation ``R = R_o R_rel`` moves relative to
    the object frame (COM ``x_o``, orientation ``R_o``, twist ``[ẋ_o; ω_o]``) with relative
    twist ``[ṗ_rel; ω_rel]`` and relative acceleration ``[a_rel; α_rel]`` (the time derivatives
    of its coordinates in the object frame, rotated to world axes). Its classical acceleration
    is the transport of the object's plus the relative motion::

        p̈ = ẍ_o + ω̇_o × r + ω_o × (ω_o × r) + 2 ω_o × ṗ_rel + a_rel
        ω̇ = ω̇_o + ω_o × ω_rel + α_rel

    With zero relative twist and acceleration this is the acceleration of the object-fixed
    frame at ``p``.

    Args:
        offset: (n, 3) ``r = p - x_o``, world axes [m].
        object_twist: (6,) ``[ẋ_o; ω_o]`` world axes at the COM [m/s, rad/s].
        object_acceleration: (6,) classical ``[ẍ_o; ω̇_o]`` world axes at the COM
            [m/s², rad/s²].
        relative_twist: (n, 6) ``[ṗ_rel; ω_rel] = [ṗ - ẋ_o - ω_o × r; ω - ω_o]``, world axes
            [m/s, rad/s] (``R_o`` times the rates of the frame's coordinates in the object
            frame); zero if None.
        relative_acceleration: (n, 6) ``R_o`` times the second derivatives of those
            coordinates, ``[R_o d²(R_oᵀ r)/dt²; R_o d(R_oᵀ ω_rel)/dt]``, world axes
            [m/s², rad/s²]; zero if None.

    Returns:
        (n, 6) classical accelerations ``[p̈; ω̇]`` of the frames, world axes (LWA).

    Raises:
        InputError: wrong shapes or NaN.
    """
    r = as_array(offset, (None, 3), "offset (n, 3)")
    n = len(r)
    v_o = as_array(object_twist, (6,), "object_twist")
    a_o = as_array(object_acceleration, (6,), "object_acceleration")
    rel_v = (np.zeros((n, 6)) if relative_twist is None
             else as_array(relative_twist, (n, 6), f"relative_twist ({n}, 6)"))
    rel_a = (np.zeros((n, 6)) if relative_acceleration is None
             else as_array(relative_acceleration, (n, 6), f"relative_acceleration ({n}, 6)"))
    return transported_acceleration(r, v_o, a_o, rel_v, rel_a)


def transported_acceleration(r, v_o, a_o, rel_v, rel_a) -> np.ndarray:
    """:func:`tool_acceleration_from_object` without the checks (hot path).

    Args: as there, already checked arrays: ``r`` (n, 3), ``v_o`` and ``a_o`` (6,),
    ``rel_v`` and ``rel_a`` (n, 6). Returns (n, 6) ``[p̈; ω̇]``, world axes.
    """
    w = v_o[3:]
    out = np.empty((len(r), 6))
    out[:, :3] = (a_o[:3] + cross(a_o[3:], r) + cross(w, cross(w, r))
                  + 2.0 * cross(w, rel_v[:, :3]) + rel_a[:, :3])
    out[:, 3:] = a_o[3:] + cross(w, rel_v[:, 3:]) + rel_a[:, 3:]
    return out


__all__ = ["tool_acceleration_from_object", "transported_acceleration"]
