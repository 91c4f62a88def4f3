"""Hand-placed collisions along a run: scenario data (dicts) of the feasibility tests.

Each function returns ``(data, file)``: a scenario's data, for
:func:`~multiarm_pin.app.scenario.schema.parse_scenario`, and the file it is read as (relative
URDF paths resolve from it). Each starts collision-free and drives a pair of bodies into each
other while it runs; :data:`ALONG_A_RUN` names the pair.
"""

from __future__ import annotations

from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parent.parent.parent
DEMO = REPO / "scenarios" / "two_ur5_box.yaml"
PICK = REPO / "scenarios" / "pick_from_table.yaml"


def demo_data(mass: float = 4.0, duration: float = 0.02, extra: dict | None = None) -> dict:
    """The demo held still (object PD, no waypoints) for ``duration`` [s]."""
    data = yaml.safe_load(DEMO.read_text(encoding="utf-8"))
    data["object"]["mass"] = mass
    data["controller"] = {"type": "object_pd", "kp": 100.0, "kd": 20.0}
    data["simulation"]["duration"] = duration
    data.update(extra or {})
    return data


def wrists_to_the_floor() -> tuple[dict, str]:
    """The demo's box lowered to 5 cm above the floor in 0.6 s: the wrists reach the ground."""
    data = demo_data(duration=0.6)
    data["controller"]["waypoints"] = [{"t": 0.6, "position": [0.5, 0.0, 0.05]}]
    return data, str(DEMO)


def forearms_crossing() -> tuple[dict, str]:
    """The right arm upright next to the left one's forearm (welded where its tool is), the
    box lowered by 10 cm: the two forearms cross."""
    data = yaml.safe_load(DEMO.read_text(encoding="utf-8"))
    right = data["arms"][1]
    right["base"]["position"] = [0.3, 0.45, 0.0]
    right["joint"] = {"type": "weld"}
    right["q0"] = [0.0, -1.57, 0.0, -1.57, 0.0, 0.0]
    del right["q_seed"]
    data["controller"]["waypoints"] = [{"t": 0.6, "position": [0.5, 0.0, 0.25]}]
    data["simulation"].update(duration=0.3, solver="auto")
    return data, str(DEMO)


def base_into_the_box() -> tuple[dict, str]:
    """One UR5 holding a long box's -y face pulls it over its own base."""
    data = yaml.safe_load("""
name: base_into_the_box
object:
  shape: {type: box, size: [1.2, 0.3, 0.3]}
  mass: 1.0
  pose: {position: [0.3, 0.45, 0.16]}
arms:
  - name: a
    robot: ur5
    q_seed: [1.2, -0.6, 1.2, -0.6, -1.57, 0.0]
    joint:
      type: weld
      placement_in_object: {position: [0.0, -0.15, 0.0], rpy: [-1.5707963267948966, 0, 0]}
controller:
  type: object_pd
  kp: 100.0
  kd: 20.0
  waypoints: [{t: 0.6, position: [0.3, 0.1, 0.16]}]
simulation: {duration: 0.6, dt: 0.002}
""")
    return data, str(REPO / "base_into_the_box.yaml")


def fingertip_into_the_table() -> tuple[dict, str]:
    """pick_from_table's box lifted, moved 12 cm in x and 10 cm in y, put down: the bottom
    fingertip (beside the stand at the start) comes down onto it."""
    data = yaml.safe_load(PICK.read_text(encoding="utf-8"))
    data["controller"]["waypoints"] = [
        {"t": 0.1, "position": [0.0, 0.0, 0.9]},
        {"t": 0.4, "position": [0.0, 0.0, 0.95]},
        {"t": 0.8, "position": [0.12, 0.1, 0.95]},
        {"t": 1.1, "position": [0.12, 0.1, 0.9005]},
        {"t": 1.3, "position": [0.12, 0.1, 0.8999]}]
    data["simulation"]["duration"] = 1.3
    return data, str(PICK)


ALONG_A_RUN = {
    "wrists_to_the_floor": (wrists_to_the_floor, "ground", ("left", "right")),
    "forearms_crossing": (forearms_crossing, "right/forearm_link", ("left",)),
    "base_into_the_box": (base_into_the_box, "object", ("a",)),
    "fingertip_into_the_table": (fingertip_into_the_table, "table", ("three_finger",)),
}
"""Case name -> (its scenario function, the other body, the arms of which a link hits it)."""

ALONG_A_RUN_LINK = {
    "wrists_to_the_floor": None,  # any wrist link
    "forearms_crossing": "forearm_link",
    "base_into_the_box": "base_link",
    "fingertip_into_the_table": "fingertip_3",
}
"""Case name -> the link that must be among those hitting the other body (None: any)."""


def assert_clearances_are_brute_force(scene, result, scan) -> int:
    """Each category's clearance of ``scan`` equals the smallest hull distance over every
    pair of that category (grasp pairs aside) at every sample of ``result``, measured here
    with coal pair by pair (``CollisionScene.hull_distances``), to 2e-10 m; None where the
    category has no pair.

    Returns the brute-force distances, (T, pairs) [m].
    """
    import numpy as np
    import pytest

    from multiarm_pin.feasibility import CATEGORIES

    brute = np.array([scene.hull_distances(scene.configuration(
        result.q[s], result.object_position[s], result.object_quaternion[s]))
        for s in range(len(result.t))])
    for ci, name in enumerate(CATEGORIES):
        cols = (scene.category == ci) & ~scene.grasp_pair
        if not cols.any():
            assert scan.clearance[name] is None, name
            continue
        assert scan.clearance[name] == pytest.approx(brute[:, cols].min(), abs=2e-10), name
    return brute
