"""Tests of the in-process replay page and of the batched replay timeline (issue 14).

The page written without a Meshcat server must be the server's page, byte for byte, and the
timeline computed for all frames at once must be the one meshcat's own per-frame API builds.
"""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys
from pathlib import Path

import example_robot_data as erd
import meshcat
import meshcat.animation
import numpy as np
import pinocchio as pin
import pytest
import umsgpack
from browser_helpers import needs_chromium, page_url, screenshot
from meshcat import Visualizer
from meshcat.commands import SetAnimation

from multiarm_pin.app import replay
from multiarm_pin.app.replay import (
    ReplayArm,
    ReplayContacts,
    ReplayObject,
    build_animation,
    close_visualizer,
    frame_indices,
    write_replay_html,
)
from multiarm_pin.app.replay_meshes import visual_mesh
from multiarm_pin.app.replay_page import PageWindow, pack
from multiarm_pin.model.polyhedron import box
from multiarm_pin.spatial import quaternion_to_rotation

MP6 = Path(__file__).resolve().parents[1] / "robots" / "mp6" / "mp6.urdf"


class RecordingWindow:
    """Stands in for a Meshcat server: keeps the commands instead of sending them."""

    def __init__(self):
        self.commands = []

    def send(self, command):
        self.commands.append(command)


class TeeWindow:
    """Sends every command to several windows."""

    def __init__(self, *windows):
        self.windows = windows

    def send(self, command):
        for w in self.windows:
            w.send(command)


@pytest.fixture(scope="module")
def ur5():
    return erd.load("ur5")


def _scene(ur5, touching: bool, n: int = 121):
    """Two UR5s (meshes), an MP6 (cylinders), a bare arm (spheres), a box, three contacts.

    Forces are random with exact zeros (no arrow) and directions near x (the other helper
    axis of the arrow's rotation); the object turns about all three axes.
    """
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.004, 0.012, n))
    q = np.array([0.0, -1.2, 1.6, -1.9, -1.57, 0.0]) + np.sin(3 * t)[:, None] * rng.uniform(
        0.1, 0.5, 6)
    model, visual = pin.buildModelsFromUrdf(str(MP6), str(MP6.parent),
                                            geometry_types=pin.GeometryType.VISUAL)
    visual.geometryObjects[1].meshScale = np.array([1.0, 1.0, 1.5])  # a scaled cylinder
    arms = [
        ReplayArm("left", ur5.model, ur5.visual_model, pin.SE3(np.eye(3), np.array([0, .6, 0])),
                  q),
        ReplayArm("right", ur5.model, ur5.visual_model,
                  pin.SE3(pin.rpy.rpyToMatrix(0.1, 0, np.pi), np.array([0, -.6, 0])), q),
        ReplayArm("mp6", model, visual, pin.SE3(np.eye(3), np.array([1.5, 0, 0])), q[:, ::-1]),
        ReplayArm("bare", ur5.model, None, pin.SE3.Identity(), q, (0.2, 0.3, 0.4, 1.0)),
    ]
    pos = np.column_stack([0 * t, 0.1 * t, 0.4 + 0.1 * np.sin(np.pi * t)])
    quat = np.array([pin.Quaternion(pin.rpy.rpyToMatrix(0.3 * s, 2.0 * s, 3.0 * s)).coeffs()
                     for s in np.sin(np.pi * t)])
    obj = ReplayObject(box([0.3, 0.4, 0.25]), pos, quat)
    points = np.stack([pos + [0, 0.2, 0], pos + [0, -0.2, 0], pos], axis=1)
    forces = rng.normal(size=points.shape) * 30
    forces[::7, 1] = 0.0
    forces[::5, 2] = [0.95, 0.01, -0.01]
    contacts = ReplayContacts(points, forces,
                              rng.random(points.shape[:2]) < 0.7 if touching else None)
    return arms, obj, contacts, t


