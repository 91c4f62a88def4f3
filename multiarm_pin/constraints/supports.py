"""Supports: unilateral frictionless contacts between points of the object and fixed planes.

A support is a plane fixed in the world (a point ``a`` on it and its unit normal ``n``,
pointing out of the support, towards the free side) and a set of points ``p`` fixed in the
object frame (the object's polyhedron vertices, or points given). Each point is one contact
row, with the conventions of docs/ARCHITECTURE.md (the world plays the tool's role, with a
zero twist and no joints). With ``x`` the COM, ``R`` the object's rotation, ``r = R p``:

- gap ``φ = n·(x + r - a)`` [m] (positive = above the plane, negative = penetrating);
- ``φ̇ = G_object·[ẋ; ω]`` with ``G_object = [n; r × n]`` (LWA at the COM);
- ``φ̈ = G_object·[ẍ; ω̇] + κ`` with ``κ = n·(ω × (ω × r))`` (classical accelerations);
- the contact pushes the object along ``+n`` (``μ > 0``); it can only push (unilateral),
  and ``restitution`` ``e`` is Newton's coefficient of its impacts (``φ̇⁺ = -e φ̇⁻``).

In the coefficient blocks every support row goes into one extra *zero-dof block* appended
after the arms (``nv = 0``: the identity padding of ``M``, ``W = 0``, ``W_o`` the rows above,
``c = -κ`` and its Baumgarte terms); see :meth:`multiarm_pin.system.MultiArmSystem.contact_blocks`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from multiarm_pin.exceptions import ConstraintError


@dataclass(frozen=True)
class Support:
    """A fixed plane and the object points that may rest on it.

    Attributes:
        name: label (events and plots name the support and the point index).
        point: (3,) a point of the plane, world frame [m].
        normal: (3,) unit normal, world axes, pointing out of the support (free side).
        points: (P, 3) contact points in the object (COM) frame [m].
        restitution: Newton's coefficient of restitution of impacts, ``0 <= e <= 1``.
    """

    name: str
    point: np.ndarray
    normal: np.ndarray
    points: np.ndarray
    restitution: float = 0.0

    def __post_init__(self):
        where = f"support {self.name!r}"
        point = np.asarray(self.point, dtype=float)
        if point.shape != (3,) or not np.all(np.isfinite(point)):
            raise ConstraintError(f"{where}: plane point must be 3 finite numbers [m], got "
                                  f"{self.point!r}")
        normal = np.asarray(self.normal, dtype=float)
        if normal.shape != (3,) or not np.all(np.isfinite(normal)):
            raise ConstraintError(f"{where}: plane normal must be 3 finite numbers, got "
                                  f"{self.normal!r}")
        length = float(np.linalg.norm(normal))
        if length < 1e-9:
            raise ConstraintError(f"{where}: plane normal has zero length ({normal.tolist()}); "
                                  "expected a direction pointing out of the support")
        pts = np.asarray(self.points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0 or not np.all(np.isfinite(pts)):
            raise ConstraintError(f"{where}: points must be a non-empty list of 3-vectors in "
                                  f"the object frame [m], got shape {pts.shape}")
        e = float(self.restitution)
        if not (np.isfinite(e) and 0.0 <= e <= 1.0):
            raise ConstraintError(f"{where}: restitution must be in [0, 1], got "
                                  f"{self.restitution!r}")
        object.__setattr__(self, "point", point)
        object.__setattr__(self, "normal", normal / length)
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "restitution", e)


@dataclass(frozen=True)
class SupportTerms:
    """All support rows at one state (K rows, in the order of :attr:`SupportSet.labels`).

    Attributes:
        phi: (K,) gaps [m]; phi_dot: (K,) gap rates [m/s].
        G_object: (K, 6) rows ``[n; r × n]`` at the COM, world axes.
        kappa: (K,) velocity-product terms [m/s²].
        contact_points: (K, 3) the object points in the world [m].
        normals: (K, 3) world directions in which each row pushes the object.
    """

    phi: np.ndarray
    phi_dot: np.ndarray
    G_object: np.ndarray
    kappa: np.ndarray
    contact_points: np.ndarray
    normals: np.ndarray


class SupportSet:
    """The supports of a system, flattened into K contact rows.

    Args:
        supports: the supports (unique names).

    Attributes:
        supports: the supports.
        n_rows: K, the number of rows (all points of all supports).
        labels: (K,) ``"name[j]"`` for point j of support ``name``.
        support_index: (K,) int, the support of each row; point_index: (K,) int.
        restitution: (K,) coefficient of restitution of each row.
    """

    def __init__(self, supports: Sequence[Support] = ()):
        self.supports: tuple[Support, ...] = tuple(supports)
        names = []
        for k, s in enumerate(self.supports):
            if not isinstance(s, Support):
                raise ConstraintError(f"supports[{k}]: expected a Support, got "
                                      f"{type(s).__name__}")
            if s.name in names:
                raise ConstraintError(f"supports[{k}]: duplicate support name {s.name!r}")
            names.append(s.name)
        idx = [(k, j) for k, s in enumerate(self.supports) for j in range(len(s.points))]
        self.n_rows = len(idx)
        self.support_index = np.array([k for k, _ in idx], dtype=int)
        self.point_index = np.array([j for _, j in idx], dtype=int)
        self.labels = tuple(f"{self.supports[k].name}[{j}]" for k, j in idx)
        if self.n_rows:
            self._p = np.concatenate([s.points for s in self.supports])
            self._n = self.supports_array("normal")
            self._a = self.supports_array("point")
            self.restitution = np.array([self.supports[k].restitution for k, _ in idx])
        else:
            self._p = self._n = self._a = np.zeros((0, 3))
            self.restitution = np.zeros(0)
        self._n_columns = tuple(np.ascontiguousarray(self._n[:, j]) for j in range(3))

    def supports_array(self, name: str) -> np.ndarray:
        """(K, 3) the plane attribute ``name`` (``"normal"`` or ``"point"``) of each row."""
        return np.array([getattr(self.supports[k], name) for k in self.support_index])

    def tables(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(points, normals, plane points)``, each (K, 3), new C-contiguous arrays.

        Every row's object-frame point [m], its plane's unit normal and a point of its plane
        [m] (the compiled contact loop's inputs).
        """
        return (np.array(self._p, dtype=float), np.array(self._n, dtype=float),
                np.array(self._a, dtype=float))

    def __len__(self) -> int:
        """Number of supports (not rows)."""
        return len(self.supports)

    def evaluate(self, position, rotation, twist) -> SupportTerms:
        """Every row at an object state.

        The cross products are written out on the (K,) columns (the same products and
        differences, in the same order, as ``np.cross``, whose generic axis handling cost
        most of this call on every step); ``np.cross`` is the tests' reference.

        Args:
            position: (3,) COM [m].
            rotation: (3, 3) object axes in world axes.
            twist: (6,) ``[ẋ; ω]`` world axes.
        """
        r = self._p @ np.asarray(rotation).T  # (K, 3) lever arms from the COM, world axes
        n = self._n
        K = len(r)
        if not K:
            return SupportTerms(np.zeros(0), np.zeros(0), np.zeros((0, 6)), np.zeros(0),
                                np.asarray(position) + r, n.copy())
        twist = np.asarray(twist)
        wx, wy, wz = twist[3:].tolist()
        pts = np.asarray(position) + r
        r0, r1, r2 = r[:, 0], r[:, 1], r[:, 2]
        n0, n1, n2 = self._n_columns
        G = np.empty((K, 6))
        G[:, :3] = n
        G[:, 3] = r1 * n2 - r2 * n1  # r × n
        G[:, 4] = r2 * n0 - r0 * n2
        G[:, 5] = r0 * n1 - r1 * n0
        u0 = wy * r2 - wz * r1  # u = ω × r
        u1 = wz * r0 - wx * r2
        u2 = wx * r1 - wy * r0
        wwr = np.empty((K, 3))  # ω × (ω × r)
        wwr[:, 0] = wy * u2 - wz * u1
        wwr[:, 1] = wz * u0 - wx * u2
        wwr[:, 2] = wx * u1 - wy * u0
        kappa = np.einsum("ki,ki->k", n, wwr)
        phi = np.einsum("ki,ki->k", n, pts - self._a)
        phi_dot = G @ twist
        return SupportTerms(phi, phi_dot, G, kappa, pts, n.copy())


__all__ = ["Support", "SupportSet", "SupportTerms"]
