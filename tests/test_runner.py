"""The run/replay commands: output files, their content, the replay page and server."""

import io
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from multiarm_pin import cli
from multiarm_pin.exceptions import InputError, ScenarioError
from multiarm_pin.replay import close_visualizer, write_replay_html
from multiarm_pin.runner import ProgressBar, http_status, load_run, run_scenario, serve_run

REPO = Path(__file__).resolve().parent.parent
DEFAULT = REPO / "scenarios" / "two_ur5_box.yaml"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "demo"
    code = cli.main(["run", str(DEFAULT), "--out", str(out), "--duration", "0.2", "--quiet"])
    assert code == 0
    return out


def test_run_prints_where_results_are(tmp_path, capsys):
    out = tmp_path / "r"
    assert cli.main(["run", str(DEFAULT), "--out", str(out), "--duration", "0.02",
                     "--quiet", "--no-html"]) == 0
    text = capsys.readouterr().out
    assert f"results: {out.resolve()}" in text
    assert "multiarm-pin replay" in text and "trajectory.npz" in text


def test_trajectory_keys_and_shapes(run_dir):
    with np.load(run_dir / "trajectory.npz") as z:
        d = {k: z[k] for k in z.files}
    T = len(d["t"])
    assert T == 101  # 0.2 s at dt = 0.002
    assert d["object_position"].shape == (T, 3)
    assert d["object_quaternion"].shape == (T, 4)
    assert np.allclose(np.linalg.norm(d["object_quaternion"], axis=1), 1.0, atol=1e-12)
    assert d["object_twist"].shape == (T, 6)
    assert d["constraint_violation"].shape == (T,)
    for arm in ("left", "right"):
        assert d[f"q_{arm}"].shape == (T, 6)
        assert d[f"v_{arm}"].shape == (T, 6)
        assert d[f"tau_{arm}"].shape == (T, 6)
        assert d[f"mu_{arm}"].shape == (T, 6)  # a weld: 6 contacts
    # constraint_violation is max |phi| over all contacts (recomputed from phi_A)
    phi = np.concatenate([np.abs(d["phi_left"]), np.abs(d["phi_right"])], axis=1)
    assert np.allclose(d["constraint_violation"], phi.max(axis=1))
    # contact forces on the object are the multipliers along the push directions: their sum
    # plus gravity accelerates the object (Newton, from the saved arrays alone)
    f = d["contact_forces"].sum(axis=1)
    a = np.gradient(d["object_twist"][:, :3], d["t"], axis=0)
    m = 4.0
    resid = m * a[2:-2] - (f[2:-2] + m * np.array([0, 0, -9.81]))
    assert np.abs(resid).max() < 1e-2 * (np.abs(f).max() + m * 9.81)


def test_summary(run_dir):
    s = json.loads((run_dir / "summary.json").read_text())
    assert s["scenario"] == "two_ur5_box"
    assert s["solver"] == "object_first" and s["steps"] == 100
    assert s["wall_time"] > 0 and s["finite"]
    assert 0 <= s["max_constraint_violation"] < 1e-6
    assert isinstance(s["warnings"], list)
    assert s["min_contact_force"] <= s["max_contact_force"]
    assert [a["q0_from"] for a in s["arms"]] == ["inverse kinematics"] * 2
    for f in ("trajectory.npz", "summary.json", "replay.html", "scenario.yaml",
              "object_pose.png", "contact_forces.png", "constraint_violation.png"):
        assert (run_dir / f).is_file(), f


def test_plots_are_png_images(run_dir):
    from PIL import Image

    for f in ("object_pose.png", "contact_forces.png", "constraint_violation.png"):
        img = np.asarray(Image.open(run_dir / f).convert("L"))
        assert img.shape[0] > 200 and img.shape[1] > 300
        assert img.std() > 5  # not a blank image


def test_scenario_copy_rebuilds(run_dir):
    sc, traj, summary = load_run(run_dir)
    assert sc.name == "two_ur5_box" and [a.name for a in sc.arms] == ["left", "right"]
    assert summary["scenario"] == "two_ur5_box"
    with pytest.raises(InputError, match="not a results folder"):
        load_run(run_dir / "nope")


