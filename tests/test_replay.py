"""Tests of the Meshcat replay: animation content, offline page, browser rendering, server."""

from __future__ import annotations

import contextlib
import io
import re
import urllib.request
from pathlib import Path

import example_robot_data as erd
import meshcat
import numpy as np
import pinocchio as pin
import pytest
from browser_helpers import needs_chromium, page_url, screenshot
from meshcat import Visualizer

from multiarm_pin.app.replay import (
    ReplayArm,
    ReplayContacts,
    ReplayObject,
    build_animation,
    close_visualizer,
    frame_indices,
    polyhedron_triangles,
    serve_replay,
    set_camera,
    write_replay_html,
)
from multiarm_pin.exceptions import InputError
from multiarm_pin.model.polyhedron import box
from multiarm_pin.spatial import quaternion_to_rotation, rotation_to_quaternion

MP6 = Path(__file__).resolve().parents[1] / "robots" / "mp6" / "mp6.urdf"

DURATION = 2.0
T_SAMPLES = 401  # 5 ms steps, as a simulation would record them


class RecordingWindow:
    """Stands in for a Meshcat server: records the commands instead of sending them."""

    def __init__(self):
        self.commands = []

    def send(self, command):
        self.commands.append(command.lower())


@pytest.fixture(scope="module")
def ur5():
    return erd.load("ur5")


def _two_ur5_scene(ur5, seed=0, color=None):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, DURATION, T_SAMPLES)
    q0 = np.array([0.0, -1.2, 1.6, -1.9, -1.57, 0.0])
    amp = rng.uniform(0.1, 0.3, 6)
    q = q0 + np.sin(np.pi * t)[:, None] * amp
    arms = [
        ReplayArm("left", ur5.model, ur5.visual_model,
                  pin.SE3(np.eye(3), np.array([0, 0.6, 0])), q, color),
        ReplayArm("right", ur5.model, ur5.visual_model,
                  pin.SE3(pin.rpy.rpyToMatrix(0, 0, np.pi), np.array([0, -0.6, 0])), q, color),
    ]
    position = np.column_stack([0 * t, 0 * t, 0.4 + 0.1 * np.sin(np.pi * t)])
    quaternion = np.array([pin.Quaternion(pin.rpy.rpyToMatrix(0, 0, 0.5 * s)).coeffs()
                           for s in np.sin(np.pi * t)])
    obj = ReplayObject(box([0.3, 0.4, 0.25]), position, quaternion)
    points = np.stack([position + [0, 0.2, 0], position + [0, -0.2, 0]], axis=1)
    forces = np.stack([np.tile([0, -30.0, 0], (len(t), 1)),
                       np.tile([0, 30.0, 5.0], (len(t), 1))], axis=1)
    forces[:, 0] *= (1 + np.sin(np.pi * t))[:, None]
    return arms, obj, ReplayContacts(points, forces), t


def _track(anim, node, prop):
    """(times, values) of one animation track, by Meshcat node path relative to the root."""
    for path, clip in anim.clips.items():
        if path.lower() == f"/meshcat/{node}":
            track = clip.tracks[prop]
            return np.array(track.frames), np.array(track.values)
    raise KeyError(node)


# ------------------------------------------------------------------ subsampling
def test_frame_indices_pick_the_nearest_sample():
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.001, 0.02, 300))
    fps = 30
    idx = frame_indices(t, fps)
    assert len(idx) == int(np.floor((t[-1] - t[0]) * fps)) + 1
    for k, i in enumerate(idx):
        target = t[0] + k / fps
        assert abs(t[i] - target) == pytest.approx(np.min(np.abs(t - target)))
    assert list(frame_indices(np.array([0.5]), fps)) == [0]


def test_polyhedron_triangles_cover_the_surface_outward():
    poly = box([0.3, 0.4, 0.25])
    tris = polyhedron_triangles(poly)
    v = poly.vertices[tris]
    normals = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    area = 0.5 * np.linalg.norm(normals, axis=1).sum()
    assert area == pytest.approx(2 * (0.3 * 0.4 + 0.3 * 0.25 + 0.4 * 0.25))
    # outward winding: the divergence theorem gives the volume with the right sign
    volume = np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6
    assert volume == pytest.approx(0.3 * 0.4 * 0.25)


