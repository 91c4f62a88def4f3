"""The run/replay commands: output files, their content, the replay page and server."""

import io
import json
import os
import signal
from pathlib import Path

import numpy as np
import pytest
from browser_helpers import needs_chromium, page_url, screenshot
from run_helpers import Q0_UR5, one_arm_scenario, write

from multiarm_pin.app import cli
from multiarm_pin.app.replay import close_visualizer, write_replay_html
from multiarm_pin.app.runner import ProgressBar, http_status, load_run, run_scenario, serve_run
from multiarm_pin.exceptions import InputError, ScenarioError

REPO = Path(__file__).resolve().parent.parent
DEFAULT = REPO / "scenarios" / "two_ur5_box.yaml"


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
    # each arm's wrench: its forces add up to the contacts' (the moments are tested against
    # W_o mu in test_arm_wrench); the UR5's URDF effort limits beside the torques
    w = d["arm_wrench"]
    assert w.shape == (len(d["t"]), 2, 6)
    assert np.abs(w[:, :, :3].sum(axis=1) - f).max() < 1e-9 * np.abs(f).max()
    assert d["tau_limit_left"].tolist() == [150.0, 150.0, 150.0, 28.0, 28.0, 28.0]
    assert "tau_commanded_left" not in d and d["unilateral_arms"].tolist() == []


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
              "object_pose.png", "arm_wrenches.png", "joint_torques.png",
              "constraint_violation.png"):
        assert (run_dir / f).is_file(), f
    assert not (run_dir / "contact_forces.png").exists()  # welds: their wrench says it


def test_plots_are_png_images(run_dir):
    from PIL import Image

    for f in ("object_pose.png", "arm_wrenches.png", "joint_torques.png",
              "constraint_violation.png"):
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


def test_a_solver_that_cannot_serve_the_rows_is_bad_input_naming_the_key(tmp_path):
    """grasp_failure's fingertips are unilateral: dense_kkt (equalities only) is refused."""
    with pytest.raises(ScenarioError, match="cannot serve the unilateral rows") as info:
        run_scenario(REPO / "scenarios" / "grasp_failure.yaml", tmp_path, solver="dense_kkt",
                     html=False, plots=False)
    assert info.value.key == "--solver" and "'dense_kkt'" in str(info.value)
    assert not list(tmp_path.iterdir())  # nothing written


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


@needs_chromium
def test_replay_page_renders_in_headless_chromium(run_dir, tmp_path):
    def shot(html, name):
        return screenshot(page_url(html), tmp_path / f"{name}.png", size=(1024, 768))

    img = shot(run_dir / "replay.html", "scene")
    empty = shot(write_replay_html(tmp_path / "empty.html", [], None, [0.0, 0.1]), "empty")
    assert img.shape == empty.shape == (768, 1024, 3)
    differ = np.any(np.abs(img - empty) > 30, axis=2).mean()
    assert differ > 0.03, f"only {differ:.1%} of the pixels differ from an empty scene"
    red = lambda im: int(np.sum((im[..., 0] > im[..., 1] + 40) & (im[..., 0] > im[..., 2] + 15)))  # noqa: E731
    assert red(img) - red(empty) > 3000  # the red box is in view


# ----------------------------------------------------------------------------- issue 13
# Nothing lost, nothing mixed: results folders, partial runs, clear errors.
def _summary(folder: Path) -> dict:
    return json.loads((folder / "summary.json").read_text())


def test_out_holding_the_input_file_is_refused(tmp_path, monkeypatch, capsys):
    sc = write(tmp_path / "scenario.yaml", "# my comments\n" + one_arm_scenario())
    before = sc.read_bytes()
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", "scenario.yaml", "--out", ".", "--quiet", "--no-html"]) == 2
    assert "holds the scenario file" in capsys.readouterr().err
    assert sc.read_bytes() == before and sorted(os.listdir(tmp_path)) == ["scenario.yaml"]


