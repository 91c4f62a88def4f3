"""Checks of a built scenario before it is simulated: designs no real system could carry out.

Each check returns warnings (printed on stderr before a run and kept in the
``input_warnings`` of ``summary.json``, like those of :mod:`multiarm_pin.app.scenario_checks`);
each names the file, the key path, the numbers and what was expected:

- :func:`grasp_warnings`: a grasp with unilateral contacts (fingertips) that is not form
  closure (:func:`multiarm_pin.grasp.form_closure.form_closure` on the contact wrenches at
  t = 0, bilateral rows counted both ways) while the object has no support to rest on;
- :func:`static_torque_warnings`: the joint torques that hold the start pose still (gravity on
  the arms plus the object's weight shared by the contacts through
  :func:`multiarm_pin.dynamics.force_distribution.distribute_forces`, mapped by ``Jᵀ``) beyond
  a joint's URDF effort limit (``model.effortLimit``);
- :func:`angle_warnings`: an ``rpy`` angle above 2π in absolute value (degrees typed?);
- :func:`scale_warnings`: an object whose mass or size is far outside the arms' scale (their
  own mass, their reach), e.g. a mass typed in grams;
- :func:`step_warnings`: a time step beyond the integrator's stability limit for the fastest
  closed-loop rate (Baumgarte gains, controller gains; :mod:`multiarm_pin.app.diagnosis`).

:func:`precheck_warnings` runs them all.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from multiarm_pin.exceptions import MultiArmError

TORQUE_RATIO_LIMIT = 1.0
"""Static torque over effort limit above which a joint is reported."""

MASS_SCALE_FACTOR = 20.0
"""An object heavier than this times the arms' own total mass is reported."""

SMALL_MASS_FACTOR = 1e-4
"""An object lighter than this times the arms' own total mass is reported."""

SIZE_SCALE_FACTOR = 10.0
"""An object larger than this times the arms' largest reach (or smaller than its inverse
times a thousandth of it) is reported."""

ANGLE_LIMIT = 2.0 * np.pi
"""Largest ``rpy`` angle [rad] (absolute) accepted without a warning."""


@dataclass(frozen=True)
class StaticTorque:
    """A joint whose static torque at a state exceeds its effort limit.

    Attributes:
        arm: the arm's name. joint: the joint's name in its model. value: the torque [N m or
        N] that holds the state still. limit: the URDF effort limit [N m or N]. ratio:
        ``|value| / limit``.
    """

    arm: str
    joint: str
    value: float
    limit: float
    ratio: float


def joint_names(arm) -> list[str]:
    """(nv,) the name of the joint owning each velocity coordinate of an arm's model."""
    from multiarm_pin.feasibility.limits import arm_limits

    return list(arm_limits(arm).joints)


def effort_limits(arm) -> np.ndarray:
    """(nv,) the URDF effort limits [N m or N] of an arm (``inf`` where none is given)."""
    from multiarm_pin.feasibility.limits import arm_limits

    return arm_limits(arm).effort


