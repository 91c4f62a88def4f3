"""The replay page's overlay (issue 25): simulated time, legend, contact timeline, in a browser."""

from __future__ import annotations

import re

import numpy as np
import pinocchio as pin
import pytest
from browser_helpers import (
    dump_dom,
    element_text,
    needs_chromium,
    page_url,
    run_command,
    screenshot,
)

from multiarm_pin.app.replay import (
    ReplayArm,
    ReplayContacts,
    ReplayEvent,
    ReplayObject,
    ReplaySupport,
    write_replay_html,
)
from multiarm_pin.app.replay_overlay import body_of, overlay_data, touching_runs
from multiarm_pin.app.replay_page import decode_block
from multiarm_pin.exceptions import InputError
from multiarm_pin.model.polyhedron import box

LABELS = ["left:tip[0]", "left:tip[1]", "table[0]", "table[1]"]
T_SEPARATE, T_TOUCH, IMPULSE = 0.4, 0.6, 0.25


def _scene(n: int = 101):
    """A box on a table held by one arm's two tips over 1 s (spheres at the joints, no mesh).

    ``table[0]`` separates at 0.4 s; ``left:tip[1]`` is off until it touches down with an
    impact at 0.6 s.
    """
    import example_robot_data as erd

    ur5 = erd.load("ur5")
    t = np.linspace(0.0, 1.0, n)
    q = np.array([0.0, -1.2, 1.6, -1.9, -1.57, 0.0]) + 0.2 * np.sin(np.pi * t)[:, None]
    arms = [ReplayArm("left", ur5.model, None, pin.SE3(np.eye(3), np.array([0, 0.6, 0])), q,
                      (0.3, 0.3, 0.35, 1.0))]
    pos = np.column_stack([0.5 + 0 * t, 0 * t, 0.1 + 0.05 * t])
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    obj = ReplayObject(box([0.3, 0.3, 0.2]), pos, quat)
    offsets = np.array([[0, 0.15, 0], [0, -0.15, 0], [0.1, 0.1, -0.1], [-0.1, -0.1, -0.1]])
    points = pos[:, None, :] + offsets[None]
    forces = np.tile([0.0, 0.0, 10.0], (n, 4, 1))
    touching = np.ones((n, 4), dtype=bool)
    touching[t >= T_SEPARATE, 2] = False
    touching[t < T_TOUCH, 1] = False
    events = [ReplayEvent(T_SEPARATE, "separation", 2), ReplayEvent(T_TOUCH, "touchdown", 1,
                                                                   IMPULSE)]
    table = ReplaySupport("table", [0.5, -1e-17, 0.0], [0, 0, 1], 0.3)
    contacts = ReplayContacts(points, forces, touching, [table], LABELS, events)
    return arms, obj, contacts, t


def test_overlay_data_groups_contacts_by_body_and_lists_events():
    arms, obj, contacts, t = _scene()
    data = overlay_data(t, contacts, title="demo", arm_names=["left"], force_scale=0.01,
                        support_colors=[0x6C584C], colors={"contact": 0xFFD60A})
    assert data["t0"] == 0.0 and data["t_end"] == 1.0 and data["colors"]["contact"] == "#ffd60a"
    assert [b["name"] for b in data["bodies"]] == ["left", "table"]
    left, table = data["bodies"]
    assert left["contacts"] == 2 and table["contacts"] == 2
    # tip[1] comes on at the first sample at or after 0.6 s; table[0] goes off at 0.4 s
    assert left["runs"] == [[0.0, 1], [pytest.approx(T_TOUCH), 2]]
    assert table["runs"] == [[0.0, 2], [pytest.approx(T_SEPARATE), 1]]
    assert data["events"] == [
        {"t": T_SEPARATE, "kind": "separation", "label": "table[0]", "body": "table",
         "impulse": 0.0, "impact": False, "row": 1},
        {"t": T_TOUCH, "kind": "touchdown", "label": "left:tip[1]", "body": "left",
         "impulse": IMPULSE, "impact": True, "row": 0}]
    # without fps (no per-frame states of the support points) one row per body
    assert data["rows"] == data["bodies"] and data["vertices"] == [] and data["phases"] == []
    assert data["supports"][0] == {"name": "table", "color": "#6c584c",
                                   "plane": "plane through (0.5, 0, 0) m, normal (0, 0, 1)"}
    assert data["force"] == {"m_per_n": 0.01, "max_n": pytest.approx(10.0)}
    assert overlay_data(t, None)["bodies"] == []
    assert body_of("a:b:c") == "a" and body_of("floor[12]") == "floor"
    assert touching_runs(np.arange(4.0), np.array([1, 1, 1, 1])) == [[0.0, 1]]


def test_bad_labels_and_events_are_refused():
    _, _, c, _ = _scene(5)
    with pytest.raises(InputError, match="expected 4 names"):
        ReplayContacts(c.points, c.forces, labels=["a"])
    with pytest.raises(InputError, match="not an event of one of the 4 contacts"):
        ReplayContacts(c.points, c.forces, events=[ReplayEvent(0.1, "separation", 4)])
    with pytest.raises(InputError, match="not an event"):
        ReplayContacts(c.points, c.forces, events=[ReplayEvent(0.1, "bounce", 0)])
    with pytest.raises(InputError, match="finite time and impulse"):
        ReplayContacts(c.points, c.forces, events=[ReplayEvent(0.1, "touchdown", 0, np.nan)])
    with pytest.raises(InputError, match="ReplayEvent items"):
        ReplayContacts(c.points, c.forces, events=[(0.1, "separation", 0)])


