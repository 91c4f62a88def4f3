"""Physically possible, or it says so: joint limits and collisions of a design and of a run.

- :mod:`.limits`: the URDF's position, velocity and effort limits of every arm joint, and how
  recorded samples use them.
- :mod:`.arm_geometry`: each arm's collision geometry (convex hulls of its URDF's meshes) and
  the self-collision pairs its SRDF leaves.
- :mod:`.batch_kinematics`: joint placements at every recorded sample at once (compiled, or numpy).
- :mod:`.collisions`: every body of a system (arms, object, supports' slabs, ground) in one
  Pinocchio geometry model; collisions and clearances at a state.
- :mod:`.scan`: collisions and clearances along a run, stretch by stretch (:class:`RunScan`).
- :mod:`.report`: :func:`feasibility_report` of a run, :func:`check_design` of a state.
- :mod:`.monitors`: the checks made while a run runs, those of the ``stop`` policies and the
  collision scan its report reuses (:func:`feasibility_monitors`, for
  ``simulate(monitors=...)``).
"""

from multiarm_pin.feasibility.collisions import CATEGORIES, CollisionScene
from multiarm_pin.feasibility.monitors import feasibility_monitors
from multiarm_pin.feasibility.report import (
    LIMIT_KINDS,
    POLICIES,
    FeasibilityReport,
    Violation,
    check_design,
    feasibility_report,
)

__all__ = [
    "CATEGORIES",
    "LIMIT_KINDS",
    "POLICIES",
    "CollisionScene",
    "FeasibilityReport",
    "Violation",
    "check_design",
    "feasibility_monitors",
    "feasibility_report",
]
