"""The closed loop compiled ahead of time (``_compiled/precompiled.py``, built by
``app/precompile.py``): built, loaded only
where it fits (these sources, this machine, these argument types), and the same results as
the JIT kernel, bit for bit."""

from __future__ import annotations

import json
import shutil
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from closed_loop_cases import RUN_FIELDS, run_scenario

from multiarm_pin._compiled import closed_loop as kernels
from multiarm_pin._compiled import precompiled
from multiarm_pin.app import precompile

OLD = precompiled.PREFIX + "0123456789abcdef.json"  # a module of other sources


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A folder with the module built for these sources (and an old one's leftover)."""
    out = tmp_path_factory.mktemp("aot")
    (out / OLD).write_text("{}")
    try:
        precompile.build(out)
    except Exception as exc:  # noqa: BLE001
        headers = Path(sysconfig.get_paths()["include"]) / "Python.h"
        if (shutil.which("cc") is None and shutil.which("gcc") is None) or not headers.exists():
            pytest.skip(f"no C compiler or no Python headers on this machine: {exc}")
        raise
    return out


def files(folder):
    return sorted(p.name for p in folder.glob(precompiled.PREFIX + "*"))


def test_build_writes_the_module_and_its_sidecar(folder):
    names = files(folder)
    assert len(names) == 2 and OLD not in names  # the old one is gone
    assert all(n.startswith(precompiled.module_name()) for n in names)
    meta = json.loads((folder / f"{precompiled.module_name()}.json").read_text())
    assert meta["machine"] == precompiled.machine()
    assert set(meta["fingerprints"]) == set(meta["arguments"]) == {"run_rk4"}
    assert len(meta["fingerprints"]["run_rk4"]) == len(meta["arguments"]["run_rk4"]) == \
        kernels.run_rk4.py_func.__code__.co_argcount - 1  # not its stage: compiled in
    assert not list(folder.glob(".aot-*"))  # no build folder left behind
    assert precompiled.load(folder) is not None


@pytest.mark.parametrize("name", ["two_ur5_box", "ur5_panda_box", "fingertips_form_closure"])
def test_runs_equal_the_jit_kernel_bit_for_bit(name, folder, monkeypatch):
    """Shipped scenarios run on the precompiled module (every stretch) with the JIT's
    results to the bit."""
    used = []
    pick = precompiled.run_rk4_for

    def spy(args, where=None):
        fn = pick(args, where)
        used.append(fn is not kernels.run_rk4)
        return fn

    monkeypatch.setattr(precompiled, "FOLDER", folder)
    monkeypatch.setattr(precompiled, "run_rk4_for", spy)
    aot, calls = run_scenario(name, 0.1, "closed", monkeypatch)
    assert calls and used and all(used)
    monkeypatch.setenv(precompiled.ENV_SWITCH, "0")
    used.clear()
    jit, _ = run_scenario(name, 0.1, "closed", monkeypatch)
    assert used and not any(used)
    for field in RUN_FIELDS:
        np.testing.assert_array_equal(getattr(aot, field), getattr(jit, field), err_msg=field)


def test_every_kernel_has_example_arguments():
    assert set(precompile.EXAMPLES) == set(precompiled.KERNELS)


def test_arguments_of_other_types_go_to_the_jit_kernel(folder):
    args = list(precompile.run_rk4_arguments())
    assert args[-1] is not kernels.closed_loop_stage  # the JIT path's pointer to the stage
    assert precompiled.run_rk4_for(tuple(args), folder) is not kernels.run_rk4
    x = args[3]
    readonly = x.copy()
    readonly.setflags(write=False)
    for other in (readonly, x.astype(np.float32), np.repeat(x, 2)[::2], x[None, :]):
        args[3] = other
        assert precompiled.run_rk4_for(tuple(args), folder) is kernels.run_rk4
    args[3] = x
    args[0] = 0.5  # a float where an integer is expected
    assert precompiled.run_rk4_for(tuple(args), folder) is kernels.run_rk4


def copy_module(folder, to, rename=None, **meta_changes):
    to.mkdir()
    for p in folder.glob(precompiled.module_name() + "*"):
        name = p.name if rename is None else p.name.replace(precompiled.module_name(), rename)
        shutil.copy(p, to / name)
    side = to / f"{rename or precompiled.module_name()}.json"
    meta = json.loads(side.read_text())
    meta.update(meta_changes)
    side.write_text(json.dumps(meta))
    return to


def test_not_loaded_for_other_sources_machine_or_numba(folder, tmp_path):
    other_cpu = list(precompiled.machine())
    other_cpu[1] = "some-other-cpu"
    assert precompiled.load(copy_module(folder, tmp_path / "same")) is not None
    assert precompiled.load(copy_module(folder, tmp_path / "cpu", machine=other_cpu)) is None
    assert precompiled.load(copy_module(folder, tmp_path / "numba", numba="0.1")) is None
    assert precompiled.load(copy_module(folder, tmp_path / "digest", digest="0" * 64)) is None
    renamed = copy_module(folder, tmp_path / "name", rename=precompiled.PREFIX + "f" * 16)
    assert precompiled.load(renamed) is None  # built from other sources: not even looked at


def test_switched_off_by_the_environment_and_without_jit(folder, monkeypatch):
    from numba.core import config

    monkeypatch.setenv(precompiled.ENV_SWITCH, "0")
    assert precompiled.load(folder) is None
    monkeypatch.delenv(precompiled.ENV_SWITCH)
    monkeypatch.setattr(config, "DISABLE_JIT", True)
    assert precompiled.load(folder) is None


def test_a_failed_build_says_so_and_keeps_the_jit(tmp_path, monkeypatch, capsys):
    def fail(*a, **k):
        raise OSError("no C compiler found")

    monkeypatch.setattr(precompile, "build", fail)
    assert precompile.main(["--folder", str(tmp_path)]) == 1
    err = capsys.readouterr().err
    assert "not built (OSError: no C compiler found)" in err and "Traceback" not in err
    assert not list(tmp_path.iterdir())


def test_the_command_line_builds_only_when_stale(monkeypatch, capsys):
    from multiarm_pin.app.cli import main

    built = []
    monkeypatch.setattr(precompile, "build", lambda folder=None: built.append(folder) or
                        precompiled.FOLDER / "x.so")
    monkeypatch.setattr(precompiled, "load", lambda folder=None: ("run_rk4", []))
    assert main(["precompile", "--if-stale"]) == 0
    assert "up to date" in capsys.readouterr().out and not built
    assert main(["precompile"]) == 0
    assert built == [None] and "built in" in capsys.readouterr().out