def test_replay_page_is_self_contained(run_dir):
    html = (run_dir / "replay.html").read_text()
    assert "<script" in html and "animation" in html.lower()
    # offline: nothing is fetched from the network
    for ref in ('src="http', "src='http", 'href="http', "href='http"):
        assert ref not in html, ref
    assert len(html) > 100_000  # three.js and the UR5 meshes are inlined


def test_replay_server_answers(run_dir):
    url, vis = serve_run(run_dir, fps=10)
    try:
        assert url.startswith("http://127.0.0.1:")
        assert http_status(url) == 200
    finally:
        close_visualizer(vis)


def test_replay_command_no_block(run_dir, capsys):
    assert cli.main(["replay", str(run_dir), "--no-block", "--fps", "10"]) == 0
    text = capsys.readouterr().out
    assert "served at http://127.0.0.1:" in text and "HTTP 200" in text


def test_bad_overrides(tmp_path):
    with pytest.raises(ScenarioError, match="did you mean 'dense_kkt'"):
        run_scenario(DEFAULT, tmp_path, solver="dense_kt", html=False)
    with pytest.raises(ScenarioError, match="positive duration"):
        run_scenario(DEFAULT, tmp_path, duration=-1.0, html=False)
    assert cli.main(["run", str(tmp_path / "missing.yaml"), "--out", str(tmp_path)]) == 2


def test_progress_bar_draws_and_ends_line():
    buf = io.StringIO()
    bar = ProgressBar("x", 2.0, stream=buf, delay=0.0, min_interval=0.0)
    bar(0.5)
    bar(1.0)
    bar.close()
    text = buf.getvalue()
    assert "50.0%" in text and "100.0%" in text and text.endswith("\n")
    assert "t = 1.000/2.000 s" in text
    quiet = io.StringIO()
    short = ProgressBar("x", 1.0, stream=quiet, delay=100.0)
    short(0.5)
    short.close()
    assert quiet.getvalue() == ""


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_progress_bar_redraws_on_a_terminal_and_logs_tenths_elsewhere():
    tty = _Terminal()
    bar = ProgressBar("x", 1.0, stream=tty, delay=0.0, min_interval=0.0)
    for k in range(1, 101):
        bar(k / 100)
    bar.close()
    text = tty.getvalue()
    assert text.count("\r") == 100 and text.endswith("\n") and text.count("\n") == 1
    log = io.StringIO()  # not a terminal: one line per tenth, no carriage returns
    bar = ProgressBar("x", 1.0, stream=log, delay=0.0, min_interval=0.0)
    for k in range(1, 101):
        bar(k / 100)
    bar.close()
    lines = log.getvalue().splitlines()
    assert "\r" not in log.getvalue() and len(lines) == 10
    assert lines[0].startswith("x [###") and "10.0%" in lines[0] and "100.0%" in lines[-1]


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (make browser)")
def test_replay_page_renders_in_headless_chromium(run_dir, tmp_path):
    from PIL import Image

    def shot(html, name):
        png = tmp_path / f"{name}.png"
        subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--use-angle=swiftshader",
                        "--enable-unsafe-swiftshader", "--disable-background-networking",
                        "--no-first-run", f"--user-data-dir={tmp_path / name}",
                        "--window-size=1024,768", "--virtual-time-budget=15000",
                        f"--screenshot={png}", f"file://{html}"],
                       check=True, capture_output=True, timeout=180)
        return np.asarray(Image.open(png).convert("RGB"), dtype=int)

    img = shot(run_dir / "replay.html", "scene")
    empty = shot(write_replay_html(tmp_path / "empty.html", [], None, [0.0, 0.1]), "empty")
    assert img.shape == empty.shape == (768, 1024, 3)
    differ = np.any(np.abs(img - empty) > 30, axis=2).mean()
    assert differ > 0.03, f"only {differ:.1%} of the pixels differ from an empty scene"
    red = lambda im: int(np.sum((im[..., 0] > im[..., 1] + 40) & (im[..., 0] > im[..., 2] + 15)))  # noqa: E731
    assert red(img) - red(empty) > 3000  # the red box is in view