def test_out_of_another_run_is_refused_then_replaced_whole(tmp_path, capsys):
    a = write(tmp_path / "a.yaml", one_arm_scenario("same_name"))
    b = write(tmp_path / "b.yaml", one_arm_scenario("same_name", mass=3.0))
    out = tmp_path / "out"
    fast = {"duration": 0.004, "html": False, "plots": False}
    run_scenario(a, out, **fast)
    old = _summary(out)
    # a replay page of an earlier run with html (written by hand: any stale file will do)
    (out / "replay.html").write_text("stale")
    # rerunning the same scenario file replaces its own results, whole
    run_scenario(a, out, **fast)
    assert not (out / "replay.html").exists()  # no stale file of the previous run
    (out / "replay.html").write_text("stale")
    capsys.readouterr()
    assert cli.main(["run", str(b), "--out", str(out), "--quiet", "--no-html"]) == 2
    err = capsys.readouterr().err
    assert "holds the results of another run" in err and "--overwrite" in err
    assert _summary(out)["scenario_file"] == old["scenario_file"]
    assert (out / "replay.html").read_text() == "stale"  # refused: untouched
    assert cli.main(["run", str(b), "--out", str(out), "--quiet", "--no-html", "--duration",
                     "0.004", "--overwrite"]) == 0
    s = _summary(out)
    assert s["scenario_file"] == str(b) and s["status"] == "complete"
    assert not (out / "replay.html").exists()  # replaced whole: the old page is gone
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.yaml", "b.yaml", "out"]