def _reference_animation(vis, arms, obj, contacts, t, fps, force_scale):
    """The timeline frame by frame through meshcat's API (``at_frame``, ``set_transform``).

    Node poses from Pinocchio directly: base placement times the geometry placement (or the
    joint placement for an arm without visuals).
    """
    anim = meshcat.animation.Animation(default_framerate=fps)
    datas = [arm.model.createData() for arm in arms]
    geom_datas = [None if a.visual_model is None else pin.GeometryData(a.visual_model)
                  for a in arms]
    for frame, i in enumerate(frame_indices(t, fps)):
        at = anim.at_frame(vis, frame)
        for arm, data, gdata in zip(arms, datas, geom_datas, strict=True):
            pin.forwardKinematics(arm.model, data, arm.q[i])
            base = arm.base_placement.homogeneous
            if gdata is None:
                for j in range(1, arm.model.njoints):
                    at[f"arms/{arm.name}/joints/{arm.model.names[j]}"].set_transform(
                        base @ data.oMi[j].homogeneous)
                continue
            pin.updateGeometryPlacements(arm.model, data, arm.visual_model, gdata)
            for g, M in zip(arm.visual_model.geometryObjects, gdata.oMg, strict=True):
                node = at[f"arms/{arm.name}/visuals/{g.name}"]
                node.set_transform(base @ M.homogeneous)
                scale = np.asarray(g.meshScale, dtype=float)
                if not np.allclose(scale, 1.0) and visual_mesh(g) is None:  # (COLLADA: slow)
                    node.set_property("scale", "vector3", scale.tolist())
        T = np.eye(4)
        T[:3, :3] = quaternion_to_rotation(obj.quaternion[i])
        T[:3, 3] = obj.position[i]
        at["object"].set_transform(T)
        for k in range(contacts.points.shape[1]):
            P = np.eye(4)
            P[:3, 3] = contacts.points[i, k]
            at[f"contacts/point_{k}"].set_transform(P)
            if contacts.touching is not None:
                on = bool(contacts.touching[i, k])
                at[f"contacts/free_{k}"].set_transform(P)
                at[f"contacts/point_{k}"].set_property("scale", "vector3",
                                                       [1.0] * 3 if on else [1e-6] * 3)
                at[f"contacts/free_{k}"].set_property("scale", "vector3",
                                                      [1e-6] * 3 if on else [1.0] * 3)
            f = contacts.forces[i, k]
            norm = float(np.linalg.norm(f))
            F = P.copy()
            if norm > 0:
                F[:3, :3] = replay._rotation_y_to(f / norm)
            at[f"contacts/force_{k}"].set_transform(F)
            at[f"contacts/force_{k}"].set_property("scale", "vector3",
                                                   [1.0, max(norm * force_scale, 1e-6), 1.0])
    return anim


@pytest.mark.parametrize("touching", [False, True])
def test_batched_timeline_is_meshcats_per_frame_one(ur5, touching):
    arms, obj, contacts, t = _scene(ur5, touching)
    fps, scale = 25, 0.004
    vis = Visualizer(window=RecordingWindow())
    anim = build_animation(vis, arms, obj, contacts, t, fps=fps, force_scale=scale)
    ref = _reference_animation(vis, arms, obj, contacts, t, fps, scale)
    # same nodes and properties in the same order (the page lists them in this order)
    assert [p.lower() for p in anim.clips] == [p.lower() for p in ref.clips]
    assert any("scale" in c.tracks for p, c in ref.clips.items() if "mp6" in p.lower())
    for path, clip in ref.clips.items():
        mine = anim.clips[path]
        assert list(mine.tracks) == list(clip.tracks), path.lower()
        assert mine.fps == clip.fps == fps
        for prop, track in clip.tracks.items():
            assert mine.tracks[prop].jstype == track.jstype
            assert mine.tracks[prop].frames == track.frames == list(range(len(track.frames)))
            np.testing.assert_allclose(np.array(mine.tracks[prop].values, dtype=float),
                                       np.array(track.values, dtype=float), rtol=0,
                                       atol=1e-12, err_msg=f"{path.lower()} {prop}")


def test_msgpack_packs_meshcat_commands_as_umsgpack(ur5):
    arms, obj, contacts, t = _scene(ur5, touching=True, n=30)
    window = RecordingWindow()
    vis = Visualizer(window=window)
    anim = build_animation(vis, arms, obj, contacts, t)
    commands = [c.lower() for c in window.commands] + [SetAnimation(anim).lower()]
    assert any(isinstance(v, umsgpack.Ext) for c in commands[:3]
               for v in _leaves(c))  # the meshes' binary arrays are msgpack extensions
    for c in commands:
        assert pack(c) == umsgpack.packb(c), c["path"]
    odd = {"type": "x", "path": "", "v": [True, None, -1, 2**40, -2**40, 1.5, "é", b"\x00",
                                           (1, 2), {"a": {}}, np.float64(0.1), -0.0]}
    assert pack(odd) == umsgpack.packb(odd)
    with pytest.raises(TypeError, match="cannot pack"):
        pack({"a": object()})


