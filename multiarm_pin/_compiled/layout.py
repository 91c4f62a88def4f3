"""The compiled path's data layout, defined once by name.

Every flat array that crosses the boundary between Python and the numba kernels is described
here, as a table of named fields; the integer constants below are derived from the tables
(module-level ints, which numba reads as compile-time constants), and both the kernels and
the Python code that builds or reads the arrays use them. No other module writes an index of
these arrays as a literal.

- **Buffer segments** (:data:`SEGMENTS`, ``SEG_*``): the flat float64 output buffer of
  :func:`multiarm_pin._compiled.evaluate.evaluate_system`, one C-contiguous segment per
  quantity, shapes in terms of ``n`` arms, ``k = nv_max`` joints and ``m = N_max`` rows.
  :func:`offsets` (compiled, callable from Python) gives their start offsets; the kernels
  take views with :func:`view2` / :func:`view3`, Python with
  :func:`segment_slices`.
  The view helpers are inlined into their callers (``inline="always"``): called as
  separate functions, numba compiled one specialisation per ``SEG_*`` constant (a literal).
  The kernels of :mod:`~multiarm_pin._compiled.evaluate` and
  :mod:`~multiarm_pin._compiled.controller_kernels` take their views through the inlined
  ``_arm_segments`` / ``_block_segments`` / ``_solution_segments`` of ``evaluate``, the
  shapes written out (no ``_dim`` call per axis: cheaper to compile, issue 14).
- **Row fields** (``ROW_*``): the ``ROW_WIDTH`` values of one packed constraint row, the
  layout of :meth:`multiarm_pin.constraints.ConstraintSet.evaluate` and of the ``rows``
  segment.
- **Contact table columns** (``CI_*``, ``CF_*``): :class:`ContactTables`, one row per kept
  contact (built by :attr:`multiarm_pin.constraints.ConstraintSet.contact_tables`).
- **Rigid-body model tables** (``KIND_*``, ``MI_*``, ``MF_*``): joints and tool frames of a
  Pinocchio model, the input of :mod:`multiarm_pin._compiled.rigid_body`.
- **Arm table columns** (``ARM_*``): joints per arm, joint indices, tool-support mask.
- **Object state** (``X_*``): position, quaternion, twist, the head of the state vector ``x``.
- **Dimensions** (``DIMS_*``): the int vector ``(k, m, nv, n)``.
- **Parameter slots** (``P_*``): object, gravity, Baumgarte and solver thresholds.
- **Controller vectors** (``OX_*``, ``REF_*``, ``PD_*``, ``GAIN_*``): the object pose
  and the reference, gains of :mod:`multiarm_pin._compiled.controller_kernels`; the
  trajectory table (``TR_*``) of :mod:`multiarm_pin._compiled.trajectory`; the external
  wrench intervals (``WE_*``) of :mod:`multiarm_pin._compiled.contact_loop`.

Units are SI; spatial vectors ``[linear; angular]`` in world axes (``docs/ARCHITECTURE.md``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba.core import types
from numba.core.imputils import impl_ret_borrowed
from numba.core.typing.templates import signature
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array

from multiarm_pin._compiled.jit import jit_disabled, kernel


def _starts(fields: Sequence[tuple[str, int]]) -> tuple[dict[str, int], int]:
    """Start index of each ``(name, width)`` field laid out one after the other, and the total."""
    starts, pos = {}, 0
    for name, width in fields:
        starts[name] = pos
        pos += width
    return starts, pos


# ------------------------------------------------------------------ packed constraint rows
ROW_FIELDS = (("phi", 1), ("phi_dot", 1), ("kappa", 1), ("G_tool", 6), ("G_object", 6),
              ("contact_point", 3), ("normal", 3))
"""Fields of one packed constraint row: gap ``φ`` [m], rate ``φ̇`` [m/s], ``κ`` [m/s²], the
row at the tool origin (6) and at the object COM (6) (world axes), the contact point (3) [m]
and the unit direction (3) in which the row pushes the object."""
_ROW, ROW_WIDTH = _starts(ROW_FIELDS)
_ROW_WIDTHS = dict(ROW_FIELDS)
ROW_PHI = _ROW["phi"]
ROW_PHI_DOT = _ROW["phi_dot"]
ROW_KAPPA = _ROW["kappa"]
ROW_G_TOOL = _ROW["G_tool"]
ROW_G_OBJECT = _ROW["G_object"]
ROW_POINT = _ROW["contact_point"]
ROW_NORMAL = _ROW["normal"]


def row_field(rows: np.ndarray, name: str) -> np.ndarray:
    """The field ``name`` of :data:`ROW_FIELDS` of packed rows ``(..., ROW_WIDTH)``: a view.

    Width-1 fields drop the last axis (``(...)``), the others keep it (``(..., width)``).
    """
    start, width = _ROW[name], _ROW_WIDTHS[name]
    return rows[..., start] if width == 1 else rows[..., start:start + width]


# ------------------------------------------------------------------ contact tables
CONTACT_INT_FIELDS = (("carrier", 1), ("surface", 1), ("slot", 1), ("tool_carries", 1))
"""Int columns per contact: carrier body and surface body (``0..n-1`` the tools, ``n`` the
object), flat slot ``arm * N_max + row``, 1 if the tool carries the tip."""
_CI, CONTACT_INTS = _starts(CONTACT_INT_FIELDS)
CI_CARRIER = _CI["carrier"]
CI_SURFACE = _CI["surface"]
CI_SLOT = _CI["slot"]
CI_TOOL_CARRIES = _CI["tool_carries"]

CONTACT_FLOAT_FIELDS = (("tip", 3), ("tip_radius", 1), ("direction", 3), ("point", 3),
                        ("curvature_radius", 1), ("curvature_sign", 1), ("is_plane", 1),
                        ("push_sign", 1))
"""Float columns per contact: tip point in the carrier's frame (3) [m], tip radius [m],
surface direction (3) and point (3) in the surface body's frame (plane: normal and point;
sphere: 0 and centre; cylinder: axis and a point of it), curvature radius [m], curvature sign
(+1 outside, -1 inside), 1.0 for planes, push sign (-1 if the tip is on the tool)."""
_CF, CONTACT_FLOATS = _starts(CONTACT_FLOAT_FIELDS)
CF_TIP = _CF["tip"]
CF_TIP_RADIUS = _CF["tip_radius"]
CF_DIRECTION = _CF["direction"]
CF_POINT = _CF["point"]
CF_CURVATURE_RADIUS = _CF["curvature_radius"]
CF_CURVATURE_SIGN = _CF["curvature_sign"]
CF_IS_PLANE = _CF["is_plane"]
CF_PUSH_SIGN = _CF["push_sign"]


@dataclass(frozen=True)
class ContactTables:
    """Per-contact tables of a constraint set, the input of the compiled constraint rows.

    Attributes:
        ints: (K, CONTACT_INTS) int64, columns :data:`CONTACT_INT_FIELDS` (read-only).
        floats: (K, CONTACT_FLOATS) float64, columns :data:`CONTACT_FLOAT_FIELDS` (read-only).
    """

    ints: np.ndarray
    floats: np.ndarray

    @classmethod
    def build(cls, carrier, surface, slot, tool_carries, tip, tip_radius, direction, point,
              curvature_radius, curvature_sign, is_plane, push_sign) -> ContactTables:
        """The tables from per-contact arrays, one entry per contact (K of them).

        Args:
            carrier: (K,) carrier body of each tip (``0..n-1`` the tools, ``n`` the object).
            surface: (K,) surface body.
            slot: (K,) flat slot ``arm * N_max + row``.
            tool_carries: (K,) 1 if the tool carries the tip.
            tip: (K, 3) tip point in the carrier's frame [m].
            tip_radius: (K,) [m].
            direction: (K, 3) surface direction in the surface body's frame.
            point: (K, 3) surface point in the surface body's frame [m].
            curvature_radius: (K,) [m] (0 for planes).
            curvature_sign: (K,) +1 outside, -1 inside.
            is_plane: (K,) 1.0 for planes.
            push_sign: (K,) -1 if the tip is on the tool, else +1.
        """
        K = len(slot)
        ints = np.zeros((K, CONTACT_INTS), dtype=np.int64)
        ints[:, CI_CARRIER] = carrier
        ints[:, CI_SURFACE] = surface
        ints[:, CI_SLOT] = slot
        ints[:, CI_TOOL_CARRIES] = tool_carries
        floats = np.zeros((K, CONTACT_FLOATS))
        floats[:, CF_TIP:CF_TIP + 3] = tip
        floats[:, CF_TIP_RADIUS] = tip_radius
        floats[:, CF_DIRECTION:CF_DIRECTION + 3] = direction
        floats[:, CF_POINT:CF_POINT + 3] = point
        floats[:, CF_CURVATURE_RADIUS] = curvature_radius
        floats[:, CF_CURVATURE_SIGN] = curvature_sign
        floats[:, CF_IS_PLANE] = is_plane
        floats[:, CF_PUSH_SIGN] = push_sign
        ints.setflags(write=False)
        floats.setflags(write=False)
        return cls(ints, floats)


# ------------------------------------------------------------------ rigid-body model tables
JOINT_KINDS = ("universe", "revolute", "prismatic", "revolute_unbounded", "frame")
"""Kinds of the rows of the rigid-body model tables (:class:`~multiarm_pin.model.compiled_model.
CompiledModel`): the universe (row 0), a revolute joint about an axis (``nq = nv = 1``), a
prismatic joint along an axis, a continuous (unbounded) revolute joint (``nq = 2``:
``[cos θ, sin θ]``, ``nv = 1``), and a tool frame (after the joints, one row per tool)."""
KIND_UNIVERSE = JOINT_KINDS.index("universe")
KIND_REVOLUTE = JOINT_KINDS.index("revolute")
KIND_PRISMATIC = JOINT_KINDS.index("prismatic")
KIND_REVOLUTE_UNBOUNDED = JOINT_KINDS.index("revolute_unbounded")
KIND_FRAME = JOINT_KINDS.index("frame")

MODEL_INT_FIELDS = (("parent", 1), ("kind", 1), ("idx_q", 1), ("idx_v", 1))
"""Int columns per row of the model tables (row ``j < njoints``: Pinocchio joint ``j``, row 0
the universe; then one row per tool frame): parent joint (-1 for the universe; a tool frame's
joint), kind (:data:`JOINT_KINDS`), first index in ``q`` and in ``v`` (-1 for the universe and
the frames)."""
_MI, MODEL_INTS = _starts(MODEL_INT_FIELDS)
MI_PARENT = _MI["parent"]
MI_KIND = _MI["kind"]
MI_IDX_Q = _MI["idx_q"]
MI_IDX_V = _MI["idx_v"]

ENERGY_FIELDS = (("kinetic", 1), ("potential", 1), ("momentum", 6))
"""Energies and momentum of the arms' bodies (``rigid_body_pass``'s ``energy``): kinetic and
gravitational potential energy [J], total momentum ``[linear; angular about the world
origin]`` [kg m/s, kg m²/s], world axes."""
_EN, ENERGY_SIZE = _starts(ENERGY_FIELDS)
EN_KINETIC = _EN["kinetic"]
EN_POTENTIAL = _EN["potential"]
EN_MOMENTUM = _EN["momentum"]

MODEL_FLOAT_FIELDS = (("placement", 12), ("axis", 3), ("mass", 1), ("lever", 3),
                      ("inertia", 9), ("armature", 1), ("gravity", 6))
"""Float columns per row of the model tables: placement in the parent joint's frame (a
joint's ``jointPlacements``, a frame's ``placement``) as the 3x4 matrix ``[R | t]``, row-major
(``t`` in m); the joint's unit axis in its own frame; the body inertia attached to the joint (mass
[kg], COM lever in the joint frame [m], rotational inertia about the COM in the joint axes,
row-major [kg m²]); the joint's armature [kg m² or kg]; the model's gravity
``[linear; angular]`` [m/s²] (row 0 only)."""
_MF, MODEL_FLOATS = _starts(MODEL_FLOAT_FIELDS)
MF_PLACEMENT = _MF["placement"]
MF_AXIS = _MF["axis"]
MF_MASS = _MF["mass"]
MF_LEVER = _MF["lever"]
MF_INERTIA = _MF["inertia"]
MF_ARMATURE = _MF["armature"]
MF_GRAVITY = _MF["gravity"]


# ------------------------------------------------------------------ arm table
ARM_NV = 0
"""Arm table ``(n, 1 + 2k)`` int64: column of the number of joints of each arm."""
ARM_JOINTS = 1
"""First of the ``k`` columns of joint indices in the combined velocity (padded with 0);
the ``k`` columns of the tool-support mask (1 where the joint moves the tool) follow them,
from ``ARM_JOINTS + k``."""


def arm_table(nv_arm: np.ndarray, joints: np.ndarray, support: np.ndarray) -> np.ndarray:
    """The arm table ``(n, 1 + 2k)`` int64 from ``nv_arm`` (n,), ``joints``, ``support`` (n, k)."""
    n, k = joints.shape
    table = np.zeros((n, ARM_JOINTS + 2 * k), dtype=np.int64)
    table[:, ARM_NV] = nv_arm
    table[:, ARM_JOINTS:ARM_JOINTS + k] = joints
    table[:, ARM_JOINTS + k:ARM_JOINTS + 2 * k] = support
    return table


# ------------------------------------------------------------------ object state, state vector
OBJECT_STATE_FIELDS = (("position", 3), ("quaternion", 4), ("twist", 6))
"""The object's state as the kernels read it: COM position [m], quaternion ``[x, y, z, w]``,
twist ``[ẋ; ω]`` (world axes). The state vector ``x`` of the kernels is this, then the
arms' ``q``, ``v`` and torques ``τ``."""
_X, OBJECT_STATE_SIZE = _starts(OBJECT_STATE_FIELDS)
X_POSITION = _X["position"]
X_QUATERNION = _X["quaternion"]
X_TWIST = _X["twist"]


