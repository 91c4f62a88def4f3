"""``multiarm-pin precompile`` (``app/precompile.py``): the shipped scenarios run once each, as
``multiarm-pin run`` runs them, so that a later run of any of them compiles nothing."""

from __future__ import annotations

import tempfile

import pytest
from numba.core import event

from multiarm_pin._compiled import function_pointers
from multiarm_pin.app import precompile, runner
from multiarm_pin.app.cli import main
from multiarm_pin.data import shipped_files
from multiarm_pin.exceptions import InputError, RunFailedError


def test_a_run_after_it_compiles_nothing(tmp_path, monkeypatch):
    """The same kernels, for the same argument types, as a full ``run`` (plots and page)."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    [done] = precompile.precompile(["box_on_table"])
    assert done.name == "box_on_table" and done.outcome == "complete" and done.seconds > 0
    assert not list(tmp_path.iterdir())  # its results folder is gone
    made = len(function_pointers._by_signature)
    with event.install_recorder("numba:compile") as rec:
        runner.run_scenario(precompile.shipped_scenarios()["box_on_table"], out=tmp_path / "run",
                            quiet=True)
    assert not rec.buffer
    assert len(function_pointers._by_signature) == made


def test_every_shipped_scenario_once_and_a_failed_run_does_not_stop_it(monkeypatch, tmp_path):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    calls = []

    def fake(path, out, quiet, html, plots):
        calls.append((path.stem, out, quiet, html, plots))
        if path.stem == "grasp_failure":
            raise RunFailedError("the grasp fails", 0.1, out, "the grasp fails")

    monkeypatch.setattr(runner, "run_scenario", fake)
    seen = []
    done = precompile.precompile(report=seen.append)
    names = [p.stem for p in shipped_files("scenarios")]
    assert [c[0] for c in calls] == names == [d.name for d in done]
    assert seen == done
    assert all(not html and not plots and quiet for _, _, quiet, html, plots in calls)
    assert all(out.parent.parent == tmp_path for _, out, *_ in calls)  # one temporary folder
    assert not list(tmp_path.iterdir())
    outcomes = {d.name: d.outcome for d in done}
    assert outcomes.pop("grasp_failure") == "ended early (RunFailedError)"
    assert set(outcomes.values()) == {"complete"}


def test_unknown_names_are_refused_before_anything_runs(monkeypatch, capsys):
    monkeypatch.setattr(runner, "run_scenario", lambda *a, **k: pytest.fail("ran"))
    with pytest.raises(InputError, match=r"'nope'.*two_ur5_box"):
        precompile.precompile(["two_ur5_box", "nope"])
    assert main(["precompile", "--scenarios", "nope"]) == 2
    err = capsys.readouterr().err
    assert "not shipped scenarios: 'nope'" in err and "Traceback" not in err


def test_the_command_line_says_what_it_compiled(monkeypatch, capsys):
    monkeypatch.setattr(runner, "run_scenario", lambda *a, **k: None)
    assert main(["precompile", "--scenarios", "two_ur5_box", "tilt_pick"]) == 0
    out = capsys.readouterr().out
    assert "two_ur5_box:" in out and "tilt_pick:" in out and "of 2 scenarios" in out


def test_without_the_jit_there_is_nothing_to_compile(monkeypatch, capsys):
    from numba.core import config

    monkeypatch.setattr(config, "DISABLE_JIT", True)
    monkeypatch.setattr(runner, "run_scenario", lambda *a, **k: pytest.fail("ran"))
    assert main(["precompile"]) == 0
    assert "nothing to compile" in capsys.readouterr().out