def _leaves(x):
    if isinstance(x, dict):
        for v in x.values():
            yield from _leaves(v)
    elif isinstance(x, list | tuple):
        for v in x:
            yield from _leaves(v)
    else:
        yield x


def test_page_is_the_meshcat_servers_page(ur5):
    arms, obj, contacts, t = _scene(ur5, touching=True, n=40)
    with contextlib.redirect_stdout(io.StringIO()):
        server = Visualizer()
    try:
        page = PageWindow(compact=False)
        vis = Visualizer(window=TeeWindow(server.window, page))
        anim = build_animation(vis, arms[:1], obj, contacts, t)
        vis.set_animation(anim, play=True, repetitions=1)
        vis["contacts/point_0"].set_property("visible", False)
        vis["contacts/free_0"].delete()  # a node removed
        vis["object"].set_object(meshcat.geometry.Sphere(0.1))  # replaced: properties cleared
        vis["object"].set_property("visible", True)
        expected = server.static_html()
    finally:
        close_visualizer(server)
    html = page.get_scene()
    assert html == expected
    assert "free_0" not in str(page.tree["meshcat"]["contacts"].keys())
    Visualizer(window=page)["/"].delete()  # the whole scene
    assert "application/octet-binary;base64" in html
    assert "application/octet-binary;base64" not in page.get_scene()
    with pytest.raises(ValueError, match="unsupported Meshcat command"):
        page.send(meshcat.commands.CaptureImage())


def test_page_is_written_without_a_server_or_pinocchios_visualizer(tmp_path):
    # A fresh interpreter: Pinocchio's MeshcatVisualizer (which imports trimesh) is loaded
    # only for primitive geometries, and no Meshcat server process is started.
    code = f"""
import sys
import meshcat.visualizer
import example_robot_data as erd
import numpy as np, pinocchio as pin

def no_server(*args, **kwargs):
    raise AssertionError("a Meshcat server was started")

meshcat.visualizer.start_zmq_server_as_subprocess = no_server
from multiarm_pin.app.replay import ReplayArm, write_replay_html
ur5 = erd.load("ur5")
arm = ReplayArm("a", ur5.model, ur5.visual_model, pin.SE3.Identity(), np.zeros((3, 6)))
write_replay_html({str(tmp_path / "a.html")!r}, [arm], None, [0.0, 0.1, 0.2])
assert "pinocchio.visualize" not in sys.modules, "MeshcatVisualizer imported for meshes"
model, visual = pin.buildModelsFromUrdf({str(MP6)!r}, {str(MP6.parent)!r},
                                        geometry_types=pin.GeometryType.VISUAL)
arm = ReplayArm("m", model, visual, pin.SE3.Identity(), np.zeros((3, model.nq)))
write_replay_html({str(tmp_path / "m.html")!r}, [arm], None, [0.0, 0.1, 0.2])
assert "pinocchio.visualize" in sys.modules  # the cylinders need it
print("ok")
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]
    assert (tmp_path / "a.html").stat().st_size > 1e6


def test_written_page_equals_the_recorded_scene(ur5, tmp_path, monkeypatch):
    # write_replay_html's file is the page of the scene that build_animation records
    arms, obj, contacts, t = _scene(ur5, touching=False, n=20)
    made = []
    monkeypatch.setattr(replay, "page_visualizer",
                        lambda: made.append(Visualizer(window=PageWindow())) or made[-1])
    path = write_replay_html(tmp_path / "r.html", arms[:2], obj, t, contacts, fps=30)
    assert len(made) == 1
    assert path.read_text(encoding="utf-8") == made[0].static_html()
    assert made[0].window.tree["meshcat"]["arms"]["left"]["visuals"]


# ----------------------------------------------------------------------------- issue 25
def _fetch_payloads(html: str) -> list[bytes]:
    """The packed commands of meshcat's page, in order."""
    import base64
    import re

    return [base64.b64decode(m) for m in
            re.findall(r'fetch\("data:application/octet-binary;base64,([A-Za-z0-9+/=]*)"\)',
                       html)]


