"""The ``multiarm-pin`` command as a user runs it: a real subprocess, signals, exit codes.

Signal tests wait for a progress line (or the "writing results" line) on stderr before
sending the signal, so they hold on a loaded machine; timeouts are generous and no verdict
depends on timing.
"""

import json
import os
import signal
from pathlib import Path

import numpy as np
import pytest
from run_helpers import CliProcess, bind_mount, one_arm_scenario, run_cli, write

from multiarm_pin.app.results_io import MARKER

LONG = 5.0  # [s] simulated by the runs that get interrupted (2500 steps; never reached)


def _summary(folder):
    return json.loads((folder / "summary.json").read_text())


@pytest.mark.parametrize("signum, name", [(signal.SIGINT, "SIGINT"),
                                          (signal.SIGTERM, "SIGTERM")])
def test_signal_mid_simulation_keeps_a_complete_partial_folder(tmp_path, signum, name):
    sc = write(tmp_path / "s.yaml", one_arm_scenario(duration=LONG))
    out = tmp_path / "out"
    run = CliProcess("run", sc, "--out", out, "--no-html")
    assert run.wait_for("elapsed"), "the run ended before its first progress line"
    run.proc.send_signal(signum)
    code, stdout, stderr = run.finish()
    assert code == 130, stderr
    assert "Traceback" not in stderr
    assert f"interrupted by {name}" in stderr and "partial results" in stderr
    s = _summary(out)
    assert s["status"] == "interrupted" and s["error"] == f"interrupted by {name}"
    assert 0 < s["t_end"] < LONG
    with np.load(out / "trajectory.npz") as z:
        t = z["t"]
        assert len(t) == s["samples"] == round(s["t_end"] / 0.002) + 1
        assert t[-1] == pytest.approx(s["t_end"]) and np.all(np.isfinite(z["q_a"]))
    for f in s["files"].values():
        assert (out / f).is_file(), f
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "s.yaml"]  # no temp folder
    if signum == signal.SIGINT:  # replay accepts it and says so (once is enough)
        p = run_cli("replay", out, "--no-block", "--fps", "10")
        assert p.returncode == 0, p.stderr
        assert "partial run (interrupted at t = " in p.stdout and "HTTP 200" in p.stdout


def test_sigint_while_writing_a_complete_run_keeps_it(tmp_path):
    sc = write(tmp_path / "s.yaml", one_arm_scenario(duration=0.004))
    out = tmp_path / "out"
    first = run_cli("run", sc, "--out", out, "--no-html", "--quiet")
    assert first.returncode == 0, first.stderr
    # the plots and the replay page take seconds after this line: the signal lands before
    # they are done (held while the trajectory and summary are written, if it comes then)
    run = CliProcess("run", sc, "--out", out, "--duration", "0.02")
    assert run.wait_for("writing results to")
    run.proc.send_signal(signal.SIGINT)
    code, stdout, stderr = run.finish()
    assert code == 130, stderr
    assert "Traceback" not in stderr and "while writing the results of the complete run" in stderr
    s = _summary(out)  # the new run, kept: its simulation had finished
    assert s["status"] == "complete" and s["requested"]["duration"] == 0.02
    assert s["write_interrupted"] == "SIGINT" and "replay.html" in s["missing_files"]
    for f in s["files"].values():
        assert (out / f).is_file(), f
    assert not any((out / f).exists() for f in s["missing_files"])
    with np.load(out / "trajectory.npz") as z:
        assert len(z["t"]) == s["samples"] == 11
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "s.yaml"]


