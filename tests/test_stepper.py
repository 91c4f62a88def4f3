"""The stepper's reuse of evaluated rows (the gaps of a known state, and of a new one), and the
initial gaps by the numpy reference."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from multiarm_pin.app.runner import scenario_controller
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.sim.simulation import simulate
from multiarm_pin.sim.stepper import ROWS_KEPT, Stepper
from multiarm_pin.system import SystemState

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


def _fresh_gaps(system, state: SystemState) -> np.ndarray:
    """Reference: the (B, R) gaps from the system's own evaluations, nothing reused."""
    out = np.zeros((system.n_blocks, system.rows_max))
    out[:system.n_arms, :system.N_max] = system.blocks(state).constraints.phi
    out[system.n_arms, :system.supports.n_rows] = system.support_terms(state).phi
    return out


def test_gaps_reuse_the_rows_of_evaluated_states_only():
    """pick_from_table (arms' fingertips and table rows): gaps equal fresh ones bit for bit.

    At an evaluated state (reused rows), at states the stepper only stepped to (computed),
    and at the first state again after more than ``ROWS_KEPT`` others (forgotten, computed
    again). A different state object at the same values is not mistaken for another one.
    """
    built = build_scenario(load_scenario(SCENARIOS / "pick_from_table.yaml"),
                           load_visuals=False)
    system, state = built.system, built.initial_state
    sim = built.scenario.simulation
    st = Stepper(system, scenario_controller(built), "auto", sim.baumgarte)
    st.init_active(st.blocks_at(0.0, state)[1], 1e-6)
    sol, _, _, rows = st.evaluate(0.0, state)
    assert st._known_rows(state) is rows
    np.testing.assert_array_equal(st.gaps(state), _fresh_gaps(system, state))
    states = [state]
    for k in range(ROWS_KEPT + 2):  # stepped states, not evaluated: computed
        new = st.advance(state, st.derivative(state, sol), 1e-3 * (k + 1))
        assert st._known_rows(new) is None
        np.testing.assert_array_equal(st.gaps(new), _fresh_gaps(system, new))
        st.evaluate(1e-3 * (k + 1), new)  # now known
        assert st._known_rows(new) is not None
        states.append(new)
    assert st._known_rows(state) is None  # forgotten: the oldest of more than ROWS_KEPT
    for s in states:
        np.testing.assert_array_equal(st.gaps(s), _fresh_gaps(system, s))
    copy = SystemState(state.q.copy(), state.v.copy(), state.obj)
    assert st._known_rows(copy) is None


def test_the_initial_gaps_by_the_reference_equal_the_compiled_ones_and_are_not_kept():
    """``blocks_at(reference=True)`` (what ``simulate`` decides the initial active set from).

    pick_from_table: the same gaps as the compiled path's to round-off, and its rows are not
    remembered for the stepper's reuse (only its own path's are).
    """
    built = build_scenario(load_scenario(SCENARIOS / "pick_from_table.yaml"),
                           load_visuals=False)
    system, state = built.system, built.initial_state
    st = Stepper(system, scenario_controller(built), "auto", built.scenario.simulation.baumgarte)
    ref = st.blocks_at(0.0, state, reference=True)[1]
    assert st._known_rows(state) is None
    fast = st.blocks_at(0.0, state)[1]
    assert st._known_rows(state) is fast
    np.testing.assert_allclose(ref.phi, fast.phi, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(ref.phi_dot, fast.phi_dot, rtol=0.0, atol=1e-12)


def test_simulate_decides_the_initial_active_set_from_the_reference(monkeypatch):
    """A run the compiled loops take never calls the Python path's compiled evaluation."""
    built = build_scenario(load_scenario(SCENARIOS / "pick_from_table.yaml"),
                           load_visuals=False)
    seen = []
    blocks_at = Stepper.blocks_at

    def spy(self, t, state, reference=False):
        seen.append((t, reference))
        return blocks_at(self, t, state, reference)

    monkeypatch.setattr(Stepper, "blocks_at", spy)
    sim = built.scenario.simulation
    simulate(built.system, built.initial_state, scenario_controller(built), 2 * sim.dt, sim.dt,
             baumgarte=sim.baumgarte, compiled=False)
    assert seen[0] == (0.0, True)
