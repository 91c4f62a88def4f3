"""The manipulated object: a rigid body with a convex polyhedral shape.

The object frame is at the centre of mass. Its pose is a position [m] and a unit quaternion
``[x, y, z, w]``; its velocity is the twist ``[ẋ; ω]`` of the COM in world axes (Pinocchio's
LOCAL_WORLD_ALIGNED at the COM). In that representation the Newton-Euler equations (thesis
Eq 3.2) read ``M_o(R) a_o = h_o + (contact wrenches)`` with

    M_o = [[m I, 0], [0, R I_c Rᵀ]],   h_o = [m g; -ω × (R I_c Rᵀ ω)] + external wrench,

``a_o = [ẍ; ω̇]`` the classical acceleration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multiarm_pin.exceptions import InputError
from multiarm_pin.model.kinematics import BodyKinematics
from multiarm_pin.model.polyhedron import Polyhedron, box, from_vertices
from multiarm_pin.spatial import as_array, as_unit_quaternion, quaternion_to_rotation


@dataclass(frozen=True)
class ObjectState:
    """Pose and twist of the object.

    Attributes:
        position: (3,) COM position in the world [m].
        quaternion: (4,) orientation ``[x, y, z, w]`` (object axes -> world axes).
        twist: (6,) ``[ẋ; ω]`` in world axes [m/s, rad/s].
    """

    position: np.ndarray
    quaternion: np.ndarray
    twist: np.ndarray

    @staticmethod
    def create(position, quaternion=(0.0, 0.0, 0.0, 1.0), twist=None) -> ObjectState:
        """Validated state; ``quaternion`` must be unit length (within 1e-6)."""
        return ObjectState(
            as_array(position, (3,), "object position"),
            as_unit_quaternion(quaternion, "object quaternion"),
            np.zeros(6) if twist is None else as_array(twist, (6,), "object twist"),
        )

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) object axes -> world axes."""
        return quaternion_to_rotation(self.quaternion)

    def kinematics(self) -> BodyKinematics:
        """The object as a one-body :class:`BodyKinematics`."""
        return BodyKinematics.single(self.position, self.rotation, self.twist)


@dataclass(frozen=True)
class RigidObject:
    """A rigid body with mass, inertia about its COM and a convex polyhedral shape.

    Attributes:
        mass: [kg], positive.
        inertia: (3, 3) inertia about the COM in object axes [kg m^2], symmetric positive
            definite and satisfying the triangle inequality.
        shape: the polyhedron in the object (COM) frame.
    """

    mass: float
    inertia: np.ndarray
    shape: Polyhedron

    def __post_init__(self) -> None:
        if not (np.isfinite(self.mass) and self.mass > 0):
            raise InputError(f"object mass: expected a positive number [kg], got {self.mass}")
        inertia = as_array(self.inertia, (3, 3), "object inertia")
        if not np.allclose(inertia, inertia.T, atol=1e-9 * max(1.0, np.abs(inertia).max())):
            raise InputError(f"object inertia: expected a symmetric 3x3 matrix, got {inertia}")
        ev = np.linalg.eigvalsh(inertia)
        if ev[0] <= 0:
            raise InputError(f"object inertia: not positive definite (eigenvalues {ev})")
        if ev[0] + ev[1] < ev[2] * (1 - 1e-9):
            raise InputError(
                f"object inertia: principal moments {ev} violate the triangle inequality"
            )
        object.__setattr__(self, "inertia", inertia)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def box(cls, size, mass: float, inertia=None) -> RigidObject:
        """A box of edge lengths ``size`` [m] centred on its COM.

        The inertia is that of a uniform-density box unless given.
        """
        shape = box(size)
        if inertia is None:
            _, inertia = shape.mass_properties(mass)
        return cls(float(mass), np.asarray(inertia, float), shape)

    @classmethod
    def from_vertices(cls, vertices, mass: float, inertia=None) -> RigidObject:
        """A convex polyhedron, the hull of ``vertices`` (V, 3) [m] given in the object frame.

        The object frame must be at the COM: with ``inertia`` omitted, the uniform-density
        COM of the hull is computed and must be at the origin (within 1 mm), else an
        :class:`InputError` says where it is, so that contact points and poses keep their
        meaning.
        """
        shape = from_vertices(vertices)
        if inertia is None:
            com, inertia = shape.mass_properties(mass)
            if np.linalg.norm(com) > 1e-3:
                raise InputError(
                    "object vertices: the object frame must be at the centre of mass, but the "
                    f"uniform-density COM of these vertices is at {np.round(com, 6).tolist()}; "
                    "shift the vertices by minus that, or give the inertia explicitly"
                )
        return cls(float(mass), np.asarray(inertia, float), shape)

    # ------------------------------------------------------------------ dynamics
    def inertia_world(self, rotation: np.ndarray) -> np.ndarray:
        """(3, 3) inertia about the COM in world axes, ``R I_c Rᵀ`` [kg m^2]."""
        return rotation @ self.inertia @ rotation.T

    def mass_matrix(self, rotation: np.ndarray) -> np.ndarray:
        """(6, 6) ``M_o = diag(m I, R I_c Rᵀ)`` for the twist ``[ẋ; ω]`` in world axes."""
        M = np.zeros((6, 6))
        M[0, 0] = M[1, 1] = M[2, 2] = self.mass
        M[3:, 3:] = self.inertia_world(rotation)
        return M

    def bias_wrench(
        self, rotation: np.ndarray, twist: np.ndarray, gravity: np.ndarray, external=None
    ) -> np.ndarray:
        """(6,) ``h_o = [m g; -ω × (I_w ω)] + external`` [N, N m], world axes, about the COM.

        Args:
            rotation: (3, 3) object axes -> world.
            twist: (6,) ``[ẋ; ω]`` world axes.
            gravity: (3,) [m/s^2] in the world.
            external: optional (6,) wrench ``[f; n]`` applied at the COM, world axes.
        """
        wx, wy, wz = twist[3], twist[4], twist[5]
        Lx, Ly, Lz = rotation @ (self.inertia @ (rotation.T @ twist[3:]))  # I_w ω
        h = np.empty(6)
        h[:3] = self.mass * gravity
        h[3] = wz * Ly - wy * Lz  # -(ω × I_w ω), written out (no np.cross call)
        h[4] = wx * Lz - wz * Lx
        h[5] = wy * Lx - wx * Ly
        if external is not None:
            h += external
        return h

    def acceleration(self, state: ObjectState, gravity, wrench=None) -> np.ndarray:
        """(6,) classical acceleration ``[ẍ; ω̇]`` under gravity and an applied wrench."""
        R = state.rotation
        return np.linalg.solve(
            self.mass_matrix(R), self.bias_wrench(R, state.twist, np.asarray(gravity), wrench)
        )

    def momentum(self, state: ObjectState) -> np.ndarray:
        """(6,) ``[m ẋ; I_w ω]``: linear momentum and angular momentum about the COM."""
        return np.concatenate(
            [self.mass * state.twist[:3], self.inertia_world(state.rotation) @ state.twist[3:]]
        )

    def kinetic_energy(self, state: ObjectState) -> float:
        """½ m |ẋ|² + ½ ωᵀ I_w ω [J]."""
        return 0.5 * float(state.twist @ self.mass_matrix(state.rotation) @ state.twist)