def static_torques(system, state, supports: bool = False, engaged_arms=None,
                   support_gap: float | None = None) -> tuple[np.ndarray, str]:
    """Joint torques that hold a state still: arms' gravity plus the object's weight.

    At rest (``v = 0``, no acceleration) the object needs ``W_o μ = -h_o`` (its weight and any
    gyroscopic term are zero at rest; ``h_o`` is gravity) and arm i ``τ_i = g_i(q) - W_i μ_i``
    (``h_i = -g_i`` at ``v = 0``), i.e. ``g_i + J_iᵀ w_i`` with ``w_i`` the wrench arm i
    applies on the object. ``μ`` is the force distribution of
    :func:`~multiarm_pin.dynamics.force_distribution.distribute_forces` with margin 0: the
    smallest multipliers keeping every unilateral contact pushing, on the rows that may carry
    force (every row, unless ``engaged_arms`` or ``support_gap`` leave some out: those carry
    zero).

    Args:
        system: the :class:`~multiarm_pin.system.MultiArmSystem` (with arms).
        state: the :class:`~multiarm_pin.system.SystemState` (its velocities are ignored).
        supports: also let the supports carry the weight (their rows in the distribution).
        engaged_arms: (n_arms,) bool, the arms whose contacts carry force (None: all), e.g.
            the ones touching the object at a phase where the others are apart.
        support_gap: with ``supports``, the largest gap [m] of a support row that carries
            force (a support point above its plane does not push); None: every row.

    Returns:
        ``(tau (nv,), how)``: the torques [N m or N] and how the weight is carried
        (``"by the arms alone"`` or ``"by the arms and the supports"``).

    Raises:
        DynamicsError: the contacts cannot hold the object at rest (no pushing distribution).
    """
    from multiarm_pin.dynamics.blocks import expand_rows, restrict_rows, select_rows
    from multiarm_pin.dynamics.force_distribution import distribute_forces
    from multiarm_pin.model.rigid_object import ObjectState
    from multiarm_pin.system import SystemState

    o = state.obj
    rest = SystemState(np.asarray(state.q, float), np.zeros(system.nv),
                       ObjectState(np.asarray(o.position, float),
                                   np.asarray(o.quaternion, float), np.zeros(6)))
    ev = system.blocks(rest, reference=True)  # once per run: numpy's, nothing to compile
    b = ev.blocks
    n = system.n_arms
    with_supports = bool(supports and system.supports.n_rows)
    if with_supports:
        b, _ = system.contact_blocks(rest, b, ev.constraints)  # the arms' blocks, then theirs
        mask, how = system.contact_unilateral, "by the arms and the supports"
    else:
        mask, how = system.unilateral, "by the arms alone"
    active = np.array(b.constraint_mask, dtype=bool)
    if engaged_arms is not None:
        active[:n][~np.asarray(engaged_arms, dtype=bool)] = False
    if with_supports and support_gap is not None:
        phi = system.support_terms(rest).phi
        active[n, :len(phi)] &= phi <= support_gap
    rhs = -np.asarray(b.h_o, float)
    if np.array_equal(active, b.constraint_mask):
        mu = distribute_forces(b, rhs, mask).mu
    else:  # the rows that carry force only; the others carry zero
        r, index = restrict_rows(b, active)
        mu = expand_rows(distribute_forces(r, rhs, select_rows(mask, index)).mu, index)
    tau = -b.h[:n] - np.einsum("nij,nj->ni", b.W[:n], mu[:n])
    return system.unpad(tau), how


def torque_excess(system, tau: np.ndarray, ratio: float = TORQUE_RATIO_LIMIT
                  ) -> list[StaticTorque]:
    """Joints whose ``|tau|`` exceeds ``ratio`` times their effort limit, worst first.

    Args:
        system: the system.
        tau: (nv,) combined joint torques [N m or N].
        ratio: the threshold on ``|tau| / effort``.
    """
    out = []
    for arm, sl in zip(system.arms, system.arm_set.v_slices, strict=True):
        lim, names, t = effort_limits(arm), joint_names(arm), np.asarray(tau)[sl]
        r = np.abs(t) / lim
        for c in np.flatnonzero(r > ratio):
            out.append(StaticTorque(arm.name, names[c], float(t[c]), float(lim[c]),
                                    float(r[c])))
    return sorted(out, key=lambda s: -s.ratio)


def static_torque_warnings(built) -> list[str]:
    """Joints whose static torque at the start pose exceeds their effort limit.

    The object is held by the arms alone when they can (that is what lifting it needs); if
    they cannot (not form closure) and there are supports, by the arms and the supports.
    """
    sc, system = built.scenario, built.system
    if not system.n_arms:
        return []
    try:
        tau, how = static_torques(system, built.initial_state)
    except MultiArmError:
        if not system.supports.n_rows:
            return []  # the arms cannot hold it at all: grasp_warnings says so
        try:
            tau, how = static_torques(system, built.initial_state, supports=True)
        except MultiArmError:
            return []
    over = torque_excess(system, tau)
    if not over:
        return []
    s = over[0]
    more = "".join(f"; {o.arm}:{o.joint} {o.value:.4g} N m ({o.ratio:.3g}x)" for o in over[1:4])
    more += f"; and {len(over) - 4} more joints" if len(over) > 4 else ""
    return [f"{sc.file}: object.mass: holding the start pose still ({sc.object.mass:g} kg "
            f"object carried {how}, gravity on the arms) needs {s.value:.5g} N m at joint "
            f"{s.joint!r} of arm {s.arm!r}, {s.ratio:.3g}x its effort limit {s.limit:g} N m "
            f"(URDF){more}; no real arm can hold this"]