def test_compact_page_holds_the_plain_pages_commands_and_each_mesh_once(ur5):
    """The compact page is the plain page's commands, each mesh's set_object taken out.

    Two UR5s in their COLLADA colours, two more each painted in one colour (coal's
    triangles: other geometries than the COLLADA files', the same for both, with other
    materials), an MP6 of primitives: the block holds the commands that are not meshes byte
    for byte in the same order; the nodes name every mesh node, in order; each distinct
    geometry is in it once, and decodes to the plain page's triangles within half a
    quantum per axis.
    """
    import msgpack

    from multiarm_pin.app.replay_page import QUANTUM, decode_block, decode_mesh

    arms, obj, contacts, t = _scene(ur5, touching=True, n=40)
    painted = [ReplayArm(f"painted{k}", ur5.model, ur5.visual_model,
                         pin.SE3(np.eye(3), np.array([2.0, k, 0])), arms[0].q, (0.5, 0.5, c, 1.0))
               for k, c in enumerate((0.5, 0.9))]
    plain, compact = PageWindow(compact=False), PageWindow()
    vis = Visualizer(window=TeeWindow(plain, compact))
    anim = build_animation(vis, arms + painted, obj, contacts, t)
    vis.set_animation(anim, play=True, repetitions=1)
    manifest, block = decode_block(compact.get_scene())
    payloads = _fetch_payloads(plain.get_scene())
    commands = [block[a:a + n] for a, n in manifest["commands"]]
    decoded = [msgpack.unpackb(p) for p in payloads]
    is_mesh = ["/visuals/" in d["path"] and d["type"] == "set_object"
               and d["object"]["geometries"][0]["type"] == "BufferGeometry" for d in decoded]
    assert [p for p, m in zip(payloads, is_mesh, strict=True) if not m] == commands
    mesh_commands = [d for d, m in zip(decoded, is_mesh, strict=True) if m]
    assert [d["path"] for d in mesh_commands] == [n[0] for n in manifest["nodes"]]
    n_ur5 = sum(visual_mesh(g) is not None for g in ur5.visual_model.geometryObjects)
    assert len(manifest["nodes"]) == 4 * n_ur5 and len(manifest["meshes"]) == 2 * n_ur5
    by_arm = [[n[1] for n in manifest["nodes"] if f"/arms/{a}/" in n[0]]
              for a in ("left", "right", "painted0", "painted1")]
    assert by_arm[0] == by_arm[1] and by_arm[2] == by_arm[3] and not set(by_arm[0]) & set(
        by_arm[2])
    colours = [[n[2] for n in manifest["nodes"] if f"/arms/{a}/" in n[0]]
               for a in ("painted0", "painted1")]
    assert not {k for m in colours[0] for k in m} & {k for m in colours[1] for k in m}
    for d, (_, g, mats) in zip(mesh_commands, manifest["nodes"], strict=True):
        geom = d["object"]["geometries"][0]["data"]
        v = np.frombuffer(geom["attributes"]["position"]["array"].data, np.float32).reshape(-1, 3)
        index = geom["index"]["array"]
        f = np.frombuffer(index.data, np.uint16 if index.code == 0x14 else np.uint32)
        f = f.reshape(-1, 3)
        m = manifest["meshes"][g]
        pos, idx = (block[a:a + n] for a, n in (m["positions"], m["index"]))
        v2, f2 = decode_mesh(m, pos, idx)
        step = np.asarray(m["step"])
        assert np.all(np.abs(v2[f2] - v[f]) <= 0.5 * step + 1e-6 * np.abs(v[f]) + 1e-9)
        assert np.all(step * QUANTUM <= np.ptp(v, axis=0) * (1 + 1e-6) + 1e-12)
        assert m["groups"] == [[g["start"] // 3, g["count"] // 3] for g in
                               geom.get("groups", [{"start": 0, "count": 3 * len(f)}])]
        materials = d["object"]["materials"]
        assert [manifest["materials"][k] for k in mats] == [
            {k: v for k, v in mat.items() if k != "uuid"} for mat in materials]


def test_mesh_encoding_round_trips_past_16_bit_indices():
    from multiarm_pin.app.replay_page import decode_mesh, encode_mesh

    rng = np.random.default_rng(5)
    for n in (3, 70000):
        v = rng.uniform(-0.3, 0.4, (n, 3)).astype(np.float32)
        v[:, 2] = 0.25  # a flat axis: step 0
        f = rng.integers(0, n, (2 * n, 3))
        header, pos, idx = encode_mesh(v, f)
        assert header["index_bits"] == (16 if n <= 2**16 else 32)
        v2, f2 = decode_mesh(header, pos, idx)
        used = np.unique(f)
        assert header["vertices"] == len(used) and f2.max() == len(used) - 1
        np.testing.assert_allclose(v2[f2], v[f], rtol=0, atol=0.7 / 65535 / 2 + 1e-7)
        assert np.all(v2[:, 2] == np.float32(0.25))


@needs_chromium
def test_compact_page_draws_what_the_plain_page_draws(ur5, tmp_path):
    """Headless Chromium: the compact page (meshes decoded by its script, materials by
    three.js's MaterialLoader, colour groups) shows the plain page's picture.

    Two UR5s in their COLLADA colours (several material groups a mesh) and one painted
    grey, at rest; without the overlay, the same camera. Nearly every pixel matches (the
    quantised vertices move edges by far less than a pixel); the arms cover a good part of
    the view, so the comparison is not one of two empty scenes.
    """
    q = np.tile([0.0, -1.2, 1.6, -1.9, -1.57, 0.0], (2, 1))
    arms = [ReplayArm("a", ur5.model, ur5.visual_model, pin.SE3.Identity(), q),
            ReplayArm("b", ur5.model, ur5.visual_model,
                      pin.SE3(np.eye(3), np.array([0.0, 0.8, 0.0])), q),
            ReplayArm("c", ur5.model, ur5.visual_model,
                      pin.SE3(np.eye(3), np.array([0.0, -0.8, 0.0])), q, (0.8, 0.8, 0.8, 1.0))]
    images = {}
    for name, compact in (("plain", False), ("compact", True), ("empty", True)):
        vis = Visualizer(window=PageWindow(compact=compact))
        anim = build_animation(vis, [] if name == "empty" else arms, None, None, [0.0, 0.1])
        vis.set_animation(anim, play=True, repetitions=1)
        page = tmp_path / f"{name}.html"
        page.write_text(vis.static_html(), encoding="utf-8")
        images[name] = screenshot(page_url(page), tmp_path / f"{name}.png")
    differ = np.any(np.abs(images["compact"] - images["plain"]) > 30, axis=2).mean()
    drawn = np.any(np.abs(images["plain"] - images["empty"]) > 30, axis=2).mean()
    assert drawn > 0.05, f"the arms cover only {drawn:.1%} of the view"
    assert differ < 0.005, f"{differ:.2%} of the pixels differ ({drawn:.1%} drawn)"


def test_a_runs_colliding_links_are_red_in_its_page(tmp_path):
    """A run whose wrists reach the floor: its page holds a red copy of each link in
    collision, shown over the time intervals that summary.json and trajectory.npz give."""
    import json

    import yaml

    from multiarm_pin.app.replay_page import decode_block
    from multiarm_pin.app.runner import run_scenario
    from tests.feasibility.collision_cases import wrists_to_the_floor

    data, _ = wrists_to_the_floor()
    f = tmp_path / "down.yaml"
    f.write_text(yaml.safe_dump(data), encoding="utf-8")
    out = run_scenario(f, tmp_path / "r", plots=False)
    summary = json.loads((out.out_dir / "summary.json").read_text())
    hits = [v for v in summary["violations"] if v["kind"] == "collision"]
    assert hits and all(v["intervals"][0][0] == v["t_first"] for v in hits)
    traj = np.load(out.out_dir / "trajectory.npz")
    assert sorted(traj["collision_link"].tolist()) == sorted(
        f"{v['arm']}/{v['link']}" for v in hits for _ in v["intervals"])
    manifest, _ = decode_block((out.out_dir / "replay.html").read_text(encoding="utf-8"))
    red = {n[0].split("/colliding/visuals/")[0].split("/arms/")[1] for n in manifest["nodes"]
           if "/colliding/" in n[0]}
    assert red == {v["arm"] for v in hits}
    assert manifest["overlay"]["colors"]["colliding"] == "#ff0000"  # in the legend
