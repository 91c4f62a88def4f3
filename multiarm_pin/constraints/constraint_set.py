"""All arms' joints evaluated at once: the vectorised hot path of the constraint layer.

The kept contacts of every joint are flattened into one list at construction, grouped by
surface kind (planes; spheres and cylinders share one formula, a sphere being a cylinder
with a zero axis). :meth:`ConstraintSet.evaluate` then computes every contact with a fixed
number of array operations, whatever the number of arms, and scatters the rows into
arrays padded to ``N_max`` constraints per arm. The formulas are those of
:mod:`multiarm_pin.constraints.contact` in world axes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from multiarm_pin.constraints.joint import Joint
from multiarm_pin.exceptions import ConstraintError, InputError
from multiarm_pin.kinematics import BodyKinematics


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
        N: (n,) independent constraints per arm.
        mask: (n, N_max) True on real (non-padded) constraints.
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


class ConstraintSet:
    """The joints of a system; ``joints[i]`` connects arm i's tool and the object.

    Args:
        joints: one :class:`Joint` per arm.

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
        self.N_max = int(self.N.max())
        mask = np.arange(self.N_max)[None, :] < self.N[:, None]
        mask.setflags(write=False)
        self.mask = mask

        planes, curved = [], []
        for i, joint in enumerate(self.joints):
            for k, c in enumerate(joint.active_contacts):
                (planes if c.surface.kind == "plane" else curved).append((i, k, c))
        ordered = planes + curved
        self._n_planes = len(planes)
        arm = np.array([i for i, _, _ in ordered])
        slot = np.array([k for _, k, _ in ordered])
        on_tool = np.array([c.tip_on_tool for _, _, c in ordered])
        # bodies: 0..n-1 tools, n the object
        self._carrier = np.where(on_tool, arm, n)
        self._holder = np.where(on_tool, n, arm)
        self._on_tool = on_tool[:, None]
        self._push_sign = np.where(on_tool, -1.0, 1.0)[:, None]
        self._tip = np.array([c.point for _, _, c in ordered])
        self._radius = np.array([c.radius for _, _, c in ordered])
        self._flat = arm * self.N_max + slot
        self._plane_point = (
            np.array([c.surface.point for _, _, c in planes]) if planes else np.zeros((0, 3))
        )
        self._plane_normal = (
            np.array([c.surface.normal for _, _, c in planes]) if planes else np.zeros((0, 3))
        )
        self._center = (
            np.array([c.surface.center for _, _, c in curved]) if curved else np.zeros((0, 3))
        )
        self._axis = (
            np.array(
                [c.surface.axis if c.surface.kind == "cylinder" else np.zeros(3)
                 for _, _, c in curved]
            )
            if curved
            else np.zeros((0, 3))
        )
        self._curv_radius = np.array([c.surface.radius for _, _, c in curved], dtype=float)
        self._curv_sign = np.array([c.surface.sign for _, _, c in curved], dtype=float)
        self._K = len(ordered)

    def evaluate(self, tools: BodyKinematics, obj: BodyKinematics) -> ConstraintTerms:
        """All constraint rows at a state, vectorised over arms and contacts.

        Args:
            tools: kinematics of the n tools (position (n, 3) [m], rotation (n, 3, 3),
                LWA twist (n, 6)).
            obj: kinematics of the object, one body at its COM.

        Returns:
            :class:`ConstraintTerms`.

        Raises:
            InputError: wrong number of tools or object bodies.
        """
        n = self.n_arms
        if len(tools.position) != n or len(obj.position) != 1:
            raise InputError(
                f"ConstraintSet.evaluate: expected {n} tools and 1 object, got "
                f"{len(tools.position)} tools and {len(obj.position)} object bodies"
            )
        X = np.concatenate([tools.position, obj.position])
        R = np.concatenate([tools.rotation, obj.rotation])
        V = np.concatenate([tools.twist, obj.twist])
        ci, si = self._carrier, self._holder
        Rc, Rs = R[ci], R[si]
        xc, xs = X[ci], X[si]
        tc, ts = V[ci], V[si]
        wc, ws = tc[:, 3:], ts[:, 3:]
        rc = np.einsum("kij,kj->ki", Rc, self._tip)
        c = xc + rc
        rs = c - xs
        u = tc[:, :3] + _cross(wc, rc) - ts[:, :3] - _cross(ws, rs)

        m = self._n_planes
        # planes: g = ν·(c - p0)
        nu_p = np.einsum("kij,kj->ki", Rs[:m], self._plane_normal)
        p0 = xs[:m] + np.einsum("kij,kj->ki", Rs[:m], self._plane_point)
        g_p = np.einsum("ki,ki->k", nu_p, c[:m] - p0)
        # spheres / cylinders: g = s (|y⊥| - R)
        a = np.einsum("kij,kj->ki", Rs[m:], self._axis)
        y = c[m:] - xs[m:] - np.einsum("kij,kj->ki", Rs[m:], self._center)
        yp = y - np.einsum("ki,ki->k", a, y)[:, None] * a
        rho = np.sqrt(np.einsum("ki,ki->k", yp, yp))
        e = yp / rho[:, None]
        sgn = self._curv_sign
        nu_c = sgn[:, None] * e
        g_c = sgn * (rho - self._curv_radius)
        uc = u[m:]
        up = uc - np.einsum("ki,ki->k", a, uc)[:, None] * a
        quad_c = sgn * (np.einsum("ki,ki->k", up, up) - np.einsum("ki,ki->k", e, uc) ** 2) / rho

        nu = np.concatenate([nu_p, nu_c])
        g = np.concatenate([g_p, g_c])
        quad = np.concatenate([np.zeros(m), quad_c])
        phi = g - self._radius
        phi_dot = np.einsum("ki,ki->k", nu, u)
        acc = _cross(wc, _cross(wc, rc)) - _cross(ws, _cross(ws, rs)) - 2.0 * _cross(ws, u)
        kappa = quad + np.einsum("ki,ki->k", nu, acc)
        Gc = np.concatenate([nu, _cross(rc, nu)], axis=1)
        Gs = -np.concatenate([nu, _cross(rs, nu)], axis=1)
        G_tool = np.where(self._on_tool, Gc, Gs)
        G_object = np.where(self._on_tool, Gs, Gc)
        points = c - g[:, None] * nu
        normals = self._push_sign * nu

        shape = (n, self.N_max)
        flat = self._flat
        return ConstraintTerms(
            phi=_scatter(phi, flat, shape),
            phi_dot=_scatter(phi_dot, flat, shape),
            G_tool=_scatter(G_tool, flat, shape),
            G_object=_scatter(G_object, flat, shape),
            kappa=_scatter(kappa, flat, shape),
            N=self.N,
            mask=self.mask,
            contact_points=_scatter(points, flat, shape),
            normals=_scatter(normals, flat, shape),
        )

    def check_initial(self, tools: BodyKinematics, obj: BodyKinematics, tol: float = 1e-6) -> None:
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
    """Row-wise cross product of (K, 3) arrays (cheaper than ``np.cross`` for small K)."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=1)


def _scatter(values: np.ndarray, flat: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    out = np.zeros((shape[0] * shape[1],) + values.shape[1:])
    out[flat] = values
    return out.reshape(shape + values.shape[1:])
