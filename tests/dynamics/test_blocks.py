"""Restricting blocks to a subset of constraint rows and expanding multipliers back."""

from __future__ import annotations

import numpy as np
import pytest

from multiarm_pin.dynamics import solve
from multiarm_pin.dynamics.blocks import SystemBlocks, expand_rows, restrict_rows, select_rows
from multiarm_pin.exceptions import InputError

from .synthetic import random_system


def test_restrict_rows_equals_blocks_built_from_the_kept_rows():
    """Reference: ``SystemBlocks.from_lists`` of each arm's kept columns, built directly.

    The forward dynamics of both must agree to round-off, and ``expand_rows`` puts the
    multipliers back at the kept rows (zero on the dropped ones).
    """
    rng = np.random.default_rng(7)
    b, _, _ = random_system(rng, [6, 7, 5], [4, 3, 2])
    active = np.zeros((b.n, b.N_max), dtype=bool)
    active[0, [0, 2, 3]] = True
    active[1, [1, 2]] = True
    active[2, :] = True  # padding ignored
    sub, index = restrict_rows(b, active)
    assert sub.N.tolist() == [3, 2, 2]
    assert index.tolist() == [[0, 2, 3, -1], [1, 2, -1, -1], [0, 1, -1, -1]]
    lists = []
    for i, rows in enumerate([[0, 2, 3], [1, 2], [0, 1]]):
        nv = int(b.nv[i])
        lists.append((b.M[i, :nv, :nv], b.h[i, :nv], b.W[i, :nv][:, rows],
                      b.W_o[i][:, rows], b.c[i, rows]))
    ref = SystemBlocks.from_lists([x[0] for x in lists], [x[1] for x in lists],
                                  [x[2] for x in lists], [x[3] for x in lists],
                                  [x[4] for x in lists], b.M_o, b.h_o)
    s1, s2 = solve(sub, "dense_kkt"), solve(ref, "dense_kkt")
    np.testing.assert_allclose(s1.a_o, s2.a_o, rtol=1e-10, atol=1e-10)
    mu = expand_rows(s1.mu, index)
    assert mu[0, 1] == 0.0 and mu[1, 0] == 0.0
    # select_rows takes full rows' values at the kept rows: the inverse of expand_rows
    np.testing.assert_array_equal(select_rows(mu, index), np.where(index >= 0, s1.mu, 0.0))
    full = np.arange(12.0).reshape(3, 4)
    assert select_rows(full, index).tolist() == [[0, 2, 3, 0], [5, 6, 0, 0], [8, 9, 0, 0]]
    np.testing.assert_allclose(mu[0, [0, 2, 3]], s2.mu[0, :3], rtol=1e-9, atol=1e-9)
    # the kept columns themselves, in order; the rest is valid padding (checked constructor)
    for i, rows in enumerate([[0, 2, 3], [1, 2], [0, 1]]):
        k = len(rows)
        np.testing.assert_array_equal(sub.W[i, :, :k], b.W[i][:, rows])
        np.testing.assert_array_equal(sub.W_o[i, :, :k], b.W_o[i][:, rows])
        np.testing.assert_array_equal(sub.c[i, :k], b.c[i, rows])
    checked = SystemBlocks(sub.M, sub.h, sub.W, sub.W_o, sub.c, sub.M_o, sub.h_o, sub.nv, sub.N)
    checked.check_padding()
    _assert_same_blocks(sub, checked)
    with pytest.raises(InputError, match="active: expected a bool array of shape"):
        restrict_rows(b, np.ones((2, 2), dtype=bool))


def _assert_same_blocks(a: SystemBlocks, b: SystemBlocks) -> None:
    """Every field, derived ones included, equal (values, dtypes and shapes)."""
    for name in ("M", "h", "W", "W_o", "c", "M_o", "h_o", "nv", "N", "dof_mask",
                 "constraint_mask", "padding_diagonal"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype, name
        np.testing.assert_array_equal(x, y, err_msg=name)
    assert a.has_constraint_padding == b.has_constraint_padding


def test_assembled_blocks_equal_the_checked_constructor():
    """``SystemBlocks.assembled`` (no checks) sets the same fields as the constructor."""
    rng = np.random.default_rng(3)
    b, _, _ = random_system(rng, [6, 7, 5], [4, 3, 2])
    fields = (b.M, b.h, b.W, b.W_o, b.c, b.M_o, b.h_o, b.nv, b.N)
    a = SystemBlocks.assembled(*fields)
    assert type(a) is SystemBlocks
    _assert_same_blocks(a, SystemBlocks(*fields))


def test_checked_constructor_still_rejects_bad_blocks():
    """The public constructor keeps its checks (only internal assembly skips them)."""
    rng = np.random.default_rng(4)
    b, _, _ = random_system(rng, [6, 5], [3, 2])
    with pytest.raises(InputError, match=r"SystemBlocks.W_o: expected shape \(2, 6, 3\)"):
        SystemBlocks(b.M, b.h, b.W, b.W_o[:, :5], b.c, b.M_o, b.h_o, b.nv, b.N)
    with pytest.raises(InputError, match="symmetric positive definite"):
        SystemBlocks(b.M, b.h, b.W, b.W_o, b.c, -b.M_o, b.h_o, b.nv, b.N)


def test_restrict_rows_repeated_patterns_give_owned_equal_results():
    """The memoised row selection: same pattern twice, other patterns between, equal results.

    Reference: the first call's arrays (copied); every returned array is the caller's own
    (writing into one changes no later result).
    """
    rng = np.random.default_rng(11)
    b, _, _ = random_system(rng, [6, 7], [4, 3])
    patterns = [rng.random((2, 4)) < 0.6 for _ in range(6)]
    first = []
    for active in patterns:
        sub, index = restrict_rows(b, active)
        first.append((index.copy(), sub.N.copy(), sub.W.copy(), sub.constraint_mask.copy(),
                      sub.padding_diagonal.copy()))
        index[:] = 7  # the caller's own arrays
        sub.N[:] = 0
        sub.constraint_mask[:] = True
        sub.padding_diagonal[:] = 3.0
    for active, ref in zip(patterns, first, strict=True):
        sub, index = restrict_rows(b, active)
        for got, want in zip((index, sub.N, sub.W, sub.constraint_mask, sub.padding_diagonal),
                             ref, strict=True):
            np.testing.assert_array_equal(got, want)
        keep = active & b.constraint_mask
        np.testing.assert_array_equal(sub.N, keep.sum(axis=1))
        for i in range(b.n):
            rows = np.flatnonzero(keep[i])
            np.testing.assert_array_equal(index[i, :len(rows)], rows)
            np.testing.assert_array_equal(sub.W[i, :, :len(rows)], b.W[i][:, rows])
            assert not sub.W[i, :, len(rows):].any()
