"""The replay of a phased task (issue 27): its phases and which support points touch.

The run is ``tests/app/data/tilt_couple_run``: the results folder ``multiarm-pin run`` wrote
for ``tests/app/data/tilt_couple.yaml`` (tilt_pick's couple turning the box about its +x
bottom edge; phases rest, tilt, settle; ``table[2]``, ``table[3]`` separate at 0.105 s).
Kept in the repository so that no test simulates (the run takes seconds, its set-up more).
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import msgpack
import numpy as np
import pytest
import yaml
from browser_helpers import dump_dom, element_text, needs_chromium, page_url

from multiarm_pin.app.replay import write_replay_html
from multiarm_pin.app.replay_overlay import overlay_data
from multiarm_pin.app.replay_page import decode_block
from multiarm_pin.app.replay_phases import (
    ReplayPhase,
    check_phases,
    phase_indices,
    phase_table,
    phases_summary,
    replay_phases,
)
from multiarm_pin.app.run_results import load_run, replay_parts
from multiarm_pin.app.scenario import build_object, load_scenario
from multiarm_pin.data import data_path
from multiarm_pin.exceptions import InputError

DATA = Path(__file__).resolve().parent / "data"
RUN = DATA / "tilt_couple_run"
FPS = 30


@cache
def _run():
    """``(scenario, trajectory, phases, contacts)`` of the saved run (no arms drawn)."""
    sc, traj, _ = load_run(RUN)
    _, _, contacts = replay_parts([], build_object(sc), traj)
    return sc, traj, replay_phases(sc, traj), contacts


def _yaml_phases() -> list[dict]:
    """The phases as the scenario file writes them (read with plain YAML, not the package)."""
    return yaml.safe_load((DATA / "tilt_couple.yaml").read_text())["controller"]["phases"]


def test_the_phases_are_the_scenarios():
    sc, traj, phases, _ = _run()
    raw = _yaml_phases()
    assert [(p.name, p.kind, p.t, p.duration) for p in phases] == [
        (d["name"], d["kind"], d["t"], d["duration"]) for d in raw]
    # press: support row indices -> the rows' labels (rest names none: every row presses)
    assert [p.press for p in phases] == [
        ("table[0]", "table[1]", "table[2]", "table[3]"), ("table[0]", "table[1]"),
        ("table[0]", "table[1]")]
    table = phase_table(phases, float(traj["t"][-1]))
    # rest moves the arms' offsets, tilt turns the box, settle moves nothing
    assert [(r["t"], r["end"], r["motion_end"], r["offsets"]) for r in table] == [
        (0.0, 0.1, 0.1, ["pusher", "stop"]), (0.1, 0.4, 0.4, []),
        (0.4, pytest.approx(0.5), 0.4, [])]
    # a scenario of another controller has no phases
    box = load_scenario(data_path("scenarios", "box_on_table.yaml"))
    assert replay_phases(box, {}) == ()


def test_the_phase_shown_at_a_time_is_the_one_the_yaml_starts():
    """phased_pd's rule: the last phase started (t >= its t), read off the YAML's t values."""
    _, traj, phases, _ = _run()
    t_tilt, t_settle = (d["t"] for d in _yaml_phases()[1:])
    assert (t_tilt, t_settle) == (0.1, 0.4)
    times = [0.0, 0.05, 0.0999, 0.1, 0.25, 0.3999, 0.4, 0.5]
    expected = ["rest", "rest", "rest", "tilt", "tilt", "tilt", "settle", "settle"]
    assert [phases[k].name for k in phase_indices(phases, times)] == expected
    # every sample of the run
    t = traj["t"]
    names = np.array([phases[k].name for k in phase_indices(phases, t)])
    assert np.all(names[t < t_tilt] == "rest") and np.all(names[t >= t_settle] == "settle")
    assert np.all(names[(t >= t_tilt) & (t < t_settle)] == "tilt")
    assert phase_indices((), t).tolist() == [-1] * len(t)


def test_support_point_states_are_the_recorded_gaps_and_forces():
    """At every frame, each support point's state, force and gap on the page against the
    run's ``mu_table`` and ``phi_table`` at the sample the frame shows (the nearest)."""
    _, traj, phases, contacts = _run()
    data = overlay_data(traj["t"], contacts, phases=phases, fps=FPS)
    t = traj["t"]
    mu, phi = traj["mu_table"], traj["phi_table"]
    vertices = data["vertices"]
    assert [v["label"] for v in vertices] == [f"table[{j}]" for j in range(4)]
    n_frames = int(np.floor((t[-1] - t[0]) * FPS + 1e-9)) + 1
    samples = [int(np.argmin(np.abs(t - (t[0] + i / FPS)))) for i in range(n_frames)]
    seen = set()
    for j, v in enumerate(vertices):
        assert len(v["on"]) == n_frames
        for i, s in enumerate(samples):
            on = v["on"][i] == 1
            seen.add((j, on))
            if on:  # on the plane, pushing or at rest
                assert abs(phi[s, j]) < 1e-6 and mu[s, j] >= 0.0, (j, i, phi[s, j], mu[s, j])
            else:  # above the plane, no force
                assert phi[s, j] > 0.0 and mu[s, j] == 0.0, (j, i, phi[s, j], mu[s, j])
            assert v["force"][i] == pytest.approx(mu[s, j], rel=1e-3, abs=1e-9)
            assert v["gap"][i] == pytest.approx(phi[s, j], rel=1e-3, abs=1e-9)
    # the pivot (0, 1) presses throughout; 2, 3 separate at the tilt's start and stay off
    assert seen == {(0, True), (1, True), (2, True), (3, True), (2, False), (3, False)}
    first_off = [i for i, s in enumerate(samples) if vertices[2]["on"][i] == 0][0]
    assert t[samples[first_off - 1]] < 0.105 <= t[samples[first_off]]
    # the timeline: one row per arm, one per support point; the events on the points' rows
    assert [r["name"] for r in data["rows"]] == ["pusher", "stop", *(v["label"] for v in
                                                                    vertices)]
    assert [(e["label"], data["rows"][e["row"]]["name"]) for e in data["events"]] == [
        ("table[2]", "table[2]"), ("table[3]", "table[3]")]


