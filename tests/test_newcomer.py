"""The README's Python example: a newcomer's script, run as written, using only the public API.

The script is read from README.md's "From Python" section (the one source of it) and run in
a temporary folder. Its results are checked against what they must be by construction:
Pinocchio's forward kinematics for the arms placed by IK and held by the welds, the end of
the trajectory for the lifted box, the null space of the wrench matrix for the LP margin
(no LP involved), and the replay page's size with and without meshes.
"""

from __future__ import annotations

import ast
import contextlib
import io
import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import multiarm_pin as mp
from multiarm_pin.grasp.design import two_corner_box_grasp

README = Path(__file__).resolve().parents[1] / "README.md"
SECTION = "## From Python"


def readme_example() -> str:
    """The first ```python block of the README's "From Python" section."""
    text = README.read_text(encoding="utf-8")
    assert f"\n{SECTION}\n" in text, f"README.md has no {SECTION!r} section"
    section = text.split(f"\n{SECTION}\n", 1)[1].split("\n## ", 1)[0]
    match = re.search(r"```python\n(.*?)```", section, re.S)
    assert match, f"README.md's {SECTION!r} section has no python block"
    return match.group(1)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """``(namespace, stdout, folder)`` of the example run in a fresh folder."""
    folder = tmp_path_factory.mktemp("newcomer")
    code = compile(readme_example(), str(README), "exec")
    namespace: dict = {"__name__": "__main__"}
    out = io.StringIO()
    with contextlib.chdir(folder), contextlib.redirect_stdout(out):
        exec(code, namespace)
    return namespace, out.getvalue(), folder


def test_example_needs_nothing_outside_the_public_api():
    tree = ast.parse(readme_example())
    imported = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            raise AssertionError(f"the example imports from a module: from {node.module} ...")
        if isinstance(node, ast.Import):
            imported |= {(a.name, a.asname) for a in node.names}
    assert imported == {("numpy", "np"), ("pinocchio", "pin"), ("multiarm_pin", "mp")}
    used = {node.attr for node in ast.walk(tree) if isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name) and node.value.id == "mp"}
    assert used, "the example uses no multiarm_pin name"
    outside = sorted(used - set(mp.__all__))
    assert not outside, f"the example uses names outside multiarm_pin.__all__: {outside}"
    lines = [ln for ln in readme_example().splitlines() if ln.strip() and not ln.startswith("#")]
    assert len(lines) <= 30, f"a newcomer's script of about 20 lines, got {len(lines)}"


def test_example_places_the_tools_on_the_grasp_and_keeps_them_there(run):
    ns, _, _ = run
    start, grasp, arms, result = ns["start"], ns["grasp"], ns["arms"], ns["result"]
    system = ns["system"]
    for i, arm in enumerate(arms):
        # t = 0: inverse kinematics put the tool where the grasp says (Pinocchio's FK)
        np.testing.assert_allclose(arm.tool_placement(ns["q0"][i]).homogeneous,
                                   (start * grasp[i]).homogeneous, atol=1e-8)
        # t = end: the weld still holds the tool there, relative to the box
        q_end = result.q[-1, system.arm_set.q_slices[i]]
        box_end = pin.XYZQUATToSE3(np.concatenate([result.object_position[-1],
                                                   result.object_quaternion[-1]]))
        np.testing.assert_allclose(box_end.actInv(arm.tool_placement(q_end)).homogeneous,
                                   grasp[i].homogeneous, atol=1e-6)
    assert result.constraint_violation.max() < 1e-8


def test_example_lifts_the_box_to_the_goal(run):
    ns, out, _ = run
    result, goal = ns["result"], ns["goal"]
    assert result.t[-1] == pytest.approx(0.2)
    np.testing.assert_allclose(result.object_position[0], [0.5, 0.0, 0.35], atol=1e-12)
    np.testing.assert_allclose(result.object_position[-1], goal.translation, atol=1e-4)
    np.testing.assert_allclose(np.abs(result.object_quaternion[-1]), [0, 0, 0, 1], atol=1e-6)
    assert "max constraint violation [m]:" in out


def test_example_grasp_analysis_is_the_thesis_two_corner_grasp(run):
    """The seven contacts are thesis Example 2.1's (A = 5 cm, E = 2 cm, D = 15 cm); their LP
    margin is min(λ)/Σλ of the positive null vector λ of the 6 x 7 wrench matrix."""
    ns, out, _ = run
    closure = ns["closure"]
    thesis = two_corner_box_grasp((0.8, 0.4, 0.3), A=0.05, E=0.02, D=0.15)
    points = np.array([p for _, p in ns["tips"]])
    np.testing.assert_allclose(points, thesis.points, atol=1e-12)
    _, sv, Vt = np.linalg.svd(thesis.wrenches())
    assert sv[-1] > 1e-3  # rank 6: a one-dimensional null space
    null = Vt[-1] * np.sign(Vt[-1].sum())
    assert np.all(null > 0)  # a strictly positive combination: form closure
    assert closure.form_closure
    assert closure.margin == pytest.approx(null.min() / null.sum(), abs=1e-9)
    assert f"form closure: True margin: {closure.margin}" in out
    assert f"margin: {closure.margin:.4f}" in README.read_text(encoding="utf-8")


def test_example_writes_a_replay_page_with_the_arms_meshes(run):
    """The viewer's script (0.85 MB) and the UR5 meshes, once for both arms (0.6 MB)."""
    _, _, folder = run
    page = folder / "replay.html"
    assert page.is_file()
    size = page.stat().st_size
    assert 1.2e6 < size < 2e6, f"replay page of {size / 1e6:.2f} MB"
    assert page.read_text(encoding="utf-8").lstrip().lower().startswith("<!doctype html")
