"""Dynamics layer: coefficient blocks, forward-dynamics solvers, inverse dynamics, forces."""

from multiarm_pin.dynamics.blocks import Residuals, Solution, SystemBlocks
from multiarm_pin.dynamics.dense_kkt import (
    assemble_kkt,
    constraint_jacobian,
    redundant_constraints,
    solve_dense_kkt,
)
from multiarm_pin.dynamics.force_distribution import (
    ForceDistribution,
    distribute_forces,
    min_norm_forces,
)
from multiarm_pin.dynamics.inverse_dynamics import (
    InternalForceBasis,
    InverseDynamicsResult,
    internal_force_basis,
    inverse_dynamics,
)
from multiarm_pin.dynamics.object_first import (
    DEFAULT_RCOND_TOL,
    ArmReduction,
    reduce_arms,
    solve_object_first,
    solve_object_first_numpy,
)
from multiarm_pin.dynamics.singular import solve_singular
from multiarm_pin.dynamics.solve import SOLVERS, SolverEntry, solve, solve_auto, solver_entry
from multiarm_pin.dynamics.unilateral import (
    ContactResiduals,
    ContactSolution,
    DelassusOperator,
    ImpactSolution,
    delassus_operator,
    solve_impact,
    solve_unilateral,
)

__all__ = [
    "DEFAULT_RCOND_TOL",
    "SOLVERS",
    "ArmReduction",
    "ContactResiduals",
    "ContactSolution",
    "DelassusOperator",
    "ForceDistribution",
    "ImpactSolution",
    "InternalForceBasis",
    "InverseDynamicsResult",
    "Residuals",
    "Solution",
    "SolverEntry",
    "SystemBlocks",
    "assemble_kkt",
    "constraint_jacobian",
    "delassus_operator",
    "distribute_forces",
    "internal_force_basis",
    "inverse_dynamics",
    "min_norm_forces",
    "reduce_arms",
    "redundant_constraints",
    "solve",
    "solve_auto",
    "solve_dense_kkt",
    "solve_impact",
    "solve_object_first",
    "solve_object_first_numpy",
    "solve_singular",
    "solve_unilateral",
    "solver_entry",
]