def test_page_carries_the_overlay(tmp_path):
    arms, obj, contacts, t = _scene()
    page = write_replay_html(tmp_path / "r.html", arms, obj, t, contacts, title="box <on> table")
    html = page.read_text()
    manifest, _ = decode_block(html)
    assert manifest["overlay"]["title"] == "box <on> table"
    assert "<title>box &lt;on&gt; table</title>" in html
    assert "<on>" not in html  # escaped in the title and in the page's JSON (\u003c)
    assert [e["label"] for e in manifest["overlay"]["events"]] == ["table[0]", "left:tip[1]"]


@needs_chromium
def test_time_legend_and_events_are_drawn(tmp_path):
    """The overlay in headless Chromium: its DOM text after the scripts ran, and its pixels.

    Opened as ``#t=0.5``, the page is paused at 0.5 s: one event so far (the separation at
    0.4 s); as ``#t=1``, at the end, both. (``--dump-dom`` renders no frame, so the animation
    does not play there: the time comes from the seek.) The legend names the colours and the
    support. The screenshot's pixels show the panel and the timeline's bars.
    """
    arms, obj, contacts, t = _scene()
    page = write_replay_html(tmp_path / "r.html", arms, obj, t, contacts, title="box on table")
    end = dump_dom(page_url(page, "#t=1"))
    assert element_text(end, "ma-time").strip() == "t = 1.000 s"
    assert "2 of 2 events so far" in element_text(end, "ma-events")
    legend = element_text(end, "ma-legend")
    for words in ("contact touching", "contact separated", "support table", "force on the "
                  "object", "separation", "touchdown", "impact"):
        assert words in legend, (words, legend)
    # a run without phases: no phase line, table or timeline row
    assert element_text(end, "ma-phase").strip() == "" and "phases" not in legend
    mid = dump_dom(page_url(page, "#t=0.5"))
    assert element_text(mid, "ma-time").strip() == "t = 0.500 s"
    events = element_text(mid, "ma-events")
    assert "1 of 2 events so far" in events and "0.400 s separation" in events, events

    img = screenshot(page_url(page, "#t=0.5"), tmp_path / "mid.png")
    # The info panel (top left) is dark over the light sky (top, right of it), with light
    # text in it.
    panel, sky = img[15:120, 15:380], img[15:120, 500:900]
    assert panel.mean() < 0.6 * sky.mean(), (panel.mean(), sky.mean())
    assert np.sum(panel.min(axis=2) > 200) > 400  # text pixels
    # The timeline (bottom) shows yellow (touching) and grey (separated) bars.
    strip = img[-90:, 180:]
    yellow = (strip[..., 0] > 200) & (strip[..., 1] > 170) & (strip[..., 2] < 80)
    grey = (np.abs(strip[..., 0] - 0x8D) < 12) & (np.abs(strip[..., 2] - 0xAE) < 12)
    assert yellow.sum() > 2000 and grey.sum() > 300, (yellow.sum(), grey.sum())


@needs_chromium
def test_the_readmes_screenshot_command_works(tmp_path):
    """The README's headless-Chromium block, run as written in a folder with a results page."""
    from pathlib import Path

    from PIL import Image

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    blocks = re.findall(r"```bash\n(.*?)```", readme, re.S)
    block = next(b for b in blocks if "--screenshot=replay.png" in b)
    (tmp_path / "results" / "demo").mkdir(parents=True)
    arms, obj, contacts, t = _scene()
    write_replay_html(tmp_path / "results" / "demo" / "replay.html", arms, obj, t, contacts)
    run_command(["sh", "-e", "-c", block], cwd=tmp_path)  # a run that hangs is run again
    img = np.asarray(Image.open(tmp_path / "replay.png").convert("RGB"), dtype=int)
    assert img.shape == (800, 1280, 3)
    panel = img[15:120, 15:380]
    assert panel.mean() < 100 and np.sum(panel.min(axis=2) > 200) > 400  # the info panel


def test_a_runs_page_marks_the_summarys_events(tmp_path, capsys):
    """Through the command line: a box dropped on a table (touchdowns with and without an
    impulse, rebounds); the page's timeline holds every event of summary.json, with its
    time, kind, contact and impulse."""
    import json

    from multiarm_pin.app import cli
    from multiarm_pin.data import data_path

    out = tmp_path / "box"
    assert cli.main(["run", str(data_path("scenarios", "box_on_table.yaml")), "--out",
                     str(out), "--quiet"]) == 0
    capsys.readouterr()
    events = json.loads((out / "summary.json").read_text())["events"]
    assert any(e["impulse"] > 0 for e in events) and any(e["impulse"] == 0 for e in events)
    overlay = decode_block((out / "replay.html").read_text())[0]["overlay"]
    assert [(e["t"], e["kind"], e["label"], e["body"], e["impulse"]) for e in
            overlay["events"]] == [(e["t"], e["kind"], e["label"], e["body"], e["impulse"])
                                   for e in events]
    assert [e["impact"] for e in overlay["events"]] == [
        e["kind"] == "touchdown" and e["impulse"] > 0 for e in events]
    assert [b["name"] for b in overlay["bodies"]] == ["table"]
    assert [s["name"] for s in overlay["supports"]] == ["table"]