def object_state_vector(position, quaternion, twist) -> np.ndarray:
    """The object's state (OBJECT_STATE_SIZE,) as the kernels read it (``OBJECT_STATE_FIELDS``)."""
    return np.concatenate((position, quaternion, twist))


def state_vector(position, quaternion, twist, q, v, tau) -> np.ndarray:
    """The kernels' state vector ``x`` (13 + nq + 2 nv,): object state, ``q``, ``v``, ``τ``."""
    return np.concatenate((position, quaternion, twist, q, v, tau))


def state_size(nq: int, nv: int) -> int:
    """Length of :func:`state_vector` for ``nq`` positions and ``nv`` velocities."""
    return OBJECT_STATE_SIZE + nq + 2 * nv


# ------------------------------------------------------------------ parameters
PARAM_FIELDS = (("mass", 1), ("inertia", 9), ("gravity", 3), ("baumgarte_alpha", 1),
                ("baumgarte_beta", 1), ("baumgarte_on", 1), ("rcond_tol", 1),
                ("object_rcond_tol", 1))
"""The float64 parameter vector: object mass [kg], inertia about the COM in object axes
(row-major) [kg m²], gravity [m/s²], Baumgarte ``α``, ``β`` [1/s] and on-flag (1.0 = on), and
the solver thresholds on each ``S_i`` and on the reduced object matrix. (The loop's integrator
is in its argument types: ``contact_loop._step``.)"""
_P, N_PARAMS = _starts(PARAM_FIELDS)
P_MASS = _P["mass"]
P_INERTIA = _P["inertia"]
P_GRAVITY = _P["gravity"]
P_BAUMGARTE_ALPHA = _P["baumgarte_alpha"]
P_BAUMGARTE_BETA = _P["baumgarte_beta"]
P_BAUMGARTE_ON = _P["baumgarte_on"]
P_RCOND_TOL = _P["rcond_tol"]
P_OBJECT_RCOND_TOL = _P["object_rcond_tol"]


