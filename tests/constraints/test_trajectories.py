"""The test trajectories' closed-form derivatives against finite differences."""

import numpy as np
import pinocchio as pin

from .trajectories import RigidTrajectory


def test_closed_form_twist_and_acceleration_match_finite_differences():
    rng = np.random.default_rng(0)
    for _ in range(5):
        traj = RigidTrajectory(rng, rng.normal(size=3))
        t, h = rng.uniform(-0.5, 0.5), 1e-5
        x, R, tw, acc = traj.state(t)
        xp, Rp, twp, _ = traj.state(t + h)
        xm, Rm, twm, _ = traj.state(t - h)
        assert np.allclose((xp - xm) / (2 * h), tw[:3], atol=1e-8)
        # world angular velocity: log(R(t+h) R(t-h)^T) / 2h
        assert np.allclose(pin.log3(Rp @ Rm.T) / (2 * h), tw[3:], atol=1e-7)
        assert np.allclose((twp - twm) / (2 * h), acc, atol=1e-6)
        assert np.linalg.norm(acc) > 0.1  # the check is not vacuous
