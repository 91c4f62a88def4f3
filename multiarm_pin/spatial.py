"""Small spatial-algebra helpers shared by every layer.

Conventions (see ``docs/ARCHITECTURE.md``): spatial vectors are ``[linear; angular]``;
quaternions are stored ``[x, y, z, w]`` like ``pin.Quaternion.coeffs()``; rotations are
3x3 matrices mapping body axes to world axes.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from multiarm_pin.exceptions import InputError

QUATERNION_TOLERANCE = 1e-6
"""Largest accepted | |q| - 1 | for a quaternion given by a user."""


def as_array(value, shape: Sequence[int | None], name: str) -> np.ndarray:
    """Convert ``value`` to a float array of the given shape, or raise :class:`InputError`.

    Args:
        value: anything ``np.asarray`` accepts.
        shape: expected shape; ``None`` entries match any length.
        name: what the value is, for the error message.

    Returns:
        A float64 array of that shape (a copy when conversion was needed).
    """
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: expected numbers of shape {_fmt(shape)}, got {value!r}") from exc
    if arr.ndim != len(shape) or any(
        s is not None and s != n for s, n in zip(shape, arr.shape, strict=False)
    ):
        raise InputError(f"{name}: expected shape {_fmt(shape)}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name}: contains NaN or infinity: {arr}")
    return arr


def _fmt(shape: Sequence[int | None]) -> str:
    inner = ", ".join("n" if s is None else str(s) for s in shape)
    return f"({inner},)" if len(shape) == 1 else f"({inner})"


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix: ``skew(a) @ b == np.cross(a, b)``; (3,) -> (3, 3)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def as_unit_quaternion(
    q, name: str = "quaternion", tol: float = QUATERNION_TOLERANCE
) -> np.ndarray:
    """Check a user quaternion ``[x, y, z, w]`` and return it normalised, shape (4,).

    Raises:
        InputError: wrong length, or norm further than ``tol`` from 1.
    """
    arr = as_array(q, (4,), f"{name} [x, y, z, w]")
    norm = float(np.linalg.norm(arr))
    if abs(norm - 1.0) > tol:
        raise InputError(
            f"{name}: expected a unit quaternion [x, y, z, w], got norm {norm:.9g} "
            f"(tolerance {tol:g}): {arr.tolist()}"
        )
    return arr / norm


def quaternion_to_rotation(q: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a unit quaternion ``[x, y, z, w]`` (not re-checked)."""
    if type(q) is np.ndarray and q.dtype == np.float64:
        x, y, z, w = q.tolist()  # Python floats: the same double arithmetic, less overhead
    else:
        x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def rotation_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``[x, y, z, w]`` (w >= 0) of a rotation matrix (3, 3)."""
    q = pin.Quaternion(np.asarray(R, dtype=float)).coeffs().copy()
    return -q if q[3] < 0 else q


def rpy_to_rotation(rpy) -> np.ndarray:
    """URDF roll-pitch-yaw [rad] to a rotation matrix, ``R = Rz(yaw) Ry(pitch) Rx(roll)``."""
    r = as_array(rpy, (3,), "rpy")
    return pin.rpy.rpyToMatrix(r[0], r[1], r[2])


def quaternion_derivative(q: np.ndarray, omega_world: np.ndarray) -> np.ndarray:
    """Time derivative of ``q = [x, y, z, w]`` for an angular velocity in world axes [rad/s].

    ``q̇ = ½ [ω; 0] ⊗ q`` (world-frame angular velocity multiplies on the left).
    """
    x, y, z, w = q
    wx, wy, wz = omega_world
    return 0.5 * np.array(
        [
            w * wx + wy * z - wz * y,
            w * wy + wz * x - wx * z,
            w * wz + wx * y - wy * x,
            -(wx * x + wy * y + wz * z),
        ]
    )


def integrate_quaternion(q: np.ndarray, omega_world: np.ndarray, dt: float) -> np.ndarray:
    """Rotate ``q`` by the constant world angular velocity ``omega_world`` for ``dt`` seconds.

    Uses the exact exponential map, so the result is a unit quaternion ``[x, y, z, w]``.
    """
    dR = pin.exp3(np.asarray(omega_world, dtype=float) * dt)
    return rotation_to_quaternion(dR @ quaternion_to_rotation(q))


def se3_from(
    position, rotation=None, quaternion=None, rpy=None, name: str = "placement"
) -> pin.SE3:
    """Build a ``pin.SE3`` from a position [m] and one of rotation (3x3), quaternion or rpy."""
    p = as_array(position, (3,), f"{name}.position")
    given = [x is not None for x in (rotation, quaternion, rpy)]
    if sum(given) > 1:
        raise InputError(f"{name}: give only one of rotation, quaternion, rpy")
    if rotation is not None:
        R = as_array(rotation, (3, 3), f"{name}.rotation")
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise InputError(f"{name}.rotation: expected a rotation matrix, got {R.tolist()}")
    elif quaternion is not None:
        R = quaternion_to_rotation(as_unit_quaternion(quaternion, f"{name}.quaternion"))
    elif rpy is not None:
        R = rpy_to_rotation(rpy)
    else:
        R = np.eye(3)
    return pin.SE3(R, p)


def as_se3(value, name: str = "placement") -> pin.SE3:
    """Check a placement given through the public API: a ``pin.SE3`` with a rotation matrix.

    The public API takes every placement (arm base, object, IK target, grasp frame) as a
    ``pin.SE3`` and nothing else, so that one call never mixes conventions.

    Args:
        value: the placement, ``pin.SE3(R, p)`` with ``R`` (3, 3) a rotation (body axes ->
            world axes) and ``p`` (3,) [m].
        name: what it is, for messages.

    Returns:
        A copy of ``value``.

    Raises:
        InputError: not a ``pin.SE3`` (e.g. a ``(position, quaternion)`` pair; the message
            says how to build one), NaN, or a rotation that is not orthonormal with det +1
            (within 1e-6).
    """
    if not isinstance(value, pin.SE3):
        raise InputError(
            f"{name}: expected a pinocchio.SE3, got {type(value).__name__}; build one with "
            "pin.SE3(rotation (3, 3), position (3,)), or from a quaternion [x, y, z, w] with "
            "pin.XYZQUATToSE3([px, py, pz, x, y, z, w])"
        )
    R, p = value.rotation, value.translation
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(p))):
        raise InputError(f"{name}: expected finite numbers, got {value.homogeneous.tolist()}")
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise InputError(f"{name}: the rotation is not a rotation matrix: {R.tolist()}")
    return value.copy()


def se3_to_pose(placement: pin.SE3) -> tuple[np.ndarray, np.ndarray]:
    """``(position (3,) [m], quaternion (4,) [x, y, z, w] with w >= 0)`` of a placement."""
    return placement.translation.copy(), rotation_to_quaternion(placement.rotation)


def wrench_transform(R: np.ndarray, x: np.ndarray) -> np.ndarray:
    """6x6 map of a wrench ``[f; m]`` from a frame at ``x`` with axes ``R`` to the reference.

    Returns ``[[R, 0], [skew(x) R, R]]`` (Eq 3.11 without its minus sign).
    """
    out = np.zeros((6, 6))
    out[:3, :3] = R
    out[3:, 3:] = R
    out[3:, :3] = skew(x) @ R
    return out


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product along the last axis of broadcastable (..., 3) arrays.

    Same result as ``np.cross(a, b)`` at a fraction of its Python overhead (it matters in
    the per-step hot path).
    """
    a, b = np.asarray(a), np.asarray(b)
    if a.shape == (3,) == b.shape and a.dtype == np.float64 and b.dtype == np.float64:
        ax, ay, az = a.tolist()  # one pair of vectors: the same products in Python floats
        bx, by, bz = b.tolist()
        return np.array([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx])
    return a[..., _NEXT] * b[..., _PREV] - a[..., _PREV] * b[..., _NEXT]


_NEXT = np.array([1, 2, 0])
_PREV = np.array([2, 0, 1])
