"""Contact surfaces: plane, sphere and cylinder, each fixed in one body's frame.

A surface is described in the frame of the body that carries it. Each surface has a
signed distance function ``g(y)`` of a point ``y`` (3,) given in that frame [m]: positive on
the *free* side (where the other body's point is), zero on the surface. Its gradient is the
unit normal pointing to the free side and its Hessian is what the acceleration-level
constraint needs (the curvature of the surface). A point contact is the constraint
``g(tip centre) - tip radius = 0`` (thesis Sec 3.9.2: a spherical fingertip acts like a sharp
point at its centre offset by its radius).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from multiarm_pin.exceptions import ConstraintError, InputError
from multiarm_pin.spatial import as_array

_MIN_LENGTH = 1e-12


def _unit(vector, name: str) -> np.ndarray:
    v = _array(vector, (3,), name)
    norm = float(np.linalg.norm(v))
    if norm < _MIN_LENGTH:
        raise ConstraintError(f"{name}: expected a non-zero direction vector, got {v.tolist()}")
    return v / norm


def _array(value, shape, name: str) -> np.ndarray:
    try:
        return as_array(value, shape, name)
    except InputError as exc:  # a bad joint definition is a ConstraintError for callers
        raise ConstraintError(str(exc)) from exc


def _positive(value, name: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise ConstraintError(f"{name}: expected a positive length [m], got {value!r}") from exc
    if not np.isfinite(x) or x <= 0.0:
        raise ConstraintError(f"{name}: expected a positive length [m], got {value!r}")
    return x


@dataclass(frozen=True)
class Plane:
    """The plane through ``point`` with unit normal ``normal`` pointing to the free side.

    Attributes:
        point: (3,) a point of the plane in the carrying body's frame [m].
        normal: (3,) unit normal in that frame (normalised on construction; zero is refused).
    """

    point: np.ndarray
    normal: np.ndarray
    kind: ClassVar[str] = "plane"

    def __post_init__(self):
        object.__setattr__(self, "point", _array(self.point, (3,), "plane point"))
        object.__setattr__(self, "normal", _unit(self.normal, "plane normal"))

    def local(self, y: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """Signed distance [m], unit normal (3,) and Hessian (3, 3) [1/m] at ``y`` (own frame)."""
        return float(self.normal @ (y - self.point)), self.normal.copy(), np.zeros((3, 3))

    def transformed(self, rotation: np.ndarray, translation: np.ndarray) -> Plane:
        """The same plane in another frame, where ``y_new = rotation @ y + translation``."""
        return Plane(rotation @ self.point + translation, rotation @ self.normal)


@dataclass(frozen=True)
class _Curved:
    """Points at distance ``radius`` from an axis (cylinder) or from a centre (sphere)."""

    center: np.ndarray
    radius: float
    inside: bool = False

    def _axis(self) -> np.ndarray:
        return np.zeros(3)

    @property
    def sign(self) -> float:
        """+1 when the free side is outside (a shaft, a ball), -1 inside (a bore, a socket)."""
        return -1.0 if self.inside else 1.0

    def local(self, y: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """Signed distance [m], unit normal (3,) and Hessian (3, 3) [1/m] at ``y`` (own frame).

        Raises:
            ConstraintError: ``y`` is on the axis / at the centre, where the normal is undefined.
        """
        a = self._axis()
        d = y - self.center
        perp = d - (a @ d) * a
        rho = float(np.linalg.norm(perp))
        if rho < _MIN_LENGTH:
            raise ConstraintError(
                f"{self.kind}: point {y.tolist()} is on the axis/centre, the normal is undefined"
            )
        e = perp / rho
        proj = np.eye(3) - np.outer(a, a)
        hess = self.sign * (proj - np.outer(e, e)) / rho
        return self.sign * (rho - self.radius), self.sign * e, hess


@dataclass(frozen=True)
class Sphere(_Curved):
    """A sphere; ``inside=False``: the free side is outside (a ball), True: a socket.

    Attributes:
        center: (3,) centre in the carrying body's frame [m].
        radius: radius [m] (> 0).
        inside: whether the free side is the inside.
    """

    kind: ClassVar[str] = "sphere"

    def __post_init__(self):
        object.__setattr__(self, "center", _array(self.center, (3,), "sphere center"))
        object.__setattr__(self, "radius", _positive(self.radius, "sphere radius"))
        object.__setattr__(self, "inside", bool(self.inside))

    def transformed(self, rotation: np.ndarray, translation: np.ndarray) -> Sphere:
        """The same sphere in another frame, where ``y_new = rotation @ y + translation``."""
        return Sphere(rotation @ self.center + translation, self.radius, self.inside)


@dataclass(frozen=True)
class Cylinder(_Curved):
    """An infinite circular cylinder; ``inside=False``: a shaft, True: a bore.

    Attributes:
        center: (3,) a point of the axis in the carrying body's frame [m].
        radius: radius [m] (> 0).
        axis: (3,) unit axis direction (normalised on construction; zero is refused).
        inside: whether the free side is the inside.
    """

    axis: np.ndarray = None  # type: ignore[assignment]
    kind: ClassVar[str] = "cylinder"

    def __post_init__(self):
        object.__setattr__(self, "center", _array(self.center, (3,), "cylinder center"))
        object.__setattr__(self, "radius", _positive(self.radius, "cylinder radius"))
        object.__setattr__(self, "inside", bool(self.inside))
        if self.axis is None:
            raise ConstraintError("cylinder axis: expected a non-zero direction vector, got None")
        object.__setattr__(self, "axis", _unit(self.axis, "cylinder axis"))

    def _axis(self) -> np.ndarray:
        return self.axis

    def transformed(self, rotation: np.ndarray, translation: np.ndarray) -> Cylinder:
        """The same cylinder in another frame, where ``y_new = rotation @ y + translation``."""
        return Cylinder(
            rotation @ self.center + translation, self.radius, self.inside, rotation @ self.axis
        )


Surface = Plane | Sphere | Cylinder
"""Any contact surface."""

SURFACE_TYPES = {"plane": Plane, "sphere": Sphere, "cylinder": Cylinder}


def make_surface(kind: str, **params) -> Surface:
    """Build a surface from plain parameters (as read from YAML).

    Args:
        kind: ``"plane"`` (``point``, ``normal``), ``"sphere"`` (``center``, ``radius``,
            ``inside``) or ``"cylinder"`` (``center``, ``axis``, ``radius``, ``inside``).
        **params: the parameters, lists and floats, in the carrying body's frame [m].

    Raises:
        ConstraintError: unknown kind (the message lists the known ones) or bad parameters.
    """
    if kind not in SURFACE_TYPES:
        raise ConstraintError(
            f"unknown surface type {kind!r}; known types: {', '.join(sorted(SURFACE_TYPES))}"
        )
    try:
        return SURFACE_TYPES[kind](**params)
    except TypeError as exc:
        raise ConstraintError(f"surface {kind!r}: bad parameters {sorted(params)}: {exc}") from exc
