"""Replay page sizes (issue 25): each mesh once per page, compact animation tracks.

Measured through the real command line for the shipped demo and two-gripper scenarios, and
through the replay API for 40 UR5s with 164 contacts.
"""

from __future__ import annotations

import example_robot_data as erd
import numpy as np
import pinocchio as pin

from multiarm_pin.app import cli
from multiarm_pin.app.replay import (
    ReplayArm,
    ReplayContacts,
    ReplayEvent,
    ReplayObject,
    ReplaySupport,
    write_replay_html,
)
from multiarm_pin.app.replay_page import decode_block
from multiarm_pin.data import data_path
from multiarm_pin.model.polyhedron import box

MB = 1e6


def test_demo_page_is_at_most_2_mb(tmp_path, capsys):
    out = tmp_path / "demo"
    assert cli.main(["demo", "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    page = out / "replay.html"
    size = page.stat().st_size
    assert size <= 2 * MB, f"{size / MB:.2f} MB"
    manifest, _ = decode_block(page.read_text())
    assert len({n[1] for n in manifest["nodes"]}) == len(manifest["meshes"])
    assert {n[0].split("/")[3] for n in manifest["nodes"]} == {"left", "right"}
    assert len(manifest["nodes"]) == 2 * len(manifest["meshes"])  # one UR5 mesh set, twice


def test_two_gripper_page_is_small(tmp_path, capsys):
    out = tmp_path / "grip"
    scenario = data_path("scenarios", "two_gripper_form_closure.yaml")
    assert cli.main(["run", str(scenario), "--out", str(out), "--quiet",
                     "--duration", "0.5"]) == 0
    capsys.readouterr()
    size = (out / "replay.html").stat().st_size
    assert size <= 1.2 * MB, f"{size / MB:.2f} MB"


def test_40_arm_page_is_at_most_10_mb(tmp_path):
    """40 UR5s moving for 2.5 s (1251 samples), four fingertips each, a table (4 contacts).

    Every arm moves at every frame (no constant run to thin) and the contacts switch often:
    the page holds one UR5 mesh set, and the 40 arms' tracks.
    """
    ur5 = erd.load("ur5")
    rng = np.random.default_rng(7)
    n, T = 40, 1251
    t = np.linspace(0.0, 2.5, T)
    arms = []
    for i in range(n):
        robot = ur5
        angle = 2 * np.pi * i / n
        base = pin.SE3(pin.rpy.rpyToMatrix(0, 0, angle + np.pi),
                       np.array([3 * np.cos(angle), 3 * np.sin(angle), 0.0]))
        q0 = np.array([0.0, -1.2, 1.6, -1.9, -1.57, 0.0])
        q = q0 + np.sin(2 * np.pi * t[:, None] / 2.5 + rng.uniform(0, 6, robot.model.nq)) * 0.3
        arms.append(ReplayArm(f"arm{i}", robot.model, robot.visual_model, base, q))
    pos = np.column_stack([0.1 * np.sin(t), 0 * t, 0.5 + 0.1 * t])
    quat = np.tile([0.0, 0.0, 0.0, 1.0], (T, 1))
    obj = ReplayObject(box([1.0, 1.0, 0.5]), pos, quat)
    K = 4 * n + 4
    points = pos[:, None, :] + rng.uniform(-0.5, 0.5, (1, K, 3))
    forces = rng.normal(size=(T, K, 3)) * 10
    touching = rng.random((T, K)) < 0.95
    labels = [f"arm{i}:tip[{j}]" for i in range(n) for j in range(4)] + [
        f"table[{j}]" for j in range(4)]
    events = [ReplayEvent(float(t[i]), "separation", k) for i, k in zip(*np.nonzero(
        touching[:-1] & ~touching[1:]), strict=True)][:500]
    contacts = ReplayContacts(points, forces, touching,
                              [ReplaySupport("table", [0, 0, 0.25], [0, 0, 1], 1.0)], labels,
                              events)
    page = write_replay_html(tmp_path / "forty.html", arms, obj, t, contacts)
    size = page.stat().st_size
    assert size <= 10 * MB, f"{size / MB:.2f} MB"
    manifest, _ = decode_block(page.read_text())
    n_meshes = len(ur5.visual_model.geometryObjects)  # all COLLADA meshes
    assert len(manifest["meshes"]) == n_meshes and len(manifest["nodes"]) == n * n_meshes
    assert len(manifest["overlay"]["bodies"]) == n + 1
