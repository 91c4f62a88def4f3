"""``multiarm-pin sweep`` from the command line: clear errors, SIGINT then --resume."""

import os
import signal
import subprocess
import sys
import time

import pytest

from multiarm_pin.app.cli import main
from multiarm_pin.study import read_table
from tests.study.helpers import REPO, rows_by_case, tiny_grasp_study, tiny_simulation_study

pytestmark = pytest.mark.timeout(900)


def test_unreachable_scheduler_is_a_clear_error_and_writes_nothing(tmp_path, capsys,
                                                                  monkeypatch):
    import multiarm_pin.study.execution as execution

    # Dask retries a refused connection until the timeout: 1 s instead of the default 10 s
    # (the same connect, with its own timeout parameter)
    real_connect = execution.connect
    monkeypatch.setattr(execution, "connect", lambda s: real_connect(s, timeout=1.0))
    study = tiny_grasp_study(tmp_path)
    out = tmp_path / "out"
    # port 9 (discard) on the loopback: nothing listens there
    code = main(["sweep", str(study), "--out", str(out), "--scheduler", "tcp://127.0.0.1:9"])
    err = capsys.readouterr().err
    assert code == 2
    assert "cannot reach the Dask scheduler at 'tcp://127.0.0.1:9' within 1 s" in err, err
    assert "Traceback" not in err
    assert not out.exists()


def test_bad_study_is_a_clear_error(tmp_path, capsys):
    p = tmp_path / "s.yaml"
    p.write_text(f"base: {REPO / 'scenarios' / 'two_ur5_box.yaml'}\n"
                 "parameters: [{path: object.mas, grid: [1, 2]}]\n")
    assert main(["sweep", str(p), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{p}: parameters[0].path: 'object.mas' does not exist" in err
    assert "did you mean 'mass'" in err and not (tmp_path / "o").exists()


def test_resume_needs_a_study_and_out_must_hold_this_study(tmp_path, capsys, monkeypatch):
    import multiarm_pin.study.execution as execution

    def no_cluster(workers):
        raise AssertionError("a cluster was started for a study that cannot run")

    monkeypatch.setattr(execution, "local_cluster", no_cluster)
    study = tiny_grasp_study(tmp_path)
    assert main(["sweep", str(study), "--out", str(tmp_path / "o"), "--resume"]) == 2
    assert "no study to resume" in capsys.readouterr().err
    other = tmp_path / "other"
    other.mkdir()
    (other / "study.json").write_text('{"name": "someone_else"}')
    assert main(["sweep", str(study), "--out", str(other)]) == 2
    assert "holds the results of study 'someone_else'" in capsys.readouterr().err


def _rows_written(out) -> int:
    return len(list((out / "cases").glob("*/row.json"))) if (out / "cases").is_dir() else 0


def _sigint_default():
    """In the child before exec: SIGINT to its default, as a terminal's foreground job has it
    (a test process started with SIGINT ignored, e.g. a background job of a shell without job
    control, would hand the ignored disposition on, and Python keeps an ignored SIGINT)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def test_ctrl_c_to_the_process_group_then_resume(tmp_path, warm_kernels):
    # a terminal's Ctrl-C: SIGINT to the whole foreground process group, the local cluster's
    # worker processes too. Cases of 3 s simulated (~0.15-0.25 s each on the compiled loop,
    # 15-20x real time): the interrupt, sent once the first row exists, lands with most of
    # the 8 cases unfinished by a wide margin (two run at a time), whatever the load
    study = tiny_simulation_study(tmp_path, masses=(2.0, 3.0, 4.0, 5.0), samples=2,
                                  duration=3.0)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "multiarm_pin.app.cli", "sweep", str(study), "--out", str(out),
           "--workers", "2"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=REPO, start_new_session=True,  # its own group, as in a shell
                            preexec_fn=_sigint_default)
    try:
        deadline = time.monotonic() + 600
        while _rows_written(out) < 1 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()
        os.killpg(proc.pid, signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, stderr
    assert "interrupted:" in stderr and "--resume" in stderr, stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr  # workers
    assert stderr.count("interrupted") == 1, stderr  # the driver alone reports it
    first = rows_by_case(read_table(out))
    assert 1 <= len(first) < 8, stderr  # stopped mid-study; every finished row in the table
    code = subprocess.run(cmd + ["--resume", "--quiet"], capture_output=True, text=True,
                          cwd=REPO, timeout=600)
    assert code.returncode == 0, code.stderr
    rows = rows_by_case(read_table(out))
    assert len(rows) == 8 and all(r["status"] == "ok" for r in rows.values()), code.stderr
    for cid, row in first.items():  # finished before the interrupt: not run again
        assert rows[cid]["run_token"] == row["run_token"]
    assert (out / "report.md").is_file()
