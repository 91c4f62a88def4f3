"""Dynamics layer: coefficient blocks, forward-dynamics solvers, inverse dynamics, forces."""

from multiarm_pin.dynamics.blocks import Residuals, Solution, SystemBlocks
from multiarm_pin.dynamics.dense_kkt import assemble_kkt, solve_dense_kkt
from multiarm_pin.dynamics.object_first import (
    DEFAULT_RCOND_TOL,
    ArmReduction,
    reduce_arms,
    solve_object_first,
)
from multiarm_pin.dynamics.singular import solve_singular
from multiarm_pin.dynamics.solve import SOLVERS, solve

__all__ = [
    "DEFAULT_RCOND_TOL",
    "SOLVERS",
    "ArmReduction",
    "Residuals",
    "Solution",
    "SystemBlocks",
    "assemble_kkt",
    "reduce_arms",
    "solve",
    "solve_dense_kkt",
    "solve_object_first",
    "solve_singular",
]