def test_second_sigint_while_writing_keeps_the_partial_trajectory(tmp_path):
    sc = write(tmp_path / "s.yaml", one_arm_scenario(duration=LONG))
    out = tmp_path / "out"
    run = CliProcess("run", sc, "--out", out)  # with the replay page: seconds of writing
    assert run.wait_for("elapsed"), "the run ended before its first progress line"
    run.proc.send_signal(signal.SIGINT)
    assert run.wait_for("writing results to")
    run.proc.send_signal(signal.SIGINT)  # the second Ctrl-C: skips the plots and the page
    code, stdout, stderr = run.finish()
    assert code == 130, stderr
    assert "Traceback" not in stderr
    assert "another Ctrl-C skips the plots and page" in stderr  # said after the first one
    assert "trajectory.npz, scenario.yaml, summary.json:" in stderr  # writing shows progress
    assert "not written (interrupted again while writing)" in stderr
    s = _summary(out)
    assert s["status"] == "interrupted" and s["write_interrupted"] == "SIGINT"
    assert "replay.html" in s["missing_files"] and 0 < s["t_end"] < LONG
    with np.load(out / "trajectory.npz") as z:
        assert len(z["t"]) == s["samples"] == round(s["t_end"] / 0.002) + 1
    for f in s["files"].values():
        assert (out / f).is_file(), f
    assert not any((out / f).exists() for f in s["missing_files"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "s.yaml"]
    p = run_cli("replay", out, "--no-block", "--fps", "10")  # what was kept replays
    assert p.returncode == 0 and "HTTP 200" in p.stdout, p.stderr


def test_a_second_run_into_the_same_folder_is_refused_naming_the_first(tmp_path, capsys):
    # the first run lasts minutes (60 s simulated), the refusals a few seconds: it is still
    # running when they come, and is interrupted after them. The refused runs go through
    # main in-process (refused before any signal handler is installed): the first run's
    # simulation then goes on for less time and its partial results are written sooner
    from multiarm_pin.app.cli import main

    a = write(tmp_path / "a.yaml", one_arm_scenario("first", duration=60.0))
    b = write(tmp_path / "b.yaml", one_arm_scenario("second", mass=3.0))
    out = tmp_path / "out"
    run = CliProcess("run", a, "--out", out, "--no-html")
    try:
        assert run.wait_for("elapsed"), "the first run ended before its first progress line"
        for other in (b, a):  # another scenario, or the same one: refused all the same
            code = main(["run", str(other), "--out", str(out), "--no-html", "--quiet"])
            err = capsys.readouterr().err
            assert code == 2, err
            assert "another run is writing into this folder" in err, err
            assert f"pid {run.proc.pid}, scenario {a}" in err, err
    finally:
        run.proc.send_signal(signal.SIGINT)
        code, _, stderr = run.finish()
    assert code == 130, stderr
    assert _summary(out)["scenario_file"] == str(a)  # the first run's results, alone
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.yaml", "b.yaml", "out"]  # no lock


def test_out_on_a_mount_point_is_written_in_place(tmp_path, capsys):
    from multiarm_pin.app.cli import main

    sc = write(tmp_path / "s.yaml", one_arm_scenario())
    other = write(tmp_path / "o.yaml", one_arm_scenario("other", mass=3.0))
    src, vol = tmp_path / "src", tmp_path / "vol"
    with bind_mount(src, vol):  # a container volume: renaming it fails with EBUSY
        p = run_cli("run", sc, "--out", vol, "--no-html")
        assert p.returncode == 0, p.stderr
        assert "is a mount point" in p.stderr and "one file at a time" in p.stderr
        assert "writing results to" in p.stderr and "plots (4 PNG files):" in p.stderr
        s = _summary(vol)
        assert s["status"] == "complete" and sorted(s["files"].values()) == sorted(
            f for f in os.listdir(src) if not f.startswith("."))
        (vol / "replay.html").write_text("stale")  # a file of an older run
        p = run_cli("run", sc, "--out", vol, "--no-html", "--quiet", "--duration", "0.01")
        assert p.returncode == 0 and p.stderr == "", p.stderr  # --quiet: writing shows nothing
        assert _summary(vol)["requested"]["duration"] == 0.01
        assert not (vol / "replay.html").exists()  # replaced whole, file by file
        assert sorted(os.listdir(vol)) == sorted([MARKER, *_summary(vol)["files"].values()])
        # refused before simulating (and before any signal handler): through main in-process
        code = main(["run", str(other), "--out", str(vol), "--no-html", "--quiet"])
        err = capsys.readouterr().err
        assert code == 2 and "holds the results of another run" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.yaml", "s.yaml", "src", "vol"]


def test_out_on_a_read_only_mount_point_is_refused_before_simulating(tmp_path):
    sc = write(tmp_path / "s.yaml", one_arm_scenario(duration=LONG))
    src, vol = tmp_path / "src", tmp_path / "ro"
    with bind_mount(src, vol, read_only=True):
        p = run_cli("run", sc, "--out", vol, "--no-html")
        assert p.returncode == 2, p.stderr
        assert p.stderr.startswith(f"error: --out {vol}: is a mount point on a read-only file "
                                   "system"), p.stderr
        assert "elapsed" not in p.stderr and "writing" not in p.stderr  # nothing simulated
        assert os.listdir(vol) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ro", "s.yaml", "src"]


def test_results_kept_where_written_when_the_final_move_fails(tmp_path):
    sc = write(tmp_path / "s.yaml", one_arm_scenario(duration=LONG))
    out = tmp_path / "out"
    first = run_cli("run", sc, "--out", out, "--no-html", "--quiet", "--duration", "0.004")
    assert first.returncode == 0, first.stderr
    old = (out / "summary.json").read_bytes()
    run = CliProcess("run", sc, "--out", out, "--no-html")
    try:
        assert run.wait_for("elapsed"), "the run ended before its first progress line"
        # checked as a plain folder before the run; a volume mounted on it since: the move
        # into place fails (EBUSY)
        with bind_mount(tmp_path / "src", out):
            run.proc.send_signal(signal.SIGINT)
            code, stdout, stderr = run.finish()
    finally:
        if run.proc.poll() is None:
            run.proc.kill()
    assert code == 1, stderr
    assert "cannot move the results into place" in stderr and "Traceback" not in stderr
    kept = Path(stderr.split("results kept in: ")[1].split()[0])
    assert kept.parent == tmp_path and kept.name.startswith(".out.tmp-")
    s = _summary(kept)  # whole: trajectory, summary, plots
    assert s["status"] == "interrupted" and s["missing_files"] == []
    with np.load(kept / "trajectory.npz") as z:
        assert len(z["t"]) == s["samples"]
    assert (out / "summary.json").read_bytes() == old  # the old results, untouched
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == sorted([kept.name, "out", "s.yaml", "src"])  # nothing else left behind


def test_exit_codes_and_no_tracebacks(tmp_path):
    sc = write(tmp_path / "s.yaml", one_arm_scenario())
    (tmp_path / "f").write_text("x")
    for args in (["run", sc, "--out", tmp_path / "f"],           # --out is a file
                 ["replay", tmp_path]):                          # not a results folder
        p = run_cli(*args)
        assert p.returncode == 2, (args, p.stderr)
        assert p.stderr.startswith("error: ") and "Traceback" not in p.stderr, p.stderr


def _numbers(line: str) -> np.ndarray:
    """The numbers of the bracketed list at the end of a printed line."""
    return np.array(line[line.rindex("[") + 1:line.rindex("]")].split(), dtype=float)


def test_info_of_a_scenario_file(capsys):
    """Issue 25: `info` accepts a scenario: its arms, tool frames, joints, object, supports.

    The scenario's report through the command; the default pair and the missing file through
    ``main`` in-process (the command's entry point; numpy's print options, which ``info``
    sets, put back after)."""
    from run_helpers import REPO

    from multiarm_pin.app.cli import main

    p = run_cli("info", REPO / "scenarios" / "pick_from_table.yaml")
    assert p.returncode == 0, p.stderr
    out = p.stdout
    lines = out.splitlines()
    assert lines[0].startswith("scenario pick_from_table (") and "2 arm(s), 1 support(s)" in out
    assert sum(ln.startswith("arm ") for ln in lines) == 2
    assert "arm four_finger (" in out and "nq=6 nv=6 tool=tool0" in out
    assert "  joints: shoulder_pan_joint (revolute z), shoulder_lift_joint (revolute y)" in out
    assert ("  joint to the object: fingertips (fingertip_1 on +x, fingertip_2 on +y, "
            "fingertip_3 on +z, fingertip_4 on +z)") in out
    assert out.count("(found by inverse kinematics)") == 2
    assert "object: box 0.8 x 0.6 x 0.4 m, 4 kg" in out
    assert "support table: plane through [0.  0.  0.7] m, normal [0. 0. 1.]" in out
    # the object's numbers against their closed forms: a uniform 4 kg box, gravity 9.81
    m, (a, b, c) = 4.0, (0.8, 0.6, 0.4)
    inertia = m / 12 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    M_o = next(ln for ln in lines if ln.startswith("  M_o diagonal"))
    np.testing.assert_allclose(_numbers(M_o), [m, m, m, *inertia], atol=1e-4)
    h_o = next(ln for ln in lines if ln.startswith("  h_o"))
    np.testing.assert_allclose(_numbers(h_o), [0, 0, -m * 9.81, 0, 0, 0], atol=1e-4)
    # without an argument: today's two arms and a box
    with np.printoptions():
        assert main(["info"]) == 0
        assert main(["info", str(REPO / "missing.yaml")]) == 2
    p = capsys.readouterr()
    assert "arm left (" in p.out and "object: box 0.8 x 0.4 x 0.3 m, 4 kg" in p.out
    assert "missing.yaml: file not found" in p.err and "Traceback" not in p.err


def _imported_after(code: str) -> set[str]:
    """Top-level packages (and a few submodules) in ``sys.modules`` after running ``code``."""
    import subprocess
    import sys

    probe = (f"{code}\nimport sys\nprint(' '.join(sorted(m for m in sys.modules "
             "if '.' not in m or m.startswith('pinocchio.'))))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    return set(out.stdout.split("\n")[-2].split())


def test_start_up_imports_only_what_the_subcommand_uses(tmp_path):
    # `--help` (and any argument error) answers without the heavy layers
    help_ = _imported_after("import contextlib, io\nfrom multiarm_pin.app.cli import main\n"
                            "with contextlib.redirect_stdout(io.StringIO()):\n"
                            "    try:\n        main(['--help'])\n"
                            "    except SystemExit:\n        pass")
    heavy = {"meshcat", "numba", "matplotlib", "dask", "distributed", "scipy", "pinocchio",
             "pyarrow", "collada", "trimesh"}
    assert "multiarm_pin" in help_
    assert not heavy & help_, sorted(heavy & help_)
    # a run with its plots and replay page: no Dask, no Pinocchio visualizer (trimesh)
    sc = write(tmp_path / "s.yaml", one_arm_scenario(duration=0.02))
    run = _imported_after(f"from multiarm_pin.app.cli import main\n"
                          f"assert main(['run', {str(sc)!r}, '--out', "
                          f"{str(tmp_path / 'out')!r}, '--quiet']) == 0")
    assert {"meshcat", "matplotlib", "numba"} <= run
    unused = {"dask", "distributed", "pyarrow", "trimesh", "pinocchio.visualize"}
    assert not unused & run, sorted(unused & run)
    assert (tmp_path / "out" / "replay.html").stat().st_size > 0