def grasp_wrenches(system, state, length_scale: float) -> np.ndarray:
    """(6, K) the unit contact wrenches of the arms at a state, for a form-closure test.

    Columns ``[n; (p - c) × n / L]`` (world axes, about the object's COM ``c``): a unilateral
    row as it is, a bilateral row twice (``±``: it pushes and pulls).
    """
    # (n, 6, N_max), rows already [n; r × n]; numpy's blocks (once: nothing to compile)
    W_o = system.blocks(state, reference=True).blocks.W_o
    cols = []
    for i in range(system.n_arms):
        for k in range(int(system.constraint_set.N[i])):
            w = W_o[i, :, k].copy()
            w[3:] /= length_scale
            cols.append(w)
            if not system.unilateral[i, k]:
                cols.append(-w)
    return np.array(cols).T if cols else np.zeros((6, 0))


def grasp_warnings(built) -> list[str]:
    """A grasp with unilateral contacts that is not form closure, with no support."""
    from multiarm_pin.grasp.form_closure import MIN_CONTACTS, form_closure

    sc, system = built.scenario, built.system
    if not system.n_arms or not system.unilateral.any() or system.supports.n_rows:
        return []
    L = float(np.max(np.linalg.norm(built.obj.shape.vertices, axis=1)))
    W = grasp_wrenches(system, built.initial_state, L)
    fc = form_closure(W, allow_fewer=True)
    if fc.form_closure:
        return []
    n_uni = int(system.unilateral.sum())
    if fc.rank < 6:
        why = f"their wrenches have rank {fc.rank} < 6"
    elif not np.isfinite(fc.lp_epsilon):
        why = "no combination of their wrenches with non-negative forces is zero"
    else:
        why = (f"no combination with strictly positive forces is zero: LP margin "
               f"{fc.lp_epsilon:.3g} <= 0")
    if W.shape[1] < MIN_CONTACTS:
        why += f"; frictionless form closure needs at least {MIN_CONTACTS} contacts"
    hold = ""
    try:
        static_torques(system, built.initial_state)
    except MultiArmError:
        hold = "; the contacts cannot even hold its weight at rest, so it falls"
    return [f"{sc.file}: arms: the grasp is not form closure ({n_uni} unilateral contacts: "
            f"{why}) and the object has no support to rest on; some object wrenches cannot "
            f"be resisted{hold} (add contacts, move them, or add a support)"]


def _walk(data, path: str = "") -> Iterator[tuple[str, object]]:
    """Every ``(key path, value)`` of a parsed YAML tree, depth first."""
    if isinstance(data, dict):
        for k, v in data.items():
            p = f"{path}.{k}" if path else str(k)
            yield p, v
            yield from _walk(v, p)
    elif isinstance(data, list):
        for k, v in enumerate(data):
            p = f"{path}[{k}]"
            yield p, v
            yield from _walk(v, p)


def angle_warnings(built) -> list[str]:
    """``rpy`` angles above 2π in absolute value (radians expected; degrees typed?)."""
    sc = built.scenario
    out = []
    for path, value in _walk(sc.data):
        if not (path.endswith(".rpy") and isinstance(value, list)):
            continue
        for k, a in enumerate(value):
            if isinstance(a, int | float) and not isinstance(a, bool) and abs(a) > ANGLE_LIMIT:
                out.append(f"{sc.file}: {path}[{k}]: {a:g} rad is more than 2π "
                           f"({ANGLE_LIMIT:.4g} rad); angles are in radians (if {a:g} is in "
                           f"degrees, write {np.deg2rad(a):.6g})")
    return out