def parameter_vector(mass: float, inertia: np.ndarray, gravity: np.ndarray, rcond_tol: float,
                     object_rcond_tol: float) -> np.ndarray:
    """The parameter vector (:data:`PARAM_FIELDS`), Baumgarte off."""
    params = np.zeros(N_PARAMS)
    params[P_MASS] = mass
    params[P_INERTIA:P_INERTIA + 9] = np.asarray(inertia, dtype=float).ravel()
    params[P_GRAVITY:P_GRAVITY + 3] = gravity
    params[P_RCOND_TOL] = rcond_tol
    params[P_OBJECT_RCOND_TOL] = object_rcond_tol
    return params


def with_baumgarte(params: np.ndarray, alpha: float, beta: float) -> np.ndarray:
    """A copy of ``params`` with Baumgarte stabilisation ``(α, β)`` [1/s] switched on."""
    out = params.copy()
    out[P_BAUMGARTE_ALPHA], out[P_BAUMGARTE_BETA], out[P_BAUMGARTE_ON] = alpha, beta, 1.0
    return out


# ------------------------------------------------------------------ controller vectors
OBJECT_POSE_FIELDS = (("position", 3), ("rotation", 9), ("twist", 6))
"""The object as the controller kernels read it: COM position [m], rotation (row-major),
twist ``[ẋ; ω]``."""
_OX, OBJECT_POSE_SIZE = _starts(OBJECT_POSE_FIELDS)
OX_POSITION = _OX["position"]
OX_ROTATION = _OX["rotation"]
OX_TWIST = _OX["twist"]

