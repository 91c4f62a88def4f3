"""``phased_pd``: a box tilted about a bottom edge on a frictionless table (thesis ch. 5).

Two mp6 arms, one fingertip each: ``pusher`` pushes +x high on the -x face, ``stop`` pushes
-x low on the +x face; the table (a finite rectangle) holds the box by its four bottom
vertices, of which the two on the +x edge (rows 0, 1) are the pivot.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest
import yaml

from multiarm_pin.app.runner import scenario_controller, simulate_built
from multiarm_pin.app.scenario import build_scenario, load_scenario
from multiarm_pin.exceptions import InputError
from multiarm_pin.sim.contact_loop import FINITE_SUPPORTS_NOTE
from multiarm_pin.sim.controllers import make_controller

ROBOTS = Path(__file__).resolve().parent.parent / "multiarm_pin" / "data" / "robots" / "mp6"
MASS, G = 4.0, 9.81
SIZE = (0.8, 0.6, 0.4)
PIVOT = (0.4, 0.0, 0.7)
TILT = 0.05
"""[rad] over 0.6 s from t = 0.1 s."""

COUPLE = {
    "name": "tilt_couple",
    "object": {"shape": {"type": "box", "size": list(SIZE)}, "mass": MASS,
               "pose": {"position": [0.0, 0.0, 0.9]}},
    "supports": [{"name": "table", "plane": {"point": [0, 0, 0.7], "normal": [0, 0, 1]},
                  "extent": [2.0, 2.0], "restitution": 0.0,
                  "points": [[0.4, 0.3, -0.2], [0.4, -0.3, -0.2], [-0.4, 0.3, -0.2],
                             [-0.4, -0.3, -0.2]]}],
    "arms": [
        {"name": "pusher", "urdf": str(ROBOTS / "mp6.urdf"), "tool_frame": "tool0",
         "base": {"position": [-1.05, 0.0, 0.55], "rpy": [0, 0, 0]},
         "q_seed": [0.0, 0.3, -1.2, 0.0, 0.9, 0.0],
         "joint": {"type": "fingertips", "tip_radius": 0.015,
                   "contacts": [{"tip": "fingertip_1", "face": "-x",
                                 "point": [-0.4, 0.0, 0.12]}]}},
        {"name": "stop", "urdf": str(ROBOTS / "mp6.urdf"), "tool_frame": "tool0",
         "base": {"position": [1.05, 0.0, 0.4], "rpy": [0, 0, float(np.pi)]},
         "q_seed": [0.0, 0.3, -1.2, 0.0, 0.9, 0.0],
         "joint": {"type": "fingertips", "tip_radius": 0.015,
                   "contacts": [{"tip": "fingertip_1", "face": "+x",
                                 "point": [0.4, 0.0, -0.17]}]}},
    ],
    "controller": {"type": "phased_pd", "support_margin": 2.0, "margin": 2.0, "phases": [
        {"name": "rest", "kind": "hold", "t": 0.0, "duration": 0.1},
        {"name": "tilt", "kind": "tilt", "t": 0.1, "duration": 0.6, "pivot": list(PIVOT),
         "axis": [0, 1, 0], "angle": TILT, "press": [0, 1]}]},
    "simulation": {"duration": 0.7, "integrator": "rk4", "dt": 0.005,
                   "solver": "object_first", "baumgarte": {"alpha": 5.0, "beta": 5.0}},
}


@cache
def _tilt_run():
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "couple.yaml"
        p.write_text(yaml.safe_dump(COUPLE), encoding="utf-8")
        sc = load_scenario(p)
    built = build_scenario(sc, load_visuals=False)
    res = simulate_built(built, scenario_controller(built), sc.simulation.duration,
                         sc.simulation.dt, sc.simulation.solver)
    return built, res


def test_statics_of_a_slow_tilt_match_the_closed_form():
    """Forces at every recorded sample of the tilt against the box's Newton-Euler equations.

    Closed form. The box turned by θ about +y (its -x side up), ``n = R e_x = (cos θ, 0,
    -sin θ)`` the inward normal of its -x face. Unknowns: the pusher's force ``F_A`` along
    ``n`` at ``r_A`` (from the COM), the stop's ``F_B`` along ``-n`` at ``r_B``, the pivot
    vertices' vertical forces ``N_1``, ``N_2`` at ``r_1``, ``r_2`` (same world x, ``r_p``;
    the table is frictionless, so they are vertical). With the recorded COM acceleration
    ``a``, angular acceleration ``α``, angular velocity ``ω`` and ``L = I α + ω × I ω``
    (world inertia ``I = R I_body Rᵀ``):

    - x: ``(F_A - F_B) cos θ = m a_x``, so ``D = F_A - F_B = m a_x / cos θ``;
    - z: ``-D sin θ + N - m g = m a_z``, so ``N = N_1 + N_2 = m (a_z + g) + D sin θ``;
    - moment about y: ``F_A m_A + F_B m_B - r_px N = L_y`` with ``m_A = r_Az cos θ +
      r_Ax sin θ``, ``m_B = -(r_Bz cos θ + r_Bx sin θ)``, so ``F_A = (L_y + r_px N +
      D m_B) / (m_A + m_B)``, ``F_B = F_A - D``;
    - moment about x (arm forces in the x-z plane through y = 0): ``r_1y N_1 + r_2y N_2 =
      L_x``, so ``N_1 = (L_x - r_2y N) / (r_1y - r_2y)``, ``N_2 = N - N_1``.

    Static limit (``a, α, ω → 0``): ``N = m g``, ``F_A = F_B = -r_px m g / (m_A + m_B)``.
    The recorded multipliers (the simulation's mixed LCP) match these to 1e-6 of ``m g``,
    the motion is slow (``|m a| < 0.05 m g``), the far vertices are off the table, and the
    pivot edge does not slide (its vertices' x moves below 1e-6 m).
    """
    built, res = _tilt_run()
    far = [e for e in res.events if e.label in ("table[2]", "table[3]")]
    assert [e.kind for e in far] == ["separation", "separation"]
    assert all(e.t < 0.12 for e in far)
    I_body = MASS / 12.0 * np.diag([SIZE[1] ** 2 + SIZE[2] ** 2, SIZE[0] ** 2 + SIZE[2] ** 2,
                                    SIZE[0] ** 2 + SIZE[1] ** 2])
    after = np.flatnonzero(res.t > max(e.t for e in far))
    assert len(after) > 100
    worst = 0.0
    for k in after:
        x, y, z, w = res.object_quaternion[k]
        R = np.array(__import__("pinocchio").Quaternion(w, x, y, z).toRotationMatrix())
        theta = np.arctan2(R[0, 2], R[0, 0])
        n = R[:, 0]
        com = res.object_position[k]
        a, alpha = res.object_acceleration[k, :3], res.object_acceleration[k, 3:]
        omega = res.object_twist[k, 3:]
        I_w = R @ I_body @ R.T
        L = I_w @ alpha + np.cross(omega, I_w @ omega)
        r_A = res.contact_points[k, 0, 0] - com
        r_B = res.contact_points[k, 1, 0] - com
        r_1 = res.contact_points[k, 2, 0] - com
        r_2 = res.contact_points[k, 2, 1] - com
        np.testing.assert_allclose(res.normals[k, 0, 0], n, atol=1e-12)
        D = MASS * a[0] / np.cos(theta)
        N = MASS * (a[2] + G) + D * np.sin(theta)
        m_A = r_A[2] * np.cos(theta) + r_A[0] * np.sin(theta)
        m_B = -(r_B[2] * np.cos(theta) + r_B[0] * np.sin(theta))
        F_A = (L[1] + r_1[0] * N + D * m_B) / (m_A + m_B)
        N_1 = (L[0] - r_2[1] * N) / (r_1[1] - r_2[1])
        expected = np.array([F_A, F_A - D, N_1, N - N_1])
        got = np.array([res.mu[k, 0, 0], res.mu[k, 1, 0], res.mu[k, 2, 0], res.mu[k, 2, 1]])
        worst = max(worst, float(np.abs(got - expected).max() / (MASS * G)))
        assert abs(r_1[0] - r_2[0]) < 1e-9 and abs(L[2]) < 1e-6 * MASS * G
        assert np.linalg.norm(MASS * a) < 0.05 * MASS * G
        assert res.mu[k, 2, 2] == 0.0 and res.mu[k, 2, 3] == 0.0
    assert worst <= 1e-6, worst
    # the static limit is the closed form without the (small) inertial terms
    k = after[-1]
    assert res.mu[k, 2, :2].sum() == pytest.approx(MASS * G, rel=1e-3)
    pivot = res.contact_points[:, 2, :2]
    assert np.abs(pivot[:, :, 0] - pivot[0, :, 0]).max() < 1e-6
    assert np.abs(pivot[:, :, 2] - PIVOT[2]).max() < 1e-6


def test_the_tilt_reaches_its_angle_and_never_asks_a_pull():
    """The final pose is the start turned by the tilt angle about the pivot edge (to 1e-4 m:
    the PD settles within the 0.6 s ramp); every arm contact pushes with the margin and the
    pivot rows press; the compiled contact loop takes the run (no note that the reference
    stepper does, nor the finite table's: every support point stays 0.5 m inside the 2 m
    square)."""
    built, res = _tilt_run()
    c, p0 = np.array(PIVOT), np.array([0.0, 0.0, 0.9])
    Ry = np.array([[np.cos(TILT), 0, np.sin(TILT)], [0, 1, 0], [-np.sin(TILT), 0, np.cos(TILT)]])
    assert np.linalg.norm(res.object_position[-1] - (c + Ry @ (p0 - c))) < 1e-4
    assert res.mu[:, :2, 0].min() >= 2.0 - 1e-6
    after = res.t > 0.12
    assert res.mu[after, 2, :2].min() >= 2.0 - 1e-6
    assert not any("numpy) stepper" in w for w in res.warnings)
    assert np.abs(res.contact_points[:, 2, :4, :2]).max() < 1.0 - 0.5
    assert FINITE_SUPPORTS_NOTE not in res.warnings


def test_bad_phases_are_clear_errors():
    built, _ = _tilt_run()
    s = built.system
    with pytest.raises(InputError, match=r"phases\[0\]\.kind"):
        make_controller("phased_pd", s, phases=[{"kind": "spin"}])
    with pytest.raises(InputError, match=r"phases\[1\]\.t"):
        make_controller("phased_pd", s, phases=[{"duration": 1.0}, {"t": 0.5}])
    with pytest.raises(InputError, match=r"phases\[0\]\.press"):
        make_controller("phased_pd", s, phases=[{"press": [7]}])
    with pytest.raises(InputError, match=r"unknown arm 'left'"):
        make_controller("phased_pd", s, phases=[{"release": ["left"]}])
    with pytest.raises(InputError, match=r"phases\[0\]\.loose: unknown contact 'stop:tip\[3\]'"):
        make_controller("phased_pd", s, phases=[{"loose": ["stop:tip[3]"]}])
    make_controller("phased_pd", s, phases=[{"loose": ["stop:tip[0]"]}])


def test_released_grippers_stop_pushing_and_separate(tmp_path):
    """``pick_from_table``'s grippers hold the box on its stand, then both are released
    (no planned force) and move 1 cm away from their grasp (object frame): every fingertip
    separates after the release starts, no multiplier is ever negative, and the box stays
    on the stand (the stand's rows take its weight: their sum is m g at the end)."""
    d = yaml.safe_load((ROBOTS.parent.parent / "scenarios" / "pick_from_table.yaml")
                       .read_text(encoding="utf-8"))
    for arm in d["arms"]:
        arm["urdf"] = str(ROBOTS / Path(arm["urdf"]).name)
    d["controller"] = {"type": "phased_pd", "margin": 2.0, "phases": [
        {"name": "hold", "kind": "hold", "t": 0.0, "duration": 0.1},
        {"name": "release", "kind": "hold", "t": 0.1, "duration": 0.15, "margin": 0.0,
         "release": ["four_finger", "three_finger"],
         "offsets": {"four_finger": [0.01, 0.01, 0.01], "three_finger": [-0.01, -0.01, -0.01]}},
    ]}
    p = tmp_path / "release.yaml"
    p.write_text(yaml.safe_dump(d), encoding="utf-8")
    sc = load_scenario(p)
    built = build_scenario(sc, load_visuals=False)
    res = simulate_built(built, scenario_controller(built), 0.3, 0.002, sc.simulation.solver)
    left = {(e.block, e.row): e.t for e in res.events if e.kind == "separation" and e.block < 2}
    assert set(left) == {(0, 0), (0, 1), (0, 2), (0, 3), (1, 0), (1, 1), (1, 2)}
    assert min(left.values()) >= 0.1
    assert not any(e.kind == "touchdown" and e.block < 2 for e in res.events)
    assert res.mu.min() >= 0.0
    assert not res.active[-1, :2].any()
    assert np.abs(res.object_position - res.object_position[0]).max() < 1e-6
    assert res.mu[-1, 2, :4].sum() == pytest.approx(MASS * G, rel=1e-6)
