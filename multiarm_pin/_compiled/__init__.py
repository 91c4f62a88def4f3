"""Compiled (numba) kernels of the fast path.

Each kernel mirrors a numpy reference in the thesis layers and is tested against it; one
module per reference: :mod:`.linalg` (Cholesky, Householder QR, singular values: LAPACK's),
:mod:`.arm_terms` (``ArmSet.evaluate``), :mod:`.constraint_rows` (``ConstraintSet.evaluate``),
:mod:`.assembly` (the reference blocks), :mod:`.object_first` (``solve_object_first_numpy``),
:mod:`.evaluate` (all of them fused on one buffer), :mod:`.controller_kernels`
(``ObjectPD.reference``), :mod:`.phased` (``PhasedPD.reference``),
:mod:`.rigid_body` (Pinocchio's pass of ``ArmSet.pinocchio_pass``: ``J``, ``dJ``, ``M``,
``nle``, tool placements; ``integrate``, ``difference``), :mod:`.trajectory`
(``MinimumJerkTrajectory.motion``), :mod:`.integrator` (``Stepper``'s tangent and steps),
:mod:`.contact_loop` (the loop of ``simulate``: RK4 or semi-implicit steps with contact events)
and :mod:`.scan`
(the collision scan's placements, path lengths and bounds: ``RunScan``'s numpy; ``nogil``).
Every kernel is compiled by one decorator, :func:`.jit.kernel` (specialised by argument
types, never by literal values). The loop calls its stages through function pointers
(:mod:`.function_pointers`), so that each stage is compiled once.
The layout of every array they exchange with Python is defined once in :mod:`.layout`.
The kernels' on-disk cache is stamped with the contents of all kernel sources
(:mod:`.cache`), so that editing a kernel recompiles the kernels that call it.
"""

import warnings as _warnings

from numba.core.errors import NumbaExperimentalFeatureWarning as _Experimental

from multiarm_pin._compiled import cache as _cache

_cache.install()
# the loops call their stages through function pointers (numba's first-class functions,
# :mod:`.function_pointers`), which numba flags as experimental at each compile of a call
_warnings.filterwarnings("ignore", message="First-class function type feature is experimental",
                         category=_Experimental)