REFERENCE_FIELDS = (("position", 3), ("rotation", 9), ("twist", 6), ("acceleration", 6))
"""The reference motion of the object at one time: position [m], rotation (row-major), twist
and classical acceleration, world axes at the COM."""
_REF, REFERENCE_SIZE = _starts(REFERENCE_FIELDS)
REF_POSITION = _REF["position"]
REF_ROTATION = _REF["rotation"]
REF_TWIST = _REF["twist"]
REF_ACCELERATION = _REF["acceleration"]


def reference_vector(position, rotation, twist, acceleration) -> np.ndarray:
    """The reference vector (:data:`REFERENCE_FIELDS`)."""
    return np.concatenate((position, np.asarray(rotation).ravel(), twist, acceleration))


TRAJECTORY_FIELDS = (("time", 1), ("position", 3), ("rotation", 9), ("displacement", 3),
                     ("log", 3), ("axis", 3))
"""One row of a minimum-jerk trajectory's table per waypoint ``k``: its time [s], position
[m] and rotation (row-major), then for the segment ``k -> k + 1`` (zeros on the last row) the
displacement ``p_{k+1} - p_k`` [m], the body-frame rotation vector ``log(R_kᵀ R_{k+1})``
[rad] and that vector in world axes ``R_k log``."""
_TR, TRAJECTORY_WIDTH = _starts(TRAJECTORY_FIELDS)
TR_TIME = _TR["time"]
TR_POSITION = _TR["position"]
TR_ROTATION = _TR["rotation"]
TR_DISPLACEMENT = _TR["displacement"]
TR_LOG = _TR["log"]
TR_AXIS = _TR["axis"]


