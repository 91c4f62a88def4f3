"""Coefficient blocks of the equations of motion of n arms holding one object, padded to stack.

The equations (``docs/ARCHITECTURE.md``, our form of thesis Eq 4.9) are, for arms
``i = 0..n-1``::

    M_o a_o   = h_o + Σ_i W_o,i μ_i          (6 object equations, LWA at the COM)
    M_i q̈_i   = h_i + W_i μ_i                (nv_i joint equations of arm i)
    W_o,iᵀ a_o + W_iᵀ q̈_i = c_i              (N_i constraint rows of arm i)

``μ_i`` are the contact multipliers, positive = pushing. Arms of different sizes are stacked
by padding every arm to ``nv_max`` joints and ``N_max`` constraints: the padded part of
``M_i`` is the identity and everything else is zero on padding, so that padded joints and
multipliers solve to zero.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import lapack

from multiarm_pin.exceptions import InputError


@dataclass(frozen=True)
class SystemBlocks:
    """Per-state coefficient blocks of the constrained equations of motion, padded and stacked.

    Attributes:
        M: (n, nv_max, nv_max) joint-space mass matrices [kg m², kg, ...]; identity on padded
            dofs.
        h: (n, nv_max) ``τ - nle`` [N m or N]; zero on padding.
        W: (n, nv_max, N_max) ``J_iᵀ G_tool,iᵀ``: joint torques per unit multiplier; zero on
            padding.
        W_o: (n, 6, N_max) ``G_object,iᵀ``: wrench ``[f; m]`` on the object about its COM in
            world axes per unit multiplier; zero on padding.
        c: (n, N_max) acceleration-level right-hand side of the constraints; zero on padding.
        M_o: (6, 6) object spatial inertia at the COM in world axes (``[[m I, 0], [0, I_c]]``).
        h_o: (6,) object force terms at the COM in world axes (gravity, ``-ω × Iω``,
            external wrench) [N, N m].
        nv: (n,) int, number of joints of each arm (``0 <= nv_i <= nv_max``).
        N: (n,) int, number of constraint rows of each arm (``0 <= N_i <= N_max``).

    Construct with :meth:`from_lists` (pads and validates fully) or directly from padded
    arrays (shapes, padding sizes and the positive definiteness of ``M_o`` are checked;
    finiteness is checked by :meth:`check_finite`, which the solvers call whenever a result
    is not finite; :meth:`check_padding` checks the padded entries).
    """

    M: np.ndarray
    h: np.ndarray
    W: np.ndarray
    W_o: np.ndarray
    c: np.ndarray
    M_o: np.ndarray
    h_o: np.ndarray
    nv: np.ndarray
    N: np.ndarray
    dof_mask: np.ndarray = field(init=False, repr=False, compare=False)
    constraint_mask: np.ndarray = field(init=False, repr=False, compare=False)
    has_constraint_padding: bool = field(init=False, repr=False, compare=False)
    padding_diagonal: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        self._check_shapes()
        self._derive()
        check_object_inertia(self.M_o)

    def _derive(self) -> None:
        """Set ``nv``, ``N`` as int arrays and the fields derived from them (the masks)."""
        nv = np.asarray(self.nv, dtype=int)
        N = np.asarray(self.N, dtype=int)
        object.__setattr__(self, "nv", nv)
        object.__setattr__(self, "N", N)
        object.__setattr__(self, "dof_mask", np.arange(self.nv_max)[None, :] < nv[:, None])
        object.__setattr__(self, "constraint_mask", np.arange(self.N_max)[None, :] < N[:, None])
        object.__setattr__(self, "has_constraint_padding", bool(np.any(N < self.N_max)))
        object.__setattr__(self, "padding_diagonal", (~self.constraint_mask).astype(float))

    @classmethod
    def assembled(cls, M: np.ndarray, h: np.ndarray, W: np.ndarray, W_o: np.ndarray,
                  c: np.ndarray, M_o: np.ndarray, h_o: np.ndarray, nv: np.ndarray,
                  N: np.ndarray, masks: tuple | None = None) -> SystemBlocks:
        """Blocks assembled inside the package from parts that are already valid.

        For the hot paths that build blocks from validated ones (:func:`restrict_rows`,
        :func:`~multiarm_pin.dynamics.contact_rows.stack_contact_blocks`): float64 arrays of
        consistent shapes, padding as documented, ``M_o`` positive definite (the caller
        checks it when it is new, :func:`check_object_inertia`). None of that is checked
        again here (the shape checks cost more than the rest of such a call). Anything from
        outside goes through the constructor or :meth:`from_lists`, which check it.

        Args:
            M: (n, nv_max, nv_max) mass matrices, identity on padding.
            h: (n, nv_max) ``τ - nle``.
            W: (n, nv_max, N_max) ``J_iᵀ G_tool,iᵀ``.
            W_o: (n, 6, N_max) ``G_object,iᵀ``.
            c: (n, N_max) constraint right-hand sides.
            M_o: (6, 6) object inertia (positive definite).
            h_o: (6,) object force terms.
            nv: (n,) int joints per arm.
            N: (n,) int rows per arm.
            masks: ``(dof_mask, constraint_mask, has_constraint_padding,
                padding_diagonal)`` of these ``nv``, ``N`` (arrays owned by the new
                blocks), or None to derive them as the constructor does.
        """
        out = object.__new__(cls)
        d = out.__dict__  # the frozen dataclass's fields, set once here
        d.update(M=M, h=h, W=W, W_o=W_o, c=c, M_o=M_o, h_o=h_o, nv=nv, N=N)
        if masks is None:
            out._derive()
        else:
            d.update(dof_mask=masks[0], constraint_mask=masks[1],
                     has_constraint_padding=masks[2], padding_diagonal=masks[3])
        return out

    # ------------------------------------------------------------------ sizes
    @property
    def n(self) -> int:
        """Number of arms."""
        return self.M.shape[0]

    @property
    def nv_max(self) -> int:
        """Padded number of joints per arm."""
        return self.M.shape[1]

    @property
    def N_max(self) -> int:
        """Padded number of constraint rows per arm."""
        return self.W.shape[2]

    @property
    def n_constraints(self) -> int:
        """Total number of (unpadded) constraint rows ``Σ N_i``."""
        return int(self.N.sum())

    # ------------------------------------------------------------ validation
    def _check_shapes(self) -> None:
        arrays = {
            name: getattr(self, name) for name in ("M", "h", "W", "W_o", "c", "M_o", "h_o")
        }
        for name, value in arrays.items():
            if not isinstance(value, np.ndarray) or value.dtype != np.float64:
                raise InputError(
                    f"SystemBlocks.{name}: expected a float64 numpy array, got "
                    f"{type(value).__name__} {getattr(value, 'dtype', '')}; "
                    "use SystemBlocks.from_lists to convert"
                )
        M, W = self.M, self.W
        if M.ndim != 3 or M.shape[1] != M.shape[2]:
            raise InputError(f"SystemBlocks.M: expected shape (n, nv_max, nv_max), got {M.shape}")
        n, k = M.shape[0], M.shape[1]
        if n < 1:
            raise InputError("SystemBlocks: expected at least one arm, got n = 0")
        if W.ndim != 3 or W.shape[:2] != (n, k):
            raise InputError(f"SystemBlocks.W: expected shape ({n}, {k}, N_max), got {W.shape}")
        m = W.shape[2]
        expected = {
            "h": (n, k),
            "W_o": (n, 6, m),
            "c": (n, m),
            "M_o": (6, 6),
            "h_o": (6,),
        }
        for name, shape in expected.items():
            if arrays[name].shape != shape:
                raise InputError(
                    f"SystemBlocks.{name}: expected shape {shape} (n={n}, nv_max={k}, "
                    f"N_max={m}), got {arrays[name].shape}"
                )
        for name, bound in (("nv", k), ("N", m)):
            v = np.asarray(getattr(self, name))
            if v.shape != (n,) or not np.issubdtype(v.dtype, np.integer):
                raise InputError(
                    f"SystemBlocks.{name}: expected {n} integers, got {v!r} (dtype {v.dtype})"
                )
            if np.any(v < 0) or np.any(v > bound):
                raise InputError(
                    f"SystemBlocks.{name}: expected values in [0, {bound}], got {v.tolist()}"
                )

    def check_finite(self) -> None:
        """Raise :class:`InputError` naming the first block (and arm) holding NaN or infinity."""
        for name in ("M_o", "h_o"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise InputError(f"SystemBlocks.{name} contains NaN or infinity")
        for name in ("M", "h", "W", "W_o", "c"):
            value = getattr(self, name)
            bad = ~np.isfinite(value.reshape(self.n, -1)).all(axis=1)
            if bad.any():
                raise InputError(
                    f"SystemBlocks.{name} contains NaN or infinity for arm(s) "
                    f"{np.flatnonzero(bad).tolist()}"
                )

    def check_padding(self) -> None:
        """Raise :class:`InputError` if the padded entries are not identity / zero."""
        dm, cm = self.dof_mask, self.constraint_mask
        pad_M = ~(dm[:, :, None] & dm[:, None, :])
        eye = np.broadcast_to(np.eye(self.nv_max), self.M.shape)
        problems = []
        if not np.array_equal(self.M[pad_M], eye[pad_M]):
            problems.append("M (identity on padded dofs, zero coupling)")
        if np.any(self.h[~dm]):
            problems.append("h")
        if np.any(self.W[~(dm[:, :, None] & cm[:, None, :])]):
            problems.append("W")
        if np.any(self.W_o.transpose(0, 2, 1)[~cm]):
            problems.append("W_o")
        if np.any(self.c[~cm]):
            problems.append("c")
        if problems:
            raise InputError(
                "SystemBlocks: wrong padding in " + ", ".join(problems)
                + "; padded dofs must have identity mass and zero elsewhere"
            )

    # ----------------------------------------------------------- construction
    @classmethod
    def from_lists(
        cls,
        M_list: Sequence,
        h_list: Sequence,
        W_list: Sequence,
        W_o_list: Sequence,
        c_list: Sequence,
        M_o,
        h_o,
    ) -> SystemBlocks:
        """Pad per-arm blocks of different sizes and stack them.

        Args:
            M_list: n mass matrices, arm i (nv_i, nv_i).
            h_list: n vectors (nv_i,) ``τ_i - nle_i``.
            W_list: n matrices (nv_i, N_i) ``J_iᵀ G_tool,iᵀ``.
            W_o_list: n matrices (6, N_i) ``G_object,iᵀ`` (LWA at the object COM).
            c_list: n vectors (N_i,).
            M_o: (6, 6) object inertia at the COM, world axes.
            h_o: (6,) object force terms at the COM, world axes.

        Returns:
            The padded blocks (``nv_max = max(1, max nv_i)``, ``N_max = max(1, max N_i)``).

        Raises:
            InputError: lists of different lengths, inconsistent sizes, NaN or infinity.
        """
        lists = {"M_list": M_list, "h_list": h_list, "W_list": W_list,
                 "W_o_list": W_o_list, "c_list": c_list}
        n = len(M_list)
        for name, lst in lists.items():
            if len(lst) != n:
                raise InputError(
                    f"SystemBlocks.from_lists: {name} has {len(lst)} entries, M_list has {n}"
                )
        if n == 0:
            raise InputError("SystemBlocks.from_lists: expected at least one arm, got none")
        Ms, hs, Ws, Wos, cs = [], [], [], [], []
        for i in range(n):
            Mi = _as_float(M_list[i], f"M_list[{i}]", ndim=2)
            k = Mi.shape[0]
            if Mi.shape != (k, k):
                raise InputError(f"M_list[{i}]: expected a square matrix, got shape {Mi.shape}")
            Wi = _as_float(W_list[i], f"W_list[{i}]", ndim=2)
            if Wi.shape[0] != k:
                raise InputError(
                    f"W_list[{i}]: expected shape ({k}, N_{i}) to match M_list[{i}], "
                    f"got {Wi.shape}"
                )
            m = Wi.shape[1]
            hi = _as_float(h_list[i], f"h_list[{i}]", shape=(k,))
            Woi = _as_float(W_o_list[i], f"W_o_list[{i}]", shape=(6, m))
            ci = _as_float(c_list[i], f"c_list[{i}]", shape=(m,))
            Ms.append(Mi)
            hs.append(hi)
            Ws.append(Wi)
            Wos.append(Woi)
            cs.append(ci)
        nv = np.array([x.shape[0] for x in Ms], dtype=int)
        N = np.array([x.shape[1] for x in Ws], dtype=int)
        k, m = max(1, int(nv.max())), max(1, int(N.max()))
        M = np.broadcast_to(np.eye(k), (n, k, k)).copy()
        h = np.zeros((n, k))
        W = np.zeros((n, k, m))
        W_o = np.zeros((n, 6, m))
        c = np.zeros((n, m))
        for i in range(n):
            a, b = nv[i], N[i]
            M[i, :a, :a] = Ms[i]
            h[i, :a] = hs[i]
            W[i, :a, :b] = Ws[i]
            W_o[i, :, :b] = Wos[i]
            c[i, :b] = cs[i]
        M_o = _as_float(M_o, "M_o", shape=(6, 6))
        h_o = _as_float(h_o, "h_o", shape=(6,))
        return cls(M, h, W, W_o, c, M_o, h_o, nv, N)

    # ------------------------------------------------------------ conversions
    def with_torques(self, tau) -> SystemBlocks:
        """The same blocks with joint torques added to ``h``.

        Args:
            tau: (n, nv_max) joint torques [N m or N], zero on padded dofs.

        Returns:
            New blocks with ``h + tau``.
        """
        t = _as_float(tau, "tau", shape=(self.n, self.nv_max))
        if np.any(t[~self.dof_mask]):
            raise InputError("tau: expected zeros on padded dofs (beyond nv_i for arm i)")
        return self.replaced(h=self.h + t)

    def replaced(self, *, h: np.ndarray | None = None,
                 h_o: np.ndarray | None = None) -> SystemBlocks:
        """The same blocks with another ``h`` and/or ``h_o`` (the other fields shared).

        ``self`` is already validated and only force terms change, so nothing is
        re-validated (shapes, Cholesky of ``M_o``): this runs on every simulation step.

        Args:
            h: (n, nv_max) new ``τ - nle`` [N m or N], zero on padding; None keeps it.
            h_o: (6,) new object force terms [N, N m]; None keeps it.

        Returns:
            New blocks of the same class (the compiled path's stay views of their buffer).
        """
        out = copy.copy(self)
        for name, value in (("h", h), ("h_o", h_o)):
            if value is not None:
                object.__setattr__(out, name, _replacement(value, getattr(self, name), name))
        return out

    def stacked_W_o(self) -> np.ndarray:
        """``W_o = [W_o,1 ... W_o,n]`` without padding, shape (6, Σ N_i), arm-major columns."""
        return self.W_o.transpose(0, 2, 1)[self.constraint_mask].T

    def flatten_mu(self, mu: np.ndarray) -> np.ndarray:
        """Padded multipliers (n, N_max) -> stacked (Σ N_i,), arm-major."""
        return np.asarray(mu)[self.constraint_mask]

    def unflatten_mu(self, mu_flat: np.ndarray) -> np.ndarray:
        """Stacked multipliers (Σ N_i,) -> padded (n, N_max) with zeros on padding."""
        out = np.zeros((self.n, self.N_max))
        out[self.constraint_mask] = mu_flat
        return out


def restrict_rows(blocks: SystemBlocks, active) -> tuple[SystemBlocks, np.ndarray]:
    """The blocks of the ``active`` constraint rows only (each arm's kept rows first).

    Args:
        blocks: the system blocks.
        active: (n, N_max) bool, True for the rows to keep (padding ignored).

    Returns:
        ``(restricted, index)``: ``restricted`` has the same ``n``, ``nv``, ``N_max``,
        ``M``, ``h``, ``M_o``, ``h_o``, with ``N_i`` the number of kept rows of arm i and
        their ``W``, ``W_o``, ``c`` columns moved to the front (zero padding after);
        ``index`` (n, N_max) int maps a restricted row to its row in ``blocks`` (-1 on
        padding). Multipliers ``μ'`` of the restricted blocks are those of the full rows
        by :func:`expand_rows`.

    Raises:
        InputError: ``active`` of the wrong shape.
    """
    active = np.asarray(active, dtype=bool)
    if active.shape != (blocks.n, blocks.N_max):
        raise InputError(f"active: expected a bool array of shape ({blocks.n}, "
                         f"{blocks.N_max}), got shape {active.shape}")
    keep = active & blocks.constraint_mask
    n, k, m = blocks.W.shape
    N, kept, index, at_W, at_W_o, at_c, has_padding, padding = _row_selection(keep, k)
    W = np.where(kept[:, None, :], blocks.W[at_W], 0.0)
    W_o = np.where(kept[:, None, :], blocks.W_o[at_W_o], 0.0)
    c = np.where(kept, blocks.c[at_c], 0.0)
    # parts of validated blocks: no new checks (this runs at every evaluation of a
    # controller while a contact is separated)
    masks = (blocks.dof_mask.copy(), kept.copy(), has_padding, padding.copy())
    out = SystemBlocks.assembled(np.array(blocks.M), np.array(blocks.h), W, W_o, c,
                                 np.array(blocks.M_o), np.array(blocks.h_o),
                                 np.array(blocks.nv), N.astype(blocks.N.dtype), masks)
    index = index.copy()
    return out, index


def check_object_inertia(M_o: np.ndarray) -> None:
    """Raise :class:`InputError` unless ``M_o`` (6, 6) is symmetric positive definite (and finite).

    Args:
        M_o: (6, 6) float64 object spatial inertia at the COM, world axes.
    """
    if lapack.dpotrf(M_o)[1] != 0:
        if not np.isfinite(M_o).all():
            raise InputError("SystemBlocks.M_o contains NaN or infinity")
        raise InputError(
            "SystemBlocks.M_o: the object spatial inertia must be symmetric positive "
            f"definite, got eigenvalues {np.linalg.eigvalsh(M_o).round(12).tolist()}"
        )


_SELECTIONS: dict = {}
"""Index arrays of :func:`restrict_rows` by kept-row pattern (a few patterns recur in a run)."""

_SELECTIONS_KEPT = 64


def _row_selection(keep: np.ndarray, k: int) -> tuple:
    """The index arrays of :func:`restrict_rows` for the (n, m) kept rows ``keep``, memoised.

    Returns:
        ``(N, kept, index, at_W, at_W_o, at_c, has_padding, padding)`` (read-only arrays):
        ``N`` (n,) kept rows per arm; ``kept`` (n, m) the restricted real rows; ``index``
        (n, m) source row of each (-1 on padding); ``at_W``, ``at_W_o``, ``at_c`` fancy
        indices gathering each arm's kept rows first, in their order, from ``W`` (n, k, m),
        ``W_o`` (n, 6, m) and ``c`` (n, m); ``has_padding`` and ``padding`` (n, m) float,
        the derived fields of blocks with these rows.
    """
    key = (keep.shape, k, keep.tobytes())
    sel = _SELECTIONS.get(key)
    if sel is not None:
        return sel
    n, m = keep.shape
    N = keep.sum(axis=1)
    kept = np.arange(m) < N[:, None]
    order = np.argsort(~keep, axis=1, kind="stable")  # kept rows first, stable
    index = np.where(kept, order, -1)
    arm, col = np.arange(n)[:, None, None], order[:, None, :]
    sel = (N, kept, index, (arm, np.arange(k)[:, None], col), (arm, np.arange(6)[:, None], col),
           (arm[:, :, 0], order), bool(N.min() < m) if n else False, (~kept).astype(float))
    for x in (N, kept, index, order, arm, sel[-1]):
        x.setflags(write=False)
    if len(_SELECTIONS) >= _SELECTIONS_KEPT:
        _SELECTIONS.clear()  # one atomic call (runs in threads may share this module)
    _SELECTIONS[key] = sel
    return sel


def expand_rows(values, index: np.ndarray) -> np.ndarray:
    """(n, N_max) values of restricted rows put back at their rows (zero elsewhere).

    Args:
        values: (n, N_max) per restricted row (e.g. multipliers [N]).
        index: the ``index`` of :func:`restrict_rows`.
    """
    values = np.asarray(values)
    out = np.zeros(index.shape, dtype=values.dtype)
    i, k = np.nonzero(index >= 0)
    out[i, index[i, k]] = values[i, k]
    return out


def select_rows(values, index: np.ndarray) -> np.ndarray:
    """(n, N_max) values of the full rows taken at the restricted rows (zero on padding).

    The inverse of :func:`expand_rows` (e.g. per-row flags or margins of the full blocks
    for the blocks of :func:`restrict_rows`).

    Args:
        values: (n, N_max) per row of the full blocks.
        index: the ``index`` of :func:`restrict_rows`.
    """
    values = np.asarray(values)
    out = np.zeros(index.shape, dtype=values.dtype)
    i, k = np.nonzero(index >= 0)
    out[i, k] = values[i, index[i, k]]
    return out


def _replacement(value, old: np.ndarray, name: str) -> np.ndarray:
    """``value`` as a float64 array of the shape of ``old`` (see :meth:`SystemBlocks.replaced`)."""
    arr = np.asarray(value, dtype=float)
    if arr.shape != old.shape:
        raise InputError(f"SystemBlocks.{name}: expected shape {old.shape}, got {arr.shape}")
    return arr


def _as_float(value, name: str, shape: tuple | None = None, ndim: int | None = None) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: expected an array of numbers, got {value!r}") from exc
    if ndim is not None and arr.ndim != ndim:
        raise InputError(f"{name}: expected a {ndim}-D array, got shape {arr.shape}")
    if shape is not None and arr.shape != tuple(shape):
        raise InputError(f"{name}: expected shape {tuple(shape)}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name}: contains NaN or infinity")
    return arr


@dataclass(frozen=True)
class Residuals:
    """Absolute residual norms (2-norms over all arms) of the three equation groups.

    Attributes:
        object: ``‖M_o a_o - h_o - Σ W_o,i μ_i‖`` [N, N m].
        arms: ``‖M_i q̈_i - h_i - W_i μ_i‖`` over all arms [N m or N].
        constraints: ``‖W_o,iᵀ a_o + W_iᵀ q̈_i - c_i‖`` over all arms.
        scale: size of the terms that should cancel (largest norm among ``M_o a_o``, ``h_o``,
            ``M q̈``, ``h``, ``W μ``, ``c``...), so that ``max residual / scale`` is a relative
            residual.
    """

    object: float
    arms: float
    constraints: float
    scale: float

    @property
    def relative(self) -> float:
        """Largest residual divided by :attr:`scale` (0 when everything is zero)."""
        worst = max(self.object, self.arms, self.constraints)
        return worst / self.scale if self.scale > 0 else worst


@dataclass(slots=True)
class Solution:
    """Result of a forward-dynamics solve.

    Attributes:
        a_o: (6,) object classical acceleration ``[ẍ; ω̇]`` at the COM, world axes
            [m/s², rad/s²].
        qdd: (n, nv_max) joint accelerations, zero on padded dofs.
        mu: (n, N_max) contact multipliers (positive = pushing), zero on padding.
        solver: name of the solver actually used (``"object_first"``, ``"dense_kkt"`` or
            ``"singular"``).
        singular_arms: indices of the arms handled by the singular-arm variant: those whose
            ``S_i = W_iᵀ M_i⁻¹ W_i`` was singular or badly conditioned, or all arms when the
            reduced object matrix was (empty when none, or for ``"dense_kkt"``).
        blocks: the blocks that were solved (not copied).
    """

    a_o: np.ndarray
    qdd: np.ndarray
    mu: np.ndarray
    solver: str
    singular_arms: tuple[int, ...]
    blocks: SystemBlocks = field(repr=False, compare=False)

    def qdd_of(self, i: int) -> np.ndarray:
        """Joint accelerations of arm ``i`` without padding, shape (nv_i,)."""
        return self.qdd[i, : self.blocks.nv[i]]

    def mu_of(self, i: int) -> np.ndarray:
        """Multipliers of arm ``i`` without padding, shape (N_i,)."""
        return self.mu[i, : self.blocks.N[i]]

    def residuals(self) -> Residuals:
        """Residuals of the equations of motion at this solution (computed on demand)."""
        b = self.blocks
        Wmu_o = np.einsum("nij,nj->i", b.W_o, self.mu)
        Mqdd = np.einsum("nij,nj->ni", b.M, self.qdd)
        Wmu = np.einsum("nij,nj->ni", b.W, self.mu)
        Mo_a = b.M_o @ self.a_o
        cons = np.einsum("nij,i->nj", b.W_o, self.a_o) + np.einsum("nij,ni->nj", b.W, self.qdd)
        terms = [Mo_a, b.h_o, Wmu_o, Mqdd, b.h, Wmu, b.c,
                 np.einsum("nij,i->nj", b.W_o, self.a_o)]
        return Residuals(
            object=float(np.linalg.norm(Mo_a - b.h_o - Wmu_o)),
            arms=float(np.linalg.norm(Mqdd - b.h - Wmu)),
            constraints=float(np.linalg.norm(cons - b.c)),
            scale=float(max(np.linalg.norm(t) for t in terms)),
        )
