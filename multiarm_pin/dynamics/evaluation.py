"""One evaluation of the system at a state: the compiled path, its buffer views, the reference.

:class:`CompiledSystem` holds the constant inputs of the compiled kernels of
:mod:`multiarm_pin._compiled.evaluate` for one system (arm table, contact tables, parameter
vector, dims, all laid out in :mod:`multiarm_pin._compiled.layout`) and runs them: one
compiled call that computes the arms' terms (the compiled rigid-body pass, Pinocchio's
algorithms on the arms' tables; a Pinocchio pass instead when an arm has a joint that pass does
not support) and writes the arm terms, constraint rows, blocks and (for a step) the
object-first solution into one fresh flat buffer. The results are handed
out as views of that buffer, made on first access (a step that only needs the solution
builds none): :class:`BufferBlocks`, :class:`BufferArmTerms` and
:class:`BufferConstraintTerms` are the :class:`~multiarm_pin.dynamics.SystemBlocks`,
:class:`~multiarm_pin.model.arm_set.ArmSetTerms` and
:class:`~multiarm_pin.constraints.ConstraintTerms` of the compiled path: small classes with a
plain constructor that hold the buffer and expose its segments as read-only properties (no
validation: the shapes are right by construction of the layout).

:func:`reference_evaluation` computes the same :class:`Evaluation` with numpy (the oracle of
the compiled path, ``MultiArmSystem.blocks(..., reference=True)``)::

    W_i = J_iᵀ G_tool,iᵀ        W_o,i = G_object,iᵀ        h_i = τ_i - nle_i
    c_i = -G_tool,i J̇q̇_i - κ_i  (Baumgarte: - 2α φ̇_i - β² φ_i)
    M_o = diag(m I, R I_c Rᵀ)   h_o = [m g; -ω × I_w ω]

(Longer than most modules: the compiled path, the views of its buffer and the
numpy reference are the two implementations of one evaluation and belong together.)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from multiarm_pin._compiled import evaluate as kernels
from multiarm_pin._compiled import layout
from multiarm_pin._compiled.object_first import SOLVE_OK
from multiarm_pin.constraints import ConstraintSet, ConstraintTerms
from multiarm_pin.dynamics.blocks import Solution, SystemBlocks, _replacement
from multiarm_pin.dynamics.object_first import DEFAULT_RCOND_TOL, OBJECT_RCOND_TOL
from multiarm_pin.exceptions import DynamicsError, InputError
from multiarm_pin.model.arm_set import ArmSet, ArmSetTerms
from multiarm_pin.model.kinematics import BodyKinematics
from multiarm_pin.model.rigid_object import RigidObject


class Evaluation:
    """Everything computed for one state (and torque).

    Args:
        blocks: the padded coefficient blocks (``h`` includes the torque given, if any).
        arms: the arms' stacked Pinocchio terms (mass matrices, tool Jacobians, ...).
        constraints: the constraint rows (``φ``, ``φ̇``, ``G``, ``κ``, contact points ...).
        active: see the attribute.

    Attributes:
        blocks, arms, constraints: as given (read-only).
        active: (n, N_max) bool, the arms' contact rows that touch (the active set of the
            event-driven simulation: bilateral rows and touching unilateral rows), or None
            (every row touches). :func:`~multiarm_pin.sim.simulation.simulate` sets it on the
            evaluation it hands to the controller, before the call
            (:meth:`with_active`); controllers that plan contact forces use it.
    """

    def __init__(self, blocks: SystemBlocks, arms: ArmSetTerms | None,
                 constraints: ConstraintTerms | None, active: np.ndarray | None = None):
        self._blocks = blocks
        self._arms = arms
        self._constraints = constraints
        self.active = active

    @property
    def blocks(self) -> SystemBlocks:
        """The padded coefficient blocks."""
        return self._blocks

    @property
    def arms(self) -> ArmSetTerms:
        """The arms' stacked terms."""
        return self._arms

    @property
    def constraints(self) -> ConstraintTerms:
        """The constraint rows."""
        return self._constraints

    def with_active(self, active: np.ndarray | None) -> Evaluation:
        """Set :attr:`active` and return ``self``.

        In place: an evaluation belongs to one state and one active set.

        Args:
            active: (n, N_max) bool mask of the touching rows, or None (all touch).
        """
        self.active = None if active is None else np.asarray(active, dtype=bool)
        return self