def arm_mass(arm) -> float:
    """Total mass [kg] of an arm's links (its Pinocchio model's inertias)."""
    return float(sum(inertia.mass for inertia in arm.model.inertias))


def arm_reach(arm) -> float:
    """Upper bound [m] of an arm's reach: the lengths of its chain to the tool, summed.

    The sum of the distances between successive joint origins on the path from the root to
    the tool frame, plus the tool frame's offset from its joint.
    """
    model = arm.model
    frame = model.frames[arm.tool_frame_id]
    total = float(np.linalg.norm(frame.placement.translation))
    jid = frame.parentJoint
    while jid > 0 and model.parents[jid] > 0:
        total += float(np.linalg.norm(model.jointPlacements[jid].translation))
        jid = model.parents[jid]
    return total


def scale_warnings(built) -> list[str]:
    """An object mass or size far outside the arms' scale (units typed wrong?)."""
    sc = built.scenario
    if not built.arms:
        return []
    out = []
    m_arms = sum(arm_mass(a) for a in built.arms)
    m = sc.object.mass
    names = ", ".join(a.name for a in built.arms)
    if m > MASS_SCALE_FACTOR * m_arms:
        out.append(f"{sc.file}: object.mass: {m:g} kg is {m / m_arms:.3g}x the arms' own mass "
                   f"({m_arms:.4g} kg for {names}); masses are in kg (a mass typed in grams? "
                   f"{m:g} g = {m / 1000:g} kg)")
    elif m < SMALL_MASS_FACTOR * m_arms:
        out.append(f"{sc.file}: object.mass: {m:g} kg is {m / m_arms:.3g}x the arms' own mass "
                   f"({m_arms:.4g} kg for {names}); masses are in kg (typed in tonnes?)")
    reach = max(arm_reach(a) for a in built.arms)
    v = built.obj.shape.vertices
    size = float(np.max(v.max(axis=0) - v.min(axis=0)))
    key = "object.shape.size" if sc.object.shape_type == "box" else "object.shape.vertices"
    if size > SIZE_SCALE_FACTOR * reach:
        out.append(f"{sc.file}: {key}: the object is {size:g} m across, {size / reach:.3g}x "
                   f"the arms' longest reach ({reach:.3g} m); lengths are in m (typed in mm? "
                   f"{size:g} mm = {size / 1000:g} m)")
    elif size < reach / (1000.0 * SIZE_SCALE_FACTOR):
        out.append(f"{sc.file}: {key}: the object is {size:g} m across, {size / reach:.3g}x "
                   f"the arms' longest reach ({reach:.3g} m); lengths are in m")
    return out


def step_warnings(built, dt: float) -> list[str]:
    """A time step beyond the integrator's stability limit for the fastest closed-loop rate."""
    from multiarm_pin.app.diagnosis import step_too_large

    msg = step_too_large(built, built.initial_state, dt)
    return [f"{built.scenario.file}: simulation.dt: {msg}"] if msg else []


def precheck_warnings(built, dt: float | None = None) -> list[str]:
    """Every check of this module on a built scenario (see the module).

    Args:
        built: a :class:`~multiarm_pin.app.scenario.BuiltScenario`.
        dt: the time step of the run [s] (after overrides; default the scenario's).
    """
    dt = built.scenario.simulation.dt if dt is None else dt
    with np.errstate(over="ignore", invalid="ignore"):  # absurd masses: said by the checks
        return (angle_warnings(built) + scale_warnings(built) + grasp_warnings(built)
                + static_torque_warnings(built) + step_warnings(built, dt))


__all__ = [
    "ANGLE_LIMIT",
    "MASS_SCALE_FACTOR",
    "SIZE_SCALE_FACTOR",
    "SMALL_MASS_FACTOR",
    "TORQUE_RATIO_LIMIT",
    "StaticTorque",
    "angle_warnings",
    "arm_mass",
    "arm_reach",
    "effort_limits",
    "grasp_warnings",
    "grasp_wrenches",
    "joint_names",
    "precheck_warnings",
    "scale_warnings",
    "static_torque_warnings",
    "static_torques",
    "step_warnings",
    "torque_excess",
]
