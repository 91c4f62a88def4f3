import numpy as np
import pinocchio as pin
import pytest

from multiarm_pin.exceptions import InputError
from multiarm_pin.sim.trajectories import MinimumJerkTrajectory, minimum_jerk, pose_error


def random_quaternion(rng):
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


@pytest.fixture
def traj(rng):
    times = [0.5, 1.7, 2.4, 4.0]
    pos = rng.normal(size=(4, 3))
    quat = np.array([random_quaternion(rng) for _ in range(4)])
    return MinimumJerkTrajectory(times, pos, quat)


def test_profile_closed_form():
    s, ds, dds = minimum_jerk(0.5)
    assert s == pytest.approx(0.5) and ds == pytest.approx(1.875) and dds == pytest.approx(0.0)
    assert minimum_jerk(0.0) == (0.0, 0.0, 0.0)
    assert minimum_jerk(1.0) == pytest.approx((1.0, 0.0, 0.0))
    # derivatives by central differences
    h = 1e-6
    for tau in (0.1, 0.37, 0.8):
        s_p, ds_p, _ = minimum_jerk(tau + h)
        s_m, ds_m, _ = minimum_jerk(tau - h)
        _, ds, dds = minimum_jerk(tau)
        assert (s_p - s_m) / (2 * h) == pytest.approx(ds, rel=1e-7)
        assert (ds_p - ds_m) / (2 * h) == pytest.approx(dds, rel=1e-6, abs=1e-7)


def test_passes_through_waypoints_at_rest(traj):
    for k, t in enumerate(traj.times):
        s = traj(t)
        np.testing.assert_allclose(s.position, traj.positions[k], atol=1e-12)
        assert abs(abs(s.quaternion @ traj.quaternions[k]) - 1) < 1e-12
        np.testing.assert_allclose(s.twist, 0, atol=1e-12)
        np.testing.assert_allclose(s.acceleration, 0, atol=1e-12)
    # held outside the time range
    np.testing.assert_allclose(traj(-3.0).position, traj.positions[0])
    np.testing.assert_allclose(traj(10.0).position, traj.positions[-1])


def test_velocity_and_acceleration_match_finite_differences(traj, rng):
    h = 1e-5
    for t in rng.uniform(0.5, 4.0, size=20):
        s, sp, sm = traj(t), traj(t + h), traj(t - h)
        np.testing.assert_allclose((sp.position - sm.position) / (2 * h), s.twist[:3],
                                   atol=1e-7)
        omega = pin.log3(sp.rotation @ sm.rotation.T) / (2 * h)
        np.testing.assert_allclose(omega, s.twist[3:], atol=1e-7)
        np.testing.assert_allclose((sp.twist - sm.twist) / (2 * h), s.acceleration, atol=1e-5)
        np.testing.assert_allclose(s.rotation, pin.Quaternion(s.quaternion).toRotationMatrix(),
                                   atol=1e-12)


def test_orientation_follows_the_geodesic(rng):
    q0, q1 = random_quaternion(rng), random_quaternion(rng)
    traj = MinimumJerkTrajectory([0.0, 2.0], np.zeros((2, 3)), [q0, q1])
    mid = traj(1.0)  # s = 1/2: halfway along the shortest rotation (slerp)
    slerp = pin.Quaternion(q0).slerp(0.5, pin.Quaternion(q1))
    np.testing.assert_allclose(mid.rotation, slerp.toRotationMatrix(), atol=1e-12)


def test_pose_error():
    R = pin.rpy.rpyToMatrix(0.1, 0.2, 0.3)
    w = np.array([0.01, -0.02, 0.03])
    e = pose_error([1, 2, 3], pin.exp3(w) @ R, [1, 2, 2.5], R)
    np.testing.assert_allclose(e, [0, 0, 0.5, *w], atol=1e-14)


def test_bad_input():
    with pytest.raises(InputError, match="strictly increasing"):
        MinimumJerkTrajectory([0, 1, 1], np.zeros((3, 3)))
    with pytest.raises(InputError, match="positions"):
        MinimumJerkTrajectory([0, 1], np.zeros((3, 3)))
    with pytest.raises(InputError, match="unit quaternion"):
        MinimumJerkTrajectory([0, 1], np.zeros((2, 3)), [[0, 0, 0, 1], [0, 0, 0, 2]])
    with pytest.raises(InputError, match="finite"):
        MinimumJerkTrajectory.hold([0, 0, 0])(np.nan)


def test_motion_equals_sample_bit_for_bit(traj, rng):
    """motion() (the controller's hot path, per-segment terms precomputed, bisect) gives
    exactly sample()'s position, rotation, twist and acceleration, at and between waypoints
    and outside the time range."""
    ts = [0.0, 0.5, 1.7, 2.4, 4.0, 5.0, *rng.uniform(0.5, 4.0, size=20)]
    for t in ts:
        p, R, tw, acc = traj.motion(float(t))
        ref = traj(float(t))
        assert np.array_equal(p, ref.position), t
        assert np.array_equal(R, ref.rotation), t
        assert np.array_equal(tw, ref.twist), t
        assert np.array_equal(acc, ref.acceleration), t


def test_compiled_reference_motion_equals_motion():
    """``_compiled.trajectory.reference_motion`` on ``table()`` is ``motion`` (before, inside,
    at and after the waypoints, small and large segment rotations)."""
    from multiarm_pin._compiled import layout
    from multiarm_pin._compiled.trajectory import reference_motion

    rng = np.random.default_rng(3)
    angles = (0.0, 1e-6, 0.5, 3.0)  # rotation of each segment [rad], one below EXP3_TAYLOR
    quats = [np.array([0.0, 0.0, 0.0, 1.0])]
    for a in angles[1:]:
        axis = rng.normal(size=3)
        R = pin.exp3(a * axis / np.linalg.norm(axis)) @ pin.Quaternion(quats[-1]).matrix()
        quats.append(pin.Quaternion(R).coeffs().copy())
    times = [0.3, 0.8, 1.6, 2.5]
    traj = MinimumJerkTrajectory(times, rng.normal(size=(4, 3)), quats)
    table, E, ref = traj.table(), np.empty((3, 3)), np.empty(layout.REFERENCE_SIZE)
    worst = 0.0
    for t in [*np.linspace(-0.5, 3.0, 701), *times]:
        reference_motion(t, table, E, ref)
        worst = max(worst, np.abs(ref - layout.reference_vector(*traj.motion(t))).max())
    assert worst <= 1e-14
    single = MinimumJerkTrajectory.hold([1.0, 2.0, 3.0], quats[2])
    reference_motion(1.0, single.table(), E, ref)
    np.testing.assert_array_equal(ref, layout.reference_vector(*single.motion(1.0)))