# ------------------------------------------------------------------ the buffer and its views
@dataclass(frozen=True)
class BufferLayout:
    """Where everything lies in the flat buffer of one system (constant per system).

    Attributes:
        segments: every segment's :class:`~multiarm_pin._compiled.layout.Segment`, by name.
        size: length of the buffer.
        blocks_constant: the constant fields of the system's :class:`SystemBlocks` (``nv``,
            ``N``, masks, ``has_constraint_padding``, ``padding_diagonal``), computed once by
            a validated build.
        N: (n,) constraints per arm (read-only, shared by the constraint terms).
        mask: (n, N_max) real constraint slots (read-only, shared).
        solution_segments: the bounds of the segments ``a_o``, ``qdd``, ``mu`` as plain
            ints and shapes: ``(a_start, a_stop, q_start, q_stop, q_shape, mu_start,
            mu_stop, mu_shape)``.
    """

    segments: dict
    size: int
    blocks_constant: dict
    N: np.ndarray
    mask: np.ndarray
    solution_segments: tuple

    def solution(self, buf: np.ndarray, blocks: SystemBlocks) -> Solution:
        """The object-first :class:`Solution` in the solution segments of ``buf``."""
        a0, a1, q0, q1, q_shape, m0, m1, m_shape = self.solution_segments  # runs once per step
        return Solution(buf[a0:a1], buf[q0:q1].reshape(q_shape), buf[m0:m1].reshape(m_shape),
                        "object_first", (), blocks)

    @classmethod
    def build(cls, nv_arm: np.ndarray, constraint_set: ConstraintSet, k: int) -> BufferLayout:
        """The layout for arms of ``nv_arm`` joints (padded to ``k``) and ``constraint_set``."""
        n, m = len(nv_arm), constraint_set.N_max
        segments = layout.segment_slices(n, k, m)
        probe = SystemBlocks(np.broadcast_to(np.eye(k), (n, k, k)).copy(), np.zeros((n, k)),
                             np.zeros((n, k, m)), np.zeros((n, 6, m)), np.zeros((n, m)),
                             np.eye(6), np.zeros(6), nv_arm, constraint_set.N.copy())
        constant = {}
        for name in ("nv", "N", "dof_mask", "constraint_mask", "padding_diagonal"):
            arr = getattr(probe, name)
            if arr.dtype == bool or name == "padding_diagonal":  # nv, N stay writable like
                arr.setflags(write=False)  # any SystemBlocks' (one compiled kernel variant)
            constant[name] = arr
        constant["has_constraint_padding"] = probe.has_constraint_padding
        a_o, qdd, mu = segments["a_o"], segments["qdd"], segments["mu"]
        return cls(segments, segments[layout.SEGMENTS[-1]].stop, constant, constraint_set.N,
                   constraint_set.mask, (a_o.start, a_o.stop, qdd.start, qdd.stop, qdd.shape,
                                         mu.start, mu.stop, mu.shape))


class _View:
    """Read-only property: a field made from the buffer on first access, then kept.

    ``make(owner)`` builds the value; it is kept in the owner's instance dict under the
    field's name (no dict of its own to make per evaluation). A data descriptor, so the
    field can be neither assigned nor shadowed by that entry.
    """

    def __init__(self, make: Callable):
        self.make = make
        self.name = ""

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        d = obj.__dict__
        value = d.get(self.name)
        if value is None:
            value = d[self.name] = self.make(obj)
        return value

    def __set__(self, obj, value) -> None:
        raise AttributeError(f"{self.name} is read-only (a view of the evaluation buffer)")


def _segment(name: str) -> _View:
    """The field ``name``: the buffer segment of the same name."""
    return _View(lambda self: self._layout.segments[name].view(self._buf))


def _constant(name: str) -> property:
    """The field ``name``: the system's constant, shared by every evaluation."""
    return property(lambda self: self._layout.blocks_constant[name])


