"""The contact primitive: a point or spherical tip on one body against a surface on the other.

The two bodies are the arm's tool (body A) and the object (body B). One of them (the
*carrier*) holds the tip centre ``c``, the other holds the surface. With ``g`` the surface's
signed distance (positive on the free side) and ``r`` the tip radius, the gap is
``φ = g(c) - r`` (thesis Sec 3.9.2). Notation used below, all in world axes:

- ``ν``: unit surface normal at ``c`` pointing to the free side;
- ``u = ċ - (v_S + ω_S × (c - x_S))``: velocity of the tip centre relative to the
  surface body's material point at ``c``;
- ``φ̇ = ν·u = G_C·v_C + G_S·v_S`` with ``G_C = [ν; (c - x_C) × ν]``,
  ``G_S = -[ν; (c - x_S) × ν]`` (twists LWA at each body frame origin);
- ``φ̈ = G_C·a_C + G_S·a_S + κ`` (classical accelerations) with
  ``κ = uᵀ H u + ν·(ω_C × (ω_C × r_C) - ω_S × (ω_S × r_S)) - 2 ν·(ω_S × u)``,
  ``H`` the surface Hessian in world axes, ``r_C = c - x_C``, ``r_S = c - x_S``.

The direction in which the contact pushes the object is ``n = -ν`` when the surface is on
the object (a fingertip on a face: the face's inward normal) and ``n = ν`` when the tip is on
the object (a gripper surface's outward normal), as docs/ARCHITECTURE.md fixes.

Unilaterality belongs to the contact (:attr:`Contact.unilateral`): a unilateral contact can
only push (``μ >= 0``, it may separate, ``φ > 0``); a bilateral one holds ``φ = 0`` with a
multiplier of either sign. The joint library makes fingertips on faces unilateral and the
contacts that model mechanical joints (weld, revolute, ...) bilateral, unless told otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multiarm_pin.constraints.surfaces import Surface, _array
from multiarm_pin.exceptions import ConstraintError
from multiarm_pin.model.kinematics import BodyKinematics
from multiarm_pin.spatial import cross

POINT_ON = ("tool", "object")


@dataclass(frozen=True)
class Contact:
    """A frictionless point contact between the tool and the object.

    Attributes:
        point: (3,) tip centre in the frame of the body that carries it [m].
        surface: the surface, in the frame of the other body.
        radius: tip radius [m] (0 for a sharp point).
        point_on: ``"tool"`` (tip on the tool, surface on the object) or ``"object"``.
        name: label used in messages.
        unilateral: True if the contact can only push (a frictionless tip pressing on a
            surface; it may separate); False for a bilateral row (``φ = 0`` held either way).
    """

    point: np.ndarray
    surface: Surface
    radius: float = 0.0
    point_on: str = "tool"
    name: str = ""
    unilateral: bool = False

    def __post_init__(self):
        object.__setattr__(self, "point", _array(self.point, (3,), f"contact {self.name} point"))
        if self.point_on not in POINT_ON:
            raise ConstraintError(
                f"contact {self.name!r}: point_on must be one of {POINT_ON}, got {self.point_on!r}"
            )
        r = float(self.radius)
        if not np.isfinite(r) or r < 0:
            raise ConstraintError(
                f"contact {self.name!r}: tip radius must be >= 0 [m], got {self.radius!r}"
            )
        object.__setattr__(self, "radius", r)
        if not isinstance(self.unilateral, bool | np.bool_):
            raise ConstraintError(
                f"contact {self.name!r}: unilateral must be True or False, got "
                f"{self.unilateral!r}"
            )
        object.__setattr__(self, "unilateral", bool(self.unilateral))
        if getattr(self.surface, "kind", None) not in ("plane", "sphere", "cylinder"):
            raise ConstraintError(
                f"contact {self.name!r}: surface must be a Plane, Sphere or Cylinder, "
                f"got {type(self.surface).__name__}"
            )

    @property
    def tip_on_tool(self) -> bool:
        """True when the tip is on the tool and the surface on the object."""
        return self.point_on == "tool"

    def evaluate(self, tool: BodyKinematics, obj: BodyKinematics) -> ContactState:
        """Gap, rates, constraint rows and velocity-product term at a state.

        Args:
            tool: the tool's kinematics (one body: position (1, 3) [m], rotation (1, 3, 3),
                LWA twist (1, 6)).
            obj: the object's kinematics (one body, frame at the COM).

        Returns:
            The :class:`ContactState`.
        """
        xt, Rt, vt = tool.position[0], tool.rotation[0], tool.twist[0]
        xo, Ro, vo = obj.position[0], obj.rotation[0], obj.twist[0]
        if self.tip_on_tool:
            (xc, Rc, tc), (xs, Rs, ts) = (xt, Rt, vt), (xo, Ro, vo)
        else:
            (xc, Rc, tc), (xs, Rs, ts) = (xo, Ro, vo), (xt, Rt, vt)
        c = xc + Rc @ self.point
        g, grad, hess = self.surface.local(Rs.T @ (c - xs))
        nu = Rs @ grad
        H = Rs @ hess @ Rs.T
        r_c, r_s = c - xc, c - xs
        wc, ws = tc[3:], ts[3:]
        c_dot = tc[:3] + cross(wc, r_c)
        u = c_dot - ts[:3] - cross(ws, r_s)
        G_c = np.concatenate([nu, cross(r_c, nu)])
        G_s = -np.concatenate([nu, cross(r_s, nu)])
        kappa = (
            u @ H @ u
            + nu @ (cross(wc, cross(wc, r_c)) - cross(ws, cross(ws, r_s)))
            - 2.0 * nu @ cross(ws, u)
        )
        nu_dot = cross(ws, nu) + H @ u
        sign = -1.0 if self.tip_on_tool else 1.0  # push direction on the object = sign * ν
        G_tool, G_object = (G_c, G_s) if self.tip_on_tool else (G_s, G_c)
        phi = g - self.radius
        surface_point = c - g * nu
        return ContactState(
            phi=float(phi),
            phi_dot=float(nu @ u),
            G_tool=G_tool,
            G_object=G_object,
            kappa=float(kappa),
            point=surface_point,
            normal=sign * nu,
            normal_rate=sign * nu_dot,
            tip_center=c,
            tip_velocity=c_dot,
            point_in_tool=Rt.T @ (surface_point - xt),
            point_in_object=Ro.T @ (surface_point - xo),
            normal_in_tool=Rt.T @ (sign * nu),
            normal_in_object=Ro.T @ (sign * nu),
            W_mi=-np.concatenate([Rt.T @ G_tool[:3], Rt.T @ G_tool[3:]]),
            W_oi=-np.concatenate([Ro.T @ G_object[:3], Ro.T @ G_object[3:]]),
        )


@dataclass(frozen=True)
class ContactState:
    """One contact at one state (world axes unless the name says otherwise).

    Attributes:
        phi: gap [m], > 0 separated.
        phi_dot: gap rate [m/s].
        G_tool: (6,) row with ``φ̇ = G_tool·v_tool + G_object·v_object``, at the tool origin.
        G_object: (6,) row at the object COM; its force part is ``normal``.
        kappa: velocity-product term of ``φ̈`` [m/s^2].
        point: (3,) contact location on the surface [m].
        normal: (3,) unit direction in which the contact pushes the object.
        normal_rate: (3,) time derivative of ``normal`` [1/s].
        tip_center: (3,) tip centre [m] (on the line of action through ``point``).
        tip_velocity: (3,) velocity of the tip centre [m/s].
        point_in_tool, point_in_object: (3,) ``point`` in the tool / object frame [m].
        normal_in_tool, normal_in_object: (3,) ``normal`` in tool / object axes.
        W_mi: (6,) the contact's column of the thesis' ``W_mi``: the wrench it applies to the
            object per unit compressive force, about the tool origin in tool axes
            (``-G_tool`` rotated into tool axes).
        W_oi: (6,) its column of the thesis' ``W_oi``: ``-G_object`` rotated into object axes
            (about the COM), so that Eq 3.11 links the two.
    """

    phi: float
    phi_dot: float
    G_tool: np.ndarray
    G_object: np.ndarray
    kappa: float
    point: np.ndarray
    normal: np.ndarray
    normal_rate: np.ndarray
    tip_center: np.ndarray
    tip_velocity: np.ndarray
    point_in_tool: np.ndarray
    point_in_object: np.ndarray
    normal_in_tool: np.ndarray
    normal_in_object: np.ndarray
    W_mi: np.ndarray
    W_oi: np.ndarray