SUPPORT_PLANE_FIELDS = (("point", 3), ("x_axis", 3), ("y_axis", 3), ("half_extent", 2))
"""The plane of each support row's support: its point [m] (the rectangle's centre), its unit
in-plane axes and the rectangle's half extents along them [m] (``inf`` for a whole plane)."""
_PL, SUPPORT_PLANE_SIZE = _starts(SUPPORT_PLANE_FIELDS)
PLANE_POINT = _PL["point"]
PLANE_X_AXIS = _PL["x_axis"]
PLANE_Y_AXIS = _PL["y_axis"]
PLANE_HALF_EXTENT = _PL["half_extent"]


PHASE_FIELDS = (("t", 1), ("duration", 1), ("kind", 1), ("pivot", 3), ("axis", 3),
                ("angle", 1), ("displacement", 3), ("start_position", 3),
                ("start_rotation", 9), ("support_margin", 1))
"""One phase of ``phased_pd`` (:class:`~multiarm_pin.sim.controllers.phased.Phase`) per row
of its table: start time and duration [s], kind (:data:`PHASE_HOLD`, :data:`PHASE_TILT`,
:data:`PHASE_MOVE`), the tilt's world pivot [m], unit axis and angle [rad], the move's world
displacement [m], the reference pose at the phase's start (position [m], rotation row-major)
and the least push of the support rows planned to press [N]. The phases' contact sets are
arrays beside the table (see :func:`multiarm_pin._compiled.phased.phased_torques`)."""
_PH, PHASE_SIZE = _starts(PHASE_FIELDS)
PH_T = _PH["t"]
PH_DURATION = _PH["duration"]
PH_KIND = _PH["kind"]
PH_PIVOT = _PH["pivot"]
PH_AXIS = _PH["axis"]
PH_ANGLE = _PH["angle"]
PH_DISPLACEMENT = _PH["displacement"]
PH_START_POSITION = _PH["start_position"]
PH_START_ROTATION = _PH["start_rotation"]
PH_SUPPORT_MARGIN = _PH["support_margin"]
PHASE_HOLD, PHASE_TILT, PHASE_MOVE = 0, 1, 2
"""Codes of the phase kinds ``hold``, ``tilt``, ``move`` (``PH_KIND``)."""