# ------------------------------------------------------------------ animation content
def test_animation_poses_match_kinematics(ur5):
    arms, obj, contacts, t = _two_ur5_scene(ur5)
    window = RecordingWindow()
    vis = Visualizer(window=window)
    fps = 25
    anim = build_animation(vis, arms, obj, contacts, t, fps=fps, force_scale=0.004)
    idx = frame_indices(t, fps)
    assert len(idx) == 51

    # Arm: the wrist_3 mesh sits on the wrist_3_link frame (identity placement); compare
    # with an independent frame-placement computation, base placement included.
    model = ur5.model
    data = model.createData()
    fid = model.getFrameId("wrist_3_link")
    geom = ur5.visual_model.geometryObjects[ur5.visual_model.getGeometryId("wrist_3_link_0")]
    assert geom.parentFrame == fid and geom.placement.isIdentity()
    frames, pos = _track(anim, "arms/right/visuals/wrist_3_link_0", "position")
    _, quat = _track(anim, "arms/right/visuals/wrist_3_link_0", "quaternion")
    assert list(frames) == list(range(len(idx)))
    for k in (0, 17, len(idx) - 1):
        pin.framesForwardKinematics(model, data, arms[1].q[idx[k]])
        expected = arms[1].base_placement * data.oMf[fid]
        np.testing.assert_allclose(pos[k], expected.translation, atol=1e-6)
        R = quaternion_to_rotation(quat[k])  # meshcat tracks are [x, y, z, w] too
        np.testing.assert_allclose(R, expected.rotation, atol=1e-6)

    # Object: position and orientation of the sample nearest each frame.
    _, pos = _track(anim, "object", "position")
    _, quat = _track(anim, "object", "quaternion")
    for k in (0, 10, 50):
        np.testing.assert_allclose(pos[k], obj.position[idx[k]], atol=1e-9)
        assert abs(quat[k] @ obj.quaternion[idx[k]]) == pytest.approx(1.0, abs=1e-9)

    # Forces: the rod's tip is the contact point, its y axis the force direction and
    # its length force_scale * |f|.
    _, pos = _track(anim, "contacts/force_0", "position")
    _, quat = _track(anim, "contacts/force_0", "quaternion")
    _, scale = _track(anim, "contacts/force_0", "scale")
    for k in (0, 25, 40):
        f = contacts.forces[idx[k], 0]
        np.testing.assert_allclose(pos[k], contacts.points[idx[k], 0], atol=1e-9)
        R = quaternion_to_rotation(quat[k])
        np.testing.assert_allclose(R[:, 1], f / np.linalg.norm(f), atol=1e-9)
        np.testing.assert_allclose(scale[k], [1.0, 0.004 * np.linalg.norm(f), 1.0], rtol=1e-9)
    _, pos = _track(anim, "contacts/point_1", "position")
    np.testing.assert_allclose(pos[7], contacts.points[idx[7], 1], atol=1e-9)

    # Every visual geometry of both arms got an object and a track.
    set_paths = {c["path"] for c in window.commands if c["type"] == "set_object"}
    for arm in ("left", "right"):
        for g in ur5.visual_model.geometryObjects:
            assert f"/meshcat/arms/{arm}/visuals/{g.name}" in set_paths


def test_automatic_force_scale_makes_longest_arrow_quarter_metre(ur5):
    arms, obj, contacts, t = _two_ur5_scene(ur5)
    anim = build_animation(Visualizer(window=RecordingWindow()), arms, obj, contacts, t)
    lengths = np.concatenate([_track(anim, f"contacts/force_{k}", "scale")[1][:, 1]
                              for k in range(2)])
    idx = frame_indices(t, 30)
    fmax = np.linalg.norm(contacts.forces[idx], axis=2).max()
    fmax_all = np.linalg.norm(contacts.forces, axis=2).max()
    assert lengths.max() == pytest.approx(0.25 * fmax / fmax_all)


def test_arm_without_visual_model_draws_joint_spheres(ur5):
    q = np.zeros((3, 6))
    arm = ReplayArm("bare", ur5.model, None, pin.SE3.Identity(), q)
    anim = build_animation(Visualizer(window=RecordingWindow()), [arm], None, None,
                           [0.0, 0.1, 0.2])
    data = ur5.model.createData()
    pin.forwardKinematics(ur5.model, data, q[0])
    _, pos = _track(anim, "arms/bare/joints/elbow_joint", "position")
    np.testing.assert_allclose(pos[0], data.oMi[ur5.model.getJointId("elbow_joint")].translation)


def _rgb(color: int) -> np.ndarray:
    """(3,) RGB in [0, 255] of a three.js colour int 0xRRGGBB."""
    return np.array([(color >> 16) & 255, (color >> 8) & 255, color & 255])


