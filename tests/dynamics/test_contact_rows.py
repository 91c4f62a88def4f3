"""The stacked blocks of every contact row against a by-hand assembly from their definition."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.dynamics.blocks import SystemBlocks

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def _by_hand(system, state, baumgarte):
    """Reference: the module docstring's layout, assembled with np.cross and plain loops."""
    n, K = system.n_arms, system.supports.n_rows
    B, R = system.n_blocks, system.rows_max
    o = state.obj
    if n:
        ev = system.blocks(state, None, baumgarte)
        b, ct = ev.blocks, ev.constraints
        k, m = b.nv_max, b.N_max
        M_o, h_o = b.M_o, b.h_o
    else:
        k, m = 1, 0
        M_o = system.obj.mass_matrix(o.rotation)
        h_o = system.obj.bias_wrench(o.rotation, o.twist, system.gravity)
    M = np.zeros((B, k, k))
    h, W, W_o = np.zeros((B, k)), np.zeros((B, k, R)), np.zeros((B, 6, R))
    c, phi = np.zeros((B, R)), np.zeros((B, R))
    for i in range(n):
        M[i], h[i] = b.M[i], b.h[i]
        W[i, :, :m], W_o[i, :, :m], c[i, :m] = b.W[i], b.W_o[i], b.c[i]
        phi[i, :m] = ct.phi[i]
    M[n] = np.eye(k)
    alpha, beta = baumgarte
    sup = system.supports
    for j in range(K):
        spt = sup.supports[int(sup.support_index[j])]
        nrm = spt.normal
        r = o.rotation @ spt.points[int(sup.point_index[j])]
        w = o.twist[3:]
        g = np.concatenate([nrm, np.cross(r, nrm)])
        gap = nrm @ (o.position + r - spt.point)
        rate = g @ o.twist
        W_o[n, :, j] = g
        c[n, j] = -nrm @ np.cross(w, np.cross(w, r)) - 2 * alpha * rate - beta ** 2 * gap
        phi[n, j] = gap
    return M, h, W, W_o, c, M_o, h_o, phi


@pytest.mark.parametrize("name", ["pick_from_table", "box_on_table"])
def test_contact_blocks_equal_the_by_hand_assembly(name, rng):
    """Arms' blocks padded, then one zero-dof block of the support rows (1e-12).

    On a moving state (random twist), with Baumgarte terms; the result also passes the
    checked constructor (shapes, padding, ``M_o``) with the same derived masks.
    """
    built = build_scenario(load_scenario(SCENARIOS / f"{name}.yaml"), load_visuals=False)
    system, s0 = built.system, built.initial_state
    state = type(s0)(s0.q, s0.v, type(s0.obj)(s0.obj.position, s0.obj.quaternion,
                                              rng.normal(size=6)))
    baumgarte = (3.0, 7.0)
    if system.n_arms:
        ev = system.blocks(state, None, baumgarte)
        full, rows = system.contact_blocks(state, ev.blocks, ev.constraints, baumgarte)
    else:
        full, rows = system.contact_blocks(state, None, None, baumgarte)
    ref = _by_hand(system, state, baumgarte)
    for name_, got, want in zip(("M", "h", "W", "W_o", "c", "M_o", "h_o", "phi"),
                                (full.M, full.h, full.W, full.W_o, full.c, full.M_o,
                                 full.h_o, rows.phi), ref, strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12, err_msg=name_)
    checked = SystemBlocks(full.M, full.h, full.W, full.W_o, full.c, full.M_o, full.h_o,
                           full.nv, full.N)
    checked.check_padding()
    for name_ in ("nv", "N", "dof_mask", "constraint_mask", "padding_diagonal"):
        np.testing.assert_array_equal(getattr(full, name_), getattr(checked, name_))
        assert getattr(full, name_).dtype == getattr(checked, name_).dtype
    assert full.has_constraint_padding == checked.has_constraint_padding
    # each call owns its arrays
    again = system.contact_blocks(state, None, None, baumgarte) if not system.n_arms else \
        system.contact_blocks(state, ev.blocks, ev.constraints, baumgarte)
    assert not np.shares_memory(again[0].constraint_mask, full.constraint_mask)
    assert not np.shares_memory(again[0].M, full.M)