WRENCH_FIELDS = (("from", 1), ("to", 1), ("wrench", 6))
"""One external wrench interval of a :class:`~multiarm_pin.sim.disturbances.WrenchSchedule`:
it acts for ``from <= t < to`` [s], ``[f; m]`` at the object's COM, world axes [N, N m]."""
_WE, WRENCH_WIDTH = _starts(WRENCH_FIELDS)
WE_FROM = _WE["from"]
WE_TO = _WE["to"]
WE_WRENCH = _WE["wrench"]


PD_GAIN_FIELDS = (("kp", 6), ("kd", 6))
"""The object PD gains ``K_p`` [1/s²] and ``K_d`` [1/s], per component of ``[x; θ]``."""
_PD, PD_GAINS_SIZE = _starts(PD_GAIN_FIELDS)
PD_KP = _PD["kp"]
PD_KD = _PD["kd"]


def pd_gain_vector(kp, kd) -> np.ndarray:
    """The PD gain vector (:data:`PD_GAIN_FIELDS`)."""
    return np.concatenate((kp, kd)).astype(float)


HOLD_GAIN_FIELDS = (("hold_kp", 1), ("hold_kd", 1), ("damping", 1), ("margin", 1))
"""Held-point gains ``hold_kp`` [1/s²], ``hold_kd`` [1/s], the relative Jacobian damping and
the force margin [N] of the controller kernels."""
_HG, HOLD_GAINS_SIZE = _starts(HOLD_GAIN_FIELDS)
GAIN_HOLD_KP = _HG["hold_kp"]
GAIN_HOLD_KD = _HG["hold_kd"]
GAIN_DAMPING = _HG["damping"]
GAIN_MARGIN = _HG["margin"]


def hold_gain_vector(hold_kp: float, hold_kd: float, damping: float, margin: float
                     ) -> np.ndarray:
    """The held-point gain vector (:data:`HOLD_GAIN_FIELDS`)."""
    gains = np.zeros(HOLD_GAINS_SIZE)
    gains[GAIN_HOLD_KP], gains[GAIN_HOLD_KD] = hold_kp, hold_kd
    gains[GAIN_DAMPING], gains[GAIN_MARGIN] = damping, margin
    return gains