def test_the_summary_lists_the_phases_and_their_events():
    """``summary.json``'s ``phases`` (written by ``run``; the saved one is compared too)."""
    import json

    sc, traj, _, _ = _run()
    saved = json.loads((RUN / "summary.json").read_text())
    rows = phases_summary(sc, traj, saved["events"])
    assert rows == saved["phases"]
    # the far edge's points separate during the tilt (0.1-0.4 s in the YAML), nothing else
    assert [(r["name"], r["events"]) for r in rows] == [
        ("rest", []), ("tilt", ["0.105 s separation table[2]", "0.105 s separation table[3]"]),
        ("settle", [])]
    box = load_scenario(data_path("scenarios", "box_on_table.yaml"))
    assert phases_summary(box, traj, saved["events"]) == []


def test_the_runs_page_gets_the_phases(tmp_path):
    """The runner's page step reads the phases from the scenario it ran."""
    from types import SimpleNamespace

    from multiarm_pin.app.runner import _write_page

    sc, traj, _, _ = _run()
    built = SimpleNamespace(arms=[], obj=build_object(sc), scenario=sc)
    page = _write_page(tmp_path, built, traj)
    overlay = decode_block(page.read_text())[0]["overlay"]
    assert [(p["name"], p["t"]) for p in overlay["phases"]] == [
        (d["name"], d["t"]) for d in _yaml_phases()]


def test_bad_phases_are_refused():
    with pytest.raises(InputError, match="duration > 0"):
        ReplayPhase("a", "hold", 0.0, 0.0)
    with pytest.raises(InputError, match="not after"):
        check_phases([ReplayPhase("a", "hold", 0.5, 1.0), ReplayPhase("b", "hold", 0.5, 1.0)])
    with pytest.raises(InputError, match="expected a ReplayPhase"):
        check_phases([{"name": "a"}])


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    """The replay page of the saved run (the object and contacts; no arms: faster)."""
    sc, traj, phases, contacts = _run()
    _, obj, _ = replay_parts([], build_object(sc), traj)
    path = tmp_path_factory.mktemp("phases") / "replay.html"
    return write_replay_html(path, [], obj, traj["t"], contacts, fps=FPS, title="tilt_couple",
                             phases=phases)


