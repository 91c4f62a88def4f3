"""Rigid-body trajectories with closed-form position, twist and classical acceleration.

``x(t) = x0 + Σ_k c_k t^k`` and ``R(t) = exp(f1(t) k1) exp(f2(t) k2) exp(f3(t) k3) R0``
with polynomial angles ``f_j`` about fixed unit axes ``k_j``. With ``b_j`` the world
direction of the j-th axis (``b_j = Q_{j-1} k_j``, ``Q_j`` the product of the first j
factors), ``ω = Σ ḟ_j b_j`` and ``ω̇ = Σ f̈_j b_j + ḟ_j (ω_{j-1} × b_j)`` exactly.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from multiarm_pin.model.kinematics import BodyKinematics


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return pin.Quaternion(*(q / np.linalg.norm(q))).toRotationMatrix()


class RigidTrajectory:
    """A smooth random rigid-body motion starting at ``(x0, R0)``.

    Args:
        rng: random generator.
        x0: (3,) position at t = 0 [m].
        R0: (3, 3) rotation at t = 0.
        speed: scale of the linear velocity [m/s].
        spin: scale of the angular velocity [rad/s].
    """

    def __init__(self, rng, x0=None, R0=None, speed=0.3, spin=1.0):
        self.x0 = np.zeros(3) if x0 is None else np.asarray(x0, float)
        self.R0 = random_rotation(rng) if R0 is None else np.asarray(R0, float)
        self.c = rng.normal(size=(3, 3)) * speed  # coefficients of t, t^2, t^3
        self.axes = [v / np.linalg.norm(v) for v in rng.normal(size=(3, 3))]
        self.f = rng.normal(size=(3, 3)) * spin  # f_j(t) = f[j] · [t, t^2, t^3]

    @staticmethod
    def _poly(coef, t):
        """value, first and second derivative of Σ coef[k] t^(k+1)."""
        p = coef[0] * t + coef[1] * t**2 + coef[2] * t**3
        dp = coef[0] + 2 * coef[1] * t + 3 * coef[2] * t**2
        ddp = 2 * coef[1] + 6 * coef[2] * t
        return p, dp, ddp

    def state(self, t: float):
        """``(x, R, twist [v; ω], classical acceleration [ẍ; ω̇])`` at time t [s]."""
        x, v, a = self._poly(self.c, t)
        Q = np.eye(3)
        omega = np.zeros(3)
        omega_dot = np.zeros(3)
        for k, coef in zip(self.axes, self.f, strict=True):
            f, df, ddf = self._poly(coef, t)
            b = Q @ k
            omega_dot += ddf * b + df * np.cross(omega, b)
            omega += df * b
            Q = Q @ pin.exp3(f * k)
        R = Q @ self.R0
        return self.x0 + x, R, np.concatenate([v, omega]), np.concatenate([a, omega_dot])

    def kinematics(self, t: float) -> BodyKinematics:
        x, R, tw, _ = self.state(t)
        return BodyKinematics.single(x, R, tw)


def stack(kins) -> BodyKinematics:
    """Stack single-body kinematics into one BodyKinematics."""
    return BodyKinematics(
        np.concatenate([k.position for k in kins]),
        np.concatenate([k.rotation for k in kins]),
        np.concatenate([k.twist for k in kins]),
    )