# ------------------------------------------------------------------ buffer segments
SEGMENT_TABLE = (
    ("M", ("n", "k", "k")), ("nle", ("n", "k")), ("J", ("n", 6, "k")), ("Jdot_qdot", ("n", 6)),
    ("position", ("n", 3)), ("rotation", ("n", 3, 3)), ("twist", ("n", 6)), ("v", ("n", "k")),
    ("rows", ("n", "m", ROW_WIDTH)), ("h", ("n", "k")), ("W", ("n", "k", "m")),
    ("W_o", ("n", 6, "m")), ("c", ("n", "m")), ("M_o", (6, 6)), ("h_o", (6,)),
    ("a_o", (6,)), ("qdd", ("n", "k")), ("mu", ("n", "m")),
)
"""The segments of the flat buffer, in order, with their shapes: the arms' terms (``M``,
``nle``, ``J`` LWA, ``Jdot_qdot``, tool ``position``, ``rotation``, ``twist``, padded ``v``),
the packed constraint ``rows``, the blocks (``h``, ``W``, ``W_o``, ``c``, ``M_o``, ``h_o``) and
the solution (``a_o``, ``qdd``, ``mu``); ``n`` arms, ``k = nv_max``, ``m = N_max``."""
SEGMENTS = tuple(name for name, _ in SEGMENT_TABLE)
"""Names of the buffer segments, in order."""
SEG_M = SEGMENTS.index("M")
SEG_NLE = SEGMENTS.index("nle")
SEG_J = SEGMENTS.index("J")
SEG_JDOT_QDOT = SEGMENTS.index("Jdot_qdot")
SEG_POSITION = SEGMENTS.index("position")
SEG_ROTATION = SEGMENTS.index("rotation")
SEG_TWIST = SEGMENTS.index("twist")
SEG_V = SEGMENTS.index("v")
SEG_ROWS = SEGMENTS.index("rows")
SEG_H = SEGMENTS.index("h")
SEG_W = SEGMENTS.index("W")
SEG_W_O = SEGMENTS.index("W_o")
SEG_C = SEGMENTS.index("c")
SEG_M_O = SEGMENTS.index("M_o")
SEG_H_O = SEGMENTS.index("h_o")
SEG_A_O = SEGMENTS.index("a_o")
SEG_QDD = SEGMENTS.index("qdd")
SEG_MU = SEGMENTS.index("mu")
N_SEGMENTS = len(SEGMENTS)

_DIM_CODE = {"n": -1, "k": -2, "m": -3}
_MAX_NDIM = 3
SHAPE_CODES = np.array([[_DIM_CODE.get(d, d) for d in shape] + [1] * (_MAX_NDIM - len(shape))
                        for _, shape in SEGMENT_TABLE], dtype=np.int64)
"""(N_SEGMENTS, 3) int64: each segment's shape, ``-1, -2, -3`` standing for ``n, k, m``
(padded with 1), the form in which the compiled code reads :data:`SEGMENT_TABLE`."""


@kernel(refcounts=False)
def _dim(code, n, k, m):  # pragma: no cover - compiled
    """A dimension of :data:`SHAPE_CODES` for ``n`` arms, ``k = nv_max``, ``m = N_max``."""
    if code == -1:
        return n
    if code == -2:
        return k
    if code == -3:
        return m
    return code


# ------------------------------------------------------------------ dimensions
DIMS_FIELDS = (("k", 1), ("m", 1), ("nv", 1), ("n", 1), ("offsets", N_SEGMENTS + 1))
"""The int64 vector ``dims``: ``nv_max``, ``N_max``, total joints, arms, then the buffer
segments' start offsets for those (:func:`buffer_layout`), computed once with the
dimensions: the kernels read them (:func:`offsets`) and allocate nothing for them."""
_D, DIMS_SIZE = _starts(DIMS_FIELDS)
DIMS_K = _D["k"]
DIMS_M = _D["m"]
DIMS_NV = _D["nv"]
DIMS_N = _D["n"]
DIMS_OFFSETS = _D["offsets"]


def dims_vector(k: int, m: int, nv: int, n: int) -> np.ndarray:
    """The ``dims`` vector (:data:`DIMS_FIELDS`)."""
    dims = np.zeros(DIMS_SIZE, dtype=np.int64)
    dims[DIMS_K], dims[DIMS_M], dims[DIMS_NV], dims[DIMS_N] = k, m, nv, n
    dims[DIMS_OFFSETS:] = buffer_layout(n, k, m)[0]
    return dims


@kernel(inline="always")
def offsets(dims):  # pragma: no cover - compiled
    """The segments' start offsets (N_SEGMENTS + 1,) int64 in ``dims``: a view of it."""
    return dims[DIMS_OFFSETS:DIMS_OFFSETS + N_SEGMENTS + 1]


def _shaped_python(buf, start, shape):
    size = 1
    for d in shape:
        size *= d
    return buf[start:start + size].reshape(shape)


