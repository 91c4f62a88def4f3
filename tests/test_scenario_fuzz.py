"""Property test: mutated scenario files either run or fail with a MultiArmError message.

Valid scenarios are mutated (a value replaced by another type or value, a key removed,
misspelt or added, the text re-encoded, cut or sprinkled with bytes); whatever the
mutation, loading, building and a short run end in a complete run or a
:class:`~multiarm_pin.exceptions.MultiArmError` whose message names the file or the output
folder: never another exception (a traceback for the user). Bounded: few examples,
at most 20 simulated steps each, derandomised so every run checks the same cases.
"""

from __future__ import annotations

import copy
import tempfile
from pathlib import Path

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from run_helpers import one_arm_scenario

from multiarm_pin.app.runner import run_scenario
from multiarm_pin.app.scenario import load_scenario
from multiarm_pin.exceptions import MultiArmError

BASE = yaml.safe_load(one_arm_scenario(
    controller="{type: object_pd, kp: 10, kd: 5, waypoints: [{t: 0.002, position: "
               "[0.5, 0.0, 0.301]}]}", duration=0.004))
MAX_STEPS = 20


def _paths(node, prefix=()):
    """Every key path (tuple of keys and indices) of a nested mapping/list."""
    out = []
    items = node.items() if isinstance(node, dict) else enumerate(node) \
        if isinstance(node, list) else ()
    for k, v in items:
        out.append((*prefix, k))
        out.extend(_paths(v, (*prefix, k)))
    return out


PATHS = _paths(BASE)

values = st.one_of(
    st.none(), st.booleans(), st.integers(-10**9, 10**9),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8),
    st.lists(st.floats(-10.0, 10.0), max_size=8),
    st.lists(st.integers(-3, 3), min_size=1, max_size=3).map(lambda v: [v, v]),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
    st.sampled_from([0, -1, 1e-300, 1e300, "weld", "object_pd", "ur5", "+x", [0, 0, 0]]),
)


def _parent(data, path):
    node = data
    for k in path[:-1]:
        node = node[k]
    return node


@st.composite
def mutated_text(draw) -> bytes:
    data = copy.deepcopy(BASE)
    for _ in range(draw(st.integers(1, 2))):
        path = draw(st.sampled_from(PATHS))
        try:
            parent = _parent(data, path)
            key = path[-1]
            parent[key]  # noqa: B018 (the path may be gone after an earlier mutation)
        except (KeyError, IndexError, TypeError):
            continue
        op = draw(st.sampled_from(["value", "delete", "rename", "add"]))
        if op == "value":
            parent[key] = draw(values)
        elif op == "delete":
            del parent[key]
        elif op == "rename" and isinstance(parent, dict):
            parent[str(key) + draw(st.sampled_from(["s", "_", "x"]))] = parent.pop(key)
        elif isinstance(parent, dict):
            parent[draw(st.text(min_size=1, max_size=6))] = draw(values)
    text = yaml.safe_dump(data, allow_unicode=True, sort_keys=False).encode("utf-8")
    enc = draw(st.sampled_from(["utf-8", "utf-8", "utf-8", "utf-16", "latin-1", "cut",
                                "bytes", "duplicate"]))
    if enc == "utf-16":
        text = text.decode("utf-8").encode("utf-16")
    elif enc == "latin-1":
        text = text.decode("utf-8").replace("ur5", "ür5").encode("latin-1", errors="replace")
    elif enc == "cut":
        text = text[: draw(st.integers(0, len(text)))]
    elif enc == "bytes":
        at = draw(st.integers(0, len(text)))
        text = text[:at] + draw(st.binary(min_size=1, max_size=3)) + text[at:]
    elif enc == "duplicate":
        lines = text.split(b"\n")
        k = draw(st.integers(0, len(lines) - 1))
        text = b"\n".join([*lines[: k + 1], lines[k], *lines[k + 1:]])
    return text


@settings(max_examples=40, deadline=60_000, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(mutated_text())
def test_mutated_scenarios_run_or_fail_with_a_message(text):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "mutated.yaml"
        path.write_bytes(text)
        try:
            sc = load_scenario(path)
            sim = sc.simulation
            duration = None if sim.duration / sim.dt <= MAX_STEPS else MAX_STEPS * sim.dt
            res = run_scenario(sc, Path(d) / "out", duration=duration, html=False,
                               plots=False)
        except MultiArmError as exc:
            message = str(exc)
            assert message and (str(path) in message or "--out" in message), message
            return
        assert res.summary["status"] == "complete"
        assert (res.out_dir / "trajectory.npz").is_file()
