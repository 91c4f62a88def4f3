"""Results folders: safe names, refused targets, atomic publication, deferred signals."""

import json
import os
import signal
from pathlib import Path

import pytest

from multiarm_pin.app.results_io import (
    LOCK_NAME,
    MARKER,
    STAGING_PREFIX,
    ResultsWriter,
    RunLock,
    deferred_signals,
    is_mount_point,
    prepare_output,
    publishes_in_place,
    run_identity,
    safe_component,
    write_atomic,
)
from multiarm_pin.exceptions import OutputError
from tests.run_helpers import python_sigint_handler


@pytest.mark.parametrize("name, expected", [
    ("two_ur5_box", "two_ur5_box"),
    ("../../escape", "escape"),
    ("/etc/passwd", "etc_passwd"),
    ("..", "run"),
    ("", "run"),
    (".hidden", "hidden"),
    ("a b/c\\d", "a_b_c_d"),
    ("x" * 300, "x" * 100),
])
def test_safe_component_is_one_harmless_path_component(name, expected):
    s = safe_component(name)
    assert s == expected
    assert "/" not in s and "\\" not in s and not s.startswith(".") and s


def _results(folder, scenario_file):
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text(json.dumps({"scenario_file": str(scenario_file)}))
    (folder / "trajectory.npz").write_bytes(b"old")
    return folder


def test_prepare_output_refuses_the_folder_of_the_input_file(tmp_path):
    sc = tmp_path / "scenario.yaml"
    sc.write_text("name: x\n")
    for target in (tmp_path, tmp_path.parent):
        with pytest.raises(OutputError, match="holds the scenario file"):
            prepare_output(target, sc)
    assert sc.read_text() == "name: x\n"


def test_prepare_output_refuses_a_file_and_a_foreign_folder(tmp_path):
    sc = tmp_path / "s.yaml"
    sc.write_text("")
    (tmp_path / "file").write_text("data")
    with pytest.raises(OutputError, match="is an existing file"):
        prepare_output(tmp_path / "file", sc)
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("precious")
    for overwrite in (False, True):  # never replaced, even with --overwrite
        with pytest.raises(OutputError, match="not a results folder"):
            prepare_output(foreign, sc, overwrite=overwrite)
    with pytest.raises(OutputError, match="cannot create"):  # parent is a file
        prepare_output(tmp_path / "file" / "sub", sc)


def test_prepare_output_other_run_needs_overwrite(tmp_path):
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    a.write_text("")
    b.write_text("")
    out = _results(tmp_path / "out", a)
    assert run_identity(out) == str(a)
    assert prepare_output(out, a) == out  # same scenario: rerun replaces its results
    with pytest.raises(OutputError, match="results of another run .*--overwrite"):
        prepare_output(out, b)
    assert prepare_output(out, b, overwrite=True) == out
    assert prepare_output(tmp_path / "new" / "deep", b) == tmp_path / "new" / "deep"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes anywhere")
def test_prepare_output_unwritable_parent(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        with pytest.raises(OutputError, match="not writable"):
            prepare_output(ro / "out", tmp_path / "s.yaml")
    finally:
        ro.chmod(0o755)


def test_writer_replaces_whole_or_leaves_untouched(tmp_path):
    sc = tmp_path / "s.yaml"
    sc.write_text("")
    out = _results(tmp_path / "out", sc)
    (out / "replay.html").write_text("stale")
    # an error while writing: the old folder is untouched, no temporary folder is left
    with pytest.raises(RuntimeError), ResultsWriter(out, sc) as w:
        (w.path / "trajectory.npz").write_bytes(b"new")
        raise RuntimeError("disk full")
    assert (out / "trajectory.npz").read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "s.yaml"]
    # a complete write replaces the folder whole: the stale replay.html is gone
    with ResultsWriter(out, sc) as w:
        (w.path / "trajectory.npz").write_bytes(b"new")
        w.publish()
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "trajectory.npz"]
    assert (out / "trajectory.npz").read_bytes() == b"new"
    assert run_identity(out) == str(sc)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "s.yaml"]


def test_write_atomic(tmp_path):
    f = tmp_path / "x.bin"
    write_atomic(f, b"abc")
    assert f.read_bytes() == b"abc"
    assert [p.name for p in tmp_path.iterdir()] == ["x.bin"]


def test_deferred_signals_deliver_after_the_block():
    done = []
    with python_sigint_handler():  # even if the suite was started with SIGINT ignored
        with pytest.raises(KeyboardInterrupt):
            with deferred_signals():
                os.kill(os.getpid(), signal.SIGINT)
                done.append("block finished")  # not interrupted inside
        assert done == ["block finished"]
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_run_lock_refuses_a_second_holder_names_it_and_is_removed(tmp_path):
    sc = tmp_path / "s.yaml"
    first = RunLock(tmp_path / ".out.lock", tmp_path / "out", sc)
    first.acquire()
    try:  # a second open file description of the same file: flock refuses it
        with pytest.raises(OutputError, match=rf"another run is writing into this folder "
                                              rf"\(pid {os.getpid()}, scenario {sc}, since "):
            RunLock(tmp_path / ".out.lock", tmp_path / "out", tmp_path / "b.yaml").acquire()
    finally:
        first.release()
    assert not (tmp_path / ".out.lock").exists()
    again = RunLock(tmp_path / ".out.lock", tmp_path / "out", sc)
    again.acquire()  # free again
    again.release()


def test_writer_holds_the_lock_until_it_ends(tmp_path):
    sc = tmp_path / "s.yaml"
    sc.write_text("")
    with ResultsWriter(tmp_path / "out", sc) as w:
        assert (tmp_path / ".out.lock").is_file() and not w.in_place
        with pytest.raises(OutputError, match="another run is writing"), \
                ResultsWriter(tmp_path / "out", tmp_path / "other.yaml"):
            pass
        w.publish()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "s.yaml"]


def test_in_place_publication_replaces_the_files_one_by_one(tmp_path, monkeypatch):
    import multiarm_pin.app.results_io as rio

    sc = tmp_path / "s.yaml"
    sc.write_text("")
    out = _results(tmp_path / "out", sc)
    (out / "replay.html").write_text("stale")
    (out / f"{STAGING_PREFIX}old").mkdir()  # left by a killed run
    monkeypatch.setattr(rio, "publishes_in_place", lambda target: True)  # as a mount point
    with ResultsWriter(out, sc) as w:
        assert w.in_place and w.path.parent == out and (out / LOCK_NAME).is_file()
        (w.path / "trajectory.npz").write_bytes(b"new")
        w.publish()
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "trajectory.npz"]
    assert (out / "trajectory.npz").read_bytes() == b"new" and run_identity(out) == str(sc)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "s.yaml"]


def test_mount_points_are_found_bind_mounts_of_the_same_file_system_too(tmp_path):
    from run_helpers import bind_mount

    assert not is_mount_point(tmp_path)
    assert is_mount_point(Path("/"))
    with bind_mount(tmp_path / "src", tmp_path / "vol"):
        assert is_mount_point(tmp_path / "vol") and publishes_in_place(tmp_path / "vol")
        assert not os.path.ismount(tmp_path / "vol")  # what os.path.ismount alone misses
    assert not is_mount_point(tmp_path / "vol")