@intrinsic
def _shaped(typingctx, buf, start, shape):
    """The C-ordered view of ``shape`` in the one-axis array ``buf`` from element ``start``.

    ``buf[start:start + prod(shape)].reshape(shape)``, made without the bounds arithmetic of
    the slice and the checks of ``reshape`` (numba lowers each into code of its own, in
    every kernel that takes a view): the segments' offsets and shapes agree by construction
    (:func:`buffer_layout`). The same array type as that expression.
    """
    if not (isinstance(buf, types.Array) and buf.ndim == 1 and buf.layout == "C"
            and isinstance(start, types.Integer) and isinstance(shape, types.BaseTuple)
            and all(isinstance(d, types.Integer) for d in shape)):
        return None

    def codegen(context, builder, sig, args):
        whole = make_array(sig.args[0])(context, builder, args[0])
        dims = [context.cast(builder, builder.extract_value(args[2], i), d, types.intp)
                for i, d in enumerate(sig.args[2])]
        strides = []
        step = whole.itemsize
        for d in reversed(dims):
            strides.insert(0, step)
            step = builder.mul(step, d)
        first = context.cast(builder, args[1], sig.args[1], types.intp)
        view = make_array(sig.return_type)(context, builder)
        populate_array(view, data=builder.gep(whole.data, [first], inbounds=True), shape=dims,
                       strides=strides, itemsize=whole.itemsize, meminfo=whole.meminfo,
                       parent=whole.parent)
        return impl_ret_borrowed(context, builder, sig.return_type, view._getvalue())

    return signature(buf.copy(ndim=len(shape), layout="C"), buf, start, shape), codegen


shaped = _shaped_python if jit_disabled() else _shaped
"""``shaped(buf, start, shape)``: the view of ``shape`` in ``buf`` from element ``start``
(:func:`_shaped` in a kernel; the slice and ``reshape`` without the JIT)."""


@kernel(inline="always")
def view2(buf, off, seg, n, k, m):  # pragma: no cover - compiled
    """The two-axis segment ``seg`` of ``buf``, shaped as :data:`SEGMENT_TABLE` says."""
    return shaped(buf, off[seg], (_dim(SHAPE_CODES[seg, 0], n, k, m),
                                  _dim(SHAPE_CODES[seg, 1], n, k, m)))


@kernel(inline="always")
def view3(buf, off, seg, n, k, m):  # pragma: no cover - compiled
    """The three-axis segment ``seg`` of ``buf``, shaped as :data:`SEGMENT_TABLE` says."""
    return shaped(buf, off[seg], (_dim(SHAPE_CODES[seg, 0], n, k, m),
                                  _dim(SHAPE_CODES[seg, 1], n, k, m),
                                  _dim(SHAPE_CODES[seg, 2], n, k, m)))


def segment_shapes(n: int, k: int, m: int) -> dict[str, tuple[int, ...]]:
    """Shapes of the buffer segments for n arms, ``k = nv_max`` joints, ``m = N_max`` rows."""
    size = {"n": n, "k": k, "m": m}
    return {name: tuple(size.get(d, d) for d in shape) for name, shape in SEGMENT_TABLE}


def buffer_layout(n: int, k: int, m: int) -> tuple[np.ndarray, int]:
    """Start offsets (N_SEGMENTS + 1,) int64 of every segment, and the buffer's size.

    The last offset is the size.
    """
    shapes = segment_shapes(n, k, m)
    sizes = [int(np.prod(shapes[name], dtype=np.int64)) for name in SEGMENTS]
    off = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    return off, int(off[-1])


@dataclass(frozen=True)
class Segment:
    """Where a segment lies in the buffer: ``buf[start:stop].reshape(shape)``."""

    start: int
    stop: int
    shape: tuple[int, ...]

    def view(self, buf: np.ndarray) -> np.ndarray:
        """The segment of ``buf`` (a view)."""
        return buf[self.start:self.stop].reshape(self.shape)


def segment_slices(n: int, k: int, m: int) -> dict[str, Segment]:
    """Every segment's :class:`Segment` for n arms, ``k = nv_max``, ``m = N_max``."""
    off, _ = buffer_layout(n, k, m)
    shapes = segment_shapes(n, k, m)
    return {name: Segment(int(off[j]), int(off[j + 1]), shapes[name])
            for j, name in enumerate(SEGMENTS)}