def test_the_page_carries_the_phases_and_cubes(page):
    manifest, _ = decode_block(page.read_text())
    overlay = manifest["overlay"]
    assert [p["name"] for p in overlay["phases"]] == ["rest", "tilt", "settle"]
    assert overlay["fps"] == FPS and len(overlay["vertices"]) == 4
    # the support points (contacts 6-9) are drawn as cubes, the arms' contacts as spheres
    _, block = decode_block(page.read_text())
    shapes = {}
    for start, size in manifest["commands"]:
        cmd = msgpack.unpackb(block[start:start + size])
        if cmd["type"] == "set_object" and "/contacts/" in cmd["path"]:
            shapes[cmd["path"].rsplit("/", 1)[1]] = cmd["object"]["geometries"][0]["type"]
    labels = [str(x) for x in _run()[1]["contact_labels"]]
    for k, label in enumerate(labels):
        want = "BoxGeometry" if label.startswith("table[") else "SphereGeometry"
        assert shapes[f"point_{k}"] == shapes[f"free_{k}"] == want, (label, shapes)
    assert sum(lab.startswith("table[") for lab in labels) == 4


@needs_chromium
def test_the_page_shows_the_phase_and_the_support_points(page):
    """In headless Chromium, paused at three times: the phase named (the YAML's intervals),
    the support points' states (the pivot pressing, the raised edge separated), the legend's
    phase table with the current phase highlighted."""
    early = dump_dom(page_url(page, "#t=0.05"))
    assert "phase 1/3: rest (hold), pusher, stop moving until 0.100 s" in element_text(
        early, "ma-phase")
    verts = element_text(early, "ma-vertices")
    assert all(f"[{j}] pressing" in verts or f"[{j}] touching" in verts for j in range(4)), verts
    legend = element_text(early, "ma-legend")
    for words in ("rest hold 0.000–0.100", "tilt tilt 0.100–0.400 table[0], table[1]",
                  "settle hold 0.400–0.500", "support point touching"):
        assert words in legend, (words, legend)
    assert 'id="ma-phase-0" class="ma-now"' in early

    mid = dump_dom(page_url(page, "#t=0.25"))
    assert "phase 2/3: tilt (tilt), moving until 0.400 s" in element_text(mid, "ma-phase")
    verts = element_text(mid, "ma-vertices")
    assert "[0] pressing" in verts and "[1] pressing" in verts, verts
    assert "[2] separated" in verts and "[3] separated" in verts, verts
    assert 'id="ma-phase-1" class="ma-now"' in mid and 'id="ma-phase-0" class=""' in mid

    late = dump_dom(page_url(page, "#t=0.45"))
    assert "phase 3/3: settle (hold), holding" in element_text(late, "ma-phase")


def test_the_contact_plot_names_the_phases(tmp_path, monkeypatch):
    """``contact_states.png``: a band per phase over its interval, named above the plot."""
    from multiarm_pin.app import plots

    _, traj, phases, _ = _run()
    figures = []
    monkeypatch.setattr(plots, "_save", lambda fig, path: figures.append(fig) or Path(path))
    plots.plot_contact_states(tmp_path / "c.png", traj["t"], traj["contact_active"],
                              traj["contact_labels"], phases=phases)
    plots.plot_contact_states(tmp_path / "d.png", traj["t"], traj["contact_active"],
                              traj["contact_labels"])
    with_phases, without = (f.axes[0] for f in figures)
    assert [x.get_text() for x in with_phases.texts] == ["rest", "tilt", "settle"]
    # two bands per phase that moves (its interval, its motion), from the YAML's intervals
    spans = sorted((round(p.get_x(), 9), round(p.get_x() + p.get_width(), 9))
                   for p in with_phases.patches)
    assert spans == [(0.0, 0.1), (0.0, 0.1), (0.1, 0.4), (0.1, 0.4), (0.4, 0.5)]  # settle: still
    assert len(without.texts) == 0 and len(without.patches) == 0
    for f in figures:
        plots.plt.close(f)


def test_the_replay_command_prints_the_phases(monkeypatch, capsys):
    """``multiarm-pin replay DIR`` (the live viewer has no overlay) lists the phase table."""
    from multiarm_pin.app import cli, replay, runner

    monkeypatch.setattr(runner, "serve_run", lambda *a, **k: ("http://127.0.0.1:7000", None))
    monkeypatch.setattr(runner, "http_status", lambda url: 200)
    monkeypatch.setattr(replay, "close_visualizer", lambda vis: None)
    assert cli.main(["replay", str(RUN), "--no-block"]) == 0
    lines = [x.split() for x in capsys.readouterr().out.splitlines() if " s  " in x]
    assert [(x[0], x[2], x[4]) for x in lines] == [
        ("0.000", "0.100", "rest"), ("0.100", "0.400", "tilt"), ("0.400", "0.500", "settle")]
    assert lines[1][-2:] == ["table[0],", "table[1]"]