def test_arm_meshes_are_sent_in_their_material_colours(ur5):
    # UR5: each mesh one binary buffer, one three.js group and Lambert material per COLLADA
    # material; an explicit arm colour paints everything; the mp6's URDF colours stay.
    mp6, mp6_visual = pin.buildModelsFromUrdf(str(MP6), str(MP6.parent),
                                              geometry_types=pin.GeometryType.VISUAL)
    t = [0.0, 0.1]
    arms = [ReplayArm("ur5", ur5.model, ur5.visual_model, pin.SE3.Identity(), np.zeros((2, 6))),
            ReplayArm("painted", ur5.model, ur5.visual_model,
                      pin.SE3(np.eye(3), np.array([1.0, 0, 0])), np.zeros((2, 6)),
                      color=(0.2, 0.6, 1.0, 1.0)),
            ReplayArm("mp6", mp6, mp6_visual, pin.SE3(np.eye(3), np.array([-1.0, 0, 0])),
                      np.zeros((2, 6)))]
    window = RecordingWindow()
    build_animation(Visualizer(window=window), arms, None, None, t)
    objects = {c["path"]: c["object"] for c in window.commands if c["type"] == "set_object"}

    shoulder = objects["/meshcat/arms/ur5/visuals/shoulder_link_0"]
    geometry = shoulder["geometries"][0]
    index = geometry["data"]["index"]
    assert index["type"] == "Uint16Array"
    n_index = len(index["array"].data) // 2
    groups = geometry["data"]["groups"]
    assert [g["materialIndex"] for g in groups] == [0, 1, 2]
    assert groups[0]["start"] == 0 and sum(g["count"] for g in groups) == n_index
    ends = [g["start"] + g["count"] for g in groups]
    assert ends[:-1] == [g["start"] for g in groups[1:]]  # contiguous
    assert shoulder["object"]["material"] == [m["uuid"] for m in shoulder["materials"]]
    # shoulder.dae's diffuse colours: verbindung 0.1784 grey, Scheibe 0.064 grey, blau
    # (0.3136, 0.4344, 0.512), times 255 and rounded
    assert sorted(m["color"] for m in shoulder["materials"]) == [0x101010, 0x2D2D2D, 0x506F83]

    for g in ur5.visual_model.geometryObjects:
        painted = objects[f"/meshcat/arms/painted/visuals/{g.name}"]
        assert [m["color"] for m in painted["materials"]] == [0x3399FF]
        assert "groups" not in painted["geometries"][0]["data"]
    for g in mp6_visual.geometryObjects:
        (material,) = objects[f"/meshcat/arms/mp6/visuals/{g.name}"]["materials"]
        np.testing.assert_allclose(_rgb(material["color"]), 255 * g.meshColor[:3], atol=1)


# ------------------------------------------------------------------ camera
MESHCAT_VIEWER = Path(meshcat.__file__).parent / "viewer"
FAR_BOX_CENTRE = np.array([2.0, 1.0, 1.2])  # content far from the world origin
FOV_DEG = 75.0  # the PerspectiveCamera of meshcat's create_camera


def _matrix(command) -> np.ndarray:
    """(4, 4) matrix of a recorded set_transform command (Meshcat sends it column-major)."""
    return np.array(command["matrix"], dtype=float).reshape(4, 4).T


