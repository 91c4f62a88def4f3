"""The ``multiarm-pin`` command as a user runs it: a real subprocess, signals, exit codes.

Signal tests wait for a progress line (or the "writing results" line) on stderr before
sending the signal, so they hold on a loaded machine; timeouts are generous and no verdict
depends on timing.
"""

import json
import signal

import numpy as np
import pytest
from run_helpers import CliProcess, one_arm_scenario, run_cli, write

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


def test_sigint_while_writing_keeps_old_or_new_results_whole(tmp_path):
    sc = write(tmp_path / "s.yaml", one_arm_scenario(duration=0.004))
    out = tmp_path / "out"
    first = run_cli("run", sc, "--out", out, "--no-html", "--quiet")
    assert first.returncode == 0, first.stderr
    old = (out / "summary.json").read_bytes()
    old_files = sorted(p.name for p in out.iterdir())
    # the replay page makes the write phase last seconds: the signal lands inside it
    run = CliProcess("run", sc, "--out", out, "--duration", "0.02")
    assert run.wait_for("writing results to")
    run.proc.send_signal(signal.SIGINT)
    code, stdout, stderr = run.finish()
    assert "Traceback" not in stderr
    assert code in (0, 130)
    new = _summary(out)
    if (out / "summary.json").read_bytes() == old:  # interrupted: the old run, untouched
        assert code == 130 and "left as it was" in stderr
        assert sorted(p.name for p in out.iterdir()) == old_files
    else:  # finished before the signal: the new run, complete
        assert new["status"] == "complete" and new["requested"]["duration"] == 0.02
        for f in new["files"].values():
            assert (out / f).is_file(), f
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "s.yaml"]


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


def test_info_of_a_scenario_file():
    """Issue 25: `info` accepts a scenario: its arms, tool frames, joints, object, supports."""
    from run_helpers import REPO

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
    p = run_cli("info")
    assert p.returncode == 0, p.stderr
    assert "arm left (" in p.stdout and "object: box 0.8 x 0.4 x 0.3 m, 4 kg" in p.stdout
    p = run_cli("info", REPO / "missing.yaml")
    assert p.returncode == 2 and "missing.yaml: file not found" in p.stderr


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
