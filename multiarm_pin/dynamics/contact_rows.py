"""Every contact row of a system at once: the arms' rows, then one zero-dof support block.

The unilateral forward dynamics (:func:`~multiarm_pin.dynamics.unilateral.solve_unilateral`)
works on all rows together: the arms' blocks (:class:`~multiarm_pin.dynamics.SystemBlocks`)
followed, when the system has supports, by one block with no joints (``nv = 0``: identity
padding of ``M``, ``W = 0``) holding the K support rows, ``W_o = G_objectᵀ`` (``[n; r × n]``)
and ``c = -κ`` (with Baumgarte, ``- 2α φ̇ - β² φ``). :class:`ContactRowTable` is the constant
layout of those rows for one system (built once); :func:`stack_contact_blocks` stacks the
blocks of one state. ``MultiArmSystem.contact_blocks`` is the public entry.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import accumulate

import numpy as np

from multiarm_pin.constraints import ConstraintTerms
from multiarm_pin.constraints.supports import SupportSet, SupportTerms
from multiarm_pin.dynamics.blocks import SystemBlocks, check_object_inertia
from multiarm_pin.dynamics.evaluation import baumgarte_gains


@dataclass(frozen=True)
class ContactRows:
    """Every contact row of the system at one state: the arms' rows, then the supports'.

    Shapes ``(B, R)`` with ``B = n_blocks`` (the n arms, plus one zero-dof block holding every
    support row when the system has supports) and ``R = rows_max``; padding is zero.

    Attributes:
        phi: (B, R) gaps [m]; phi_dot: (B, R) gap rates [m/s].
        contact_points: (B, R, 3) world contact points [m].
        normals: (B, R, 3) world directions in which each row pushes the object.
    """

    phi: np.ndarray
    phi_dot: np.ndarray
    contact_points: np.ndarray
    normals: np.ndarray


@dataclass(frozen=True)
class ContactRowTable:
    """The constant layout of every contact row of one system (arms' rows, then supports').

    Attributes:
        n_arms: n; N_max: padded rows per arm.
        n_blocks: n, plus 1 when there are supports.
        rows_max: padded rows per block (``max(N_max, K)``).
        mask, unilateral: (n_blocks, rows_max) bool, real rows and unilateral rows (read-only).
        restitution: (n_blocks, rows_max) Newton's coefficient of each row (read-only).
        labels: one ``(block, row, label)`` per real row: ``"<arm>:<contact>"`` or
            ``"<support>[j]"``.
        nv_blocks, N_blocks: (n_blocks,) joints and rows per block.
        nv_max_blocks: padded joints per block without arms (at least 1).
    """

    n_arms: int
    N_max: int
    n_blocks: int
    rows_max: int
    mask: np.ndarray
    unilateral: np.ndarray
    restitution: np.ndarray
    labels: list
    nv_blocks: np.ndarray
    N_blocks: np.ndarray
    nv_max_blocks: int
    _masks: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def block_masks(self, k: int) -> tuple:
        """The derived masks of the stacked blocks padded to ``k`` joints (new arrays).

        ``(dof_mask, constraint_mask, has_constraint_padding, padding_diagonal)`` as
        :class:`SystemBlocks` derives them from ``nv_blocks``, ``N_blocks``: computed once
        per ``k``, copied for each call (each blocks object owns its arrays).
        """
        m = self._masks.get(k)
        if m is None:
            probe = SystemBlocks.assembled(np.eye(k)[None].repeat(self.n_blocks, 0), None,
                                           np.zeros((self.n_blocks, k, self.rows_max)), None,
                                           None, None, None, self.nv_blocks, self.N_blocks)
            m = self._masks[k] = (probe.dof_mask, probe.constraint_mask,
                                  probe.has_constraint_padding, probe.padding_diagonal)
        return m[0].copy(), m[1].copy(), m[2], m[3].copy()

    @classmethod
    def build(cls, nv_arm: np.ndarray, N: np.ndarray, unilateral: np.ndarray,
              contact_names: Sequence[Sequence[str]], supports: SupportSet) -> ContactRowTable:
        """The table of n arms and the supports.

        Args:
            nv_arm: (n,) joints per arm.
            N: (n,) rows per arm.
            unilateral: (n, N_max) True on the arms' unilateral rows.
            contact_names: per arm, ``"<arm>:<contact>"`` of each of its rows.
            supports: the system's supports (K rows).
        """
        n, K = len(N), supports.n_rows
        N_max = int(N.max()) if n else 0
        B, R = n + (1 if K else 0), max(N_max, K)
        mask = np.zeros((B, R), dtype=bool)
        uni = np.zeros((B, R), dtype=bool)
        rest = np.zeros((B, R))
        labels = []
        for i in range(n):
            Ni = int(N[i])
            mask[i, :Ni] = True
            uni[i, :Ni] = unilateral[i, :Ni]
            labels += [(i, k, contact_names[i][k]) for k in range(Ni)]
        if K:
            mask[n, :K] = True
            uni[n, :K] = True
            rest[n, :K] = supports.restitution
            labels += [(n, k, lab) for k, lab in enumerate(supports.labels)]
        for a in (mask, uni, rest):
            a.setflags(write=False)
        return cls(n, N_max, B, R, mask, uni, rest, labels,
                   np.concatenate([nv_arm, [0] * (B - n)]).astype(int),
                   np.concatenate([N, [K] * (B - n)]).astype(int),
                   max(int(nv_arm.max()) if n else 0, 1))


def stack_contact_blocks(table: ContactRowTable, M_o: np.ndarray, h_o: np.ndarray,
                         support: SupportTerms, blocks: SystemBlocks | None,
                         constraints: ConstraintTerms | None,
                         baumgarte: tuple[float, float] | None
                         ) -> tuple[SystemBlocks, ContactRows]:
    """The blocks of every contact row at one state (see the module docstring).

    Args:
        table: the system's :class:`ContactRowTable`.
        M_o: (6, 6) object inertia at the COM, world axes.
        h_o: (6,) object force terms [N, N m] (external wrench included).
        support: the support rows at this state (the system has supports).
        blocks: the arms' blocks (with torques), or None without arms.
        constraints: the arms' constraint rows of the same evaluation, or None.
        baumgarte: ``(α, β)`` [1/s] of the support rows (the arms' are in ``blocks``).

    Returns:
        ``(blocks, rows)``: :class:`SystemBlocks` with ``n_blocks`` blocks padded to
        ``rows_max`` rows, and their :class:`ContactRows`.
    """
    n, B, R, m = table.n_arms, table.n_blocks, table.rows_max, table.N_max
    K = len(support.phi)
    c_s = -support.kappa
    if baumgarte is not None:
        a, b = baumgarte_gains(baumgarte)
        c_s = c_s - 2.0 * a * support.phi_dot - b * b * support.phi
    k = blocks.nv_max if n else table.nv_max_blocks
    # every array a view of one zeroed buffer (C-contiguous), as separate np.zeros were
    sizes = (B * k * k, B * k, B * k * R, B * 6 * R, B * R, B * R, B * R, B * R * 3,
             B * R * 3)
    ends = list(accumulate(sizes))
    buf = np.zeros(ends[-1])
    M = buf[:ends[0]].reshape(B, k, k)
    h = buf[ends[0]:ends[1]].reshape(B, k)
    W = buf[ends[1]:ends[2]].reshape(B, k, R)
    W_o = buf[ends[2]:ends[3]].reshape(B, 6, R)
    c = buf[ends[3]:ends[4]].reshape(B, R)
    phi = buf[ends[4]:ends[5]].reshape(B, R)
    phi_dot = buf[ends[5]:ends[6]].reshape(B, R)
    pts = buf[ends[6]:ends[7]].reshape(B, R, 3)
    nrm = buf[ends[7]:].reshape(B, R, 3)
    buf[n * k * k:(n + 1) * k * k:k + 1] = 1.0  # M[n] = I (the support block has no joints)
    if n:
        M[:n] = blocks.M
        h[:n] = blocks.h
        W[:n, :, :m] = blocks.W
        W_o[:n, :, :m] = blocks.W_o
        c[:n, :m] = blocks.c
        phi[:n, :m] = constraints.phi
        phi_dot[:n, :m] = constraints.phi_dot
        pts[:n, :m] = constraints.contact_points
        nrm[:n, :m] = constraints.normals
    W_o[n, :, :K] = support.G_object.T
    c[n, :K] = c_s
    phi[n, :K] = support.phi
    phi_dot[n, :K] = support.phi_dot
    pts[n, :K] = support.contact_points
    nrm[n, :K] = support.normals
    M_o = np.array(M_o, dtype=float)
    if blocks is None:  # new at this state (with arms it is the arms' blocks', checked)
        check_object_inertia(M_o)
    # the arms' validated blocks, the table's constant layout and the support rows: the
    # shapes hold by construction and are not checked again (this runs at every evaluation)
    full = SystemBlocks.assembled(M, h, W, W_o, c, M_o, np.array(h_o, dtype=float),
                                  table.nv_blocks.copy(), table.N_blocks.copy(),
                                  table.block_masks(k))
    return full, ContactRows(phi, phi_dot, pts, nrm)


__all__ = ["ContactRowTable", "ContactRows", "stack_contact_blocks"]
