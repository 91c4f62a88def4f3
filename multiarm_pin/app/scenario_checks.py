"""Checks of a scenario against its loaded robots: errors and warnings.

Errors for impossible values (:class:`~multiarm_pin.exceptions.ScenarioError`, raised
while building):

- ``q0`` outside the joint position limits of the arm's model.

Warnings (:func:`input_warnings`; printed on stderr before a run and kept in the
``input_warnings`` of ``summary.json``):

- an object heavier than :data:`MASS_LIMIT` (numbers may overflow);
- ``object_pd`` waypoints after the end of the run (never reached);
- a placed joint (weld, revolute...) whose frame lies inside the object, more than
  :data:`INSIDE_TOLERANCE` from its surface (the tool would be inside the object).
"""

from __future__ import annotations

import numpy as np

from multiarm_pin.exceptions import ScenarioError
from multiarm_pin.feasibility.limits import LIMIT_TOLERANCE, one_dof_limits

MASS_LIMIT = 1e6
"""Object mass [kg] above which a warning is given (a building, not a payload)."""

INSIDE_TOLERANCE = 1e-3
"""Depth [m] below the object's surface from which a joint frame counts as inside it."""


def check_within_limits(file: str, key: str, arm, q: np.ndarray) -> None:
    """Raise if ``q`` is outside the arm's joint position limits.

    Args:
        file: scenario file (for the message).
        key: key path of ``q`` (``arms[0].q0``).
        arm: the :class:`~multiarm_pin.model.arm.Arm`.
        q: (nq,) configuration [rad or m].

    Raises:
        ScenarioError: naming the first coordinate outside (``arms[0].q0[2]``), its joint, its
            value and the limits.
    """
    lo, hi, names = one_dof_limits(arm.model)
    out = np.nonzero((q < lo - LIMIT_TOLERANCE) | (q > hi + LIMIT_TOLERANCE))[0]
    if out.size:
        c = int(out[0])
        raise ScenarioError(
            file, f"{key}[{c}]",
            f"{q[c]:.6g} is outside the position limits [{lo[c]:.6g}, {hi[c]:.6g}] of joint "
            f"{names[c]!r} of {arm.source}" + (f" ({out.size} coordinates outside)"
                                               if out.size > 1 else ""))


def input_warnings(built, duration: float) -> list[str]:
    """Legal but suspicious values of a built scenario.

    Args:
        built: a :class:`~multiarm_pin.app.scenario.BuiltScenario`.
        duration: the simulated time of the run [s] (after overrides).

    Returns:
        Messages naming the file and the key path.
    """
    sc = built.scenario
    out = []
    if sc.controller.type == "object_pd":
        raw = sc.data.get("controller", {}).get("waypoints") or []
        late = [(k, w["t"]) for k, w in enumerate(raw) if isinstance(w, dict)
                and isinstance(w.get("t"), int | float) and w["t"] > duration]
        if late:
            k, t = late[0]
            more = f" (and {len(late) - 1} later ones)" if len(late) > 1 else ""
            out.append(f"{sc.file}: controller.waypoints[{k}].t: t = {t:g} s is after the end "
                       f"of the run ({duration:g} s){more}; the object never gets there")
    if sc.object.mass > MASS_LIMIT:
        out.append(f"{sc.file}: object.mass: {sc.object.mass:g} kg is more than "
                   f"{MASS_LIMIT:g} kg; forces and accelerations may overflow")
    shape = built.obj.shape
    for spec in sc.arms:
        J_o = spec.joint.placement_in_object
        if J_o is None or spec.joint.type == "fingertips":
            continue
        p = J_o.translation
        depth = -float(np.max(shape.normals @ p - shape.offsets))
        if depth > INSIDE_TOLERANCE:
            out.append(f"{sc.file}: arms[{spec.index}].joint.placement_in_object: the joint "
                       f"frame is {depth:.3g} m inside the object (the tool would be inside it;"
                       " expected on or outside its surface)")
    return out


__all__ = [
    "INSIDE_TOLERANCE",
    "MASS_LIMIT",
    "check_within_limits",
    "input_warnings",
]
