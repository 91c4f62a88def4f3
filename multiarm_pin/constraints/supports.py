"""Supports: unilateral frictionless contacts between points of the object and fixed planes.

A support is a plane fixed in the world (a point ``a`` on it and its unit normal ``n``,
pointing out of the support, towards the free side) and a set of points ``p`` fixed in the
object frame (the object's polyhedron vertices, or points given). The plane is infinite, or,
with an ``extent`` ``[lx, ly]``, the rectangle of those side lengths centred at ``a``, its
sides along the plane's axes ``e_x`` (:attr:`Support.x_axis`) and ``e_y = n × e_x``. A point
whose in-plane position is outside the rectangle is not supported: it neither rests nor
touches down there (:meth:`SupportSet.edge_margins`; the simulation's ``off_edge`` events,
:mod:`multiarm_pin.sim.contact_events`). Only the listed points touch: the rectangle's edge
does not push on the object's faces. Each point is one contact
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

from multiarm_pin._compiled import layout
from multiarm_pin.exceptions import ConstraintError

PARALLEL_SINE = 1e-6
"""An ``x_axis`` whose angle to the plane's normal has a sine below this is refused (its
projection onto the plane, the rectangle's x axis, would be undefined or round-off)."""

DEFAULT_X_SWITCH = 1.0 / np.sqrt(2.0)
"""The default x axis is the world x axis projected onto the plane, or the world y axis
projected when ``|n_x|`` exceeds this (the normal within 45° of ±x)."""


def plane_x_axis(normal: np.ndarray, x_axis=None, where: str = "support") -> np.ndarray:
    """(3,) unit x axis of a plane: ``x_axis`` projected onto it, or the default.

    Args:
        normal: (3,) unit normal of the plane, world axes.
        x_axis: (3,) a world direction not parallel to ``normal``, or None for the default:
            world x projected onto the plane, or world y when ``|n_x| > 1/√2``
            (:data:`DEFAULT_X_SWITCH`).
        where: prefix of the error messages.

    Raises:
        ConstraintError: ``x_axis`` not 3 finite numbers, or (nearly) parallel to the normal.
    """
    n = np.asarray(normal, dtype=float)
    if x_axis is None:
        axis = np.eye(3)[1 if abs(n[0]) > DEFAULT_X_SWITCH else 0]
    else:
        axis = np.asarray(x_axis, dtype=float)
        if axis.shape != (3,) or not np.all(np.isfinite(axis)):
            raise ConstraintError(f"{where}: x_axis must be 3 finite numbers (a world "
                                  f"direction in the plane), got {x_axis!r}")
    length = float(np.linalg.norm(axis))
    in_plane = axis - float(axis @ n) * n
    norm = float(np.linalg.norm(in_plane))
    if length == 0.0 or norm < PARALLEL_SINE * length:
        raise ConstraintError(f"{where}: x_axis {axis.tolist()} is parallel to the plane's "
                              f"normal {n.tolist()} (or zero); expected a direction along "
                              "the plane (it is projected onto it)")
    return in_plane / norm


