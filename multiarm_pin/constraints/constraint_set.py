"""All arms' joints evaluated at once: the vectorised hot path of the constraint layer.

The kept contacts of every joint are flattened into one list at construction, with the
carrier and surface body of each, its tip, and its surface as a (direction, point) pair in
the surface body's frame. :meth:`ConstraintSet.evaluate` then computes every contact with a
fixed number of array operations whatever the number of arms: the two surface formulas
(planes; spheres and cylinders, a sphere being a cylinder with a zero axis) are evaluated
for all contacts and selected by a mask, which costs fewer numpy calls than grouping by
kind. The rows are scattered once into arrays padded to ``N_max`` constraints per arm (no
scatter when every arm has ``N_max``). The formulas are those of
:mod:`multiarm_pin.constraints.contact`, in world axes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from multiarm_pin._compiled.layout import (
    ROW_G_OBJECT,
    ROW_G_TOOL,
    ROW_KAPPA,
    ROW_NORMAL,
    ROW_PHI,
    ROW_PHI_DOT,
    ROW_POINT,
    ROW_WIDTH,
    ContactTables,
    row_field,
)
from multiarm_pin.constraints.joint import INITIAL_GAP_TOLERANCE, Joint
from multiarm_pin.exceptions import ConstraintError, InputError
from multiarm_pin.model.kinematics import BodyKinematics


@dataclass(frozen=True)
class ConstraintTerms:
    """Constraint rows of n arms at one state, padded to ``N_max`` (padding is zero).

    Attributes:
        phi: (n, N_max) gaps [m] (> 0 separated).
        phi_dot: (n, N_max) gap rates [m/s].
        G_tool: (n, N_max, 6) rows at each tool origin, world axes (LWA tool twists).
        G_object: (n, N_max, 6) rows at the object COM, world axes (LWA object twist).
        kappa: (n, N_max) velocity-product terms [m/s^2]:
            ``φ̈ = G_tool·a_tool + G_object·a_object + κ`` (classical accelerations).
        N: (n,) independent constraints per arm (read-only, shared between calls).
        mask: (n, N_max) True on real (non-padded) constraints (read-only, shared).
        contact_points: (n, N_max, 3) world contact locations [m].
        normals: (n, N_max, 3) world unit directions in which each contact pushes the object.
    """

    phi: np.ndarray
    phi_dot: np.ndarray
    G_tool: np.ndarray
    G_object: np.ndarray
    kappa: np.ndarray
    N: np.ndarray
    mask: np.ndarray
    contact_points: np.ndarray
    normals: np.ndarray

    @classmethod
    def from_rows(cls, rows: np.ndarray, N: np.ndarray, mask: np.ndarray) -> ConstraintTerms:
        """The terms as views of packed rows.

        Args:
            rows: (n, N_max, ROW_WIDTH) packed rows, fields ``ROW_*`` of
                :mod:`multiarm_pin._compiled.layout` (the layout of the compiled path's
                ``rows`` segment).
            N: (n,) constraints per arm (shared, read-only).
            mask: (n, N_max) real constraint slots (shared, read-only).
        """
        return cls(
            phi=row_field(rows, "phi"),
            phi_dot=row_field(rows, "phi_dot"),
            G_tool=row_field(rows, "G_tool"),
            G_object=row_field(rows, "G_object"),
            kappa=row_field(rows, "kappa"),
            N=N,
            mask=mask,
            contact_points=row_field(rows, "contact_point"),
            normals=row_field(rows, "normal"),
        )


class ConstraintSet:
    """The joints of a system; ``joints[i]`` connects arm i's tool and the object.

    Args:
        joints: one :class:`Joint` per arm.

    Attributes:
        joints: the joints, in arm order.
        n_arms: number of arms n.
        N: (n,) independent constraints per arm; ``N_max`` their maximum.
        mask: (n, N_max) True on real (non-padded) constraint slots.
        unilateral: (n, N_max) True on rows of unilateral contacts (:attr:`Contact.unilateral`
            of each joint's kept contacts), False on bilateral rows and padding.
        contact_tables: the kept contacts' geometry as the compiled constraint rows read it
            (:class:`~multiarm_pin._compiled.layout.ContactTables`, built once).

    Raises:
        ConstraintError: an empty list or something that is not a Joint.
    """

    def __init__(self, joints: Sequence[Joint]):
        self.joints: tuple[Joint, ...] = tuple(joints)
        if not self.joints:
            raise ConstraintError("ConstraintSet: needs at least one joint")
        for i, j in enumerate(self.joints):
            if not isinstance(j, Joint):
                raise ConstraintError(
                    f"ConstraintSet: joints[{i}] is a {type(j).__name__}, expected Joint"
                )
        n = len(self.joints)
        self.n_arms = n
        self.N = np.array([j.n_constraints for j in self.joints], dtype=int)
        self.N.setflags(write=False)  # shared by every ConstraintTerms
        self.N_max = int(self.N.max())
        mask = np.arange(self.N_max)[None, :] < self.N[:, None]
        mask.setflags(write=False)
        self.mask = mask
        unilateral = np.zeros((n, self.N_max), dtype=bool)
        for i, joint in enumerate(self.joints):
            unilateral[i, :joint.n_constraints] = joint.unilateral
        unilateral.setflags(write=False)
        self.unilateral = unilateral

        ordered = [
            (i, k, c)
            for i, joint in enumerate(self.joints)
            for k, c in enumerate(joint.active_contacts)
        ]
        arm = np.array([i for i, _, _ in ordered])
        slot = np.array([k for _, k, _ in ordered])
        on_tool = np.array([c.tip_on_tool for _, _, c in ordered])
        # bodies 0..n-1 are the tools, n the object; row 0 the carrier, row 1 the surface's
        self._bodies = np.stack([np.where(on_tool, arm, n), np.where(on_tool, n, arm)])
        self._push_sign = np.where(on_tool, -1.0, 1.0)
        self._tip = np.array([c.point for _, _, c in ordered]).T.copy()  # (3, K)
        self._radius = np.array([c.radius for _, _, c in ordered])
        self._flat = arm * self.N_max + slot
        self._dense = len(ordered) == n * self.N_max  # every slot used: no scatter needed
        # surfaces, one formula per kind selected by mask: planes use (normal, point),
        # spheres (0, centre), cylinders (axis, point of the axis)
        kinds = [c.surface.kind for _, _, c in ordered]
        self._is_plane = np.array([k == "plane" for k in kinds])
        self._all_planes = bool(self._is_plane.all())
        local = np.zeros((len(ordered), 3, 2))
        radius = np.zeros(len(ordered))
        sign = np.ones(len(ordered))
        for m, (_, _, c) in enumerate(ordered):
            surf = c.surface
            if surf.kind == "plane":
                local[m, :, 0], local[m, :, 1] = surf.normal, surf.point
            else:
                local[m, :, 0] = surf.axis if surf.kind == "cylinder" else 0.0
                local[m, :, 1] = surf.center
                radius[m], sign[m] = surf.radius, surf.sign
        self._surface_local = local.transpose(1, 2, 0).copy()  # (3, 2, K)
        self._curv_radius = radius
        self._curv_sign = sign
        self._K = len(ordered)
        self._sigma = np.array([1.0, -1.0])[:, None]
        self._tool_first = np.stack([np.where(on_tool, 0, 1), np.where(on_tool, 1, 0)])
        self._arange = np.arange(len(ordered))[None, :]
        self._contact_tables = ContactTables.build(
            carrier=self._bodies[0], surface=self._bodies[1], slot=self._flat,
            tool_carries=on_tool, tip=self._tip.T, tip_radius=self._radius,
            direction=self._surface_local[:, 0, :].T, point=self._surface_local[:, 1, :].T,
            curvature_radius=radius, curvature_sign=sign, is_plane=self._is_plane,
            push_sign=self._push_sign)

    @property
    def contact_tables(self) -> ContactTables:
        """Per-contact tables of the kept contacts (flattened in arm order) for the kernels.

        ``ints`` (K, CONTACT_INTS): carrier and surface body (``0..n-1`` the tools, ``n`` the
        object), flat slot ``arm * N_max + row``, 1 if the tool carries the tip; ``floats``
        (K, CONTACT_FLOATS): tip point in the carrier frame [m], tip radius [m], surface
        direction and point in the surface body's frame, curvature radius [m] and sign, plane
        flag, push sign (columns of :mod:`multiarm_pin._compiled.layout`). Read-only.
        """
        return self._contact_tables

    def evaluate(self, tools: BodyKinematics, obj: BodyKinematics) -> ConstraintTerms:
        """All constraint rows at a state, vectorised over arms and contacts.

        Args:
            tools: kinematics of the n tools (position (n, 3) [m], rotation (n, 3, 3),
                LWA twist (n, 6)).
            obj: kinematics of the object, one body at its COM.

        Returns:
            :class:`ConstraintTerms` (its arrays may be views of one buffer).

        Raises:
            InputError: wrong number of tools or object bodies.
        """
        n = self.n_arms
        if len(tools.position) != n or len(obj.position) != 1:
            raise InputError(
                f"ConstraintSet.evaluate: expected {n} tools and 1 object, got "
                f"{len(tools.position)} tools and {len(obj.position)} object bodies"
            )
        # component-major layout: every vector array is (3, ...) so that each numpy call
        # works on contiguous rows of K contacts
        b = self._bodies  # (2, K): carrier, surface body
        K = self._K
        bodies = np.concatenate(
            [
                np.concatenate([tools.position, obj.position]),
                np.concatenate([tools.rotation, obj.rotation]).reshape(n + 1, 9),
                np.concatenate([tools.twist, obj.twist]),
            ],
            axis=1,
        )  # (n + 1, 18): position, rotation (row-major), twist of each body
        gathered = np.ascontiguousarray(np.take(bodies, b, axis=0).transpose(2, 0, 1))
        X = gathered[:3]  # (3, 2, K)
        R = gathered[3:12].reshape(3, 3, 2, K)
        V = gathered[12:]  # (6, 2, K)
        W = V[3:]
        c = X[:, 0] + (R[:, :, 0] * self._tip).sum(1)  # tip centres (3, K)
        r = c[:, None] - X  # (3, 2, K) lever arms from the carrier's and the surface's origins
        w_r = _cross(W, r)
        vel = V[:3] + w_r  # velocities of both bodies' material points at c
        u = vel[:, 0] - vel[:, 1]

        # surfaces: planes g = ν·y; spheres/cylinders g = s (|y⊥| - R), ν = s y⊥/|y⊥|
        S = (R[:, :, 1, None] * self._surface_local).sum(1)  # (3, 2, K) direction, point
        a = S[:, 0]
        y = c - X[:, 1] - S[:, 1]
        ay = (a * y).sum(0)
        if self._all_planes:
            nu, g, quad = a, ay, 0.0
        else:
            yp = y - ay * a
            rho = np.maximum(np.sqrt((yp * yp).sum(0)), 1e-300)
            e = yp / rho
            sgn = self._curv_sign
            nu = np.where(self._is_plane, a, sgn * e)
            g = np.where(self._is_plane, ay, sgn * (rho - self._curv_radius))
            au, eu = (a * u).sum(0), (e * u).sum(0)
            quad = np.where(self._is_plane, 0.0, sgn * ((u * u).sum(0) - au * au - eu * eu) / rho)

        # κ = uᵀHu + ν·(ω_C×(ω_C×r_C) - ω_S×(ω_S×r_S + 2u))
        B = w_r.copy()
        B[:, 1] += 2.0 * u
        t = _cross(W, B)
        kappa = quad + (nu * (t[:, 0] - t[:, 1])).sum(0)
        G = np.empty((6, 2, K))
        G[:3] = nu[:, None]
        G[3:] = _cross(r, nu[:, None])
        G *= self._sigma  # +1 carrier, -1 surface body
        G = G[:, self._tool_first, self._arange]  # (6, 2, K): tool, object
        packed = np.empty((ROW_WIDTH, K))  # the fields of the compiled path's packed rows
        packed[ROW_PHI] = g - self._radius
        packed[ROW_PHI_DOT] = (nu * u).sum(0)
        packed[ROW_KAPPA] = kappa
        packed[ROW_G_TOOL:ROW_G_TOOL + 6] = G[:, 0]
        packed[ROW_G_OBJECT:ROW_G_OBJECT + 6] = G[:, 1]
        packed[ROW_POINT:ROW_POINT + 3] = c - g * nu
        packed[ROW_NORMAL:ROW_NORMAL + 3] = self._push_sign * nu
        if self._dense:
            out = packed.T.reshape(n, self.N_max, ROW_WIDTH)
        else:
            out = np.zeros((n * self.N_max, ROW_WIDTH))
            out[self._flat] = packed.T
            out = out.reshape(n, self.N_max, ROW_WIDTH)
        return ConstraintTerms.from_rows(out, self.N, self.mask)

    def check_initial(self, tools: BodyKinematics, obj: BodyKinematics,
                      tol: float = INITIAL_GAP_TOLERANCE) -> None:
        """Raise if any contact of any joint (dropped ones included) has ``|φ| > tol``.

        Args:
            tools: the n tools' kinematics at t = 0.
            obj: the object's kinematics at t = 0.
            tol: largest accepted gap [m].

        Raises:
            ConstraintError: names the arm, joint, contact, gap and tolerance.
        """
        if len(tools) != self.n_arms or len(obj) != 1:
            raise InputError(
                f"check_initial: expected {self.n_arms} tools and 1 object, got "
                f"{len(tools)} tools and {len(obj)} object bodies"
            )
        for i, joint in enumerate(self.joints):
            joint.check_initial(tools.take([i]), obj, tol=tol, arm=i)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product along the first axis of (3, ...) arrays (broadcasting).

    Appending the first two components makes both cyclic shifts plain slices.
    """
    a = np.concatenate([a, a[:2]])
    b = np.concatenate([b, b[:2]])
    return a[1:4] * b[2:5] - a[2:5] * b[1:4]