def test_default_folder_is_a_safe_name_and_copies_do_not_mix(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    write(tmp_path / "esc.yaml", one_arm_scenario("../../escape"))
    assert cli.main(["run", "esc.yaml", "--quiet", "--no-html"]) == 0
    assert (tmp_path / "results" / "escape" / "summary.json").is_file()
    assert sorted(os.listdir(tmp_path)) == ["esc.yaml", "results"]
    # a copy-edited scenario with the same name does not overwrite the first one's results
    write(tmp_path / "esc2.yaml", one_arm_scenario("../../escape", mass=5.0))
    capsys.readouterr()
    assert cli.main(["run", "esc2.yaml", "--quiet", "--no-html"]) == 2
    assert "another run" in capsys.readouterr().err
    assert _summary(tmp_path / "results" / "escape")["scenario_file"].endswith("esc.yaml")


def test_output_checked_before_simulating(tmp_path, monkeypatch, capsys):
    import multiarm_pin.app.runner as runner

    def never(*args, **kwargs):
        raise AssertionError("the scenario was built before the output was checked")

    monkeypatch.setattr(runner, "build_scenario", never)
    sc = write(tmp_path / "s.yaml", one_arm_scenario())
    write(tmp_path / "file", "not a folder")
    assert cli.main(["run", str(sc), "--out", str(tmp_path / "file"), "--quiet"]) == 2
    assert "is an existing file" in capsys.readouterr().err
    assert cli.main(["run", str(sc), "--out", str(tmp_path / "file" / "x"), "--quiet"]) == 2
    assert "cannot create" in capsys.readouterr().err


def test_complete_run_status_and_tool_frames(tmp_path):
    sc = write(tmp_path / "s.yaml", one_arm_scenario(duration=0.01))
    res = run_scenario(sc, tmp_path / "out", html=False, plots=False)
    s = _summary(res.out_dir)
    assert s["status"] == "complete" and s["error"] is None
    assert s["t_end"] == pytest.approx(0.01, abs=1e-12)
    assert s["arms"][0]["tool_frame"] == "tool0"
    assert s["arms"][0]["tool_offset"]["quaternion"] == [0.0, 0.0, 0.0, 1.0]


def _nan_after(t_fail: float):
    """A scenario_controller replacement: gravity compensation, then NaN torques from t_fail."""
    import multiarm_pin.app.runner as runner

    real = runner.scenario_controller

    def make(built):
        inner = real(built)

        def controller(t, state, ev):
            tau = inner(t, state, ev)
            return tau * np.nan if t >= t_fail else tau

        return controller

    return make


def test_mid_run_failure_keeps_the_partial_trajectory(tmp_path, monkeypatch, capsys):
    import multiarm_pin.app.runner as runner

    monkeypatch.setattr(runner, "scenario_controller", _nan_after(0.0105))
    sc = write(tmp_path / "s.yaml", one_arm_scenario(duration=0.04))
    out = tmp_path / "out"
    assert cli.main(["run", str(sc), "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert str(sc) in err and "t = 0.011 s" in err and "NaN" in err  # file and time
    assert "partial results" in err and str(out) in err
    s = _summary(out)
    assert s["status"] == "failed" and "t = 0.011 s" in s["error"]
    # samples 0..0.010 were completed; the step from 0.010 to 0.012 failed at its stage 0.011
    assert s["t_end"] == pytest.approx(0.010, abs=1e-12)
    sc_copy, traj, summary = load_run(out)
    assert len(traj["t"]) == 6 and traj["t"][-1] == pytest.approx(0.010)
    assert np.all(np.isfinite(traj["q_a"]))
    assert (out / "replay.html").is_file()
    assert cli.main(["replay", str(out), "--no-block", "--fps", "10"]) == 0
    text = capsys.readouterr().out
    assert "partial run (failed at t = 0.01 s of 0.04 s)" in text and "HTTP 200" in text


def test_failure_before_the_first_sample_is_an_input_error(tmp_path):
    monkeypatch_free = write(tmp_path / "s.yaml", one_arm_scenario(
        joint="{type: spherical}", controller="{type: object_pd, kp: 10, kd: 5}"))
    with pytest.raises(ScenarioError, match=r"controller: the simulation cannot start: t = 0 s"
                       r".*rank 3 < 6"):
        run_scenario(monkeypatch_free, tmp_path / "out", html=False, plots=False)
    assert not (tmp_path / "out").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.yaml"]  # no temporary folder


def test_huge_mass_fails_with_time_and_a_warning(tmp_path, capsys):
    sc = write(tmp_path / "s.yaml", one_arm_scenario(
        mass="1e300", controller="{type: object_pd, kp: 10, kd: 5}"))
    out = tmp_path / "out"
    assert cli.main(["run", str(sc), "--out", str(out), "--quiet", "--no-html"]) == 1
    err = capsys.readouterr().err
    assert "object.mass: 1e+300 kg is more than" in err
    assert "simulation failed: t = " in err and "NaN" in err and "Traceback" not in err
    s = _summary(out)
    assert s["status"] == "failed" and any("object.mass" in w for w in s["input_warnings"])


@pytest.mark.parametrize("content", [b"", b"PK\x03\x04truncated", b"not a zip at all"])
def test_replay_rejects_an_empty_or_truncated_trajectory(tmp_path, capsys, content):
    sc = write(tmp_path / "s.yaml", one_arm_scenario(duration=0.004))
    out = tmp_path / "out"
    run_scenario(sc, out, html=False, plots=False)
    (out / "trajectory.npz").write_bytes(content)
    with pytest.raises(InputError, match="trajectory.npz: not a readable trajectory"):
        load_run(out)
    assert cli.main(["replay", str(out), "--no-block"]) == 2
    err = capsys.readouterr().err
    assert "empty or truncated" in err and "Traceback" not in err


def test_replay_rejects_a_trajectory_cut_in_the_middle(tmp_path):
    sc = write(tmp_path / "s.yaml", one_arm_scenario(duration=0.004))
    out = tmp_path / "out"
    run_scenario(sc, out, html=False, plots=False)
    data = (out / "trajectory.npz").read_bytes()
    (out / "trajectory.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="not a readable trajectory"):
        load_run(out)


def test_duration_overrides_and_memory_guard(tmp_path):
    sc = write(tmp_path / "s.yaml", one_arm_scenario(dt=0.002))
    with pytest.raises(ScenarioError, match=r"--duration: 0.001 s is shorter than the time step "
                       r"simulation.dt = 0.002 s"):
        run_scenario(sc, tmp_path / "o", duration=0.001, html=False)
    with pytest.raises(ScenarioError, match=r"--duration: 1e\+13 s .* GiB of memory"):
        run_scenario(sc, tmp_path / "o", duration=1e13, html=False)
    long = write(tmp_path / "long.yaml", one_arm_scenario(duration="1e12"))
    with pytest.raises(ScenarioError, match=r"simulation.duration: 1e\+12 s .* GiB of memory"):
        run_scenario(long, tmp_path / "o", html=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.yaml", "s.yaml"]


def test_late_waypoints_warn_on_stderr_and_in_summary(tmp_path, capsys):
    ctrl = ("{type: object_pd, kp: 10, kd: 5, waypoints: [{t: 0.005, position: [0.5, 0, 0.3]},"
            " {t: 5.0, position: [0.5, 0, 0.31]}, {t: 6.0, position: [0.5, 0, 0.3]}]}")
    sc = write(tmp_path / "s.yaml", one_arm_scenario(controller=ctrl, duration=0.01,
                                                     joint="{type: weld}"))
    # one arm welded: object_pd needs W_o of rank 6, which a weld gives
    assert cli.main(["run", str(sc), "--out", str(tmp_path / "o"), "--quiet",
                     "--no-html"]) == 0
    err = capsys.readouterr().err
    assert "controller.waypoints[1].t: t = 5 s is after the end of the run (0.01 s) " \
           "(and 1 later ones)" in err
    assert any("waypoints[1]" in w for w in _summary(tmp_path / "o")["input_warnings"])


def test_bad_files_give_messages_not_tracebacks(tmp_path, capsys):
    bad = tmp_path / "latin1.yaml"
    bad.write_bytes(one_arm_scenario("caf\xe9").encode("latin-1"))
    assert cli.main(["run", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: not a UTF-8 text file: byte 9 (line 1) is 0xe9" in err
    dup = write(tmp_path / "dup.yaml", one_arm_scenario().replace(
        "  mass: 2.0\n", "  mass: 4\n  mass: 400\n"))
    assert cli.main(["run", str(dup), "--out", str(tmp_path / "o")]) == 2
    assert "object.mass: duplicate key 'mass' on line 5 (first on line 4)" in \
        capsys.readouterr().err


def test_q0_outside_the_joint_limits_is_an_error(tmp_path):
    q0 = list(Q0_UR5)
    q0[2] = 3.5  # the UR5 elbow (example-robot-data) is limited to ±π
    sc = write(tmp_path / "s.yaml", one_arm_scenario(q0=q0))
    with pytest.raises(ScenarioError, match=r"arms\[0\].q0\[2\]: 3.5 is outside the position "
                       r"limits \[-3.14159, 3.14159\] of joint 'elbow_joint'"):
        run_scenario(sc, tmp_path / "o", html=False)


def test_version(capsys):
    from multiarm_pin import __version__

    with pytest.raises(SystemExit) as exc:
        cli.main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"multiarm-pin {__version__}"


def test_interrupt_while_writing_keeps_the_trajectory_and_summary(tmp_path, monkeypatch):
    import multiarm_pin.app.runner as runner
    from multiarm_pin.app.run_results import plot_names
    from multiarm_pin.exceptions import RunFailedError, RunInterrupted

    sc = write(tmp_path / "s.yaml", one_arm_scenario())
    out = tmp_path / "out"
    run_scenario(sc, out, duration=0.004, html=False, plots=False)
    real_publish = runner.ResultsWriter.publish

    def plots_cut_short(folder, *args):
        (folder / "object_pose.png").write_bytes(b"half a PNG")  # a file cut short
        raise KeyboardInterrupt  # Ctrl-C while the plots are drawn

    monkeypatch.setattr(runner, "_write_plots", plots_cut_short)
    with pytest.raises(RunInterrupted, match="while writing the results of the complete "
                                             "run: .*png not written") as info:
        run_scenario(sc, out, duration=0.006, html=False, plots=True)
    assert info.value.out_dir == out.resolve() and info.value.t_end == pytest.approx(0.006)
    s = _summary(out)  # the new run, with what was written before the signal
    assert s["status"] == "complete" and s["t_end"] == pytest.approx(0.006)
    with np.load(out / "trajectory.npz") as z:
        assert len(z["t"]) == s["samples"] == 4
    with np.load(out / "trajectory.npz") as z:
        names = plot_names({k: z[k] for k in z.files}, arm_names=["a"])
    assert names == ["arm_wrenches.png", "joint_torques.png", "object_pose.png",
                     "constraint_violation.png"]  # a weld: its wrench, no contact forces
    assert s["missing_files"] == names and s["write_interrupted"] == "SIGINT"
    assert any("not written" in w for w in s["warnings"])
    assert not any((out / n).exists() for n in names)
    assert sorted(s["files"].values()) == ["scenario.yaml", "summary.json", "trajectory.npz"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "s.yaml"]

    def publish_then_signal(self):
        real_publish(self)
        os.kill(os.getpid(), signal.SIGINT)  # held by the run: reported after the move

    monkeypatch.undo()
    monkeypatch.setattr(runner.ResultsWriter, "publish", publish_then_signal)
    with pytest.raises(RunInterrupted, match="everything was written") as info:
        run_scenario(sc, out, duration=0.008, html=False, plots=False)
    s = _summary(out)
    assert s["status"] == "complete" and s["t_end"] == pytest.approx(0.008)
    assert s["missing_files"] == [] and s["write_interrupted"] is None

    def page_fails(*args):
        raise RuntimeError("no space for the page")

    monkeypatch.undo()
    monkeypatch.setattr(runner, "_write_page", page_fails)
    with pytest.raises(RunFailedError, match="complete but replay page not written: "
                                             "RuntimeError: no space"):
        run_scenario(sc, out, duration=0.004, html=True, plots=False)
    s = _summary(out)
    assert s["missing_files"] == ["replay.html"] and s["status"] == "complete"
    assert any("replay page not written" in w for w in s["warnings"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "s.yaml"]


def test_plot_names_are_the_plots_written(run_dir, tmp_path):
    from multiarm_pin.app.plots import write_plots
    from multiarm_pin.app.run_results import plot_names

    s = _summary(run_dir)
    pngs = [f for f in s["files"].values() if f.endswith(".png")]
    _, traj, _ = load_run(run_dir)
    assert pngs == plot_names(traj) and "contact_states.png" not in pngs
    traj = dict(traj, event_t=np.array([0.1]), event_kind=np.array(["separation"]),
                event_contact=np.array([0]))  # one event: the contact states are drawn too
    written = write_plots(tmp_path, traj, ["left", "right"])
    assert [p.name for p in written] == plot_names(traj)
    assert plot_names(traj)[0] == "contact_states.png"


def test_a_bug_mid_run_keeps_the_partial_results_and_surfaces(tmp_path, monkeypatch):
    import multiarm_pin.app.runner as runner

    real = runner.scenario_controller

    def make(built):
        inner = real(built)

        def controller(t, state, ev):
            if t >= 0.005:
                raise ZeroDivisionError("a bug in a controller")
            return inner(t, state, ev)

        return controller

    monkeypatch.setattr(runner, "scenario_controller", make)
    sc = write(tmp_path / "s.yaml", one_arm_scenario(duration=0.02))
    with pytest.raises(ZeroDivisionError, match="a bug"):
        run_scenario(sc, tmp_path / "out", html=False, plots=False)
    s = _summary(tmp_path / "out")
    assert s["status"] == "failed" and "internal error (a bug): ZeroDivisionError" in s["error"]
    assert s["t_end"] == pytest.approx(0.004)