class BufferBlocks(SystemBlocks):
    """:class:`SystemBlocks` of the compiled path: views of the buffer, made on first access.

    Args:
        buf: the evaluation's flat buffer.
        layout: the system's buffer layout.
        h: ``h`` to use instead of the buffer's (e.g. with torques added), or None.
        h_o: likewise for ``h_o``.
    """

    # the fields are read-only descriptors: the inherited frozen check is not needed for
    # them, and the plain one is several times faster on the private attributes set below
    __setattr__ = object.__setattr__

    M = _segment("M")
    h = _segment("h")
    W = _segment("W")
    W_o = _segment("W_o")
    c = _segment("c")
    M_o = _segment("M_o")
    h_o = _segment("h_o")
    nv = _constant("nv")
    N = _constant("N")
    dof_mask = _constant("dof_mask")
    constraint_mask = _constant("constraint_mask")
    has_constraint_padding = _constant("has_constraint_padding")
    padding_diagonal = _constant("padding_diagonal")

    def __init__(self, buf: np.ndarray, layout: BufferLayout, h: np.ndarray | None = None,
                 h_o: np.ndarray | None = None):
        # into the instance dict: a __setattr__ in the class dict makes every assignment a
        # Python-level call (this runs once per step)
        d = self.__dict__
        d["_buf"] = buf
        d["_layout"] = layout
        if h is not None:
            d["h"] = h  # the field's kept value (see _View)
        if h_o is not None:
            d["h_o"] = h_o

    @property
    def buffer(self) -> np.ndarray:
        """The flat buffer these blocks are views of (``h``, ``h_o`` may differ)."""
        return self._buf

    @property
    def layout(self) -> BufferLayout:
        """The buffer's layout."""
        return self._layout

    def replaced(self, *, h: np.ndarray | None = None,
                 h_o: np.ndarray | None = None) -> BufferBlocks:
        """The same views with another ``h`` and/or ``h_o`` (see :meth:`SystemBlocks.replaced`)."""
        views = self.__dict__
        if h is not None:
            h = _replacement(h, self.h, "h")
        if h_o is not None:
            h_o = _replacement(h_o, self.h_o, "h_o")
        return BufferBlocks(self._buf, self._layout, views.get("h") if h is None else h,
                            views.get("h_o") if h_o is None else h_o)


class BufferArmTerms(ArmSetTerms):
    """:class:`ArmSetTerms` of the compiled path: views of the buffer, made on first access.

    ``M`` shares memory with the blocks' ``M``.

    Args:
        buf: the evaluation's flat buffer.
        layout: the system's buffer layout.
    """

    __setattr__ = object.__setattr__  # the fields are read-only descriptors (see BufferBlocks)
    M = _segment("M")
    nle = _segment("nle")
    J = _segment("J")
    Jdot_qdot = _segment("Jdot_qdot")
    v = _segment("v")
    tools = _View(lambda self: BodyKinematics(*(
        self._layout.segments[name].view(self._buf) for name in ("position", "rotation",
                                                                  "twist"))))

    def __init__(self, buf: np.ndarray, layout: BufferLayout):
        self._buf = buf
        self._layout = layout


def _row_field(name: str) -> _View:
    """A field of :class:`ConstraintTerms`: the row field ``name`` of the packed rows (a view)."""
    return _View(lambda self: layout.row_field(self._rows, name))


class BufferConstraintTerms(ConstraintTerms):
    """:class:`ConstraintTerms` of the compiled path: views of the packed rows of the buffer.

    Args:
        buf: the evaluation's flat buffer.
        layout: the system's buffer layout.
    """

    __setattr__ = object.__setattr__  # the fields are read-only descriptors (see BufferBlocks)
    phi = _row_field("phi")
    phi_dot = _row_field("phi_dot")
    kappa = _row_field("kappa")
    G_tool = _row_field("G_tool")
    G_object = _row_field("G_object")
    contact_points = _row_field("contact_point")
    normals = _row_field("normal")
    N = property(lambda self: self._layout.N)
    mask = property(lambda self: self._layout.mask)

    def __init__(self, buf: np.ndarray, layout: BufferLayout):
        self._layout = layout
        self._rows = layout.segments["rows"].view(buf)