def _rx(angle: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = pin.rpy.rpyToMatrix(angle, 0.0, 0.0)
    return T


def test_set_camera_puts_the_target_at_the_viewers_world_origin():
    # What the viewer does with these commands, read from meshcat's own source: the scene
    # root is rotated by Rx(-pi/2), the camera sits under /Cameras/default/rotated (rotated
    # by Rx(pi/2)), and OrbitControls calls camera.lookAt(target = three.js world origin).
    source = (MESHCAT_VIEWER / "src" / "index.js").read_text()
    assert "scene.rotateX(-Math.PI / 2);" in source
    assert "mat.makeRotationX(Math.PI / 2);" in source
    minified = (MESHCAT_VIEWER / "dist" / "main.min.js").read_text()
    assert "n.object.lookAt(n.target)" in minified and "set_target" not in minified

    rng = np.random.default_rng(3)
    target = rng.uniform(-3, 3, 3)
    eye = target + rng.uniform(-2, 2, 3)
    window = RecordingWindow()
    set_camera(Visualizer(window=window), target, eye)
    by_path = {(c["type"], c["path"]): c for c in window.commands}
    root = _matrix(by_path["set_transform", "/"])
    cameras = _matrix(by_path["set_transform", "/Cameras/default"])
    local = np.append(by_path["set_property", "/Cameras/default/rotated/<object>"]["value"], 1)

    # The root keeps the viewer's own z-up rotation; the target becomes the world origin.
    np.testing.assert_allclose(root[:3, :3], _rx(-np.pi / 2)[:3, :3], atol=1e-15)
    np.testing.assert_allclose(root @ np.append(target, 1), [0, 0, 0, 1], atol=1e-12)
    # The camera is at the eye: the same three.js world point as the eye in the scene.
    chain = root @ cameras @ _rx(np.pi / 2)
    np.testing.assert_allclose(chain @ local, root @ np.append(eye, 1), atol=1e-12)
    # Its parent frame is three.js's world frame, as in meshcat's default set-up
    # (identity root-to-camera chain there too), so orbiting and zooming act about target.
    np.testing.assert_allclose(chain, np.eye(4), atol=1e-12)
    default = _rx(-np.pi / 2) @ np.eye(4) @ _rx(np.pi / 2)
    np.testing.assert_allclose(default, np.eye(4), atol=1e-15)


def test_set_camera_rejects_bad_points():
    vis = Visualizer(window=RecordingWindow())
    with pytest.raises(InputError, match="different from the target"):
        set_camera(vis, [1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
    with pytest.raises(InputError, match=r"camera target \[m\]"):
        set_camera(vis, [1.0, 2.0], [0.0, 0.0, 0.0])
    with pytest.raises(InputError, match=r"camera eye \[m\]"):
        set_camera(vis, [1.0, 2.0, 3.0], [[0.0, 0.0, 0.0]])


def test_framing_centres_on_content_not_on_the_world_origin():
    # A box far from the origin: the camera's target is the box's centre.
    obj = _far_box()
    window = RecordingWindow()
    build_animation(Visualizer(window=window), [], obj, None, [0.0, 0.1])
    root = [_matrix(c) for c in window.commands
            if c["type"] == "set_transform" and c["path"] == "/"]
    assert len(root) == 1
    np.testing.assert_allclose(root[0] @ np.append(FAR_BOX_CENTRE, 1), [0, 0, 0, 1],
                               atol=1e-12)


def _far_box() -> ReplayObject:
    return ReplayObject(box([0.3, 0.3, 0.3]), np.tile(FAR_BOX_CENTRE, (2, 1)),
                        np.tile([0.0, 0.0, 0.0, 1.0], (2, 1)))


# ------------------------------------------------------------------ bad input
def test_bad_input_raises_clear_errors(ur5, tmp_path):
    arms, obj, contacts, t = _two_ur5_scene(ur5)
    vis = Visualizer(window=RecordingWindow())
    with pytest.raises(InputError, match=r"q \(T, nq\).*shape \(n, 6\)"):
        ReplayArm("a", ur5.model, None, pin.SE3.Identity(), np.zeros((4, 5)))
    with pytest.raises(InputError, match="without '/'"):
        ReplayArm("a/b", ur5.model, None, pin.SE3.Identity(), np.zeros((4, 6)))
    with pytest.raises(InputError, match="base_placement must be a pin.SE3"):
        ReplayArm("a", ur5.model, None, np.eye(4), np.zeros((4, 6)))
    with pytest.raises(InputError, match=r"RGBA values in \[0, 1\]"):
        ReplayArm("a", ur5.model, None, pin.SE3.Identity(), np.zeros((4, 6)), color=(2, 0, 0, 1))
    with pytest.raises(InputError, match="row 1 has norm 2"):
        ReplayObject(box([1, 1, 1]), np.zeros((2, 3)), [[0, 0, 0, 1], [0, 0, 0, 2]])
    with pytest.raises(InputError, match=r"quaternion \(T, 4\)"):
        ReplayObject(box([1, 1, 1]), np.zeros((2, 3)), np.zeros((3, 4)))
    with pytest.raises(InputError, match=r"forces \(T, K, 3\)"):
        ReplayContacts(np.zeros((2, 1, 3)), np.zeros((2, 2, 3)))
    with pytest.raises(InputError, match="strictly increasing"):
        build_animation(vis, arms, obj, contacts, t[::-1])
    with pytest.raises(InputError, match="q has 401 rows, t has 400 samples"):
        build_animation(vis, arms, None, None, t[:-1])
    with pytest.raises(InputError, match="duplicate arm name 'left'"):
        build_animation(vis, [arms[0], arms[0]], None, None, t)
    with pytest.raises(InputError, match="fps"):
        build_animation(vis, arms, obj, contacts, t, fps=0)
    with pytest.raises(InputError, match="force_scale"):
        build_animation(vis, arms, obj, contacts, t, force_scale=-1.0)
    with pytest.raises(InputError, match="list of ReplayArm"):
        build_animation(vis, arms[0], obj, contacts, t)
    with pytest.raises(InputError, match="does not exist"):
        write_replay_html(tmp_path / "missing" / "x.html", arms, obj, t)


# ------------------------------------------------------------------ pages
def _assert_offline(html: str):
    assert "<script" in html
    assert not re.search(r"<script[^>]*\bsrc\s*=", html, re.I), "page loads an external script"
    assert not re.search(r"""\b(src|href)\s*=\s*["']?(https?:)?//""", html, re.I)
    assert not re.search(r"""(import|fetch)\s*\(\s*["']https?://""", html)


def test_write_replay_html_two_ur5_and_a_box(ur5, tmp_path):
    arms, obj, contacts, t = _two_ur5_scene(ur5)
    path = write_replay_html(tmp_path / "replay.html", arms, obj, t, contacts=contacts)
    html = path.read_text()
    _assert_offline(html)
    size = path.stat().st_size
    empty = write_replay_html(tmp_path / "empty.html", [], None, t).stat().st_size
    # the meshes of one UR5 are in the page once (two arms), compactly (quantised, deflated)
    assert 3e5 < size - empty < 8e5, size - empty
    assert "MeshCat.Viewer" in html


def test_write_replay_html_panda_and_mp6(tmp_path):
    panda = erd.load("panda")
    model, visual = pin.buildModelsFromUrdf(str(MP6), str(MP6.parent),
                                            geometry_types=pin.GeometryType.VISUAL)
    t = np.linspace(0, 1, 11)
    arms = [
        ReplayArm("panda", panda.model, panda.visual_model, pin.SE3.Identity(),
                  np.tile(panda.q0, (11, 1))),
        ReplayArm("mp6", model, visual, pin.SE3(np.eye(3), np.array([1.5, 0, 0])),
                  np.zeros((11, 6))),
    ]
    path = write_replay_html(tmp_path / "mixed.html", arms, None, t)
    _assert_offline(path.read_text())


# ------------------------------------------------------------------ browser
def _screenshot(page: Path | str, png: Path) -> np.ndarray:
    """(768, 1024, 3) RGB screenshot of an HTML file or of a URL (str)."""
    url = page if isinstance(page, str) else page_url(page)
    return screenshot(url, png, size=(1024, 768))


def _object_pixels(img: np.ndarray) -> int:
    """Pixels of the red object over the blue sky: red clearly above green and blue."""
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return int(np.sum((r > g + 40) & (r > b + 15)))


LIGHT_GREY = (0.9, 0.9, 0.9, 1.0)


def _arm_pixels(img: np.ndarray) -> int:
    """Pixels of the light-grey UR5 meshes: bright and unsaturated (the sky is saturated)."""
    return int(np.sum((img.min(axis=2) > 150) & (img.max(axis=2) - img.min(axis=2) < 40)))


@needs_chromium
def test_page_renders_arms_and_object_in_headless_chromium(ur5, tmp_path):
    # Light-grey arms (Pinocchio's default meshColor, the UR5's look before its COLLADA
    # materials were used), which _arm_pixels tells from the sky; the UR5's own dark and
    # blue colours are checked by test_page_shows_the_ur5_in_its_material_colours.
    arms, obj, contacts, t = _two_ur5_scene(ur5, color=LIGHT_GREY)
    scene = write_replay_html(tmp_path / "scene.html", arms, obj, t, contacts=contacts)
    empty = write_replay_html(tmp_path / "empty.html", [], None, t)
    img = _screenshot(scene, tmp_path / "scene.png")
    ref = _screenshot(empty, tmp_path / "empty.png")
    assert img.shape == ref.shape == (768, 1024, 3)
    differ = np.any(np.abs(img - ref) > 30, axis=2).mean()
    assert differ > 0.03, f"only {differ:.1%} of the pixels differ from an empty scene"
    # The empty scene has a few such pixels too (the red x axis, the grid): count the excess.
    assert _object_pixels(img) - _object_pixels(ref) > 5000
    assert _arm_pixels(img) - _arm_pixels(ref) > 5000


UR5_CAMERA_TARGET = np.array([0.2, 0.1, 0.35])
UR5_CAMERA_EYE = UR5_CAMERA_TARGET + np.array([0.55, -0.8, 0.35])


def _ur5_screenshot(tmp_path: Path, name: str, arms) -> np.ndarray:
    """Screenshot of a page with ``arms`` at rest, seen by one fixed camera."""
    with contextlib.redirect_stdout(io.StringIO()):
        vis = Visualizer()
    try:
        build_animation(vis, arms, None, None, [0.0, 0.1])
        set_camera(vis, UR5_CAMERA_TARGET, UR5_CAMERA_EYE)
        html = vis.static_html()
    finally:
        close_visualizer(vis)
    page = tmp_path / f"{name}.html"
    page.write_text(html, encoding="utf-8")
    return _screenshot(page, tmp_path / f"{name}.png")


def _blue_pixels(img: np.ndarray, mask: np.ndarray) -> int:
    """Pixels in ``mask`` with chroma max - min > 40 whose strongest channel is blue."""
    chroma = img.max(axis=2) - img.min(axis=2)
    return int(np.sum(mask & (chroma > 40) & (img[..., 2] == img.max(axis=2))))


@needs_chromium
def test_page_shows_the_ur5_in_its_material_colours(ur5, tmp_path):
    """One UR5 in its COLLADA colours against the same UR5 in light grey, same camera.

    The arm's pixels are those where both pages differ from the page without the arm
    (the sky is blue, so colour is only looked for there). The UR5's caps are blue
    (0.3136, 0.4344, 0.512): measured (Chromium 1xx, SwiftShader, 1024 x 768) 3021 blue
    pixels of chroma > 40 on the coloured arm's 30056 pixels against 276 on the grey arm
    (anti-aliased edges over the sky); at least 1000 more are required.
    """
    q = np.tile([0.0, -1.2, 1.6, -1.9, -1.57, 0.0], (2, 1))

    def arm(color):
        return [ReplayArm("ur5", ur5.model, ur5.visual_model, pin.SE3.Identity(), q, color)]

    empty = _ur5_screenshot(tmp_path, "empty", [])
    grey = _ur5_screenshot(tmp_path, "grey", arm(LIGHT_GREY))
    coloured = _ur5_screenshot(tmp_path, "coloured", arm(None))
    grey_arm = np.any(np.abs(grey - empty) > 30, axis=2)
    coloured_arm = np.any(np.abs(coloured - empty) > 30, axis=2)
    assert _arm_pixels(grey) - _arm_pixels(empty) > 15000  # the grey arm fills the view
    # the same arm at the same place (dark parts over the dark sky blur the edge a little)
    assert np.sum(grey_arm ^ coloured_arm) < 0.06 * np.sum(grey_arm)
    region = grey_arm & coloured_arm
    blue, blue_in_grey = _blue_pixels(coloured, region), _blue_pixels(grey, region)
    assert blue - blue_in_grey > 1000, (blue, blue_in_grey, int(region.sum()))


def _red_centroid(img: np.ndarray) -> tuple[int, np.ndarray]:
    """(count, (2,) centroid [x, y] in pixels) of the red object's pixels."""
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    ys, xs = np.nonzero((r > g + 40) & (r > b + 15))
    return len(xs), np.array([xs.mean(), ys.mean()]) if len(xs) else np.full(2, np.nan)


def _project(point, eye, target, width=1024, height=768) -> np.ndarray:
    """(2,) pixel [x, y] of a world point for a pinhole camera at eye looking at target,
    world z up on screen, three.js's PerspectiveCamera (vertical fov FOV_DEG)."""
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    p = np.asarray(point) - eye
    depth = p @ forward
    t = np.tan(np.radians(FOV_DEG) / 2)
    x = (p @ right) / depth / (t * width / height)
    y = (p @ up) / depth / t
    return np.array([width / 2 * (1 + x), height / 2 * (1 - y)])


@needs_chromium
def test_page_centres_content_far_from_the_origin(tmp_path):
    page = write_replay_html(tmp_path / "far.html", [], _far_box(), [0.0, 0.1])
    img = _screenshot(page, tmp_path / "far.png")
    count, centroid = _red_centroid(img)
    assert count > 5000, f"the box covers only {count} pixels"
    centre = np.array([img.shape[1], img.shape[0]]) / 2
    # Meshcat 0.3.2 used to keep looking at the world origin: the box was at the right
    # edge, about 45 % of the width away from the centre.
    offset = np.linalg.norm(centroid - centre) / img.shape[1]
    assert offset < 0.05, f"box centroid {centroid} is {offset:.1%} of the width off-centre"


@needs_chromium
@pytest.mark.parametrize(("shift", "view"), [([0.5, -0.2, -0.45], [1.2, -1.8, 0.7]),
                                              ([-0.3, 0.4, 0.3], [-1.5, -1.0, 1.2])])
def test_camera_view_matches_a_pinhole_projection(tmp_path, shift, view):
    # The target is not the box: the box must appear where a pinhole camera at the eye,
    # looking at the target with z up, sees it (checks eye, target and up together).
    target = FAR_BOX_CENTRE + np.array(shift)
    eye = target + np.array(view)
    with contextlib.redirect_stdout(io.StringIO()):
        vis = Visualizer()
    try:
        build_animation(vis, [], _far_box(), None, [0.0, 0.1])
        set_camera(vis, target, eye)
        html = vis.static_html()
    finally:
        close_visualizer(vis)
    page = tmp_path / "pinhole.html"
    page.write_text(html, encoding="utf-8")
    img = _screenshot(page, tmp_path / "pinhole.png")
    count, centroid = _red_centroid(img)
    assert count > 2000, f"the box covers only {count} pixels"
    expected = _project(FAR_BOX_CENTRE, eye, target)
    centre = np.array([img.shape[1], img.shape[0]]) / 2
    assert np.linalg.norm(expected - centre) > 100  # the test is not the centring test
    error = np.linalg.norm(centroid - expected)
    assert error < 15, f"box centroid {centroid}, pinhole projection {expected}"


# ------------------------------------------------------------------ live server
def test_serve_replay_answers_http_and_closes(ur5):
    arms, obj, contacts, t = _two_ur5_scene(ur5)
    url, vis = serve_replay(arms[:1], obj, t, contacts=None, fps=10)
    try:
        assert url.startswith("http://127.0.0.1:")
        with urllib.request.urlopen(url, timeout=10) as response:
            assert response.status == 200
            assert b"meshcat" in response.read().lower()
    finally:
        close_visualizer(vis)
    assert vis.window.server_proc.poll() is not None


@needs_chromium
def test_live_viewer_centres_content_far_from_the_origin(tmp_path):
    url, vis = serve_replay([], _far_box(), [0.0, 0.1])
    try:
        img = _screenshot(url, tmp_path / "live.png")
    finally:
        close_visualizer(vis)
    count, centroid = _red_centroid(img)
    assert count > 5000, f"the box covers only {count} pixels"
    centre = np.array([img.shape[1], img.shape[0]]) / 2
    offset = np.linalg.norm(centroid - centre) / img.shape[1]
    assert offset < 0.05, f"box centroid {centroid} is {offset:.1%} of the width off-centre"


def test_rotation_to_quaternion_roundtrip_used_by_tests():
    # guards the helper the tests above rely on to read Meshcat's [x, y, z, w] tracks
    R = pin.rpy.rpyToMatrix(0.3, -0.2, 1.1)
    np.testing.assert_allclose(quaternion_to_rotation(rotation_to_quaternion(R)), R, atol=1e-12)


# ------------------------------------------------------------------ contact states, supports
def test_contact_state_switches_spheres_and_supports_are_drawn():
    """A contact that separates: its yellow sphere shrinks to nothing and a grey one appears.

    Two contacts over 1 s at 10 fps; contact 1 touches for t < 0.5 s only. The scale tracks
    of ``contacts/point_1`` and ``contacts/free_1`` are 1 / ~0 before and ~0 / 1 after;
    contact 0 stays touching. A support slab's top face lies on its plane: its centre is
    half a thickness below the given centre along the normal, its z axis along the normal.
    """
    from multiarm_pin.app.replay import SUPPORT_THICKNESS, ReplaySupport

    t = np.linspace(0.0, 1.0, 11)
    points = np.zeros((11, 2, 3))
    points[:, 1] = [0.1, 0.0, 0.0]
    touching = np.ones((11, 2), dtype=bool)
    touching[t >= 0.5, 1] = False
    n = np.array([0.0, 0.6, 0.8])
    contacts = ReplayContacts(points, np.zeros_like(points), touching,
                              [ReplaySupport("table", [0.2, 0.0, 0.0], n, 0.3)])
    window = RecordingWindow()
    vis = Visualizer(window=window)
    anim = build_animation(vis, [], None, contacts, t, fps=10)
    _, on = _track(anim, "contacts/point_1", "scale")
    _, off = _track(anim, "contacts/free_1", "scale")
    on, off = np.reshape(on, (-1, 3))[:, 0], np.reshape(off, (-1, 3))[:, 0]
    np.testing.assert_array_equal(on > 0.5, t < 0.5)
    np.testing.assert_array_equal(off > 0.5, t >= 0.5)
    _, on0 = _track(anim, "contacts/point_0", "scale")
    assert np.all(np.asarray(on0) == 1.0)
    slab = [c for c in window.commands if "supports/table" in str(c)]
    assert slab, "the support slab is sent to the viewer"
    T = _slab_pose(window)
    np.testing.assert_allclose(T[:3, 3], [0.2, 0.0, 0.0] - 0.5 * SUPPORT_THICKNESS * n,
                               atol=1e-12)
    np.testing.assert_allclose(T[:3, 2], n, atol=1e-12)
    with pytest.raises(InputError, match="touching"):
        ReplayContacts(points, np.zeros_like(points), touching[:, :1])


def _slab_pose(window) -> np.ndarray:
    """The 4 x 4 transform last set on ``supports/table`` (column-major in the command)."""
    for c in reversed(window.commands):
        if isinstance(c, dict) and c.get("path", "").endswith("supports/table") \
                and c.get("type") == "set_transform":
            return np.array(c["matrix"]).reshape(4, 4).T
    raise AssertionError("no set_transform on supports/table")


def test_a_finite_support_is_drawn_as_its_rectangle():
    """A support with an extent: a slab of its sides ``lx x ly``, x along its ``x_axis``.

    The trajectory arrays of a run carry each support's extent and x axis
    (``support_extents``, ``support_x_axes``); :func:`replay_parts` makes the rectangle of
    them, centred at the plane point; the slab's pose has the columns ``x_axis``,
    ``n × x_axis``, ``n`` and its box the sides ``[lx, ly, thickness]``.
    """
    from multiarm_pin.app.replay import SUPPORT_THICKNESS
    from multiarm_pin.app.run_results import replay_parts, system_trajectory_arrays
    from multiarm_pin.constraints import Support
    from multiarm_pin.model.rigid_object import RigidObject
    from multiarm_pin.sim.simulation import simulate
    from multiarm_pin.system import MultiArmSystem

    box = RigidObject.box([0.4, 0.3, 0.2], 2.0)
    x_axis = np.array([0.6, 0.8, 0.0])
    table = Support("table", [0.1, 0.0, 0.0], [0, 0, 1], box.shape.vertices, extent=[1.2, 0.5],
                    x_axis=x_axis)
    system = MultiArmSystem([], box, [], supports=[table])
    r = simulate(system, system.state(np.zeros(0), None, [0.1, 0.0, 0.1]), None, 0.01, 0.01)
    traj = system_trajectory_arrays(system, r)
    np.testing.assert_array_equal(traj["support_extents"], [[1.2, 0.5]])
    np.testing.assert_array_equal(traj["support_x_axes"], [x_axis])
    _, _, contacts = replay_parts([], box, traj)
    sp = contacts.supports[0]
    np.testing.assert_array_equal(sp.center, [0.1, 0.0, 0.0])
    window = RecordingWindow()
    build_animation(Visualizer(window=window), [], None, contacts, r.t, fps=10)
    T = _slab_pose(window)
    np.testing.assert_allclose(T[:3, :3], np.column_stack([x_axis, [-0.8, 0.6, 0.0],
                                                           [0, 0, 1]]), atol=1e-12)
    np.testing.assert_allclose(T[:3, 3], [0.1, 0.0, -0.5 * SUPPORT_THICKNESS], atol=1e-12)
    geometry = [c["object"]["geometries"][0] for c in window.commands
                if isinstance(c, dict) and c.get("type") == "set_object"
                and c.get("path", "").endswith("supports/table")]
    assert geometry, "the support slab is sent to the viewer"
    g = geometry[-1]
    np.testing.assert_allclose([g["width"], g["height"], g["depth"]],
                               [1.2, 0.5, SUPPORT_THICKNESS])


# ------------------------------------------------------------------ compact tracks (issue 25)
def test_compact_track_sends_float32_keys_without_the_inside_of_constant_runs():
    """The viewer interpolates linearly between the keys it gets: at every frame that gives
    the full track's float32 values exactly (dropped keys are inside runs of equal values)."""
    import umsgpack

    from multiarm_pin.app.replay import CompactTrack

    rng = np.random.default_rng(2)
    values = rng.normal(size=(40, 3))
    values[5:15] = values[5]  # a run: keys 6..13 dropped
    values[20:22] = values[20]  # two equal frames: both kept (ends of the run)
    values[30:] = values[30]  # a run to the end
    track = CompactTrack("position", "vector3", list(range(40)), values)
    lowered = track.lower()
    assert lowered["name"] == ".position" and lowered["type"] == "vector3"
    assert "keys" not in lowered
    times = np.frombuffer(lowered["times"].data, np.float32)
    kept = np.frombuffer(lowered["values"].data, np.float32).reshape(-1, 3)
    assert isinstance(lowered["times"], umsgpack.Ext) and lowered["times"].type == 0x17
    expected = [f for f in range(40) if not (6 <= f <= 13 or 31 <= f <= 38)]
    assert times.tolist() == expected
    replayed = np.column_stack([np.interp(np.arange(40), times, kept[:, j]) for j in range(3)])
    np.testing.assert_array_equal(replayed.astype(np.float32), values.astype(np.float32))
    short = CompactTrack("scale", "vector3", [0, 1], np.ones((2, 3))).lower()
    assert np.frombuffer(short["times"].data, np.float32).tolist() == [0.0, 1.0]


def test_supports_get_their_own_colours():
    from multiarm_pin.app.replay import SUPPORT_COLORS, ReplaySupport

    t = np.linspace(0.0, 1.0, 3)
    contacts = ReplayContacts(np.zeros((3, 2, 3)), np.zeros((3, 2, 3)), supports=[
        ReplaySupport("floor", [0, 0, 0], [0, 0, 1], 1.0),
        ReplaySupport("wall", [1, 0, 0], [-1, 0, 0], 1.0)])
    window = RecordingWindow()
    build_animation(Visualizer(window=window), [], None, contacts, t)
    colours = {c["path"].split("/")[-1]: c["object"]["materials"][0]["color"]
               for c in window.commands if c["type"] == "set_object"
               and "/supports/" in c["path"]}
    assert colours == {"floor": SUPPORT_COLORS[0], "wall": SUPPORT_COLORS[1]}


def test_colliding_links_are_drawn_red_while_they_collide(ur5):
    """A link's red copy is shown (its own geometry scaled to nothing) exactly at the frames
    of its collision samples; the other links have no copy."""
    from multiarm_pin.app.replay import COLLIDING_COLOR

    arms, obj, contacts, t = _two_ur5_scene(ur5)
    mask = (t >= 0.5) & (t <= 1.2)
    arms[0] = ReplayArm(arms[0].name, arms[0].model, arms[0].visual_model,
                        arms[0].base_placement, arms[0].q, colliding={"forearm_link": mask})
    window = RecordingWindow()
    vis = Visualizer(window=window)
    fps = 10
    anim = build_animation(vis, arms, obj, contacts, t, fps=fps)
    idx = frame_indices(t, fps)
    model = ur5.model
    forearm = [g.name for g in ur5.visual_model.geometryObjects
               if model.frames[g.parentFrame].name == "forearm_link"]
    paths = [p.lower() for p in anim.clips]
    copies = [p.split("/colliding/visuals/")[1] for p in paths if "/colliding/" in p]
    assert forearm and sorted(copies) == sorted(n.lower() for n in forearm)
    for name in forearm:
        _, red = _track(anim, f"arms/left/colliding/visuals/{name}", "scale")
        _, own = _track(anim, f"arms/left/visuals/{name}", "scale")
        red, own = np.reshape(red, (-1, 3))[:, 0], np.reshape(own, (-1, 3))[:, 0]
        np.testing.assert_array_equal(red > 0.5, mask[idx])
        np.testing.assert_array_equal(own > 0.5, ~mask[idx])
        _, p_red = _track(anim, f"arms/left/colliding/visuals/{name}", "position")
        _, p_own = _track(anim, f"arms/left/visuals/{name}", "position")
        np.testing.assert_array_equal(p_red, p_own)  # drawn where the link is
    red = (round(255 * COLLIDING_COLOR[0]) << 16) | (round(255 * COLLIDING_COLOR[1]) << 8) \
        | round(255 * COLLIDING_COLOR[2])
    sent = [c for c in window.commands if c["type"] == "set_object"
            and "/colliding/" in c["path"]]
    assert len(sent) == len(forearm)
    for c in sent:  # one material, the colliding colour
        assert [m["color"] for m in c["object"]["materials"]] == [red]
    assert not any("/colliding/" in p for p in paths if "/right/" in p)
