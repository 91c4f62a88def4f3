"""Kinematic state of rigid bodies, the interface between the arms/object and the constraints."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BodyKinematics:
    """Placements and twists of B rigid bodies, stacked.

    Attributes:
        position: (B, 3) world position of each body frame's origin [m].
        rotation: (B, 3, 3) body axes -> world axes.
        twist: (B, 6) ``[v; ω]`` of each frame origin in world axes (LOCAL_WORLD_ALIGNED)
            [m/s, rad/s].
    """

    position: np.ndarray
    rotation: np.ndarray
    twist: np.ndarray

    def __len__(self) -> int:
        return len(self.position)

    def take(self, index) -> BodyKinematics:
        """The bodies at ``index`` (an int array or a slice), still stacked."""
        idx = np.atleast_1d(np.arange(len(self))[index])
        return BodyKinematics(self.position[idx], self.rotation[idx], self.twist[idx])

    @staticmethod
    def single(position: np.ndarray, rotation: np.ndarray, twist: np.ndarray) -> BodyKinematics:
        """One body (B = 1) from (3,), (3, 3), (6,) arrays."""
        return BodyKinematics(
            np.asarray(position, float)[None],
            np.asarray(rotation, float)[None],
            np.asarray(twist, float)[None],
        )