class BufferEvaluation(Evaluation):
    """:class:`Evaluation` of the compiled path; ``arms`` and ``constraints`` made on demand.

    Args:
        blocks: its blocks (at zero torque or with the torques given), views of the buffer.
    """

    def __init__(self, blocks: BufferBlocks):
        self._blocks = blocks
        self._arms = self._constraints = self.active = None

    @property
    def buffer(self) -> np.ndarray:
        """The evaluation's flat buffer."""
        return self._blocks.buffer

    @property
    def arms(self) -> ArmSetTerms:
        """The arms' terms (views of the buffer)."""
        if self._arms is None:
            self._arms = BufferArmTerms(self._blocks.buffer, self._blocks.layout)
        return self._arms

    @property
    def constraints(self) -> ConstraintTerms:
        """The constraint rows (views of the buffer)."""
        if self._constraints is None:
            self._constraints = BufferConstraintTerms(self._blocks.buffer, self._blocks.layout)
        return self._constraints


# ------------------------------------------------------------------ the compiled path
_REJECTED = -1
"""Status of :meth:`CompiledSystem.evaluate`'s fast path: an input rejected (a type the
kernel was not compiled for, a missing attribute): the checked path decides."""

_guarded = False
"""True once :func:`_guarded_call` has stopped ``evaluate_state``'s dispatcher from compiling
new specialisations (never with ``NUMBA_DISABLE_JIT``)."""


def _guarded_call(*args) -> int:
    """``kernels.evaluate_state(*args)`` on checked arguments of the kernel's types.

    The first call compiles (or loads) the specialisation; then the dispatcher is told to
    compile no other one: an argument of another type (an int or read-only array, a list, a
    strided view) in :meth:`CompiledSystem.evaluate`'s fast path then raises ``TypeError``
    at once, instead of compiling a specialisation per type (a minute each), and the checked
    path converts or rejects it. The type check is the dispatcher's own, so the fast path
    checks nothing in Python. A system whose constant tables have other types than the
    first one's (none known) compiles its specialisation here.
    """
    global _guarded
    kernel = kernels.evaluate_state
    if not hasattr(kernel, "disable_compile"):  # NUMBA_DISABLE_JIT: plain Python
        return kernel(*args)
    try:
        return kernel(*args)
    except TypeError:  # compiling disabled, and these constant tables' types are new
        if not _guarded:
            raise
        kernel.disable_compile(False)
        try:
            return kernel(*args)
        finally:
            kernel.disable_compile(True)
    finally:
        if not _guarded and kernel.signatures:
            kernel.disable_compile(True)
            _guarded = True


