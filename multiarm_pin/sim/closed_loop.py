"""One closed-loop evaluation: blocks, controller torques and forward dynamics on one buffer.

:func:`closed_loop_evaluation` is what :func:`multiarm_pin.sim.simulation.simulate` calls at every
integrator stage. One Pinocchio pass and one set of compiled blocks (at zero torque,
``h = -nle``) serve both the controller (which reads them through the :class:`Evaluation`) and
the forward dynamics: for the compiled solvers (``auto``, ``object_first``) the torques are
added inside :func:`~multiarm_pin._compiled.controller_kernels.solve_with_torques`, which solves
on the
same buffer; no blocks are rebuilt or re-validated. The reference (numpy) path, controller then
``blocks.with_torques`` then :func:`multiarm_pin.dynamics.solve`, gives the same solution to
round-off, and is what a doubtful case (singular arm, badly conditioned object matrix) and
every other solver run.

The compiled loop's stage (:func:`multiarm_pin._compiled.contact_loop.contact_stage`) mirrors
this evaluation, for the controllers that have a kernel.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from multiarm_pin.dynamics import SOLVERS, Solution
from multiarm_pin.dynamics import solve as solve_dynamics
from multiarm_pin.dynamics.evaluation import BufferEvaluation
from multiarm_pin.exceptions import DynamicsError, InputError, MultiArmError
from multiarm_pin.system import Evaluation, MultiArmSystem, SystemState

FUSED_SOLVERS = frozenset(name for name, e in SOLVERS.items() if e.compiled)
"""Solvers whose compiled kernel :func:`closed_loop_evaluation` runs on the shared buffer
(those whose :data:`~multiarm_pin.dynamics.SOLVERS` entry says ``compiled``)."""


def closed_loop_evaluation(system: MultiArmSystem, controller: Callable | None, t: float,
                           state: SystemState, solver: str = "auto",
                           baumgarte: tuple[float, float] | None = None, *,
                           reference: bool = False) -> tuple[Solution, Evaluation, np.ndarray]:
    """Controller torques and the forward dynamics they produce, at one state.

    Args:
        system: the system.
        controller: ``controller(t, state, evaluation) -> tau (nv,)`` [N m], or None (zero).
        t: time [s].
        state: the state.
        solver: a name of :data:`multiarm_pin.dynamics.SOLVERS`.
        baumgarte: ``(α, β)`` [1/s] or None.
        reference: the numpy path instead (reference blocks, the controller's
            ``reference`` method if it has one, ``with_torques``, :func:`solve`).

    Returns:
        ``(solution, evaluation, tau)``: the solution (``solution.blocks`` include the
        torques), the evaluation at zero torque the controller saw, and ``tau`` (nv,).

    Raises:
        InputError: torques of the wrong shape.
        DynamicsError: NaN torques or state, no solution, or a controller that failed
            (``"t = ... s: controller: ..."``); the message gives ``t``.
    """
    ev = system.blocks(state, None, baumgarte, reference=reference)
    call = controller
    if reference:
        call = getattr(controller, "reference", controller)
    fused = None if reference else getattr(controller, "closed_loop", None)
    if fused is not None and solver in FUSED_SOLVERS:  # torques and solve in one call
        try:
            out = fused(t, state, ev, True)
        except MultiArmError as exc:  # no solution at this state: with the time
            raise DynamicsError(f"t = {t:.6g} s: controller: {exc}") from exc
        if out is None:  # the compiled path reported a doubtful case: the reference decides
            call = getattr(controller, "reference", controller)
        if out is not None:
            tau, status = out
            with_tau, sol = system.compiled.with_torques(ev.blocks, controller.last.tau, status)
            if sol is not None:
                return sol, ev, tau
            try:
                return solve_dynamics(with_tau, solver), ev, tau
            except DynamicsError as exc:
                raise DynamicsError(f"t = {t:.6g} s: {exc}") from exc
    tau = np.zeros(system.nv) if controller is None else controller_torques(
        call, t, state, ev, system.nv)
    tau_p = system.pad(tau)
    if not reference and isinstance(ev, BufferEvaluation) and solver in FUSED_SOLVERS:
        with_tau, sol = system.compiled.solve_with_torques(ev.blocks, tau_p)
        if sol is not None:
            return sol, ev, tau
    else:
        with_tau = ev.blocks.with_torques(tau_p)
    try:
        sol = solve_dynamics(with_tau, solver)
    except DynamicsError as exc:
        raise DynamicsError(f"t = {t:.6g} s: {exc}") from exc
    return sol, ev, tau


def controller_torques(controller, t: float, state, evaluation, nv: int) -> np.ndarray:
    """The controller's torques at ``(t, state)``, checked.

    Args:
        controller: ``controller(t, state, evaluation) -> tau (nv,)``.
        t: time [s].
        state: the state.
        evaluation: its evaluation, as the controller sees it.
        nv: the number of joints.

    Returns:
        ``tau`` (nv,) [N m or N].

    Raises:
        InputError: torques of the wrong shape.
        DynamicsError: the controller failed (``"t = ... s: controller: ..."``) or returned
            NaN or infinite torques.
    """
    try:
        tau = np.asarray(controller(t, state, evaluation), dtype=float)
    except MultiArmError as exc:  # NaN or no solution at this state: with the time
        raise DynamicsError(f"t = {t:.6g} s: controller: {exc}") from exc
    if tau.shape != (nv,):
        raise InputError(f"controller returned torques of shape {tau.shape}, expected ({nv},)")
    if not np.all(np.isfinite(tau)):
        raise DynamicsError(f"t = {t:.6g} s: controller returned NaN or infinite torques")
    return tau


__all__ = ["FUSED_SOLVERS", "closed_loop_evaluation", "controller_torques"]
