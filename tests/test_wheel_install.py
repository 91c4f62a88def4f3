"""The package as a user installs it: a wheel in a fresh venv, outside the checkout.

The wheel is built from a copy of the sources (nothing written into the checkout) without
build isolation (offline: the dev environment's setuptools), installed with ``--no-deps`` into
a new venv that reuses the dev environment's installed dependencies through a ``.pth`` line
plus copies of its ``.pth`` hooks (site-packages added that way are not scanned for ``.pth``
files) except the editable install's, so the dev environment's multiarm_pin stays invisible.
Then, from a temporary folder, ``multiarm-pin demo`` and ``multiarm-pin grasp`` on a shipped
grasp file must work with only the installed files.

The commands run with ``NUMBA_DISABLE_JIT=1``: a fresh install has no kernel cache, and
compiling the kernels takes ~100 s on a loaded 2-core machine, while the 0.05 s demo runs in
plain Python in about the time of a cached run (the compiled kernels are tested elsewhere).
Marked ``wheel`` (deselect with ``-m "not wheel"``).
"""

import json
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.wheel


def _run(cmd, cwd, timeout=600):
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1"}
    p = subprocess.run([str(c) for c in cmd], cwd=cwd, capture_output=True, text=True,
                       timeout=timeout, env=env)
    assert p.returncode == 0, f"{cmd}\n{p.stdout[-3000:]}\n{p.stderr[-3000:]}"
    return p


@pytest.fixture(scope="module")
def venv(tmp_path_factory):
    """``(bin folder, site-packages)`` of a fresh venv holding only the built wheel."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    for f in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / f, src / f)
    shutil.copytree(ROOT / "multiarm_pin", src / "multiarm_pin",
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
          "--no-index", "--quiet", "-w", tmp / "dist", src], cwd=tmp)
    (wheel,) = (tmp / "dist").glob("multiarm_pin-*.whl")
    env = tmp / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", env], cwd=tmp)
    site = Path(_run([env / "bin" / "python", "-c",
                      "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                     cwd=tmp).stdout.strip())
    deps = sorted({sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]})
    # "_dev..." sorts before the copied .pth files (cmeel.pth imports from these folders)
    (site / "_dev_dependencies.pth").write_text("\n".join(deps) + "\n")
    for d in deps:  # their own .pth hooks (cmeel's pinocchio path), not the editable install
        for pth in Path(d).glob("*.pth"):
            if not pth.name.startswith("__editable__"):
                shutil.copy(pth, site / pth.name)
    _run([sys.executable, "-m", "pip", "--python", env / "bin" / "python", "install",
          "--no-deps", "--no-index", "--ignore-installed", "--quiet", wheel], cwd=tmp)
    return env / "bin", site


def test_wheel_holds_the_data_as_files(venv):
    _, site = venv
    data = site / "multiarm_pin" / "data"
    assert (data / "scenarios" / "two_ur5_box.yaml").is_file()
    assert (data / "scenarios" / "grasps" / "box_form_closure.yaml").is_file()
    assert (data / "scenarios" / "studies" / "grasp_robustness.yaml").is_file()
    assert (data / "robots" / "mp6" / "mp6.urdf").is_file()
    assert not (data / "scenarios" / "studies" / "reports").exists()
    assert not any(p.is_symlink() for p in data.rglob("*"))


def test_demo_and_grasp_from_any_folder(venv, tmp_path):
    bin_dir, site = venv
    work = tmp_path / "elsewhere"
    work.mkdir()
    where = _run([bin_dir / "python", "-c", "import multiarm_pin; print(multiarm_pin.__file__)"],
                 cwd=work).stdout.strip()
    assert Path(where).is_relative_to(site), where  # the wheel, not the checkout
    cli = bin_dir / "multiarm-pin"
    _run([cli, "demo", "--out", "demo", "--duration", "0.05", "--quiet"], cwd=work)
    s = json.loads((work / "demo" / "summary.json").read_text())
    assert s["status"] == "complete" and s["t_end"] == pytest.approx(0.05)
    assert s["scenario_file"].startswith(str(site))
    assert (work / "demo" / "replay.html").stat().st_size > 100_000
    grasp = site / "multiarm_pin" / "data" / "scenarios" / "grasps" / "box_form_closure.yaml"
    rep = json.loads(_run([cli, "grasp", grasp, "--json"], cwd=work).stdout)
    assert rep["form_closure"] is True and rep["independent"] is True
    assert (work / "box_form_closure_grasp.png").stat().st_size > 1000
    listing = _run([cli, "scenarios"], cwd=work).stdout
    assert "two_ur5_box.yaml" in listing and str(site) in listing