class CompiledSystem:
    """The compiled path of one system: constant kernel inputs and the calls that use them.

    Args:
        arm_set: the system's arms (with the system's gravity on their models).
        constraint_set: the system's joints.
        obj: the object.
        gravity: (3,) [m/s²].
        check_state: the system's state check, called on the slow path to raise an error
            that names the field (``MultiArmSystem.check_state``).

    Attributes:
        layout: the :class:`BufferLayout`.
        arm_table: (n, 1 + 2k) int64 (``ARM_*`` columns of :mod:`multiarm_pin._compiled.layout`).
        contact_tables: the constraint set's :class:`~multiarm_pin._compiled.layout.ContactTables`.
        params: (N_PARAMS,) the parameter vector, Baumgarte off.
        dims: (DIMS_SIZE,) int64 ``(k, m, nv, n)``.
        N: (n,) int64 constraint rows per arm.
        nv_arm: (n,) int64 joints per arm.
        model: the arms' :class:`~multiarm_pin.model.compiled_model.CompiledModel` (the
            tables of the compiled rigid-body pass, which then replaces Pinocchio's pass), or
            None when an arm has a joint it does not support.
    """

    def __init__(self, arm_set: ArmSet, constraint_set: ConstraintSet, obj: RigidObject,
                 gravity: np.ndarray, check_state: Callable):
        aset = arm_set
        n, k, m = aset.n, aset.nv_max, constraint_set.N_max
        self.arm_set = aset
        self.nq, self.nv = aset.nq, aset.nv
        self.arm_table = layout.arm_table(aset.nv_arm, aset.joint_index,
                                          aset.tool_support.astype(int))
        self.nv_arm = np.ascontiguousarray(self.arm_table[:, layout.ARM_NV])
        self.contact_tables = constraint_set.contact_tables
        self.params = layout.parameter_vector(obj.mass, obj.inertia, gravity,
                                              DEFAULT_RCOND_TOL, OBJECT_RCOND_TOL)
        self.dims = layout.dims_vector(k, m, aset.nv, n)
        self.v_starts = aset.v_starts
        self.N = np.ascontiguousarray(constraint_set.N, dtype=np.int64)
        self.layout = BufferLayout.build(aset.nv_arm.copy(), constraint_set, k)
        self._single = len(aset.groups) == 1
        self._group_tables = []
        for g in aset.groups:  # joint indices relative to the group's velocity vector
            gi = self.arm_table[g.arms].copy()
            joints = gi[:, layout.ARM_JOINTS:layout.ARM_JOINTS + k]
            joints[:] = np.maximum(joints - g.v.start, 0)
            self._group_tables.append(gi)
        self._zero_tau = np.zeros(self.nv)
        self._zero_tau.setflags(write=False)
        self._tau_zero = np.zeros(self.nv)  # the same, writable: the kernel's argument type
        self._check_state = check_state
        self._baumgarte_key = self._baumgarte_params = None  # see _params_with
        # the arms' tables of the compiled rigid-body pass (None: a joint it does not support,
        # then Pinocchio's pass)
        self.model = aset.compiled_model
        if self.model is not None:  # evaluate_state's constant arguments: the packed
            # tables and the mass-matrix work array (zero off the arms' blocks)
            self._head = (*kernels.state_tables(
                self.model.ints, self.model.floats, self.arm_table, self.v_starts,
                self.contact_tables.ints, self.contact_tables.floats, self.dims, self.N),
                self.model.outputs()[2])

    def evaluate(self, state, tau, baumgarte, step: bool
                 ) -> tuple[BufferEvaluation, Solution | None]:
        """Blocks (and, if ``step``, the object-first solution) at a state, compiled.

        Args:
            state: the :class:`~multiarm_pin.system.SystemState`.
            tau: (nv,) joint torques [N m] or None (zero).
            baumgarte: ``(α, β)`` [1/s] or None.
            step: also solve.

        Returns:
            ``(evaluation, solution)``; the solution is None if ``step`` is False or the
            kernel reported a doubtful case (singular or badly conditioned ``S_i`` / object
            matrix), which the caller hands to the numpy solvers.

        Raises:
            InputError: wrong shapes (naming the field).
            DynamicsError: NaN or infinity in the state or the torques.
        """
        buf = np.empty(self.layout.size)
        model = self.model
        status = _REJECTED
        if model is not None and _guarded:  # the fast path: the kernel checks the parts
            try:  # (lengths, finiteness) and its dispatcher their types: nothing in Python
                o = state.obj
                status = kernels.evaluate_state(
                    *self._head, o.position, o.quaternion, o.twist, state.q, state.v,
                    self._tau_zero if tau is None else tau,
                    self.params if baumgarte is None else self._params_with(baumgarte),
                    step, buf)
            except (AttributeError, TypeError, InputError):  # then checked below, in order
                status = _REJECTED
        if not 0 <= status < kernels.SOLVE_NOT_FINITE:  # rejected, NaN or a wrong length
            status = self._evaluate_checked(state, tau, baumgarte, step, buf)
        blocks = BufferBlocks(buf, self.layout)
        if step and status == SOLVE_OK:
            return BufferEvaluation(blocks), self.layout.solution(buf, blocks)
        return BufferEvaluation(blocks), None

    def _evaluate_checked(self, state, tau, baumgarte, step: bool, buf: np.ndarray) -> int:
        """Slow path of :meth:`evaluate`: every input checked, converted, evaluated into ``buf``.

        Raises naming the field that is wrong; what is acceptable but not of the kernel's
        types (lists, int or read-only arrays, strided views) is copied to them.

        Returns:
            The kernel's status (``SOLVE_OK`` or a doubtful case).
        """
        if tau is None:
            t = self._zero_tau
        else:
            t = np.asarray(tau, dtype=float)
            if t.shape != (self.nv,):
                raise InputError(f"tau: expected shape ({self.nv},), got {t.shape}")
        try:  # cheap checks first: types and shapes (finiteness is checked by the kernel)
            o = state.obj
            q, v = state.q, state.v
            ok = (q.shape == (self.nq,) and v.shape == (self.nv,)
                  and o.position.shape == (3,) and o.quaternion.shape == (4,)
                  and o.twist.shape == (6,))
        except (AttributeError, TypeError, ValueError):
            ok = False
        if not ok:
            self._check_state_and_tau(state, t)  # raises naming the field, or accepts
        o = state.obj
        parts = [np.array(a, dtype=np.float64, order="C")  # fresh, writable: the kernel's
                 for a in (o.position, o.quaternion, o.twist, state.q, state.v, t)]  # types
        params = self.params if baumgarte is None else self._params_with(baumgarte)
        model = self.model
        if model is not None:  # arm terms, blocks (and solve) in one compiled call
            status = _guarded_call(*self._head, *parts, params, step, buf)
            if status == kernels.SOLVE_BAD_LENGTH:  # cannot happen after the checks above
                raise RuntimeError("evaluate_state: the state's lengths do not match the "
                                   "system's compiled model tables")
            finite = status != kernels.SOLVE_NOT_FINITE
        else:
            x = layout.state_vector(*parts)
            H = self.arm_set.pinocchio_pass(parts[3], parts[4])
            finite, status = self.kernel_pass(H, x, params, buf, step)
        if not finite:
            self._check_state_and_tau(state, t)  # raises naming the field
            raise DynamicsError("state or torques contain NaN or infinity")
        return status

    def _params_with(self, baumgarte) -> np.ndarray:
        """The parameter vector with Baumgarte ``(α, β)`` on, checked once per value.

        A run passes the same tuple at every evaluation: a tuple of Python floats (immutable)
        is kept with its vector, so it is neither re-parsed nor copied again.
        """
        if baumgarte is self._baumgarte_key:
            return self._baumgarte_params
        params = layout.with_baumgarte(self.params, *baumgarte_gains(baumgarte))
        if type(baumgarte) is tuple and all(type(x) is float for x in baumgarte):
            self._baumgarte_key, self._baumgarte_params = baumgarte, params
        return params

    def kernel_pass(self, H: np.ndarray, x: np.ndarray, params: np.ndarray, buf: np.ndarray,
                    step: bool) -> tuple[bool, int]:
        """The compiled kernels after :meth:`ArmSet.pinocchio_pass` (which gave ``H``).

        Args:
            H: (n, 4, 4) tool placements.
            x: the state vector (:func:`~multiarm_pin._compiled.layout.state_vector`).
            params: (N_PARAMS,) the parameter vector.
            buf: the output buffer (``layout.size``).
            step: also solve (object-first) into the buffer.

        Returns:
            ``(finite, status)``: False if ``x`` holds NaN or infinity; the solve status
            (``SOLVE_OK`` when not solving).
        """
        aset = self.arm_set
        status = SOLVE_OK
        tables = self.contact_tables
        if self._single:  # one compiled call
            J, dJ, M, nle = aset.data_arrays()
            args = (J, dJ, M, nle, H, x, self.arm_table, self.v_starts, tables.ints,
                    tables.floats, params, self.dims)
            if step:
                status = kernels.step_system(*args, self.N, buf)
                return status != kernels.SOLVE_NOT_FINITE, status
            return kernels.evaluate_system(*args, buf), status
        for g, gi in zip(aset.groups, self._group_tables, strict=True):  # arm terms by group
            kernels.group_arm_terms(*g.views, H[g.arms], x, gi, self.dims, g.v.start,
                                    g.arms.start, buf)
        finite = kernels.finish_system(x, self.arm_table, self.v_starts, tables.ints,
                                       tables.floats, params, self.dims, buf)
        if step and finite:
            status = kernels.solve_buffer(self.N, params, self.dims, buf)
        return finite, status

    def solve_with_torques(self, blocks: BufferBlocks, tau_padded: np.ndarray
                           ) -> tuple[BufferBlocks, Solution | None]:
        """Object-first solve of compiled ``blocks`` (at zero torque) plus torques, compiled.

        Args:
            blocks: blocks of :meth:`evaluate` at zero torque.
            tau_padded: (n, nv_max) torques [N m], zero on padding.

        Returns:
            ``(blocks_with_torques, solution)``: the blocks with ``h + τ`` (views of the same
            buffer); the solution, or None if the kernel reported a doubtful case.
        """
        from multiarm_pin._compiled.controller_kernels import solve_with_torques

        status = solve_with_torques(blocks.buffer, self.dims, self.N, self.params, tau_padded,
                                    np.zeros(6))
        return self.with_torques(blocks, tau_padded, status)

    def with_torques(self, blocks: BufferBlocks, tau_padded: np.ndarray, status: int
                     ) -> tuple[BufferBlocks, Solution | None]:
        """``blocks`` with ``h + τ``, and the solution in the buffer if ``status`` is OK.

        Args:
            blocks: blocks of :meth:`evaluate` at zero torque.
            tau_padded: (n, nv_max) the torques [N m] that were solved with.
            status: the status of the compiled solve.
        """
        with_tau = blocks.replaced(h=blocks.h + tau_padded)
        if status == SOLVE_OK:
            return with_tau, self.layout.solution(blocks.buffer, with_tau)
        return with_tau, None

    def _check_state_and_tau(self, state, tau: np.ndarray) -> None:
        """Slow path of the checks: raise naming the field that is wrong or not finite."""
        self._check_state(state)
        if not np.all(np.isfinite(tau)):
            raise DynamicsError(f"tau contains NaN or infinity: {tau.tolist()}")