@dataclass(frozen=True)
class Support:
    """A fixed plane (or a rectangle of it) and the object points that may rest on it.

    Attributes:
        name: label (events and plots name the support and the point index).
        point: (3,) a point of the plane, world frame [m]; the rectangle's centre.
        normal: (3,) unit normal, world axes, pointing out of the support (free side).
        points: (P, 3) contact points in the object (COM) frame [m].
        restitution: Newton's coefficient of restitution of impacts, ``0 <= e <= 1``.
        extent: None (an infinite plane) or (2,) ``[lx, ly]`` [m] (> 0): the side lengths of
            the supporting rectangle, along ``x_axis`` and ``n × x_axis``, centred at
            ``point``.
        x_axis: (3,) the rectangle's x axis, world axes: the given direction projected onto
            the plane and normalised; default (None given) the world x axis projected onto
            the plane, or the world y axis when the normal is within 45° of ±x
            (:func:`plane_x_axis`).
    """

    name: str
    point: np.ndarray
    normal: np.ndarray
    points: np.ndarray
    restitution: float = 0.0
    extent: np.ndarray | None = None
    x_axis: np.ndarray | None = None

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
        extent = None
        if self.extent is not None:
            extent = np.asarray(self.extent, dtype=float)
            if (extent.shape != (2,) or not np.all(np.isfinite(extent))
                    or not np.all(extent > 0.0)):
                raise ConstraintError(f"{where}: extent must be 2 positive finite side lengths "
                                      f"[lx, ly] [m], got {self.extent!r}")
        object.__setattr__(self, "point", point)
        object.__setattr__(self, "normal", normal / length)
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "restitution", e)
        object.__setattr__(self, "extent", extent)
        object.__setattr__(self, "x_axis", plane_x_axis(self.normal, self.x_axis, where))

    @property
    def y_axis(self) -> np.ndarray:
        """(3,) the rectangle's y axis ``n × x_axis``, world axes (unit)."""
        return np.cross(self.normal, self.x_axis)

    @property
    def finite(self) -> bool:
        """True when the support is a rectangle (an ``extent``), False for a whole plane."""
        return self.extent is not None

    def edge_margins(self, points_in_world) -> np.ndarray:
        """(P,) how far inside the rectangle each world point's in-plane position is [m].

        ``min(lx/2 - |u|, ly/2 - |v|)`` with ``(u, v)`` the point's coordinates along
        ``x_axis`` and ``y_axis`` from :attr:`point`: positive inside, zero on the edge,
        negative outside (the point is supported iff > 0); ``+inf`` for an infinite plane.

        Args:
            points_in_world: (P, 3) world points [m].
        """
        p = np.asarray(points_in_world, dtype=float).reshape(-1, 3)
        if self.extent is None:
            return np.full(len(p), np.inf)
        d = p - self.point
        return np.minimum(0.5 * self.extent[0] - np.abs(d @ self.x_axis),
                          0.5 * self.extent[1] - np.abs(d @ self.y_axis))


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
        finite: True when some support has an ``extent`` (a rectangle).
        finite_rows: (K,) bool, the rows of such supports.
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
        self.finite_rows = np.array([self.supports[k].finite for k in self.support_index],
                                    dtype=bool)
        self.finite = bool(self.finite_rows.any())
        if self.finite:
            self._ex = self.supports_array("x_axis")
            self._ey = np.array([self.supports[k].y_axis for k in self.support_index])
            self._half = np.array([0.5 * self.supports[k].extent if self.supports[k].finite
                                   else (np.inf, np.inf) for k in self.support_index])

    def supports_array(self, name: str) -> np.ndarray:
        """(K, 3) the attribute ``name`` (``"normal"``, ``"point"``, ``"x_axis"``) of each row."""
        return np.array([getattr(self.supports[k], name) for k in self.support_index])

    def edge_margins(self, contact_points) -> np.ndarray:
        """(K,) how far inside its support's rectangle each row's point is [m].

        :meth:`Support.edge_margins` row by row: positive inside (supported), zero on the
        edge, negative outside; ``+inf`` on the rows of infinite planes.

        Args:
            contact_points: (K, 3) the rows' object points in the world [m]
                (:attr:`SupportTerms.contact_points`).
        """
        if not self.finite:
            return np.full(self.n_rows, np.inf)
        d = np.asarray(contact_points, dtype=float) - self._a
        u = np.einsum("ki,ki->k", d, self._ex)
        v = np.einsum("ki,ki->k", d, self._ey)
        return np.minimum(self._half[:, 0] - np.abs(u), self._half[:, 1] - np.abs(v))

    def tables(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(points (K, 3), normals (K, 3), planes (K, SUPPORT_PLANE_SIZE))``, new arrays.

        Every row's object-frame point [m], its plane's unit normal, and its support's plane:
        its point [m] (the rectangle's centre), in-plane unit axes and half extents [m]
        (``inf`` for a whole plane), as ``multiarm_pin._compiled.layout.SUPPORT_PLANE_FIELDS``
        lays them out (the compiled contact loop's inputs).
        """
        planes = np.zeros((self.n_rows, layout.SUPPORT_PLANE_SIZE))
        point, x_axis = layout.PLANE_POINT, layout.PLANE_X_AXIS
        y_axis, half = layout.PLANE_Y_AXIS, layout.PLANE_HALF_EXTENT
        planes[:, point:point + 3] = self._a
        planes[:, half:half + 2] = np.inf
        if self.finite:
            planes[:, x_axis:x_axis + 3] = self._ex
            planes[:, y_axis:y_axis + 3] = self._ey
            planes[:, half:half + 2] = self._half
        return (np.array(self._p, dtype=float), np.array(self._n, dtype=float),
                np.ascontiguousarray(planes))

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


__all__ = ["DEFAULT_X_SWITCH", "PARALLEL_SINE", "Support", "SupportSet", "SupportTerms",
           "plane_x_axis"]