# ------------------------------------------------------------------ the numpy reference
def reference_evaluation(arm_set: ArmSet, constraint_set: ConstraintSet, obj: RigidObject,
                         gravity: np.ndarray, state, tau: np.ndarray | None = None,
                         baumgarte: tuple[float, float] | None = None) -> Evaluation:
    """The blocks by the numpy reference implementation (the compiled path's oracle).

    :meth:`ArmSet.evaluate`, :meth:`ConstraintSet.evaluate` and an ``einsum`` assembly (see
    the module docstring). The state must have been checked.

    Args:
        arm_set: the system's arms.
        constraint_set: its joints.
        obj: the object.
        gravity: (3,) [m/s²].
        state: the state.
        tau: (nv,) joint torques [N m], zero when None.
        baumgarte: ``(α, β)`` [1/s] or None.

    Raises:
        InputError: ``tau`` of the wrong shape.
        DynamicsError: NaN torques.
    """
    arms = arm_set.evaluate(state.q, state.v)
    o = state.obj
    R = o.rotation
    ct = constraint_set.evaluate(arms.tools, BodyKinematics.single(o.position, R, o.twist))
    Gt = ct.G_tool
    W = np.einsum("niv,nki->nvk", arms.J, Gt)
    W_o = ct.G_object.transpose(0, 2, 1).copy()
    c = -np.einsum("nki,ni->nk", Gt, arms.Jdot_qdot) - ct.kappa
    if baumgarte is not None:
        a, b = baumgarte_gains(baumgarte)
        c -= 2.0 * a * ct.phi_dot + b * b * ct.phi
    h = -arms.nle
    if tau is not None:
        t = np.asarray(tau, dtype=float)
        if t.shape != (arm_set.nv,):
            raise InputError(f"tau: expected shape ({arm_set.nv},), got {t.shape}")
        if not np.all(np.isfinite(t)):
            raise DynamicsError(f"tau contains NaN or infinity: {t.tolist()}")
        h = h + arm_set.pad_v(t)
    blocks = SystemBlocks(arms.M, h, W, W_o, c, obj.mass_matrix(R),
                          obj.bias_wrench(R, o.twist, gravity), arm_set.nv_arm.copy(),
                          constraint_set.N.copy())
    return Evaluation(blocks, arms, ct)


def baumgarte_gains(value) -> tuple[float, float]:
    """``(α, β)`` [1/s] of a Baumgarte stabilisation, checked.

    Raises:
        InputError: not two finite numbers >= 0.
    """
    try:
        a, b = (float(x) for x in value)
    except (TypeError, ValueError) as exc:
        raise InputError(f"baumgarte: expected (alpha, beta) [1/s], got {value!r}") from exc
    # math.isfinite: the same test on Python floats, without numpy's per-call overhead
    if not (math.isfinite(a) and math.isfinite(b) and a >= 0 and b >= 0):
        raise InputError(f"baumgarte: expected finite (alpha, beta) >= 0 [1/s], got {value!r}")
    return a, b


__all__ = ["BufferArmTerms", "BufferBlocks", "BufferConstraintTerms", "BufferEvaluation",
           "BufferLayout", "CompiledSystem", "Evaluation",
           "baumgarte_gains", "reference_evaluation"]
